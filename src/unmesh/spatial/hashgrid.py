"""Dynamic spatial hash grid (thesis section 3.4.2, eqs. 3.16-3.17).

An unbounded virtual grid of cubic cells whose non-empty cells live in a hash table:
O(1) average insertion, removal and moving of points, memory proportional to the
number of points and occupied cells, never to the extent.  Use it when points are
added, deleted or moved a few at a time; for point sets that change completely every
step (SPH) rebuilding a :class:`~unmesh.spatial.CellGrid` is faster.
"""

from __future__ import annotations

import math

import numpy as np

from unmesh._threads import serial_if_small
from unmesh._validate import as_array, as_points, first_index, positive_scalar
from unmesh.errors import InputError
from unmesh.spatial import _hash_kernels as H

__all__ = ["HashGrid"]

#: Largest id + 1 accepted; memory grows with the largest id (ids are array indices).
MAX_ID = 1 << 31
_MARGIN = 1e-6


def _next_prime(n: int) -> int:
    """Smallest prime >= n (the table size s of eq. 3.17 should be prime)."""
    n = max(n, 2)
    while True:
        if n % 2 or n == 2:
            lim = math.isqrt(n)
            if all(n % f for f in range(3, lim + 1, 2)):
                return n
        n += 1


class HashGrid:
    """Dynamic spatial hash of points identified by integer ids (eqs. 3.16, 3.17).

    Cells are cubes of edge ``cell_size`` indexed ``(floor(x/d), floor(y/d),
    floor(z/d))`` (eq. 3.16); the table slot of a cell is found from
    ``h(i, j, k) = (i p1 xor j p2 xor k p3) mod s`` (eq. 3.17, Teschner's primes,
    ``s`` prime) with linear probing.  Slots store their cell indices, so hash
    collisions never produce false neighbours.  The table grows (and drops emptied
    cells) when more than half of it is used.

    A query of radius ``r <= cell_size / 2`` visits the 8 cells (4 in 2-D) nearest
    to the query (Figure 3.7 c, ``d = 2 r_max``, which the thesis finds fastest);
    ``r <= cell_size`` visits the 27 cells (9) around the query's cell (Figure
    3.7 b); larger radii visit ``(2m+1)^3`` cells, ``m = ceil(r / cell_size)``, or
    every point when that is fewer.  Queries are grouped by cell so that each group
    gathers its cells once.

    Parameters
    ----------
    cell_size : float
        Cell edge ``d`` (> 0); choose ``2 r_max`` (8-cell searches) or ``r_max``
        (27-cell searches) for the largest query radius ``r_max``.  The effective
        edge is ``d (1 + 1e-6)`` so that round-off never pushes a point at distance
        ``d`` (or ``d / 2``) out of the searched cells.
    dim : {2, 3}
        Spatial dimension.

    Example
    -------
    >>> g = HashGrid(0.5)
    >>> g.insert([0, 1, 2], [[0, 0, 0], [0.4, 0, 0], [3, 0, 0]])
    >>> g.move([2], [[0.1, 0.1, 0]])
    >>> g.remove([0])
    >>> off, ind = g.query_radius([[0, 0, 0]], 0.5)
    >>> ind.tolist(), len(g)
    ([1, 2], 2)
    """

    def __init__(self, cell_size: float, dim: int = 3) -> None:
        if dim not in (2, 3) or isinstance(dim, bool):
            raise InputError(f"dim: expected 2 or 3, got {dim!r}")
        self.cell_size = positive_scalar(cell_size, "cell_size")
        self.dim = int(dim)
        self._inv = 1.0 / (self.cell_size * (1.0 + _MARGIN))
        if not math.isfinite(self._inv) or self._inv <= 0:
            raise InputError(f"cell_size: {cell_size} is out of the representable range")
        self._n = 0
        self._used = 0
        self._alloc_points(0)
        self._new_table(_next_prime(61))

    # -- storage ------------------------------------------------------------------
    def _alloc_points(self, cap: int) -> None:
        self._pos = np.zeros((cap, self.dim))
        self._alive = np.zeros(cap, np.bool_)
        self._nxt = np.full(cap, -1, np.int64)
        self._prv = np.full(cap, -1, np.int64)
        self._pslot = np.full(cap, -1, np.int64)

    def _grow_points(self, need: int) -> None:
        cap = len(self._alive)
        if need <= cap:
            return
        new = max(need, 2 * cap, 64)
        old = (self._pos, self._alive, self._nxt, self._prv, self._pslot)
        self._alloc_points(new)
        for dst, src in zip((self._pos, self._alive, self._nxt, self._prv, self._pslot), old, strict=True):
            dst[:cap] = src

    def _new_table(self, size: int) -> None:
        self._slot_cell = np.zeros((size, 3), np.int64)
        self._slot_used = np.zeros(size, np.bool_)
        self._slot_head = np.full(size, -1, np.int64)
        self._slot_count = np.zeros(size, np.int64)
        self._used = 0

    def _reserve_slots(self, extra: int) -> None:
        """Make sure ``extra`` more cells keep the table at most half full."""
        size = len(self._slot_used)
        if 2 * (self._used + extra) <= size:
            return
        live = int(np.count_nonzero(self._slot_count)) if self._used else 0
        size = _next_prime(max(61, 4 * (live + extra)))
        (self._slot_cell, self._slot_used, self._slot_head, self._slot_count,
         self._nxt, self._prv, self._pslot, self._used) = H.hash_rebuild(
            size, self._inv, self._pos, self._alive)

    # -- validation ---------------------------------------------------------------
    def _ids(self, ids: object, name: str = "ids") -> np.ndarray:
        arr = as_array(ids, name, (None,), np.int64, finite=False)
        if arr.size:
            bad = (arr < 0) | (arr >= MAX_ID)
            if bad.any():
                raise InputError(f"{name}: expected integers in [0, 2**31), got {arr[first_index(bad)]} at index {first_index(bad)}")
            srt = np.sort(arr)
            dup = srt[1:] == srt[:-1]
            if dup.any():
                raise InputError(f"{name}: expected unique ids, got {srt[1:][dup][0]} twice")
        return arr

    def _check_alive(self, ids: np.ndarray, want: bool, name: str = "ids") -> None:
        cap = len(self._alive)
        alive = np.zeros(ids.shape, bool)
        inside = ids < cap
        alive[inside] = self._alive[ids[inside]]
        bad = alive != want
        if bad.any():
            t = first_index(bad)
            state = "already in the grid" if want is False else "not in the grid"
            raise InputError(f"{name}: id {ids[t]} at index {t} is {state}")

    # -- updates -------------------------------------------------------------------
    def insert(self, ids: object, points: object) -> None:
        """Add points under new ids (O(1) average each).

        Parameters
        ----------
        ids : array_like, shape (M,), int
            Unique ids in ``[0, 2**31)`` not in the grid.  Memory grows with the
            largest id, so use small integers (e.g. particle indices).
        points : array_like, shape (M, dim)

        Example
        -------
        >>> g = HashGrid(1.0, dim=2)
        >>> g.insert([0, 7], [[0.0, 0.0], [2.5, 1.0]])
        >>> g.ids.tolist(), g.n_cells
        ([0, 7], 2)
        """
        ids = self._ids(ids)
        pts = as_points(points, "points", dim=self.dim, length=len(ids))
        if not len(ids):
            return
        self._check_alive(ids, False)
        self._grow_points(int(ids.max()) + 1)
        self._reserve_slots(len(ids))
        self._used += H.hash_insert(ids, pts, self._inv, self._slot_cell, self._slot_used, self._slot_head,
                                    self._slot_count, self._pos, self._alive, self._nxt, self._prv, self._pslot)
        self._n += len(ids)

    def remove(self, ids: object) -> None:
        """Delete points by id (O(1) each).

        Parameters
        ----------
        ids : array_like, shape (M,), int
            Unique ids currently in the grid.

        Example
        -------
        >>> g = HashGrid(1.0)
        >>> g.insert([0, 1], [[0, 0, 0], [5, 5, 5]])
        >>> g.remove([0])
        >>> len(g), 0 in g
        (1, False)
        """
        ids = self._ids(ids)
        if not len(ids):
            return
        self._check_alive(ids, True)
        H.hash_remove(ids, self._slot_head, self._slot_count, self._alive, self._nxt, self._prv, self._pslot)
        self._n -= len(ids)

    def move(self, ids: object, new_points: object) -> None:
        """Set new positions (O(1) each; only points that change cell are relinked).

        Parameters
        ----------
        ids : array_like, shape (M,), int
            Unique ids currently in the grid.
        new_points : array_like, shape (M, dim)

        Example
        -------
        >>> g = HashGrid(1.0)
        >>> g.insert([3], [[0, 0, 0]])
        >>> g.move([3], [[10.0, 0, 0]])
        >>> g.positions([3]).tolist(), g.query_radius([[10, 0, 0]], 0.5)[1].tolist()
        ([[10.0, 0.0, 0.0]], [3])
        """
        ids = self._ids(ids)
        pts = as_points(new_points, "new_points", dim=self.dim, length=len(ids))
        if not len(ids):
            return
        self._check_alive(ids, True)
        self._reserve_slots(len(ids))
        self._used += H.hash_move(ids, pts, self._inv, self._slot_cell, self._slot_used, self._slot_head,
                                  self._slot_count, self._pos, self._nxt, self._prv, self._pslot)

    def clear(self) -> None:
        """Remove every point.

        Example
        -------
        >>> g = HashGrid(1.0)
        >>> g.insert([0], [[0, 0, 0]])
        >>> g.clear()
        >>> len(g)
        0
        """
        self._n = 0
        self._alloc_points(0)
        self._new_table(_next_prime(61))

    # -- inspection ----------------------------------------------------------------
    def __len__(self) -> int:
        return self._n

    def __contains__(self, i: object) -> bool:
        try:
            i = int(i)  # type: ignore[call-overload]
        except (TypeError, ValueError):
            return False
        return 0 <= i < len(self._alive) and bool(self._alive[i])

    def __repr__(self) -> str:
        return f"HashGrid(cell_size={self.cell_size:g}, dim={self.dim}, n_points={self._n}, n_cells={self.n_cells})"

    @property
    def ids(self) -> np.ndarray:
        """Ids in the grid, ascending, shape (N,) int64."""
        return np.flatnonzero(self._alive).astype(np.int64)

    @property
    def n_cells(self) -> int:
        """Number of non-empty cells."""
        return int(np.count_nonzero(self._slot_count))

    def positions(self, ids: object = None) -> np.ndarray:
        """Positions of ``ids`` (default: all, in :attr:`ids` order), shape (M, dim) float64.

        Example
        -------
        >>> g = HashGrid(1.0, dim=2)
        >>> g.insert([4, 2], [[1, 1], [2, 2]])
        >>> g.positions().tolist()
        [[2.0, 2.0], [1.0, 1.0]]
        """
        if ids is None:
            return self._pos[self._alive].copy()
        ids = self._ids(ids)
        self._check_alive(ids, True)
        return self._pos[ids].copy()

    # -- queries ---------------------------------------------------------------------
    def query_radius(self, queries: object, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Ids within ``radius`` of each query, as CSR (see
        :func:`unmesh.spatial.radius_neighbors` for the conventions).

        Parameters
        ----------
        queries : array_like, shape (Q, dim)
        radius : float
            Any positive radius; ``radius <= cell_size / 2`` visits 8 (4) cells,
            ``radius <= cell_size`` 27 (9).

        Returns
        -------
        offsets : ndarray, shape (Q+1,), int64
        indices : ndarray, int64
            Ids with ``sum((x_id - q_i)**2) <= radius**2``, ascending per row.

        Example
        -------
        >>> g = HashGrid(1.0, dim=2)
        >>> g.insert([5, 3], [[0, 0], [0.5, 0.5]])
        >>> g.query_radius([[0, 0], [9, 9]], 1.0)[1].tolist()
        [3, 5]
        """
        q = as_points(queries, "queries", dim=self.dim)
        r = positive_scalar(radius, "radius")
        nq = len(q)
        offsets = np.zeros(nq + 1, np.int64)
        counts = np.zeros(nq, np.int64)
        if nq == 0 or self._n == 0:
            return offsets, np.empty(0, np.int64)
        with serial_if_small(nq + self._n):
            return self._query(q, r, offsets, counts)

    def _query(self, q: np.ndarray, r: float, offsets: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        reach = max(1, math.ceil(r * self._inv * (1.0 + 1e-9)))
        cells = (2 * reach + 1) ** self.dim
        if cells > max(64, 2 * self._n):
            ids = self.ids
            H.brute_query(q, r, ids, self._pos, counts, offsets, counts, False)
            np.cumsum(counts, out=offsets[1:])
            indices = np.empty(int(offsets[-1]), np.int64)
            H.brute_query(q, r, ids, self._pos, counts, offsets, indices, True)
            return offsets, indices
        # group the queries by cell (half-cell for the 8-cell search): each group
        # gathers its cells once
        half = r * self._inv * (1.0 + 1e-9) <= 0.5
        cells = H.query_cells(q, self._inv, half)
        qorder = np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0])).astype(np.int64)
        sc = cells[qorder]
        new = np.ones(len(q), bool)
        new[1:] = np.any(sc[1:] != sc[:-1], axis=1)
        group_start = np.append(np.flatnonzero(new), len(q)).astype(np.int64)
        qcells = np.ascontiguousarray(sc[new])
        args = (q, qorder, group_start, qcells, r, reach, half, self._slot_cell, self._slot_used, self._slot_head,
                self._slot_count, self._pos, self._nxt)
        H.hash_query(*args, counts, offsets, counts, False)
        np.cumsum(counts, out=offsets[1:])
        indices = np.empty(int(offsets[-1]), np.int64)
        H.hash_query(*args, counts, offsets, indices, True)
        return offsets, indices
