"""Numba kernels for the elastic forces of a fiber-sampled shell (thesis 7.2.2, eqs. 7.5-7.17).

Numpy reference: :func:`unmesh.shells.energy.elastic_forces_reference`. The fiber geometry
(arc length, tangent angle and their gradients) is in :mod:`unmesh.shells._fiber_kernels`.
Forces are computed in one pass over the centre nodes, whose fibers are contiguous
(:func:`node_forces`): per node the umbrella vector, each fiber's ``l~`` and ``theta``
with gradients, the node sums ``A_i``, ``H_i`` and then the force triplets (7.16) of its
fibers and the umbrella-normal terms. The nodes are split into a fixed number of
contiguous ranges (chunks), each scattering into its own buffer, so no two threads write
the same entry and the summation order does not depend on the number of threads.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.shells._block_kernels import BLK, ROWS, block_forces
from unmesh.shells._fiber_kernels import (
    FASTMATH,
    _cross,
    angle,
    arc,
    degenerate_edges,
    umbrella_at,
)

#: Doubles of per-fiber scratch in :func:`node_forces`: dl/dx1, dl/dx2, dtheta/dx1, dtheta/dx2, dtheta/dN.
SCRATCH = 15


@njit(cache=True, fastmath=FASTMATH, inline="always")
def node_forces(i, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast, sscale,
                bscale, ks, kb, gram, ref, offs, buf, scr, out_len, out_ang, out_s, out_normal, out_node, scatter,
                ratio2):
    """Energy and force contributions of node ``i``'s umbrella and fibers (7.5-7.17).

    One pass per centre node: the umbrella vector ``s_i`` (normal of the tangent angles),
    every fiber's ``l~`` and ``theta`` with gradients (kept in ``scr`` (cap, SCRATCH)), the
    node sums, then (``scatter``) ``dE/dx`` of every node touched by the fibers and the umbrella
    scattered into ``buf`` (N, 3) (``buf -= dE/dx``). Energies (per node ``i``, ``m`` fibers ``k``)::

        E_s = K_s/2 [ mean(sigma) da^2 + (1/m) sum_k sigma_k (A_k - A_k^0)^2 ]      (7.7)
        E_b = K_b/2 A_i^0 mean(beta) dh^2                                          (7.11)
        da  = A_i - A_i^0 - offs[i, 0],   dh = H_i - H_i^0 - offs[i, 1]
        H_i = sum_k beta_k theta_k / sum_k beta_k                                  (7.9)

    (the printed forms; see :mod:`unmesh.shells.energy`). Each ``theta`` is taken on the
    branch nearest ``ref[k]``. ``gram`` is the table of
    :func:`unmesh.shells._fiber_kernels.gram_weights`.

    Returns
    -------
    (es, eb, folds, bad)
        Membrane and bending energy of the node, the number of its fibers whose angle moved
        by more than pi/2 from ``ref``, and (``ratio2 > 0``) the number of degenerate ones
        (:func:`unmesh.shells._fiber_kernels.degenerate_edges`, squared ratio ``ratio2``).
    """
    xi0 = x[i, 0]
    xi1 = x[i, 1]
    xi2 = x[i, 2]
    p0 = pstart[i]
    umbrella_at(i, x, pairs, p0, p0 + pcount[i], out_s, out_normal)
    s0 = out_s[i, 0]
    s1 = out_s[i, 1]
    s2 = out_s[i, 2]
    m = fcount[i]
    if m == 0:
        out_node[i, 0] = 0.0
        out_node[i, 1] = 0.0
        out_node[i, 2] = 0.0
        out_node[i, 3] = 0.0
        return 0.0, 0.0, 0, 0
    f0 = fstart[i]
    sf = soft[i]
    q4 = math.pi / 4.0
    two_pi = 2.0 * math.pi
    inv_two_pi = 1.0 / two_pi
    area = 0.0
    area0 = 0.0
    sig = 0.0
    bsum = 0.0
    h = 0.0
    h0 = 0.0
    folds = 0
    bad = 0
    for q in range(m):
        k = f0 + q
        j1 = fibers[k, 0]
        j2 = fibers[k, 2]
        d10 = x[j1, 0] - xi0
        d11 = x[j1, 1] - xi1
        d12 = x[j1, 2] - xi2
        d20 = x[j2, 0] - xi0
        d21 = x[j2, 1] - xi1
        d22 = x[j2, 2] - xi2
        if ratio2 > 0.0 and degenerate_edges(d10, d11, d12, d20, d21, d22, s0, s1, s2, sf, ratio2):
            bad += 1
        ln, g11, g12, g22 = arc(d10, d11, d12, d20, d21, d22, gram)
        th, ga0, ga1, ga2, gc0, gc1, gc2, gn0, gn1, gn2 = angle(d10, d11, d12, d20, d21, d22, s0, s1, s2, sf, True)
        r = ref[k]
        th += two_pi * math.floor((r - th) * inv_two_pi + 0.5)
        if abs(th - r) > 0.5 * math.pi:
            folds += 1
        out_len[k] = ln
        out_ang[k] = th
        g = scr
        g[q, 0] = g11 * d10 + g12 * d20
        g[q, 1] = g11 * d11 + g12 * d21
        g[q, 2] = g11 * d12 + g12 * d22
        g[q, 3] = g12 * d10 + g22 * d20
        g[q, 4] = g12 * d11 + g22 * d21
        g[q, 5] = g12 * d12 + g22 * d22
        g[q, 6] = ga0
        g[q, 7] = ga1
        g[q, 8] = ga2
        g[q, 9] = gc0
        g[q, 10] = gc1
        g[q, 11] = gc2
        g[q, 12] = gn0
        g[q, 13] = gn1
        g[q, 14] = gn2
        l0 = lorig[k] + lplast[k]
        area += q4 * ln * ln
        area0 += q4 * l0 * l0
        sig += sscale[k]
        bk = bscale[k]
        bsum += bk
        h += bk * th
        h0 += bk * (aorig[k] + aplast[k])
    inv_m = 1.0 / m
    area *= inv_m
    area0 *= inv_m
    sig *= inv_m
    if bsum > 0.0:
        h /= bsum
        h0 /= bsum
    out_node[i, 0] = area
    out_node[i, 1] = area0
    out_node[i, 2] = h
    out_node[i, 3] = h0
    da = area - area0 - offs[i, 0]
    dh = h - h0 - offs[i, 1]
    esum = 0.0
    gs0 = 0.0
    gs1 = 0.0
    gs2 = 0.0
    fi0 = 0.0
    fi1 = 0.0
    fi2 = 0.0
    half_pi = 0.5 * math.pi
    kd = kb * area0 * dh * inv_m
    for q in range(m):
        k = f0 + q
        g = scr
        ln = out_len[k]
        l0 = lorig[k] + lplast[k]
        dak = q4 * (ln * ln - l0 * l0)
        sk = sscale[k]
        esum += sk * dak * dak
        if not scatter:
            continue
        de_dl = ks * inv_m * (sig * da + sk * dak) * half_pi * ln
        de_dth = kd * bscale[k]
        j1 = fibers[k, 0]
        j2 = fibers[k, 2]
        a0 = de_dl * g[q, 0] + de_dth * g[q, 6]
        a1 = de_dl * g[q, 1] + de_dth * g[q, 7]
        a2 = de_dl * g[q, 2] + de_dth * g[q, 8]
        c0 = de_dl * g[q, 3] + de_dth * g[q, 9]
        c1 = de_dl * g[q, 4] + de_dth * g[q, 10]
        c2 = de_dl * g[q, 5] + de_dth * g[q, 11]
        buf[j1, 0] -= a0
        buf[j1, 1] -= a1
        buf[j1, 2] -= a2
        buf[j2, 0] -= c0
        buf[j2, 1] -= c1
        buf[j2, 2] -= c2
        fi0 += a0 + c0
        fi1 += a1 + c1
        fi2 += a2 + c2
        gs0 += de_dth * g[q, 12]
        gs1 += de_dth * g[q, 13]
        gs2 += de_dth * g[q, 14]
    es = 0.5 * ks * (sig * da * da + esum * inv_m)
    eb = 0.5 * kb * area0 * bsum * inv_m * dh * dh
    if not scatter:
        return es, eb, folds, bad
    if gs0 != 0.0 or gs1 != 0.0 or gs2 != 0.0:
        # through the umbrella vector s_i = sum e_a x e_b: dE/dx_a = e_b x g, dE/dx_b = g x e_a
        for q in range(p0, p0 + pcount[i]):
            a = pairs[q, 0]
            b = pairs[q, 1]
            ga0, ga1, ga2 = _cross(x[b, 0] - xi0, x[b, 1] - xi1, x[b, 2] - xi2, gs0, gs1, gs2)
            gb0, gb1, gb2 = _cross(gs0, gs1, gs2, x[a, 0] - xi0, x[a, 1] - xi1, x[a, 2] - xi2)
            buf[a, 0] -= ga0
            buf[a, 1] -= ga1
            buf[a, 2] -= ga2
            buf[b, 0] -= gb0
            buf[b, 1] -= gb1
            buf[b, 2] -= gb2
            fi0 += ga0 + gb0
            fi1 += ga1 + gb1
            fi2 += ga2 + gb2
    buf[i, 0] += fi0
    buf[i, 1] += fi1
    buf[i, 2] += fi2
    return es, eb, folds, bad


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def chunk_forces(lo, hi, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast,
                 sscale, bscale, ks, kb, gram, ref, offs, buf, blk, scr, out_len, out_ang, out_s, out_normal, out_node,
                 out_es, out_eb, only, scatter, ratio2):
    """Forces of the nodes ``lo .. hi-1`` into ``buf`` (``buf -= dE/dx``); returns the fold count and
    (``ratio2 > 0``) the number of degenerate fibers (:func:`node_forces`).

    Consecutive nodes are grouped into blocks of at most :data:`BLK` fibers for
    :func:`unmesh.shells._block_kernels.block_forces` (a node with more fibers takes the
    scalar :func:`node_forces`). With a non-empty bool mask ``only`` (N,), only blocks that
    contain a listed node are evaluated and only the listed nodes' forces are scattered;
    ``scatter`` False skips the forces.
    """
    folds = 0
    bad = 0
    a = lo
    masked = only.shape[0] > 0
    while a < hi:
        if fcount[a] > BLK:
            if not masked or only[a]:
                es, eb, fo, bd = node_forces(a, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast,
                                             aorig, aplast, sscale, bscale, ks, kb, gram, ref, offs, buf, scr, out_len,
                                             out_ang, out_s, out_normal, out_node, scatter, ratio2)
                out_es[a] = es
                out_eb[a] = eb
                folds += fo
                bad += bd
            a += 1
            continue
        b = a + 1
        while b < hi and fcount[b] <= BLK and fstart[b] + fcount[b] - fstart[a] <= BLK:
            b += 1
        wanted = not masked
        for i in range(a, b):
            if masked and only[i]:
                wanted = True
        if wanted:
            fo, bd = block_forces(a, b, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig,
                                  aplast, sscale, bscale, ks, kb, gram, ref, offs, buf, blk, out_len, out_ang, out_s,
                                  out_normal, out_node, out_es, out_eb, scatter, only, ratio2)
            folds += fo
            bad += bd
        a = b
    return folds, bad


@njit(cache=True)
def touched_range(lo, hi, pairs, pstart, pcount, fibers, fstart, fcount, only):
    """Smallest node range ``[a, b)`` holding every node the forces of nodes ``lo .. hi-1`` touch
    (their fibers' ends and umbrella pairs): the part of a chunk buffer that is not zero. With
    a non-empty mask ``only`` (N,), of the listed nodes only (the only ones that scatter)."""
    if hi <= lo:
        return lo, lo
    if only.shape[0] == 0:
        a = lo
        b = hi
        for k in range(fstart[lo], fstart[hi - 1] + fcount[hi - 1]):
            a = min(a, fibers[k, 0], fibers[k, 2])
            b = max(b, fibers[k, 0] + 1, fibers[k, 2] + 1)
        for q in range(pstart[lo], pstart[hi - 1] + pcount[hi - 1]):
            a = min(a, pairs[q, 0], pairs[q, 1])
            b = max(b, pairs[q, 0] + 1, pairs[q, 1] + 1)
        return a, b
    a = hi
    b = lo
    for i in range(lo, hi):
        if only[i]:
            a = min(a, i)
            b = max(b, i + 1)
            for k in range(fstart[i], fstart[i] + fcount[i]):
                a = min(a, fibers[k, 0], fibers[k, 2])
                b = max(b, fibers[k, 0] + 1, fibers[k, 2] + 1)
            for q in range(pstart[i], pstart[i] + pcount[i]):
                a = min(a, pairs[q, 0], pairs[q, 1])
                b = max(b, pairs[q, 0] + 1, pairs[q, 1] + 1)
    if b <= a:
        return lo, lo
    return a, b


@njit(cache=True, inline="always")
def _clear_rows(b, lo, hi):
    """``b[lo:hi, :] = 0`` as a loop (an array expression in a parallel kernel is a parallel loop of its own)."""
    for i in range(lo, hi):
        for d in range(b.shape[1]):
            b[i, d] = 0.0


@njit(cache=True, inline="always")
def sum_chunks(i, chunks, buf, span):
    """Force on node ``i``: the sum over the chunk buffers that can hold a contribution (fixed order)."""
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    for c in range(chunks):
        if span[c, 0] <= i < span[c, 1]:
            f0 += buf[c, i, 0]
            f1 += buf[c, i, 1]
            f2 += buf[c, i, 2]
    return f0, f1, f2


@njit(cache=True, parallel={"fusion": False}, fastmath=FASTMATH, error_model="numpy")
def force_chunks(chunks, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast,
                 sscale, bscale, ks, kb, gram, ref, offs, cap, buf, out_force, out_len, out_ang, out_s,
                 out_normal, out_node, out_es, out_eb, only, scatter):
    """Elastic forces of all nodes (7.16): ``chunks`` contiguous node ranges in parallel.

    Every chunk scatters into its own buffer ``buf[c]`` (chunks, N, 3) -- no write races --
    and the buffers are summed into ``out_force`` (N, 3); only the node range a chunk can
    touch (:func:`touched_range`) is cleared and summed. ``cap`` is the largest fiber count
    of a node (scratch size). With a non-empty mask ``only`` (N,) only the blocks holding
    listed nodes are evaluated (same arithmetic) and only the listed nodes' force
    contributions summed; ``scatter`` False computes measures, node terms and energies only.
    """
    n = x.shape[0]
    # plain loops, no array expressions: in a parallel kernel each would be a parallel loop of its own
    # (a separate compile)
    span = np.empty((chunks, 2), dtype=np.int64)
    for c in range(chunks):
        span[c, 0] = 0
        span[c, 1] = 0
    masked = only.shape[0] > 0
    for c in prange(chunks):
        b = buf[c]
        c0 = c * n // chunks
        c1 = (c + 1) * n // chunks
        if masked:
            listed = False
            for i in range(c0, c1):
                listed |= only[i]
            if not listed:
                continue
        if scatter:
            lo, hi = touched_range(c0, c1, pairs, pstart, pcount, fibers, fstart, fcount, only)
            span[c, 0] = lo
            span[c, 1] = hi
            _clear_rows(b, lo, hi)
        blk = np.empty(ROWS * BLK)
        scr = np.empty((max(cap, 1), SCRATCH))
        chunk_forces(c0, c1, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast,
                     sscale, bscale, ks, kb, gram, ref, offs, b, blk, scr, out_len, out_ang, out_s, out_normal,
                     out_node, out_es, out_eb, only, scatter, 0.0)
    if not scatter:
        return
    # nodes outside every chunk's range get no contribution: zero (the sum of zeros)
    for i in prange(n):
        f0, f1, f2 = sum_chunks(i, chunks, buf, span)
        out_force[i, 0] = f0
        out_force[i, 1] = f1
        out_force[i, 2] = f2
