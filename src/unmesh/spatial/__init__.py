"""Neighbour search (cell grids, spatial hashing, kd-trees; thesis section 3.4) and triangle queries.

Every meshless method in unmesh needs the points near a point: MLS projection,
SPH sums, surfel normals and radii, shell nodes.  This package answers the two query
types of section 3.4 -- *range* (all points within ``r``) and *nearest neighbour*
(the ``k`` closest) -- exactly: results are identical to a numpy brute force.

Conventions
-----------
- Points and queries are ``(N, 3)`` or ``(N, 2)`` arrays (the same dimension);
  indices are int64 and refer to the original order.
- A point ``x_j`` is within ``r`` of ``q_i`` when ``sum((x_j - q_i)**2) <= r**2``
  (squared distances, summed in axis order, as numpy's ``((x - q)**2).sum(-1)``).
- Neighbour lists are CSR: neighbours of query ``i`` are
  ``indices[offsets[i]:offsets[i+1]]``, ascending.

Public functions
----------------
``radius_neighbors(points, radius, queries=None, method="auto") -> (offsets, indices)``
    CSR of the points within ``radius`` of each query; ``offsets`` (Q+1,) int64,
    ``indices`` int64.  With ``queries=None`` the queries are the points themselves
    and every point is its own neighbour.
``radius_pairs(points, radius, method="auto") -> pairs``
    (P, 2) int64 unique pairs ``i < j`` within ``radius``, sorted lexicographically
    (the analogue of ``cKDTree.query_pairs``).
``knn(points, k, queries=None) -> (distances, indices)``
    (Q, k) float64 / int64, sorted by distance then by index (identical to a
    brute-force stable sort, duplicates included); a point is its own first
    neighbour when ``queries=None`` (unless an exact duplicate has a lower index);
    rows padded with ``inf`` / ``-1`` when ``k > N``.  kd-tree (section 3.4.1).
``KDTree(points)``
    For repeated queries on the same points: ``.knn(queries, k)``,
    ``.radius_neighbors(queries, radius)``, ``.radius_pairs(radius)``, same
    conventions (``queries=None`` = the points).
``choose_method(points, radius, queries=None)``
    What ``method="auto"`` picks: the uniform grid unless the extent needs more than
    2^20 cells of size ``radius`` along an axis, or a 256-query sample shows the grid
    testing > 512 candidates per query at < 1 % hits (extremely non-uniform
    density); then the kd-tree.
``TriangleBVH(vertices, faces)``
    Bounding volume hierarchy over triangles (:mod:`unmesh.spatial.bvh`):
    ``.closest(points) -> (distance, face, point, barycentric)``,
    ``.winding_number(points)`` and ``.contains(points)`` (generalized winding
    number > 1/2), ``.ray_hits(origins, directions, first=True) -> (t, face,
    barycentric)`` (``t = inf`` where missed; ``first=False`` gives every hit in CSR).
``build_cell_grid(points, cell_size) -> CellGrid``
    Static grid for numba kernels, see below.
``HashGrid(cell_size, dim=3)``
    Dynamic spatial hash (eqs. 3.16-3.17) of points with integer ids:
    ``insert(ids, points)``, ``remove(ids)``, ``move(ids, new_points)`` in O(1)
    average each, ``query_radius(queries, radius) -> (offsets, indices)`` (CSR of
    ids, any radius; ``radius <= cell_size / 2`` visits the 8 nearest cells as in
    Figure 3.7 c, ``radius <= cell_size`` the 27 around the query), ``ids``,
    ``positions(ids)``, ``len``, ``in``, ``clear()``.  Results always equal a
    brute force over the current contents.  For point sets rebuilt every step
    (SPH) rebuilding a ``CellGrid`` is faster.

How the radius searches work: the static searches use a sorted-cell layout rather
than the hash table of eq. 3.17 (only non-empty cells are stored, as sorted keys
found by binary search: no collisions, and neighbouring cells are contiguous in
memory).  The points are sorted by cell key (counting sort, O(N)); cell edge = radius, so the 27 cells around a cell (9 in 2-D) hold every
neighbour, and they are 9 (3) contiguous slices of the sorted points (a cell edge
of radius/2 with 125 cells was measured slower).  Self queries (``queries=None``,
``radius_pairs``) visit each pair once (only partners later in the sorted order),
writing chunks of cells in parallel into space estimated from an exact count on a
sample of cells (chunks that run out finish with an exact count + fill pass), then
put the pairs into rows by a counting sort and sort each row (rank sort).  Other
queries are grouped by cell and use a count pass + prefix sum + fill pass.  All
numba-parallel without write races; inputs below 20000 points run on one thread
(thread wake-up would dominate).

Example
-------
>>> import numpy as np
>>> from unmesh.spatial import radius_neighbors, radius_pairs, knn
>>> pts = np.array([[0.0, 0, 0], [0.3, 0, 0], [1, 0, 0], [1, 0.2, 0]])
>>> off, ind = radius_neighbors(pts, 0.5)
>>> [ind[off[i]:off[i + 1]].tolist() for i in range(len(pts))]
[[0, 1], [0, 1], [2, 3], [2, 3]]
>>> radius_pairs(pts, 0.5).tolist()
[[0, 1], [2, 3]]
>>> d, i = knn(pts, 2, queries=[[0.9, 0.0, 0.0]])
>>> i.tolist()
[[2, 3]]

Static cell grid for numba kernels
----------------------------------
``grid = build_cell_grid(points, h)`` sorts the points into cubic cells of edge
``h`` (eq. 3.16; actually ``h*(1+1e-6)`` so that round-off never pushes a point at
distance ``h`` out of the stencil: ``grid.reach(h) == 1``).  Fields (all
C-contiguous, to pass to numba):

- ``grid.points`` (N, dim) float64: the points **sorted by cell**, for memory
  locality; ``grid.order`` (N,) int64: sorted position ``a`` is original point
  ``order[a]`` (within a cell ascending); ``grid.rank`` (N,): the inverse.
  Reorder per-particle arrays once with ``arr[grid.order]`` and work in sorted
  order; go back with ``arr_sorted[grid.rank]``.
- ``grid.origin`` (dim,), ``grid.inv_cell`` (float), ``grid.dims`` (3,) int64: the
  virtual grid ``(n0, n1, n2)`` (``n0 == 1`` in 2-D, where ``x, y`` map to
  ``j, k``); indices are clamped, so queries outside the grid are fine.
- ``grid.cell_keys`` (C,) int64 sorted keys of the non-empty cells,
  ``grid.cell_start`` (C+1,) int64 offsets into the sorted points,
  ``grid.cell_of`` (N,) int64 the cell of every sorted point.
- ``grid.stencil_table(radius=None)`` -> (C, 9, 2) int64 ((C, 3, 2) in 2-D): the
  ``[start, end)`` slices of sorted points covering the 27 (9) cells around every
  cell, computed once per build.  The fastest way to loop over the neighbours of
  the grid's own points (SPH):

>>> from numba import njit, prange
>>> from unmesh.spatial import build_cell_grid
>>> @njit  # in real code: @njit(parallel=True, cache=True)
... def density(x, m, cell_of, table, h):   # x, m in sorted order
...     rho = np.zeros(x.shape[0])
...     for a in prange(x.shape[0]):
...         c = cell_of[a]
...         for s in range(table.shape[1]):
...             for b in range(table[c, s, 0], table[c, s, 1]):
...                 r2 = ((x[a, 0] - x[b, 0]) ** 2 + (x[a, 1] - x[b, 1]) ** 2
...                       + (x[a, 2] - x[b, 2]) ** 2)
...                 if r2 < h * h:
...                     rho[a] += m[b] * (h * h - r2) ** 3   # poly6 up to a constant
...     return rho
>>> x0 = np.random.default_rng(0).random((1000, 3))
>>> g = build_cell_grid(x0, 0.1)
>>> rho = density(g.points, np.ones(1000), g.cell_of, g.stencil_table(), 0.1)[g.rank]
>>> d2 = ((x0 - x0[0]) ** 2).sum(axis=1)
>>> bool(np.isclose(rho[0], ((0.01 - d2[d2 < 0.01]) ** 3).sum()))
True

``@njit`` helpers in ``unmesh.spatial._kernels`` for arbitrary query points (MLS
iterates, ray-marching samples):
``point_cell(p, origin, inv_cell, dims) -> (i, j, k)`` (clamped);
``cell_key(i, j, k, dims)``; ``find_cell(key, cell_keys) -> c`` (-1 if empty);
``cell_range(c, cell_start) -> (start, end)``;
``stencil_ranges(i, j, k, reach, dims, cell_keys, cell_start, out) -> n``, which
writes the slices covering the 27 (9 in 2-D) neighbouring cells into ``out[:n]``
(``out`` needs ``(2*reach+1)**2`` rows):

>>> from unmesh.spatial._kernels import point_cell, stencil_ranges
>>> @njit
... def count_within(q, x, origin, inv_cell, dims, cell_keys, cell_start, h):
...     out = np.zeros(q.shape[0], np.int64)
...     for a in prange(q.shape[0]):
...         ranges = np.empty((9, 2), np.int64)
...         i, j, k = point_cell(q[a], origin, inv_cell, dims)
...         ns = stencil_ranges(i, j, k, 1, dims, cell_keys, cell_start, ranges)
...         for s in range(ns):
...             for b in range(ranges[s, 0], ranges[s, 1]):   # b: sorted index
...                 d2 = 0.0
...                 for t in range(x.shape[1]):
...                     d2 += (q[a, t] - x[b, t]) ** 2
...                 if d2 <= h * h:
...                     out[a] += 1
...     return out
>>> q = np.random.default_rng(1).random((50, 3)) * 2 - 0.5
>>> n = count_within(q, g.points, g.origin, g.inv_cell, g.dims, g.cell_keys, g.cell_start, 0.1)
>>> bool(np.array_equal(n, np.diff(radius_neighbors(x0, 0.1, q)[0])))
True

For a search radius ``r > h`` use ``reach = grid.reach(r)`` and
``(2*reach+1)**2`` rows in ``ranges`` (or ``grid.stencil_table(r)``).

kd-tree vs. grid (section 3.4.3): the grid wins for fixed-radius searches on
roughly uniform data (SPH, surfel neighbourhoods); ``knn`` uses the kd-tree, which
adapts to varying density.
"""

from unmesh.spatial.bvh import TriangleBVH
from unmesh.spatial.cellgrid import CellGrid, build_cell_grid
from unmesh.spatial.hashgrid import HashGrid
from unmesh.spatial.kdtree import KDTree
from unmesh.spatial.neighbors import choose_method, knn, radius_neighbors, radius_pairs

__all__ = ["CellGrid", "HashGrid", "KDTree", "TriangleBVH", "build_cell_grid", "choose_method", "knn", "radius_neighbors",
           "radius_pairs"]
