"""Surface reconstruction of a surfel cloud for conversion (thesis 6.1, "an implicit function
as intermediate representation").

The MLS surface of :mod:`unmesh.mls` is turned into a triangle mesh:

1. a regular grid of cell edge ``h = grid_factor * median radius`` covers the cloud; its
   *narrow band* (nodes within about ``max(h, 2 r)`` of a surfel centre, counted in cells) is evaluated with the implicit
   function ``f(x) = n(x) . (x - a(x))`` of the MLS fit (``a``, ``n``: the kernel-weighted
   mean position and normal, eqs. 3.6 and 3.8, via :func:`unmesh.mls.interpolate`);
2. every connected region of nodes outside the band takes the majority sign of the band
   nodes next to it (the interior of a closed cloud is inside, pockets such as nostrils
   stay outside), so closed clouds give closed meshes;
3. :func:`unmesh.meshes.marching_cubes` extracts ``f = 0``;
4. faces whose centroid is farther than ``h`` from every surfel disc are cut: open clouds (scans with
   holes) keep their boundaries instead of growing caps;
5. the vertices are projected onto the MLS surface (:func:`unmesh.mls.project`, degree 2),
   which removes the grid's and the plane fit's bias.

Example
-------
>>> import numpy as np
>>> from unmesh.surfels import SurfelCloud
>>> rng = np.random.default_rng(1)
>>> n = rng.normal(size=(3000, 3)); n /= np.linalg.norm(n, axis=1, keepdims=True)
>>> mesh = reconstruct(SurfelCloud(n, n, radii=np.full(3000, 0.06)))
>>> len(mesh.boundary_edges()), bool(abs(np.linalg.norm(mesh.vertices, axis=1) - 1).max() < 5e-3)
(0, True)
"""

from __future__ import annotations

import numpy as np

from unmesh.errors import InputError, MissingDependencyError
from unmesh.meshes import TriangleMesh
from unmesh.meshes.marching import marching_cubes
from unmesh.mls import MLSSurface, interpolate, project
from unmesh.spatial import knn
from unmesh.surfels import SurfelCloud

__all__ = ["MAX_GRID_NODES", "MIN_POINTS", "clean_mesh", "disc_distance", "reconstruct", "reconstruct_poisson"]

#: Fewest surfels a conversion accepts.
MIN_POINTS = 20
#: Largest number of grid nodes (the cell edge grows beyond ``grid_factor`` radii to stay below).
MAX_GRID_NODES = 1 << 24


def reconstruct(cloud: SurfelCloud, grid_factor: float = 2.0, surface: MLSSurface | None = None) -> TriangleMesh:
    """Triangle mesh of the MLS surface of ``cloud`` (marching cubes on a narrow band).

    Parameters
    ----------
    cloud : SurfelCloud
        At least :data:`MIN_POINTS` surfels with oriented normals.
    grid_factor : float
        Cell edge in units of the median surfel radius.
    surface : MLSSurface, optional
        A prepared MLS surface of ``cloud`` (default options otherwise).

    Returns
    -------
    TriangleMesh
        Outward faces; closed for closed clouds, with boundaries where the cloud has holes.

    Raises
    ------
    unmesh.errors.InputError
        Too few surfels, or no surface found.
    """
    from scipy import ndimage

    if len(cloud) < MIN_POINTS:
        raise InputError(f"cloud: expected at least {MIN_POINTS} surfels, got {len(cloud)}")
    surf = surface if surface is not None else MLSSurface(cloud)
    pos = cloud.positions
    radii = np.asarray(cloud.radii)
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    h = float(grid_factor * np.median(radii))
    pad = 3
    dims = np.ceil((hi - lo) / h).astype(np.int64) + 1 + 2 * pad
    if np.prod(dims.astype(np.float64)) > MAX_GRID_NODES:
        h *= float((np.prod(dims.astype(np.float64)) / MAX_GRID_NODES) ** (1 / 3)) * 1.01
        dims = np.ceil((hi - lo) / h).astype(np.int64) + 1 + 2 * pad
    origin = lo - pad * h
    # narrow band: nodes within two cells of a surfel centre
    cell = np.floor((pos - origin) / h).astype(np.int64)
    cube = np.ones((3, 3, 3), bool)
    near = np.zeros(tuple(dims), dtype=bool)  # cells within about max(h, 2 r) of a surfel centre
    reach = np.maximum(np.ceil(2.0 * radii / h).astype(np.int64), 1)
    for k in np.unique(reach):
        mark = np.zeros(tuple(dims), dtype=bool)
        sel = reach == k
        mark[cell[sel, 0], cell[sel, 1], cell[sel, 2]] = True
        near |= ndimage.binary_dilation(mark, structure=cube, iterations=int(min(k, 64)))
    band = near.copy()
    # (cell corners: the dilated cells' lower corners; add the +1 corners)
    band[1:, :, :] |= band[:-1, :, :]
    band[:, 1:, :] |= band[:, :-1, :]
    band[:, :, 1:] |= band[:, :, :-1]
    idx = np.argwhere(band)
    nodes = origin + h * idx
    data = interpolate(surf, nodes, np.concatenate([pos, cloud.normals], axis=1))
    nrm = data[:, 3:]
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    fval = np.einsum("ij,ij->i", nodes - data[:, :3], nrm)
    values = np.zeros(tuple(dims))
    values[idx[:, 0], idx[:, 1], idx[:, 2]] = fval
    # every region outside the band takes the majority sign of the band nodes next to it
    labels, count = ndimage.label(~band)
    rim = band & ndimage.binary_dilation(~band, structure=cube)
    neighbour = ndimage.maximum_filter(labels, size=3)[rim]
    votes = np.bincount(neighbour, weights=np.sign(values[rim]), minlength=count + 1)
    side = np.where(votes >= 0, 3 * h, -3 * h)
    side[0] = 0.0
    values = np.where(band, values, side[labels])
    mesh = marching_cubes(values, origin, h, 0.0)
    if len(mesh.faces) == 0:
        raise InputError("cloud: no surface found (the implicit function does not change sign)")
    # cut faces far from the surfels (no caps over holes, no spurious sheets of the implicit
    # function away from the samples)
    v = mesh.vertices
    keep = disc_distance(v[mesh.faces].mean(axis=1), cloud) <= h
    mesh = clean_mesh(TriangleMesh(v, mesh.faces[keep]))
    if len(mesh.faces) == 0:
        raise InputError("cloud: no surface found near the surfels")
    proj, _ = project(surf, mesh.vertices, max_iter=8, tol=1e-4)
    ok = np.isfinite(proj).all(axis=1) & (np.linalg.norm(proj - mesh.vertices, axis=1) < 2 * h)
    verts = np.where(ok[:, None], proj, mesh.vertices)
    return clean_mesh(TriangleMesh(verts, mesh.faces))

