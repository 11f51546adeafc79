"""Brush (5.4): rest under pressure, no mass inside, penalty force K_p d, splitting at 60 degrees,
and the haptic loop (5.4.2)."""

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import SurfelCloud
from unmesh.paint import Brush, Paint, PaintOptions, Sample, Session
from unmesh.paint.brush import K_PENALTY, RESERVOIR, SPLIT_ANGLE, BrushState
from unmesh.paint.collide import collide, force_shading
from unmesh.paint.haptic import WINDOW, HapticLoop
from unmesh.shapes import by_name
from unmesh.spatial import KDTree

#: brush frame z (handle) -> world +y, brush x -> world x
UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])


@pytest.fixture(scope="module")
def plane():
    c = by_name("plane", size=0.6).surfels(0.01)
    return KDTree(c.positions), c.positions, c.normals


def roof(angle_deg, spacing=0.004):
    """Two half-planes meeting at the ridge x = 0 whose normals differ by ``angle_deg``."""
    phi = np.radians(angle_deg / 2)
    xs = np.arange(-0.2, 0.2 + 1e-9, spacing) + spacing / 2
    zs = np.arange(-0.1, 0.1 + 1e-9, spacing)
    X, Z = np.meshgrid(xs, zs)
    x, z = X.ravel(), Z.ravel()
    pos = np.stack([x, -np.abs(x) * np.tan(phi), z], axis=1)
    nrm = np.stack([np.sign(x) * np.sin(phi), np.full_like(x, np.cos(phi)), np.zeros_like(x)], axis=1)
    return KDTree(pos), pos, nrm


def test_force_shading_on_a_plane(plane):
    tree, pos, nrm = plane
    inside, d, n = collide(tree, pos, nrm, np.array([[0.01, -0.02, 0.03], [0.0, 0.05, 0.0]]))
    assert inside.tolist() == [True, False]
    np.testing.assert_allclose(d, [0.02, -0.05], atol=1e-12)
    np.testing.assert_allclose(n, [[0, 1, 0], [0, 1, 0]], atol=1e-12)


@pytest.mark.parametrize("kind", ["round", "flat", "pencil"])
def test_brush_pressed_onto_a_plane_comes_to_rest_outside(plane, kind):
    tree, pos, nrm = plane
    b = BrushState(Brush(kind, 0.03))
    origin = np.array([0.0, -0.5 * 0.09, 0.0])  # handle pushed half the bristle length down
    for _ in range(40):
        b.simulate(tree, pos, nrm, origin, UP, steps=12)
        assert np.all(b.x[:, 1] >= -1e-12)  # never ends inside
    assert b.colliding.any()
    before = b.x.copy()
    b.simulate(tree, pos, nrm, origin, UP, steps=12)
    np.testing.assert_allclose(b.x, before, atol=1e-9)  # at rest


@settings(deadline=None, max_examples=15)
@given(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(0.0, 1.0), st.sampled_from(["round", "flat"]))
def test_active_masses_never_inside_a_sphere(dx, dz, push, kind):
    sphere = by_name("sphere", radius=0.5).surfels(0.02)
    tree = KDTree(sphere.positions)
    b = BrushState(Brush(kind, 0.04))
    top = np.array([dx, 0.0, dz])
    top[1] = np.sqrt(max(0.25 - dx * dx - dz * dz, 0.0))
    n = top / np.linalg.norm(top)
    R = UP if abs(n[1]) > 0.999 else None
    if R is None:
        x = np.cross([0, 1.0, 0], n)
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(n, x), n], axis=1)
    for k in range(5):
        b.simulate(tree, sphere.positions, sphere.normals, top - n * push * 0.06 * (k + 1) / 5, R, steps=12)
        inside, d, _ = collide(tree, sphere.positions, sphere.normals, b.x)
        assert np.all(~inside | (d <= 1e-12))


