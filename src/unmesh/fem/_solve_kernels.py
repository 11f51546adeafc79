"""Numba kernels of the implicit solve: 3×3-block sparse products and filtered PCG.

The filtered (projected) preconditioned conjugate gradient method of Baraff &
Witkin (1998) solves ``A v = b`` with per-node constraints: kind 0 free, kind 1
all three components prescribed, kind 2 the component along ``normal``
prescribed (ground contact). The initial guess must already satisfy the
constraints; the filter keeps every update in the free subspace.

The kernels release the GIL (``nogil``): the background refactorisation's thread
(:mod:`unmesh.fem.factor`) needs it briefly and often (scipy's SuperLU takes it for
each allocation), and would otherwise wait for each kernel of the main thread to end.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh._linalg_kernels import inv3


@njit(cache=True)
def _block_row(indptr, indices, blocks, x, i):
    """Row i of A x for a 3×3-block CSR matrix (blocks (nnz, 9), x (n, 3)): three floats."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    for k in range(indptr[i], indptr[i + 1]):
        j = indices[k]
        x0 = x[j, 0]
        x1 = x[j, 1]
        x2 = x[j, 2]
        a0 += blocks[k, 0] * x0 + blocks[k, 1] * x1 + blocks[k, 2] * x2
        a1 += blocks[k, 3] * x0 + blocks[k, 4] * x1 + blocks[k, 5] * x2
        a2 += blocks[k, 6] * x0 + blocks[k, 7] * x1 + blocks[k, 8] * x2
    return a0, a1, a2


@njit(cache=True, nogil=True, parallel=True)
def bsr_matvec(indptr, indices, blocks, x):
    """y = A x for a 3×3-block CSR matrix; x, y of shape (n, 3)."""
    n = indptr.shape[0] - 1
    y = np.empty((n, 3))  # every row written; np.zeros would be a parfor of its own
    for i in prange(n):
        # np.int64: the parfor's own index is unsigned, a second signature of _block_row otherwise
        y[i, 0], y[i, 1], y[i, 2] = _block_row(indptr, indices, blocks, x, np.int64(i))
    return y


@njit(cache=True, nogil=True)
def bsr_matvec_rows(indptr, indices, blocks, x, rows):
    """Rows ``rows`` (m,) of y = A x for a 3×3-block CSR matrix: (m, 3) (serial; reference: :func:`bsr_matvec`)."""
    m = rows.shape[0]
    y = np.zeros((m, 3))
    for t in range(m):
        y[t, 0], y[t, 1], y[t, 2] = _block_row(indptr, indices, blocks, x, rows[t])
    return y


@njit(cache=True)
def _filter(r, kind, normal):
    n = r.shape[0]
    for i in range(n):
        k = kind[i]
        if k == 1:
            r[i, 0] = 0.0
            r[i, 1] = 0.0
            r[i, 2] = 0.0
        elif k == 2:
            d = r[i, 0] * normal[0] + r[i, 1] * normal[1] + r[i, 2] * normal[2]
            r[i, 0] -= d * normal[0]
            r[i, 1] -= d * normal[1]
            r[i, 2] -= d * normal[2]


@njit(cache=True)
def _dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i, 0] * b[i, 0] + a[i, 1] * b[i, 1] + a[i, 2] * b[i, 2]
    return s


@njit(cache=True, parallel=True)
def _precond(pinv, r):
    n = r.shape[0]
    z = np.empty((n, 3))
    for i in prange(n):
        for a in range(3):
            z[i, a] = pinv[i, a, 0] * r[i, 0] + pinv[i, a, 1] * r[i, 1] + pinv[i, a, 2] * r[i, 2]
    return z


@njit(cache=True)
def block_jacobi(blocks, diag):
    """Inverses of the diagonal 3×3 blocks (identity where a block is singular).

    Closed-form cofactor inverse (:func:`unmesh._linalg_kernels.inv3`): ``np.linalg.det`` /
    ``inv`` brought LAPACK wrappers that cost more to compile than the whole kernel.
    """
    n = diag.shape[0]
    out = np.empty((n, 3, 3))
    for i in range(n):
        B = blocks[diag[i]].reshape(3, 3)
        det = inv3(B, out[i])
        if not abs(det) > 1e-300:
            for a in range(3):
                for b in range(3):
                    out[i, a, b] = 1.0 if a == b else 0.0
    return out


