"""Numba kernels of the paint buffer (thesis 5.5): who owns each buffer pixel.

:func:`grid_knn2d` finds the ``k`` nearest of a small 2-D point set (surfel centres in the
paint-buffer plane) for every pixel centre, exactly as :meth:`unmesh.spatial.KDTree.knn`
(distances ``sqrt(dx*dx + dy*dy)``, rows sorted by (distance, index)), with a dense cell grid
built per call: the paint buffer asks this for tens of thousands of pixels against a few
thousand surfels per paint event, where building a kd-tree and its Python query path cost
more than the search. :func:`pixel_owners` adds the ownership rule of
:func:`unmesh.paint.transfer.pixel_owners_reference` (its reference, which uses the kd-tree).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: Pixels per parallel chunk (each chunk allocates its own k-best buffers once).
_CHUNK = 512
#: Points per cell of the grid (of the points' own box). Any value gives the same answers; half
#: a point per cell visits fewer candidates than three (owners of a paint event 0.56 -> 0.45 ms,
#: nearest 0.28 -> 0.20 ms per call on the studio replay's events, docs/performance.md).
_PER_CELL = 0.5


@njit(cache=True)
def _bin(points, x0, y0, inv, nx, ny):  # pragma: no cover - numba
    """Counting sort of the points into a dense ``nx`` x ``ny`` grid: (start (nx*ny+1,), order)."""
    n = points.shape[0]
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for a in range(n):
        i = min(max(math.floor((points[a, 0] - x0) * inv), 0), nx - 1)
        j = min(max(math.floor((points[a, 1] - y0) * inv), 0), ny - 1)
        cell[a] = j * nx + i
        start[cell[a] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for a in range(n):  # ascending point index within each cell
        order[fill[cell[a]]] = a
        fill[cell[a]] += 1
    return start, order


@njit(cache=True)
def _insert(bd, bi, m, k, d, a):  # pragma: no cover - numba
    """Insert (d, a) into the sorted k-best lists of length m; returns the new length."""
    if m == k:
        if d > bd[k - 1] or (d == bd[k - 1] and a > bi[k - 1]):
            return m
        t = k - 1
    else:
        t = m
        m += 1
    while t > 0 and (bd[t - 1] > d or (bd[t - 1] == d and bi[t - 1] > a)):
        bd[t] = bd[t - 1]
        bi[t] = bi[t - 1]
        t -= 1
    bd[t] = d
    bi[t] = a
    return m


@njit(cache=True)
def _query(qx, qy, points, start, order, x0, y0, cell, inv, nx, ny, k, bd, bi):  # pragma: no cover - numba
    """The k nearest points of (qx, qy) into bd, bi (sorted by distance, then index)."""
    ci = min(max(math.floor((qx - x0) * inv), 0), nx - 1)
    cj = min(max(math.floor((qy - y0) * inv), 0), ny - 1)
    eps = 1e-9 * cell
    m = 0
    r = 0
    lim = np.inf  # squared distances above this are certainly farther than the k-th
    while True:
        for j in range(max(cj - r, 0), min(cj + r, ny - 1) + 1):
            edge = j == cj - r or j == cj + r
            step = 1 if edge else 2 * r
            i = ci - r
            while i <= ci + r:
                if 0 <= i < nx:
                    c = j * nx + i
                    for s in range(start[c], start[c + 1]):
                        a = order[s]
                        dx = points[a, 0] - qx
                        d2 = dx * dx
                        dy = points[a, 1] - qy
                        d2 = d2 + dy * dy
                        if d2 > lim:
                            continue
                        m = _insert(bd, bi, m, k, np.sqrt(d2), a)
                        if m == k:
                            lim = bd[k - 1] * bd[k - 1] * (1.0 + 1e-12)
                if step == 0:
                    break
                i += step
        if ci - r <= 0 and cj - r <= 0 and ci + r >= nx - 1 and cj + r >= ny - 1:
            return  # the whole grid is visited
        if m == k:
            # every point outside the visited block is at least this far from the query
            bound = np.inf
            if ci - r > 0:
                bound = min(bound, qx - (x0 + (ci - r) * cell))
            if ci + r < nx - 1:
                bound = min(bound, (x0 + (ci + r + 1) * cell) - qx)
            if cj - r > 0:
                bound = min(bound, qy - (y0 + (cj - r) * cell))
            if cj + r < ny - 1:
                bound = min(bound, (y0 + (cj + r + 1) * cell) - qy)
            if bound - eps > bd[k - 1]:
                return
        r += 1


@njit(cache=True)
def _grid_of(points, queries, max_cells):  # pragma: no cover - numba
    """A dense grid over the bounding box of points and queries: (x0, y0, cell, nx, ny)."""
    x0 = min(points[:, 0].min(), queries[:, 0].min())
    y0 = min(points[:, 1].min(), queries[:, 1].min())
    x1 = max(points[:, 0].max(), queries[:, 0].max())
    y1 = max(points[:, 1].max(), queries[:, 1].max())
    ex = max(x1 - x0, 1e-300)
    ey = max(y1 - y0, 1e-300)
    # about _PER_CELL points per cell of the points' own box, at most max_cells cells
    px = max(points[:, 0].max() - points[:, 0].min(), 0.0)
    py = max(points[:, 1].max() - points[:, 1].min(), 0.0)
    cell = math.sqrt(max(px * py, 1e-300) * _PER_CELL / points.shape[0])
    cell = max(cell, math.sqrt(ex * ey / max_cells), max(ex, ey) / max_cells, 1e-300)
    nx = min(int(ex / cell) + 1, max_cells)
    ny = min(int(ey / cell) + 1, max_cells)
    return x0, y0, cell, nx, ny


@njit(cache=True, parallel=True)
def grid_knn2d(points, queries, k, dist, idx):  # pragma: no cover - numba
    """``dist[q], idx[q]`` = the ``k`` nearest ``points`` (P, 2) of ``queries[q]`` (Q, 2), sorted
    by (distance, index), distances ``sqrt(dx*dx + dy*dy)``; requires ``1 <= k <= P``."""
    x0, y0, cell, nx, ny = _grid_of(points, queries, 4 * points.shape[0] + 16)
    inv = 1.0 / cell
    start, order = _bin(points, x0, y0, inv, nx, ny)
    nq = queries.shape[0]
    for c in prange((nq + _CHUNK - 1) // _CHUNK):
        bd = np.empty(k)
        bi = np.empty(k, np.int64)
        for q in range(c * _CHUNK, min((c + 1) * _CHUNK, nq)):
            _query(queries[q, 0], queries[q, 1], points, start, order, x0, y0, cell, inv, nx, ny, k, bd, bi)
            for t in range(k):
                dist[q, t] = bd[t]
                idx[q, t] = bi[t]


@njit(cache=True, parallel=True)
def pixel_owners(points, radius, queries, k, own, ratio):  # pragma: no cover - numba
    """Pixel ownership of the paint buffer: among the ``k`` nearest ``points`` of each query
    (as :func:`grid_knn2d`), the first with the smallest ``distance / radius``: ``own[q]`` its
    index, ``ratio[q]`` that ratio."""
    x0, y0, cell, nx, ny = _grid_of(points, queries, 4 * points.shape[0] + 16)
    inv = 1.0 / cell
    start, order = _bin(points, x0, y0, inv, nx, ny)
    nq = queries.shape[0]
    for c in prange((nq + _CHUNK - 1) // _CHUNK):
        bd = np.empty(k)
        bi = np.empty(k, np.int64)
        for q in range(c * _CHUNK, min((c + 1) * _CHUNK, nq)):
            _query(queries[q, 0], queries[q, 1], points, start, order, x0, y0, cell, inv, nx, ny, k, bd, bi)
            best = 0
            rb = bd[0] / radius[bi[0]]
            for t in range(1, k):
                rt = bd[t] / radius[bi[t]]
                if rt < rb:
                    rb = rt
                    best = t
            own[q] = bi[best]
            ratio[q] = rb
