"""Numba kernels of visibility between shell nodes: does a segment pass through a surfel disc?

Used by fracture (7.3: a crack tip's new fibers must not cross the opened surface) and tearing
(which partners of a node are still connected across a crack). :func:`segments_blocked` tests
every segment against every disc; :func:`segments_blocked_grid` the same with the discs in a
uniform grid (:func:`unmesh.spatial._kernels.dense_grid`), for many segments and discs. Numpy reference: the tests'
brute-force segment/disc intersection (``tests/shells/test_speed_paths.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.spatial._kernels import cell_key, dense_cell, dense_grid


@njit(cache=True)
def discs_near_segments(p, q, centers, radii):
    """Indices of the discs whose centre lies within (1 + 1e-9) radius of the bounding box of all
    segments p[m]-q[m]: only those can block one of them (7.3.2)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for k in range(p.shape[0]):
        for d in range(3):
            lo[d] = min(lo[d], p[k, d], q[k, d])
            hi[d] = max(hi[d], p[k, d], q[k, d])
    out = np.empty(centers.shape[0], dtype=np.int64)
    m = 0
    for c in range(centers.shape[0]):
        g = 0.0
        for d in range(3):
            e = max(lo[d] - centers[c, d], centers[c, d] - hi[d], 0.0)
            g += e * e
        if g <= radii[c] * radii[c] * (1.0 + 1e-9) + 1e-300:
            out[m] = c
            m += 1
    return out[:m]


@njit(cache=True, inline="always")
def _disc_hit(p, q, k, mx, my, mz, half, centers, normals, radii, c):
    """Segment ``k`` of :func:`segments_blocked` against disc ``c``."""
    dx = mx - centers[c, 0]
    dy = my - centers[c, 1]
    dz = mz - centers[c, 2]
    reach = half + radii[c]
    if dx * dx + dy * dy + dz * dz > reach * reach:
        return False
    dp = (normals[c, 0] * (p[k, 0] - centers[c, 0]) + normals[c, 1] * (p[k, 1] - centers[c, 1])
          + normals[c, 2] * (p[k, 2] - centers[c, 2]))
    dq = (normals[c, 0] * (q[k, 0] - centers[c, 0]) + normals[c, 1] * (q[k, 1] - centers[c, 1])
          + normals[c, 2] * (q[k, 2] - centers[c, 2]))
    if (dp >= 0.0) == (dq >= 0.0):
        return False
    t = dp / (dp - dq)
    ix = p[k, 0] + t * (q[k, 0] - p[k, 0]) - centers[c, 0]
    iy = p[k, 1] + t * (q[k, 1] - p[k, 1]) - centers[c, 1]
    iz = p[k, 2] + t * (q[k, 2] - p[k, 2]) - centers[c, 2]
    return ix * ix + iy * iy + iz * iz <= radii[c] * radii[c]


@njit(cache=True, inline="always")
def _segment(p, q, k):
    mx = 0.5 * (p[k, 0] + q[k, 0])
    my = 0.5 * (p[k, 1] + q[k, 1])
    mz = 0.5 * (p[k, 2] + q[k, 2])
    half = 0.5 * math.sqrt((q[k, 0] - p[k, 0]) ** 2 + (q[k, 1] - p[k, 1]) ** 2 + (q[k, 2] - p[k, 2]) ** 2)
    return mx, my, mz, half


@njit(cache=True, parallel=True)
def segments_blocked(p, q, centers, normals, radii, out):
    """out[m] = True when segment p[m]-q[m] crosses one of the crack discs (7.3.2).

    A disc (c, n, r) separates the closed half-space n.(x - c) >= 0 from the open one
    n.(x - c) < 0; a segment with ends on different sides is blocked when it meets the
    disc's plane within distance r of c. A node on the plane belongs to the + side.
    """
    m = p.shape[0]
    nc = centers.shape[0]
    for k in prange(m):
        mx, my, mz, half = _segment(p, q, k)
        hit = False
        for c in range(nc):
            if _disc_hit(p, q, k, mx, my, mz, half, centers, normals, radii, c):
                hit = True
                break
        out[k] = hit


@njit(cache=True, parallel=True)
def segments_blocked_grid(p, q, centers, normals, radii, out):
    """:func:`segments_blocked` with the discs in a uniform grid (many segments and discs).

    The cell edge is at least the largest half segment length plus the largest radius, so a
    disc that passes the first test of a segment (its centre within half length plus radius
    of the segment's midpoint) lies in the 27 cells around the midpoint's cell: the result
    is the same, and each segment meets only the discs near it (:func:`unmesh.spatial._kernels.dense_grid`).
    """
    m = p.shape[0]
    hmax = 0.0
    for k in range(m):
        hmax = max(hmax, _segment(p, q, k)[3])
    rmax = 0.0
    for c in range(centers.shape[0]):
        rmax = max(rmax, radii[c])
    lo, _, inv, dims, start, order = dense_grid(centers, (hmax + rmax) * (1.0 + 1e-9) + 1e-300, 8 * centers.shape[0] + 64)
    for k in prange(m):
        mx, my, mz, half = _segment(p, q, k)
        c0, c1, c2 = dense_cell(mx, my, mz, lo, inv)       # any value is safe: the cell ranges are clipped
        hit = False
        for j0 in range(max(c0 - 1, 0), min(c0 + 2, dims[0])):
            for j1 in range(max(c1 - 1, 0), min(c1 + 2, dims[1])):
                for j2 in range(max(c2 - 1, 0), min(c2 + 2, dims[2])):
                    g = cell_key(j0, j1, j2, dims)
                    for e in range(start[g], start[g + 1]):
                        if not hit and _disc_hit(p, q, k, mx, my, mz, half, centers, normals, radii, order[e]):
                            hit = True
        out[k] = hit
