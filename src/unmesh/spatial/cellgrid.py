"""Static uniform cell grid with points sorted by cell (thesis section 3.4.2).

The grid bins points into cubic cells of edge ``cell_size`` (eq. 3.16) and stores
the points sorted by cell key, so that the points of a cell, and of a row of
neighbouring cells, are contiguous in memory.  Only non-empty cells are stored
(sorted keys + start offsets; the "hash table" of eq. 3.17 replaced by a sorted
key array, which needs no collision handling and keeps neighbour rows contiguous).
Its arrays are meant to be passed to numba kernels, see
:mod:`unmesh.spatial` for an example loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from unmesh._threads import serial_if_small
from unmesh._validate import as_points, positive_scalar
from unmesh.errors import InputError
from unmesh.spatial import _kernels as K

__all__ = ["MAX_CELLS_PER_AXIS", "CellGrid", "build_cell_grid", "cell_reach"]

#: Largest number of cells along one axis; a larger extent/cell_size ratio enlarges the cells.
MAX_CELLS_PER_AXIS = 1 << 20

#: Relative safety margin between a search radius and the cell size it needs.
_MARGIN = 1e-6


def cell_reach(radius: float, cell_size: float) -> int:
    """Number of cells ``m`` to search on each side so that every point within
    ``radius`` of a cell is inside its ``(2m+1)^3`` stencil.

    A relative margin of 1e-9 covers round-off in the cell coordinates.

    Example
    -------
    >>> cell_reach(1.0, 1.001), cell_reach(1.0, 0.5005), cell_reach(1.0, 1.0)
    (1, 2, 2)
    """
    return max(1, math.ceil(radius / cell_size * (1.0 + 1e-9)))


def _dim_of(points: object) -> int:
    arr = np.asarray(points)
    if arr.ndim == 2 and arr.shape[1] in (2, 3):
        return int(arr.shape[1])
    if arr.ndim == 1 and arr.shape[0] in (2, 3):
        return int(arr.shape[0])
    if arr.size == 0 and arr.ndim <= 2:
        return 3
    raise InputError(f"points: expected shape (N, 3) or (N, 2), got {arr.shape}")


@dataclass(frozen=True, eq=False, repr=False)
class CellGrid:
    """Points sorted into a uniform grid of cubic cells (eqs. 3.16, 3.17).

    Build it with :func:`build_cell_grid`.  All arrays are C-contiguous and can be
    passed straight to numba kernels together with the helpers of
    :mod:`unmesh.spatial._kernels` (``point_cell``, ``cell_key``, ``find_cell``,
    ``cell_range``, ``stencil_ranges``).

    Attributes
    ----------
    points : ndarray, shape (N, dim), float64
        The points sorted by cell: ``points[a] == original[order[a]]``.
    order : ndarray, shape (N,), int64
        Permutation: sorted position ``a`` holds original point ``order[a]``.
        Within a cell, original indices are ascending.
    rank : ndarray, shape (N,), int64
        Inverse permutation: original point ``i`` is at sorted position ``rank[i]``.
    origin : ndarray, shape (dim,), float64
        Lower corner of the grid (the points' bounding-box minimum).
    upper : ndarray, shape (dim,), float64
        Bounding-box maximum of the points.
    cell_size : float
        Edge length ``d`` of a cell.
    inv_cell : float
        ``1 / cell_size``.
    dims : ndarray, shape (3,), int64
        Virtual grid size ``(n0, n1, n2)``; 2-D grids have ``n0 == 1``.
    cell_keys : ndarray, shape (C,), int64
        Sorted keys ``(i*n1 + j)*n2 + k`` of the non-empty cells.
    cell_start : ndarray, shape (C+1,), int64
        Cell ``c`` holds sorted points ``cell_start[c]:cell_start[c+1]``.
    cell_of : ndarray, shape (N,), int64
        Non-empty-cell index ``c`` of every sorted point.

    Example
    -------
    >>> g = build_cell_grid([[0.0, 0, 0], [0.05, 0, 0], [1, 1, 1]], 0.1)
    >>> g.n_points, g.n_cells, g.dim
    (3, 2, 3)
    """

    points: np.ndarray
    order: np.ndarray
    rank: np.ndarray
    origin: np.ndarray
    upper: np.ndarray
    cell_size: float
    inv_cell: float
    dims: np.ndarray
    cell_keys: np.ndarray
    cell_start: np.ndarray
    cell_of: np.ndarray

    @property
    def dim(self) -> int:
        """Spatial dimension (2 or 3)."""
        return int(self.points.shape[1])

    @property
    def n_points(self) -> int:
        """Number of points N."""
        return int(self.points.shape[0])

    @property
    def n_cells(self) -> int:
        """Number of non-empty cells C."""
        return int(self.cell_keys.shape[0])

    def reach(self, radius: float) -> int:
        """Stencil half-width for searches of ``radius`` (see :func:`cell_reach`)."""
        return cell_reach(float(radius), self.cell_size)

    def stencil_table(self, radius: float | None = None) -> np.ndarray:
        """Neighbour-cell slices of every non-empty cell (for loops over grid points).

        Row ``c`` lists the ``[start, end)`` slices of sorted points covering every
        cell within reach of cell ``c`` (what :func:`_kernels.stencil_ranges` gives);
        the neighbours of sorted point ``a`` within ``radius`` are among the points
        ``table[cell_of[a], s, 0] : table[cell_of[a], s, 1]``.

        Parameters
        ----------
        radius : float, optional
            Search radius (default: the cell size, 9 slices in 3-D, 3 in 2-D).

        Returns
        -------
        ndarray, shape (C, (2*reach+1)**2, 2), int64
            Unused rows are empty (``start == end``).

        Example
        -------
        >>> g = build_cell_grid([[0.0, 0, 0], [0.05, 0, 0], [1, 1, 1]], 0.1)
        >>> t = g.stencil_table()
        >>> t.shape, t[g.cell_of[0], 0].tolist()
        ((2, 9, 2), [0, 2])
        """
        reach = 1 if radius is None else self.reach(positive_scalar(radius, "radius"))
        return K.stencil_table(self.cell_keys, self.cell_start, self.dims, reach)

    def __repr__(self) -> str:
        dims = tuple(int(v) for v in self.dims[3 - self.dim :])
        return f"CellGrid(n_points={self.n_points}, dim={self.dim}, cell_size={self.cell_size:g}, dims={dims}, n_cells={self.n_cells})"


def build_cell_grid(points: object, cell_size: float) -> CellGrid:
    """Sort points into a uniform grid of cubic cells of edge ``cell_size``.

    Construction is O(N) (counting sort) when the grid has at most ``4 N + 4096``
    cells, else O(N log N) (stable argsort of the cell keys).  Cells are enlarged
    when the extent would need more than ``MAX_CELLS_PER_AXIS`` cells along an axis
    (``grid.cell_size`` then exceeds the requested size; searches stay exact).

    Parameters
    ----------
    points : array_like, shape (N, 3) or (N, 2)
        Point positions (finite).
    cell_size : float
        Requested cell edge ``d`` (> 0).  The grid's actual edge is
        ``d * (1 + 1e-6)``, so that a search of radius ``d`` is covered by the
        27-cell (9 in 2-D) stencil despite round-off: ``grid.reach(d) == 1``.  A
        search of radius ``r`` visits ``(2m+1)^3`` cells, ``m = grid.reach(r)``.

    Returns
    -------
    CellGrid

    Example
    -------
    >>> import numpy as np
    >>> g = build_cell_grid(np.random.default_rng(0).random((100, 2)), 0.25)
    >>> g.dims.tolist(), bool(np.all(np.diff(g.cell_start) > 0))
    ([1, 4, 4], True)
    """
    dim = _dim_of(points)
    pts = as_points(points, "points", dim=dim)
    d = positive_scalar(cell_size, "cell_size")
    with serial_if_small(len(pts)):
        return _build(pts, d)


def _build(pts: np.ndarray, d: float) -> CellGrid:
    """Build from validated (N, dim) float64 points and cell size ``d``."""
    n, dim = pts.shape
    d = d * (1.0 + _MARGIN)
    if n == 0:
        lower = np.zeros(dim)
        upper = np.zeros(dim)
    else:
        lower, upper = K.bounds(pts)
    with np.errstate(over="ignore"):
        extent = upper - lower
    if not np.all(np.isfinite(extent)):
        raise InputError("points: the coordinate range overflows float64 (differences of coordinates are infinite)")
    # cells along each axis; enlarge d when the extent needs too many
    need = float(extent.max()) / (MAX_CELLS_PER_AXIS - 1) if n else 0.0
    if need > d:
        d = need * (1.0 + 1e-12)
    inv = 1.0 / d
    if not math.isfinite(inv) or inv <= 0.0:
        raise InputError(f"cell_size: {d} is out of the representable range")
    per_axis = [min(MAX_CELLS_PER_AXIS, math.floor(float(e) * inv) + 1) for e in extent]
    dims = np.array(([1, *per_axis]) if dim == 2 else per_axis, dtype=np.int64)
    if n == 0:
        empty = np.empty(0, np.int64)
        return CellGrid(pts.copy(), empty, empty.copy(), lower, upper, d, inv, dims, empty.copy(), np.zeros(1, np.int64),
                        empty.copy())
    keys = K.compute_keys(pts, lower, inv, dims)
    total = int(dims[0]) * int(dims[1]) * int(dims[2])
    if total <= 4 * n + 4096:
        order = K.counting_sort(keys, total)
    else:
        order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    cell_keys, cell_start = K.compress_cells(sorted_keys)
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n, dtype=np.int64)
    sp = K.gather_rows(pts, order)
    cell_of = K.cell_of_sorted(cell_start, n)
    return CellGrid(sp, order, rank, lower, upper, d, inv, dims, cell_keys, cell_start, cell_of)
