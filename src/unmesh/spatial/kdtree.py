"""kd-tree searches with exact, brute-force-identical results (thesis section 3.4.1).

A thin layer over :class:`scipy.spatial.cKDTree` (balanced, median splits, O(N log N)
construction).  SciPy's answers are turned into exact ones: distances are recomputed
as ``sqrt(sum((x_j - q_i)**2))`` (axis order, like numpy), radius tests compare squared
distances with ``radius**2``, and k-nearest ties are broken by index, so results are
identical to a brute-force stable sort even with duplicate points.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from unmesh._threads import SERIAL_BELOW, serial_if_small
from unmesh._validate import as_points, positive_scalar
from unmesh.errors import InputError
from unmesh.spatial import _kernels as K

__all__ = ["KDTree"]

#: Relative slack given to SciPy's own distance tests; exact filtering follows.
_SLACK = 1e-8
#: Up to this many queries, radius searches ask SciPy per query instead of pairing two trees.
_FEW_QUERIES = 16


def _check_k(k: object) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise InputError(f"k: expected a positive integer, got {k!r}")
    if int(k) < 1:
        raise InputError(f"k: expected a positive integer, got {k}")
    return int(k)


def _sq_dist(points: np.ndarray, i: np.ndarray, queries: np.ndarray, q: np.ndarray) -> np.ndarray:
    return ((points[i] - queries[q]) ** 2).sum(axis=1)


def _within(points: np.ndarray, i: np.ndarray, queries: np.ndarray, q: np.ndarray, r2: float) -> np.ndarray:
    """``_sq_dist(points, i, queries, q) <= r2`` (the same sums) by a kernel, (P,) bool."""
    keep = np.empty(len(i), np.bool_)
    with serial_if_small(len(i)):
        K.pairs_within(points, np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(queries),
                       np.ascontiguousarray(q, dtype=np.int64), float(r2), keep)
    return keep


def _csr_from_pairs(rows: np.ndarray, cols: np.ndarray, nrows: int, ncols: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR (offsets, indices) of the (row, col) pairs, each row sorted ascending."""
    order = np.argsort(rows * np.int64(max(ncols, 1)) + cols, kind="stable")
    indices = np.ascontiguousarray(cols[order], dtype=np.int64)
    offsets = np.zeros(nrows + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=nrows), out=offsets[1:])
    return offsets, indices


