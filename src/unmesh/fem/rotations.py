"""Per-element rotations for stiffness warping: Horn's closed-form absolute orientation.

Horn (1987) finds the rotation R minimising ``Σ_i w_i |R X_i' - x_i'|²`` (primes:
centred on the weighted centroids) as the unit quaternion that is the
eigenvector of the largest eigenvalue of a symmetric 4×4 matrix built from the
cross-covariance ``S = Σ w_i X_i' x_i'ᵀ``. Unlike polar decomposition of a
deformation gradient it needs no inverse, so it is stable for flat (coplanar)
elements (thesis 9.1.4). The 4×4 eigenproblem is solved by cyclic Jacobi
rotations (numba), checked against ``numpy.linalg.eigh`` in the tests.

Example
-------
>>> import numpy as np
>>> X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)  # flat element
>>> c, s = np.cos(0.3), np.sin(0.3)
>>> R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
>>> Rh = horn_rotations(X, X @ R.T + 5.0, np.array([0, 4]), np.arange(4))
>>> bool(np.allclose(Rh[0], R))
True
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from unmesh._linalg_kernels import jacobi_eigh
from unmesh._validate import as_array, as_points

__all__ = ["horn_matrix", "horn_rotations", "jacobi_eigh4", "quaternion_to_matrix"]


@njit(cache=True)
def jacobi_eigh4(N):
    """Eigenvalues (4,) and eigenvectors (columns, 4×4) of a symmetric 4×4 matrix (cyclic Jacobi).

    Example
    -------
    >>> import numpy as np
    >>> w, v = jacobi_eigh4(np.diag([1.0, 4.0, 2.0, 3.0]))
    >>> sorted(w.tolist())
    [1.0, 2.0, 3.0, 4.0]
    """
    A = N.copy()
    V = np.empty((4, 4))
    jacobi_eigh(A, V)
    w = np.empty(4)
    for i in range(4):
        w[i] = A[i, i]
    return w, V


@njit(cache=True)
def horn_matrix(S):
    """Horn's symmetric 4×4 matrix N of the cross-covariance S_ab = Σ w X'_a x'_b.

    Example
    -------
    >>> import numpy as np
    >>> horn_matrix(np.eye(3))[0].tolist()
    [3.0, 0.0, 0.0, 0.0]
    """
    Sxx, Sxy, Sxz = S[0, 0], S[0, 1], S[0, 2]
    Syx, Syy, Syz = S[1, 0], S[1, 1], S[1, 2]
    Szx, Szy, Szz = S[2, 0], S[2, 1], S[2, 2]
    return np.array((
        (Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx),
        (Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz),
        (Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy),
        (Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz),
    ))


@njit(cache=True)
def quaternion_to_matrix(q):
    """Rotation matrix of a unit quaternion (w, x, y, z).

    Example
    -------
    >>> import numpy as np
    >>> quaternion_to_matrix(np.array([1.0, 0.0, 0.0, 0.0])).tolist() == np.eye(3).tolist()
    True
    """
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    return np.array((
        (q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)),
        (2 * (q2 * q1 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)),
        (2 * (q3 * q1 - q0 * q2), 2 * (q3 * q2 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3),
    ))


@njit(cache=True, parallel=True)
def _horn_all(rest, cur, node_off, nodes, weights):
    ne = node_off.shape[0] - 1
    out = np.empty((ne, 3, 3))
    for e in prange(ne):
        a0 = node_off[e]
        a1 = node_off[e + 1]
        wsum = 0.0
        cX = np.zeros(3)
        cx = np.zeros(3)
        for k in range(a0, a1):
            w = weights[k]
            wsum += w
            cX += w * rest[nodes[k]]
            cx += w * cur[nodes[k]]
        cX /= wsum
        cx /= wsum
        S = np.zeros((3, 3))
        for k in range(a0, a1):
            w = weights[k]
            X = rest[nodes[k]] - cX
            x = cur[nodes[k]] - cx
            for a in range(3):
                for b in range(3):
                    S[a, b] += w * X[a] * x[b]
        vals, vecs = jacobi_eigh4(horn_matrix(S))
        best = 0
        for i in range(1, 4):
            if vals[i] > vals[best]:
                best = i
        q = vecs[:, best].copy()
        q /= np.sqrt((q * q).sum())
        out[e] = quaternion_to_matrix(q)
    return out


def horn_rotations(rest: Any, current: Any, node_offsets: Any, nodes: Any, weights: Any | None = None) -> np.ndarray:
    """Best-fit rotation of every element from rest to current positions (Horn 1987).

    Parameters
    ----------
    rest, current : (n, 3) float arrays
        Rest and current node positions.
    node_offsets, nodes : int arrays
        CSR of each element's nodes.
    weights : (Σn,) float array, optional
        Per element-node weights (e.g. the volume fractions μ of 9.17); uniform if omitted.

    Returns
    -------
    (E, 3, 3) float64
        Proper rotations R_e with ``R_e X' ≈ x'``.

    Example
    -------
    >>> import numpy as np
    >>> X = np.random.default_rng(0).normal(size=(5, 3))
    >>> R = horn_rotations(X, X, [0, 5], np.arange(5))
    >>> bool(np.allclose(R[0], np.eye(3)))
    True
    """
    X = as_points(rest, "rest")
    x = as_points(current, "current", length=len(X))
    off = as_array(node_offsets, "node_offsets", (None,), np.int64)
    nd = as_array(nodes, "nodes", (None,), np.int64)
    w = np.ones(len(nd)) if weights is None else as_array(weights, "weights", (len(nd),))
    return _horn_all(X, x, off, nd, w)
