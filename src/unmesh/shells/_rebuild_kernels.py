"""Numba kernels of the local fiber rebuild after a crack (thesis 7.3.2): splicing CSR rows.

The connectivity arrays (neighbour lists, umbrella pairs, fibers with their state) are
grouped by node. A rebuild replaces the groups of the affected nodes; :func:`splice_runs`
gives, for the entries of the result, where they come from (runs of consecutive entries of
the old array, or of the array of new rows), and :func:`gather_runs` / :func:`gather_runs2`
copy them as contiguous blocks (a rebuild replaces a few hundred rows of arrays with ~10^5
entries: the cost of a memory copy). The result is what ``numpy.concatenate`` of the kept
and the new entries followed by a stable sort by node gives (the reference,
:func:`unmesh.shells.fracture.rebuild_near`), in one pass.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def splice_runs(old_offsets, row_of, new_offsets, out_offsets):
    """Sources of the spliced CSR: old rows, except rows ``c`` with ``row_of[c] = r >= 0`` taken
    from row ``r`` of the new CSR, as runs (R, 3) int64 ``(out start, source start, length)``
    with source ``k >= 0`` the old entries ``k, k + 1, ..``, ``-1 - q`` the new entries ``q, ..``
    (consecutive old rows form one run). ``out_offsets`` (N + 1,) receives the offsets."""
    n = old_offsets.shape[0] - 1
    runs = np.empty((2 * n + 1, 3), dtype=np.int64)
    nr = 0
    total = 0
    for c in range(n):
        out_offsets[c] = total
        r = row_of[c]
        if r >= 0:
            length = new_offsets[r + 1] - new_offsets[r]
            if length > 0:
                runs[nr, 0] = total
                runs[nr, 1] = -1 - new_offsets[r]
                runs[nr, 2] = length
                nr += 1
        else:
            length = old_offsets[c + 1] - old_offsets[c]
            if length > 0:
                if nr > 0 and runs[nr - 1, 1] >= 0 and runs[nr - 1, 1] + runs[nr - 1, 2] == old_offsets[c]:
                    runs[nr - 1, 2] += length
                else:
                    runs[nr, 0] = total
                    runs[nr, 1] = old_offsets[c]
                    runs[nr, 2] = length
                    nr += 1
        total += length
    out_offsets[n] = total
    return runs[:nr].copy()


@njit(cache=True)
def gather_runs(runs, old, new, out):
    """``out[o + e] = old[s + e]`` or ``new[-1 - s + e]`` for every run ``(o, s, m)``, ``e < m`` (1-D)."""
    for r in range(runs.shape[0]):
        o = runs[r, 0]
        s = runs[r, 1]
        m = runs[r, 2]
        if s >= 0:
            for e in range(m):
                out[o + e] = old[s + e]
        else:
            q = -1 - s
            for e in range(m):
                out[o + e] = new[q + e]


@njit(cache=True)
def gather_runs2(runs, old, new, out):
    """:func:`gather_runs` of rows of 2-D arrays."""
    for r in range(runs.shape[0]):
        o = runs[r, 0]
        s = runs[r, 1]
        m = runs[r, 2]
        w = out.shape[1]
        if s >= 0:
            for e in range(m):
                for c in range(w):
                    out[o + e, c] = old[s + e, c]
        else:
            q = -1 - s
            for e in range(m):
                for c in range(w):
                    out[o + e, c] = new[q + e, c]


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


@njit(cache=True)
def moved_rows(x, old_x, offsets, old_offsets, moved, only):
    """``moved[i]``: node ``i`` is not where it was (``x`` vs ``old_x``); ``only[i] |= `` its node-term
    offsets changed (``offsets`` vs ``old_offsets``, (N, 2)). Returns the number of moved nodes."""
    count = 0
    for i in range(x.shape[0]):
        moved[i] = x[i, 0] != old_x[i, 0] or x[i, 1] != old_x[i, 1] or x[i, 2] != old_x[i, 2]
        count += moved[i]
        if offsets[i, 0] != old_offsets[i, 0] or offsets[i, 1] != old_offsets[i, 1]:
            only[i] = True
    return count


@njit(cache=True)
def refresh_merge(only, centre, origin, last_len, last_ang, new_len, new_ang, last_force, before_force, new_force,
                  last_es, new_es, last_eb, new_eb, last_normal, new_normal, last_s, new_s, last_node, new_node):
    """Merge the masked force pass ``new_*`` of the centres ``only`` into the last pass, in place in ``new_*``.

    Fibers (F,) whose centre is listed keep the new ``l~`` and ``theta``, the others take those of
    their ``origin`` in the last pass; ``new_force = last_force - before_force + new_force`` for
    every node; the node values (energies, normals, umbrella vectors, node terms) of nodes not
    listed are those of the last pass (what ``numpy.where`` gives, element for element).
    """
    for k in range(centre.shape[0]):
        if not only[centre[k]]:
            o = max(origin[k], 0)
            new_len[k] = last_len[o]
            new_ang[k] = last_ang[o]
    for i in range(only.shape[0]):
        for c in range(3):
            new_force[i, c] = last_force[i, c] - before_force[i, c] + new_force[i, c]
        if not only[i]:
            new_es[i] = last_es[i]
            new_eb[i] = last_eb[i]
            for c in range(3):
                new_normal[i, c] = last_normal[i, c]
                new_s[i, c] = last_s[i, c]
            for c in range(4):
                new_node[i, c] = last_node[i, c]


@njit(cache=True)
def mark_on_fiber(fibers, out):
    """``out[i] = True`` (N,) bool for every node of a fiber (``out`` cleared first)."""
    out[:] = False
    for k in range(fibers.shape[0]):
        out[fibers[k, 0]] = True
        out[fibers[k, 1]] = True
        out[fibers[k, 2]] = True


@njit(cache=True)
def carry(origin, values, fresh, out):
    """``out[k] = values[origin[k]]`` where ``origin[k] >= 0``, else ``fresh[k]`` (``numpy.where``)."""
    for k in range(origin.shape[0]):
        o = origin[k]
        out[k] = values[o] if o >= 0 else fresh[k]


@njit(cache=True)
def fiber_partners(x, q, off, nbr, cos_limit, out):
    """Most-opposite-neighbour candidates of :func:`unmesh.shells.nodes.create_fibers` (7.4), (M, 3).

    For every centre ``q[r]`` with neighbours ``nbr[off[r]:off[r + 1]]`` and every neighbour
    ``j``: ``j'`` the first neighbour minimising ``e_j'.e_j - |e_j|^2`` (``e = x_n - x_i``); the
    row ``(i, min(j, j'), max(j, j'))`` is written when ``j' != j`` and the cosine of the angle
    between ``e_j`` and ``e_j'`` is at most ``cos_limit``. Same arithmetic and order as the
    numpy reference (``create_fibers_reference``); returns the number of rows.
    """
    m = 0
    kmax = 0
    for r in range(q.shape[0]):
        kmax = max(kmax, off[r + 1] - off[r])
    e = np.empty((max(kmax, 1), 3))
    nrm = np.empty(max(kmax, 1))
    for r in range(q.shape[0]):
        i = q[r]
        a0 = off[r]
        cnt = off[r + 1] - a0
        for a in range(cnt):
            j = nbr[a0 + a]
            for c in range(3):
                e[a, c] = x[j, c] - x[i, c]
            nrm[a] = math.sqrt(e[a, 0] * e[a, 0] + (e[a, 1] * e[a, 1] + e[a, 2] * e[a, 2]))
        for a in range(cnt):
            daa = e[a, 0] * e[a, 0] + e[a, 1] * e[a, 1] + e[a, 2] * e[a, 2]
            best = np.inf
            jb = 0
            dbest = 0.0
            for b in range(cnt):
                dab = e[a, 0] * e[b, 0] + e[a, 1] * e[b, 1] + e[a, 2] * e[b, 2]
                if dab - daa < best:
                    best = dab - daa
                    jb = b
                    dbest = dab
            j = nbr[a0 + a]
            jp = nbr[a0 + jb]
            if jp == j:
                continue
            if dbest / max(nrm[a] * nrm[jb], 1e-300) <= cos_limit:
                out[m, 0] = i
                out[m, 1] = min(j, jp)
                out[m, 2] = max(j, jp)
                m += 1
    return m