def disc_distance(points: np.ndarray, cloud: SurfelCloud, k: int = 4) -> np.ndarray:
    """Distance (Q,) from points to the nearest of their ``k`` nearest surfel discs.

    The disc of surfel j is the circle of radius r_j around x_j in its tangent plane; the
    distance to it is ``sqrt(max(0, |t| - r_j)^2 + (n_j . d)^2)`` with ``d = p - x_j`` and
    ``t`` its tangential part.

    Example
    -------
    >>> c = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0])
    >>> disc_distance(np.array([[0.5, 0, 0.2], [3.0, 0, 0]]), c, k=1).round(6).tolist()
    [0.2, 2.0]
    """
    k = min(k, len(cloud))
    _, idx = knn(cloud.positions, k, queries=points)
    d = points[:, None, :] - cloud.positions[idx]
    nrm = cloud.normals[idx]
    dn = np.einsum("qkj,qkj->qk", d, nrm)
    tang = np.linalg.norm(d - dn[..., None] * nrm, axis=2)
    r = np.asarray(cloud.radii)[idx]
    return np.sqrt(np.maximum(tang - r, 0.0) ** 2 + dn**2).min(axis=1)


def clean_mesh(mesh: TriangleMesh, min_component: int = 8) -> TriangleMesh:
    """Drop degenerate faces, components of fewer than ``min_component`` faces and unused vertices.

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], [[0, 1, 2], [0, 0, 1]])
    >>> clean_mesh(m, min_component=1)
    TriangleMesh(3 vertices, 1 faces)
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = mesh.faces
    good = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    good &= mesh.face_areas() > 0
    f = f[good]
    nv = len(mesh.vertices)
    if len(f) and min_component > 1:
        rows = np.concatenate([f[:, 0], f[:, 1]])
        cols = np.concatenate([f[:, 1], f[:, 2]])
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nv, nv))
        _, lab = connected_components(graph, directed=False)
        sizes = np.bincount(lab[f[:, 0]], minlength=lab.max() + 1)
        f = f[sizes[lab[f[:, 0]]] >= min_component]
    used = np.unique(f)
    remap = np.full(nv, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return TriangleMesh(mesh.vertices[used], remap[f])


def reconstruct_poisson(cloud: SurfelCloud, depth: int = 9) -> TriangleMesh:
    """Screened Poisson reconstruction (Kazhdan and Hoppe 2013) through Open3D, where installed.

    Low-density vertices (the caps Poisson grows over holes) are removed like in the MLS
    backend: faces farther than two radii from every surfel are cut.

    Raises
    ------
    unmesh.errors.MissingDependencyError
        Without the ``open3d`` package.
    """
    try:
        import open3d as o3d  # type: ignore[import-not-found]
    except ImportError:
        raise MissingDependencyError("backend='poisson': needs the open3d package (pip install open3d)") from None
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.positions))
    pcd.normals = o3d.utility.Vector3dVector(cloud.normals)
    m, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)
    mesh = TriangleMesh(np.asarray(m.vertices), np.asarray(m.triangles, dtype=np.int64))
    radii = np.asarray(cloud.radii)
    dist, near = knn(cloud.positions, 1, queries=mesh.vertices[mesh.faces].mean(axis=1))
    keep = dist[:, 0] <= 2.0 * radii[near[:, 0]] + 1e-12
    return clean_mesh(TriangleMesh(mesh.vertices, mesh.faces[keep]))