@njit(cache=True, nogil=True)
def filtered_pcg(indptr, indices, blocks, pinv, b, x0, kind, normal, tol, maxiter):
    """Filtered block-Jacobi PCG. Returns (x, iterations, relative residual)."""
    x = x0.copy()
    r = b - bsr_matvec(indptr, indices, blocks, x)
    _filter(r, kind, normal)
    fb = b.copy()
    _filter(fb, kind, normal)
    bnorm = np.sqrt(_dot(fb, fb))
    if bnorm == 0.0:
        bnorm = 1.0
    rnorm = np.sqrt(_dot(r, r))
    if rnorm <= tol * bnorm:
        return x, 0, rnorm / bnorm
    z = _precond(pinv, r)
    _filter(z, kind, normal)
    d = z.copy()
    delta = _dot(r, z)
    it = 0
    while it < maxiter:
        it += 1
        q = bsr_matvec(indptr, indices, blocks, d)
        _filter(q, kind, normal)
        dq = _dot(d, q)
        if dq <= 0.0:
            break
        alpha = delta / dq
        x += alpha * d
        r -= alpha * q
        rnorm = np.sqrt(_dot(r, r))
        if rnorm <= tol * bnorm:
            break
        z = _precond(pinv, r)
        _filter(z, kind, normal)
        dnew = _dot(r, z)
        beta = dnew / delta
        delta = dnew
        d = z + beta * d
    return x, it, rnorm / bnorm


@njit(cache=True, nogil=True, parallel=True)
def add_diagonal(blocks, diag, scale_k, masses, scale_m):
    """A = scale_k · K' + scale_m · diag(m) in place on the block array."""
    out = blocks * scale_k
    for i in prange(diag.shape[0]):
        k = diag[i]
        out[k, 0] += scale_m * masses[i]
        out[k, 4] += scale_m * masses[i]
        out[k, 8] += scale_m * masses[i]
    return out


@njit(cache=True, nogil=True)
def grow_mask(indptr, indices, mask, rings):
    """``mask`` (n,) bool grown by ``rings`` layers of neighbours (reference: :func:`unmesh.fem.solvers.grow`)."""
    out = mask.copy()
    for _ in range(rings):
        prev = out.copy()
        for i in range(prev.shape[0]):
            if prev[i]:
                for k in range(indptr[i], indptr[i + 1]):
                    out[indices[k]] = True
    return out


@njit(cache=True, nogil=True)
def sub_pattern(indptr, indices, nodes, n):
    """Pattern ``(indptr, indices)`` of the submatrix on the sorted node set ``nodes`` (m,), and the
    positions (nnz_sub,) of its blocks in the full pattern (reference: ``solvers._sub_block_array``)."""
    m = nodes.shape[0]
    local = np.full(n, -1, np.int64)
    for t in range(m):
        local[nodes[t]] = t
    ptr = np.zeros(m + 1, np.int64)
    for t in range(m):
        c = 0
        for k in range(indptr[nodes[t]], indptr[nodes[t] + 1]):
            if local[indices[k]] >= 0:
                c += 1
        ptr[t + 1] = ptr[t] + c
    idx = np.empty(ptr[m], np.int64)
    keep = np.empty(ptr[m], np.int64)
    for t in range(m):
        q = ptr[t]
        for k in range(indptr[nodes[t]], indptr[nodes[t] + 1]):
            j = local[indices[k]]
            if j >= 0:
                idx[q] = j
                keep[q] = k
                q += 1
    return ptr, idx, keep


@njit(cache=True, nogil=True)
def add_masses(blocks, diag, masses, scale_m):
    """blocks += scale_m · diag(m) in place (the mass term of :func:`add_diagonal`)."""
    for i in range(diag.shape[0]):
        k = diag[i]
        blocks[k, 0] += scale_m * masses[i]
        blocks[k, 4] += scale_m * masses[i]
        blocks[k, 8] += scale_m * masses[i]


@njit(cache=True, nogil=True)
def dot(a, b):
    """Σ a·b over (n,3) arrays (serial, no BLAS threads)."""
    return _dot(a, b)


@njit(cache=True, nogil=True)
def filter_inplace(r, kind, normal):
    """Zero the constrained components of r (n,3) in place."""
    _filter(r, kind, normal)


@njit(cache=True, nogil=True)
def cg_update(x, r, d, q, alpha):
    """x += α d, r -= α q (in place); returns |r|."""
    s = 0.0
    for i in range(x.shape[0]):
        for k in range(3):
            x[i, k] += alpha * d[i, k]
            r[i, k] -= alpha * q[i, k]
            s += r[i, k] * r[i, k]
    return np.sqrt(s)


