"""The conversion against its quality claims (issue #20): image fidelity, patch errors, mesh
distance, adaptive patch sizes, normal maps, bad input."""

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from unmesh.convert import ConvertOptions, TexturedMesh, convert_cloud, to_textured_mesh
from unmesh.convert._patch_kernels import bilinear_reference
from unmesh.convert.reconstruct import disc_distance
from unmesh.errors import InputError
from unmesh.render import Camera, render
from unmesh.render.raster import texture_levels
from unmesh.spatial import TriangleBVH
from unmesh.surfels import SurfelCloud

VIEWS = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]


def _camera(d, size=200):
    up = (0, 0, 1) if abs(d[1]) > 0.5 else (0, 1, 0)
    return Camera(np.array(d, float) * 3.5, (0, 0, 0), up=up, width=size, height=size, fov=40)


def test_surfels_and_textured_mesh_render_alike_from_six_views(pattern_cloud, converted):
    psnr, ssim = [], []
    for d in VIEWS:
        cam = _camera(d)
        a = render(pattern_cloud, cam)
        b = render(converted.textured, cam)
        both = a.coverage & b.coverage
        # the silhouettes differ by the polygonal outline only
        assert (a.coverage ^ b.coverage).sum() < 0.05 * a.coverage.sum()
        psnr.append(10 * np.log10(1.0 / np.mean((a.color[both] - b.color[both]) ** 2)))
        ssim.append(structural_similarity(a.color, b.color, channel_axis=2, data_range=1.0))
    print(f"PSNR {np.round(psnr, 1)} dB, SSIM {np.round(ssim, 3)}")  # measured 32-36 dB, SSIM ~0.91
    assert min(psnr) >= 30.0
    assert min(ssim) > 0.85


def _atlas_errors(cloud, tm: TexturedMesh):
    """Mean colour error (6.1) of every triangle, measured on the written atlas pages."""
    errs = []
    for part in tm.parts:
        v = part.vertices[part.faces]  # (F,3,3)
        uv = part.uv[part.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        for f in range(len(v)):
            d = cloud.positions - v[f, 0]
            dist = d @ n[f]
            near = (np.abs(dist) < 0.1) & (cloud.normals @ n[f] > 0)
            p = cloud.positions[near] - dist[near, None] * n[f]
            e0, e1, e2 = v[f, 1] - v[f, 0], v[f, 2] - v[f, 0], p - v[f, 0]
            d00, d01, d11 = e0 @ e0, e0 @ e1, e1 @ e1
            d20, d21 = e2 @ e0, e2 @ e1
            den = d00 * d11 - d01 * d01
            b1 = (d11 * d20 - d01 * d21) / den
            b2 = (d00 * d21 - d01 * d20) / den
            inside = (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1)
            if not inside.any():
                errs.append(0.0)
                continue
            bary = np.c_[1 - b1 - b2, b1, b2][inside]
            t = bary @ uv[f]
            h, w = part.texture.shape[:2]
            tex = bilinear_reference(part.texture, t[:, 0] * w, (1 - t[:, 1]) * h)
            errs.append(float(np.linalg.norm(cloud.colors[near][inside] - tex, axis=1).mean()))
    return np.array(errs)


def test_every_patch_error_is_below_the_threshold(pattern_cloud, converted):
    rep = converted.report["patches"]
    assert rep["capped"] == 0  # smooth colours: the d_min cap is never needed
    errs = _atlas_errors(pattern_cloud, converted.textured)
    assert len(errs) == rep["triangles"]
    assert errs.max() <= ConvertOptions().texture_error + 1e-9
    assert rep["color_error_max_converged"] <= ConvertOptions().texture_error


def test_mesh_within_the_mesh_error_both_ways(pattern_cloud, converted):
    mesh = converted.mesh
    bound = ConvertOptions().mesh_error * np.linalg.norm(np.ptp(pattern_cloud.positions, axis=0))
    d, _, _, _ = TriangleBVH(mesh.vertices, mesh.faces).closest(pattern_cloud.positions)
    assert d.max() <= bound
    rng = np.random.default_rng(0)
    f = mesh.faces[rng.integers(0, len(mesh.faces), 20000)]
    pts = np.einsum("nk,nkj->nj", rng.dirichlet(np.ones(3), 20000), mesh.vertices[f])
    assert disc_distance(pts, pattern_cloud).max() <= bound
    assert converted.report["simplification"]["met"]
    assert converted.report["reconstruction"]["boundary_edges"] == 0


def test_uniform_region_gets_tiny_patches_and_painted_detail_large_ones(pattern_cloud):
    # uniformly blue everywhere except a painted cap with fine stripes (Fig. 6.3: 6 vs 5228 texels)
    p = pattern_cloud.positions
    col = np.tile([0.2, 0.3, 0.8], (len(p), 1))
    cap = p[:, 2] > 0.6
    col[cap] = np.c_[0.5 + 0.5 * np.sin(30 * p[cap, 0]), 0.5 + 0.5 * np.cos(30 * p[cap, 1]), np.full(cap.sum(), 0.1)]
    res = convert_cloud(pattern_cloud.replace(colors=col), ConvertOptions(faces=200, normal_map=False))
    mesh = res.mesh
    cz = mesh.vertices[mesh.faces].mean(axis=1)[:, 2]
    tex = np.array([p.size for p in _patch_sizes(res)])
    uniform, painted = cz < 0.0, cz > 0.75
    assert uniform.sum() > 50 and painted.sum() > 5
    print(f"texels: uniform median {np.median(tex[uniform])}, painted median {np.median(tex[painted])}")
    assert np.median(tex[uniform]) <= 12  # level 0: 3 x 3 texels or 3 x 4 with the borders
    assert np.median(tex[painted]) >= 20 * np.median(tex[uniform])


def _patch_sizes(res):
    from unmesh.convert.patches import patch_size, triangle_frames

    w, h = patch_size(triangle_frames(res.mesh), np.array(res.report["_levels"]))
    return [np.zeros((hh, ww)) for ww, hh in zip(w, h, strict=True)]


def test_normal_map_restores_normal_detail_the_mesh_does_not_have(pattern_cloud):
    # a smooth sphere whose surfel normals carry a bump pattern (geometric detail below the
    # mesh resolution, as after strong simplification, Fig. 6.6)
    p = pattern_cloud.positions
    bump = 0.25 * np.c_[np.sin(9 * p[:, 1]), np.sin(9 * p[:, 2]), np.sin(9 * p[:, 0])]
    bump -= np.einsum("ij,ij->i", bump, p)[:, None] * p
    cloud = pattern_cloud.replace(normals=p + bump)
    res = convert_cloud(cloud, ConvertOptions(faces=300))
    cam = _camera((0.3, 0.5, 0.8))
    ref = render(cloud, cam)
    with_map = render(res.textured, cam)
    without = render(res.textured.without_normal_map(), cam)
    both = ref.coverage & with_map.coverage

    def angle(a):
        return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a.normal[both], ref.normal[both]), -1, 1))).mean()

    print(f"normal error {angle(with_map):.2f} deg with the map, {angle(without):.2f} without")
    assert angle(with_map) < 0.4 * angle(without)


