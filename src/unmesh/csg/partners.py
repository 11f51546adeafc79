"""Clipping partners (thesis 4.2.1): the surfels of other patches that a surfel may intersect.

Two surfels ``s1, s2`` of different patches are partners when ``|c1 - c2| < r1 + r2`` (the
conservative estimate of 4.2.1; ``r`` the largest semi-axis). Two ways to find them; both
contain every pair of truly intersecting discs (tests check this by brute force):

``"range"``
    Range queries of :class:`unmesh.spatial.KDTree`, with the surfels grouped into radius
    classes (powers of two) so that the query radius stays tight for mixed sizes. Exactly the
    pairs of the estimate (:func:`partners_brute_force`).
``"grid"``
    Algorithm 4.1 with the clip buffer's cells also split in depth: a 3D grid of cubes, each
    surfel entered in the cells of its disc's 3D box; surfels sharing a cell whose boxes and
    bounding spheres overlap are partners (surfels far apart in depth, which share a column of
    the 2D clip buffer, are never tested). Exactly the pairs of the estimate whose disc boxes
    overlap (:func:`grid_reference`), whatever the cell size.
``"clipbuffer"``
    Algorithm 4.1: the surfels are splatted into a clip buffer (a 2D grid in an orthographic
    view along the axis of least extent, which sees every surfel); surfels sharing a cell are
    tested. Each surfel covers the cells of its projected box, which for surfels seen edge-on
    is the thick line covering the degenerate ellipse (4.2.3). Any projection keeps
    intersecting surfels overlapping, so the result is complete; pairs whose bounding spheres
    overlap but whose projections do not are left out (they cannot intersect).

Partners are recomputed for every frame (dynamic CSG); ``benchmarks/bench_csg.py`` times both.

Example
-------
>>> import numpy as np
>>> pos = np.array([[0.0, 0, 0], [0.15, 0, 0], [1.0, 0, 0]])
>>> off, idx = find_partners(pos, np.array([0.1, 0.1, 0.1]), np.array([0, 1, 1]))
>>> off.tolist(), idx.tolist()
([0, 1, 2, 2], [1, 0])
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._threads import serial_if_small
from unmesh.csg._kernels import cell_boxes, clip_buffer_csr, disc_boxes, grid_boxes, grid_csr
from unmesh.errors import InputError
from unmesh.spatial import KDTree

__all__ = ["METHODS", "clip_buffer_reference", "find_partners", "grid_reference", "pairs_to_csr",
           "partners_brute_force"]

#: Partner search methods; the first is the default (faster in ``benchmarks/bench_csg.py``).
METHODS = ("grid", "clipbuffer", "range")

#: At most this many cells of the 3D clip grid per surfel (fewer, larger cells: faster in
#: ``benchmarks/bench_csg.py``, the cells' items stay few in 3D).
_CELLS_PER_SURFEL = 0.5


def pairs_to_csr(pairs: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric CSR ``(offsets (n+1,), indices)`` of unique pairs (P, 2), neighbours ascending."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.lexsort((cols, rows))
    rows, cols = rows[order], cols[order]
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=offsets[1:])
    return offsets, np.ascontiguousarray(cols)


def _unique_pairs(pairs: np.ndarray, n: int) -> np.ndarray:
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    keys = np.unique(pairs[:, 0] * np.int64(n) + pairs[:, 1])
    return np.stack([keys // n, keys % n], axis=1)


def partners_brute_force(positions: Any, radii: Any, patch: Any) -> tuple[np.ndarray, np.ndarray]:
    """O(N^2) reference of :func:`find_partners`."""
    pos = np.asarray(positions, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    p = np.asarray(patch)
    d2 = ((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1)
    hit = (d2 < (r[:, None] + r[None, :]) ** 2) & (p[:, None] != p[None, :])
    i, j = np.nonzero(np.triu(hit, 1))
    return pairs_to_csr(np.stack([i, j], axis=1), len(pos))


def _range_pairs(pos: np.ndarray, r: np.ndarray, patch: np.ndarray) -> np.ndarray:
    cls = np.floor(np.log2(r)).astype(np.int64)
    groups = [np.flatnonzero(cls == c) for c in np.unique(cls)]
    trees = [KDTree(pos[g]) for g in groups]
    rmax = [float(r[g].max()) for g in groups]
    out = []
    for a, ga in enumerate(groups):
        for b in range(a, len(groups)):
            gb = groups[b]
            off, idx = trees[b].radius_neighbors(pos[ga], rmax[a] + rmax[b])
            i = np.repeat(ga, np.diff(off))
            j = gb[idx]
            d2 = ((pos[i] - pos[j]) ** 2).sum(-1)
            keep = (patch[i] != patch[j]) & (d2 < (r[i] + r[j]) ** 2)
            i, j = i[keep], j[keep]
            out.append(np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2), dtype=np.int64)


def _clip_buffer_grid(pos: np.ndarray, r: np.ndarray, nrm: np.ndarray) -> tuple:
    """Projection axes, projected centres and box half-extents, and the grid of the clip buffer."""
    ext = np.ptp(pos, axis=0)
    axis = int(np.argmin(ext))
    au, av = [k for k in range(3) if k != axis]
    u = np.ascontiguousarray(pos[:, au])
    v = np.ascontiguousarray(pos[:, av])
    # projected box of the disc {c + t : t.n = 0, |t| <= r}: half-extent r sqrt(1 - n_k^2) along k
    hu = r * np.sqrt(np.clip(1.0 - nrm[:, au] ** 2, 0.0, 1.0)) * (1 + 1e-9) + 1e-12
    hv = r * np.sqrt(np.clip(1.0 - nrm[:, av] ** 2, 0.0, 1.0)) * (1 + 1e-9) + 1e-12
    u0, u1 = float((u - hu).min()), float((u + hu).max())
    v0, v1 = float((v - hv).min()), float((v + hv).max())
    # cells of twice the median radius, at most ~4N cells (memory stays O(N))
    cell = max(2.0 * float(np.median(r)), float(np.sqrt((u1 - u0) * (v1 - v0) / (4.0 * len(pos)))),
               (u1 - u0) / 4096, (v1 - v0) / 4096, 1e-12)
    nu = int((u1 - u0) / cell) + 1
    nv = int((v1 - v0) / cell) + 1
    return u, v, hu, hv, u0, v0, cell, nu, nv


def clip_buffer_reference(positions: Any, radii: Any, patch: Any, normals: Any) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy O(N^2) reference of the ``"clipbuffer"`` method: the pairs of the 4.2.1
    estimate whose projected boxes cover a common clip-buffer cell."""
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    r = np.ascontiguousarray(radii, dtype=np.float64)
    u, v, hu, hv, u0, v0, cell, nu, nv = _clip_buffer_grid(pos, r, np.asarray(normals, dtype=np.float64))
    a0 = np.maximum(np.floor((u - hu - u0) / cell), 0)
    a1 = np.minimum(np.floor((u + hu - u0) / cell), nu - 1)
    b0 = np.maximum(np.floor((v - hv - v0) / cell), 0)
    b1 = np.minimum(np.floor((v + hv - v0) / cell), nv - 1)
    share = ((np.maximum(a0[:, None], a0[None, :]) <= np.minimum(a1[:, None], a1[None, :]))
             & (np.maximum(b0[:, None], b0[None, :]) <= np.minimum(b1[:, None], b1[None, :])))
    off, idx = partners_brute_force(pos, r, patch)
    rows = np.repeat(np.arange(len(pos)), np.diff(off))
    keep = share[rows, idx]
    return pairs_to_csr(np.stack([rows[keep], idx[keep]], axis=1)[rows[keep] < idx[keep]], len(pos))


