"""Numba kernels of the clip buffer (thesis Algorithm 4.1).

The numpy references are :func:`unmesh.csg.partners.partners_brute_force` (the 4.2.1 estimate)
and :func:`unmesh.csg.partners.clip_buffer_reference` (the same estimate restricted to surfels
sharing a clip-buffer cell); tests compare them.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["cell_boxes", "clip_buffer_csr", "disc_boxes", "grid_boxes", "grid_csr"]


@njit(cache=True)
def cell_boxes(pos, radii, nrm, au, av):
    """Clip-buffer grid (cells of twice the median radius, at most ~4N cells) of the projection onto axes ``au, av``: (N, 4) int64 inclusive cell
    ranges ``a0, a1, b0, b1`` of the projected surfel boxes, and the grid size ``nu, nv``.

    The projected box of the disc ``{c + t : t.n = 0, |t| <= r}`` has half-extent
    ``r sqrt(1 - n_k^2)`` along axis ``k`` (a surfel seen edge-on covers a thick line).
    """
    n = pos.shape[0]
    cell = 2.0 * np.median(radii)  # cells of twice the median radius, at most ~4N cells
    hu = np.empty(n)
    hv = np.empty(n)
    u0 = np.inf
    u1 = -np.inf
    v0 = np.inf
    v1 = -np.inf
    for i in range(n):
        hu[i] = radii[i] * np.sqrt(min(max(1.0 - nrm[i, au] ** 2, 0.0), 1.0)) * (1 + 1e-9) + 1e-12
        hv[i] = radii[i] * np.sqrt(min(max(1.0 - nrm[i, av] ** 2, 0.0), 1.0)) * (1 + 1e-9) + 1e-12
        u0 = min(u0, pos[i, au] - hu[i])
        u1 = max(u1, pos[i, au] + hu[i])
        v0 = min(v0, pos[i, av] - hv[i])
        v1 = max(v1, pos[i, av] + hv[i])
    cell = max(cell, np.sqrt((u1 - u0) * (v1 - v0) / (4.0 * n)), (u1 - u0) / 4096, (v1 - v0) / 4096, 1e-12)
    nu = int((u1 - u0) / cell) + 1
    nv = int((v1 - v0) / cell) + 1
    box = np.empty((n, 4), dtype=np.int64)
    for i in range(n):
        box[i, 0] = max(int(np.floor((pos[i, au] - hu[i] - u0) / cell)), 0)
        box[i, 1] = min(int(np.floor((pos[i, au] + hu[i] - u0) / cell)), nu - 1)
        box[i, 2] = max(int(np.floor((pos[i, av] - hv[i] - v0) / cell)), 0)
        box[i, 3] = min(int(np.floor((pos[i, av] + hv[i] - v0) / cell)), nv - 1)
    return box, nu, nv


@njit(cache=True)
def _bin(box, nu, nv):
    """Cell lists: ``items[start[c]:start[c+1]]`` are the surfels whose box covers cell ``c``."""
    n = box.shape[0]
    ncell = nu * nv
    start = np.zeros(ncell + 1, dtype=np.int64)
    for i in range(n):
        for b in range(box[i, 2], box[i, 3] + 1):
            for a in range(box[i, 0], box[i, 1] + 1):
                start[b * nu + a + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    items = np.empty(start[ncell], dtype=np.int64)
    fill = start[:-1].copy()
    for i in range(n):
        for b in range(box[i, 2], box[i, 3] + 1):
            for a in range(box[i, 0], box[i, 1] + 1):
                c = b * nu + a
                items[fill[c]] = i
                fill[c] += 1
    return start, items


@njit(cache=True)
def _cell_pairs(c, nu, start, items, pos, radii, patch, box, out, base, write):
    """Pairs met in cell ``c`` (Algorithm 4.1: a fragment meets the cell's list), each pair
    only in the first cell its two boxes share, written from ``out[base]`` if ``write``.
    Returns their number.
"""
    a = c % nu
    b = c // nu
    m = 0
    for p in range(start[c], start[c + 1]):
        for q in range(start[c], p):
            s1 = items[p]
            s2 = items[q]
            if patch[s1] == patch[s2]:
                continue
            if max(box[s1, 0], box[s2, 0]) != a or max(box[s1, 2], box[s2, 2]) != b:
                continue
            dx = pos[s1, 0] - pos[s2, 0]
            dy = pos[s1, 1] - pos[s2, 1]
            dz = pos[s1, 2] - pos[s2, 2]
            rr = radii[s1] + radii[s2]
            if dx * dx + dy * dy + dz * dz < rr * rr:
                if write:
                    out[base + m, 0] = s1
                    out[base + m, 1] = s2
                m += 1
    return m


@njit(cache=True, parallel=True)
def _pairs_csr(buf, bound, counts, n):
    """Symmetric CSR rows (ascending) of the pairs ``buf[bound[k] : bound[k] + counts[k]]`` of every chunk."""
    nchunks = counts.shape[0]
    offsets = np.zeros(n + 1, dtype=np.int64)
    for k in range(nchunks):
        for q in range(bound[k], bound[k] + counts[k]):
            offsets[buf[q, 0] + 1] += 1
            offsets[buf[q, 1] + 1] += 1
    for i in range(n):
        offsets[i + 1] += offsets[i]
    fill = offsets[:-1].copy()
    out = np.empty(offsets[n], dtype=np.int64)
    for k in range(nchunks):
        for q in range(bound[k], bound[k] + counts[k]):
            i = buf[q, 0]
            j = buf[q, 1]
            out[fill[i]] = j
            fill[i] += 1
            out[fill[j]] = i
            fill[j] += 1
    for i in prange(n):
        lo = offsets[i]
        for q in range(lo + 1, offsets[i + 1]):  # insertion sort: rows are short
            x = out[q]
            r = q - 1
            while r >= lo and out[r] > x:
                out[r + 1] = out[r]
                r -= 1
            out[r + 1] = x
    return offsets, out


@njit(cache=True, parallel=True)
def clip_buffer_csr(pos, radii, patch, box, nu, nv, nchunks):
    """Clipping partners by the clip buffer (Algorithm 4.1) as a symmetric CSR.

    ``box`` (N, 4) int64 cell ranges of the projected surfel boxes (:func:`cell_boxes`) in a
    grid of ``nu x nv`` cells, processed in ``nchunks`` parallel chunks of cells. Surfels of
    different ``patch`` whose boxes share a cell and whose bounding spheres overlap
    (``|c_i - c_j| < r_i + r_j``) are partners.

    Returns ``offsets`` (N+1,) int64 and ``indices`` int64, each row ascending.
    """
    n = pos.shape[0]
    start, items = _bin(box, nu, nv)
    ncell = nu * nv
    step = (ncell + nchunks - 1) // nchunks
    # one pass: chunk k writes from the bound sum k(k-1)/2 of its cells (np.empty does not
    # touch the memory it reserves, so the loose bound costs nothing); when that bound is
    # too loose (huge surfels covering many cells), an exact counting pass first
    bound = np.zeros(nchunks + 1, dtype=np.int64)
    for k in range(nchunks):
        m = 0
        for c in range(k * step, min(ncell, (k + 1) * step)):
            kc = start[c + 1] - start[c]
            m += kc * (kc - 1) // 2
        bound[k + 1] = bound[k] + m
    if bound[nchunks] > 64 * n + 1000000:
        exact = np.zeros(nchunks + 1, dtype=np.int64)
        nowhere = np.empty((0, 2), dtype=np.int64)
        for k in prange(nchunks):
            m = 0
            for c in range(k * step, min(ncell, (k + 1) * step)):
                m += _cell_pairs(c, nu, start, items, pos, radii, patch, box, nowhere, 0, False)
            exact[k + 1] = m
        for k in range(nchunks):
            bound[k + 1] = bound[k] + exact[k + 1]
    buf = np.empty((bound[nchunks], 2), dtype=np.int64)
    counts = np.zeros(nchunks, dtype=np.int64)
    for k in prange(nchunks):
        m = bound[k]
        for c in range(k * step, min(ncell, (k + 1) * step)):
            m += _cell_pairs(c, nu, start, items, pos, radii, patch, box, buf, m, True)
        counts[k] = m - bound[k]
    return _pairs_csr(buf, bound, counts, n)


@njit(cache=True)
def disc_boxes(pos, radii, nrm):
    """Half-extents (N, 3) of the 3D boxes of the discs ``{c + t : t.n = 0, |t| <= r}``
    (``r sqrt(1 - n_k^2)`` along axis ``k``, padded like :func:`cell_boxes`) and the corners
    ``lo, hi`` (3,) of the box around all of them."""
    n = pos.shape[0]
    half = np.empty((n, 3))
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(n):
        for k in range(3):
            h = radii[i] * np.sqrt(min(max(1.0 - nrm[i, k] ** 2, 0.0), 1.0)) * (1 + 1e-9) + 1e-12
            half[i, k] = h
            lo[k] = min(lo[k], pos[i, k] - h)
            hi[k] = max(hi[k], pos[i, k] + h)
    return half, lo, hi


@njit(cache=True)
def grid_boxes(pos, half, lo, cell, dims):
    """(N, 6) int64 inclusive cell ranges ``i0, i1, j0, j1, k0, k1`` of the disc boxes (``half``
    from :func:`disc_boxes`) in the grid of cubes of edge ``cell`` from ``lo`` (3,) with ``dims``
    (3,) cells per axis, and the number of (surfel, cell) entries."""
    n = pos.shape[0]
    box = np.empty((n, 6), dtype=np.int64)
    total = 0
    for i in range(n):
        m = 1
        for k in range(3):
            a = max(int(np.floor((pos[i, k] - half[i, k] - lo[k]) / cell)), 0)
            b = min(int(np.floor((pos[i, k] + half[i, k] - lo[k]) / cell)), dims[k] - 1)
            box[i, 2 * k] = a
            box[i, 2 * k + 1] = b
            m *= b - a + 1
        total += m
    return box, total


@njit(cache=True)
def _bin3(box, dims):
    """Cell lists of the 3D grid: ``items[start[c]:start[c+1]]`` are the surfels whose box covers
    cell ``c = (k * ny + j) * nx + i``."""
    n = box.shape[0]
    nx, ny = dims[0], dims[1]
    ncell = dims[0] * dims[1] * dims[2]
    start = np.zeros(ncell + 1, dtype=np.int64)
    for s in range(n):
        for k in range(box[s, 4], box[s, 5] + 1):
            for j in range(box[s, 2], box[s, 3] + 1):
                for i in range(box[s, 0], box[s, 1] + 1):
                    start[(k * ny + j) * nx + i + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    items = np.empty(start[ncell], dtype=np.int64)
    fill = start[:-1].copy()
    for s in range(n):
        for k in range(box[s, 4], box[s, 5] + 1):
            for j in range(box[s, 2], box[s, 3] + 1):
                for i in range(box[s, 0], box[s, 1] + 1):
                    c = (k * ny + j) * nx + i
                    items[fill[c]] = s
                    fill[c] += 1
    return start, items


@njit(cache=True)
def _grid_cell_pairs(c, dims, start, items, pos, radii, half, patch, box, out, base, write):
    """Pairs met in 3D cell ``c``: surfels of different patches whose boxes overlap and whose
    bounding spheres overlap, each pair only in the first cell its two boxes share; written
    from ``out[base]`` if ``write``. Returns their number. The cell's items are ordered by
    patch (surfels sorted by patch, binned in order), so each surfel is only tested against
    the runs of other patches before its own run."""
    i = c % dims[0]
    j = (c // dims[0]) % dims[1]
    k = c // (dims[0] * dims[1])
    m = 0
    g = start[c]
    for p in range(start[c], start[c + 1]):
        s1 = items[p]
        if p > g and patch[s1] != patch[items[p - 1]]:
            g = p
        for q in range(start[c], g):
            s2 = items[q]
            if (max(box[s1, 0], box[s2, 0]) != i or max(box[s1, 2], box[s2, 2]) != j
                    or max(box[s1, 4], box[s2, 4]) != k):
                continue
            dx = pos[s1, 0] - pos[s2, 0]
            dy = pos[s1, 1] - pos[s2, 1]
            dz = pos[s1, 2] - pos[s2, 2]
            if (abs(dx) > half[s1, 0] + half[s2, 0] or abs(dy) > half[s1, 1] + half[s2, 1]
                    or abs(dz) > half[s1, 2] + half[s2, 2]):
                continue
            rr = radii[s1] + radii[s2]
            if dx * dx + dy * dy + dz * dz < rr * rr:
                if write:
                    out[base + m, 0] = s1
                    out[base + m, 1] = s2
                m += 1
    return m


@njit(cache=True)
def _cross_candidates(c, start, items, patch):
    """Number of pairs of different patches among the items of cell ``c`` (ordered by patch)."""
    m = 0
    g = start[c]
    for p in range(start[c], start[c + 1]):
        if p > g and patch[items[p]] != patch[items[p - 1]]:
            g = p
        m += g - start[c]
    return m


@njit(cache=True, parallel=True)
def grid_csr(pos, radii, patch, half, box, dims, nchunks):
    """Clipping partners by a 3D clip grid as a symmetric CSR: :func:`clip_buffer_csr` with the
    clip buffer's cells split in depth (cubes instead of columns), so that surfels far apart in
    depth are never tested; pairs of different ``patch`` whose disc boxes overlap (``half``,
    ``box`` from :func:`disc_boxes`, :func:`grid_boxes`) and whose bounding spheres overlap. ``patch`` must be
    non-decreasing (surfels ordered by patch). Returns ``offsets`` (N+1,) int64 and ``indices``
    int64, each row ascending."""
    n = pos.shape[0]
    start, items = _bin3(box, dims)
    ncell = dims[0] * dims[1] * dims[2]
    step = (ncell + nchunks - 1) // nchunks
    # chunk t writes from the number of cross-patch candidates of the chunks before it (np.empty
    # does not touch the memory it reserves); when that bound is too loose, an exact count first
    bound = np.zeros(nchunks + 1, dtype=np.int64)
    for t in prange(nchunks):
        m = 0
        for c in range(t * step, min(ncell, (t + 1) * step)):
            m += _cross_candidates(c, start, items, patch)
        bound[t + 1] = m
    if bound[1:].sum() > 64 * n + 1000000:
        nowhere = np.empty((0, 2), dtype=np.int64)
        for t in prange(nchunks):
            m = 0
            for c in range(t * step, min(ncell, (t + 1) * step)):
                m += _grid_cell_pairs(c, dims, start, items, pos, radii, half, patch, box, nowhere, 0, False)
            bound[t + 1] = m
    for t in range(nchunks):
        bound[t + 1] += bound[t]
    buf = np.empty((bound[nchunks], 2), dtype=np.int64)
    counts = np.zeros(nchunks, dtype=np.int64)
    for t in prange(nchunks):
        m = bound[t]
        for c in range(t * step, min(ncell, (t + 1) * step)):
            m += _grid_cell_pairs(c, dims, start, items, pos, radii, half, patch, box, buf, m, True)
        counts[t] = m - bound[t]
    return _pairs_csr(buf, bound, counts, n)
