"""Rigid-motion invariance of the MLS operators (hypothesis)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import mls
from unmesh.mls import MLSSurface

from . import samples as S

CLOUD = S.torus_cloud(0.06)
RNG = np.random.default_rng(7)
PTS, NRM = S.torus_surface_points(40, RNG)
X = PTS + RNG.uniform(-0.1, 0.1, (40, 1)) * NRM
O = RNG.normal(size=(40, 3))
O *= 2.5 / np.linalg.norm(O, axis=1, keepdims=True)
D = RNG.uniform(-1.2, 1.2, (40, 3)) * [1, 1, 0.3] - O
# Wendland weights go to zero continuously at the support, so round-off in which samples are
# within the support cannot change the result by more than round-off.
BASE = MLSSurface(CLOUD, kernel="wendland")
P0, N0 = mls.project(BASE, X)
T0, H0 = mls.intersect(BASE, O, D)
IN0 = mls.inside(BASE, X)


def _rotation(v):
    v = np.asarray(v, dtype=float)
    angle = np.linalg.norm(v)
    if angle < 1e-12:
        return np.eye(3)
    k = v / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


vec = st.tuples(*[st.floats(-3.0, 3.0)] * 3)


@settings(max_examples=15, deadline=None)
@given(rot=vec, shift=st.tuples(*[st.floats(-20.0, 20.0)] * 3))
def test_rigid_motion_invariance(rot, shift):
    assert 0 < H0.sum() < len(H0)
    R = _rotation(rot)
    s = np.asarray(shift)
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = s
    surf = MLSSurface(CLOUD.transformed(M), kernel="wendland")
    p, n = mls.project(surf, X @ R.T + s)
    np.testing.assert_allclose(p, P0 @ R.T + s, atol=1e-9)
    np.testing.assert_allclose(n, N0 @ R.T, atol=1e-9)
    np.testing.assert_array_equal(mls.inside(surf, X @ R.T + s), IN0)
    t, hit = mls.intersect(surf, O @ R.T + s, D @ R.T)
    np.testing.assert_array_equal(hit, H0)
    np.testing.assert_allclose(t[hit], T0[H0], atol=1e-9)