class KDTree:
    """kd-tree over a fixed point set for repeated exact queries.

    Parameters
    ----------
    points : array_like, shape (N, 3) or (N, 2)
        Point positions (finite); a copy is kept.
    leafsize : int, optional
        Points per leaf of SciPy's tree (default 16). Results do not depend on it; larger
        leaves cost less for queries far from the points (fewer boxes to rule out) and a
        little more for close ones.

    Example
    -------
    >>> tree = KDTree([[0.0, 0, 0], [1, 0, 0], [0, 2, 0]])
    >>> d, i = tree.knn([[0.9, 0, 0]], 2)
    >>> i.tolist(), [round(float(v), 3) for v in d[0]]
    ([[1, 0]], [0.1, 0.9])
    """

    def __init__(self, points: object, leafsize: int = 16) -> None:
        from unmesh.spatial.cellgrid import _dim_of

        if isinstance(leafsize, bool) or not isinstance(leafsize, (int, np.integer)) or leafsize < 1:
            raise InputError(f"leafsize: expected a positive integer, got {leafsize!r}")
        self.dim = _dim_of(points)
        self.points = as_points(points, "points", dim=self.dim)
        self._tree = cKDTree(self.points, leafsize=int(leafsize)) if len(self.points) else None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def __repr__(self) -> str:
        return f"KDTree(n_points={len(self)}, dim={self.dim})"

    def _queries(self, queries: object) -> np.ndarray:
        if queries is None:
            return self.points
        return as_points(queries, "queries", dim=self.dim)

    def knn(self, queries: object, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest points of each query, sorted by (distance, index).

        Parameters
        ----------
        queries : array_like, shape (Q, dim), or None
            Query positions; ``None`` queries the points themselves (each point is
            then among its own neighbours at distance 0).
        k : int
            Number of neighbours (>= 1).  Rows are padded with ``inf`` / ``-1`` when
            ``k > N``.

        Returns
        -------
        distances : ndarray, shape (Q, k), float64
            ``sqrt(sum((x_j - q_i)**2))``, ascending.
        indices : ndarray, shape (Q, k), int64
            Point indices; among equal distances ascending.

        Example
        -------
        >>> KDTree([[0.0, 0], [1, 0], [1, 0]]).knn(None, 2)[1].tolist()
        [[0, 1], [1, 2], [1, 2]]
        """
        k = _check_k(k)
        q = self._queries(queries)
        n, nq = len(self), len(q)
        dist = np.full((nq, k), np.inf)
        idx = np.full((nq, k), -1, np.int64)
        if n == 0 or nq == 0:
            return dist, idx
        kk = min(k + 1, n)
        d_kd, i_kd = self._query(q, kk)
        if kk <= k:  # every point is a neighbour: exact sort of all of them
            dist[:, :kk], idx[:, :kk] = self._finish(q, i_kd, kk)
            return dist, idx
        # The k nearest are determined when the (k+1)-th kd distance is clearly larger
        # than the k-th; otherwise (ties, near-ties) ask for more candidates until the
        # last one is clearly farther, then sort all of them exactly.
        dist[:], idx[:] = self._finish(q, i_kd, k)
        rows = np.flatnonzero(d_kd[:, k] <= d_kd[:, k - 1] * (1.0 + _SLACK))
        kq = kk
        while rows.size:
            kq = min(2 * kq, n)
            d2, i2 = self._query(q[rows], kq)
            done = np.ones(len(rows), bool) if kq == n else d2[:, kq - 1] > d2[:, k - 1] * (1.0 + _SLACK)
            if done.any():
                dist[rows[done]], idx[rows[done]] = self._finish(q[rows[done]], i2[done], k)
            rows = rows[~done]
        return dist, idx

    def _query(self, q: np.ndarray, kk: int) -> tuple[np.ndarray, np.ndarray]:
        # SciPy starts its worker threads on every call: for small queries that costs more than the search
        workers = -1 if len(q) * kk >= SERIAL_BELOW else 1
        d, i = self._tree.query(q, k=kk, workers=workers)
        d = d.reshape(len(q), kk)
        i = np.ascontiguousarray(i.reshape(len(q), kk), dtype=np.int64)
        n = len(self)
        # SciPy marks neighbours whose squared distance overflows (points near 1e200) with
        # index n; they are at infinite distance, which a stable sort orders by index.
        for r in np.flatnonzero((i >= n).any(axis=1)):
            found = i[r][i[r] < n]
            rest = np.setdiff1d(np.arange(n, dtype=np.int64), found, assume_unique=True)
            i[r] = np.concatenate([found, rest[:kk - len(found)]])
        return d, i

    def _finish(self, q: np.ndarray, cand: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact distances of the candidates, rows sorted by (distance, index); first k."""
        cand = np.ascontiguousarray(cand)
        dd = np.empty(cand.shape)
        with serial_if_small(cand.size):
            K.knn_finish(self.points, np.ascontiguousarray(q), cand, dd)
        return dd[:, :k], cand[:, :k]

    def radius_neighbors(self, queries: object, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """CSR of the points within ``radius`` of each query (see
        :func:`unmesh.spatial.radius_neighbors`, ``method="kdtree"``).

        Example
        -------
        >>> off, ind = KDTree([[0.0, 0], [1, 0]]).radius_neighbors(None, 1.0)
        >>> off.tolist(), ind.tolist()
        ([0, 2, 4], [0, 1, 0, 1])
        """
        radius = positive_scalar(radius, "radius")
        q = self._queries(queries)
        n, nq = len(self), len(q)
        if n == 0 or nq == 0:
            return np.zeros(nq + 1, np.int64), np.empty(0, np.int64)
        r2 = radius * radius
        if queries is None:
            pairs = self.radius_pairs(radius)
            ar = np.arange(n, dtype=np.int64)
            rows = np.concatenate([pairs[:, 0], pairs[:, 1], ar])
            cols = np.concatenate([pairs[:, 1], pairs[:, 0], ar])
            return _csr_from_pairs(rows, cols, n, n)
        if nq == 1:  # one query (a paint event's neighbourhood): sorted indices without pairing
            found = self._tree.query_ball_point(q[0], radius * (1.0 + _SLACK), workers=1, return_sorted=False)
            cols = np.array(found, dtype=np.int64)
            cols = np.sort(cols[_within(self.points, cols, q, np.zeros(len(cols), np.int64), r2)])
            return np.array([0, len(cols)], np.int64), cols
        if nq <= _FEW_QUERIES:  # building a tree of the queries costs more than asking per query
            # (unsorted: _csr_from_pairs sorts each row)
            found = self._tree.query_ball_point(q, radius * (1.0 + _SLACK), workers=1, return_sorted=False)
            counts = np.fromiter((len(f) for f in found), np.int64, nq)
            rows = np.repeat(np.arange(nq, dtype=np.int64), counts)
            cols = np.fromiter(itertools.chain.from_iterable(found), np.int64, int(counts.sum()))
        else:
            sdm = cKDTree(q).sparse_distance_matrix(self._tree, radius * (1.0 + _SLACK), output_type="ndarray")
            rows = np.ascontiguousarray(sdm["i"], dtype=np.int64)
            cols = np.ascontiguousarray(sdm["j"], dtype=np.int64)
        keep = _within(self.points, cols, q, rows, r2)
        return _csr_from_pairs(rows[keep], cols[keep], nq, n)

    def radius_pairs(self, radius: float) -> np.ndarray:
        """Pairs ``i < j`` with ``sum((x_i - x_j)**2) <= radius**2``, shape (P, 2) int64,
        sorted lexicographically.

        Example
        -------
        >>> KDTree([[0.0, 0], [1, 0], [5, 5]]).radius_pairs(1.0).tolist()
        [[0, 1]]
        """
        radius = positive_scalar(radius, "radius")
        if len(self) < 2:
            return np.empty((0, 2), np.int64)
        pairs = self._tree.query_pairs(radius * (1.0 + _SLACK), output_type="ndarray").astype(np.int64, copy=False)
        pairs = pairs[_within(self.points, pairs[:, 0], self.points, pairs[:, 1], radius * radius)]
        lo = np.minimum(pairs[:, 0], pairs[:, 1])
        hi = np.maximum(pairs[:, 0], pairs[:, 1])
        order = np.argsort(lo * np.int64(len(self)) + hi, kind="stable")
        return np.ascontiguousarray(np.stack([lo[order], hi[order]], axis=1))
