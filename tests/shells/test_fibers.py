"""Fiber splines, arc length and tangent angle (thesis 7.2.1, Appendix B) against references."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.shells import fibers as fb


def _random_fibers(rng, n=40, bend=0.4):
    """Fibers roughly along x with random bends, centre near the origin."""
    x = rng.normal(scale=0.05, size=(n, 3))
    d = np.array([1.0, 0.0, 0.0]) + rng.normal(scale=bend, size=(n, 3))
    x1 = x - d * rng.uniform(0.5, 1.5, size=(n, 1)) + rng.normal(scale=bend * 0.5, size=(n, 3))
    x2 = x + d * rng.uniform(0.5, 1.5, size=(n, 1)) + rng.normal(scale=bend * 0.5, size=(n, 3))
    normal = np.cross(d, rng.normal(size=(n, 3)))
    return x1, x, x2, normal


def _central_difference(func, nodes, h=1e-6):
    """d func / d nodes by central differences: nodes (F, R, 3) -> (F, R, 3)."""
    grad = np.zeros_like(nodes)
    for r in range(nodes.shape[1]):
        for c in range(3):
            plus, minus = nodes.copy(), nodes.copy()
            plus[:, r, c] += h
            minus[:, r, c] -= h
            grad[:, r, c] = (func(plus) - func(minus)) / (2 * h)
    return grad


def test_spline_is_natural_and_interpolates(rng):
    x1, x, x2, _ = _random_fibers(rng)
    t = np.array([0.0, 0.5, 1.0])
    pts = fb.evaluate(x1, x, x2, t)
    np.testing.assert_allclose(pts[:, 0], x1, atol=1e-14)
    np.testing.assert_allclose(pts[:, 1], x, atol=1e-14)
    np.testing.assert_allclose(pts[:, 2], x2, atol=1e-14)
    c = fb.spline_coefficients(x1, x, x2)
    # C1 and C2 continuity at the centre; zero second derivative at both ends (natural spline)
    np.testing.assert_allclose(c["b1"] + 2 * c["c1"] + 3 * c["d1"], c["b2"], atol=1e-14)
    np.testing.assert_allclose(2 * c["c1"] + 6 * c["d1"], 2 * c["c2"], atol=1e-14)
    np.testing.assert_allclose(2 * c["c1"], 0.0, atol=1e-14)
    np.testing.assert_allclose(2 * c["c2"] + 6 * c["d2"], 0.0, atol=1e-14)
    # agrees with scipy's natural cubic spline through the same three points
    from scipy.interpolate import CubicSpline

    tt = np.linspace(0, 1, 11)
    ours = fb.evaluate(x1, x, x2, tt)
    for k in range(5):
        ref = CubicSpline([0.0, 0.5, 1.0], np.stack([x1[k], x[k], x2[k]]), bc_type="natural")(tt)
        np.testing.assert_allclose(ours[k], ref, atol=1e-12)


def test_tangents_are_spline_derivatives(rng):
    x1, x, x2, _ = _random_fibers(rng)
    t0, t1, tc = fb.tangents(x1, x, x2)
    h = 1e-6
    # the local parameter s = 2t, so f_i'(s) = (1/2) df/dt
    d0 = (fb.evaluate(x1, x, x2, [h])[:, 0] - fb.evaluate(x1, x, x2, [0.0])[:, 0]) / h / 2
    d1 = (fb.evaluate(x1, x, x2, [1.0])[:, 0] - fb.evaluate(x1, x, x2, [1 - h])[:, 0]) / h / 2
    dc = (fb.evaluate(x1, x, x2, [0.5 + h])[:, 0] - fb.evaluate(x1, x, x2, [0.5 - h])[:, 0]) / (2 * h) / 2
    np.testing.assert_allclose(t0, d0, atol=1e-5)
    np.testing.assert_allclose(t1, d1, atol=1e-5)
    np.testing.assert_allclose(tc, dc, atol=1e-5)


def test_arc_length_converges_to_true_length(rng):
    x1, x, x2, _ = _random_fibers(rng, n=10)
    t = np.linspace(0, 1, 200001)
    pts = fb.evaluate(x1, x, x2, t)
    true = np.linalg.norm(np.diff(pts, axis=1), axis=2).sum(axis=1)
    errors = [np.abs(fb.arc_length(x1, x, x2, n) - true).max() for n in (2, 4, 8, 16)]
    assert errors[1] < 0.02 * true.min()
    # the midpoint rule is second order: halving the spacing divides the error by ~4
    assert errors[3] < errors[2] / 3 < errors[1] / 9
    # straight, evenly spaced fiber: exact
    assert fb.arc_length([0, 0, 0], [1, 1, 1], [2, 2, 2], 1)[0] == pytest.approx(2 * np.sqrt(3), rel=1e-14)


def test_arc_length_is_symmetric_and_invariant(rng):
    x1, x, x2, _ = _random_fibers(rng)
    np.testing.assert_allclose(fb.arc_length(x1, x, x2), fb.arc_length(x2, x, x1), rtol=1e-13)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    shift = rng.normal(size=3)
    moved = [p @ q.T + shift for p in (x1, x, x2)]
    np.testing.assert_allclose(fb.arc_length(*moved), fb.arc_length(x1, x, x2), rtol=1e-12)


@pytest.mark.parametrize("samples", [1, 4, 7])
def test_arc_length_gradient_matches_central_differences(rng, samples):
    x1, x, x2, _ = _random_fibers(rng)
    _length, grad = fb.arc_length_gradient(x1, x, x2, samples)
    nodes = np.stack([x1, x, x2], axis=1)
    fd = _central_difference(lambda p: fb.arc_length(p[:, 0], p[:, 1], p[:, 2], samples), nodes)
    np.testing.assert_allclose(grad, fd, atol=1e-7)
    np.testing.assert_allclose(grad.sum(axis=1), 0.0, atol=1e-12)


def test_arc_length_gradient_matches_printed_weights_b6():
    """(B.6): weights of d|f1'|/dx1 = (-5/4 + 3/4 s^2) etc. (last line reading f2)."""
    w1, w2 = fb._speed_weights(3)
    s = (np.arange(3) + 0.5) / 3
    np.testing.assert_allclose(w1[:, 0], -5 / 4 + 3 / 4 * s**2)
    np.testing.assert_allclose(w1[:, 1], 3 / 2 - 3 / 2 * s**2)
    np.testing.assert_allclose(w1[:, 2], -1 / 4 + 3 / 4 * s**2)
    np.testing.assert_allclose(w2[:, 0], -1 / 2 + 3 / 2 * s - 3 / 4 * s**2)
    np.testing.assert_allclose(w2[:, 1], -3 * s + 3 / 2 * s**2)
    np.testing.assert_allclose(w2[:, 2], 1 / 2 + 3 / 2 * s - 3 / 4 * s**2)


