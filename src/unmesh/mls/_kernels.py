"""Numba kernels of the MLS surface (thesis section 3.1).

Samples are bucketed into *support levels* (power-of-two bands of the support
``cutoff·σ_i``, :func:`unmesh.mls.surface.size_levels`), each with its own
:class:`unmesh.spatial.CellGrid` whose cell edge is the level's largest support plus a
margin ``m``. Per-sample data is in *kernel order* (level after level, each level
sorted by cell) in one packed array ``gpack`` (N, 10): columns 0–2 position, 3–5
unit normal, 6 squared support ``(cutoff·σ_i)²``, 7 ``1/σ_i²`` (Gaussian) or
``1/(cutoff·σ_i)`` (Wendland), 8 σ_i, 9 support ``cutoff·σ_i``; ``grho`` (N,) are the
disc radii for ray starts. The level grids (``lv_*``): ``lv_origin`` (L,3),
``lv_inv`` (L,) inverse cell edges, ``lv_dims`` (L,3), and the concatenated sorted
non-empty cell keys ``lv_keys`` of all levels (level ℓ:
``lv_keys[lv_koff[ℓ]:lv_koff[ℓ+1]]``) with their starts ``lv_start`` (level ℓ:
``lv_start[lv_koff[ℓ]+ℓ : lv_koff[ℓ+1]+ℓ+1]``, already offset to kernel order).
Cells are found with the helpers of :mod:`unmesh.spatial._kernels`.

Neighbour gathering (:func:`gather`): the candidates around a centre c are the
samples with ``‖c − x_i‖ < cutoff·σ_i + m``, found in the 27-cell stencil of c in
every level grid, and copied with their data into a work buffer. They hold every
sample whose kernel reaches any point within m of c, so the iterations of a
projection or a ray, and neighbouring queries of a work item, reuse one candidate
list (:func:`refresh`) while they stay within m of its centre. Candidates come out in
ascending kernel order whatever the centre (stencil rows are visited in key order),
so a fit gives bit-identical results however its list was gathered.

Options (integers so that they can be passed to numba):
``kernel`` 0 = clipped Gaussian (3.11), 1 = Wendland C² (3.12) with support
``cutoff·σ_i``; ``normal_mode`` 0 = Hermite normal (3.8), 1 = covariance normal
(3.5); ``degree`` 1 = plane only (3.7), 2 = plus a quadratic height field (3.3, 3.4).

The local fit at a point x (:func:`local_fit`) writes into ``res``:
``res[0:3]`` foot point p, ``res[3:6]`` unit normal n, ``res[6:9]`` weighted mean
q (3.6), ``res[9]`` weight sum, ``res[10]`` mean σ of the neighbours, ``res[11]``
neighbour count. ``p − x`` is parallel to ``n``.

Ray casting (Algorithm 3.1) builds on these in :mod:`unmesh.mls._ray_kernels`.

The plain numpy reference implementation is ``tests/mls/reference.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh._linalg_kernels import smallest_eigenvector
from unmesh.spatial._kernels import point_cell, stencil_ranges

#: Status codes of :func:`project_kernel`.
CONVERGED, NOT_CONVERGED, NO_NEIGHBORS, LOST = 0, 1, 2, 3

_BLOCK = 64  # queries per parallel work item (work arrays are allocated per item)
_CAP = 1024  # initial candidate buffer of a work item (grown on demand)
_SLACK = 1.0 + 1e-9  # relative slack of the candidate test (round-off in the kernels' cut-off tests)


@njit(cache=True, inline="always")
def _wrow(d2, cut2, inv, kernel):
    """MLS weight w(d²) (3.11 or 3.12) from precomputed ``cut2 = (cutoff·σ)²`` and ``inv``
    (``1/σ²`` for the Gaussian, ``1/(cutoff·σ)`` for Wendland), without a division.

    Equals ``clipped_gaussian_w(d2, σ, cutoff)`` / ``wendland_c2_w(√d2, cutoff·σ)`` of
    :mod:`unmesh.kernels._kernels` up to round-off; the Gaussian is cut exactly where
    ``clipped_gaussian_w`` cuts it.
    """
    if d2 >= cut2:
        return 0.0
    if kernel == 0:
        return math.exp(-d2 * inv)
    u = math.sqrt(d2) * inv
    if u >= 1.0:
        return 0.0
    b = 1.0 - u
    return b * b * b * b * (1.0 + 4.0 * u)


@njit(cache=True)
def tangent_frame(nx, ny, nz):
    """Orthonormal tangents t1, t2 with t1 × t2 = n (Duff et al. 2017, branchless)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@njit(cache=True)
