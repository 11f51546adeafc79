"""Transpose of the neighbour lists: the position of ``i`` in the list of each of its neighbours.

Numpy reference: a search of ``i`` in every neighbour's row, which the test compares against.

Example
-------
>>> import numpy as np
>>> nbr = np.array([[1, 2], [0, 2], [0, 1]], np.int32)
>>> rev = np.full(nbr.shape, -1, np.int32)
>>> int(reverse_positions(nbr, np.array([2, 2, 2]), 1, rev)), rev.tolist()
(0, [[0, 0], [0, 1], [1, 1]])
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh.sph._kernels import PLAIN


@njit(**PLAIN)
def _position(row, count, value):
    """Index of ``value`` in the ascending ``row[:count]`` (-1 if absent); branch-free search."""
    if count == 0:
        return -1
    base = 0
    n = count
    while n > 1:
        half = n >> 1
        probe = base + half
        base = probe if row[probe] <= value else base
        n -= half
    return base if row[base] == value else -1


@njit(**PLAIN)
def _lower_bound(row, count, value):
    """Number of entries of the ascending ``row[:count]`` that are below ``value``."""
    lo = 0
    hi = count
    while lo < hi:
        mid = (lo + hi) >> 1
        if row[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, parallel=True)
def reverse_positions(nbr, nnbr, nblocks, rev):
    """Position of ``i`` in the neighbour list of each of its neighbours.

    ``rev[i, t] = u`` with ``nbr[j, u] == i`` for ``j = nbr[i, t]`` (-1 when ``i``
    is missing from j's list, which a symmetric neighbour relation never gives).
    Rows must be ascending (as the density pass and ``radius_neighbors`` produce
    them). The rows are split into ``nblocks`` contiguous blocks processed in
    parallel; within a block, the entries of row ``j`` that belong to the block's
    rows come in ascending order, so one cursor per ``j`` (started by a binary
    search) finds every position in O(1): O(N·k) in all.

    Returns the number of missing entries.
    """
    n = nbr.shape[0]
    cap = nbr.shape[1]
    nb = max(1, min(nblocks, n))
    missing = 0
    for blk in prange(nb):
        r0 = blk * n // nb
        r1 = (blk + 1) * n // nb
        lo = n
        hi = -1
        for i in range(r0, r1):
            c = min(nnbr[i], cap)
            if c > 0:
                lo = min(lo, nbr[i, 0])
                hi = max(hi, nbr[i, c - 1])
        if hi < lo:
            continue
        cur = np.full(hi - lo + 1, -1, np.int64)
        for i in range(r0, r1):
            c = min(nnbr[i], cap)
            for t in range(c):
                j = nbr[i, t]
                cj = min(nnbr[j], cap)
                k = cur[j - lo]
                if k < 0:
                    k = _lower_bound(nbr[j], cj, r0)
                if k < cj and nbr[j, k] == i:
                    rev[i, t] = k
                    cur[j - lo] = k + 1
                else:
                    u = _position(nbr[j], cj, i)
                    rev[i, t] = u
                    if u < 0:
                        missing += 1
                    else:
                        cur[j - lo] = u + 1
    return missing
