"""Depth (displacement) textures (6.2): the height of the surfels above every triangle's plane."""

import numpy as np
import pytest

from unmesh.convert import ConvertOptions, convert_cloud, write_textured_obj
from unmesh.convert._patch_kernels import bilinear_reference


@pytest.fixture(scope="module")
def coarse(sphere_cloud):
    return convert_cloud(sphere_cloud, ConvertOptions(faces=80, depth_map=True, normal_map=False, fit_mesh=False))


def test_depth_texture_lifts_coarse_triangles_onto_the_sphere(coarse):
    tm = coarse.textured
    assert len(tm.depth_pages) == len(tm.parts)
    rng = np.random.default_rng(0)
    before, after = [], []
    for part, page in zip(tm.parts, tm.depth_pages, strict=True):
        v = part.vertices[part.faces]
        uv = part.uv[part.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        bary = rng.dirichlet(np.ones(3), size=(len(v), 20))  # (F, 20, 3) points inside every face
        p = np.einsum("fsk,fkj->fsj", bary, v).reshape(-1, 3)
        t = np.einsum("fsk,fkj->fsj", bary, uv).reshape(-1, 2)
        h, w = page.shape
        height = bilinear_reference(page[..., None], t[:, 0] * w, (1 - t[:, 1]) * h)[:, 0]
        lifted = p + height[:, None] * np.repeat(n, 20, axis=0)
        before.append(np.abs(np.linalg.norm(p, axis=1) - 1))
        after.append(np.abs(np.linalg.norm(lifted, axis=1) - 1))
    before, after = np.concatenate(before), np.concatenate(after)
    print(f"distance to the unit sphere: flat triangles max {before.max():.4f} mean {before.mean():.4f}; "
          f"displaced max {after.max():.4f} mean {after.mean():.4f}")
    assert before.max() > 0.05  # the triangles are coarse
    assert after.mean() < 0.1 * before.mean()
    assert after.max() < 0.3 * before.max()


def test_depth_page_is_written_as_16_bit_png_with_disp_statement(coarse, tmp_path):
    from PIL import Image

    files = write_textured_obj(tmp_path / "s.obj", coarse.textured)
    mtl = (tmp_path / "s.mtl").read_text()
    depth_files = [f for f in files if f.name.endswith("_depth.png")]
    assert len(depth_files) == len(coarse.textured.parts)
    for k, f in enumerate(depth_files):
        line = next(ln for ln in mtl.splitlines() if ln.startswith("disp") and ln.endswith(f.name))
        base, gain = map(float, line.split()[2:4])
        grey = np.asarray(Image.open(f), dtype=np.float64) / 65535.0
        page = coarse.textured.depth_pages[k]
        assert np.abs(base + gain * grey - page).max() <= gain / 65535.0 + 1e-12


def test_height_map_is_unbiased_on_a_sphere_cap(coarse, sphere_cloud):
    """Every depth texel inside its triangle against the sphere's exact height above the plane.

    The splatted depth alone extrapolates the surfels' tangent planes over a texel-wide
    footprint and sits above the sphere by ~ sigma^2 / 2 (unit sphere at 80 triangles, level-2
    texels: +0.006 mean); the splatted centre heights sit below by as much. Their mean is the
    height texture (`patches._height_map`).
    """
    from unmesh.convert.patches import render_patches, spacings, texel_positions, triangle_frames

    mesh = coarse.mesh
    cloud = sphere_cloud
    pa = render_patches(mesh, cloud, texture_error=0.02, normal_error=None, max_level=7, depth=True)
    fr = triangle_frames(mesh)
    errs, sizes = [], []
    for t in range(len(mesh.faces)):
        h, w = pa.depth[t].shape
        rr, cc = (a.ravel() for a in np.mgrid[0:h, 0:w])
        lxy, world = texel_positions(fr, np.full(len(rr), t), pa.level, pa.height, rr, cc, pa.offset)
        n = fr.rotation[t, 2]
        d0 = n @ fr.origin[t]
        true = np.sqrt(1 - ((world**2).sum(1) - (world @ n) ** 2)) - d0
        ax, ay, length = fr.apex[t, 0], fr.apex[t, 1], fr.length[t]
        x, y = lxy[:, 0], lxy[:, 1]
        inside = (y >= 0) & (ax * y - ay * x <= 0) & ((length - ax) * y + ay * (x - length) <= 0)
        errs.append((pa.depth[t].ravel() - true)[inside])
        sizes.append(np.full(inside.sum(), length / spacings(pa.level[t])))
    e, h = np.concatenate(errs), np.concatenate(sizes)
    bias = (h**2 / 2).mean()  # the extrapolated depth's bias for this footprint (one texel)
    assert abs(e.mean()) < 0.1 * bias
    assert np.abs(e).max() < 0.5 * (h**2).max()

