"""The shared cyclic Jacobi eigensolver against numpy.linalg.eigh."""

import numpy as np
import pytest

from unmesh._linalg_kernels import jacobi_eigh


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
