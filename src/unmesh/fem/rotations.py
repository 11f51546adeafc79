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

from unmesh._linalg_kernels import jacobi_eigh, jacobi_eigh4
from unmesh._validate import as_array, as_points

__all__ = ["horn_matrix", "horn_rotations", "jacobi_eigh4", "piece_rotations", "polar_rotations", "quaternion_to_matrix"]


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


#: Elements per parallel chunk of :func:`_horn_all` (its work arrays are allocated once per chunk).
_CHUNK = 256


@njit(cache=True, nogil=True)
def _horn_chunk(ch, rest, cur, node_off, nodes, weights, out):
    """Rotations of the elements of chunk ``ch`` (body of :func:`_horn_all`)."""
    ne = node_off.shape[0] - 1
    N = np.empty((4, 4))
    V = np.empty((4, 4))
    q = np.empty(4)
    for e in range(ch * _CHUNK, min(ne, (ch + 1) * _CHUNK)):
        a0 = node_off[e]
        a1 = node_off[e + 1]
        wsum = 0.0
        cX0 = cX1 = cX2 = 0.0
        cx0 = cx1 = cx2 = 0.0
        for k in range(a0, a1):
            w = weights[k]
            i = nodes[k]
            wsum += w
            cX0 += w * rest[i, 0]
            cX1 += w * rest[i, 1]
            cX2 += w * rest[i, 2]
            cx0 += w * cur[i, 0]
            cx1 += w * cur[i, 1]
            cx2 += w * cur[i, 2]
        cX0 /= wsum
        cX1 /= wsum
        cX2 /= wsum
        cx0 /= wsum
        cx1 /= wsum
        cx2 /= wsum
        Sxx = Sxy = Sxz = Syx = Syy = Syz = Szx = Szy = Szz = 0.0
        for k in range(a0, a1):
            w = weights[k]
            i = nodes[k]
            X0 = w * (rest[i, 0] - cX0)
            X1 = w * (rest[i, 1] - cX1)
            X2 = w * (rest[i, 2] - cX2)
            x0 = cur[i, 0] - cx0
            x1 = cur[i, 1] - cx1
            x2 = cur[i, 2] - cx2
            Sxx += X0 * x0
            Sxy += X0 * x1
            Sxz += X0 * x2
            Syx += X1 * x0
            Syy += X1 * x1
            Syz += X1 * x2
            Szx += X2 * x0
            Szy += X2 * x1
            Szz += X2 * x2
        # Horn's matrix (as :func:`horn_matrix`), written into the chunk's work array
        N[0, 0] = Sxx + Syy + Szz
        N[0, 1] = N[1, 0] = Syz - Szy
        N[0, 2] = N[2, 0] = Szx - Sxz
        N[0, 3] = N[3, 0] = Sxy - Syx
        N[1, 1] = Sxx - Syy - Szz
        N[1, 2] = N[2, 1] = Sxy + Syx
        N[1, 3] = N[3, 1] = Szx + Sxz
        N[2, 2] = -Sxx + Syy - Szz
        N[2, 3] = N[3, 2] = Syz + Szy
        N[3, 3] = -Sxx - Syy + Szz
        jacobi_eigh(N, V)
        best = 0
        for i in range(1, 4):
            if N[i, i] > N[best, best]:
                best = i
        nq = 0.0
        for i in range(4):
            q[i] = V[i, best]
            nq += q[i] * q[i]
        nq = np.sqrt(nq)
        q0, q1, q2, q3 = q[0] / nq, q[1] / nq, q[2] / nq, q[3] / nq
        # as :func:`quaternion_to_matrix`
        out[e, 0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
        out[e, 0, 1] = 2 * (q1 * q2 - q0 * q3)
        out[e, 0, 2] = 2 * (q1 * q3 + q0 * q2)
        out[e, 1, 0] = 2 * (q2 * q1 + q0 * q3)
        out[e, 1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
        out[e, 1, 2] = 2 * (q2 * q3 - q0 * q1)
        out[e, 2, 0] = 2 * (q3 * q1 - q0 * q2)
        out[e, 2, 1] = 2 * (q3 * q2 + q0 * q1)
        out[e, 2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3


@njit(cache=True, nogil=True, parallel=True)
def _horn_all(rest, cur, node_off, nodes, weights):
    ne = node_off.shape[0] - 1
    out = np.empty((ne, 3, 3))
    nchunk = (ne + _CHUNK - 1) // _CHUNK
    # a thin prange loop over a serial body (typed once, not again inside the parfor)
    for ch in prange(nchunk):
        _horn_chunk(np.int64(ch), rest, cur, node_off, nodes, weights, out)
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


def piece_rotations(rest: Any, current: Any, weights: Any, labels: Any, n_pieces: int) -> np.ndarray:
    """Best-fit rotation of each connected piece from its rest to its current node positions.

    For piece p, the rotation R_p maximising ``Σ_i w_i (x_i - c)·R_p (X_i - C)`` over
    its nodes (weighted centroids c, C): the rotation factor of the polar decomposition
    of the weighted cross-covariance ``F = Σ_i w_i (x_i - c)(X_i - C)ᵀ`` (the same
    absolute-orientation problem as Horn's method, solved here by one SVD per piece).
    It is the rotation of the preconditioner of the implicit solve
    (:mod:`unmesh.fem.solvers`): a rigid motion of a piece is rotated exactly, and
    the rotation is constant on each piece, so the translations of the current
    configuration stay in the near-null space of the rotated rest-frame matrix.

    Parameters
    ----------
    rest, current : (n, 3) float64
        Rest and current node positions.
    weights : (n,) float64
        Node weights (masses); pieces of zero total weight get the identity.
    labels : (n,) int
        Piece of each node, ``0 <= labels < n_pieces``.
    n_pieces : int

    Returns
    -------
    (n_pieces, 3, 3) float64
        Proper rotations (det +1).

    Example
    -------
    >>> import numpy as np
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    >>> c, s = np.cos(0.5), np.sin(0.5)
    >>> R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    >>> Q = piece_rotations(X, X @ R.T + 2.0, np.ones(4), np.zeros(4, int), 1)
    >>> bool(np.allclose(Q[0], R))
    True
    """
    X = as_points(rest, "rest")
    x = as_array(current, "current", X.shape)
    w = as_array(weights, "weights", (len(X),))
    lab = np.asarray(labels, dtype=np.int64)
    npc = int(n_pieces)
    tot = np.bincount(lab, weights=w, minlength=npc)
    safe = np.where(tot > 0, tot, 1.0)
    cen_x = np.stack([np.bincount(lab, weights=w * x[:, k], minlength=npc) for k in range(3)], axis=1) / safe[:, None]
    cen_X = np.stack([np.bincount(lab, weights=w * X[:, k], minlength=npc) for k in range(3)], axis=1) / safe[:, None]
    dx = x - cen_x[lab]
    dX = X - cen_X[lab]
    F = np.empty((npc, 3, 3))
    for a in range(3):
        wa = w * dx[:, a]
        for b in range(3):
            F[:, a, b] = np.bincount(lab, weights=wa * dX[:, b], minlength=npc)
    q = polar_rotations(F)
    q[~(tot > 0) | ~np.isfinite(q).all(axis=(1, 2))] = np.eye(3)
    return q


def polar_rotations(F: np.ndarray) -> np.ndarray:
    """Proper rotation factors of the polar decompositions of a stack of 3×3 matrices.

    ``F`` (k, 3, 3) float64 → (k, 3, 3): the rotation R closest to each ``F`` in the
    Frobenius norm with det R = +1 (``U Vᵀ`` of the SVD, the last singular direction
    flipped where ``det U Vᵀ < 0``).

    Example
    -------
    >>> import numpy as np
    >>> polar_rotations(np.diag([2.0, 3.0, -1.0])[None]).round(12).tolist()
    [[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]]
    """
    u, _, vt = np.linalg.svd(F)
    q = u @ vt
    flip = np.linalg.det(q) < 0
    if flip.any():
        u[flip, :, 2] *= -1
        q[flip] = u[flip] @ vt[flip]
    return q
