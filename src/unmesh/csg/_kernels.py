"""Numba kernels of the clip buffer (thesis Algorithm 4.1).

The numpy reference is :func:`unmesh.csg.partners.partners_brute_force`; tests compare them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["clip_buffer_pairs"]


@njit(cache=True)
def _box(i, u, v, hu, hv, u0, v0, cell, nu, nv):
    a0 = max(int(np.floor((u[i] - hu[i] - u0) / cell)), 0)
    a1 = min(int(np.floor((u[i] + hu[i] - u0) / cell)), nu - 1)
    b0 = max(int(np.floor((v[i] - hv[i] - v0) / cell)), 0)
    b1 = min(int(np.floor((v[i] + hv[i] - v0) / cell)), nv - 1)
    return a0, a1, b0, b1


@njit(cache=True)
def clip_buffer_pairs(pos, radii, patch, u, v, hu, hv, u0, v0, cell, nu, nv):
    """All pairs ``i < j`` of surfels of different patches with ``|c_i - c_j| < r_i + r_j``
    that share a clip-buffer cell (Algorithm 4.1).

    ``u, v`` (N,) projected centres, ``hu, hv`` (N,) half-extents of the projected surfel's box
    (for a surfel seen edge-on this box is the thick line covering its ellipse), ``cell`` the
    cell size, ``nu x nv`` cells from ``(u0, v0)``. Returns (P, 2) int64 pairs, possibly with
    duplicates (a pair sharing several cells is found in each).
    """
    n = pos.shape[0]
    ncell = nu * nv
    counts = np.zeros(ncell + 1, dtype=np.int64)
    for i in range(n):
        a0, a1, b0, b1 = _box(i, u, v, hu, hv, u0, v0, cell, nu, nv)
        for b in range(b0, b1 + 1):
            for a in range(a0, a1 + 1):
                counts[b * nu + a + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    items = np.empty(counts[ncell], dtype=np.int64)
    fill = counts[:-1].copy()
    for i in range(n):
        a0, a1, b0, b1 = _box(i, u, v, hu, hv, u0, v0, cell, nu, nv)
        for b in range(b0, b1 + 1):
            for a in range(a0, a1 + 1):
                c = b * nu + a
                items[fill[c]] = i
                fill[c] += 1
    cap = 1024
    out = np.empty((cap, 2), dtype=np.int64)
    m = 0
    for c in range(ncell):
        for p in range(counts[c], counts[c + 1]):
            s1 = items[p]
            for q in range(counts[c], p):  # Algorithm 4.1: the fragment of s1 meets the cell's list
                s2 = items[q]
                if patch[s1] == patch[s2]:
                    continue
                dx = pos[s1, 0] - pos[s2, 0]
                dy = pos[s1, 1] - pos[s2, 1]
                dz = pos[s1, 2] - pos[s2, 2]
                rr = radii[s1] + radii[s2]
                if dx * dx + dy * dy + dz * dz < rr * rr:
                    if m == cap:
                        cap *= 2
                        grown = np.empty((cap, 2), dtype=np.int64)
                        grown[:m] = out[:m]
                        out = grown
                    out[m, 0] = min(s1, s2)
                    out[m, 1] = max(s1, s2)
                    m += 1
    return out[:m]
