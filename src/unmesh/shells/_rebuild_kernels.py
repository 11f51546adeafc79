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


@njit(cache=True)
def changed_centres(old_foff, old_fibers, old_poff, old_pairs, old_soft, old_offs, old_l0, old_lp, old_a0, old_ap,
                    old_ss, old_bs, new_foff, new_fibers, new_poff, new_pairs, new_soft, new_offs, new_l0, new_lp,
                    new_a0, new_ap, new_ss, new_bs, moved, out):
    """``out[c]`` (N,) bool: the force contribution of centre ``c`` may differ between the old
    arrays at the old positions and the new arrays at the new positions -- its fibers (nodes,
    rest lengths and angles with their plastic parts, stiffness scales), umbrella pairs,
    regularisation or node-term offsets changed, or one of the nodes it touches ``moved``."""
    for c in range(out.shape[0]):
        ch = moved[c] or old_soft[c] != new_soft[c] or old_offs[c, 0] != new_offs[c, 0] or old_offs[c, 1] != new_offs[c, 1]
        m = old_foff[c + 1] - old_foff[c]
        p = old_poff[c + 1] - old_poff[c]
        ch = ch or m != new_foff[c + 1] - new_foff[c] or p != new_poff[c + 1] - new_poff[c]
        q = 0
        while not ch and q < m:
            ko = old_foff[c] + q
            kn = new_foff[c] + q
            a = old_fibers[ko, 0]
            b = old_fibers[ko, 2]
            ch = (a != new_fibers[kn, 0] or b != new_fibers[kn, 2] or moved[a] or moved[b]
                  or old_l0[ko] != new_l0[kn] or old_lp[ko] != new_lp[kn] or old_a0[ko] != new_a0[kn]
                  or old_ap[ko] != new_ap[kn] or old_ss[ko] != new_ss[kn] or old_bs[ko] != new_bs[kn])
            q += 1
        q = 0
        while not ch and q < p:
            po = old_poff[c] + q
            pn = new_poff[c] + q
            a = old_pairs[po, 0]
            b = old_pairs[po, 1]
            ch = a != new_pairs[pn, 0] or b != new_pairs[pn, 1] or moved[a] or moved[b]
            q += 1
        out[c] = ch


@njit(cache=True)
def touching(fibers, pairs, pair_offsets, moved, out):
    """Mark in ``out`` (N,) every centre with a fiber or umbrella pair that touches a ``moved`` node."""
    for k in range(fibers.shape[0]):
        if moved[fibers[k, 0]] or moved[fibers[k, 1]] or moved[fibers[k, 2]]:
            out[fibers[k, 1]] = True
    for c in range(pair_offsets.shape[0] - 1):
        if moved[c]:
            out[c] = True
        for q in range(pair_offsets[c], pair_offsets[c + 1]):
            if moved[pairs[q, 0]] or moved[pairs[q, 1]]:
                out[c] = True
