"""Inside/outside test (3.9, sign corrected) near sphere and torus."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import mls
from unmesh.surfels import SurfelCloud

from . import reference as ref
from . import samples as S
from .samples import H


@pytest.mark.parametrize("shape", ["sphere", "torus"])
def test_inside_outside_near_the_surface(shape, sphere_surface, torus_surface, rng):
    if shape == "sphere":
        surf, (pts, nrm) = sphere_surface, S.sphere_surface_points(5000, rng)
    else:
        surf, (pts, nrm) = torus_surface, S.torus_surface_points(5000, rng)
    # signed offsets along the normal from a tenth of a spacing to three spacings, both sides
    mag = rng.uniform(0.1 * H, 3 * H, len(pts))
    sign = rng.choice([-1.0, 1.0], len(pts))
    x = pts + (sign * mag)[:, None] * nrm
    got = mls.inside(surf, x)
    np.testing.assert_array_equal(got, sign < 0)


def test_printed_sign_of_3_9_would_be_wrong(small_sphere_surface):
    """(3.9) as printed, (Psi(x) - x).N > 0 => outside, calls a point outside the sphere inside."""
    x = np.array([[0.0, 0.0, 1.1]])
    p, n = mls.project(small_sphere_surface, x)
    assert float(((p - x) * n).sum()) < 0  # the printed criterion says "not outside"
    assert mls.inside(small_sphere_surface, x).tolist() == [False]


def test_far_points_use_the_nearest_sample(sphere_surface, torus_surface):
    assert mls.inside(sphere_surface, [[0, 0, 0], [0.3, 0.2, 0.1], [0, 0, 3.0], [5, 5, 5]]).tolist() == [
        True, True, False, False]
    # the hole of the torus is outside, the tube centre inside
    assert mls.inside(torus_surface, [[0, 0, 0], [1.0, 0, 0], [0, -1.0, 0.0], [0, 0, 1.0]]).tolist() == [
        False, True, True, False]


def test_numba_equals_reference(small_sphere_surface, rng):
    pts, nrm = S.sphere_surface_points(100, rng)
    x = pts + rng.uniform(-0.2, 0.2, (100, 1)) * nrm
    np.testing.assert_array_equal(mls.inside(small_sphere_surface, x), ref.inside(small_sphere_surface, x))


def test_open_plane():
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-1, 1, 41)), -1).reshape(-1, 2)
    plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.05))
    assert mls.inside(plane, [[0.1, 0.2, 0.01], [0.1, 0.2, -0.01], [0.3, 0.3, 0.0]]).tolist() == [False, True, True]
