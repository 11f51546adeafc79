"""Mesh builders: hexahedral grids, TetGen tetrahedral meshes, Voronoi foams, convex hulls.

Example
-------
>>> m = hex_grid((3, 3, 3))
>>> m.n_nodes, m.n_elements
(64, 27)
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import warnings
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_indices, as_points, positive_scalar
from unmesh.errors import InputError, MissingDependencyError
from unmesh.fem.mesh import PolyMesh

__all__ = ["convex_polyhedron", "hex_grid", "polymesh_from_faces", "tet_mesh", "tetrahedralize", "voronoi_foam"]


def _triple(value: Any, name: str, integer: bool = False) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.repeat(arr, 3)
    arr = as_array(arr, name, (3,))
    if integer:
        if np.any(arr < 1) or np.any(arr % 1):
            raise InputError(f"{name}: expected three positive integers, got {arr.tolist()}")
        return arr.astype(np.int64)
    if np.any(arr <= 0):
        raise InputError(f"{name}: expected three positive numbers, got {arr.tolist()}")
    return arr


def polymesh_from_faces(points: Any, face_elem: np.ndarray, face_nodes: np.ndarray, face_offsets: np.ndarray,
                        n_elements: int, *, tolerance: float = 1e-6, check: bool = True) -> PolyMesh:
    """Build a mesh from per-element outward faces, merging faces shared by two elements.

    Parameters
    ----------
    points : array_like, shape (n, 3)
    face_elem : (K,) int64
        Element of each (element-local) face.
    face_nodes, face_offsets : int64 CSR
        Node cycle of each element-local face, counter-clockwise from outside.
    n_elements : int

    Returns
    -------
    PolyMesh
        Faces with the same node set are stored once (sign +1 for the first
        element, -1 for the second).

    Example
    -------
    >>> tets = np.array([[0, 1, 2, 3]])
    >>> f = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    >>> polymesh_from_faces([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.zeros(4, np.int64),
    ...                     f.ravel(), np.arange(0, 13, 3), 1).n_faces
    4
    """
    sizes = np.diff(face_offsets)
    width = int(sizes.max())
    pad = np.full((len(sizes), width), -1, dtype=np.int64)
    rows = np.repeat(np.arange(len(sizes)), sizes)
    cols = np.arange(len(face_nodes)) - np.repeat(face_offsets[:-1], sizes)
    pad[rows, cols] = face_nodes
    key = np.sort(np.where(pad < 0, np.iinfo(np.int64).max, pad), axis=1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    # keep global faces in the order of their first appearance
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    gid = rank[inv]
    owner = first[order]
    gsizes = sizes[owner]
    gidx = np.repeat(face_offsets[owner] - np.cumsum(np.r_[0, gsizes[:-1]]), gsizes) + np.arange(gsizes.sum())
    fn = face_nodes[gidx]
    fo = np.r_[0, np.cumsum(gsizes)].astype(np.int64)
    signs = np.where(np.arange(len(sizes)) == owner[gid], 1, -1).astype(np.int64)
    order_e = np.argsort(face_elem, kind="stable")
    ef = gid[order_e]
    es = signs[order_e]
    eo = np.r_[0, np.cumsum(np.bincount(face_elem, minlength=n_elements))].astype(np.int64)
    return PolyMesh.from_arrays(points, fn, fo, ef, es, eo, tolerance=tolerance, check=check)


def hex_grid(shape: Any = (1, 1, 1), size: Any = (1.0, 1.0, 1.0), origin: Any = (0.0, 0.0, 0.0)) -> PolyMesh:
    """A box of ``nx × ny × nz`` hexahedral (cube-like) elements.

    Parameters
    ----------
    shape : int or (3,) ints
        Cells per axis.
    size : float or (3,) floats
        Box extent.
    origin : (3,) floats
        Minimum corner.

    Returns
    -------
    PolyMesh
        Node ``i + (nx+1)(j + (ny+1)k)`` at ``origin + (i, j, k)·size/shape``;
        element ``i + nx(j + ny k)``.

    Example
    -------
    >>> hex_grid((2, 1, 1), size=(2, 1, 1)).n_faces
    11
    """
    nx, ny, nz = _triple(shape, "shape", integer=True).tolist()
    sz = _triple(size, "size")
    org = as_array(origin, "origin", (3,))
    gx, gy, gz = (np.linspace(0, s, n + 1) for s, n in zip(sz, (nx, ny, nz), strict=True))
    X, Y, Z = np.meshgrid(gx, gy, gz, indexing="ij")
    pts = np.stack([X.transpose(2, 1, 0).ravel(), Y.transpose(2, 1, 0).ravel(), Z.transpose(2, 1, 0).ravel()], 1) + org

    def nid(i, j, k):
        return i + (nx + 1) * (j + (ny + 1) * k)

    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    elem = i + nx * (j + ny * k)
    # six faces per cell, outward, counter-clockwise from outside
    faces = [
        np.stack([nid(i, j, k), nid(i, j, k + 1), nid(i, j + 1, k + 1), nid(i, j + 1, k)], 1),  # -x
        np.stack([nid(i + 1, j, k), nid(i + 1, j + 1, k), nid(i + 1, j + 1, k + 1), nid(i + 1, j, k + 1)], 1),  # +x
        np.stack([nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j, k + 1), nid(i, j, k + 1)], 1),  # -y
        np.stack([nid(i, j + 1, k), nid(i, j + 1, k + 1), nid(i + 1, j + 1, k + 1), nid(i + 1, j + 1, k)], 1),  # +y
        np.stack([nid(i, j, k), nid(i, j + 1, k), nid(i + 1, j + 1, k), nid(i + 1, j, k)], 1),  # -z
        np.stack([nid(i, j, k + 1), nid(i + 1, j, k + 1), nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1)], 1),  # +z
    ]
    allf = np.stack(faces, 1).reshape(-1, 4)
    fe = np.repeat(elem, 6)
    return polymesh_from_faces(pts, fe, allf.ravel(), np.arange(0, 4 * len(allf) + 1, 4, dtype=np.int64), nx * ny * nz)


def tet_mesh(points: Any, tets: Any, *, check: bool = True) -> PolyMesh:
    """A PolyMesh of linear tetrahedra (negatively oriented tets are flipped).

    Parameters
    ----------
    points : array_like, shape (n, 3)
    tets : array_like, shape (E, 4) int

    Example
    -------
    >>> tet_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 3, 2]]).volume() > 0
    True
    """
    pts = as_points(points, "points")
    t = as_indices(tets, "tets", (None, 4), upper=len(pts)).copy()
    vol = np.einsum("ij,ij->i", pts[t[:, 1]] - pts[t[:, 0]],
                    np.cross(pts[t[:, 2]] - pts[t[:, 0]], pts[t[:, 3]] - pts[t[:, 0]]))
    neg = vol < 0
    t[neg] = t[neg][:, [0, 2, 1, 3]]
    a, b, c, d = t.T
    faces = np.stack([np.stack([a, c, b], 1), np.stack([a, b, d], 1), np.stack([b, c, d], 1),
                      np.stack([a, d, c], 1)], 1).reshape(-1, 3)
    fe = np.repeat(np.arange(len(t)), 4)
    return polymesh_from_faces(pts, fe, faces.ravel(), np.arange(0, 3 * len(faces) + 1, 3, dtype=np.int64), len(t),
                               check=check)


def tetrahedralize(surface: Any, *, max_volume: float | None = None, quality: float = 2.0,
                   min_dihedral: float = 0.0) -> PolyMesh:
    """Tetrahedral mesh of a closed triangle surface with TetGen (the ``tetgen`` package).

    Parameters
    ----------
    surface : TriangleMesh
        Closed, consistently oriented surface.
    max_volume : float, optional
        Maximum tetrahedron volume (TetGen ``-a``); default: no limit (the surface
        resolution and the quality bound decide).
    quality : float
        Maximum radius-edge ratio (TetGen ``-q``, default 2).
    min_dihedral : float
        Minimum dihedral angle in degrees.

    Returns
    -------
    PolyMesh

    Example
    -------
    >>> from unmesh.meshes import TriangleMesh
    >>> v = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> m = tetrahedralize(TriangleMesh(v, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]), max_volume=0.01)
    >>> round(m.volume(), 9)
    0.166666667
    """
    try:
        import tetgen
    except ImportError as exc:  # pragma: no cover - tetgen is a dependency
        raise MissingDependencyError("tetrahedralize needs the 'tetgen' package: pip install tetgen") from exc
    v = np.asarray(surface.vertices, dtype=np.float64)
    f = np.asarray(surface.faces, dtype=np.int32)
    enclosed = abs(float(surface.volume()))
    if not enclosed > 0:
        raise InputError("surface: encloses no volume (expected a closed triangle mesh)")
    extra: dict[str, Any] = {}
    if max_volume is not None:
        extra = {"fixedvolume": True, "maxvolume": positive_scalar(max_volume, "max_volume")}
    gen = tetgen.TetGen(v, f)
    # TetGen writes the facets it had to skip (self-intersections) to ``_skipped.*`` in the
    # current directory and has no switch to disable that: run it in a private temporary
    # directory and turn those files into a warning instead of litter in the user's directory.
    with tempfile.TemporaryDirectory(prefix="unmesh-tetgen-") as tmp, contextlib.chdir(tmp):
        try:
            nodes, elems = gen.tetrahedralize(order=1, quality=True, minratio=float(quality),
                                              mindihedral=float(min_dihedral), verbose=0, **extra)[:2]
        except RuntimeError as exc:
            raise InputError(f"surface: TetGen failed ({exc}); is the surface closed and free of "
                             "self-intersections?") from None
        skipped = sorted(os.listdir(tmp))
    if skipped:
        warnings.warn(f"surface: TetGen skipped parts of the input surface (it wrote {', '.join(skipped)}); "
                      "the surface probably self-intersects", UserWarning, stacklevel=2)
    return tet_mesh(nodes, elems)


def _polygon_order(pts: np.ndarray, ids: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Order coplanar points counter-clockwise around ``normal``."""
    c = pts[ids].mean(axis=0)
    u = pts[ids[0]] - c
    u -= normal * (u @ normal)
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)
    r = pts[ids] - c
    ang = np.arctan2(r @ w, r @ u)
    return ids[np.argsort(ang, kind="stable")]


