"""Fixed-radius neighbour search: CSR neighbour lists and unique pairs.

Backed by the static cell grid (:mod:`unmesh.spatial.cellgrid`, thesis section
3.4.2) with a kd-tree fallback (section 3.4.1) for layouts where a uniform grid is
pathological; see :func:`choose_method` for the heuristic.
"""

from __future__ import annotations

import numba
import numpy as np

from unmesh._threads import serial_if_small
from unmesh._validate import as_points, scalar
from unmesh.errors import InputError
from unmesh.spatial import _kernels as K
from unmesh.spatial import _pair_kernels as PK
from unmesh.spatial.cellgrid import CellGrid, _build, _dim_of
from unmesh.spatial.kdtree import KDTree

__all__ = ["choose_method", "knn", "radius_neighbors", "radius_pairs"]

#: Cells per search radius: cell edge = radius / CELLS_PER_RADIUS (tuned, see benchmarks).
CELLS_PER_RADIUS = 1
#: A grid whose sampled hit rate (results / distance tests) is below this ...
_MIN_EFFICIENCY = 0.01
#: ... while testing more than this many candidates per query falls back to the kd-tree.
_MIN_CANDIDATES = 512
#: Number of sample queries used to estimate the grid's hit rate.
_N_SAMPLES = 256

_METHODS = ("auto", "grid", "kdtree")


def _check_radius(radius: object) -> float:
    r = scalar(radius, "radius")
    if not r > 0:
        raise InputError(f"radius: expected a positive number, got {r}")
    return r


def _check_method(method: object) -> str:
    if method not in _METHODS:
        raise InputError(f"method: expected one of {', '.join(map(repr, _METHODS))}, got {method!r}")
    return str(method)


def _inputs(points: object, queries: object) -> tuple[np.ndarray, np.ndarray | None]:
    dim = _dim_of(points)
    if queries is None:
        return as_points(points, "points", dim=dim), None
    qarr = np.asarray(queries)
    if np.asarray(points).size == 0 and qarr.ndim == 2 and qarr.shape[1] in (2, 3):
        dim = int(qarr.shape[1])  # empty points: take the dimension from the queries
    pts = as_points(points, "points", dim=dim)
    qdim = qarr.shape[-1] if qarr.ndim in (1, 2) and qarr.size else dim
    if qdim != dim:
        raise InputError(f"queries: expected {dim}-D points like `points`, got shape {qarr.shape}")
    return pts, as_points(queries, "queries", dim=dim)


def _grid_for(pts: np.ndarray, radius: float) -> tuple[CellGrid, int]:
    grid = _build(pts, radius / CELLS_PER_RADIUS)
    return grid, grid.reach(radius)


def _group_queries(grid: CellGrid, q: np.ndarray):
    """Sort queries by grid cell; returns (sorted queries, order, group keys, group starts)."""
    keys = K.compute_keys(q, grid.origin, grid.inv_cell, grid.dims)
    total = int(grid.dims[0] * grid.dims[1] * grid.dims[2])
    order = K.counting_sort(keys, total) if total <= 4 * len(q) + 4096 else np.argsort(keys, kind="stable")
    gkeys, gstart = K.compress_cells(keys[order])
    return K.gather_rows(q, order), order, gkeys, gstart


