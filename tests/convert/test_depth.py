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