@pytest.mark.parametrize(("soft", "soft_x"), [(0.0, 0.0), (0.3, 0.0), (0.3, 0.05)])
def test_bending_angle_gradient_matches_central_differences(rng, soft, soft_x):
    x1, x, x2, normal = _random_fibers(rng, bend=0.6)
    _theta, grad, grad_n = fb.bending_angle_gradient(x1, x, x2, normal, soft, soft_x)
    nodes = np.stack([x1, x, x2], axis=1)
    fd = _central_difference(lambda p: fb.bending_angle(p[:, 0], p[:, 1], p[:, 2], normal, soft, soft_x), nodes)
    np.testing.assert_allclose(grad, fd, atol=2e-6)
    fd_n = _central_difference(lambda nn: fb.bending_angle(x1, x, x2, nn[:, 0], soft, soft_x),
                               normal[:, None, :])[:, 0]
    np.testing.assert_allclose(grad_n, fd_n, atol=2e-6)


def test_softened_angle_stays_bounded_where_the_normal_vanishes():
    """soft > 0: theta and its gradient stay finite and fade as N -> 0 or N || tc."""
    x1, x, x2 = np.array([[-1.0, 0, 0]]), np.zeros((1, 3)), np.array([[1.0, 0.3, 0]])
    for n in ([0.0, 1e-9, 0.0], [1.0, 0.0, 0.0]):
        th, g, gn = fb.bending_angle_gradient(x1, x, x2, [n], 0.1)
        assert np.isfinite(th).all() and np.isfinite(g).all() and np.isfinite(gn).all()
        assert np.abs(g).max() < 100
    th_small = fb.bending_angle(x1, x, x2, [[0.0, 1e-9, 0.0]], 0.1)
    assert abs(th_small[0]) < 1e-6
    # a centre slid towards an end (t1 -> 0): with soft_x the gradient stays bounded
    x2b = np.array([[1.0, 0.0, 0.0]])
    xc = (x1 + 5 * x2b) / 6 + [[0.0, 0.0, 1e-3]]
    _, g, _ = fb.bending_angle_gradient(x1, xc, x2b, [[0.0, 0.0, 1.0]], 0.1, 0.05)
    assert np.abs(g).max() < 100