def choose_method(
    points: np.ndarray, radius: float, queries: np.ndarray | None = None, grid: CellGrid | None = None
) -> str:
    """The backend ``method="auto"`` uses for a radius search: ``"grid"`` or ``"kdtree"``.

    The uniform grid (cell edge = radius) is used unless it is pathological:

    1. the extent is so large compared with the radius that the grid would need more
       than ``MAX_CELLS_PER_AXIS`` (2^20) cells along an axis and its cells had to be
       enlarged beyond twice the radius; or
    2. the density is so non-uniform at the scale of the radius that, on 256 sample
       queries (evenly spaced in the query order), the grid would test more than 512
       candidates per query while fewer than 1 % of them are hits (a uniform cloud
       has about 15 %, a sampled surface about 25 %).  Example: queries in a shell
       just outside the radius around a dense cluster.

    Both checks cost O(N) at most (the grid is built anyway).

    Parameters
    ----------
    points : array_like, shape (N, dim)
    radius : float
    queries : array_like, shape (Q, dim), optional
        Query positions (``None``: the points).
    grid : CellGrid, optional
        The grid for this radius if already built (then ``points`` and ``queries``
        must be validated float64 arrays).

    Returns
    -------
    str

    Example
    -------
    >>> import numpy as np
    >>> choose_method(np.random.default_rng(0).random((1000, 3)), 0.1)
    'grid'
    >>> choose_method(np.array([[0.0, 0, 0], [1e9, 0, 0]]), 1e-6)
    'kdtree'
    """
    radius = _check_radius(radius)
    if grid is None:
        pts, q = _inputs(points, queries)
        queries = q
        grid = _build(pts, radius / CELLS_PER_RADIUS) if len(pts) else None
    if grid is None:
        return "grid"
    if grid.cell_size > 2.0 * radius:
        return "kdtree"
    n = grid.n_points
    if n == 0:
        return "grid"
    reach = grid.reach(radius)
    src = grid.points if queries is None else np.ascontiguousarray(queries, dtype=np.float64)
    if len(src) == 0:
        return "grid"
    sample = src[np.linspace(0, len(src) - 1, min(len(src), _N_SAMPLES)).astype(np.int64)]
    cand, hits = K.sample_efficiency(grid.points, grid.cell_keys, grid.cell_start, grid.origin,
                                     grid.inv_cell, grid.dims, reach, sample, radius)
    if cand > _MIN_CANDIDATES * len(sample) and hits < _MIN_EFFICIENCY * cand:
        return "kdtree"
    return "grid"


#: Chunks per thread of the one-pass pair search, and the slack on its size estimate.
_CHUNKS_PER_THREAD = 32
_CAPACITY_SLACK = 1.25