def _disc_half_extents(r: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """(N, 3) half-extents of the 3D boxes of the discs (as :func:`grid_boxes` pads them)."""
    return r[:, None] * np.sqrt(np.clip(1.0 - nrm ** 2, 0.0, 1.0)) * (1 + 1e-9) + 1e-12


def grid_reference(positions: Any, radii: Any, patch: Any, normals: Any) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy O(N^2) reference of the ``"grid"`` method: the pairs of the 4.2.1 estimate
    whose disc boxes overlap."""
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    r = np.ascontiguousarray(radii, dtype=np.float64)
    h = _disc_half_extents(r, np.asarray(normals, dtype=np.float64))
    off, idx = partners_brute_force(pos, r, patch)
    rows = np.repeat(np.arange(len(pos)), np.diff(off))
    keep = np.all(np.abs(pos[rows] - pos[idx]) <= h[rows] + h[idx], axis=1) & (rows < idx)
    return pairs_to_csr(np.stack([rows[keep], idx[keep]], axis=1), len(pos))


def _grid(pos: np.ndarray, r: np.ndarray, nrm: np.ndarray) -> tuple:
    """Boxes and the 3D clip grid: cubes of twice the median radius, coarsened until there are at
    most :data:`_CELLS_PER_SURFEL` cells per surfel and ~16 (surfel, cell) entries per surfel
    (memory and time stay O(N))."""
    n = len(pos)
    half, lo, hi = disc_boxes(pos, r, nrm)
    ext = hi - lo
    cell = max(2.0 * float(np.median(r)), float(ext.max()) / 4096, 1e-12)
    while True:
        dims = (ext / cell).astype(np.int64) + 1
        if int(np.prod(dims)) <= _CELLS_PER_SURFEL * n + 64:
            box, total = grid_boxes(pos, half, lo, cell, dims)
            if total <= 16 * n + 100000:
                return half, box, dims
        cell *= 1.26


def find_partners(positions: Any, radii: Any, patch: Any, normals: Any = None,
                  method: str = "grid") -> tuple[np.ndarray, np.ndarray]:
    """Clipping partners of every surfel (4.2.1).

    Parameters
    ----------
    positions : (N, 3) float64
    radii : (N,) float64
        Largest semi-axis of each surfel.
    patch : (N,) int
        Patch (leaf) of each surfel; surfels of one patch are never partners.
    normals : (N, 3) float64, optional
        Needed by ``"clipbuffer"`` (the projected box); without them a surfel covers the box of
        its bounding sphere.
    method : {"grid", "clipbuffer", "range"}

    Returns
    -------
    offsets : (N+1,) int64
    indices : int64
        Partners of surfel ``i`` are ``indices[offsets[i]:offsets[i+1]]``, ascending.
    """
    if method not in METHODS:
        raise InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    r = np.ascontiguousarray(radii, dtype=np.float64)
    p = np.ascontiguousarray(patch, dtype=np.int64)
    n = len(pos)
    if n == 0:
        return np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if method == "range":
        pairs = _range_pairs(pos, r, p)
    elif method == "grid":
        nrm = np.zeros_like(pos) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
        order = None
        if np.any(p[1:] < p[:-1]):  # the kernel wants surfels ordered by patch
            order = np.argsort(p, kind="stable")
            pos, r, p, nrm = pos[order], r[order], p[order], nrm[order]
        half, box, dims = _grid(pos, r, nrm)
        ncell = int(np.prod(dims))
        with serial_if_small(n):  # no parallel launch for a few surfels
            off, idx = grid_csr(pos, r, p, half, box, dims, max(1, min(256, ncell // 256)))
        if order is None:
            return off, idx
        rows = np.repeat(order, np.diff(off))
        cols = order[idx]
        keep = rows < cols
        return pairs_to_csr(np.stack([rows[keep], cols[keep]], axis=1), n)
    else:
        nrm = np.zeros_like(pos) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
        axis = int(np.argmin(np.ptp(pos, axis=0)))
        au, av = [k for k in range(3) if k != axis]
        box, nu, nv = cell_boxes(pos, r, nrm, au, av)
        return clip_buffer_csr(pos, r, p, box, nu, nv, max(1, min(64, (nu * nv) // 64)))
    return pairs_to_csr(_unique_pairs(pairs, n), n)