def solve_spd(A, b, n):
    """Solve A x = b (n×n symmetric positive definite, upper triangle used) in place.

    Cholesky; returns False when a pivot is below 1e-12 of the largest diagonal
    entry (rank-deficient fit). ``b`` receives the solution.
    """
    dmax = 0.0
    for i in range(n):
        dmax = max(dmax, A[i, i])
    if dmax <= 0.0:
        return False
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[k, j] * A[k, j]
        if s <= 1e-12 * dmax:
            return False
        d = math.sqrt(s)
        A[j, j] = d
        for i in range(j + 1, n):
            t = A[j, i]
            for k in range(j):
                t -= A[k, j] * A[k, i]
            A[j, i] = t / d
    # forward: U^T y = b
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= A[k, i] * b[k]
        b[i] = t / A[i, i]
    # backward: U x = y
    for i in range(n - 1, -1, -1):
        t = b[i]
        for k in range(i + 1, n):
            t -= A[i, k] * b[k]
        b[i] = t / A[i, i]
    return True


# -- neighbour gathering -----------------------------------------------------------------


@njit(cache=True)
def gather(c, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, ranges, cand, cbuf):
    """Candidates around ``c`` (3,): samples with ``‖c − x_i‖ < cutoff·σ_i + margin``, ascending.

    Writes the sample indices into ``cand`` and their rows of ``gpack`` (columns 0–8)
    into ``cbuf`` and returns how many candidates there are; a count of ``len(cand)``
    or more means the buffers were too small (their contents are then invalid).
    ``ranges`` is a (9, 2) int64 work array.
    """
    last = cand.shape[0] - 1
    n = 0
    c0, c1, c2 = c[0], c[1], c[2]
    for lv in range(lv_inv.shape[0]):
        k0 = lv_koff[lv]
        k1 = lv_koff[lv + 1]
        dims = lv_dims[lv]
        i, j, k = point_cell(c, lv_origin[lv], lv_inv[lv], dims)
        ns = stencil_ranges(i, j, k, 1, dims, lv_keys[k0:k1], lv_start[k0 + lv:k1 + lv + 1], ranges)
        for s in range(ns):
            for a in range(ranges[s, 0], ranges[s, 1]):
                dx = gpack[a, 0] - c0
                dy = gpack[a, 1] - c1
                dz = gpack[a, 2] - c2
                r = (gpack[a, 9] + margin) * _SLACK
                # branch-free compaction (the test fails unpredictably for a third of the samples)
                cand[min(n, last)] = a
                n += dx * dx + dy * dy + dz * dz < r * r
    for m in range(min(n, last + 1)):
        a = cand[m]
        for t in range(9):
            cbuf[m, t] = gpack[a, t]
    return n


