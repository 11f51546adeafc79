"""3×3 algebra of the lattice pass (thesis eq. 8.24): SVD, polar decomposition, against numpy."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import _linalg_kernels as LA
from unmesh.sph import _polar_kernels as PK
from unmesh.sph.elastic import goal_matrix, rotation_svd


@settings(max_examples=40, deadline=None)
@given(dim=st.sampled_from([2, 3]), seed=st.integers(0, 10_000))
def test_numba_svd_matches_numpy(dim, seed):
    """svd_rot: A = U Σ Vᵀ with proper rotations; R and the goal matrix equal the numpy reference."""
    rng = np.random.default_rng(seed)
    a = np.eye(3) + 0.5 * rng.standard_normal((3, 3))
    if dim == 2:
        a[2, :] = a[:, 2] = 0.0
        a[2, 2] = 1.0
    u, s, v = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
    LA.svd_rot(a, dim, u, s, v, np.empty((4, 3, 3)))
    assert np.allclose(u @ np.diag(s) @ v.T, a, atol=1e-10)
    assert abs(np.linalg.det(u) - 1) < 1e-10 and abs(np.linalg.det(v) - 1) < 1e-10
    ur, sr, vr = rotation_svd(a, dim)
    assert np.allclose(u @ v.T, ur @ vr.T, atol=1e-9)
    assert np.allclose(goal_matrix(u, s, v, 0.6, dim), goal_matrix(ur, sr, vr, 0.6, dim), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 100_000), kind=st.sampled_from(["general", "near_rotation", "degenerate", "diagonal"]))
def test_unrolled_jacobi_is_bit_identical(seed, kind):
    """jacobi3 (registers) performs exactly the rotations of the shared jacobi_eigh: identical bits."""
    from unmesh._linalg_kernels import jacobi_eigh

    rng = np.random.default_rng(seed)
    if kind == "general":
        a = rng.standard_normal((3, 3))
    elif kind == "near_rotation":  # AᵀA ≈ I: nearly degenerate eigenvalues, as in a rigid lattice
        q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        a = q @ (np.eye(3) + 1e-6 * rng.standard_normal((3, 3)))
    elif kind == "degenerate":
        a = np.diag([1.0, 1.0, 2.0]) + np.diag([1e-9, 0.0], 1)
    else:
        a = np.diag(rng.uniform(0.5, 2.0, 3))
    # AᵀA summed as svd_rot sums it (so the svd_rot check below sees the same input)
    b = np.array([[(a[0, i] * a[0, j] + a[1, i] * a[1, j]) + a[2, i] * a[2, j] for j in range(3)] for i in range(3)])
    ref = b.copy()
    vec = np.empty((3, 3))
    jacobi_eigh(ref, vec)
    out = LA.jacobi3(*b.ravel())
    assert np.array_equal(np.array(out[:3]), np.diag(ref))
    assert np.array_equal(np.array(out[3:]).reshape(3, 3), vec)
    # and svd_rot (3D) takes V from it exactly as sym_eig3 does
    u, s, v = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
    LA.svd_rot(a, 3, u, s, v, np.empty((4, 3, 3)))
    v_ref, val = np.empty((3, 3)), np.empty(3)
    LA.sym_eig3(b, v_ref, val, np.empty((3, 3)))
    assert np.array_equal(v, v_ref)


def _lane_matrix(rng: np.random.Generator, kind: str, stretch: float) -> np.ndarray:
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.linalg.det(q))
    if kind == "stretched":  # nearly a rotation (the usual neighbourhood) up to large deformations
        return q @ (np.eye(3) + stretch * rng.standard_normal((3, 3)))
    if kind == "inverted":  # det A < 0
        return q @ np.diag([1.0, 1.0, -1.0]) @ (np.eye(3) + 0.1 * stretch * rng.standard_normal((3, 3)))
    if kind == "clamped":  # a singular value above SIG_HI
        return q @ np.diag([1.5 * PK.SIG_HI, 1.0, 0.8])
    return np.eye(3)  # an idle lane of the lattice pass


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 100_000), stretch=st.floats(0.0, 0.6),
       kinds=st.lists(st.sampled_from(["stretched", "stretched", "inverted", "clamped", "eye"]), min_size=8,
                      max_size=8))
def test_polar_lanes_match_the_svd(seed, stretch, kinds):
    """The polar decomposition of the lattice pass, a group of matrices at once: R = U Vᵀ and S = V Σ Vᵀ
    of the SVD (8.24) in every lane it accepts (det A > 0, every singular value strictly inside the
    clamps); the lanes it declines are inverted or have a Gershgorin disc of S at a clamp."""
    rng = np.random.default_rng(seed)
    mats = [_lane_matrix(rng, k, stretch) for k in kinds]
    lanes = np.ascontiguousarray(np.array([a.ravel() for a in mats]).T)  # (9, L), row-major entries
    rot, sym, fast = np.empty((9, 8)), np.empty((9, 8)), np.empty(8)
    PK.polar_lanes(lanes, rot, sym, fast, np.empty(8))
    for k, a in enumerate(mats):
        r, sm = rot[:, k].reshape(3, 3), sym[:, k].reshape(3, 3)
        u, s, v = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
        LA.svd_rot(a, 3, u, s, v, np.empty((4, 3, 3)))
        inside = np.linalg.det(a) > 0 and PK.SIG_LO < s.min() and s.max() < PK.SIG_HI
        if fast[k]:
            assert inside
            assert np.allclose(r, u @ v.T, atol=1e-12) and np.allclose(r @ r.T, np.eye(3), atol=1e-14)
            assert np.allclose(sm, v @ np.diag(s) @ v.T, atol=1e-12) and np.allclose(r @ sm, a, atol=1e-12)
        else:  # declined: A is inverted or a Gershgorin disc of S reaches a clamp
            assert kinds[k] != "eye"
            ref = v @ np.diag(s) @ v.T
            rad = np.abs(ref).sum(axis=1) - np.abs(np.diag(ref))
            assert (not inside or (np.diag(ref) - rad).min() < PK.SIG_LO * (1 + 1e-5)
                    or (np.diag(ref) + rad).max() > PK.SIG_HI * (1 - 1e-5))
