"""Rendering (5.7): differential updates equal full re-renders where the depth is unchanged."""

import numpy as np
import pytest

from tests.paint.conftest import RED, ROUND, line
from unmesh.errors import InputError
from unmesh.paint import Brush, Paint, PaintOptions, Sample, Session
from unmesh.paint.session import _BRISTLE
from unmesh.paint.view import PaintView
from unmesh.render import Camera
from unmesh.shapes import by_name

CAM = Camera((0.3, 1.2, 0.8), (0, 0, 0), width=160, height=120, fov=40)


def _fresh(s, cam):
    v = PaintView(s.surface)
    s.surface.dirty.clear()
    r = v.update(cam, force_full=True)
    return r, v.result()


def test_differential_equals_full_where_depth_unchanged():
    s = Session(by_name("plane", size=1.0).surfels(0.02), PaintOptions(haptics=False))
    s.render(CAM)
    assert s.last_update == "full"
    s.stroke(line(n=2, x0=-0.05, x1=0.05), brush=ROUND, paint=Paint("oil", (0.9, 0.1, 0.1), relief="none"))
    s.stroke(line(n=1, z=0.1), brush=Brush("flat", 0.03), paint=Paint("watercolor", (0.1, 0.2, 0.9)))
    s.advance(0.5)
    diff = s.render(CAM, brush=False)
    assert s.last_update == "differential"
    zd = s._view.renderer.zvis.copy()
    full_r, full = _fresh(s, CAM)
    same = (zd == full_r.zvis) & full.coverage
    assert same.sum() > 0.8 * full.coverage.sum()
    np.testing.assert_allclose(diff.albedo[same], full.albedo[same], atol=1e-6)
    np.testing.assert_allclose(diff.color[same], full.color[same], atol=1e-6)
    # undo is a differential update too
    s.undo()
    diff = s.render(CAM, brush=False)
    full_r, full = _fresh(s, CAM)
    same = (s._view.renderer.zvis == full_r.zvis) & full.coverage
    np.testing.assert_allclose(diff.albedo[same], full.albedo[same], atol=1e-6)


def test_full_update_when_view_moves_or_lists_grow(session):
    s = session
    s.render(CAM)
    s.render(CAM)
    assert s.last_update == "differential"
    s.render(CAM.orbit(10))
    assert s.last_update == "full"
    # repainting the same region too often triggers a full update (the update counter)
    s._view.max_partial = 4
    kinds = []
    for k in range(8):
        s.stroke([Sample(0.0, (0.0, 0.0, 0.0), 0.3)], brush=Brush("pencil", 0.01), paint=RED)
        s.render(CAM.orbit(10), brush=False)
        kinds.append(s.last_update)
        if k > 3 and kinds[-1] == "full":
            break
    assert "full" in kinds[1:]


def test_pick_hits_the_surface(session):
    cam = Camera((0, 2.0, 0), (0, 0, 0), up=(0, 0, -1), width=100, height=100, ortho=1.0)
    p = session.pick(cam, 50.5, 50.5)
    np.testing.assert_allclose(p, [0.005, 0.0, 0.005], atol=1e-9)
    assert session.pick(cam, -3, 5) is None
    far = Camera((0, 2.0, 0), (0, 0, 0), up=(0, 0, -1), width=100, height=100, ortho=4.0)
    assert session.pick(far, 2, 2) is None  # background


def test_brush_is_drawn(session):
    sid = session.begin_stroke(ROUND, RED)
    session.add_samples(sid, line(n=3))
    with_brush = session.render(CAM)
    without = session.render(CAM, brush=False)
    session.end_stroke(sid)
    assert np.abs(with_brush.color - without.color).max() > 0.1


def _composed(view, brush):
    """Reference composition: whole-image copies of the object image with the brush drawn in."""
    from unmesh.paint.view import _draw_brush

    g = view._g
    color, depth, cov = view._color.copy(), g.depth.copy(), g.coverage.copy()
    np.copyto(depth, np.inf, where=~cov)
    if brush is not None:
        _draw_brush(g, color, depth, cov, view.camera, brush, view)
    return color, depth, cov


@pytest.fixture(scope="module")
def fine_plane():
    return by_name("plane", size=1.0).surfels(0.02)


def test_frame_composition_equals_whole_image_composition(fine_plane):
    """Dirty windows only: after paint events with a moving brush (and frames without it), every
    frame equals the composition of whole-image copies; a dropped result's buffers are reused."""
    s = Session(fine_plane, PaintOptions(haptics=False))
    s.render(CAM)
    sid = s.begin_stroke(ROUND, RED)
    bases, kinds = set(), []
    for k, smp in enumerate([*line(n=6, x0=-0.1, x1=0.1), None, None]):
        if smp is not None:
            s.add_samples(sid, [smp])
        drawn = k % 3 != 2 and k != 7  # the last frame: nothing repainted, the brush removed
        res = s.render(CAM, brush=drawn)
        assert not res.color.flags.writeable and not res.depth.flags.writeable
        b = s._last_brush
        pos, nrm = b.surfels()
        brush = (pos, nrm, np.where(b.vw[:, None] > 0, b.wet, _BRISTLE)) if drawn else None
        color, depth, cov = _composed(s._view, brush)
        assert np.array_equal(res.coverage, cov)
        assert np.array_equal(res.depth, depth)
        np.testing.assert_allclose(res.color, color, rtol=0, atol=1e-12)
        bases.add(id(res.color.base))
        kinds.append(s.last_update)
        del res
    s.end_stroke(sid)
    assert kinds.count("differential") >= 5
    assert len(bases) == 1  # nothing held: one set of buffers, windows rewritten in place