def test_bad_input_gives_one_line_errors():
    with pytest.raises(InputError, match="positions"):
        SurfelCloud([[np.nan, 0, 0]] * 30, [[0, 0, 1]] * 30, radii=np.ones(30))
    with pytest.raises(InputError, match="at least 20 surfels"):
        to_textured_mesh(SurfelCloud(np.eye(3), np.eye(3), radii=np.ones(3)))
    with pytest.raises(InputError, match="SurfelCloud"):
        to_textured_mesh(np.zeros((100, 3)))
    with pytest.raises(InputError, match="mesh_error"):
        ConvertOptions(mesh_error=-1)
    with pytest.raises(InputError, match="page_size"):
        ConvertOptions(page_size=1000)


def test_unmeetable_mesh_error_falls_back_to_the_finest_mesh(pattern_cloud):
    from unmesh.convert import reconstruct, simplify_to_error

    mesh = reconstruct(pattern_cloud)
    out, rec = simplify_to_error(mesh, pattern_cloud, 1e-9)
    assert rec["met"] is False and out is mesh and rec["faces"] == len(mesh.faces)


def test_regions_give_every_page_texel_its_patch(converted):
    """``TexturedMesh.regions``: the texel under every triangle's centroid belongs to that
    triangle's patch, so the rasteriser's filtered levels stay within the patch (6.5)."""
    tm = converted.textured
    assert len(tm.regions) == len(tm.parts)
    for part, reg in zip(tm.parts, tm.regions, strict=True):
        ids = np.unique(reg[reg >= 0])
        assert len(ids) == len(part.faces)  # one region per triangle of the page, in face order
        uv = part.uv[part.faces].mean(axis=1)
        edge = reg.shape[0]
        col = np.floor(uv[:, 0] * edge).astype(int)
        row = np.floor((1.0 - uv[:, 1]) * edge).astype(int)
        assert np.array_equal(reg[row, col], ids)
        # the levels of a patch's texels lie within the range of that patch's own texels
        lv = np.stack(texture_levels(part.texture, reg, count=4))
        for r in ids[:20]:
            inside = reg == r
            lo, hi = part.texture[inside].min(axis=0), part.texture[inside].max(axis=0)
            assert np.all(lv[:, inside] >= lo - 1e-12) and np.all(lv[:, inside] <= hi + 1e-12)
