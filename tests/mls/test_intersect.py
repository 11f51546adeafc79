"""Ray-surface intersection (Algorithm 3.1) against analytic sphere and torus intersections."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import mls
from unmesh.errors import InputError
from unmesh.mls import MLSSurface
from unmesh.surfels import SurfelCloud

from . import reference as ref
from . import samples as S
from .samples import angle_deg


def _check(surf, o, d, exact_t, normal_fn, tol=1e-3):
    t, hit, n = mls.intersect(surf, o, d, return_normals=True)
    te = exact_t(o, d)
    np.testing.assert_array_equal(hit, np.isfinite(te))
    np.testing.assert_array_equal(np.isinf(t), ~hit)
    err = np.abs(t[hit] - te[hit]) * np.linalg.norm(d[hit], axis=1)
    assert err.max() < tol
    p = o[hit] + t[hit, None] * d[hit]
    assert angle_deg(n[hit], normal_fn(p)).max() < 1.0
    assert np.isnan(n[~hit]).all()
    return err


def test_sphere_rays_from_outside(sphere_surface, rng):
    n = 2000
    o = rng.normal(size=(n, 3))
    o *= 3 / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.uniform(-1.3, 1.3, (n, 3)) - o  # about half of them hit, unnormalised directions
    err = _check(sphere_surface, o, d, S.ray_sphere, S.sphere_normal)
    assert err.max() < 1e-4


def test_sphere_rays_from_inside(sphere_surface, rng):
    n = 1000
    o = rng.uniform(-0.6, 0.6, (n, 3))
    d = rng.normal(size=(n, 3))
    err = _check(sphere_surface, o, d, S.ray_sphere, S.sphere_normal)
    assert err.max() < 1e-5


def test_sphere_grazing_hits_and_misses(sphere_surface, rng):
    """Rays tangent to spheres of radius 1 +- delta: misses just outside, hits just inside."""
    n = 400
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(u, rng.normal(size=(n, 3)))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    for delta in (0.01, 0.004, 0.002, -0.002, -0.004, -0.01):
        o = (1 + delta) * u - 2 * w
        t, hit = mls.intersect(sphere_surface, o, w)
        te = S.ray_sphere(o, w)
        np.testing.assert_array_equal(hit, np.isfinite(te), err_msg=f"delta={delta}")
        if delta < 0:
            assert np.abs(t - te).max() < 1e-3


def test_torus_rays_from_outside_and_inside_the_tube(torus_surface, rng):
    n = 1500
    o = rng.normal(size=(n, 3))
    o *= 3 / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.uniform(-1.4, 1.4, (n, 3)) * [1, 1, 0.4] - o
    err = _check(torus_surface, o, d, S.ray_torus, S.torus_normal)
    assert err.max() < 1e-3
    th = rng.uniform(0, 2 * np.pi, n)
    o2 = np.c_[np.cos(th), np.sin(th), rng.uniform(-0.1, 0.1, n)] * [1.1, 1.1, 1]
    _check(torus_surface, o2, rng.normal(size=(n, 3)), S.ray_torus, S.torus_normal)


def test_torus_hole_and_grazing_rays(torus_surface):
    # down the axis through the hole: miss; down at rho = 1: hit the top of the tube at z = 0.35
    o = np.array([[0, 0, 2.0], [1.0, 0, 2.0], [0, 1.0, -2.0], [0.66, 0, 2.0], [0.64, 0, 2.0]])
    d = np.array([[0, 0, -1.0], [0, 0, -1], [0, 0, 1], [0, 0, -1], [0, 0, -1]])
    t, hit = mls.intersect(torus_surface, o, d)
    te = S.ray_torus(o, d)
    assert hit.tolist() == [False, True, True, True, False]
    np.testing.assert_allclose(t[hit], te[hit], atol=1e-3)
    # horizontal rays tangent to the outer equator (radius 1.35) and to the inner one (0.65)
    o = np.array([[1.35 + 0.005, -3, 0], [1.35 - 0.005, -3, 0], [0.65 - 0.005, -3, 0.0], [0.65 + 0.005, -3, 0]])
    d = np.tile([0, 1.0, 0], (4, 1))
    t, hit = mls.intersect(torus_surface, o, d)
    te = S.ray_torus(o, d)
    np.testing.assert_array_equal(hit, np.isfinite(te))
    np.testing.assert_allclose(t[hit], te[hit], atol=1e-3 / 0.1)  # grazing: error / sin(angle)


def test_tmax_and_single_origin_broadcast(sphere_surface):
    d = np.array([[0, 0, -1.0], [0, 0, -1.0], [0.0, 0.0, -2.0]])
    t, hit = mls.intersect(sphere_surface, [0, 0, 3.0], d, tmax=[2.5, 1.5, 1.5])
    assert hit.tolist() == [True, False, True]
    np.testing.assert_allclose(t[[0, 2]], [2.0, 1.0], atol=1e-6)
    t, hit = mls.intersect(sphere_surface, [0, 0, 3.0], [0, 0, -1.0], tmax=1.99)
    assert not hit[0] and np.isinf(t[0])


def test_origins_next_to_the_surface(sphere_surface):
    """Only hits with t > 0 count: rays leaving the surface miss, rays from just inside hit close by."""
    e = 1e-4
    o = np.array([[0, 0, 1 - e], [0, 0, 1 - e], [0, 0, 1 + e], [0, 0, 1 + e]])
    d = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0], [0, 0, -1.0]])
    t, hit = mls.intersect(sphere_surface, o, d)
    assert hit.tolist() == [True, True, False, True]
    np.testing.assert_allclose(t[hit], [e, 2 - e, e], atol=1e-6)


def test_open_surface_boundary():
    """A square patch: rays inside the samples hit, rays clearly outside the boundary miss."""
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 51), np.linspace(-1, 1, 51)), -1).reshape(-1, 2)
    plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.04))
    xs = np.array([0.0, 0.9, 0.99, 1.1, 1.2])
    o = np.c_[xs, np.zeros(5), np.ones(5)]
    t, hit = mls.intersect(plane, o, [0, 0, -1.0])
    assert hit.tolist() == [True, True, True, False, False]
    np.testing.assert_allclose(t[hit], 1.0, atol=1e-12)


def test_numba_equals_reference(small_sphere_surface, rng):
    n = 80
    o = rng.normal(size=(n, 3))
    o *= 2.5 / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.uniform(-1.2, 1.2, (n, 3)) - o
    t, hit = mls.intersect(small_sphere_surface, o, d)
    tr, hr = ref.intersect(small_sphere_surface, o, d)
    np.testing.assert_array_equal(hit, hr)
    np.testing.assert_allclose(t[hit], tr[hit], rtol=0, atol=1e-9)
    np.testing.assert_allclose(S.ray_sphere(o, d)[hit], t[hit], atol=5e-3)  # coarse sampling


def test_plane_fit_surface_is_consistent_with_projection(sphere_surface, rng):
    """With degree=1 the hits lie on the (biased) surface that project() returns."""
    surf = MLSSurface(sphere_surface.cloud, degree=1)
    o = rng.normal(size=(200, 3))
    o *= 3 / np.linalg.norm(o, axis=1, keepdims=True)
    d = -o + rng.uniform(-0.3, 0.3, (200, 3))
    t, hit = mls.intersect(surf, o, d)
    assert hit.all()
    x = o + t[:, None] * d
    p, _ = mls.project(surf, x)
    assert np.abs(p - x).max() < 1e-8


@pytest.mark.parametrize(
    ("args", "kwargs", "match"),
    [
        (([[0, 0, 3.0]], [[0, 0, 0.0]]), {}, "directions: expected non-zero vectors"),
        (([[0, 0, 3.0]] * 2, [[0, 0, 1.0]] * 3), {}, "expected the same number of rays"),
        (([[0, 0, 3.0]], [[0, 0, 1.0]]), {"tmax": 0.0}, "tmax: expected positive"),
        (([[0, 0, 3.0]], [[0, 0, 1.0]]), {"tmax": [1.0, 2.0]}, "tmax: expected 1 rows"),
        (([[0, 0, 3.0]], [[0, 0, 1.0]]), {"eps2": 0}, "eps2: expected a positive"),
        (([[0, 0, 3.0]], [[0, 0, 1.0]]), {"max_attempts": 0}, "max_attempts: expected a positive integer"),
        (([[0, 0, np.inf]], [[0, 0, 1.0]]), {}, "origins: expected finite"),
    ],
)
def test_bad_arguments(args, kwargs, match, small_sphere_surface):
    with pytest.raises(InputError, match=match):
        mls.intersect(small_sphere_surface, *args, **kwargs)