def test_penalty_force_is_k_p_d(plane):
    tree, pos, nrm = plane
    b = BrushState(Brush("pencil", 0.02))
    hz = 0.6 * 3 * 0.02
    d = 0.004
    origin = np.array([0.0, -hz - d, 0.0])  # all four handle points d below the plane
    for _ in range(30):
        b.simulate(tree, pos, nrm, origin, UP, steps=12)
    np.testing.assert_allclose(b.handle_depth, d, rtol=1e-9)
    np.testing.assert_allclose(b.penalty(), [0.0, 4 * K_PENALTY * d, 0.0], atol=1e-12)  # at rest: no friction
    s_force = b.penalty() + b.spring_reaction
    assert s_force[1] > 4 * K_PENALTY * d * 0.99  # the bristles push the handle up too, never down


def test_friction_opposes_tangential_motion(plane):
    tree, pos, nrm = plane
    b = BrushState(Brush("pencil", 0.02))
    hz = 0.6 * 3 * 0.02
    b.simulate(tree, pos, nrm, np.array([0.0, -hz - 0.004, 0.0]), UP)
    b.simulate(tree, pos, nrm, np.array([0.01, -hz - 0.004, 0.0]), UP)
    f = b.penalty()
    assert f[0] < 0 and f[1] > 0


@pytest.mark.parametrize("angle, split", [(45.0, False), (SPLIT_ANGLE - 5, False), (SPLIT_ANGLE + 5, True), (90.0, True)])
def test_flat_brush_splits_at_60_degrees(angle, split):
    tree, pos, nrm = roof(angle)
    b = BrushState(Brush("flat", 0.05))
    y0 = -0.05 * np.tan(np.radians(angle / 2)) - 0.004  # outer masses just pressed onto the faces
    for _ in range(5):
        b.simulate(tree, pos, nrm, np.array([0.0, y0, 0.0]), UP)
    assert b.colliding[0] and b.colliding[2]
    assert b.split is split
    n0, n2 = b.contact_normals[0], b.contact_normals[2]
    np.testing.assert_allclose(np.degrees(np.arccos(np.clip(n0 @ n2, -1, 1))), angle, atol=1.0)


def test_split_brush_paints_with_one_buffer_per_tip():
    _tree, pos, nrm = roof(90.0)
    cloud = SurfelCloud(pos, nrm, radii=np.full(len(pos), 0.004))
    s = Session(cloud, PaintOptions(haptics=False))
    r = s.stroke([Sample(0.05 * i, (0.0, 0.0, -0.05 + 0.02 * i), 0.9) for i in range(6)],
                 brush=Brush("flat", 0.05))
    assert r.pixels > 0
    kids = np.arange(s.surface.n_original, s.surface.n)
    kids = kids[s.surface.alive[kids] & (s.surface.vw[kids] > 0)]
    # paint landed on both faces
    assert (s.surface.pos[kids, 0] < -0.02).any() and (s.surface.pos[kids, 0] > 0.02).any()


def test_haptic_loop_low_passes_and_measures():
    loop = HapticLoop(K_PENALTY)
    loop.publish(np.array([0.001, 0.0]), np.array([[0, 1.0, 0], [0, 1.0, 0]]), np.zeros(3), 0.5, np.zeros(3))
    loop.start()
    time.sleep(0.2)
    loop.stop()
    np.testing.assert_allclose(loop.force, [0, K_PENALTY * 0.001, 0], rtol=1e-12)
    st_ = loop.stats()
    assert st_["samples"] > 20 and st_["rate"] > 0
    # a step in the force reaches the output over the 1/60 s window (moving average)
    loop2 = HapticLoop(K_PENALTY)
    outs = []
    for k in range(WINDOW + 3):
        if k == 2:
            loop2.publish(np.array([0.001]), np.array([[0, 1.0, 0]]), np.zeros(3), 0.0, np.zeros(3))
        outs.append(loop2.step()[1])
    assert outs[1] == 0 and 0 < outs[2] < outs[5] < K_PENALTY * 0.001
    assert outs[-1] == pytest.approx(K_PENALTY * 0.001, rel=1e-12)


