"""EWA splatting: numba kernels vs the numpy reference, quality against the analytic sphere,
partial updates, clipping and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import SurfelCloud
from unmesh.render import Camera, ClipPlanes, SplatOptions, SplatRenderer, render
from unmesh.render._reference import splat_reference
from unmesh.render.splat import surfel_arrays

from .conftest import fibonacci_sphere

CAMERAS = {
    "perspective": Camera((0.3, 0.2, 3), (0, 0, 0), width=48, height=40, fov=50),
    "ortho": Camera((0.3, 0.2, 3), (0, 0, 0), width=48, height=40, ortho=2.5),
    "close": Camera((0.1, 0.05, 0.2), (0, 0, -1), width=48, height=40, fov=80),
}


def random_cloud(rng, n=60, elliptical=False):
    pos = rng.normal(size=(n, 3)) * 0.5
    nrm = rng.normal(size=(n, 3))
    col = rng.random((n, 3))
    if elliptical:
        axes = rng.normal(size=(n, 2, 3)) * rng.uniform(0.05, 0.3, (n, 2, 1))
        return SurfelCloud(pos, nrm, axes=axes, colors=col)
    return SurfelCloud(pos, nrm, radii=rng.uniform(0.05, 0.4, n), colors=col)


def compare(renderer, ref, cam, tol):
    assert np.array_equal(np.isfinite(ref["zvis"]), np.isfinite(renderer.zvis))
    fin = np.isfinite(ref["zvis"])
    assert np.abs(ref["zvis"][fin] - renderer.zvis[fin]).max() < tol
    assert np.array_equal(ref["count"], renderer.count)
    for key in ("sum_weight", "sum_depth", "sum_color"):
        assert np.abs(ref[key] - getattr(renderer, key)).max() < tol, key
    world = renderer.sum_normal @ cam.rotation  # accumulated in camera space
    assert np.abs(ref["sum_normal"] - world).max() < tol


@pytest.mark.parametrize("camname", list(CAMERAS))
@pytest.mark.parametrize("elliptical", [False, True])
@pytest.mark.parametrize("seed", [0, 1])
def test_kernels_match_numpy_reference(camname, elliptical, seed):
    cam = CAMERAS[camname]
    cloud = random_cloud(np.random.default_rng(seed), elliptical=elliptical)
    r = SplatRenderer(cam, SplatOptions(precision="double", tile=16)).render(cloud)
    a = surfel_arrays(cloud)
    ref = splat_reference(a.positions, a.normals, cloud.tangent_axes(), a.colors, cam)
    compare(r, ref, cam, 1e-9)


def test_single_precision_parameters_agree_with_double(rng):
    cam = CAMERAS["perspective"]
    cloud = fibonacci_sphere(3000)
    g64 = SplatRenderer(cam, SplatOptions(precision="double")).render(cloud).gbuffer()
    g32 = SplatRenderer(cam, SplatOptions(precision="single")).render(cloud).gbuffer()
    both = g64.coverage & g32.coverage
    assert (g64.coverage != g32.coverage).sum() <= 2
    assert np.abs(g64.depth[both] - g32.depth[both]).max() < 1e-5
    assert np.abs(g64.albedo[both] - g32.albedo[both]).max() < 1e-5


def test_filter_and_tolerance_options_reach_the_kernels(rng):
    cam = CAMERAS["perspective"]
    cloud = random_cloud(rng)
    opts = SplatOptions(kappa=1.0, filter_radius=2.0, depth_tolerance=0.3, precision="double", tile=8)
    r = SplatRenderer(cam, opts).render(cloud)
    a = surfel_arrays(cloud)
    ref = splat_reference(a.positions, a.normals, cloud.tangent_axes(), a.colors, cam, kappa=1.0,
                          filter_radius=2.0, depth_tolerance=0.3)
    compare(r, ref, cam, 1e-9)


# -- quality against the analytic sphere ------------------------------------------------------
@pytest.fixture(scope="module")
def ortho_sphere(sphere20k):
    cam = Camera((0, 0, 5), (0, 0, 0), width=512, height=512, ortho=2.4)
    res = render(sphere20k, cam, shading="none")
    o, _ = cam.rays()
    x, y = o[..., 0], o[..., 1]
    return res, x, y


def test_coverage_equals_analytic_disc(ortho_sphere):
    res, x, y = ortho_sphere
    disc = x * x + y * y <= 1.0
    iou = (res.coverage & disc).sum() / (res.coverage | disc).sum()
    assert iou >= 0.99


def test_normals_match_analytic_sphere(ortho_sphere):
    res, x, y = ortho_sphere
    mask = (x * x + y * y <= 1.0) & res.coverage
    nz = np.sqrt(np.clip(1 - x * x - y * y, 0, None))
    truth = np.stack([x, y, nz], -1)
    ang = np.degrees(np.arccos(np.clip(np.sum(res.normal * truth, -1), -1, 1)))
    assert ang[mask].mean() <= 2.0
    assert np.allclose(np.linalg.norm(res.normal[res.coverage], axis=1), 1.0)
    assert np.all(res.normal[~res.coverage] == 0)


def test_depth_within_one_percent_of_radius(ortho_sphere):
    res, x, y = ortho_sphere
    mask = (x * x + y * y <= 1.0) & res.coverage
    truth = 5.0 - np.sqrt(np.clip(1 - x * x - y * y, 0, None))
    err = np.abs(res.depth - truth)[mask]
    assert err.mean() <= 0.01
    assert np.percentile(err, 99) <= 0.01
    assert np.all(np.isinf(res.depth[~res.coverage]))


def test_constant_colour_is_reproduced_exactly_without_shading(ortho_sphere):
    res, _, _ = ortho_sphere
    err = np.abs(res.color[res.coverage] - [0.2, 0.6, 0.4]).max()
    assert err <= 1.0 / 255.0
    assert np.all(res.color[~res.coverage] == 1.0)


@pytest.mark.parametrize("center", [(0.3, 0.2), (-0.6, 0.1), (0.0, -0.85)])
def test_no_holes_at_eight_times_magnification(sphere20k, center):
    cam = Camera((center[0], center[1], 5), (center[0], center[1], 0), width=200, height=200, ortho=2.4 / 8)
    res = render(sphere20k, cam, shading="none")
    o, _ = cam.rays()
    inside = o[..., 0] ** 2 + o[..., 1] ** 2 < 1.0
    assert inside.any()
    assert not np.any(inside & ~res.coverage)


def test_perspective_close_up_has_no_holes(sphere5k):
    cam = Camera((0.0, 0.0, 1.3), (0, 0, 0), width=160, height=120, fov=40)
    res = render(sphere5k, cam)
    assert res.coverage.all()


def test_minified_sphere_keeps_its_area_and_colour():
    """Far away, many surfels fall in each pixel: the screen-space filter keeps every one
    visible and colours average instead of aliasing."""
    cloud = fibonacci_sphere(20000)
    red = np.random.default_rng(7).random(20000) < 0.5
    col = np.where(red[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    cloud = cloud.replace(colors=col)
    cam = Camera((0, 0, 5), (0, 0, 0), width=24, height=24, ortho=2.4)
    res = render(cloud, cam, shading="none")
    o, _ = cam.rays()
    dist = np.hypot(o[..., 0], o[..., 1]) * 10.0  # in pixels (radius 10 px)
    assert res.coverage[dist < 10.0 - 0.5].all()  # no holes
    assert not res.coverage[dist > 10.0 + 1.0].any()  # grown by at most the filter radius (1 px)
    inner = dist < 8.0
    # randomly red or blue surfels (about 0.2 px each): every interior pixel is a blend of many
    # (point sampling would give pure red or blue pixels, and holes)
    red_fraction = res.color[inner][:, 0]
    assert np.all(np.abs(red_fraction - 0.5) < 0.3)
    assert abs(red_fraction.mean() - red.mean()) < 0.05
    assert np.all(np.abs(res.color[inner][:, 0] + res.color[inner][:, 2] - 1.0) < 1e-9)
    point = render(cloud, cam, shading="none", splat=SplatOptions(filter_radius=0.0))
    point_red = point.color[inner][:, 0]  # without the EWA prefilter: only the few discs on the ray
    assert point_red.std() > 2 * red_fraction.std()


def test_depth_test_separates_front_and_back(sphere5k):
    # looking along -z, back-facing surfels of the far hemisphere must not show
    cam = Camera((0, 0, 5), (0, 0, 0), width=64, height=64, ortho=2.4)
    front = sphere5k.subset(sphere5k.normals[:, 2] > 0)
    back = sphere5k.subset(sphere5k.normals[:, 2] <= 0).replace(colors=np.tile([1.0, 0, 0], (int((sphere5k.normals[:, 2] <= 0).sum()), 1)))
    res = render([front, back], cam, shading="none")
    o, _ = cam.rays()
    inner = o[..., 0] ** 2 + o[..., 1] ** 2 < 0.9**2
    assert np.abs(res.color[inner] - [0.2, 0.6, 0.4]).max() < 1e-6  # colours travel in float32


# -- partial updates (5.7) ------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_partial_updates_equal_full_rerender(seed):
    rng = np.random.default_rng(seed)
    base = fibonacci_sphere(3000)
    n = len(base)
    col = rng.random((n, 3))
    base = base.replace(colors=col)
    cam = Camera((0.4, 0.3, 3), (0, 0, 0), width=96, height=80, fov=45)
    present = np.ones(n, dtype=bool)
    present[rng.choice(n, 300, replace=False)] = False
    r = SplatRenderer(cam).render(base.subset(present))
    for _ in range(6):
        on = np.flatnonzero(present)
        off = np.flatnonzero(~present)
        remove = rng.choice(on, 150, replace=False)
        add = rng.choice(off, min(120, len(off)), replace=False)
        r.unsplat(base.subset(remove))
        present[remove] = False
        r.splat(base.subset(add))
        present[add] = True
    full = SplatRenderer(cam).render(base.subset(present))
    same = full.zvis == r.zvis
    assert same.mean() > 0.5
    ga, gb = r.gbuffer(), full.gbuffer()
    assert np.array_equal(ga.coverage[same], gb.coverage[same])
    m = same & gb.coverage
    assert np.abs(ga.albedo[m] - gb.albedo[m]).max() <= 1e-6
    assert np.abs(ga.normal[m] - gb.normal[m]).max() <= 1e-6
    assert np.abs(ga.depth[m] - gb.depth[m]).max() <= 1e-6
    assert np.abs(ga.weight[m] - gb.weight[m]).max() <= 1e-6


def test_recolouring_by_unsplat_and_splat_is_exact(sphere5k):
    cam = Camera((0, 0, 3), (0, 0, 0), width=64, height=64, fov=45)
    r = SplatRenderer(cam).render(sphere5k)
    sel = np.flatnonzero(sphere5k.positions[:, 0] > 0.3)
    painted = sphere5k.replace(colors=np.where((sphere5k.positions[:, 0] > 0.3)[:, None], [1.0, 0, 0], sphere5k.colors))
    r.unsplat(sphere5k.subset(sel)).splat(painted.subset(sel))
    full = SplatRenderer(cam).render(painted)
    assert np.array_equal(r.zvis, full.zvis)  # recolouring never changes visibility
    ga, gb = r.gbuffer(), full.gbuffer()
    assert np.array_equal(ga.coverage, gb.coverage)
    assert np.abs(ga.albedo - gb.albedo).max() <= 1e-6


def test_unsplat_everything_returns_to_exact_zero(sphere5k):
    cam = Camera((0, 0, 3), (0, 0, 0), width=48, height=48, fov=45)
    r = SplatRenderer(cam).render(sphere5k)
    r.unsplat(sphere5k)
    assert not r.count.any() and not r.sum_weight.any() and not r.sum_color.any()
    assert not r.gbuffer().coverage.any()


def test_full_update_into_reused_buffers_equals_a_fresh_renderer():
    """A full update does not clear the sums first: it overwrites the tiles it splats into and
    zeroes the others that held values (per-tile flags). Re-rendering other surfels, after a
    full update and after partial ones, into the same renderer, and render() after render() in
    one thread, give bit for bit what a fresh renderer gives."""
    cam = Camera((0.3, 0.2, 3), (0, 0, 0), width=96, height=80, fov=45)
    sphere = fibonacci_sphere(3000)
    left, right = sphere.subset(sphere.positions[:, 0] < -0.2), sphere.subset(sphere.positions[:, 0] > 0.4)
    keys = ("zvis", "sum_weight", "sum_color", "sum_normal", "sum_depth", "count")
    fresh = SplatRenderer(cam).render(right)
    r = SplatRenderer(cam).render(sphere)
    r.render(right)
    assert all(np.array_equal(getattr(r, k), getattr(fresh, k)) for k in keys)
    r.render(left).splat(right).unsplat(left.subset(np.arange(0, len(left), 2)))
    r.render(right)
    assert all(np.array_equal(getattr(r, k), getattr(fresh, k)) for k in keys)
    r.render(SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0)))  # nothing splatted
    assert not r.count.any() and not r.sum_weight.any() and np.isinf(r.zvis).all()
    shared = SplatRenderer(cam)  # a new renderer splatting against another's visibility buffer
    shared.zvis = fresh.zvis
    shared.splat(right)
    assert shared.zvis is fresh.zvis
    assert all(np.array_equal(getattr(shared, k), getattr(fresh, k)) for k in keys)
    g = fresh.gbuffer()
    render(sphere, cam)
    res = render(right, cam, shading="none")
    for k in ("albedo", "normal", "depth", "coverage", "weight"):
        assert np.array_equal(getattr(res, k), getattr(g, k)), k


# -- clipping hook (chapter 4) ---------------------------------------------------------------
def test_clip_planes_cut_fragments():
    cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.8], colors=[[1, 0, 0]])
    cam = Camera((0, 0, 3), (0, 0, 0), width=64, height=64, ortho=2.0)
    full = SplatRenderer(cam).render(cloud).gbuffer()
    half = SplatRenderer(cam).render(cloud, clip=ClipPlanes([0, 1], [[1.0, 0, 0, 0]])).gbuffer()
    o, _ = cam.rays()
    x = o[..., 0]
    assert half.coverage[full.coverage & (x < -0.05)].all()
    assert not half.coverage[x > 0.05].any()
    quarter = SplatRenderer(cam).render(cloud, clip=ClipPlanes([0, 2], [[1.0, 0, 0, 0], [0, 1.0, 0, 0]])).gbuffer()
    y = o[..., 1]
    assert not quarter.coverage[(x > 0.05) | (y > 0.05)].any()
    union = SplatRenderer(cam).render(cloud, clip=ClipPlanes([0, 2], [[1.0, 0, 0, 0], [0, 1.0, 0, 0]], [1])).gbuffer()
    assert not union.coverage[(x > 0.05) & (y > 0.05)].any()
    assert union.coverage[full.coverage & (x < -0.05) & (y > 0.05)].all()


# -- bad and degenerate input -------------------------------------------------------------------
def test_empty_cloud_renders_background():
    empty = SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0))
    res = render(empty, Camera((0, 0, 3), (0, 0, 0), width=16, height=12), background=(0.1, 0.2, 0.3))
    assert np.allclose(res.color, [0.1, 0.2, 0.3])
    assert not res.coverage.any() and np.all(np.isinf(res.depth)) and not res.normal.any()
    res2 = render([], Camera((0, 0, 3), (0, 0, 0), width=8, height=8))
    assert np.all(res2.color == 1.0)


def test_tiny_surfels_stay_visible_and_do_not_crash():
    rng = np.random.default_rng(3)
    pos = rng.uniform(-1, 1, (200, 3))
    cloud = SurfelCloud(pos, rng.normal(size=(200, 3)), radii=np.full(200, 1e-30))
    cam = Camera((0, 0, 5), (0, 0, 0), width=64, height=64, ortho=2.5)
    res = render(cloud, cam)
    row, col, _ = cam.project(pos)
    assert res.coverage[np.floor(row).astype(int), np.floor(col).astype(int)].all()
    assert np.all(np.isfinite(res.color)) and np.all(np.isfinite(res.depth[res.coverage]))


def test_edge_on_surfels_do_not_crash_or_leave_holes():
    # a flat sheet seen exactly edge-on: only the screen filter draws it, as a line
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-1, 1, 41)), -1).reshape(-1, 2)
    sheet = SurfelCloud(np.c_[g[:, 0], np.zeros(len(g)), g[:, 1]], np.tile([0, 1.0, 0], (len(g), 1)),
                        radii=np.full(len(g), 0.05))
    cam = Camera((0, 0, 5), (0, 0, 0), width=64, height=64, ortho=2.5)
    res = render(sheet, cam)
    assert np.all(np.isfinite(res.color))
    cols = np.flatnonzero(res.coverage.any(axis=0))
    span = np.arange(cols.min(), cols.max() + 1)
    assert len(cols) == len(span)  # a continuous line, no gaps
    assert abs(np.mean(np.flatnonzero(res.coverage.any(axis=1))) - 31.5) < 1.0
    # sphere rims are edge-on too: the sphere must still be closed at its silhouette
    sph = render(fibonacci_sphere(5000), Camera((0, 0, 5), (0, 0, 0), width=128, height=128, ortho=2.4))
    o, _ = sph.camera.rays()
    inside = o[..., 0] ** 2 + o[..., 1] ** 2 < 0.99
    assert sph.coverage[inside].all()


def test_camera_inside_the_bounding_box(sphere5k):
    cam = Camera((0, 0, 0), (0, 0, -1), width=64, height=48, fov=90)
    res = render(sphere5k, cam)
    assert res.coverage.all()  # the inside of the sphere surrounds the camera
    assert np.allclose(res.depth[24, 32], 1.0, atol=0.01)
    assert np.all(np.isfinite(res.color))
    # surfels right at the eye are cut by the near plane, not drawn huge
    close = SurfelCloud([[0, 0, 0.0], [0, 0, -1.0]], [[0, 0, 1]] * 2, radii=[0.5, 0.5], colors=[[1, 0, 0], [0, 1, 0]])
    res2 = render(close, Camera((0, 0, 1e-4), (0, 0, -1), width=32, height=32, fov=60, near=1e-3), shading="none")
    assert np.allclose(res2.color[16, 16], [0, 1, 0])


def test_bad_options_raise():
    from unmesh.errors import InputError

    with pytest.raises(InputError):
        SplatOptions(tile=3)
    with pytest.raises(InputError):
        SplatOptions(precision="half")
    with pytest.raises(InputError):
        SplatRenderer("camera")  # type: ignore[arg-type]
    cam = Camera((0, 0, 3), (0, 0, 0), width=8, height=8)
    cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5])
    with pytest.raises(InputError):
        SplatRenderer(cam).render(cloud, clip=ClipPlanes([0, 0, 0], np.zeros((0, 4))))


def test_supersampling_antialiases_silhouettes(sphere5k):
    cam = Camera((0, 0, 5), (0, 0, 0), width=40, height=40, ortho=2.4)
    one = render(sphere5k, cam, shading="none")
    aa = render(sphere5k, cam, shading="none", supersample=3)
    assert aa.color.shape == (40, 40, 3) and aa.depth.shape == (40, 40)
    # interior pixels keep the colour; silhouette pixels blend surface and background
    assert np.allclose(aa.color[20, 20], [0.2, 0.6, 0.4], atol=1e-6)
    blended = aa.coverage & (np.abs(aa.color - [0.2, 0.6, 0.4]).max(-1) > 0.05)
    assert blended.sum() > 20 and not (one.coverage & (np.abs(one.color - [0.2, 0.6, 0.4]).max(-1) > 1e-5)).any()
    assert np.allclose(np.linalg.norm(aa.normal[aa.coverage], axis=-1), 1.0)
    assert np.all(np.isinf(aa.depth[~aa.coverage]))


def test_discontinuity_surfels_are_not_splatted():
    """Crack markers (attribute ``discontinuity`` == 1, thin shells 7.4) do not change the image."""
    from unmesh.render import Camera, render
    from unmesh.shapes import Sphere

    cloud = Sphere().surfels(0.1)
    n = len(cloud)
    marker = SurfelCloud([[0.0, 0.0, 1.5]], [[0.0, 0.0, 1.0]], radii=[0.3], colors=[[1.0, 0.0, 0.0]])
    flagged = SurfelCloud.concatenate([cloud.replace(attributes={"discontinuity": np.zeros(n)}),
                                       marker.replace(attributes={"discontinuity": np.ones(1)})])
    cam = Camera((0, 0, 4), (0, 0, 0), width=64, height=64, ortho=2.5)
    a = render(cloud, cam)
    b = render(flagged, cam)
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.depth, b.depth)


def test_backface_culling_drops_only_the_far_side():
    """``cull_backfaces``: a surfel facing away is not drawn; on a closed sphere the image is unchanged
    except at the silhouette, where the far side's splats no longer poke out."""
    from unmesh.render import Camera, render
    from unmesh.shapes import Sphere

    cam = Camera((0, 0, 3), (0, 0, 0), width=48, height=48, ortho=2.6)
    cull = SplatOptions(cull_backfaces=True)
    away = SurfelCloud([[0.0, 0.0, 0.0]], [[0.0, 0.0, -1.0]], radii=[0.5])
    assert render(away, cam).coverage.any() and not render(away, cam, splat=cull).coverage.any()
    ortho_tilted = SurfelCloud([[0.0, 0.0, 0.0]], [[0.0, 0.6, 0.8]], radii=[0.5])  # faces the camera
    assert render(ortho_tilted, cam, splat=cull).coverage.any()
    sphere = Sphere().surfels(0.08)
    a = render(sphere, cam, shading="none")
    b = render(sphere, cam, shading="none", splat=cull)
    inner = np.hypot(*np.meshgrid(np.arange(48) - 23.5, np.arange(48) - 23.5)) < 0.85 * 48 / 2.6
    np.testing.assert_allclose(a.color[inner], b.color[inner], atol=1e-6)
    assert b.coverage.sum() >= 0.98 * a.coverage.sum()
    persp = Camera((0, 0, 3), (0, 0, 0), width=48, height=48, fov=50)
    assert render(sphere, persp, splat=cull).coverage.sum() >= 0.98 * render(sphere, persp).coverage.sum()


