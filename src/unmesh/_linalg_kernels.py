"""Small dense linear algebra shared by numba kernels of several capabilities.

:func:`jacobi_eigh` diagonalises a small symmetric matrix in place by cyclic Jacobi rotations
(Golub & Van Loan, section 8.5); it serves the polar decompositions of SPH shape matching
(thesis 8.24, 3×3) and Horn's absolute orientation for FEM stiffness warping (9.1.4, 4×4).
Reference: ``numpy.linalg.eigh`` (``tests/test_linalg_kernels.py``).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def jacobi_eigh(b, vec, sweeps=30):  # pragma: no cover - numba
    """Diagonalise the symmetric (n, n) ``b`` in place; ``vec`` (n, n) receives the eigenvectors.

    On return ``b[k, k]`` are the eigenvalues (unsorted) and column ``k`` of ``vec`` the unit
    eigenvector of ``b[k, k]``. Stops when the off-diagonal mass is below ``1e-32`` of the
    diagonal's (or zero), after at most ``sweeps`` sweeps.

    Example
    -------
    >>> import numpy as np
    >>> b, v = np.diag([3.0, 1.0, 2.0]), np.empty((3, 3))
    >>> jacobi_eigh(b, v); sorted(np.diag(b).tolist())
    [1.0, 2.0, 3.0]
    """
    n = b.shape[0]
    for p in range(n):
        for q in range(n):
            vec[p, q] = 1.0 if p == q else 0.0
    for _sweep in range(sweeps):
        off = 0.0
        diag = 0.0
        for p in range(n):
            diag += b[p, p] * b[p, p]
            for q in range(p + 1, n):
                off += b[p, q] * b[p, q]
        if off <= 1e-32 * diag or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = b[p, q]
                if apq == 0.0:
                    continue
                theta = (b[q, q] - b[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):  # b = b J
                    bkp = b[k, p]
                    bkq = b[k, q]
                    b[k, p] = c * bkp - s * bkq
                    b[k, q] = s * bkp + c * bkq
                for k in range(n):  # b = J^T b
                    bpk = b[p, k]
                    bqk = b[q, k]
                    b[p, k] = c * bpk - s * bqk
                    b[q, k] = s * bpk + c * bqk
                for k in range(n):
                    vkp = vec[k, p]
                    vkq = vec[k, q]
                    vec[k, p] = c * vkp - s * vkq
                    vec[k, q] = s * vkp + c * vkq
