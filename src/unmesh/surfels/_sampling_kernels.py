"""Numba kernels of LDC ray-bundle sampling: every triangle rasterised into the ray lattice of one axis.

:func:`ldc_count` / :func:`ldc_fill`; reference ``unmesh.surfels.sampling.ldc_reference``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _less(au, av, bu, bv):  # pragma: no cover - numba
    """Lexicographic order of 2-D points (u first, then v)."""
    return au < bu or (au == bu and av < bv)


@njit(cache=True, inline="always")
def _edge(au, av, bu, bv, pu, pv):  # pragma: no cover - numba
    """Edge function of directed edge a->b at p, computed in a canonical vertex order.

    Returns ``(value, tie)``: ``value > 0`` left of a->b; bitwise ``-value`` for
    b->a. ``tie`` says whether a point exactly on the edge belongs to this side.
    """
    if _less(au, av, bu, bv):
        return (bu - au) * (pv - av) - (bv - av) * (pu - au), True
    return -((au - bu) * (pv - bv) - (av - bv) * (pu - bu)), False


@njit(cache=True, inline="always")
def _inside(e, tie):  # pragma: no cover - numba
    return e > 0.0 or (e == 0.0 and tie)


@njit(cache=True)
def _raster(vertices, faces, t, axis, inv_d, d, count_only, out_pos, out_face, out_bary, base):  # pragma: no cover
    """Hits of the rays along ``axis`` at lattice positions ``(i + 1/2) d`` with triangle ``t``."""
    ua = (axis + 1) % 3
    va = (axis + 2) % 3
    f0 = faces[t, 0]
    f1 = faces[t, 1]
    f2 = faces[t, 2]
    au = vertices[f0, ua]
    av = vertices[f0, va]
    bu = vertices[f1, ua]
    bv = vertices[f1, va]
    cu = vertices[f2, ua]
    cv = vertices[f2, va]
    area2 = (bu - au) * (cv - av) - (bv - av) * (cu - au)
    if area2 == 0.0 or not math.isfinite(area2):
        return 0
    i1 = f1
    i2 = f2
    if area2 < 0.0:  # make the projected triangle counter-clockwise
        bu, cu = cu, bu
        bv, cv = cv, bv
        i1, i2 = f2, f1
        area2 = -area2
    umin = min(au, bu, cu)
    umax = max(au, bu, cu)
    vmin = min(av, bv, cv)
    vmax = max(av, bv, cv)
    i_lo = math.ceil(umin * inv_d - 0.5) - 1
    i_hi = math.floor(umax * inv_d - 0.5) + 1
    j_lo = math.ceil(vmin * inv_d - 0.5) - 1
    j_hi = math.floor(vmax * inv_d - 0.5) + 1
    n = 0
    for i in range(i_lo, i_hi + 1):
        pu = (i + 0.5) * d
        if pu < umin or pu > umax:
            continue
        # Scanline: the v-range of the triangle on the line u = pu (slivers cost only their area);
        # widened by a cell on each side, the exact edge tests below decide.
        slo = vmax
        shi = vmin
        for e in range(3):
            if e == 0:
                eu0, ev0, eu1, ev1 = au, av, bu, bv
            elif e == 1:
                eu0, ev0, eu1, ev1 = bu, bv, cu, cv
            else:
                eu0, ev0, eu1, ev1 = cu, cv, au, av
            if min(eu0, eu1) <= pu <= max(eu0, eu1):
                if eu1 != eu0:
                    vv = ev0 + (pu - eu0) * (ev1 - ev0) / (eu1 - eu0)
                    slo = min(slo, vv)
                    shi = max(shi, vv)
                else:
                    slo = min(slo, ev0, ev1)
                    shi = max(shi, ev0, ev1)
        if slo > shi:
            continue
        jl = max(j_lo, math.ceil(slo * inv_d - 0.5) - 1)
        jh = min(j_hi, math.floor(shi * inv_d - 0.5) + 1)
        for j in range(jl, jh + 1):
            pv = (j + 0.5) * d
            if pv < vmin or pv > vmax:
                continue
            e0, t0 = _edge(bu, bv, cu, cv, pu, pv)  # opposite a
            if not _inside(e0, t0):
                continue
            e1, t1 = _edge(cu, cv, au, av, pu, pv)  # opposite b
            if not _inside(e1, t1):
                continue
            e2, t2 = _edge(au, av, bu, bv, pu, pv)  # opposite c
            if not _inside(e2, t2):
                continue
            if not count_only:
                s = e0 + e1 + e2
                if s <= 0.0:
                    s = area2
                b0 = e0 / s
                b1 = e1 / s
                b2 = e2 / s
                k = base + n
                w = b0 * vertices[f0, axis] + b1 * vertices[i1, axis] + b2 * vertices[i2, axis]
                out_pos[k, axis] = w
                out_pos[k, ua] = pu
                out_pos[k, va] = pv
                out_face[k] = t
                # Barycentrics in the face's own vertex order.
                out_bary[k, 0] = b0
                if i1 == f1:
                    out_bary[k, 1] = b1
                    out_bary[k, 2] = b2
                else:
                    out_bary[k, 1] = b2
                    out_bary[k, 2] = b1
            n += 1
    return n


@njit(cache=True, parallel=True)
def _ldc_pass(vertices, faces, f0, f1, axis, d, count_only, offsets, counts, pos, face, bary):  # pragma: no cover
    """Count (into ``counts``) or write (from ``offsets``) the hits of ``faces[f0:f1]``.

    One kernel with a run-time ``count_only`` for both passes: a single parallel kernel and a
    single ``_raster`` to compile instead of two of each.
    """
    inv_d = 1.0 / d
    for t in prange(f0, f1):
        base = 0 if count_only else offsets[t - f0]
        n = _raster(vertices, faces, t, axis, inv_d, d, count_only, pos, face, bary, base)
        if count_only:
            counts[t - f0] = n


def ldc_count(vertices, faces, f0, f1, axis, d):
    """Number of ray hits (f1-f0,) of each triangle in ``faces[f0:f1]`` for one ray bundle."""
    counts = np.zeros(f1 - f0, np.int64)
    _ldc_pass(vertices, faces, f0, f1, axis, float(d), True, counts, counts, np.empty((0, 3)),
              np.empty(0, np.int64), np.empty((0, 3)))
    return counts


def ldc_fill(vertices, faces, f0, f1, axis, d, offsets):
    """Hit positions (H,3), faces (H,) and barycentrics (H,3); ``offsets`` from :func:`ldc_count`."""
    total = int(offsets[-1])
    pos = np.empty((total, 3))
    face = np.empty(total, np.int64)
    bary = np.empty((total, 3))
    _ldc_pass(vertices, faces, f0, f1, axis, float(d), False, offsets, np.empty(0, np.int64), pos, face, bary)
    return pos, face, bary
