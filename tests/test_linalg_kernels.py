"""The shared small dense linear algebra (:mod:`unmesh._linalg_kernels`) against numpy."""

import numpy as np
import pytest

from unmesh._linalg_kernels import (
    inv3,
    jacobi_eigh,
    jacobi_eigh4,
    smallest_eigenvector,
    smallest_eigenvectors,
    sym_adjugate,
)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_jacobi_matches_eigh(rng, n):
    for _ in range(50):
        a = rng.normal(size=(n, n))
        a = a + a.T
        b = a.copy()
        v = np.empty((n, n))
        jacobi_eigh(b, v)
        w = np.diag(b)
        np.testing.assert_allclose(np.sort(w), np.linalg.eigvalsh(a), atol=1e-12 * np.abs(a).max())
        np.testing.assert_allclose(v.T @ v, np.eye(n), atol=1e-13)
        np.testing.assert_allclose(a @ v, v * w, atol=1e-12 * np.abs(a).max())


def test_zero_and_diagonal_matrices():
    v = np.empty((3, 3))
    b = np.zeros((3, 3))
    jacobi_eigh(b, v)
    np.testing.assert_array_equal(v, np.eye(3))
    b = np.diag([3.0, 1.0, 2.0])
    jacobi_eigh(b, v)
    np.testing.assert_array_equal(np.diag(b), [3.0, 1.0, 2.0])


def test_jacobi_eigh4_matches_eigh(rng):
    a = rng.normal(size=(4, 4))
    a = a + a.T
    w, v = jacobi_eigh4(a)
    np.testing.assert_allclose(np.sort(w), np.linalg.eigvalsh(a), atol=1e-12 * np.abs(a).max())
    np.testing.assert_allclose(a @ v, v * w, atol=1e-12 * np.abs(a).max())


def test_inverse_and_adjugate_match_numpy(rng):
    for _ in range(50):
        m = rng.normal(size=(3, 3))
        out = np.empty((3, 3))
        det = inv3(m, out)
        np.testing.assert_allclose(det, np.linalg.det(m), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(out, np.linalg.inv(m), rtol=1e-9, atol=1e-9 * np.abs(np.linalg.inv(m)).max())
        s = m + m.T
        c00, c01, c02, c11, c12, c22, d = sym_adjugate(s[0, 0], s[0, 1], s[0, 2], s[1, 1], s[1, 2], s[2, 2])
        adj = np.array([[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]])
        np.testing.assert_allclose(d, np.linalg.det(s), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(adj, np.linalg.det(s) * np.linalg.inv(s), rtol=1e-9, atol=1e-9 * np.abs(adj).max())
    out = np.full((3, 3), 7.0)
    assert inv3(np.zeros((3, 3)), out) == 0.0 and (out == 7.0).all()


def test_smallest_eigenvector_matches_eigh(rng):
    a = rng.normal(size=(200, 3, 3))
    cov = a @ a.transpose(0, 2, 1)
    v = smallest_eigenvectors(cov)
    ref = np.linalg.eigh(cov)[1][:, :, 0]
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", v, ref)), 1.0, atol=1e-8)
    assert smallest_eigenvector(0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == (0.0, 0.0, 1.0)
    vx, vy, vz = smallest_eigenvector(1.0, 0.0, 0.0, 1.0, 0.0, 0.0)     # diag(1, 1, 0)
    assert (vx, vy, abs(vz)) == (0.0, 0.0, 1.0)