def test_kept_results_are_not_changed_by_later_frames(fine_plane):
    s = Session(fine_plane, PaintOptions(haptics=False))
    first = s.render(CAM, brush=False)
    keep = {k: np.array(getattr(first, k)) for k in ("color", "depth", "coverage", "albedo", "normal", "weight")}
    albedo_view = first.albedo[10:50]  # a view of a kept result's buffer keeps it too
    before = albedo_view.copy()
    sid = s.begin_stroke(ROUND, RED)
    s.add_samples(sid, line(n=2, x0=-0.03, x1=0.03))
    second = s.render(CAM)
    s.end_stroke(sid)
    assert s.last_update == "differential"
    assert np.abs(second.color - first.color).max() > 0.1
    for k, v in keep.items():
        assert np.array_equal(getattr(first, k), v), k
    del first
    s.stroke(line(n=2, z=0.1, x0=-0.03, x1=0.03), brush=ROUND, paint=RED)
    s.render(CAM, brush=False)
    assert s.last_update == "differential"
    assert np.array_equal(albedo_view, before)


def test_full_updates_reuse_free_buffers_and_keep_held_ones(fine_plane):
    """A full update resolves into the view's last G-buffer unless a caller holds a result of it;
    either way the image equals a fresh view's."""
    s = Session(fine_plane, PaintOptions(haptics=False))
    first = s.render(CAM, brush=False)
    keep = {k: np.array(getattr(first, k)) for k in ("color", "depth", "coverage", "albedo", "normal", "weight")}
    g_before = s._view._g
    s.stroke(line(n=2, x0=-0.03, x1=0.03), brush=ROUND, paint=RED)
    second = s.render(CAM.orbit(5), brush=False)  # a new camera: a full update
    assert s.last_update == "full"
    assert s._view._g is not g_before  # first's albedo, normal and weight are held
    for k, v in keep.items():
        assert np.array_equal(getattr(first, k), v), k
    del first, second
    g_free = s._view._g
    again = s.render(CAM, brush=False)
    assert s.last_update == "full" and s._view._g is g_free  # nothing held: reused
    _, fresh = _fresh(s, CAM)
    for k in ("color", "depth", "coverage", "albedo", "normal", "weight"):
        assert np.array_equal(getattr(again, k), getattr(fresh, k)), k


def test_shadow_map_against_brute_force():
    """A point is in the brush's shadow iff a brush surfel whose map cell is within 4 cells of
    the point's is above it (brute force over all pairs)."""
    from unmesh.paint.view import shadow_test

    rng = np.random.default_rng(3)
    rad = 0.05
    brush = np.column_stack([rng.normal(0, 0.2, (300, 2)), rng.uniform(0.0, 0.3, 300)])
    pts = np.column_stack([rng.uniform(-1, 1, (4000, 2)), rng.uniform(-0.1, 0.4, 4000)])
    got = shadow_test(brush, pts, rad)
    lo = brush[:, :2].min(axis=0) - 4.5 * 0.5 * rad
    cb = np.floor((brush[:, :2] - lo) / (0.5 * rad))
    cp = np.floor((pts[:, :2] - lo) / (0.5 * rad))
    near = ((cp[:, None, :] - cb[None, :, :]) ** 2).sum(axis=2) <= 16
    want = (near & (brush[None, :, 2] > pts[:, None, 2] + 1e-9)).any(axis=1)
    assert np.array_equal(got, want)
    assert 200 < want.sum() < 3800


def test_backface_culling_in_full_and_differential_updates():
    """A closed model splats only surfels facing the camera (full and differential alike), and
    the differential image still equals a full re-render; ``cull=False`` splats both sides."""
    sphere = by_name("sphere", radius=0.5).surfels(0.06)
    s = Session(sphere, PaintOptions(haptics=False))
    cam = Camera((0.4, 0.9, 1.4), (0, 0, 0), width=160, height=120, fov=40)

    def facing_rows():
        rows = s.surface.visible_rows()
        p, n = s.surface.pos[rows], s.surface.nrm[rows]
        return rows[np.einsum("ij,ij->i", n, cam.eye - p) > 0]  # brute force, not Camera.facing

    s.render(cam)
    assert s.last_update == "full" and s._view.last_count == len(facing_rows()) < 0.7 * len(s.surface.visible_rows())
    assert np.array_equal(np.flatnonzero(s._view._on[:s.surface.n]), np.sort(facing_rows()))
    top = tuple(0.5 * cam.eye / np.linalg.norm(cam.eye))  # the point of the sphere nearest the eye
    s.stroke([Sample(0.0, top, 0.7)], brush=ROUND, paint=RED)
    s.stroke([Sample(0.0, (0.0, -0.5, 0.0), 0.7)], brush=ROUND, paint=RED)  # on the far side: culled
    diff = s.render(cam, brush=False)
    assert s.last_update == "differential"
    assert np.array_equal(np.flatnonzero(s._view._on[:s.surface.n]), np.sort(facing_rows()))
    zd = s._view.renderer.zvis.copy()
    v = PaintView(s.surface)
    s.surface.dirty.clear()
    full_r = v.update(cam, force_full=True)
    full = v.result()
    same = (zd == full_r.zvis) & full.coverage
    assert same.sum() > 0.8 * full.coverage.sum()
    np.testing.assert_allclose(diff.color[same], full.color[same], atol=1e-6)
    assert (np.abs(diff.color - (0.9, 0.1, 0.1)).sum(axis=2) < 0.3).any()  # the front stroke shows
    s.render(cam, cull=False)
    assert s.last_update == "full" and s._view.last_count == len(s.surface.visible_rows())