def test_session_force_and_haptics(plane_cloud):
    s = Session(plane_cloud, PaintOptions(haptics=True))
    sid = s.begin_stroke(Brush("round", 0.04), None or __import__("unmesh.paint", fromlist=["Paint"]).Paint())
    s.add_samples(sid, [Sample(0.0, (0, 0, 0), 1.0), Sample(0.05, (0.02, 0, 0), 1.0)])
    time.sleep(0.05)
    f = s.force()
    assert f.shape == (3,) and np.isfinite(f).all()
    s.end_stroke(sid)
    assert s.haptic_stats()["samples"] > 0
    s.close()


def test_force_shading_weights_interpolate_normals():
    tree, pos, nrm = roof(90.0)
    _d, n = force_shading(tree, pos, nrm, np.array([[0.0, -0.01, 0.0]]))
    np.testing.assert_allclose(n[0], [0, 1, 0], atol=1e-9)  # symmetric at the ridge


def test_haptic_process_publishes_the_force():
    from unmesh.paint.haptic import HapticProcess

    loop = HapticProcess(K_PENALTY).start()
    try:
        loop.publish(np.array([0.002]), np.array([[0, 1.0, 0]]), np.zeros(3), 0.5, np.zeros(3))
        deadline = time.time() + 20.0
        # the loop writes the force before it counts the period: wait for both (a preempted
        # loop process showed the force with no period counted yet)
        while time.time() < deadline and not (np.allclose(loop.force, [0, K_PENALTY * 0.002, 0], rtol=1e-12)
                                              and loop.stats()["samples"] > 0):
            time.sleep(0.05)
        np.testing.assert_allclose(loop.force, [0, K_PENALTY * 0.002, 0], rtol=1e-12)
        assert loop.stats()["samples"] > 0
    finally:
        loop.stop()
    assert not loop.running


def test_flat_brush_internal_surfaces_face_the_neighbouring_bundles():
    """5.4.3: the faces between the flat brush's bundles are internal; a round brush has none."""
    from unmesh.paint.brush import skeleton

    sk = skeleton(Brush("flat", 0.02))
    off = sk.body[:, 0] - sk.active[sk.owner, 0]
    # the outer bundles' internal faces point to the middle, the middle bundle's to both sides
    assert sk.internal.any()
    assert np.all(off[sk.internal & (sk.owner == 0)] > 0) and np.all(off[sk.internal & (sk.owner == 2)] < 0)
    assert np.all(np.abs(sk.bnormal[sk.internal, 0]) > np.cos(np.radians(45.0)))
    # the brush's outer ends and its broad faces are never internal
    assert not sk.internal[sk.body[:, 0] <= sk.body[:, 0].min() + 1e-12].any()
    assert not sk.internal[np.abs(sk.bnormal[:, 1]) > 0.9].any()
    assert not skeleton(Brush("round", 0.02)).internal.any()


def test_internal_surfaces_exchange_paint_only_when_the_brush_is_split(plane_cloud):
    """A whole flat brush paints with its outer surface only (internal surfels keep their paint,
    the others exchange); a split brush's tips use their internal surfaces too."""
    s = Session(plane_cloud, PaintOptions(haptics=False))
    paint = Paint("oil", (0.9, 0.1, 0.1))
    sid = s.begin_stroke(Brush("flat", 0.03), paint)
    s.add_samples(sid, [Sample(0.05 * i, (-0.05 + 0.02 * i, 0.0, 0.0), 0.9) for i in range(6)])
    b = s._last_brush
    assert not b.split
    loaded = RESERVOIR * paint.thickness * b.sk.spacing ** 2
    assert np.all(b.vw[b.sk.internal] == loaded)
    assert np.any(b.vw[~b.sk.internal] != loaded)
    s.end_stroke(sid)
    whole, tip0 = b.transfer_body(), b.transfer_body(0)
    assert not np.intersect1d(whole, np.flatnonzero(b.sk.internal)).size
    assert np.isin(np.flatnonzero(b.sk.internal & (b.sk.owner == 0)), tip0).all()


def test_cross3_is_np_cross_bit_for_bit():
    from unmesh.paint.brush import cross3

    rng = np.random.default_rng(5)
    for _ in range(2000):
        a, b = rng.standard_normal((2, 3)) * 10.0 ** rng.integers(-6, 6, size=(2, 1))
        assert np.array_equal(cross3(a, b), np.cross(a, b))
