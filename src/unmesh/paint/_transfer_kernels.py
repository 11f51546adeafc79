"""Numba kernels of one paint event's bookkeeping (thesis 5.5): the numpy step chains of
:func:`unmesh.paint.transfer.paint_event` fused into single passes, each without its dozen
temporaries. References (the former numpy steps) in :mod:`unmesh.paint.transfer`:
:func:`~unmesh.paint.transfer.near_rows_reference`,
:func:`~unmesh.paint.transfer.hidden_fathers_reference`,
:func:`~unmesh.paint.transfer.replaced_pixels_reference`,
:func:`~unmesh.paint.transfer.pixel_state_reference`,
:func:`~unmesh.paint.transfer.brush_pixels_reference`,
:func:`~unmesh.paint.transfer.brush_write_back_reference`,
:func:`~unmesh.paint.transfer.child_frames_reference`,
:func:`~unmesh.paint.transfer.merge_orphans` (of :func:`merge_orphan_rows`).

All but the first two are the same operations in the same order as their references (tests
compare bit for bit). :func:`near_rows` and :func:`hidden_fathers` project onto the plane
axes with ``(x0 n0 + x1 n1) + x2 n2``, where numpy's matrix products (BLAS) round differently
(and differently by the row's position in the array): their projections agree with the
reference to round-off and are used only in comparisons (selection, pixel ownership, the
nearest father), never stored.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _dot3(a, i, v):  # pragma: no cover - numba
    return (a[i, 0] * v[0] + a[i, 1] * v[1]) + a[i, 2] * v[2]


@njit(cache=True)
def near_rows(rows, pos, nrm, rad, o, N, t1, t2, reach, out_rows, pos_r, nrm_r, rad_r, ou):  # pragma: no cover - numba
    """The rows among ``rows`` that face the plane (``nrm . N > 0.2``) within ``reach`` of it
    (``|(pos - o) . N| < reach``), in order: their indices, positions, normals, radii and plane
    coordinates ``((pos - o) . t1, (pos - o) . t2)`` into the first ``m`` entries of the outputs
    (each as long as ``rows``); returns ``m``."""
    m = 0
    rel = np.empty(3)
    for k in range(rows.shape[0]):
        r = rows[k]
        for c in range(3):
            rel[c] = pos[r, c] - o[c]
        rh = (rel[0] * N[0] + rel[1] * N[1]) + rel[2] * N[2]
        cn = _dot3(nrm, r, N)
        if cn > 0.2 and abs(rh) < reach:
            out_rows[m] = r
            for c in range(3):
                pos_r[m, c] = pos[r, c]
                nrm_r[m, c] = nrm[r, c]
            rad_r[m] = rad[r]
            ou[m, 0] = (rel[0] * t1[0] + rel[1] * t1[1]) + rel[2] * t1[2]
            ou[m, 1] = (rel[0] * t2[0] + rel[1] * t2[1]) + rel[2] * t2[2]
            m += 1
    return m


@njit(cache=True)
def hidden_fathers(fathers, replaced, n_original, active, pos, nrm, o, N, t1, t2, out_idx, out_uv):  # pragma: no cover - numba
    """The originals among ``fathers`` that are hidden (inactive, or among the ``replaced`` rows)
    and face the plane (``nrm . N > 0.2``), in order, with their plane coordinates, into the
    first ``m`` entries of ``out_idx`` / ``out_uv``; returns ``m``."""
    rep = np.sort(replaced[replaced < n_original])
    m = 0
    for k in range(fathers.shape[0]):
        f = fathers[k]
        hidden = not active[f]
        if not hidden and rep.shape[0] > 0:
            j = np.searchsorted(rep, f)
            hidden = j < rep.shape[0] and rep[j] == f
        if hidden and _dot3(nrm, f, N) > 0.2:
            out_idx[m] = f
            r0 = pos[f, 0] - o[0]
            r1 = pos[f, 1] - o[1]
            r2 = pos[f, 2] - o[2]
            out_uv[m, 0] = (r0 * t1[0] + r1 * t1[1]) + r2 * t1[2]
            out_uv[m, 1] = (r0 * t2[0] + r1 * t2[1]) + r2 * t2[2]
            m += 1
    return m


@njit(cache=True)
def replaced_pixels(own, pen, covered, ou, rad_r, lo0, lo1, W, H, h):  # pragma: no cover - numba
    """The rows replaced by a paint event and the pixels they cover.

    A row is replaced when its cell (1.5 radii) lies inside the buffer and it owns a penetrated
    pixel or its centre lies on one. Returns ``is_rep`` (R,) bool, ``cpix`` (R,) int64 (the
    pixel under each row's centre, 0 outside the buffer), ``Q`` (the covered pixels owned by
    replaced rows, ascending) and ``npix`` (R,) float64 (pixels of ``Q`` per row).
    """
    R = rad_r.shape[0]
    Wh = W * h
    Hh = H * h
    is_rep = np.zeros(R, np.bool_)
    cand = np.zeros(R, np.bool_)
    cpix = np.empty(R, np.int64)
    for q in range(pen.shape[0]):
        if pen[q]:
            cand[own[q]] = True
    for i in range(R):
        ci = math.floor((ou[i, 0] - lo0) / h)
        cj = math.floor((lo1 + Hh - ou[i, 1]) / h)
        inside = ci >= 0 and ci < W and cj >= 0 and cj < H
        cpix[i] = cj * W + ci if inside else 0
        if inside and pen[cpix[i]]:
            cand[i] = True
        if cand[i]:
            r15 = 1.5 * rad_r[i]
            is_rep[i] = ((ou[i, 0] - r15 > lo0) and (ou[i, 0] + r15 < lo0 + Wh)
                         and (ou[i, 1] - r15 > lo1) and (ou[i, 1] + r15 < lo1 + Hh))
    nq = 0
    for q in range(own.shape[0]):
        if covered[q] and is_rep[own[q]]:
            nq += 1
    Q = np.empty(nq, np.int64)
    npix = np.zeros(R)
    nq = 0
    for q in range(own.shape[0]):
        if covered[q] and is_rep[own[q]]:
            Q[nq] = q
            npix[own[q]] += 1.0
            nq += 1
    return is_rep, cpix, Q, npix


@njit(cache=True)
def pixels_near(ou, rad_r, sel, pix, skip, lo0, lo1, W, H, h):  # pragma: no cover - numba
    """The buffer pixels (ascending, (K,) int64) whose centre ``pix`` lies within the radius of
    one of the rows ``sel`` (plane coordinates ``ou``, radii ``rad_r``; with a relative margin
    of 1e-9), but for those marked in ``skip``: the pixels those rows may own (an owner covers
    its pixel: distance / radius <= 1)."""
    mark = np.zeros(W * H, np.bool_)
    Hh = H * h
    for t in range(sel.shape[0]):
        i = sel[t]
        u = ou[i, 0]
        v = ou[i, 1]
        r = rad_r[i] * (1.0 + 1e-9)
        r2 = r * r
        i0 = max(math.floor((u - r - lo0) / h) - 1, 0)
        i1 = min(math.floor((u + r - lo0) / h) + 1, W - 1)
        j0 = max(math.floor((lo1 + Hh - (v + r)) / h) - 1, 0)
        j1 = min(math.floor((lo1 + Hh - (v - r)) / h) + 1, H - 1)
        for j in range(j0, j1 + 1):
            for c in range(i0, i1 + 1):
                q = j * W + c
                if skip[q] or mark[q]:
                    continue
                dx = pix[q, 0] - u
                dy = pix[q, 1] - v
                if dx * dx + dy * dy <= r2:
                    mark[q] = True
    return np.flatnonzero(mark)


@njit(cache=True)
def pixel_state(Q, own, rows, npix, wet, vw, vd, dry, rho, kappa, diff, refl, shin, metal, pix, rq, cw, vwq, vdq, dc,
                props, pu):  # pragma: no cover - numba
    """Surface pixel state of pixels ``Q``: owner rows ``rq``, the owner's colours, its volumes
    times its share ``1 / npix``, its paint attributes (``props`` rows: rho, kappa, diff, refl,
    shin, metal) and the pixel centres ``pu``, all (K, ...) outputs filled in place."""
    for k in range(Q.shape[0]):
        q = Q[k]
        oq = own[q]
        r = rows[oq]
        rq[k] = r
        share = 1.0 / npix[oq]
        for c in range(3):
            cw[k, c] = wet[r, c]
            dc[k, c] = dry[r, c]
        vwq[k] = vw[r] * share
        vdq[k] = vd[r] * share
        props[0, k] = rho[r]
        props[1, k] = kappa[r]
        props[2, k] = diff[r]
        props[3, k] = refl[r]
        props[4, k] = shin[r]
        props[5, k] = metal[r]
        pu[k, 0] = pix[q, 0]
        pu[k, 1] = pix[q, 1]


@njit(cache=True)
def brush_pixels(Q, P, bown, depth, sel, brush_wet, brush_vw, pressure, lower):  # pragma: no cover - numba
    """Brush pixel state of the penetrated pixels ``Q[P]``: brush surfel ``bsel``, its colour,
    its volume times its share, and the pressure ``pressure * clip(depth / lower, 0, 1)``."""
    n = 0
    for k in range(Q.shape[0]):
        if P[k]:
            n += 1
    bq = np.empty(n, np.int64)
    pd = np.empty(n)
    nb = np.zeros(sel.shape[0])
    n = 0
    for k in range(Q.shape[0]):
        if P[k]:
            bq[n] = bown[Q[k]]
            pd[n] = depth[Q[k]]
            nb[bq[n]] += 1.0
            n += 1
    bsel = np.empty(n, np.int64)
    cbp = np.empty((n, 3))
    vbp = np.empty(n)
    press = np.empty(n)
    low = max(lower, 1e-300)
    for k in range(n):
        b = sel[bq[k]]
        bsel[k] = b
        for c in range(3):
            cbp[k, c] = brush_wet[b, c]
        vbp[k] = brush_vw[b] * (1.0 / nb[bq[k]])
        press[k] = pressure * min(max(pd[k] / low, 0.0), 1.0)
    return bsel, cbp, vbp, press


@njit(cache=True)
def brush_write_back(bsel, vb2, cb2, brush_wet, brush_vw):  # pragma: no cover - numba
    """Per brush surfel of ``bsel``: its volume becomes the sum of its pixels' ``vb2``, its
    colour their volume-weighted colour (kept where that sum is 0); in place."""
    nbr = brush_vw.shape[0]
    tot = np.zeros(nbr)
    acc = np.zeros((nbr, 3))
    hit = np.zeros(nbr, np.bool_)
    for k in range(bsel.shape[0]):
        b = bsel[k]
        hit[b] = True
        tot[b] += vb2[k]
        for c in range(3):
            acc[b, c] += vb2[k] * cb2[k, c]
    for b in range(nbr):
        if hit[b]:
            if tot[b] > 0:
                for c in range(3):
                    brush_wet[b, c] = acc[b, c] / tot[b]
            brush_vw[b] = tot[b]


@njit(cache=True)
def blend_props(props, P, fb, values):  # pragma: no cover - numba
    """``props[f, P] = (1 - fb) * props[f, P] + fb * values[f]`` for every attribute row ``f``
    (the new paint's attributes blended by the brush fraction ``fb`` of pixels ``P``)."""
    for f in range(props.shape[0]):
        v = values[f]
        for k in range(P.shape[0]):
            q = P[k]
            props[f, q] = (1.0 - fb[k]) * props[f, q] + fb[k] * v


@njit(cache=True)
def child_frames(rq, pu, o, t1, t2, pos, nrm, lift, father, base_pt, onr, fnr, opl, owner_lift):  # pragma: no cover - numba
    """Per child (owner row ``rq[k]``, pixel centre ``pu[k]``): the pixel centre in space
    ``o + u t1 + v t2``, the owner's normal, its father's normal ``fnr``, its lift and its
    father-surface point ``pos - lift fnr``; (K, ...) outputs filled in place."""
    for k in range(rq.shape[0]):
        r = rq[k]
        f = father[r]
        lf = lift[r]
        owner_lift[k] = lf
        for c in range(3):
            base_pt[k, c] = (o[c] + pu[k, 0] * t1[c]) + pu[k, 1] * t2[c]
            onr[k, c] = nrm[r, c]
            fnr[k, c] = nrm[f, c]
            opl[k, c] = pos[r, c] - lf * nrm[f, c]


@njit(cache=True)
def merge_orphan_rows(ks, rr, s_vw, s_vd, s_wet, s_dry, s_rho, s_kappa, s_diff, s_refl, s_shin, s_metal, cw, vw, dc, vd,
                      props):  # pragma: no cover - numba
    """Merge surface rows ``rr`` into the pixel state at pixels ``ks``, one after the other (a
    pixel may take several): volumes summed, colours and the attribute rows of ``props`` (rho,
    kappa, diff, refl, shin, metal) mixed by volume; in place."""
    for j in range(ks.shape[0]):
        k = ks[j]
        r = rr[j]
        a = vw[k] + vd[k]
        b = s_vw[r] + s_vd[r]
        t = a + b
        if t > 0:
            props[0, k] = (a * props[0, k] + b * s_rho[r]) / t
            props[1, k] = (a * props[1, k] + b * s_kappa[r]) / t
            props[2, k] = (a * props[2, k] + b * s_diff[r]) / t
            props[3, k] = (a * props[3, k] + b * s_refl[r]) / t
            props[4, k] = (a * props[4, k] + b * s_shin[r]) / t
            props[5, k] = (a * props[5, k] + b * s_metal[r]) / t
        _mix_colour(cw, vw, k, s_wet, s_vw, r)
        _mix_colour(dc, vd, k, s_dry, s_vd, r)


@njit(cache=True, inline="always")
def _mix_colour(col, vol, k, s_col, s_vol, r):  # pragma: no cover - numba
    """Pixel ``k``'s colour (3,) and volume take surface row ``r``'s: colours mixed by volume,
    volumes summed (the wet or the dry layer of :func:`merge_orphan_rows`); in place."""
    a = vol[k]
    b = s_vol[r]
    t = a + b
    if t > 0:
        for c in range(3):
            col[k, c] = (a * col[k, c] + b * s_col[r, c]) / t
    vol[k] = t