def _self_pairs(grid: CellGrid, reach: int, radius: float):
    """Every pair within ``radius`` once, as original indices ``plo < phi``.

    One pass writes the pairs of chunks of cells into space estimated from an exact
    count on a sample of cells; chunks that run out of space finish with an exact
    count + fill pass.  Returns ``(plo, phi, seg_start, seg_len)``: the pairs are the
    segments ``[seg_start[s], seg_start[s] + seg_len[s])`` of ``plo`` / ``phi``."""
    n, nc = grid.n_points, grid.n_cells
    itype = np.int32 if n < 2**31 else np.int64  # halves the scratch memory
    base = (grid.points, grid.cell_keys, grid.cell_start, grid.dims, reach, radius)
    if nc == 0:
        e = np.empty(0, np.int64)
        return np.empty(0, itype), np.empty(0, itype), e, e.copy()
    # pairs per point, from an exact count on ~256 evenly spread cells
    sample = np.arange(0, nc, max(1, nc // 256), dtype=np.int64)
    in_sample = int((grid.cell_start[sample + 1] - grid.cell_start[sample]).sum())
    per_point = PK.half_count(*base, sample).sum() / max(1, in_sample)
    # chunks of consecutive cells holding about the same number of points
    nch = max(1, min(nc, _CHUNKS_PER_THREAD * numba.get_num_threads()))
    cuts = np.searchsorted(grid.cell_start, np.linspace(0, n, nch + 1)[1:-1])
    chunk_cells = np.unique(np.concatenate([[0], cuts, [nc]])).astype(np.int64)
    pts = grid.cell_start[chunk_cells[1:]] - grid.cell_start[chunk_cells[:-1]]
    cap = np.ceil(pts * per_point * _CAPACITY_SLACK).astype(np.int64) + 256
    chunk_base = np.zeros(len(cap) + 1, np.int64)
    np.cumsum(cap, out=chunk_base[1:])
    plo = np.empty(int(chunk_base[-1]), itype)
    phi = np.empty(int(chunk_base[-1]), itype)
    lengths, stops = PK.half_fill_chunks(grid.points, grid.order, *base[1:], chunk_cells, chunk_base, plo, phi)
    undone = stops < chunk_cells[1:]
    if not undone.any():
        return plo, phi, chunk_base[:-1].copy(), lengths
    # finish the cells of the chunks that ran out of space exactly, then compact
    rest = np.concatenate([np.arange(a, b) for a, b in zip(stops[undone], chunk_cells[1:][undone], strict=True)])
    rest = rest.astype(np.int64)
    counts = PK.half_count(*base, rest)
    off = np.zeros(len(rest) + 1, np.int64)
    np.cumsum(counts, out=off[1:])
    total = int(lengths.sum() + off[-1])
    out_lo = np.empty(total, itype)
    out_hi = np.empty(total, itype)
    w = 0
    for b0, ln in zip(chunk_base[:-1].tolist(), lengths.tolist(), strict=True):
        out_lo[w : w + ln] = plo[b0 : b0 + ln]
        out_hi[w : w + ln] = phi[b0 : b0 + ln]
        w += ln
    del plo, phi
    PK.half_fill(grid.points, grid.order, *base[1:], rest, off + w, out_lo, out_hi)
    return out_lo, out_hi, np.zeros(1, np.int64), np.array([total], np.int64)


def _self_search(grid: CellGrid, reach: int, radius: float, pairs_only: bool):
    """Self query: pairs found once each (half stencil), scattered into rows by
    counting sort, rows sorted.  Returns the (P, 2) pairs when ``pairs_only``, else
    the CSR (offsets, indices)."""
    plo, phi, seg_start, seg_len = _self_pairs(grid, reach, radius)
    n = grid.n_points
    nparts = max(1, min(numba.get_num_threads(), 8))
    both = not pairs_only
    counts = PK.pair_row_counts(plo, phi, seg_start, seg_len, n, both, nparts)
    offsets, cursors = PK.row_cursors(counts, both)
    del counts
    tmp = np.empty(int(offsets[-1]), plo.dtype)  # compact scratch: cheaper random writes
    if both:
        PK.write_self_loops(offsets, tmp)
    PK.pair_row_scatter(plo, phi, seg_start, seg_len, cursors, both, tmp)
    del plo, phi, cursors
    if pairs_only:
        out = np.empty((len(tmp), 2), np.int64)
        PK.sort_pair_rows(offsets, tmp, out)
        return out
    indices = np.empty(len(tmp), np.int64)
    PK.sort_rows(offsets, tmp, indices)
    return offsets, indices


def _grid_search(grid: CellGrid, reach: int, q: np.ndarray | None, radius: float, pairs_only: bool):
    if q is None:
        return _self_search(grid, reach, radius, pairs_only)
    sq, qorder, gkeys, gstart = _group_queries(grid, q)
    args = (grid.points, grid.order, grid.cell_keys, grid.cell_start, grid.dims, reach,
            sq, qorder, gkeys, gstart, True, grid.origin, grid.upper, radius, pairs_only)
    nq = len(q)
    counts = K.radius_count(*args)
    offsets = np.zeros(nq + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    indices = np.empty(int(offsets[-1]), np.int64)
    K.radius_fill(*args, offsets, indices)
    return offsets, indices


def radius_neighbors(
    points: object, radius: float, queries: object = None, method: str = "auto"
) -> tuple[np.ndarray, np.ndarray]:
    """All points within ``radius`` of each query, as CSR neighbour lists.

    A point ``x_j`` is a neighbour of query ``q_i`` when
    ``sum((x_j - q_i)**2) <= radius**2`` (squared distances summed in axis order,
    exactly as numpy's ``((x - q)**2).sum(-1)``).

    Parameters
    ----------
    points : array_like, shape (N, 3) or (N, 2)
        Point positions (finite).
    radius : float
        Search radius (> 0).
    queries : array_like, shape (Q, dim), optional
        Query positions of the same dimension; ``None`` queries the points
        themselves (each point is then its own neighbour).
    method : {"auto", "grid", "kdtree"}
        Backend: the uniform cell grid of eqs. 3.16-3.17 (cell edge = radius, 27
        cells searched, 9 in 2-D), the kd-tree, or ``"auto"`` (see
        :func:`choose_method`).  Results are identical.

    Returns
    -------
    offsets : ndarray, shape (Q+1,), int64
    indices : ndarray, shape (offsets[-1],), int64
        Neighbours of query ``i`` are ``indices[offsets[i]:offsets[i+1]]``, ascending.

    Example
    -------
    >>> off, ind = radius_neighbors([[0.0, 0, 0], [0.5, 0, 0], [2, 0, 0]], 0.5)
    >>> [ind[off[i]:off[i + 1]].tolist() for i in range(3)]
    [[0, 1], [0, 1], [2]]
    """
    pts, q = _inputs(points, queries)
    r = _check_radius(radius)
    method = _check_method(method)
    nq = len(pts) if q is None else len(q)
    if len(pts) == 0 or nq == 0:
        return np.zeros(nq + 1, np.int64), np.empty(0, np.int64)
    if method == "kdtree":
        return KDTree(pts).radius_neighbors(q, r)
    with serial_if_small(len(pts) + nq):
        grid, reach = _grid_for(pts, r)
        if method == "auto" and choose_method(pts, r, q, grid) == "kdtree":
            return KDTree(pts).radius_neighbors(q, r)
        return _grid_search(grid, reach, q, r, False)


def radius_pairs(points: object, radius: float, method: str = "auto", sort: bool = True) -> np.ndarray:
    """Unique pairs of points closer than ``radius`` (like ``cKDTree.query_pairs``).

    Parameters
    ----------
    points : array_like, shape (N, 3) or (N, 2)
    radius : float
        Pairs with ``sum((x_i - x_j)**2) <= radius**2`` are returned.
    method : {"auto", "grid", "kdtree"}
        As in :func:`radius_neighbors`.
    sort : bool
        Sort the rows lexicographically (default). ``False`` returns the same set of rows in
        an unspecified order, like ``cKDTree.query_pairs``, which saves the sorting pass.

    Returns
    -------
    ndarray, shape (P, 2), int64
        Rows ``(i, j)`` with ``i < j``, sorted lexicographically when ``sort``.

    Example
    -------
    >>> radius_pairs([[0.0, 0], [0.5, 0], [2, 0], [0, 0.5]], 0.6).tolist()
    [[0, 1], [0, 3]]
    """
    pts, _ = _inputs(points, None)
    r = _check_radius(radius)
    method = _check_method(method)
    if len(pts) < 2:
        return np.empty((0, 2), np.int64)
    if method == "kdtree":
        return KDTree(pts).radius_pairs(r)
    with serial_if_small(len(pts)):
        grid, reach = _grid_for(pts, r)
        if method == "auto" and choose_method(pts, r, None, grid) == "kdtree":
            return KDTree(pts).radius_pairs(r)
        if not sort:
            plo, phi, seg_start, seg_len = _self_pairs(grid, reach, r)
            out = np.empty((int(seg_len.sum()), 2), np.int64)
            PK.compact_pairs(plo, phi, seg_start, seg_len, out)
            return out
        return _grid_search(grid, reach, None, r, True)


def knn(points: object, k: int, queries: object = None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest points of each query (kd-tree, thesis section 3.4.1).

    Exact: distances are ``sqrt(sum((x_j - q_i)**2))`` and each row is sorted by
    distance, then by index, so the result equals a brute-force stable sort, also with
    duplicate points.

    Parameters
    ----------
    points : array_like, shape (N, 3) or (N, 2)
    k : int
        Number of neighbours (>= 1); rows are padded with ``inf`` / ``-1`` if ``k > N``.
    queries : array_like, shape (Q, dim), optional
        ``None`` queries the points themselves (each point is among its own
        neighbours, at distance 0).

    Returns
    -------
    distances : ndarray, shape (Q, k), float64
    indices : ndarray, shape (Q, k), int64

    Example
    -------
    >>> d, i = knn([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]], 2)
    >>> i.tolist(), d[2].tolist()
    ([[0, 1], [1, 0], [2, 1]], [0.0, 2.0])
    """
    pts, q = _inputs(points, queries)
    return KDTree(pts).knn(q, k)
