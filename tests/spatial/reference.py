"""Plain numpy reference implementations for the spatial kernels and searches."""

from __future__ import annotations

import numpy as np


def sq_dist_matrix(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """(Q, N) squared distances, summed in axis order like the kernels."""
    return ((points[None, :, :] - queries[:, None, :]) ** 2).sum(-1)


def brute_radius(points, radius, queries=None):
    """CSR (offsets, indices) of ``sum((x_j - q_i)**2) <= radius**2``."""
    points = np.asarray(points, dtype=np.float64)
    q = points if queries is None else np.asarray(queries, dtype=np.float64)
    offsets = [0]
    indices = []
    for s in range(0, len(q), 512):
        if len(points) == 0:
            hit = np.zeros((len(q[s : s + 512]), 0), bool)
        else:
            hit = sq_dist_matrix(points, q[s : s + 512]) <= radius * radius
        for row in hit:
            nb = np.flatnonzero(row)
            indices.append(nb)
            offsets.append(offsets[-1] + nb.size)
    ind = np.concatenate(indices).astype(np.int64) if indices else np.empty(0, np.int64)
    return np.array(offsets, np.int64), ind


def brute_pairs(points, radius):
    """(P, 2) pairs i < j within radius, lexicographic."""
    off, ind = brute_radius(points, radius)
    rows = np.repeat(np.arange(len(off) - 1), np.diff(off))
    keep = ind > rows
    return np.stack([rows[keep], ind[keep]], axis=1).astype(np.int64).reshape(-1, 2)


def brute_knn(points, k, queries=None):
    """Brute-force k nearest: stable sort of distances, padded with inf / -1."""
    points = np.asarray(points, dtype=np.float64)
    q = points if queries is None else np.asarray(queries, dtype=np.float64)
    dist = np.full((len(q), k), np.inf)
    idx = np.full((len(q), k), -1, np.int64)
    if len(points) == 0:
        return dist, idx
    d = np.sqrt(sq_dist_matrix(points, q))
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    m = order.shape[1]
    idx[:, :m] = order
    dist[:, :m] = np.take_along_axis(d, order, axis=1)
    return dist, idx


# ---- kernel references ------------------------------------------------------------


def ref_cells(points, origin, inv_cell, dims):
    """Virtual (i, j, k) cells, clamped, and keys of each point (eq. 3.16)."""
    t = (points - origin) * inv_cell
    if points.shape[1] == 2:
        t = np.concatenate([np.zeros((len(points), 1)), t], axis=1)
    ijk = np.clip(np.floor(t), 0, dims - 1).astype(np.int64)
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    return ijk, keys


def ref_compress(sorted_keys):
    keys, start = np.unique(sorted_keys, return_index=True)
    return keys.astype(np.int64), np.append(start, len(sorted_keys)).astype(np.int64)


def ref_stencil_points(i, j, k, reach, dims, cell_keys, cell_start):
    """Sorted-point indices of every non-empty cell within ``reach`` (set semantics)."""
    out = []
    for ii in range(i - reach, i + reach + 1):
        for jj in range(j - reach, j + reach + 1):
            for kk in range(k - reach, k + reach + 1):
                if 0 <= ii < dims[0] and 0 <= jj < dims[1] and 0 <= kk < dims[2]:
                    key = (ii * dims[1] + jj) * dims[2] + kk
                    c = np.searchsorted(cell_keys, key)
                    if c < len(cell_keys) and cell_keys[c] == key:
                        out.extend(range(cell_start[c], cell_start[c + 1]))
    return np.array(sorted(out), np.int64)


def ref_knn_finish(points, queries, idx):
    d = np.sqrt(((points[idx] - queries[:, None, :]) ** 2).sum(-1))
    order = np.array([np.lexsort((i, r)) for i, r in zip(idx, d, strict=True)])
    return np.take_along_axis(d, order, 1), np.take_along_axis(idx, order, 1)
