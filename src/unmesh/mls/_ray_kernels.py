"""Numba kernels of MLS ray casting (thesis section 3.1.3, Algorithm 3.1).

Ray starts (:func:`first_disc`) are the nearest hits of the ray with the surfel discs
(radius ``grho``), found in one ray grid per power-of-two band of the disc radii (see
:meth:`unmesh.mls.MLSSurface.ray_grid` for the arrays ``r_*``) by a 3D-DDA walk with
empty-space skipping; from there :func:`ray_iterate` intersects the ray with the
local fit planes of :func:`unmesh.mls._kernels.local_fit`, reusing candidate lists
as described in :mod:`unmesh.mls._kernels` (whose argument conventions apply).

The plain numpy reference implementation is ``tests/mls/reference.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.mls._kernels import _BLOCK, block_scratch, local_fit, refresh
from unmesh.spatial._kernels import find_cell


@njit(cache=True)
def ray_cells(pos, rho, idx, lo, cell, dims, keys, items):
    """List sample ``idx[m]`` in every ray-grid cell its disc's bounding sphere overlaps.

    Cells have edge ``cell`` from ``lo``; with ``cell >= 2·ρ`` a sample lands in at
    most 8 cells, so ``keys``/``items`` need ``8·len(idx)`` entries. Returns the number
    of entries written (sample-major).
    """
    n = 0
    c0 = np.empty(3, np.int64)
    c1 = np.empty(3, np.int64)
    for m in range(idx.shape[0]):
        a = idx[m]
        for ax in range(3):
            u = math.floor((pos[a, ax] - rho[a] - lo[ax]) / cell)
            v = math.floor((pos[a, ax] + rho[a] - lo[ax]) / cell)
            c0[ax] = min(max(u, 0), dims[ax] - 1)
            c1[ax] = min(max(v, 0), dims[ax] - 1)
        for i in range(c0[0], c1[0] + 1):
            for j in range(c0[1], c1[1] + 1):
                for k in range(c0[2], c1[2] + 1):
                    keys[n] = (i * dims[1] + j) * dims[2] + k
                    items[n] = a
                    n += 1
    return n


@njit(cache=True)
def _scan_cell(key, keys, start, items, gpack, grho, o, d, tlo, thi, best):
    """Ray–disc tests against the discs listed in the ray-grid cell with ``key``.

    Keeps the nearest hit with ``tlo <= t <= thi`` in ``best`` (``best[0]`` = t,
    ``best[1]`` = sample index as float).
    """
    c = find_cell(key, keys)
    if c < 0:
        return
    o0, o1, o2 = o[0], o[1], o[2]
    d0, d1, d2 = d[0], d[1], d[2]
    for m in range(start[c], start[c + 1]):
        a = items[m]
        den = gpack[a, 3] * d0 + gpack[a, 4] * d1 + gpack[a, 5] * d2
        if den == 0.0:
            continue
        cx = gpack[a, 0] - o0
        cy = gpack[a, 1] - o1
        cz = gpack[a, 2] - o2
        t = (gpack[a, 3] * cx + gpack[a, 4] * cy + gpack[a, 5] * cz) / den
        if t < tlo or t > thi or t >= best[0]:
            continue
        ex = t * d0 - cx
        ey = t * d1 - cy
        ez = t * d2 - cz
        if ex * ex + ey * ey + ez * ez <= grho[a] * grho[a]:
            best[0] = t
            best[1] = a


@njit(cache=True)
def _walk(o, d, tlo, thi, gpack, grho, origin, cell, dims, keys, start, items, skip, use_skip, best):
    """Improve ``best`` with the disc hits of one ray-grid level in ``[tlo, thi]`` (3D-DDA walk).

    Every sample is listed in each cell its disc's bounding sphere overlaps, so the
    disc hits inside a cell are all found by scanning that cell's list, and a hit is
    final once it lies before the exit of the current cell. Empty space is skipped
    with ``skip`` (when ``use_skip``): the Chebyshev distance in cells from each cell
    to the nearest non-empty one; from a cell at distance D >= 3 the ray jumps
    ``D − 2`` cells.
    """
    n0, n1, n2 = dims[0], dims[1], dims[2]
    dmax = max(abs(d[0]), abs(d[1]), abs(d[2]))
    # clip to the grid box
    tcur = tlo
    for ax in range(3):
        lo = origin[ax]
        hi = origin[ax] + dims[ax] * cell
        if d[ax] == 0.0:
            if o[ax] < lo or o[ax] > hi:
                return
        else:
            ta = (lo - o[ax]) / d[ax]
            tb = (hi - o[ax]) / d[ax]
            if ta > tb:
                ta, tb = tb, ta
            tcur = max(tcur, ta)
            thi = min(thi, tb)
    if not tcur <= thi:
        return
    # per axis: key stride, step direction, time between cell faces
    st0, st1, st2 = n1 * n2, n2, 1
    s0 = 1 if d[0] > 0.0 else (-1 if d[0] < 0.0 else 0)
    s1 = 1 if d[1] > 0.0 else (-1 if d[1] < 0.0 else 0)
    s2 = 1 if d[2] > 0.0 else (-1 if d[2] < 0.0 else 0)
    td0 = cell / abs(d[0]) if s0 != 0 else math.inf
    td1 = cell / abs(d[1]) if s1 != 0 else math.inf
    td2 = cell / abs(d[2]) if s2 != 0 else math.inf
    while True:
        # (re)start the walk at tcur: cell and time of the next face crossing per axis
        p0 = o[0] + tcur * d[0]
        p1 = o[1] + tcur * d[1]
        p2 = o[2] + tcur * d[2]
        c0 = min(max(math.floor((p0 - origin[0]) / cell), 0), n0 - 1)
        c1 = min(max(math.floor((p1 - origin[1]) / cell), 0), n1 - 1)
        c2 = min(max(math.floor((p2 - origin[2]) / cell), 0), n2 - 1)
        tm0 = tcur + (origin[0] + (c0 + (s0 > 0)) * cell - p0) / d[0] if s0 != 0 else math.inf
        tm1 = tcur + (origin[1] + (c1 + (s1 > 0)) * cell - p1) / d[1] if s1 != 0 else math.inf
        tm2 = tcur + (origin[2] + (c2 + (s2 > 0)) * cell - p2) / d[2] if s2 != 0 else math.inf
        key = (c0 * n1 + c1) * n2 + c2
        jumped = False
        while True:
            dist = skip[key] if use_skip else 0
            if dist == 0:
                _scan_cell(key, keys, start, items, gpack, grho, o, d, tlo, thi, best)
            texit = min(tm0, tm1, tm2)
            if best[0] <= texit or texit > thi:
                return
            if dist >= 2:
                tj = min(texit + (dist - 1.25) * cell / dmax, best[0])
                if tj > thi:
                    return
                if tj > tcur:
                    tcur = tj
                    jumped = True
                    break
            if tm0 <= tm1 and tm0 <= tm2:
                c0 += s0
                tm0 += td0
                key += s0 * st0
                if c0 < 0 or c0 >= n0:
                    return
            elif tm1 <= tm2:
                c1 += s1
                tm1 += td1
                key += s1 * st1
                if c1 < 0 or c1 >= n1:
                    return
            else:
                c2 += s2
                tm2 += td2
                key += s2 * st2
                if c2 < 0 or c2 >= n2:
                    return
        if not jumped:
            return


@njit(cache=True)
def first_disc(o, d, tlo, thi, gpack, grho, r_origin, r_cell, r_dims, r_koff, r_keys, r_start, r_items, r_skoff,
               r_skip, r_use_skip, best):
    """Nearest ray–disc hit with ``tlo <= t <= thi`` over all ray-grid levels.

    Walks each level (:func:`_walk`) up to the best hit so far. Returns True and
    ``best = (t, sample)`` when found.
    """
    best[0] = math.inf
    best[1] = -1.0
    for lv in range(r_cell.shape[0]):
        k0 = r_koff[lv]
        k1 = r_koff[lv + 1]
        _walk(o, d, tlo, min(thi, best[0]), gpack, grho, r_origin[lv], r_cell[lv], r_dims[lv], r_keys[k0:k1],
              r_start[k0 + lv:k1 + lv + 1], r_items, r_skip[r_skoff[lv]:r_skoff[lv + 1]], r_use_skip[lv], best)
    return best[1] >= 0.0


@njit(cache=True)
def ray_iterate(o, d, t0, gpack, kernel, normal_mode, degree, margin,
                lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, max_iter, tol, reach_len,
                ranges, A, rhs, res, cand, cbuf, nbuf, centre, meta, x):
    """Algorithm 3.1 from ``x_0 = o + t0 d``: intersect the ray with the local fit plane until converged.

    The plane at ``x_k = o + t_k d`` passes through the foot point p with normal n; its
    intersection with the ray is ``t_k + g(t_k)`` with the step
    ``g(t) = n·(p − x)/(n·d)`` (Algorithm 3.1, line 4, sign corrected), whose root is
    the intersection with the MLS surface. Plain plane steps (a Newton iteration on g)
    can fall into a 2-cycle where the fit changes quickly along the ray (creases, folds
    of scanned models); so once two iterates have steps of opposite sign they bracket
    the root and the next iterate is the Illinois (modified regula falsi) point of the
    bracket instead. Converged when ``|g(t)|·|d| <= tol·σ`` (returns ``t + g(t)``) or
    the bracket is that narrow. Returns ``(converged, t, cand, cbuf, nbuf)``; fails
    when no kernel reaches an iterate, the ray is nearly parallel to the plane, or the
    iterate drifts more than ``reach_len`` from the start. ``res`` holds the fit at the
    last iterate (within ``tol·σ`` of the returned point when converged).
    """
    dn = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    t = t0
    ta = ga = tb = gb = 0.0  # bracket ends: step g > 0 at ta, g < 0 at tb
    has_a = has_b = False
    side = 0  # which end moved last (Illinois: halve the other end's g when one end moves twice)
    for _ in range(max_iter):
        for ax in range(3):
            x[ax] = o[ax] + t * d[ax]
        cand, cbuf, nbuf = refresh(x, margin, gpack, lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start,
                                   ranges, cand, cbuf, nbuf, centre, meta)
        if not local_fit(x, kernel, normal_mode, degree, cbuf, meta[0], nbuf, A, rhs, res):
            return False, t, cand, cbuf, nbuf
        nd = res[3] * d[0] + res[4] * d[1] + res[5] * d[2]
        if abs(nd) < 1e-3 * dn:
            return False, t, cand, cbuf, nbuf
        g = (res[3] * (res[0] - x[0]) + res[4] * (res[1] - x[1]) + res[5] * (res[2] - x[2])) / nd
        tn = t + g
        if abs(tn - t0) * dn > reach_len:
            return False, tn, cand, cbuf, nbuf
        if abs(g) * dn <= tol * res[10]:
            return True, tn, cand, cbuf, nbuf
        if g > 0.0:
            if side == 1 and has_b:
                gb *= 0.5
            ta, ga, has_a, side = t, g, True, 1
        else:
            if side == 2 and has_a:
                ga *= 0.5
            tb, gb, has_b, side = t, g, True, 2
        if has_a and has_b:
            if abs(tb - ta) * dn <= tol * res[10]:
                return True, tn, cand, cbuf, nbuf
            tn = (ta * gb - tb * ga) / (gb - ga)
        t = tn
    return False, t, cand, cbuf, nbuf


@njit(cache=True)
def _intersect_block(blk, origins, dirs, tmax, gpack, kernel, normal_mode, degree, margin, lv_origin, lv_inv,
                     lv_dims, lv_koff, lv_keys, lv_start, grho, rho_max, reach_len, r_origin, r_cell, r_dims,
                     r_koff, r_keys, r_start, r_items, r_skoff, r_skip, r_use_skip, max_iter, tol, eps2,
                     max_attempts, out_t, out_hit, out_n, nr):
    """Rays of block ``blk`` (body of :func:`intersect_kernel`)."""
    ranges, A, rhs, res, cand, cbuf, nbuf, centre, meta = block_scratch()
    x = np.empty(3)
    best = np.empty(2)
    o = np.empty(3)
    d = np.empty(3)
    for ri in range(blk * _BLOCK, min(nr, (blk + 1) * _BLOCK)):
        out_t[ri] = math.inf
        out_hit[ri] = False
        for ax in range(3):
            out_n[ri, ax] = math.nan
            o[ax] = origins[ri, ax]
            d[ax] = dirs[ri, ax]
        dn = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        # a disc may be hit slightly behind the origin with the surface in front of it
        t0 = -rho_max / dn
        t1 = tmax[ri]
        tlo = t0
        for _ in range(max_attempts):
            if not first_disc(o, d, tlo, t1, gpack, grho, r_origin, r_cell, r_dims, r_koff, r_keys, r_start,
                              r_items, r_skoff, r_skip, r_use_skip, best):
                break
            th = best[0]
            j = int(best[1])
            ok, tc, cand, cbuf, nbuf = ray_iterate(o, d, th, gpack, kernel, normal_mode, degree, margin,
                                                   lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start,
                                                   max_iter, tol, reach_len, ranges, A, rhs, res, cand, cbuf,
                                                   nbuf, centre, meta, x)
            if ok and tc > 0.0:
                if tc > tmax[ri]:
                    break
                # line 6 of Algorithm 3.1, with the fit of the last iterate (within tol·σ of x)
                e = 0.0
                for ax in range(3):
                    e += (res[6 + ax] - (o[ax] + tc * d[ax])) ** 2
                if math.sqrt(e) < eps2 * res[10]:
                    out_t[ri] = tc
                    out_hit[ri] = True
                    out_n[ri, 0] = res[3]
                    out_n[ri, 1] = res[4]
                    out_n[ri, 2] = res[5]
                    break
            tlo = th + grho[j] / dn
            if tlo > t1:
                break


@njit(cache=True, parallel=True)
def intersect_kernel(origins, dirs, tmax, gpack, kernel, normal_mode, degree, margin,
                     lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, grho, rho_max, reach_len,
                     r_origin, r_cell, r_dims, r_koff, r_keys, r_start, r_items, r_skoff, r_skip, r_use_skip,
                     max_iter, tol, eps2, max_attempts, out_t, out_hit, out_n):
    """First intersection with t > 0 of every ray with the MLS surface (Algorithm 3.1).

    For each ray: find the nearest surfel-disc hit (:func:`first_disc`, which culls
    the ray against the ray grids' boxes) in ``[−ρ_max/|d|, tmax]`` as the start point;
    run :func:`ray_iterate`; accept when it converges to ``t > 0`` with
    ``‖q(x) − x‖ < eps2·σ`` (line 6 of Algorithm 3.1). Otherwise continue behind the
    failed start (by the disc radius), at most ``max_attempts`` times.
    """
    nr = origins.shape[0]
    nblk = (nr + _BLOCK - 1) // _BLOCK
    # a thin prange loop over a serial block body (typed once, not again inside the parfor)
    for blk in prange(nblk):
        _intersect_block(np.int64(blk), origins, dirs, tmax, gpack, kernel, normal_mode, degree, margin,
                         lv_origin, lv_inv, lv_dims, lv_koff, lv_keys, lv_start, grho, rho_max, reach_len,
                         r_origin, r_cell, r_dims, r_koff, r_keys, r_start, r_items, r_skoff, r_skip,
                         r_use_skip, max_iter, tol, eps2, max_attempts, out_t, out_hit, out_n, nr)