def test_last_windows_cover_every_changed_pixel():
    s = Session(by_name("plane", size=1.0).surfels(0.015), PaintOptions(haptics=False))  # fine: no full updates
    first = np.array(s.render(CAM).color)
    assert s.last_windows is None  # a full update: anywhere
    serial = s.render_serial
    sid = s.begin_stroke(ROUND, RED)
    prev = first
    for i in range(4):
        s.add_samples(sid, [Sample(0.05 * i, (-0.1 + 0.06 * i, 0.0, 0.02), 0.7)])
        cur = np.array(s.render(CAM).color)  # differential, with the brush
        wins = s.last_windows
        assert wins is not None and s.render_serial == serial + i + 1
        outside = np.ones(cur.shape[:2], bool)
        for r0, r1, c0, c1 in wins:
            outside[r0:r1, c0:c1] = False
        assert outside.any() and (cur != prev).any()
        np.testing.assert_array_equal(cur[outside], prev[outside])
        prev = cur
    s.end_stroke(sid)


def test_preview_level_of_detail():
    """``preview`` with stride 1 is the full image; with stride 4 (a quarter of the surfels, radii
    doubled) it covers about the same pixels; the view's own buffers are not touched."""
    s = Session(by_name("sphere", radius=0.5).surfels(0.03), PaintOptions(haptics=False))
    s.stroke([Sample(0.0, (0.0, 0.5, 0.0), 0.7)], brush=ROUND, paint=RED)
    s.render(CAM)
    p1 = s.preview(CAM, 1)
    full = s.render(CAM, brush=False, full=True)
    np.testing.assert_allclose(p1.color, full.color, atol=1e-12)
    assert np.array_equal(p1.coverage, full.coverage)
    p4 = s.preview(CAM, 4)
    both = (p4.coverage & full.coverage).sum()
    assert both > 0.97 * full.coverage.sum() and p4.coverage.sum() < 1.05 * full.coverage.sum()
    s.render(CAM)
    assert s.last_update == "differential"  # the previews did not disturb the view
    with pytest.raises(InputError, match="stride"):
        s.preview(CAM, 0)


def test_shadow_and_disc_kernels_equal_their_numpy_references():
    """The brush's shadow map and its discs with a z-test (kernels of _draw_brush) equal the numpy
    references bit for bit, ties between equal depths included (the last fragment wins)."""
    from unmesh.paint._view_kernels import brush_discs
    from unmesh.paint.view import brush_discs_reference, shadow_test, shadow_test_reference

    rng = np.random.default_rng(5)
    brush = np.column_stack([rng.normal(0, 0.2, (300, 2)), rng.uniform(0.0, 0.3, 300)])
    pts = np.column_stack([rng.uniform(-1, 1, (4000, 2)), rng.uniform(-0.1, 0.4, 4000)])
    assert np.array_equal(shadow_test(brush, pts, 0.05), shadow_test_reference(brush, pts, 0.05))
    for ties in (False, True):
        n, r0, r1, c0, c1 = 200, 5, 60, 3, 70
        pr = rng.integers(0, 70, n)
        pc = rng.integers(0, 75, n)
        rpx = rng.uniform(0.3, 3.5, n)
        z = np.round(rng.uniform(1, 2, n + 7), 1) if ties else rng.uniform(1, 2, n + 7)
        src = np.sort(rng.choice(n + 7, n, replace=False))
        col, nrm = rng.random((n + 7, 3)), rng.random((n + 7, 3))
        P = (r1 - r0) * (c1 - c0)
        base = (rng.random((P, 3)), rng.random((P, 3)), rng.uniform(1.3, 3, P), rng.random(P) < 0.5)
        want = [a.copy() for a in base]
        got = [a.copy() for a in base]
        args = (pr, pc, (rpx + 0.5) ** 2, z, src, int(np.ceil(rpx.max())), r0, r1, c0, c1, col, nrm)
        brush_discs_reference(*args, *want)
        brush_discs(*args, *got)
        for a, b in zip(got, want, strict=True):
            assert np.array_equal(a, b)
        assert (want[2] != base[2]).sum() > 100