def convex_polyhedron(points: Any) -> PolyMesh:
    """One convex element: the convex hull of ``points`` (coplanar hull triangles merged).

    Parameters
    ----------
    points : array_like, shape (P, 3)
        At least 4 points not all coplanar. Points inside the hull are dropped.

    Returns
    -------
    PolyMesh
        A single element whose nodes are the hull vertices (in input order).

    Example
    -------
    >>> cube = [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    >>> poly = convex_polyhedron(cube)
    >>> poly.n_nodes, poly.n_faces
    (8, 6)
    """
    from scipy.spatial import ConvexHull, QhullError

    pts = as_points(points, "points")
    if len(pts) < 4:
        raise InputError(f"points: expected at least 4 points, got {len(pts)}")
    try:
        hull = ConvexHull(pts)
    except QhullError:
        raise InputError("points: the convex hull is flat (all points coplanar)") from None
    used = np.unique(hull.vertices)
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    P = pts[used]
    eq = hull.equations
    scale = np.ptp(P, axis=0).max()
    key = np.round(np.c_[eq[:, :3] * 1e6, eq[:, 3:] / scale * 1e6]).astype(np.int64)
    _, grp = np.unique(key, axis=0, return_inverse=True)
    faces = []
    for g in np.unique(grp):
        ids = np.unique(remap[hull.simplices[grp.ravel() == g]])
        n = eq[grp.ravel() == g][0, :3]
        # keep every hull vertex lying on this face plane (t-junction consistency)
        on = np.flatnonzero(np.abs((P - P[ids[0]]) @ n) <= 1e-9 * scale)
        ids = np.union1d(ids, on)
        faces.append(_polygon_order(P, ids, n / np.linalg.norm(n)).tolist())
    return PolyMesh(P, [faces])


