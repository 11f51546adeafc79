"""Numba kernels of the static cell grid (thesis section 3.4.2).

Layout
------
Points are binned into cubic cells of edge ``d`` (eq. 3.16,
``I(x) = (floor(x/d), floor(y/d), floor(z/d))`` measured from the grid origin).
Every grid is handled as three *virtual* axes ``(i, j, k)`` with sizes
``dims = (n0, n1, n2)``; a 2-D grid uses ``n0 = 1`` and puts ``x`` on ``j`` and
``y`` on ``k``.  A cell's key is ``(i * n1 + j) * n2 + k`` (``k`` fastest), so the
cells ``(i, j, k - m) ... (i, j, k + m)`` of a stencil row are consecutive keys and,
because the points are sorted by key, one contiguous slice of the sorted points.
A stencil of reach ``m`` is therefore ``(2m+1)^2`` slices in 3-D and ``2m+1``
slices in 2-D.  Only non-empty cells are stored (sorted ``cell_keys`` with
``cell_start`` offsets), so memory grows with the number of points, never with the
number of empty cells; a cell is found by binary search.

Indices are clamped to ``[0, n - 1]`` on each axis.  Clamping is monotone and
1-Lipschitz, so two points whose unclamped indices differ by at most ``m`` still
do after clamping: queries outside the grid stay correct.

The self-query pipeline (every pair once) is in :mod:`unmesh.spatial._pair_kernels`.
Every kernel here has a plain numpy reference in ``tests/spatial`` (``reference.py``
and the tests themselves).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh._csr_kernels import counting_sort_csr, csr_rows

# ---------------------------------------------------------------------------
# Scalar helpers, callable from other numba kernels
# ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _axis_cell(t: float, n: int) -> int:
    """Clamp a cell coordinate in cell units to an index in [0, n - 1]."""
    if t < 0.0:
        return 0
    if t >= n:
        return n - 1
    c = int(t)
    if c > n - 1:
        c = n - 1
    return c


@njit(cache=True)
def point_cell(p, origin, inv_cell, dims):
    """Virtual cell ``(i, j, k)`` of point ``p`` (eq. 3.16), clamped to the grid.

    ``p`` and ``origin`` have length 2 or 3; in 2-D ``i == 0``.
    """
    if p.shape[0] == 3:
        i = _axis_cell((p[0] - origin[0]) * inv_cell, dims[0])
        j = _axis_cell((p[1] - origin[1]) * inv_cell, dims[1])
        k = _axis_cell((p[2] - origin[2]) * inv_cell, dims[2])
    else:
        i = 0
        j = _axis_cell((p[0] - origin[0]) * inv_cell, dims[1])
        k = _axis_cell((p[1] - origin[1]) * inv_cell, dims[2])
    return i, j, k


@njit(cache=True, inline="always")
def cell_key(i, j, k, dims):
    """Linear key ``(i * n1 + j) * n2 + k`` of virtual cell ``(i, j, k)``."""
    return (i * dims[1] + j) * dims[2] + k


@njit(cache=True, inline="always")
def _lower_bound(a, value):
    """First index ``t`` with ``a[t] >= value`` in the sorted array ``a``."""
    lo = 0
    hi = a.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def find_cell(key, cell_keys):
    """Index of the non-empty cell with ``key`` in ``cell_keys``, or -1 if empty."""
    c = _lower_bound(cell_keys, key)
    if c < cell_keys.shape[0] and cell_keys[c] == key:
        return c
    return -1


@njit(cache=True)
def cell_range(c, cell_start):
    """``[start, end)`` of the sorted points in non-empty cell ``c`` (``-1`` = empty)."""
    if c < 0:
        return 0, 0
    return cell_start[c], cell_start[c + 1]


@njit(cache=True)
def stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, out):
    """Slices of sorted points covering the cells within ``reach`` of ``(i, j, k)``.

    Writes ``[start, end)`` pairs into ``out`` (shape ``((2*reach+1)**2, 2)`` or
    larger) and returns how many rows were written; rows may be empty
    (``start == end``).  With ``reach = ceil(radius / cell_size)`` every point within
    ``radius`` of a point of cell ``(i, j, k)`` lies in one of the slices.
    """
    n = 0
    i0 = max(i - reach, 0)
    i1 = min(i + reach, dims[0] - 1)
    j0 = max(j - reach, 0)
    j1 = min(j + reach, dims[1] - 1)
    k0 = max(k - reach, 0)
    k1 = min(k + reach, dims[2] - 1)
    lo = 0
    for ii in range(i0, i1 + 1):
        for jj in range(j0, j1 + 1):
            base = (ii * dims[1] + jj) * dims[2]
            # keys grow with (ii, jj): search only the tail of cell_keys
            c0 = lo + _lower_bound(cell_keys[lo:], base + k0)
            c1 = c0 + _lower_bound(cell_keys[c0:], base + k1 + 1)
            out[n, 0] = cell_start[c0]
            out[n, 1] = cell_start[c1]
            n += 1
            lo = c1
    return n


# ---------------------------------------------------------------------------
# Construction
# ---------------------------------------------------------------------------


@njit(cache=True, parallel=True)
def stencil_table(cell_keys, cell_start, dims, reach):
    """:func:`stencil_ranges` of every non-empty cell, shape (C, (2*reach+1)**2, 2)
    int64; unused rows are empty (``start == end == 0``)."""
    nc = cell_keys.shape[0]
    m = 2 * reach + 1
    out = np.zeros((nc, m * m, 2), np.int64)
    for c in prange(nc):
        key = cell_keys[c]
        k = key % dims[2]
        j = (key // dims[2]) % dims[1]
        i = key // (dims[1] * dims[2])
        stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, out[c])
    return out


@njit(cache=True)
def cell_of_sorted(cell_start, n):
    """Non-empty-cell index of every sorted point, shape (N,) int64 (``n == cell_start[-1]``;
    :func:`unmesh._csr_kernels.csr_rows`)."""
    return csr_rows(cell_start)


@njit(cache=True, parallel=True)
def bounds(points):
    """Per-axis minimum and maximum of the (N >= 1) points, two arrays of shape (dim,)."""
    n, dim = points.shape
    step = (n + 63) // 64
    nchunk = (n + step - 1) // step  # every chunk non-empty
    lo = np.empty((nchunk, dim))
    hi = np.empty((nchunk, dim))
    for c in prange(nchunk):
        a0 = c * step
        a1 = min(n, a0 + step)
        for t in range(dim):
            lo[c, t] = points[a0, t]
            hi[c, t] = points[a0, t]
        for a in range(a0, a1):
            for t in range(dim):
                v = points[a, t]
                if v < lo[c, t]:
                    lo[c, t] = v
                if v > hi[c, t]:
                    hi[c, t] = v
    out_lo = lo[0].copy()
    out_hi = hi[0].copy()
    for c in range(1, nchunk):
        for t in range(dim):
            out_lo[t] = min(out_lo[t], lo[c, t])
            out_hi[t] = max(out_hi[t], hi[c, t])
    return out_lo, out_hi


@njit(cache=True, parallel=True)
def compute_keys(points, origin, inv_cell, dims):
    """Cell key of every point, shape (N,) int64."""
    n = points.shape[0]
    keys = np.empty(n, np.int64)
    for a in prange(n):
        i, j, k = point_cell(points[a], origin, inv_cell, dims)
        keys[a] = (i * dims[1] + j) * dims[2] + k
    return keys


@njit(cache=True)
def counting_sort(keys, nkeys):
    """Stable permutation sorting ``keys`` (values in ``[0, nkeys)``), shape (N,) int64
    (the ``order`` of :func:`unmesh._csr_kernels.counting_sort_csr`)."""
    return counting_sort_csr(keys, nkeys)[0]


@njit(cache=True)
def compress_cells(sorted_keys):
    """Unique keys ``(C,)`` and start offsets ``(C+1,)`` of a sorted key array."""
    n = sorted_keys.shape[0]
    ncell = 0
    for a in range(n):
        if a == 0 or sorted_keys[a] != sorted_keys[a - 1]:
            ncell += 1
    keys = np.empty(ncell, np.int64)
    start = np.empty(ncell + 1, np.int64)
    c = 0
    for a in range(n):
        if a == 0 or sorted_keys[a] != sorted_keys[a - 1]:
            keys[c] = sorted_keys[a]
            start[c] = a
            c += 1
    start[ncell] = n
    return keys, start


@njit(cache=True, parallel=True)
def gather_rows(points, order):
    """``points[order]`` (parallel row gather)."""
    out = np.empty((order.shape[0], points.shape[1]), points.dtype)
    for a in prange(order.shape[0]):
        for t in range(points.shape[1]):
            out[a, t] = points[order[a], t]
    return out


# ---------------------------------------------------------------------------
# Radius queries: count pass + prefix sum + fill pass, parallel over query cells
# ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _dist2(p, a, q, b):
    """Squared distance ``sum((p[a] - q[b])**2)``, summed in axis order like numpy."""
    d = p[a, 0] - q[b, 0]
    s = d * d
    d = p[a, 1] - q[b, 1]
    s = s + d * d
    if p.shape[1] == 3:
        d = p[a, 2] - q[b, 2]
        s = s + d * d
    return s


@njit(cache=True, inline="always")
def _outside(q, b, lower, upper, r):
    for t in range(q.shape[1]):
        if q[b, t] < lower[t] - r or q[b, t] > upper[t] + r:
            return True
    return False


@njit(cache=True, inline="always")
def _rank_sort_into(vals, m, dst, lo):
    """Write the ``m`` distinct values ``vals[:m]`` sorted into ``dst[lo:lo+m]``.

    Rank sort (each value's position = number of smaller values): branch-free and
    several times faster than insertion sort for the short rows of neighbour lists."""
    if m > 64:
        dst[lo:lo + m] = np.sort(vals[:m])
        return
    for t in range(m):
        x = vals[t]
        rk = 0
        for u in range(m):
            rk += vals[u] < x
        dst[lo + rk] = x


@njit(cache=True, parallel=True)
def radius_count(
    sp, p_order, cell_keys, cell_start, dims, reach,
    sq, q_order, q_keys, q_start, check_box, lower, upper, radius, pairs_only,
):
    """Number of neighbours of each query, by original query index.

    ``sp``: points sorted by cell, ``p_order[a]`` = original index of sorted point
    ``a``; ``sq``: queries sorted by cell in groups ``q_start`` of key ``q_keys``,
    ``q_order`` = original query index.  ``pairs_only`` counts only ``j > i``.
    """
    nq = sq.shape[0]
    counts = np.zeros(nq, np.int64)
    r2 = radius * radius
    m = 2 * reach + 1
    nrow = m * m
    for g in prange(q_keys.shape[0]):
        key = q_keys[g]
        k = key % dims[2]
        j = (key // dims[2]) % dims[1]
        i = key // (dims[1] * dims[2])
        ranges = np.empty((nrow, 2), np.int64)
        ns = stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, ranges)
        for b in range(q_start[g], q_start[g + 1]):
            if check_box and _outside(sq, b, lower, upper, radius):
                continue
            qi = q_order[b]
            cnt = 0
            for s in range(ns):
                for a in range(ranges[s, 0], ranges[s, 1]):
                    if _dist2(sp, a, sq, b) <= r2:
                        if not pairs_only or p_order[a] > qi:
                            cnt += 1
            counts[qi] = cnt
    return counts


@njit(cache=True, parallel=True)
def radius_fill(
    sp, p_order, cell_keys, cell_start, dims, reach,
    sq, q_order, q_keys, q_start, check_box, lower, upper, radius, pairs_only,
    offsets, indices,
):
    """Write neighbour indices (original numbering, ascending) into CSR ``indices``.

    Candidates are first written branch-free into a per-group scratch buffer."""
    r2 = radius * radius
    m = 2 * reach + 1
    nrow = m * m
    for g in prange(q_keys.shape[0]):
        key = q_keys[g]
        k = key % dims[2]
        j = (key // dims[2]) % dims[1]
        i = key // (dims[1] * dims[2])
        ranges = np.empty((nrow, 2), np.int64)
        ns = stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, ranges)
        tot = 0
        for s in range(ns):
            tot += ranges[s, 1] - ranges[s, 0]
        buf = np.empty(tot, np.int64)
        vals = np.empty(tot, np.int64)
        for b in range(q_start[g], q_start[g + 1]):
            if check_box and _outside(sq, b, lower, upper, radius):
                continue
            qi = q_order[b]
            nb = 0
            for s in range(ns):
                for a in range(ranges[s, 0], ranges[s, 1]):
                    buf[nb] = a
                    nb += _dist2(sp, a, sq, b) <= r2
            m = 0
            for t in range(nb):
                pj = p_order[buf[t]]
                vals[m] = pj
                m += not pairs_only or pj > qi
            _rank_sort_into(vals, m, indices, offsets[qi])


# ---------------------------------------------------------------------------
# Exact k-nearest-neighbour finishing (distances recomputed, ties by index)
# ---------------------------------------------------------------------------


@njit(cache=True, parallel=True)
def pairs_within(points, i, queries, q, r2, keep):
    """``keep[t] = sum((points[i[t]] - queries[q[t]])**2) <= r2`` (summed in axis order, as
    numpy's ``((points[i] - queries[q]) ** 2).sum(axis=1)``, without its temporaries)."""
    for t in prange(i.shape[0]):
        keep[t] = _dist2(points, i[t], queries, q[t]) <= r2


@njit(cache=True, parallel=True)
def knn_finish(points, queries, idx, dist):
    """Recompute ``dist[q, t] = |points[idx[q, t]] - queries[q]|`` and sort each row
    by (distance, index).  Rows are nearly sorted on entry (kd-tree order)."""
    for q in prange(idx.shape[0]):
        kk = idx.shape[1]
        for t in range(kk):
            dist[q, t] = np.sqrt(_dist2(points, idx[q, t], queries, q))
        for s in range(1, kk):
            dv = dist[q, s]
            iv = idx[q, s]
            t = s - 1
            while t >= 0 and (dist[q, t] > dv or (dist[q, t] == dv and idx[q, t] > iv)):
                dist[q, t + 1] = dist[q, t]
                idx[q, t + 1] = idx[q, t]
                t -= 1
            dist[q, t + 1] = dv
            idx[q, t + 1] = iv


@njit(cache=True)
def sample_efficiency(sp, cell_keys, cell_start, origin, inv_cell, dims, reach, samples, radius):
    """Total candidates tested and hits found by grid searches around ``samples``."""
    r2 = radius * radius
    m = 2 * reach + 1
    ranges = np.empty((m * m, 2), np.int64)
    cand = 0
    hits = 0
    for b in range(samples.shape[0]):
        i, j, k = point_cell(samples[b], origin, inv_cell, dims)
        ns = stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, ranges)
        for s in range(ns):
            cand += ranges[s, 1] - ranges[s, 0]
            for a in range(ranges[s, 0], ranges[s, 1]):
                if _dist2(sp, a, samples, b) <= r2:
                    hits += 1
    return cand, hits


# ---------------------------------------------------------------------------
# Dense grid for use inside other kernels (every cell stored, same keying)
# ---------------------------------------------------------------------------


@njit(cache=True)
def dense_grid(points, cell, max_cells):
    """Dense cell grid of the (N, 3) ``points`` built inside a kernel, with this module's keying.

    Cells of edge at least ``cell`` over the points' bounding box, the edge doubled until
    there are at most ``max_cells`` cells; point ``a`` is in cell :func:`point_cell` with key
    :func:`cell_key`. Unlike the sparse grid of :func:`unmesh.spatial.build_cell_grid` every
    cell has an entry, so a kernel visits the cells around a point by key without a search.
    A point within ``cell`` of a grid point lies in the 27 cells around its
    :func:`dense_cell` (clipped to the grid).

    Returns
    -------
    origin : (3,) float64
        The box's lower corner.
    cell, inv_cell : float
        The cell edge used and its inverse.
    dims : (3,) int64
        Cells per axis.
    start, order : int64 arrays
        The points of key ``g`` are ``order[start[g]:start[g + 1]]``
        (:func:`unmesh._csr_kernels.counting_sort_csr`).

    Example
    -------
    >>> import numpy as np
    >>> origin, cell, inv, dims, start, order = dense_grid(np.array([[0.0, 0, 0], [1.0, 0, 0]]), 0.6, 64)
    >>> dims.tolist(), order.tolist()
    ([2, 1, 1], [0, 1])
    """
    n = points.shape[0]
    if n == 0:
        origin = np.zeros(3)
        upper = np.zeros(3)
    else:
        origin, upper = bounds(points)
    ext = max(upper[0] - origin[0], upper[1] - origin[1], upper[2] - origin[2])
    h = cell
    while ((int((upper[0] - origin[0]) / h) + 1) * (int((upper[1] - origin[1]) / h) + 1)
           * (int((upper[2] - origin[2]) / h) + 1) > max_cells):
        h = max(2.0 * h, ext / 64.0)
    inv = 1.0 / h
    dims = np.empty(3, np.int64)
    for d in range(3):
        dims[d] = int((upper[d] - origin[d]) * inv) + 1
    keys = np.empty(n, np.int64)
    for a in range(n):
        i, j, k = point_cell(points[a], origin, inv, dims)
        keys[a] = cell_key(i, j, k, dims)
    order, start = counting_sort_csr(keys, dims[0] * dims[1] * dims[2])
    return origin, h, inv, dims, start, order


@njit(cache=True, inline="always")
def dense_cell(x, y, z, origin, inv_cell):
    """Unclamped cell ``(i, j, k)`` of the point ``(x, y, z)`` in a :func:`dense_grid` (clip the ranges)."""
    return (math.floor((x - origin[0]) * inv_cell), math.floor((y - origin[1]) * inv_cell),
            math.floor((z - origin[2]) * inv_cell))
