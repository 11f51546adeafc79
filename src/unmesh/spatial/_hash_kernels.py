"""Numba kernels of the dynamic spatial hash grid (thesis eqs. 3.16, 3.17).

State (all arrays owned by :class:`unmesh.spatial.HashGrid`):

- table of ``s`` slots (``s`` prime), open addressing with linear probing:
  ``slot_cell (s, 3) int64`` cell indices ``(i, j, k)`` stored in the slot,
  ``slot_used (s,) bool`` slot holds a cell (possibly with no point left),
  ``slot_head (s,) int64`` first point of the cell's list (-1 = none),
  ``slot_count (s,) int64`` points in the cell;
- per point id: ``pos (cap, dim)``, ``alive (cap,) bool``, doubly linked list
  ``nxt``, ``prv`` and ``pslot`` (its slot).

The cell of ``x`` is ``(floor(x/d), floor(y/d), floor(z/d))`` (eq. 3.16, origin 0,
``k = 0`` in 2-D) and its slot starts the probe at
``h = (i p1 xor j p2 xor k p3) mod s`` (eq. 3.17, Teschner et al. primes).  The
stored cell indices make lookups exact, so collisions cost a probe, never a false
neighbour.  Every kernel has a numpy/Python reference in ``tests/spatial``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh.spatial._kernels import _rank_sort_into

P1 = 73856093
P2 = 19349663
P3 = 83492791
#: Cell indices are clamped to +-CLAMP so that huge coordinates stay representable.
CLAMP = 1 << 60


@njit(cache=True, inline="always")
def _axis_index(t, lim=CLAMP):
    if t >= lim:
        return lim
    if t <= -lim:
        return -lim
    return int(np.floor(t))


@njit(cache=True)
def hash_cell_of(p, inv_cell):
    """Cell ``(i, j, k)`` of point ``p`` (eq. 3.16); ``k = 0`` for 2-D points."""
    i = _axis_index(p[0] * inv_cell)
    j = _axis_index(p[1] * inv_cell)
    k = 0
    if p.shape[0] == 3:
        k = _axis_index(p[2] * inv_cell)
    return i, j, k


@njit(cache=True, inline="always")
def hash_index(i, j, k, size):
    """Eq. 3.17: ``(i*p1 xor j*p2 xor k*p3) mod s`` (wrapping int64 products)."""
    h = (i * P1) ^ (j * P2) ^ (k * P3)
    h = h % size
    if h < 0:
        h += size
    return h


@njit(cache=True)
def find_slot(i, j, k, slot_cell, slot_used):
    """Slot holding cell ``(i, j, k)``, or -1."""
    s = slot_used.shape[0]
    h = hash_index(i, j, k, s)
    for _ in range(s):
        if not slot_used[h]:
            return -1
        if slot_cell[h, 0] == i and slot_cell[h, 1] == j and slot_cell[h, 2] == k:
            return h
        h += 1
        if h == s:
            h = 0
    return -1


@njit(cache=True)
def _find_or_add_slot(i, j, k, slot_cell, slot_used, slot_head, slot_count):
    s = slot_used.shape[0]
    h = hash_index(i, j, k, s)
    while slot_used[h]:
        if slot_cell[h, 0] == i and slot_cell[h, 1] == j and slot_cell[h, 2] == k:
            return h, False
        h += 1
        if h == s:
            h = 0
    slot_used[h] = True
    slot_cell[h, 0] = i
    slot_cell[h, 1] = j
    slot_cell[h, 2] = k
    slot_head[h] = -1
    slot_count[h] = 0
    return h, True


@njit(cache=True, inline="always")
def _link(a, h, slot_head, slot_count, nxt, prv, pslot):
    first = slot_head[h]
    nxt[a] = first
    prv[a] = -1
    if first >= 0:
        prv[first] = a
    slot_head[h] = a
    slot_count[h] += 1
    pslot[a] = h


@njit(cache=True, inline="always")
def _unlink(a, slot_head, slot_count, nxt, prv, pslot):
    h = pslot[a]
    if prv[a] >= 0:
        nxt[prv[a]] = nxt[a]
    else:
        slot_head[h] = nxt[a]
    if nxt[a] >= 0:
        prv[nxt[a]] = prv[a]
    slot_count[h] -= 1
    nxt[a] = -1
    prv[a] = -1
    pslot[a] = -1


@njit(cache=True)
def hash_insert(ids, points, inv_cell, slot_cell, slot_used, slot_head, slot_count, pos, alive, nxt, prv, pslot):
    """Insert points under ``ids`` (not alive, capacity checked by the caller).
    Returns the number of newly used slots."""
    added = 0
    for t in range(ids.shape[0]):
        a = ids[t]
        for c in range(points.shape[1]):
            pos[a, c] = points[t, c]
        i, j, k = hash_cell_of(points[t], inv_cell)
        h, new = _find_or_add_slot(i, j, k, slot_cell, slot_used, slot_head, slot_count)
        if new:
            added += 1
        _link(a, h, slot_head, slot_count, nxt, prv, pslot)
        alive[a] = True
    return added


@njit(cache=True)
def hash_remove(ids, slot_head, slot_count, alive, nxt, prv, pslot):
    """Remove alive ``ids``; their cells stay in the table (emptied)."""
    for t in range(ids.shape[0]):
        a = ids[t]
        _unlink(a, slot_head, slot_count, nxt, prv, pslot)
        alive[a] = False


@njit(cache=True)
def hash_move(ids, points, inv_cell, slot_cell, slot_used, slot_head, slot_count, pos, nxt, prv, pslot):
    """Move alive ``ids`` to ``points``; relinks only those that change cell.
    Returns the number of newly used slots."""
    added = 0
    for t in range(ids.shape[0]):
        a = ids[t]
        for c in range(points.shape[1]):
            pos[a, c] = points[t, c]
        i, j, k = hash_cell_of(points[t], inv_cell)
        h = pslot[a]
        if slot_cell[h, 0] == i and slot_cell[h, 1] == j and slot_cell[h, 2] == k:
            continue
        _unlink(a, slot_head, slot_count, nxt, prv, pslot)
        h, new = _find_or_add_slot(i, j, k, slot_cell, slot_used, slot_head, slot_count)
        if new:
            added += 1
        _link(a, h, slot_head, slot_count, nxt, prv, pslot)
    return added


@njit(cache=True)
def hash_rebuild(size, inv_cell, pos, alive):
    """A fresh table of ``size`` slots holding the alive points (drops empty cells)."""
    slot_cell = np.zeros((size, 3), np.int64)
    slot_used = np.zeros(size, np.bool_)
    slot_head = np.full(size, -1, np.int64)
    slot_count = np.zeros(size, np.int64)
    cap = alive.shape[0]
    nxt = np.full(cap, -1, np.int64)
    prv = np.full(cap, -1, np.int64)
    pslot = np.full(cap, -1, np.int64)
    used = 0
    # link in decreasing id order so that each list is in increasing id order
    for a in range(cap - 1, -1, -1):
        if alive[a]:
            i, j, k = hash_cell_of(pos[a], inv_cell)
            h, new = _find_or_add_slot(i, j, k, slot_cell, slot_used, slot_head, slot_count)
            if new:
                used += 1
            _link(a, h, slot_head, slot_count, nxt, prv, pslot)
    return slot_cell, slot_used, slot_head, slot_count, nxt, prv, pslot, used


@njit(cache=True, inline="always")
def _hash_dist2(pos, a, q, b):
    d = pos[a, 0] - q[b, 0]
    s = d * d
    d = pos[a, 1] - q[b, 1]
    s = s + d * d
    if pos.shape[1] == 3:
        d = pos[a, 2] - q[b, 2]
        s = s + d * d
    return s


@njit(cache=True, parallel=True)
def query_cells(queries, inv_cell, half):
    """Cells ``(i, j, k)`` of the queries (eq. 3.16), or with ``half`` the indices
    ``floor(2 x / d)`` of the half-cells (``cell = half >> 1``), shape (Q, 3) int64."""
    out = np.empty((queries.shape[0], 3), np.int64)
    f = 2.0 if half else 1.0
    lim = 2 * CLAMP if half else CLAMP  # so that half >> 1 clamps like the cells
    for b in prange(queries.shape[0]):
        for t in range(queries.shape[1]):
            out[b, t] = _axis_index(f * (queries[b, t] * inv_cell), lim)
        if queries.shape[1] == 2:
            out[b, 2] = 0
    return out


#: Beyond this cell index, round-off in x/d may reach 1e-7 cells: search one more ring.
_FAR = 1 << 30


@njit(cache=True, inline="always")
def _query_box(qc, reach, half, dim):
    """Per-axis cell ranges searched for a query group with cell (or half-cell) ``qc``.

    ``half``: the 2x2x2 cells nearest to the query's half-cell (radius <= d/2, the
    8-cell search of Figure 3.7 c); otherwise the cells within ``reach``."""
    far = False
    for t in range(3):
        if qc[t] >= _FAR or qc[t] <= -_FAR:
            far = True
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for t in range(3):
        if half:
            c = qc[t] >> 1
            if far:
                lo[t] = c - 1
                hi[t] = c + 1
            else:
                lo[t] = (qc[t] - 1) >> 1
                hi[t] = (qc[t] + 1) >> 1
        else:
            rr = reach + 1 if far else reach
            lo[t] = qc[t] - rr
            hi[t] = qc[t] + rr
    if dim == 2:
        lo[2] = 0
        hi[2] = 0
    return lo, hi


@njit(cache=True)
def _query_group(g, queries, qorder, group_start, qcells, r2, reach, half, dim, slot_cell, slot_used, slot_head,
                 slot_count, pos, nxt, counts, offsets, indices, fill):
    """Queries of group ``g`` (body of :func:`hash_query`)."""
    lo, hi = _query_box(qcells[g], reach, half, dim)
    tot = 0
    for ii in range(lo[0], hi[0] + 1):
        for jj in range(lo[1], hi[1] + 1):
            for kk in range(lo[2], hi[2] + 1):
                h = find_slot(ii, jj, kk, slot_cell, slot_used)
                if h >= 0:
                    tot += slot_count[h]
    cid = np.empty(tot, np.int64)
    cpos = np.empty((tot, 3), np.float64)
    w = 0
    for ii in range(lo[0], hi[0] + 1):
        for jj in range(lo[1], hi[1] + 1):
            for kk in range(lo[2], hi[2] + 1):
                h = find_slot(ii, jj, kk, slot_cell, slot_used)
                if h < 0:
                    continue
                a = slot_head[h]
                while a >= 0:
                    cid[w] = a
                    for t in range(dim):
                        cpos[w, t] = pos[a, t]
                    w += 1
                    a = nxt[a]
    hits = np.empty(tot, np.int64)
    for t in range(group_start[g], group_start[g + 1]):
        b = qorder[t]
        nb = 0
        qx = queries[b, 0]
        qy = queries[b, 1]
        qz = queries[b, 2] if dim == 3 else 0.0
        for c in range(tot):
            dx = cpos[c, 0] - qx
            s2 = dx * dx
            dx = cpos[c, 1] - qy
            s2 = s2 + dx * dx
            if dim == 3:
                dx = cpos[c, 2] - qz
                s2 = s2 + dx * dx
            hits[nb] = cid[c]
            nb += s2 <= r2
        if fill:
            _rank_sort_into(hits, nb, indices, offsets[b])
        else:
            counts[b] = nb


@njit(cache=True, parallel=True)
def hash_query(queries, qorder, group_start, qcells, radius, reach, half, slot_cell, slot_used, slot_head,
               slot_count, pos, nxt, counts, offsets, indices, fill):
    """Count (``fill=False``, into ``counts``) or write (``fill=True``, CSR rows
    sorted ascending) the ids within ``radius`` of each query.

    Queries ``qorder[group_start[g]:group_start[g+1]]`` share the cell (or half-cell,
    see :func:`_query_box`) ``qcells[g]``; the ids and positions of the cells to
    search are gathered once per group into contiguous scratch arrays, then scanned
    branch-free."""
    # a thin prange loop over a serial body (compiled once, not typed again inside the parfor)
    r2 = radius * radius
    dim = pos.shape[1]
    for g in prange(group_start.shape[0] - 1):
        _query_group(np.int64(g), queries, qorder, group_start, qcells, r2, reach, half, dim, slot_cell, slot_used,
                     slot_head, slot_count, pos, nxt, counts, offsets, indices, fill)


@njit(cache=True, parallel=True)
def brute_query(queries, radius, ids, pos, counts, offsets, indices, fill):
    """Same as :func:`hash_query` by testing every alive id (``ids`` ascending);
    used when the stencil has more cells than the table has points."""
    r2 = radius * radius
    for b in prange(queries.shape[0]):
        cnt = 0
        w = 0
        if fill:
            w = offsets[b]
        for t in range(ids.shape[0]):
            a = ids[t]
            if _hash_dist2(pos, a, queries, b) <= r2:
                if fill:
                    indices[w] = a
                    w += 1
                else:
                    cnt += 1
        if not fill:
            counts[b] = cnt
