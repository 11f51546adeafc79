"""Numba kernels of the self-query pipeline: every pair once, then CSR rows.

``radius_pairs`` and ``radius_neighbors(points, r)`` (thesis section 3.4.2):

1. :func:`half_fill_chunks` -- each point ``a`` (sorted by cell) is tested only
   against the partners ``b > a`` of its 27-cell stencil, which finds every pair
   exactly once (the stencil relation is symmetric); chunks of cells write in
   parallel into space estimated beforehand, :func:`half_count` +
   :func:`half_fill` finish chunks that ran out of it exactly;
2. :func:`pair_row_counts` / :func:`row_cursors` / :func:`pair_row_scatter` -- a
   parallel counting sort of the pairs by row, each part with its own counts and
   cursors (no write races);
3. :func:`sort_rows` / :func:`sort_pair_rows` -- each row sorted (rank sort).

Every kernel has a plain numpy reference in ``tests/spatial``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh.spatial._kernels import _dist2, _rank_sort_into, stencil_ranges


@njit(cache=True, inline="always")
def _half_hits(sp, a, ranges, ns, r2, buf):
    """Sorted positions ``b > a`` within the stencil slices and ``radius``, written
    branch-free into ``buf``; returns their number."""
    nb = 0
    for s in range(ns):
        for b in range(max(ranges[s, 0], a + 1), ranges[s, 1]):
            buf[nb] = b
            nb += _dist2(sp, a, sp, b) <= r2
    return nb


@njit(cache=True, inline="always")
def _cell_stencil(c, cell_keys, cell_start, dims, reach, ranges):
    key = cell_keys[c]
    k = key % dims[2]
    j = (key // dims[2]) % dims[1]
    i = key // (dims[1] * dims[2])
    ns = stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, ranges)
    tot = 0
    for s in range(ns):
        tot += ranges[s, 1] - ranges[s, 0]
    return ns, tot


@njit(cache=True)
def _count_cell(c, sp, cell_keys, cell_start, dims, reach, r2):
    """Pairs ``a < b`` with ``a`` in cell ``c`` (body of :func:`half_count`)."""
    m = 2 * reach + 1
    ranges = np.empty((m * m, 2), np.int64)
    ns, tot = _cell_stencil(c, cell_keys, cell_start, dims, reach, ranges)
    buf = np.empty(tot, np.int64)
    cnt = 0
    for a in range(cell_start[c], cell_start[c + 1]):
        cnt += _half_hits(sp, a, ranges, ns, r2, buf)
    return cnt


@njit(cache=True)
def _fill_cell(c, w, sp, order, cell_keys, cell_start, dims, reach, r2, plo, phi):
    """Write the pairs of cell ``c`` from ``w`` on (body of :func:`half_fill`)."""
    m = 2 * reach + 1
    ranges = np.empty((m * m, 2), np.int64)
    ns, tot = _cell_stencil(c, cell_keys, cell_start, dims, reach, ranges)
    buf = np.empty(tot, np.int64)
    for a in range(cell_start[c], cell_start[c + 1]):
        nb = _half_hits(sp, a, ranges, ns, r2, buf)
        w = _write_pairs(order, a, buf, nb, plo, phi, w)


@njit(cache=True)
def _fill_chunk(t, sp, order, cell_keys, cell_start, dims, reach, r2, chunk_cells, chunk_base, plo, phi,
                lengths, stops):
    """Chunk ``t`` of :func:`half_fill_chunks` (its body)."""
    m = 2 * reach + 1
    w = chunk_base[t]
    cap = chunk_base[t + 1]
    stops[t] = chunk_cells[t + 1]
    ranges = np.empty((m * m, 2), np.int64)
    for c in range(chunk_cells[t], chunk_cells[t + 1]):
        ns, tot = _cell_stencil(c, cell_keys, cell_start, dims, reach, ranges)
        buf = np.empty(tot, np.int64)
        w_cell = w
        full = False
        for a in range(cell_start[c], cell_start[c + 1]):
            nb = _half_hits(sp, a, ranges, ns, r2, buf)
            if w + nb > cap:
                full = True
                break
            w = _write_pairs(order, a, buf, nb, plo, phi, w)
        if full:
            w = w_cell
            stops[t] = c
            break
    lengths[t] = w - chunk_base[t]


@njit(cache=True, parallel=True)
def half_count(sp, cell_keys, cell_start, dims, reach, radius, cells):
    """Pairs ``a < b`` (sorted positions) within ``radius`` with ``a`` in each of the
    listed non-empty ``cells``, shape (len(cells),) int64.

    The stencil relation is symmetric, so scanning only ``b > a`` finds every pair
    exactly once."""
    # thin prange loops over serial per-cell bodies in these kernels: a body inside the
    # parfor is typed and lowered twice, and np.zeros there is a parfor of its own
    counts = np.empty(cells.shape[0], np.int64)
    r2 = radius * radius
    for t in prange(cells.shape[0]):
        counts[t] = _count_cell(cells[t], sp, cell_keys, cell_start, dims, reach, r2)
    return counts


@njit(cache=True, inline="always")
def _write_pairs(order, a, buf, nb, plo, phi, w):
    oa = order[a]
    for t in range(nb):
        ob = order[buf[t]]
        if oa < ob:
            plo[w] = oa
            phi[w] = ob
        else:
            plo[w] = ob
            phi[w] = oa
        w += 1
    return w


@njit(cache=True, parallel=True)
def half_fill(sp, order, cell_keys, cell_start, dims, reach, radius, cells, offsets, plo, phi):
    """Write the pairs counted by :func:`half_count` for ``cells`` as original
    indices ``plo < phi``; the pairs of ``cells[t]`` go to ``offsets[t]:offsets[t+1]``."""
    r2 = radius * radius
    for t in prange(cells.shape[0]):
        _fill_cell(cells[t], offsets[t], sp, order, cell_keys, cell_start, dims, reach, r2, plo, phi)


@njit(cache=True, parallel=True)
def half_fill_chunks(sp, order, cell_keys, cell_start, dims, reach, radius, chunk_cells, chunk_base, plo, phi):
    """One-pass version of :func:`half_count` + :func:`half_fill` into estimated space.

    Chunk ``t`` handles cells ``chunk_cells[t]:chunk_cells[t+1]`` and writes into
    ``chunk_base[t]:chunk_base[t+1]``.  A cell whose pairs do not fit is rolled back
    and the chunk stops there.  Returns ``(lengths, stops)``: pairs written per chunk
    and the first cell of each chunk left undone (``chunk_cells[t+1]`` if none)."""
    nch = chunk_cells.shape[0] - 1
    lengths = np.empty(nch, np.int64)
    stops = np.empty(nch, np.int64)
    r2 = radius * radius
    for t in prange(nch):
        _fill_chunk(np.int64(t), sp, order, cell_keys, cell_start, dims, reach, r2, chunk_cells, chunk_base, plo, phi,
                    lengths, stops)
    return lengths, stops


@njit(cache=True, parallel=True)
def pair_row_counts(plo, phi, seg_start, seg_len, n, both, nparts):
    """Entries per row and part for the CSR built from the pairs in segments
    ``[seg_start[s], seg_start[s] + seg_len[s])``: row ``plo`` (and ``phi`` when
    ``both``).  Part ``t`` takes the segments ``t, t + nparts, ...``, so every pair
    is read once and each part counts into its own row of the (nparts, n) result
    (a parallel counting sort without write races)."""
    counts = np.zeros((nparts, n), np.int64)
    for part in prange(nparts):
        for sg in range(part, seg_start.shape[0], nparts):
            for t in range(seg_start[sg], seg_start[sg] + seg_len[sg]):
                counts[part, plo[t]] += 1
                if both:
                    counts[part, phi[t]] += 1
    return counts


@njit(cache=True, parallel=True)
def pair_row_scatter(plo, phi, seg_start, seg_len, cursors, both, cols):
    """Scatter the pairs into CSR columns ``cols``: part ``t`` (segments as in
    :func:`pair_row_counts`) writes row ``v`` at ``cursors[t, v]``, incrementing
    it.  The order within a row is unspecified."""
    nparts = cursors.shape[0]
    for part in prange(nparts):
        cur = cursors[part]
        for sg in range(part, seg_start.shape[0], nparts):
            for t in range(seg_start[sg], seg_start[sg] + seg_len[sg]):
                v = plo[t]
                cols[cur[v]] = phi[t]
                cur[v] += 1
                if both:
                    v = phi[t]
                    cols[cur[v]] = plo[t]
                    cur[v] += 1


@njit(cache=True, parallel=True)
def row_cursors(counts, self_loops):
    """CSR offsets (n+1,) and per-part write cursors (nparts, n) from the per-part
    row counts of :func:`pair_row_counts`; with ``self_loops`` every row gets one
    more entry, written by :func:`write_self_loops` at its start."""
    nparts, n = counts.shape
    rowlen = np.empty(n, np.int64)
    for v in prange(n):
        tot = 1 if self_loops else 0
        for t in range(nparts):
            tot += counts[t, v]
        rowlen[v] = tot
    offsets = np.zeros(n + 1, np.int64)
    for v in range(n):
        offsets[v + 1] = offsets[v] + rowlen[v]
    cursors = np.empty((nparts, n), np.int64)
    for v in prange(n):
        c = offsets[v] + (1 if self_loops else 0)
        for t in range(nparts):
            cursors[t, v] = c
            c += counts[t, v]
    return offsets, cursors


@njit(cache=True, parallel=True)
def write_self_loops(offsets, cols):
    """Put row index ``v`` first in every row ``v`` (see :func:`row_cursors`)."""
    for v in prange(offsets.shape[0] - 1):
        cols[offsets[v]] = v


@njit(cache=True, inline="always")
def _sorted_row(cols, lo, m):
    """``cols[lo:lo+m]`` (distinct values) sorted, as a new int64 array."""
    tmp = np.empty(m, np.int64)
    for t in range(m):
        tmp[t] = cols[lo + t]
    if m > 64:
        return np.sort(tmp)
    out = np.empty(m, np.int64)
    _rank_sort_into(tmp, m, out, 0)
    return out


@njit(cache=True, parallel=True)
def sort_rows(offsets, cols, out):
    """Every CSR row ``cols[offsets[i]:offsets[i+1]]`` (distinct values), sorted,
    into the same rows of ``out`` (may be ``cols`` itself)."""
    for v in prange(offsets.shape[0] - 1):
        lo = offsets[v]
        row = _sorted_row(cols, lo, offsets[v + 1] - lo)
        for t in range(row.shape[0]):
            out[lo + t] = row[t]


@njit(cache=True, parallel=True)
def sort_pair_rows(offsets, cols, out):
    """Like :func:`sort_rows` into the (P, 2) array ``out`` as rows ``(i, col)``."""
    for v in prange(offsets.shape[0] - 1):
        lo = offsets[v]
        row = _sorted_row(cols, lo, offsets[v + 1] - lo)
        for t in range(row.shape[0]):
            out[lo + t, 0] = v
            out[lo + t, 1] = row[t]


@njit(cache=True, parallel=True)
def compact_pairs(plo, phi, seg_start, seg_len, out):
    """Copy the segments of ``plo`` / ``phi`` into the (P, 2) int64 array ``out`` (grid order,
    the unsorted output of ``radius_pairs(..., sort=False)``)."""
    nseg = seg_start.shape[0]
    dst = np.zeros(nseg + 1, np.int64)
    for s in range(nseg):
        dst[s + 1] = dst[s] + seg_len[s]
    for s in prange(nseg):
        src = seg_start[s]
        d = dst[s]
        for t in range(seg_len[s]):
            out[d + t, 0] = plo[src + t]
            out[d + t, 1] = phi[src + t]