def test_bending_angle_gradient_at_straight_fibers(rng):
    """The printed gradient (B.11/B.12) is singular at theta = 0; ours is smooth there."""
    d = rng.normal(size=(20, 3))
    x = rng.normal(size=(20, 3))
    x1, x2 = x - d, x + d * rng.uniform(0.5, 2, size=(20, 1))
    normal = np.cross(d, rng.normal(size=(20, 3)))
    theta, grad, _ = fb.bending_angle_gradient(x1, x, x2, normal)
    np.testing.assert_allclose(theta, 0.0, atol=1e-12)
    nodes = np.stack([x1, x, x2], axis=1)
    fd = _central_difference(lambda p: fb.bending_angle(p[:, 0], p[:, 1], p[:, 2], normal), nodes)
    assert np.isfinite(grad).all()
    np.testing.assert_allclose(grad, fd, atol=1e-6)


def test_bending_angle_invariances(rng):
    x1, x, x2, normal = _random_fibers(rng, bend=0.6)
    theta, grad, grad_n = fb.bending_angle_gradient(x1, x, x2, normal)
    # translation: node gradients sum to zero; rotation: total torque of the gradient vanishes
    np.testing.assert_allclose(grad.sum(axis=1), 0.0, atol=1e-12)
    nodes = np.stack([x1, x, x2], axis=1)
    torque = np.cross(nodes, grad).sum(axis=1) + np.cross(normal, grad_n)
    np.testing.assert_allclose(torque, 0.0, atol=1e-11)
    _, grad_s, grad_ns = fb.bending_angle_gradient(x1, x, x2, normal, 0.2, 0.05)
    torque = np.cross(nodes, grad_s).sum(axis=1) + np.cross(normal, grad_ns)
    np.testing.assert_allclose(torque, 0.0, atol=1e-11)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    rot = fb.bending_angle(x1 @ q.T, x @ q.T, x2 @ q.T, normal @ q.T)
    np.testing.assert_allclose(rot, theta, atol=1e-12)
    # reversing the fiber does not change its angle; scaling N does not either
    np.testing.assert_allclose(fb.bending_angle(x2, x, x1, normal), theta, atol=1e-12)
    np.testing.assert_allclose(fb.bending_angle(x1, x, x2, 3.0 * normal), theta, atol=1e-12)


def test_bending_angle_equals_thesis_b9_in_the_normal_plane(rng):
    """Fibers bending in the plane of tc and N: |atan2 form| == arccos(...) of (B.9) always,
    and the sign equals (B.9)'s sign(-N.f''(1/2)) for moderate bends (7.10)."""
    n = 40
    tangent = rng.normal(size=(n, 3))
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent, rng.normal(size=(n, 3)))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    x = rng.normal(size=(n, 3))
    for height, spread in ((0.8, 0.5), (0.25, 0.2)):
        h1, h2 = rng.uniform(-height, height, size=(2, n, 1))
        x1 = x - tangent * rng.uniform(1 - spread, 1 + spread, size=(n, 1)) + h1 * normal
        x2 = x + tangent * rng.uniform(1 - spread, 1 + spread, size=(n, 1)) + h2 * normal
        ours = fb.bending_angle(x1, x, x2, normal)
        printed = fb.thesis_bending_angle(x1, x, x2, normal)
        np.testing.assert_allclose(np.abs(ours), np.abs(printed), atol=1e-10)
    np.testing.assert_allclose(ours, printed, atol=1e-10)
    # (7.10): theta < 0 exactly when f''(1/2) points along N
    second = x1 - 2 * x + x2
    assert np.all((ours < 0) == (np.einsum("ij,ij->i", normal, second) > 0))


def test_bending_angle_is_continuous_where_b9_jumps():
    """A fiber with an in-surface (geodesic) bend: B.9 flips sign as the normal bend crosses 0."""
    normal = np.array([[0.0, 0.0, 1.0]])
    x1, x = np.array([[-1.0, -0.3, 0.0]]), np.zeros((1, 3))
    ours, printed = [], []
    for z in (-1e-6, 1e-6):
        x2 = np.array([[1.0, -0.3, z]])
        ours.append(fb.bending_angle(x1, x, x2, normal)[0])
        printed.append(fb.thesis_bending_angle(x1, x, x2, normal)[0])
    assert abs(ours[1] - ours[0]) < 1e-5
    assert abs(printed[1] - printed[0]) > 0.5