@njit(cache=True)
def refresh(x, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, ranges,
            cand, cbuf, nbuf, centre, meta):
    """Make the candidate list valid for ``x``: keep it when ``x`` is within ``margin`` of its centre.

    ``meta[0]`` = number of candidates, ``meta[1]`` = 1 when the list is valid;
    ``centre`` (3,) its gather point. Returns the work buffers ``(cand, cbuf, nbuf)``,
    reallocated (1.5× the need) when the candidates do not fit.
    """
    if meta[1] != 0:
        dx = x[0] - centre[0]
        dy = x[1] - centre[1]
        dz = x[2] - centre[2]
        if dx * dx + dy * dy + dz * dz <= margin * margin:
            return cand, cbuf, nbuf
    n = gather(x, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, ranges, cand, cbuf)
    if n >= cand.shape[0]:
        cand, cbuf, nbuf = work_buffers(n + n // 2 + 1)
        n = gather(x, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, ranges, cand, cbuf)
    meta[0] = n
    meta[1] = 1
    centre[0] = x[0]
    centre[1] = x[1]
    centre[2] = x[2]
    return cand, cbuf, nbuf


@njit(cache=True)
def work_buffers(size):
    """Candidate indices (size,) int64, candidate rows (size, 9) and neighbour rows (size, 4) float64."""
    return np.empty(size, np.int64), np.empty((size, 9)), np.empty((size, 4))


@njit(cache=True)
def block_scratch():
    """The per-block scratch of the projection and ray kernels: cell ``ranges`` (9, 2) int64, normal
    equations ``A`` (6, 6) and ``rhs`` (6,), fit results ``res`` (12,), the :func:`work_buffers` of
    :data:`_CAP` rows, a ``centre`` (3,) and ``meta`` (2,) int64 (zeroed)."""
    cand, cbuf, nbuf = work_buffers(np.int64(_CAP))  # int64, not a literal: one signature
    return (np.empty((9, 2), np.int64), np.empty((6, 6)), np.empty(6), np.empty(12), cand, cbuf, nbuf, np.empty(3),
            np.zeros(2, np.int64))


# -- local fit -------------------------------------------------------------------------------


@njit(cache=True)
def _quadratic(nbuf, cnt, ex, ey, ez, nx, ny, nz, isl, A, rhs):
    """Weighted normal equations of the height field ``z = a + b u + c v + d u² + e uv + f v²`` (3.3).

    ``nbuf[:cnt]`` holds the neighbours' offsets from x and weights; ``(u, v, z)`` are
    their coordinates in the frame at ``o = x + e`` with normal n, u and v in units of
    ``1/isl``. ``A = Σ w φ φᵀ`` (φ = (1, u, v, u², uv, v²)) is assembled from the 15
    moments ``Σ w u^i v^j`` (i + j <= 4), ``rhs = Σ w z φ``. Returns the tangents (t1, t2).
    """
    t1, t2 = tangent_frame(nx, ny, nz)
    m00 = m10 = m01 = m20 = m11 = m02 = 0.0
    m30 = m21 = m12 = m03 = m40 = m31 = m22 = m13 = m04 = 0.0
    r0 = r1 = r2 = r3 = r4 = r5 = 0.0
    for m in range(cnt):
        rx = nbuf[m, 0] - ex
        ry = nbuf[m, 1] - ey
        rz = nbuf[m, 2] - ez
        w = nbuf[m, 3]
        u = (t1[0] * rx + t1[1] * ry + t1[2] * rz) * isl
        v = (t2[0] * rx + t2[1] * ry + t2[2] * rz) * isl
        z = nx * rx + ny * ry + nz * rz
        wu = w * u
        wv = w * v
        wuu = wu * u
        wuv = wu * v
        wvv = wv * v
        m00 += w
        m10 += wu
        m01 += wv
        m20 += wuu
        m11 += wuv
        m02 += wvv
        m30 += wuu * u
        m21 += wuu * v
        m12 += wvv * u
        m03 += wvv * v
        m40 += wuu * u * u
        m31 += wuu * u * v
        m22 += wuu * v * v
        m13 += wvv * u * v
        m04 += wvv * v * v
        wz = w * z
        r0 += wz
        r1 += wz * u
        r2 += wz * v
        r3 += wz * u * u
        r4 += wz * u * v
        r5 += wz * v * v
    A[0, 0], A[0, 1], A[0, 2], A[0, 3], A[0, 4], A[0, 5] = m00, m10, m01, m20, m11, m02
    A[1, 1], A[1, 2], A[1, 3], A[1, 4], A[1, 5] = m20, m11, m30, m21, m12
    A[2, 2], A[2, 3], A[2, 4], A[2, 5] = m02, m21, m12, m03
    A[3, 3], A[3, 4], A[3, 5] = m40, m31, m22
    A[4, 4], A[4, 5] = m22, m13
    A[5, 5] = m04
    rhs[0], rhs[1], rhs[2], rhs[3], rhs[4], rhs[5] = r0, r1, r2, r3, r4, r5
    return t1, t2


@njit(cache=True)
def local_fit(x, kernel, normal_mode, degree, cbuf, ncand, nbuf, A, rhs, res):
    """MLS fit at point ``x`` (3,): plane (3.5, 3.6, 3.8) and optional quadratic (3.3, 3.4).

    ``cbuf[:ncand]`` (rows of ``gpack``, see :func:`gather`) must hold every sample
    whose kernel reaches ``x``, in ascending sample order; ``nbuf`` (at least as
    long, 4 columns) receives the neighbours' offsets from x and weights
    (:func:`_wrow`). Returns False when no sample's kernel reaches ``x`` (or the
    normals cancel); otherwise fills ``res`` (see the module docstring). Only the
    upper triangle of ``A`` (6×6) is used.
    """
    x0, x1, x2 = x[0], x[1], x[2]
    wsum = 0.0
    mx = my = mz = 0.0
    hx = hy = hz = 0.0
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    ssum = 0.0
    cnt = 0
    for m in range(ncand):
        dx = cbuf[m, 0] - x0
        dy = cbuf[m, 1] - x1
        dz = cbuf[m, 2] - x2
        w = _wrow(dx * dx + dy * dy + dz * dz, cbuf[m, 6], cbuf[m, 7], kernel)
        if w <= 0.0:
            continue
        nbuf[cnt, 0] = dx
        nbuf[cnt, 1] = dy
        nbuf[cnt, 2] = dz
        nbuf[cnt, 3] = w
        cnt += 1
        wsum += w
        mx += w * dx
        my += w * dy
        mz += w * dz
        hx += w * cbuf[m, 3]
        hy += w * cbuf[m, 4]
        hz += w * cbuf[m, 5]
        ssum += w * cbuf[m, 8]
        if normal_mode == 1:
            c00 += w * dx * dx
            c01 += w * dx * dy
            c02 += w * dx * dz
            c11 += w * dy * dy
            c12 += w * dy * dz
            c22 += w * dz * dz
    if cnt == 0 or not wsum > 0.0:
        return False
    inv = 1.0 / wsum
    mx *= inv  # q - x
    my *= inv
    mz *= inv
    hx *= inv
    hy *= inv
    hz *= inv
    sl = ssum * inv
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if normal_mode == 1:
        vx, vy, vz = smallest_eigenvector(c00 * inv - mx * mx, c01 * inv - mx * my, c02 * inv - mx * mz,
                                          c11 * inv - my * my, c12 * inv - my * mz, c22 * inv - mz * mz)
        if vx * hx + vy * hy + vz * hz < 0.0:
            vx, vy, vz = -vx, -vy, -vz
        nx, ny, nz = vx, vy, vz
    else:
        if hn < 1e-9:
            return False
        nx, ny, nz = hx / hn, hy / hn, hz / hn
    # projection of x onto the plane through q with normal N: o = x + (N.(q - x)) N
    dn = nx * mx + ny * my + nz * mz
    ex, ey, ez = dn * nx, dn * ny, dn * nz
    fa = 0.0
    nx2, ny2, nz2 = nx, ny, nz
    if degree == 2 and cnt >= 6:
        isl = 1.0 / sl
        t1, t2 = _quadratic(nbuf, cnt, ex, ey, ez, nx, ny, nz, isl, A, rhs)
        if solve_spd(A, rhs, 6):
            fa = rhs[0]
            fb = rhs[1] * isl
            fc = rhs[2] * isl
            # normal of the height field at the origin: N - f_u t1 - f_v t2
            px = nx - fb * t1[0] - fc * t2[0]
            py = ny - fb * t1[1] - fc * t2[1]
            pz = nz - fb * t1[2] - fc * t2[2]
            pn = 1.0 / math.sqrt(px * px + py * py + pz * pz)
            nx2, ny2, nz2 = px * pn, py * pn, pz * pn
    res[0] = x0 + ex + fa * nx
    res[1] = x1 + ey + fa * ny
    res[2] = x2 + ez + fa * nz
    res[3] = nx2
    res[4] = ny2
    res[5] = nz2
    res[6] = x0 + mx
    res[7] = x1 + my
    res[8] = x2 + mz
    res[9] = wsum
    res[10] = sl
    res[11] = cnt
    return True


@njit(cache=True)
def _project_block(blk, queries, gpack, kernel, normal_mode, degree, margin, lv_origin, lv_inv, lv_dims,
                   lv_koff, lv_keys, lv_start, max_iter, tol, out_p, out_n, status, nq):
    """Queries of block ``blk`` (body of :func:`project_kernel`)."""
    ranges, A, rhs, res, cand, cbuf, nbuf, centre, meta = block_scratch()
    y = np.empty(3)
    for qi in range(blk * _BLOCK, min(nq, (blk + 1) * _BLOCK)):
        x0, x1, x2 = queries[qi, 0], queries[qi, 1], queries[qi, 2]
        y[0] = x0
        y[1] = x1
        y[2] = x2
        st = NOT_CONVERGED
        nx = ny = nz = math.nan
        for it in range(max_iter):
            cand, cbuf, nbuf = refresh(y, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys,
                                       lv_start, ranges, cand, cbuf, nbuf, centre, meta)
            ok = local_fit(y, kernel, normal_mode, degree, cbuf, meta[0], nbuf, A, rhs, res)
            if not ok:
                st = NO_NEIGHBORS if it == 0 else LOST
                break
            nx, ny, nz = res[3], res[4], res[5]
            dist = nx * (x0 - res[0]) + ny * (x1 - res[1]) + nz * (x2 - res[2])
            y0, y1, y2 = x0 - dist * nx, x1 - dist * ny, x2 - dist * nz
            step = math.sqrt((y0 - y[0]) ** 2 + (y1 - y[1]) ** 2 + (y2 - y[2]) ** 2)
            y[0] = y0
            y[1] = y1
            y[2] = y2
            if step <= tol * res[10]:
                st = CONVERGED
                break
        status[qi] = st
        if st == NO_NEIGHBORS or st == LOST:
            for t in range(3):
                out_p[qi, t] = math.nan
                out_n[qi, t] = math.nan
        else:
            out_p[qi, 0] = y[0]
            out_p[qi, 1] = y[1]
            out_p[qi, 2] = y[2]
            out_n[qi, 0] = nx
            out_n[qi, 1] = ny
            out_n[qi, 2] = nz


@njit(cache=True, parallel=True)
def project_kernel(queries, gpack, kernel, normal_mode, degree, margin,
                   lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, max_iter, tol,
                   out_p, out_n, status):
    """Iterated orthogonal projection of every query onto the MLS surface.

    Iteration: fit at y_k (foot p_k, normal n_k), then
    ``y_{k+1} = x − (n_k·(x − p_k)) n_k``; at the fixed point ``x − y ∥ n(y)`` and y
    lies on its own local fit (constraint 3.2 of Levin's definition).
    Stops when ``|y_{k+1} − y_k| <= tol·σ_local``. Writes NaN for queries that no
    kernel reaches.
    """
    nq = queries.shape[0]
    nblk = (nq + _BLOCK - 1) // _BLOCK
    # a thin prange loop over a serial block body (typed once, not again inside the parfor)
    for blk in prange(nblk):
        _project_block(np.int64(blk), queries, gpack, kernel, normal_mode, degree, margin, lv_origin,
                       lv_inv, lv_dims, lv_koff, lv_keys, lv_start, max_iter, tol, out_p, out_n, status,
                       nq)


@njit(cache=True)
def _interpolate_block(blk, points, values, gpack, kernel, margin, lv_origin, lv_inv, lv_dims, lv_koff,
                       lv_keys, lv_start, out, found, nq, nk):
    """Points of block ``blk`` (body of :func:`interpolate_kernel`)."""
    ranges = np.empty((9, 2), np.int64)
    cand, cbuf, nbuf = work_buffers(np.int64(_CAP))  # int64, not a literal: one signature
    centre = np.empty(3)
    meta = np.zeros(2, np.int64)
    acc = np.empty(nk)
    for qi in range(blk * _BLOCK, min(nq, (blk + 1) * _BLOCK)):
        x = points[qi]
        cand, cbuf, nbuf = refresh(x, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys,
                                   lv_start, ranges, cand, cbuf, nbuf, centre, meta)
        for t in range(nk):
            acc[t] = 0.0
        wsum = 0.0
        for m in range(meta[0]):
            dx = cbuf[m, 0] - x[0]
            dy = cbuf[m, 1] - x[1]
            dz = cbuf[m, 2] - x[2]
            w = _wrow(dx * dx + dy * dy + dz * dz, cbuf[m, 6], cbuf[m, 7], kernel)
            if w <= 0.0:
                continue
            a = cand[m]
            wsum += w
            for t in range(nk):
                acc[t] += w * values[a, t]
        ok = wsum > 0.0
        found[qi] = ok
        for t in range(nk):
            out[qi, t] = acc[t] / wsum if ok else 0.0


@njit(cache=True, parallel=True)
def interpolate_kernel(points, values, gpack, kernel, margin,
                       lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, out, found):
    """MLS-weighted average of per-sample ``values`` (N, k) (kernel order) at ``points`` (M, 3).

    ``out[i] = Σ w_j(x_i) values[j] / Σ w_j(x_i)`` with the weights of the local fit
    (3.10–3.12); ``found[i]`` is False (and ``out[i]`` zero) where no kernel reaches x_i.
    """
    nq = points.shape[0]
    nk = values.shape[1]
    nblk = (nq + _BLOCK - 1) // _BLOCK
    # a thin prange loop over a serial block body (typed once, not again inside the parfor)
    for blk in prange(nblk):
        _interpolate_block(np.int64(blk), points, values, gpack, kernel, margin, lv_origin, lv_inv,
                           lv_dims, lv_koff, lv_keys, lv_start, out, found, nq, nk)
