"""Context geometry (floors, boxes, polygons): exact ray casting against brute force and the
triangle rasteriser, compositing of translucent objects, the grid and the contact shadow."""

import numpy as np
import pytest

from unmesh import SurfelCloud
from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.render import Box, Camera, Floor, Polygon, render
from unmesh.render.context import context_hits


def _brute_box_t(o, d, lo, hi, n=4000, tmax=10.0):
    """First ray parameter inside the box by marching (inf when missed)."""
    ts = np.linspace(0, tmax, n)
    x = o + ts[:, None] * d
    inside = np.all((x >= lo) & (x <= hi), axis=1)
    return ts[np.argmax(inside)] if inside.any() else np.inf


def test_box_hit_matches_ray_marching():
    rng = np.random.default_rng(3)
    box = Box((-0.4, -0.2, -0.3), (0.5, 0.6, 0.2))
    o = rng.uniform(-3, 3, (200, 3))
    o[:, 2] = 3.0
    target = rng.uniform(-0.7, 0.7, (200, 3))
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, normal, _, _ = box.hit(o[None], d[None])
    ref = np.array([_brute_box_t(a, b, box.lo, box.hi) for a, b in zip(o, d, strict=True)])
    hit = np.isfinite(ref)
    assert hit.sum() > 40 and (~hit).sum() > 20
    assert np.array_equal(np.isfinite(t[0]), hit)
    assert np.allclose(t[0][hit], ref[hit], atol=10.0 / 4000 + 1e-9)
    # the normal is the outward normal of the face hit: its axis is where the hit point is on the box surface
    x = o[hit] + t[0][hit][:, None] * d[hit]
    n = normal[0][hit]
    on_face = np.where(n.sum(axis=1) > 0, x[np.arange(len(x)), np.abs(n).argmax(1)] - box.hi[np.abs(n).argmax(1)],
                       x[np.arange(len(x)), np.abs(n).argmax(1)] - box.lo[np.abs(n).argmax(1)])
    assert np.allclose(on_face, 0.0, atol=1e-9)


def test_box_depth_head_on_is_analytic():
    cam = Camera((0, 0, 5), (0, 0, 0), width=16, height=16, ortho=4.0)
    res = render(Box((-1, -1, -1), (1, 1, 0.5), color=(1, 0, 0)), cam, shading="none")
    assert res.depth[8, 8] == pytest.approx(4.5)
    assert res.color[8, 8].tolist() == [1.0, 0.0, 0.0]
    assert res.coverage.sum() == 8 * 8  # a 2x2 square on a 4-wide, 16-pixel image


def test_polygon_matches_the_triangle_rasteriser():
    quad = np.array([[-0.8, -0.5, 0.2], [0.7, -0.6, -0.3], [0.6, 0.7, -0.1], [-0.7, 0.5, 0.3]])
    quad[3] = quad[0] + quad[2] - quad[1]  # planar
    cam = Camera((0.3, 0.4, 3), (0, 0, 0), width=96, height=80, fov=40)
    poly = render(Polygon(quad, edge=0), cam, shading="none")
    mesh = render(TriangleMesh(quad, [[0, 1, 2], [0, 2, 3]]), cam, shading="none")
    inter = (poly.coverage & mesh.coverage).sum()
    union = (poly.coverage | mesh.coverage).sum()
    assert inter / union > 0.98
    both = poly.coverage & mesh.coverage
    assert np.allclose(poly.depth[both], mesh.depth[both], rtol=1e-6)


def test_opaque_context_is_z_buffered_with_meshes_and_splats():
    cam = Camera((0, 0, 5), (0, 0, 0), width=32, height=32, ortho=2.0)
    wall = Box((-2, -2, -0.1), (2, 2, 0.1), color=(0, 0, 1))

    def quad(z):
        return TriangleMesh([[-0.3, -0.3, z], [0.3, -0.3, z], [0.3, 0.3, z], [-0.3, 0.3, z]], [[0, 1, 2], [0, 2, 3]],
                            vertex_colors=np.tile([1.0, 0.0, 0.0], (4, 1)))

    def surfel(z):
        return SurfelCloud([[0, 0, z]], [[0, 0, 1]], radii=[0.3], colors=[[1, 0, 0]])

    for make in (quad, surfel):
        assert render([wall, make(1.0)], cam, shading="none").color[16, 16].tolist() == [1.0, 0.0, 0.0]
        assert render([wall, make(-1.0)], cam, shading="none").color[16, 16].tolist() == [0.0, 0.0, 1.0]