def test_curvature_of_circle_sample():
    """Three points on a unit circle, a apart: the natural spline turns by ~3/4 of the circle's 2a.

    (Zero end curvature: t1 - t0 = 3q/2 with |q| ~ a^2 and |t| ~ a, so theta ~ 1.5 a.)"""
    for a in (0.05, 0.1, 0.2):
        x1 = np.array([[np.sin(-a), np.cos(-a), 0.0]])
        x = np.array([[0.0, 1.0, 0.0]])
        x2 = np.array([[np.sin(a), np.cos(a), 0.0]])
        theta = fb.bending_angle(x1, x, x2, [[0.0, 1.0, 0.0]])[0]  # outward normal, convex
        assert theta > 0
        assert theta == pytest.approx(1.5 * a, rel=0.01)
        assert fb.arc_length(x1, x, x2)[0] == pytest.approx(2 * a, rel=1e-3)


def test_bad_input():
    with pytest.raises(InputError, match="x"):
        fb.arc_length([[0, 0, 0]], [[1, 0, 0], [2, 0, 0]], [[3, 0, 0]])
    with pytest.raises(InputError, match="samples"):
        fb.arc_length([0, 0, 0], [1, 0, 0], [2, 0, 0], samples=0)
    with pytest.raises(InputError, match="finite"):
        fb.bending_angle([0, 0, 0], [1, np.nan, 0], [2, 0, 0], [0, 0, 1])


def test_degenerate_fibers_are_those_whose_projected_end_tangent_vanishes(rng):
    """The degenerate test looks at the end tangents the angle (7.10) sees: projected onto the
    fiber's normal plane. A centre slid to one end and sideways within a flat sheet has a long
    end tangent (its sideways part) whose projection vanishes; the angle there jumps by pi."""
    n = [0.0, 0.0, 1.0]
    x1, x, x2 = [-1.0, 0, 0], [0.7, 0.45, 0], [1.0, 0, 0]
    t0, t1, tc = fb.tangents(x1, x, x2)
    assert np.linalg.norm(t1) > 0.6 * np.linalg.norm(tc)           # the full tangent is long
    assert fb.degenerate(x1, x, x2, n)[0]
    # near the flip the angle jumps from 0 to pi between two nearby positions of the centre
    before, after = ([0.683 + d, 0.45, 0] for d in (-0.01, 0.01))
    assert abs(fb.bending_angle(x1, before, x2, n, 0.0, fb.TANGENT_SOFTENING)[0]) < 1e-12
    assert abs(fb.bending_angle(x1, after, x2, n, 0.0, fb.TANGENT_SOFTENING)[0]) == pytest.approx(np.pi)
    assert fb.degenerate(x1, before, x2, n)[0] and fb.degenerate(x1, after, x2, n)[0]
    # bending in the normal plane: the projection is the tangent itself (the plain test)
    a1, a, a2, _ = _random_fibers(rng, 400, bend=0.8)
    t0, t1, tc = fb.tangents(a1, a, a2)
    plane = np.cross(a - a1, a2 - a1)                 # normal of the fiber's plane: N in the plane
    nrm_in = np.cross(plane, tc)
    plain = np.minimum(np.einsum("ij,ij->i", t0, t0), np.einsum("ij,ij->i", t1, t1)) < 0.09 * np.einsum(
        "ij,ij->i", tc, tc)
    assert 0 < plain.sum() < len(plain)
    np.testing.assert_array_equal(fb.degenerate(a1, a, a2, nrm_in), plain)


def test_degenerate_kernels_match_the_reference(rng):
    """Per-step scan (:func:`unmesh.shells._fracture_kernels.fracture_scan`) counts the fibers the numpy test finds."""
    from unmesh.shells import _fracture_kernels

    f = 30_000
    x = rng.normal(size=(3 * f, 3))
    fibers = np.arange(3 * f).reshape(f, 3)
    s = rng.normal(size=(3 * f, 3))
    s[::7] *= 1e-3                                    # umbrella vectors almost zero: the soft axis
    soft = rng.uniform(0.0, 0.3, 3 * f)
    soft[::5] = 0.0
    ref = fb.degenerate(x[fibers[:, 0]], x[fibers[:, 1]], x[fibers[:, 2]], s[fibers[:, 1]], soft[fibers[:, 1]], 0.3)
    z, one = np.zeros(f), np.ones(f)
    _, bad = _fracture_kernels.fracture_scan(x, fibers, s, soft, z, z, one, z, one, one, 0.09)
    assert 0 < ref.sum() < f
    assert bad == ref.sum()