def test_work_buffers_do_not_grow_when_precisions_alternate():
    """The thread's work buffers are kept per dtype: renderers of both precisions in turn (paint
    view and render() in one session) reuse them instead of growing them on every switch."""
    from unmesh.render import splat as splat_module

    cam = CAMERAS["perspective"]
    cloud = fibonacci_sphere(500)
    renderers = [SplatRenderer(cam, SplatOptions(precision=p)) for p in ("single", "double")]
    sizes = []
    for _ in range(6):
        for r in renderers:
            r.render(cloud)
        sizes.append(sum(b.nbytes for b in splat_module._SCRATCH.buffers.values()))
    assert sizes[-1] == sizes[1]


@pytest.mark.parametrize("tile", [16, 24])  # a power of two (shifts) and not (divisions)
def test_setup_and_fused_setup_bin_agree_with_binning_the_boxes(tile):
    from unmesh.render._kernels import bin_boxes
    from unmesh.render._splat_kernels import NPARAM, splat_setup, splat_setup_bin

    cam = CAMERAS["perspective"]
    cloud = random_cloud(np.random.default_rng(5), n=300, elliptical=True)
    a = surfel_arrays(cloud)
    f, cx, cy, ortho, near = cam.kernel_params()
    h, w = cam.shape
    n = len(a)
    out = []
    for fused in (False, True):
        P, box, group = np.empty((n, NPARAM)), np.empty((n, 4), np.int32), np.empty(n, np.int8)
        args = (a.positions, a.normals, a.radii, a.axes, True, a.colors, cam.rotation, cam.eye, f, cx, cy, ortho, near,
                w, h, 1.0, P, box, group)
        if fused:
            ntx, nty = (w + tile - 1) // tile, (h + tile - 1) // tile
            offsets, items, _ = splat_setup_bin(*args, tile, ntx, nty, 3)
        else:
            splat_setup(*args)
        out.append((P, box, group))
    for x, y in zip(out[0], out[1], strict=True):
        assert np.array_equal(x, y, equal_nan=True)
    ref_offsets, ref_items = bin_boxes(out[0][1], out[0][2], 2, tile, ntx, nty, 3)
    assert np.array_equal(offsets, ref_offsets)
    assert np.array_equal(items, ref_items)