@njit(cache=True, nogil=True)
def cg_direction(z, d, beta):
    """d = z + β d (in place)."""
    for i in range(d.shape[0]):
        for k in range(3):
            d[i, k] = z[i, k] + beta * d[i, k]


@njit(cache=True, nogil=True)
def filter_blocks(indptr, indices, blocks, kind, normal):
    """Blocks (nnz, 9) of ``S A S + (I - S)``: the matrix with the constraints of ``kind`` eliminated.

    ``S_i`` is 0 (kind 1), ``I - n nᵀ`` (kind 2) or I (kind 0); the numpy reference is in the tests.
    Releases the GIL (it runs in the background factorisation's thread too).
    """
    n = indptr.shape[0] - 1
    P = np.zeros((n, 3, 3))
    for i in range(n):
        for a in range(3):
            for b in range(3):
                if kind[i] == 0:
                    P[i, a, b] = 1.0 if a == b else 0.0
                elif kind[i] == 2:
                    P[i, a, b] = (1.0 if a == b else 0.0) - normal[a] * normal[b]
    out = np.empty_like(blocks)
    for i in range(n):
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if kind[i] == 0 and kind[j] == 0:
                for q in range(9):
                    out[k, q] = blocks[k, q]
                continue
            T = np.zeros((3, 3))
            for a in range(3):
                for b in range(3):
                    s = 0.0
                    for c in range(3):
                        s += blocks[k, 3 * a + c] * P[j, c, b]
                    T[a, b] = s
            for a in range(3):
                for b in range(3):
                    s = 0.0
                    for c in range(3):
                        s += P[i, a, c] * T[c, b]
                    if i == j:
                        s += (1.0 if a == b else 0.0) - P[i, a, b]
                    out[k, 3 * a + b] = s
    return out


@njit(cache=True, nogil=True)
def permuted_scalar_csr(indptr, indices, blocks, perm, scaled, data):
    """Scalar CSR ``(indptr (3n+1,), indices)`` of ``P A Pᵀ`` for a symmetric 3×3-block CSR matrix A.

    ``perm`` (n,): node order (row r of the result is node ``perm[r]``, its DOFs 3r..3r+2);
    with ``scaled``, A is scaled to a unit diagonal first, ``D^{-1/2} A D^{-1/2}``, and the
    scale ``D^{-1/2}`` (3n,) of the original DOFs is returned (ones otherwise). ``data``
    (9 nnz,) of the wanted dtype receives the values; indices are sorted within rows (so,
    A being symmetric, the arrays are its CSC too). Releases the GIL (it prepares the
    background factorisation). The reference is scipy's ``A[p][:, p]`` in the tests.
    """
    n = perm.shape[0]
    iperm = np.empty(n, np.int64)
    for r in range(n):
        iperm[perm[r]] = r
    scale = np.ones(3 * n)
    if scaled:
        for i in range(n):
            for k in range(indptr[i], indptr[i + 1]):
                if indices[k] == i:
                    for a in range(3):
                        scale[3 * i + a] = 1.0 / np.sqrt(blocks[k, 4 * a])
    ptr = np.zeros(3 * n + 1, np.int64)
    for r in range(n):
        m = indptr[perm[r] + 1] - indptr[perm[r]]
        for a in range(3):
            ptr[3 * r + a + 1] = ptr[3 * r + a] + 3 * m
    idx = np.empty(ptr[3 * n], np.int64)
    order = np.empty(64, np.int64)
    cols = np.empty(64, np.int64)
    for r in range(n):
        i = perm[r]
        m = indptr[i + 1] - indptr[i]
        if m > order.shape[0]:
            order = np.empty(2 * m, np.int64)
            cols = np.empty(2 * m, np.int64)
        for t in range(m):  # the row's blocks sorted by new column (insertion sort: rows are short)
            c = iperm[indices[indptr[i] + t]]
            q = t - 1
            while q >= 0 and cols[q] > c:
                cols[q + 1] = cols[q]
                order[q + 1] = order[q]
                q -= 1
            cols[q + 1] = c
            order[q + 1] = indptr[i] + t
        for a in range(3):
            o = ptr[3 * r + a]
            sa = scale[3 * i + a]
            for t in range(m):
                k = order[t]
                j = indices[k]
                for b in range(3):
                    idx[o + 3 * t + b] = 3 * cols[t] + b
                    data[o + 3 * t + b] = blocks[k, 3 * a + b] * sa * scale[3 * j + b]
    return ptr, idx, scale
