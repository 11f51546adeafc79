"""Numba kernels of the local fiber rebuild after a crack (thesis 7.3.2): splicing CSR rows.

The connectivity arrays (neighbour lists, umbrella pairs, fibers with their state) are
grouped by node. A rebuild replaces the groups of the affected nodes; :func:`splice_sources`
gives, for every entry of the result, where it comes from (an entry of the old array, or
of the array of new rows), and :func:`gather` / :func:`gather2` copy the values. The result
is what ``numpy.concatenate`` of the kept and the new entries followed by a stable sort by
node gives (the reference, :func:`unmesh.shells.fracture.rebuild_near`), in one pass.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def splice_sources(old_offsets, row_of, new_offsets, out_offsets):
    """Sources of the spliced CSR: old rows, except rows ``c`` with ``row_of[c] = r >= 0`` taken
    from row ``r`` of the new CSR. Returns ``src`` (M,) int64: ``k >= 0`` is old entry ``k``,
    ``-1 - q`` is new entry ``q``; ``out_offsets`` (N + 1,) receives the offsets."""
    n = old_offsets.shape[0] - 1
    total = 0
    for c in range(n):
        out_offsets[c] = total
        r = row_of[c]
        total += new_offsets[r + 1] - new_offsets[r] if r >= 0 else old_offsets[c + 1] - old_offsets[c]
    out_offsets[n] = total
    src = np.empty(total, dtype=np.int64)
    p = 0
    for c in range(n):
        r = row_of[c]
        if r >= 0:
            for q in range(new_offsets[r], new_offsets[r + 1]):
                src[p] = -1 - q
                p += 1
        else:
            for k in range(old_offsets[c], old_offsets[c + 1]):
                src[p] = k
                p += 1
    return src


@njit(cache=True)
def gather(src, old, new, out):
    """``out[m] = old[src[m]]`` or ``new[-1 - src[m]]`` (1-D)."""
    for m in range(src.shape[0]):
        k = src[m]
        out[m] = old[k] if k >= 0 else new[-1 - k]


@njit(cache=True)
def gather2(src, old, new, out):
    """:func:`gather` of rows of 2-D arrays."""
    for m in range(src.shape[0]):
        k = src[m]
        if k >= 0:
            for c in range(old.shape[1]):
                out[m, c] = old[k, c]
        else:
            for c in range(new.shape[1]):
                out[m, c] = new[-1 - k, c]
