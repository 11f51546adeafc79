"""Triangle rasteriser: analytic coverage, z-buffer vs the numpy reference, perspective-correct
interpolation, textures ((0,0) bottom-left, bilinear) and normal maps."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import TriangleMesh
from unmesh.render import Camera, GBuffer, render
from unmesh.render._reference import triangles_reference
from unmesh.render.raster import draw_meshes

QUAD_V = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
QUAD_F = [[0, 1, 2], [0, 2, 3]]
QUAD_UV = [[0, 0], [1, 0], [1, 1], [0, 1]]


def gbuffer_of(meshes, cam):
    g = GBuffer.empty(*cam.shape)
    draw_meshes(g, meshes, cam)
    return g


def test_axis_aligned_quad_covers_exactly_the_analytic_pixels():
    cam = Camera((0, 0, 5), (0, 0, 0), width=40, height=30, ortho=3.0)  # 0.1 units per pixel
    quad = TriangleMesh([[-0.73, -0.42, 0], [1.17, -0.42, 0], [1.17, 0.61, 0], [-0.73, 0.61, 0]], QUAD_F)
    g = gbuffer_of([quad], cam)
    o, _ = cam.rays()
    inside = (o[..., 0] >= -0.73) & (o[..., 0] <= 1.17) & (o[..., 1] >= -0.42) & (o[..., 1] <= 0.61)
    assert np.array_equal(g.coverage, inside)
    assert np.allclose(g.depth[inside], 5.0)
    assert np.allclose(g.normal[inside], [0, 0, 1])


def test_triangle_coverage_matches_point_in_triangle():
    cam = Camera((0, 0, 5), (0, 0, 0), width=64, height=64, ortho=2.0)
    a, b, c = np.array([-0.83, -0.71]), np.array([0.77, -0.35]), np.array([-0.12, 0.88])
    tri = TriangleMesh([[*a, 0], [*b, 0], [*c, 0]], [[0, 1, 2]])
    g = gbuffer_of([tri], cam)
    o, _ = cam.rays()
    p = o[..., :2]

    def side(u, v, q):
        return (v[0] - u[0]) * (q[..., 1] - u[1]) - (v[1] - u[1]) * (q[..., 0] - u[0])

    inside = (side(a, b, p) >= 0) & (side(b, c, p) >= 0) & (side(c, a, p) >= 0)
    assert np.array_equal(g.coverage, inside)


@pytest.mark.parametrize("ortho", [False, True])
def test_zbuffer_matches_reference_on_random_triangles(rng, ortho):
    v = rng.normal(size=(60, 3)) * 0.7
    f = rng.integers(0, 60, size=(40, 3))
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    mesh = TriangleMesh(v, f)
    cam = Camera((0.4, 0.3, 3.0), (0, 0, 0), width=56, height=44, fov=None if ortho else 50, ortho=3.0 if ortho else None)
    g = gbuffer_of([mesh], cam)
    depth, face, _ = triangles_reference(mesh.vertices, mesh.faces, cam)
    assert np.array_equal(g.coverage, face >= 0)
    assert np.abs(g.depth[face >= 0] - depth[face >= 0]).max() < 1e-9


def test_perspective_correct_vertex_colour_interpolation():
    # a tilted quad: screen-space (affine) interpolation would be visibly wrong
    v = np.array([[-1, -1, 0.0], [1, -1, 0], [1, 1, -3], [-1, 1, -3]])
    colors = np.array([[1.0, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 1]])
    mesh = TriangleMesh(v, QUAD_F, vertex_colors=colors)
    cam = Camera((0, 0.5, 3), (0, -0.3, -1), width=48, height=48, fov=60)
    g = gbuffer_of([mesh], cam)
    depth, face, bary = triangles_reference(mesh.vertices, mesh.faces, cam)
    m = face >= 0
    expected = np.einsum("hwk,hwkc->hwc", bary, colors[mesh.faces[np.where(m, face, 0)]])
    assert np.array_equal(g.coverage, m)
    assert np.abs(g.albedo[m] - expected[m]).max() < 1e-9
    # the world point halfway in z (z = -1.5) has blue fraction 0.5 (colour linear in z along the quad)
    o, d = cam.rays()
    p = o + (depth / (d @ cam.forward))[..., None] * d
    blue = g.albedo[..., 2]
    assert np.allclose(blue[m], (-p[..., 2] / 3.0)[m], atol=1e-9)


def test_texture_origin_is_bottom_left_and_filtering_is_bilinear():
    tex = np.zeros((2, 2, 3))
    tex[1, 0] = [1, 0, 0]  # bottom-left texel (row 1 = bottom) red
    tex[0, 0] = [0, 1, 0]  # top-left green
    tex[0, 1] = [0, 0, 1]  # top-right blue
    tex[1, 1] = [1, 1, 1]  # bottom-right white
    quad = TriangleMesh(QUAD_V, QUAD_F, uv=QUAD_UV, texture=tex)
    cam = Camera((0, 0, 5), (0, 0, 0), width=40, height=40, ortho=2.0)
    g = gbuffer_of([quad], cam)
    assert np.allclose(g.albedo[39, 0], [1, 0, 0], atol=0.06)  # image bottom-left = texture bottom-left
    assert np.allclose(g.albedo[0, 0], [0, 1, 0], atol=0.06)
    assert np.allclose(g.albedo[0, 39], [0, 0, 1], atol=0.06)
    assert np.allclose(g.albedo[39, 39], [1, 1, 1], atol=0.06)
    # bilinear between the texel centres (u = 0.25 .. 0.75): linear along a row
    o, _ = cam.rays()
    u = (o[20, :, 0] + 1) / 2
    mid = (u > 0.25) & (u < 0.75)
    v = (o[20, 0, 1] + 1) / 2
    fy = (1 - v) * 2 - 0.5  # texel-space row coordinate
    top = (1 - (u * 2 - 0.5))[:, None] * tex[0, 0] + (u * 2 - 0.5)[:, None] * tex[0, 1]
    bottom = (1 - (u * 2 - 0.5))[:, None] * tex[1, 0] + (u * 2 - 0.5)[:, None] * tex[1, 1]
    expected = (1 - fy) * top + fy * bottom
    assert np.allclose(g.albedo[20, mid], expected[mid], atol=1e-9)


def test_normal_map_tilts_normals_along_tangent():
    flat = np.tile([0.5, 0.5, 1.0], (4, 4, 1))
    tilted = np.tile([0.5 + 0.5 * np.sin(0.5), 0.5, 0.5 + 0.5 * np.cos(0.5)], (4, 4, 1))
    cam = Camera((0, 0, 5), (0, 0, 0), width=16, height=16, ortho=1.5)
    g0 = gbuffer_of([TriangleMesh(QUAD_V, QUAD_F, uv=QUAD_UV, normal_map=flat)], cam)
    assert np.allclose(g0.normal[g0.coverage], [0, 0, 1], atol=1e-6)
    g1 = gbuffer_of([TriangleMesh(QUAD_V, QUAD_F, uv=QUAD_UV, normal_map=tilted)], cam)
    assert np.allclose(g1.normal[g1.coverage], [np.sin(0.5), 0, np.cos(0.5)], atol=2e-3)  # +u is world +x


def test_crease_angle_keeps_box_faces_flat():
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                  [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    box = TriangleMesh(v, f)
    cam = Camera((0, 0, 6), (0, 0, 0), width=32, height=32, ortho=3.0)
    g = gbuffer_of([box], cam)
    assert np.allclose(np.abs(g.normal[g.coverage]), [0, 0, 1], atol=1e-9)


def test_near_plane_and_mixed_scene_occlusion():
    big = TriangleMesh([[-50, -1, 10], [50, -1, 10], [0, -1, -50]], [[0, 1, 2]])  # reaches behind the eye
    cam = Camera((0, 0, 0), (0, 0, -1), width=32, height=32, fov=90)
    g = gbuffer_of([big], cam)
    assert g.coverage[20:].any() and not g.coverage[:15].any()
    assert np.all(g.depth[g.coverage] > cam.near_distance)
    # a mesh in front hides surfels behind it, surfels in front of a mesh show
    from unmesh import SurfelCloud

    wall = TriangleMesh(np.array(QUAD_V) * 0.5 + [0, 0, 0.5], QUAD_F, vertex_colors=[[1.0, 0, 0]] * 4)
    surf = SurfelCloud([[0, 0, 0], [0.8, 0, 1.0]], [[0, 0, 1]] * 2, radii=[1.0, 0.2], colors=[[0, 1.0, 0], [0, 0, 1.0]])
    res = render([wall, surf], Camera((0, 0, 5), (0, 0, 0), width=40, height=40, ortho=3.0), shading="none")
    assert np.allclose(res.color[20, 20], [1, 0, 0])  # wall in front of the big surfel
    assert np.allclose(res.color[20, 30], [0, 0, 1], atol=1e-6)  # small surfel in front of everything
    assert np.allclose(res.color[20, 27], [0, 1, 0], atol=1e-6)  # big surfel beside the wall


def test_empty_and_degenerate_meshes():
    cam = Camera((0, 0, 5), (0, 0, 0), width=16, height=16)
    g = gbuffer_of([TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int))], cam)
    assert not g.coverage.any()
    flat = TriangleMesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]])  # zero area
    g = gbuffer_of([flat], cam)
    assert not g.coverage.any()
    edge_on = TriangleMesh([[0, -1, -1], [0, 1, -1], [0, 0, 1]], [[0, 1, 2]])
    res = render(edge_on, cam)
    assert np.all(np.isfinite(res.color))


def _checker_plane(n=64):
    """A 10 x 10 plane y = 0 with an n x n checkerboard texture (n / 8 texels per square)."""
    idx = np.arange(n) // 8
    tex = np.repeat(((idx[:, None] + idx[None, :]) % 2).astype(float)[..., None], 3, axis=2)
    v = [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]]
    return TriangleMesh(v, QUAD_F, uv=QUAD_UV, texture=tex)


def test_trilinear_lookup_at_grazing_angle_is_closer_to_supersampling_than_bilinear():
    plane = _checker_plane()
    eye, target = (0, 0.35, 5.5), (0, 0, -2)
    cam = Camera(eye, target, width=48, height=48, fov=50)
    ss = 8
    g_ref = GBuffer.empty(48 * ss, 48 * ss)
    draw_meshes(g_ref, [plane], Camera(eye, target, width=48 * ss, height=48 * ss, fov=50), texture_filter="bilinear")
    ref = g_ref.albedo.reshape(48, ss, 48, ss, 3).mean(axis=(1, 3))
    cov = g_ref.coverage.reshape(48, ss, 48, ss).all(axis=(1, 3))
    errors = {}
    for mode in ("bilinear", "trilinear"):
        g = GBuffer.empty(48, 48)
        draw_meshes(g, [plane], cam, texture_filter=mode)
        m = cov & g.coverage
        errors[mode] = np.sqrt(np.mean((g.albedo[m] - ref[m]) ** 2))
    assert errors["trilinear"] < 0.6 * errors["bilinear"], errors
    # where the texture is magnified (near the eye) both lookups are the same bilinear one
    near = GBuffer.empty(48, 48)
    draw_meshes(near, [plane], Camera((0, 6, 0.1), (0, 0, 0), width=48, height=48, fov=40), texture_filter="bilinear")
    near_t = GBuffer.empty(48, 48)
    draw_meshes(near_t, [plane], Camera((0, 6, 0.1), (0, 0, 0), width=48, height=48, fov=40))
    assert np.array_equal(near.albedo, near_t.albedo)


def test_texture_levels_have_mip_variances_and_keep_regions_apart():
    from unmesh.render.raster import REGION_LEVELS, texture_levels

    img = np.zeros((64, 64, 1))
    img[32, 32] = 1.0  # an impulse: level k is the filter's impulse response
    lv = texture_levels(img, regions=np.zeros((64, 64), int), count=4)
    x = np.mgrid[0:64, 0:64][1]
    for k in range(4):
        w = lv[k][:, :, 0]
        assert np.isclose(w.sum(), 1.0)
        var = (w * (x - 32) ** 2).sum()
        assert np.isclose(var, (4**k - 1) / 12)  # the variance of a box of 2^k texels beyond level 0
    reg = (x >= 20).astype(int)
    img2 = np.where(reg[..., None] == 1, 1.0, 0.25)
    lv2 = texture_levels(img2, regions=reg)
    assert len(lv2) == REGION_LEVELS and all(v.shape == img2.shape for v in lv2)
    assert all(np.allclose(v[reg == 1], 1.0) and np.allclose(v[reg == 0], 0.25) for v in lv2)  # constant per region
    # without regions: the mip pyramid of 2 x 2 means down to one texel
    rng = np.random.default_rng(3)
    img3 = rng.random((12, 5, 3))
    pyr = texture_levels(img3)
    assert [p.shape[:2] for p in pyr] == [(12, 5), (6, 3), (3, 2), (2, 1), (1, 1)]
    assert np.allclose(pyr[1][1, 0], img3[2:4, 0:2].mean(axis=(0, 1)))
    assert np.allclose(pyr[1][1, 2], img3[2:4, 4].mean(axis=0))  # the odd last column repeated


def test_texture_level_kernel_matches_reference(rng):
    from unmesh.render._raster_kernels import texture_level
    from unmesh.render.raster import texture_level_reference

    prev = rng.random((23, 17, 3))
    regions = rng.integers(-1, 3, size=(23, 17))
    for s in (1, 2, 8):
        out = np.empty_like(prev)
        texture_level(prev, regions, s, out)
        assert np.allclose(out, texture_level_reference(prev, regions, s), atol=1e-14)