def voronoi_foam(n_cells: int = 30, size: Any = (1.0, 1.0, 1.0), origin: Any = (0.0, 0.0, 0.0),
                 seed: int = 0, points: Any | None = None) -> PolyMesh:
    """An irregular polyhedral "foam": Voronoi cells of random seeds clipped to a box.

    Parameters
    ----------
    n_cells : int
        Number of random seed points (ignored when ``points`` is given).
    size, origin : (3,) floats
        The box.
    seed : int
        Random seed.
    points : array_like, shape (N, 3), optional
        Explicit Voronoi sites inside the box.

    Returns
    -------
    PolyMesh
        One convex element per site; shared faces are exact bisector polygons.

    Example
    -------
    >>> m = voronoi_foam(20, seed=1)
    >>> m.n_elements, round(m.volume(), 9)
    (20, 1.0)
    """
    from scipy.spatial import HalfspaceIntersection

    from unmesh.spatial import KDTree

    sz = _triple(size, "size")
    org = as_array(origin, "origin", (3,))
    if points is None:
        if int(n_cells) < 1:
            raise InputError(f"n_cells: expected a positive integer, got {n_cells}")
        rng = np.random.default_rng(seed)
        sites = org + rng.random((int(n_cells), 3)) * sz
    else:
        sites = as_points(points, "points")
        if np.any(sites < org) or np.any(sites > org + sz):
            raise InputError("points: expected sites inside the box")
    n = len(sites)
    scale = float(np.linalg.norm(sz))
    # half-spaces A x + b <= 0: box faces and bisectors with every other site
    box_A = np.r_[-np.eye(3), np.eye(3)]
    box_b = np.r_[org, -(org + sz)]
    verts: list[np.ndarray] = []
    planes: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for i in range(n):
        others = np.delete(np.arange(n), i)
        A = sites[others] - sites[i]
        b = -(A * (sites[others] + sites[i]) / 2).sum(axis=1)
        A = np.r_[box_A, A]
        b = np.r_[box_b, b]
        hs = HalfspaceIntersection(np.c_[A, b], sites[i])
        verts.append(hs.intersections)
        planes.append((A, b, np.r_[-np.ones(6, np.int64), others]))
    allv = np.concatenate(verts)
    pairs = KDTree(allv).radius_pairs(1e-9 * scale)  # near-duplicate corners, i < j sorted
    parent = np.arange(len(allv))
    for a, b in sorted(map(tuple, pairs)):  # union-find on near-duplicates
        ra, rb = a, b
        while parent[ra] != ra:
            ra = parent[ra]
        while parent[rb] != rb:
            rb = parent[rb]
        parent[max(ra, rb)] = min(ra, rb)
    for k in range(len(parent)):
        r = k
        while parent[r] != r:
            r = parent[r]
        parent[k] = r
    uniq, gidx = np.unique(parent, return_inverse=True)
    P = allv[uniq]
    cells = []
    start = 0
    for i in range(n):
        ids = np.unique(gidx[start:start + len(verts[i])])
        start += len(verts[i])
        A, b, _ = planes[i]
        nrm = np.linalg.norm(A, axis=1)
        dist = (P[ids] @ A.T + b) / nrm
        faces = []
        for p in range(len(A)):
            on = ids[np.abs(dist[:, p]) <= 1e-9 * scale]
            if len(on) >= 3:
                faces.append(_polygon_order(P, on, A[p] / nrm[p]).tolist())
        cells.append(faces)
    return PolyMesh(P, cells)
