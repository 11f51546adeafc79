"""Polyhedral meshes: nodes, shared convex polygonal faces, convex elements (ch. 9).

A :class:`PolyMesh` stores its topology in flat arrays:

- ``face_nodes`` / ``face_offsets``: CSR of node cycles, one per *global* face.
  A face shared by two elements is stored once; its node order is
  counter-clockwise seen from outside the element that references it with
  sign ``+1``.
- ``elem_faces`` / ``elem_signs`` / ``elem_offsets``: CSR element -> faces with an
  orientation sign (``+1`` face order is outward, ``-1`` reversed).

Every node lying on the boundary of a face is a vertex of that face (a node in the
middle of an edge, a *t-junction*, appears in every face containing that edge), and
every face is triangulated once (:meth:`PolyMesh.triangles`), so both elements
sharing it see the same triangles: the mean value shape functions (9.8–9.10) are
then conforming.

Example
-------
>>> cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
>>> faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
>>> m = PolyMesh(cube, [faces])
>>> m.n_nodes, m.n_elements, round(m.volume(), 12)
(8, 1, 1.0)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, scalar
from unmesh.errors import InputError
from unmesh.fem import _kernels as K
from unmesh.fem import _meshcheck
from unmesh.fem.cellparse import parse_cells as _parse_cells

__all__ = ["PolyMesh"]

#: Relative tolerance of the ear-clipping corner test (quality 2A/Σ|e|², 0 = collinear).
_EAR_TOL = 1e-9


def _csr_lengths(offsets: np.ndarray) -> np.ndarray:
    return np.diff(offsets)


def _segment_ids(offsets: np.ndarray) -> np.ndarray:
    return np.repeat(np.arange(len(offsets) - 1, dtype=np.int64), np.diff(offsets))


@dataclass(frozen=True, eq=False, repr=False, init=False)
class PolyMesh:
    """A mesh of convex polyhedral elements sharing convex polygonal faces.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Node positions (rest state), float64.
    cells : list of list of list of int
        One entry per element: its faces, each a list of node indices ordered
        counter-clockwise seen from outside the element. Faces shared by two
        elements must list the same nodes (in opposite order).
    tolerance : float, optional
        Relative tolerance of the convexity and planarity checks (a distance
        divided by the element's bounding-box diagonal). Default 1e-6.
    abs_tolerance : float, optional
        Absolute distance also accepted by those checks (default 0; cuts set it
        to twice their snapping distance).
    check : bool, optional
        Validate closedness, orientation, convexity (default True).
    node_scale : array_like, shape (n,), optional
        Length scale of every node for the snapping of cuts (9.3.1): by default the
        longest edge at the node. Cuts carry it over (interpolated to new nodes) so a
        node's snapping distance never changes while the mesh is cut repeatedly.

    Raises
    ------
    InputError
        Naming the element (and face) that is open, inverted, non-convex, or
        inconsistently oriented.

    Example
    -------
    >>> tet = PolyMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
    ...                [[[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]])
    >>> round(tet.volume() * 6, 12)
    1.0
    """

    points: np.ndarray
    face_nodes: np.ndarray
    face_offsets: np.ndarray
    elem_faces: np.ndarray
    elem_signs: np.ndarray
    elem_offsets: np.ndarray
    tolerance: float
    abs_tolerance: float
    node_scale: np.ndarray | None

    def __init__(self, points: Any, cells: Any, *, tolerance: float = 1e-6, abs_tolerance: float = 0.0,
                 check: bool = True, node_scale: Any | None = None) -> None:
        pts = as_points(points, "points")
        fn, fo, ef, es, eo = _parse_cells(cells, len(pts))
        self._set(pts, fn, fo, ef, es, eo, tolerance, abs_tolerance, check, node_scale)

    @classmethod
    def from_arrays(cls, points: Any, face_nodes: Any, face_offsets: Any, elem_faces: Any, elem_signs: Any,
                    elem_offsets: Any, *, tolerance: float = 1e-6, abs_tolerance: float = 0.0,
                    check: bool = True, node_scale: Any | None = None) -> PolyMesh:
        """Build from the flat CSR arrays (see the module docstring).

        Example
        -------
        >>> m = PolyMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
        ...     [0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2], [0, 3, 6, 9, 12], [0, 1, 2, 3], [1, 1, 1, 1], [0, 4])
        >>> m.n_faces
        4
        """
        obj = cls.__new__(cls)
        pts = as_points(points, "points")
        fn = as_array(face_nodes, "face_nodes", (None,), np.int64)
        fo = as_array(face_offsets, "face_offsets", (None,), np.int64)
        ef = as_array(elem_faces, "elem_faces", (None,), np.int64)
        es = as_array(elem_signs, "elem_signs", (None,), np.int64)
        eo = as_array(elem_offsets, "elem_offsets", (None,), np.int64)
        obj._set(pts, fn, fo, ef, es, eo, tolerance, abs_tolerance, check, node_scale)
        return obj

    def _set(self, pts, fn, fo, ef, es, eo, tolerance, abs_tolerance, check, node_scale=None) -> None:
        tol = scalar(tolerance, "tolerance", minimum=0.0)
        atol = scalar(abs_tolerance, "abs_tolerance", minimum=0.0)
        if node_scale is not None:
            node_scale = as_array(node_scale, "node_scale", (len(pts),))
            if np.any(~(node_scale >= 0)):
                raise InputError("node_scale: expected non-negative lengths")
        for name, value in (("points", pts), ("face_nodes", fn), ("face_offsets", fo), ("elem_faces", ef),
                            ("elem_signs", es), ("elem_offsets", eo), ("tolerance", tol), ("abs_tolerance", atol),
                            ("node_scale", node_scale)):
            object.__setattr__(self, name, value)
        _meshcheck.check_structure(self)
        if check:
            _meshcheck.check_geometry(self)

    def __repr__(self) -> str:
        return f"PolyMesh({self.n_nodes} nodes, {self.n_elements} elements, {self.n_faces} faces)"

    # -- sizes ------------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return int(self.points.shape[0])

    @property
    def n_elements(self) -> int:
        """Number of elements."""
        return int(self.elem_offsets.shape[0] - 1)

    @property
    def n_faces(self) -> int:
        """Number of global (shared) faces."""
        return int(self.face_offsets.shape[0] - 1)

    # -- list-of-lists view -------------------------------------------------------------
    @property
    def cells(self) -> list[list[list[int]]]:
        """Elements as lists of outward-oriented faces (lists of node indices).

        Example
        -------
        >>> PolyMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
        ...          [[[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]]).cells[0][0]
        [0, 2, 1]
        """
        fn = self.face_nodes.tolist()
        fo = self.face_offsets.tolist()
        out = []
        for e in range(self.n_elements):
            faces = []
            for k in range(self.elem_offsets[e], self.elem_offsets[e + 1]):
                f = int(self.elem_faces[k])
                cyc = fn[fo[f]:fo[f + 1]]
                faces.append(cyc if self.elem_signs[k] > 0 else [cyc[0], *cyc[:0:-1]])
            out.append(faces)
        return out

    # -- derived topology ------------------------------------------------------------------
    @cached_property
    def _elem_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        if self.n_elements:
            return K.element_node_sets(self.elem_offsets, self.elem_faces, self.face_offsets, self.face_nodes,
                                       self.n_nodes)
        return self._elem_nodes_reference()

    def _elem_nodes_reference(self) -> tuple[np.ndarray, np.ndarray]:
        """Numpy reference of :meth:`element_nodes` (one global unique)."""
        eid = _segment_ids(self.elem_offsets)
        lens = _csr_lengths(self.face_offsets)[self.elem_faces]
        rows = np.repeat(eid, lens)
        starts = self.face_offsets[self.elem_faces]
        idx = np.repeat(starts - np.cumsum(np.r_[0, lens[:-1]]), lens) + np.arange(lens.sum())
        nodes = self.face_nodes[idx]
        key = np.unique(rows * np.int64(self.n_nodes + 1) + nodes)
        e = key // (self.n_nodes + 1)
        offsets = np.searchsorted(e, np.arange(self.n_elements + 1)).astype(np.int64)
        return offsets, (key % (self.n_nodes + 1)).astype(np.int64)

    def element_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR ``(offsets (E+1,), nodes)`` of each element's nodes, sorted ascending.

        Example
        -------
        >>> from unmesh.fem import hex_grid
        >>> off, nodes = hex_grid((1, 1, 1)).element_nodes()
        >>> nodes[off[0]:off[1]].tolist()
        [0, 1, 2, 3, 4, 5, 6, 7]
        """
        return self._elem_nodes

    @cached_property
    def _triangles(self) -> tuple[np.ndarray, np.ndarray]:
        tris = K.triangulate_faces(self.points, self.face_nodes, self.face_offsets, _EAR_TOL)
        offsets = self.face_offsets - 2 * np.arange(self.n_faces + 1, dtype=np.int64)
        return offsets, tris

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """The one triangulation of every face: ``(offsets (F+1,), tris (T,3))``.

        Face ``f`` owns rows ``offsets[f]:offsets[f+1]``, oriented like the face.
        Convex faces with collinear (t-junction) vertices get no zero-area
        triangles.
        """
        return self._triangles

    @cached_property
    def _elem_tris(self) -> tuple[np.ndarray, np.ndarray]:
        return self.triangles_of(np.arange(self.n_elements, dtype=np.int64))

    def triangles_of(self, elements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """CSR ``(offsets (k+1,), tris (T,3))`` of the outward triangles of ``elements`` (k,) int64, global node ids.

        A kernel over the listed elements only (the re-integration after a cut needs a few hundred).

        Example
        -------
        >>> from unmesh.fem import hex_grid
        >>> hex_grid((2, 1, 1)).triangles_of(np.array([1]))[0].tolist()
        [0, 12]
        """
        toff, tris = self._triangles
        return K.element_triangles(self.elem_offsets, self.elem_faces, self.elem_signs, toff, tris,
                                   np.ascontiguousarray(elements, dtype=np.int64))

    def _elem_tris_reference(self) -> tuple[np.ndarray, np.ndarray]:
        """Numpy reference of :meth:`element_triangles`."""
        toff, tris = self._triangles
        ntri = np.diff(toff)[self.elem_faces]
        rows = np.repeat(np.arange(len(self.elem_faces)), ntri)
        idx = np.repeat(toff[self.elem_faces] - np.cumsum(np.r_[0, ntri[:-1]]), ntri) + np.arange(ntri.sum())
        t = tris[idx].copy()
        flip = self.elem_signs[rows] < 0
        t[flip] = t[flip][:, ::-1]
        per_elem = np.add.reduceat(ntri, self.elem_offsets[:-1]) if len(ntri) else np.zeros(0, np.int64)
        per_elem = np.where(np.diff(self.elem_offsets) > 0, per_elem, 0)
        return np.r_[0, np.cumsum(per_elem)].astype(np.int64), np.ascontiguousarray(t)

    def element_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR ``(offsets (E+1,), tris (T,3))`` of each element's outward triangles (global node ids)."""
        return self._elem_tris

    # -- geometry -------------------------------------------------------------------------
    def element_centers(self) -> np.ndarray:
        """Vertex average of each element (E,3): the centroid ``c`` of (9.17)–(9.18)."""
        off, nodes = self._elem_nodes
        sums = np.add.reduceat(self.points[nodes], off[:-1], axis=0)
        return sums / np.diff(off)[:, None]

    def volumes(self, points: Any | None = None) -> np.ndarray:
        """Signed volume of every element (E,) by the divergence theorem over its triangles.

        Parameters
        ----------
        points : array_like, shape (n, 3), optional
            Evaluate on these positions instead of the rest positions (deformed volume).
        """
        pts = self.points if points is None else as_points(points, "points", length=self.n_nodes)
        off, tris = self._elem_tris
        c = self.element_centers() if points is None else _centers(pts, *self._elem_nodes)
        vols = K.element_tri_volumes(pts, off, tris, c)
        return np.add.reduceat(vols, off[:-1]) * (np.diff(off) > 0)

    def volume(self, points: Any | None = None) -> float:
        """Total volume (float): sum of :meth:`volumes`.

        Example
        -------
        >>> from unmesh.fem import hex_grid
        >>> round(hex_grid((2, 2, 2), size=(2.0, 1.0, 1.0)).volume(), 12)
        2.0
        """
        return float(self.volumes(points).sum())

    def diameters(self) -> np.ndarray:
        """Bounding-box diagonal of every element (E,)."""
        lo, hi = self.element_bounds()
        return np.linalg.norm(hi - lo, axis=1)

    def element_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding box ``(lo (E,3), hi (E,3))`` of every element's nodes."""
        return K.element_bounds(self.points, *self._elem_nodes)

    def face_use(self) -> np.ndarray:
        """Number of elements using each face (F,): 1 on the boundary, 2 inside."""
        return np.bincount(self.elem_faces, minlength=self.n_faces)

    def face_elements(self) -> np.ndarray:
        """(F,2) int64: element using each face with sign +1 and with sign -1 (-1 if none)."""
        out = np.full((self.n_faces, 2), -1, dtype=np.int64)
        eid = _segment_ids(self.elem_offsets)
        out[self.elem_faces, (self.elem_signs < 0).astype(np.int64)] = eid
        return out

    def boundary_triangles(self, return_elements: bool = False) -> Any:
        """Outward triangles (B,3) of the faces used by exactly one element.

        With ``return_elements``, also the element of each triangle (B,).
        """
        toff, tris = self._triangles
        fe = self.face_elements()
        bnd = np.flatnonzero(self.face_use() == 1)
        ntri = np.diff(toff)[bnd]
        idx = np.repeat(toff[bnd] - (np.cumsum(ntri) - ntri), ntri) + np.arange(ntri.sum())
        t = tris[idx].copy()
        flip = np.repeat(fe[bnd, 0] < 0, ntri)
        t[flip] = t[flip][:, ::-1]
        if return_elements:
            return t, np.repeat(np.where(fe[bnd, 0] >= 0, fe[bnd, 0], fe[bnd, 1]), ntri)
        return t

    def edges(self) -> np.ndarray:
        """Unique undirected face edges (M,2) int64, each sorted."""
        nxt = np.arange(len(self.face_nodes)) + 1
        ends = self.face_offsets[1:] - 1
        nxt[ends] = self.face_offsets[:-1]
        e = np.sort(np.stack([self.face_nodes, self.face_nodes[nxt]], axis=1), axis=1)
        return np.unique(e, axis=0)

    @cached_property
    def _edge_stats(self) -> tuple[float, float]:
        e = self.edges()
        if len(e) == 0:
            return 0.0, 0.0
        ln = np.linalg.norm(self.points[e[:, 0]] - self.points[e[:, 1]], axis=1)
        return float(np.median(ln)), float(ln.max())

    @cached_property
    def _node_scales(self) -> np.ndarray:
        if self.node_scale is not None:
            return self.node_scale
        e = self.edges()
        ln = np.linalg.norm(self.points[e[:, 0]] - self.points[e[:, 1]], axis=1)
        out = np.zeros(self.n_nodes)
        np.maximum.at(out, e[:, 0], ln)
        np.maximum.at(out, e[:, 1], ln)
        return out

    def node_scales(self) -> np.ndarray:
        """Snapping length scale of every node (n,): ``node_scale`` if given, else its longest edge.

        Example
        -------
        >>> from unmesh.fem import hex_grid
        >>> hex_grid((2, 1, 1), size=(2, 1, 1)).node_scales()[:3].tolist()
        [1.0, 1.0, 1.0]
        """
        return self._node_scales

    def median_edge_length(self) -> float:
        """Median length of the face edges (cached)."""
        return self._edge_stats[0]

    def max_edge_length(self) -> float:
        """Longest face edge (cached)."""
        return self._edge_stats[1]

    def surface(self, displacement: Any | None = None) -> Any:
        """The boundary as a :class:`unmesh.meshes.TriangleMesh` (unused nodes dropped).

        Parameters
        ----------
        displacement : array_like, shape (n, 3), optional
            Added to the rest positions (deformed surface).

        Returns
        -------
        TriangleMesh
            With a per-vertex attribute ``node`` (int64): the mesh node index.
        """
        from unmesh.meshes import TriangleMesh

        pts = self.points if displacement is None else self.points + as_points(displacement, "displacement",
                                                                               length=self.n_nodes)
        tris = self.boundary_triangles()
        used, inv = np.unique(tris, return_inverse=True)
        return TriangleMesh(pts[used], inv.reshape(-1, 3), attributes={"node": used})

    def replace_points(self, points: Any, *, check: bool = False) -> PolyMesh:
        """Same topology on new rest positions (validated when ``check``)."""
        return PolyMesh.from_arrays(points, self.face_nodes, self.face_offsets, self.elem_faces, self.elem_signs,
                                    self.elem_offsets, tolerance=self.tolerance, abs_tolerance=self.abs_tolerance,
                                    check=check, node_scale=self.node_scale)

    def check(self, tolerance: float | None = None, elements: Any | None = None) -> None:
        """Run the full validation again (raises :class:`InputError` naming the element).

        Parameters
        ----------
        tolerance : float, optional
            Relative convexity tolerance (default: the mesh's).
        elements : int array, optional
            Check only these elements (e.g. the ones an edit changed); their numbers
            are reported as in this mesh.
        """
        target = self if elements is None else self._subset(np.asarray(elements, dtype=np.int64))
        try:
            _meshcheck.check_geometry(target, tolerance)
        except InputError as exc:
            if elements is None:
                raise
            import re

            msg = re.sub(r"element (\d+)", lambda m: f"element {int(np.asarray(elements)[int(m.group(1))])}", str(exc), count=1)
            raise InputError(msg) from None

    def _subset(self, elements: np.ndarray) -> PolyMesh:
        """Same points and faces, only ``elements`` (not validated; for partial checks)."""
        sizes = np.diff(self.elem_offsets)[elements]
        idx = np.repeat(self.elem_offsets[elements] - (np.cumsum(sizes) - sizes), sizes) + np.arange(sizes.sum())
        obj = PolyMesh.__new__(PolyMesh)
        for name, value in (("points", self.points), ("face_nodes", self.face_nodes),
                            ("face_offsets", self.face_offsets), ("elem_faces", self.elem_faces[idx]),
                            ("elem_signs", self.elem_signs[idx]), ("elem_offsets", np.r_[0, np.cumsum(sizes)]),
                            ("tolerance", self.tolerance), ("abs_tolerance", self.abs_tolerance),
                            ("node_scale", self.node_scale)):
            object.__setattr__(obj, name, value)
        obj.__dict__["_triangles"] = self._triangles  # same points and faces (triangulated once per mesh)
        return obj

    def element_is_tet(self) -> np.ndarray:
        """True for elements with four nodes (E,) bool."""
        return np.diff(self._elem_nodes[0]) == 4


def _centers(points: np.ndarray, off: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    return np.add.reduceat(points[nodes], off[:-1], axis=0) / np.diff(off)[:, None]