def test_translucent_context_blends_over_what_is_behind():
    cam = Camera((0, 0, 5), (0, 0, 0), width=32, height=32, ortho=2.0)
    red = Box((-0.5, -0.5, -1), (0.5, 0.5, -0.5), color=(1, 0, 0))
    glass = Polygon([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], color=(0, 0, 1), opacity=0.25, edge=0)
    res = render([glass, red], cam, shading="none", background=(1, 1, 1))
    assert np.allclose(res.color[16, 16], [0.75, 0.0, 0.25])  # over the red box
    assert np.allclose(res.color[1, 1], [0.75, 0.75, 1.0])  # over the white background
    assert res.depth[16, 16] == pytest.approx(5.5)  # the box's depth is kept
    # behind an opaque object the glass is not drawn
    near = Box((-0.2, -0.2, 1), (0.2, 0.2, 1.2), color=(0, 1, 0))
    assert render([glass, near], cam, shading="none").color[16, 16].tolist() == [0.0, 1.0, 0.0]


def test_floor_grid_lines_sit_on_multiples_of_the_spacing():
    cam = Camera((0.05, 5, 0.05), (0.05, 0, 0.0501), width=100, height=100, ortho=2.0)  # from above
    floor = Floor(grid=0.5, extent=5)
    res = render(floor, cam, shading="none")
    ref = render(Floor(grid=None, extent=5), cam, shading="none")
    dark = (res.color < ref.color - 0.05).any(axis=-1)
    origins, _ = cam.rays()
    x = origins[..., 0]
    on_line = np.abs(x / 0.5 - np.round(x / 0.5)) * 0.5 < 0.5 * 2.0 / 100
    assert dark[on_line[:, :]].mean() > 0.9 or dark.any(axis=0)[on_line.any(axis=0)].all()
    far = np.abs(x / 0.5 - np.round(x / 0.5)) * 0.5 > 3 * 2.0 / 100
    z = origins[..., 2]
    far &= np.abs(z / 0.5 - np.round(z / 0.5)) * 0.5 > 3 * 2.0 / 100
    assert not dark[far].any()
    assert res.depth[50, 50] == pytest.approx(5.0)


def test_floor_contact_shadow_darkens_below_the_casters_and_fades_with_height():
    cam = Camera((0, 5, 0.001), (0, 0, 0), width=64, height=64, ortho=4.0)
    rng = np.random.default_rng(0)
    blob = rng.uniform(-0.3, 0.3, (2000, 3))
    low = render(Floor(grid=None, extent=3, casters=blob + np.array([0, 0.35, 0])), cam, shading="none").color[..., 0]
    high = render(Floor(grid=None, extent=3, casters=blob + np.array([0, 3.0, 0])), cam, shading="none").color[..., 0]
    plain = render(Floor(grid=None, extent=3), cam, shading="none").color[..., 0]
    assert low[32, 32] < plain[32, 32] - 0.2  # dark below the blob
    assert np.allclose(low[2, 2], plain[2, 2])  # far from it: untouched
    assert low[32, 32] < high[32, 32] <= plain[32, 32]


def test_context_hits_are_cached_per_camera_and_read_only():
    cam = Camera((0, 1, 3), (0, 0, 0), width=16, height=12)
    a = context_hits(Box((0, 0, 0), (1, 1, 1)), cam)
    b = context_hits(Box((0, 0, 0), (1, 1, 1)), cam)
    assert a[0] is b[0] and not a[0].flags.writeable


@pytest.mark.parametrize("make, match", [
    (lambda: Box((0, 0, 0), (1, -1, 1)), "hi"),
    (lambda: Box((0, 0, 0), (1, 1, 1), opacity=0), "opacity"),
    (lambda: Polygon([[0, 0, 0], [1, 0, 0], [2, 0, 0]]), "vertices"),
    (lambda: Polygon([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]]), "plane"),
    (lambda: Floor(normal=(0, 0, 0)), "normal"),
    (lambda: Floor(grid=-1), "grid"),
    (lambda: Floor(color=(2, 0, 0)), "color"),
])
def test_bad_input_names_the_argument(make, match):
    with pytest.raises(InputError, match=match):
        make()
