"""Numba kernels of the brush drawn over the painted image (:func:`unmesh.paint.view._draw_brush`):
its shadow map and its surfels as small discs with a z-test. References:
:func:`unmesh.paint.view.shadow_test_reference` and :func:`unmesh.paint.view.brush_discs_reference`
(the same arithmetic in numpy; tests compare them bit for bit).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def shadow_lookup(cells, height, du, dv, nu, nv, points, lo0, lo1, cell, out):  # pragma: no cover - numba
    """Shadow map and test: each brush surfel (map cell ``cells[i]``, height ``height[i]``)
    raises the cells ``cells[i] + (du[s], dv[s])`` of an ``nu`` x ``nv`` map to its height;
    ``out[m]`` is True where the map cell of ``points[m]`` (``floor((p - lo) / cell)``) is above
    ``points[m, 2] + 1e-9``."""
    smap = np.full(nu * nv, -np.inf)
    for i in range(cells.shape[0]):
        for s in range(du.shape[0]):
            k = (cells[i, 0] + du[s]) * nv + (cells[i, 1] + dv[s])
            if height[i] > smap[k]:
                smap[k] = height[i]
    for m in range(points.shape[0]):
        a = math.floor((points[m, 0] - lo0) / cell)
        b = math.floor((points[m, 1] - lo1) / cell)
        out[m] = False
        if a >= 0 and b >= 0 and a < nu and b < nv:
            out[m] = smap[int(a) * nv + int(b)] > points[m, 2] + 1e-9


@njit(cache=True)
def brush_discs(pr, pc, thr, z, src, R, r0, r1, c0, c1, col, nrm, albedo, normal, depth, coverage):  # pragma: no cover - numba
    """Draw discs: surfel ``i`` covers the pixels ``(pr[i] + oy, pc[i] + ox)`` with
    ``oy^2 + ox^2 <= thr[i]`` (|oy|, |ox| <= R) inside rows ``r0:r1`` and columns ``c0:c1`` at
    depth ``z[src[i]]``; per pixel the nearest fragment in front of ``depth`` wins (among equal
    depths the last, in surfel then row-major offset order) and writes ``col[src[i]]`` /
    ``nrm[src[i]]`` into ``albedo`` / ``normal`` (flat (P, 3) windows), its depth and coverage."""
    w = c1 - c0
    zb = np.full((r1 - r0) * w, np.inf)
    for write in range(2):  # the nearest depth per pixel first, then the colours of the fragments at it
        for i in range(pr.shape[0]):
            zi = z[src[i]]
            for oy in range(-R, R + 1):
                r = pr[i] + oy
                if r < r0 or r >= r1:
                    continue
                for ox in range(-R, R + 1):
                    c = pc[i] + ox
                    if c < c0 or c >= c1 or oy * oy + ox * ox > thr[i]:
                        continue
                    f = (r - r0) * w + (c - c0)
                    if write == 0:
                        if zi < zb[f]:
                            zb[f] = zi
                    elif zi == zb[f] and zi < depth[f]:
                        for t in range(3):
                            albedo[f, t] = col[src[i], t]
                            normal[f, t] = nrm[src[i], t]
    for f in range(zb.shape[0]):
        if zb[f] < depth[f]:
            depth[f] = zb[f]
            coverage[f] = True
