"""Reuse between frames (dynamic CSG): per-patch caches and the frame of an unchanged model."""

import numpy as np

from unmesh.csg import Patch, prepare
from unmesh.csg.cache import local_points, overlap_pairs
from unmesh.shapes import Sphere


def _rotation(angle, scale=1.0, shift=(0.0, 0.0, 0.0)):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:3, :3] = scale * np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]])
    m[:3, 3] = shift
    return m


def test_moved_patch_classifies_like_the_same_surfels_given_in_world_space():
    """insidePatch in the patch's own frame (cached k-d tree) equals the world-space result."""
    box = Patch.halfspace((0, 0, 0.4), (0, 0, 1), 2.0, 0.08) & Patch.halfspace((0, 0, -0.4), (0, 0, -1), 2.0, 0.08)
    ball = Patch.from_shape(Sphere(radius=0.35), 0.05)
    m = _rotation(0.7, 1.3, (0.2, -0.1, 0.05))
    moved = box - ball.moved(m)
    world = box - Patch(ball.cloud.transformed(m))
    a, b = prepare(moved, reuse=False), prepare(world, reuse=False)
    assert np.array_equal(a.classes, b.classes)
    assert np.array_equal(a.offsets, b.offsets) and np.array_equal(a.partners, b.partners)
    assert (a.classes == 1).sum() > 50


def test_frame_of_an_unchanged_model_is_reused_and_a_moved_one_is_not():
    a = Patch.halfspace((0, 0, 0), (0, 0, 1), 2.0, 0.25)
    b = Patch.halfspace((0, 0, 0), (1, 0, 0), 2.0, 0.25)
    model = a & b
    f = prepare(model)
    assert prepare(model) is f
    g = prepare(model, reuse=False)
    assert g is not f and np.array_equal(g.classes, f.classes)
    moved = a & b.moved(_rotation(0.0, 1.0, (0.3, 0, 0)))
    assert prepare(moved) is not f


def test_overlap_pairs_equal_brute_force_and_local_points_invert_the_transform():
    c = Sphere(radius=0.5).surfels(0.1)
    pos, r = c.positions, np.asarray(c.radii)
    d2 = ((pos[:, None] - pos[None]) ** 2).sum(-1)
    i, j = np.nonzero(np.triu(d2 < (r[:, None] + r[None]) ** 2, 1))
    assert np.array_equal(overlap_pairs(c), np.stack([i, j], 1))
    m = _rotation(1.1, 0.7, (1, 2, 3))
    x = np.random.default_rng(0).normal(size=(20, 3))
    world = x @ m[:3, :3].T + m[:3, 3]
    assert np.allclose(local_points(m, world), x, atol=1e-12)
    shear = np.eye(4)
    shear[0, 1] = 0.5
    assert local_points(shear, world) is None


def test_dropping_decided_surfels_between_patches_keeps_the_classes(monkeypatch):
    """Asking the patches one after the other and dropping surfels already off the surface
    gives the classes and partner rows of asking every patch for every surfel."""
    import unmesh.csg.frame as frame

    ball = Patch.from_shape(Sphere(radius=1.0), 0.08)
    cuts = [Patch.from_shape(Sphere(radius=1.0, center=c), 0.1) for c in ((0.9, 0.9, 0.0), (-0.9, 0.0, 0.9))]
    model = ball - cuts[0] - cuts[1]
    monkeypatch.setattr(frame, "_DECIDE_EARLY", 0)
    early = prepare(model, reuse=False)
    monkeypatch.setattr(frame, "_DECIDE_EARLY", 10**9)
    late = prepare(model, reuse=False)
    assert np.array_equal(early.classes, late.classes)
    assert np.array_equal(early.clip.offsets, late.clip.offsets)
    assert np.array_equal(early.clip.partners, late.clip.partners)
    assert (early.classes == 2).sum() > 100 and (early.classes == 1).sum() > 50


def test_asking_representatives_of_pieces_keeps_the_classes(monkeypatch):
    """insidePatch valued per piece of the asked surfels (a few representatives asked, pieces
    whose representatives disagree asked whole) gives the classes and partner rows of asking
    every surfel, for spheres cut by spheres and for moved patches (memo path)."""
    from unmesh.csg import cache, frame

    calls = []
    real = frame.inside_patch
    monkeypatch.setattr(frame, "inside_patch", lambda c, x, *a, **k: calls.append(len(x)) or real(c, x, *a, **k))
    monkeypatch.setattr(frame, "_MEMO_FROM", 0)
    ball = Patch.from_shape(Sphere(radius=1.0), 0.06)
    cuts = [Patch.from_shape(Sphere(radius=1.6, center=c), 0.1) for c in ((1.4, 1.4, 0.0), (-1.4, 0.0, 1.4),
                                                                          (0.0, -1.5, -1.2))]
    models = [ball - cuts[0] - cuts[1] - cuts[2],
              (ball.moved(_rotation(0.4, 1.1, (0.1, 0, 0))) - cuts[0]) | (cuts[1] & cuts[2].moved(_rotation(0.2)))]
    for model in models:
        monkeypatch.setattr(frame, "_PIECES_FROM", 0)
        cache._MEMO.clear()
        calls.clear()
        pieced = prepare(model, reuse=False)
        asked = sum(calls)
        cache._MEMO.clear()
        monkeypatch.setattr(frame, "_PIECES_FROM", 10**9)
        calls.clear()
        every = prepare(model, reuse=False)
        cache._MEMO.clear()
        assert np.array_equal(pieced.classes, every.classes)
        assert np.array_equal(pieced.clip.offsets, every.clip.offsets)
        assert np.array_equal(pieced.clip.partners, every.clip.partners)
        assert asked < sum(calls)
        assert (every.classes == 1).sum() > 50 and (every.classes == 2).sum() > 100


def test_values_of_unmoved_patches_are_reused_and_equal_a_fresh_evaluation(monkeypatch):
    """Frames of a moving ball: the memo of the unmoved pairs gives exactly the fresh result,
    and the moved ball is asked again (its values change)."""
    from unmesh.csg import cache, frame

    box = Patch.halfspace((0, 0, 0.4), (0, 0, 1), 2.0, 0.08) & Patch.halfspace((0, 0, -0.4), (0, 0, -1), 2.0, 0.08)
    ball = Patch.from_shape(Sphere(radius=0.35), 0.05)
    monkeypatch.setattr(frame, "_MEMO_FROM", 0)  # the memo for every set of points asked
    calls = []
    real = frame.inside_patch
    monkeypatch.setattr(frame, "inside_patch", lambda c, x, *a, **k: calls.append(len(x)) or real(c, x, *a, **k))
    frames = []
    for k in range(3):
        model = box - ball.moved(_rotation(0.3 * k, 1.0, (0.1 * k, 0.05 * k, 0.0)))
        calls.clear()
        f = prepare(model)
        asked = sum(calls)
        cache._MEMO.clear()  # the same frame from scratch
        calls.clear()
        g = prepare(model, reuse=False)
        assert np.array_equal(f.classes, g.classes)
        assert np.array_equal(f.clip.partners, g.clip.partners) and np.array_equal(f.clip.offsets, g.clip.offsets)
        frames.append((asked, sum(calls)))
    # frames 1 and 2 reuse the values between the box's half-spaces of the frame before, and
    # ask only the pairs with the moved ball
    assert all(0 < a < b for a, b in frames[1:]), frames
