"""Normal estimation for raw point clouds (PCA + consistent orientation).

Normals are the eigenvector of the smallest eigenvalue of the covariance of each
point's ``k`` nearest neighbours (the least-squares plane, as in the MLS plane fit
of eq. 3.5 with constant weights). PCA gives no sign; the signs are made
consistent as in Hoppe et al. (1992), "Surface reconstruction from unorganized
points": build the symmetric nearest-neighbour graph (the 10 nearest of each
point), weight each edge ``1 - |n_i . n_j|`` (small where the tangent planes
agree; quantised to 16 bits for a linear-time sort), take its minimum spanning
tree (Kruskal) and flip normals while traversing it from a seed so that each agrees
with its parent (``n_i . n_p > 0``; across sharp edges, where the normals are nearly
perpendicular, each point must lie on the same side of the other's tangent plane). Each connected component is finally flipped as a whole so that
``sum_i n_i . (x_i - c) > 0`` (c = component centroid): by the divergence theorem
this sum approximates 3 x the enclosed volume for a closed surface, so closed
surfaces end up pointing outward. Flat open sheets (where the sum vanishes) point
towards the positive side of their dominant normal axis.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_points
from unmesh.errors import InputError

#: Below this |n_i . n_j| orientation is propagated by the tangent-plane side test (sharp edges).
SHARP_DOT = 0.3
#: Nearest neighbours (besides the point) that form the orientation graph.
GRAPH_K = 10

__all__ = [
    "covariance_reference",
    "estimate_normals",
    "orient_normals",
    "orient_reference",
    "pca_normals",
    "propagate_reference",
]

#: Largest coordinate magnitude whose squared neighbour distances and covariances
#: stay finite in float64 (issue 24: a point at 1e200 overflowed them).
_MAX_COORDINATE = 1e150


def _bounded(pts: np.ndarray) -> np.ndarray:
    if pts.size and np.abs(pts).max() > _MAX_COORDINATE:
        row = int(np.flatnonzero((np.abs(pts) > _MAX_COORDINATE).any(axis=1))[0])
        raise InputError(f"points: expected coordinates of magnitude <= {_MAX_COORDINATE:g} (squared distances "
                         f"overflow beyond), got {pts[row].tolist()} at row {row}")
    return pts


def _check_k(k: Any, n: int) -> int:
    kk = int(k)
    if kk != k or kk < 3:
        raise InputError(f"k: expected an integer >= 3, got {k!r}")
    return min(kk, n)


def pca_normals(points: Any, k: int = 16) -> np.ndarray:
    """Unoriented unit normals (N,3): smallest-eigenvalue eigenvector of the k-neighbour covariance.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> pts = np.c_[rng.random((200, 2)), np.zeros(200)]
    >>> bool(np.allclose(np.abs(pca_normals(pts)[:, 2]), 1.0))
    True
    """
    from unmesh.spatial import knn

    pts = _bounded(as_points(points, "points"))
    if len(pts) < 3:
        raise InputError(f"points: expected at least 3 points to fit planes, got {len(pts)}")
    kk = _check_k(k, len(pts))
    return _pca(pts, knn(pts, kk)[1])


def _pca(pts: np.ndarray, idx: np.ndarray) -> np.ndarray:
    from unmesh._linalg_kernels import smallest_eigenvectors
    from unmesh.surfels._normals_kernels import neighbour_covariances

    return smallest_eigenvectors(neighbour_covariances(pts, idx))


def orient_normals(points: Any, normals: Any, k: int = 16) -> np.ndarray:
    """Consistently oriented copy (N,3) of unit ``normals`` (MST propagation, module docstring).

    Example
    -------
    >>> rng = np.random.default_rng(1)
    >>> p = rng.normal(size=(500, 3)); p /= np.linalg.norm(p, axis=1, keepdims=True)
    >>> flipped = p * rng.choice([-1.0, 1.0], size=(500, 1))
    >>> bool(np.all(np.einsum("ij,ij->i", orient_normals(p, flipped), p) > 0))
    True
    """
    from unmesh.spatial import knn

    pts = _bounded(as_points(points, "points"))
    nrm = as_points(normals, "normals", length=len(pts)).copy()
    n = len(pts)
    if n == 0:
        return nrm
    lengths = np.linalg.norm(nrm, axis=1, keepdims=True)
    if not np.all(lengths > 1e-12):
        raise InputError("normals: expected non-zero vectors")
    nrm /= lengths
    kk = _check_k(k, n) if n >= 3 else n
    return _orient(pts, nrm, knn(pts, kk)[1])


def _orient(pts: np.ndarray, nrm: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Orient unit normals ``nrm`` in place along the MST of the neighbour graph ``idx``."""
    from unmesh.surfels._normals_kernels import forest_bfs, kruskal_forest, propagate_orientation

    n = len(pts)
    kg = min(idx.shape[1], GRAPH_K + 1)
    rows = np.repeat(np.arange(n), kg)
    cols = idx[:, :kg].ravel()
    ok = (cols >= 0) & (cols != rows)
    a, b = rows[ok], cols[ok]
    # The directed k-NN graph: (i, j) and (j, i) may both appear; Kruskal skips the second.
    # Weights 1 - |n_i . n_j| quantised to 16 bits: a stable radix sort, deterministic ties.
    w = 1.0 - np.abs(np.einsum("ij,ij->i", nrm[a], nrm[b]))
    key = np.round(np.clip(w, 0.0, 1.0) * 65535.0).astype(np.uint16)
    ta, tb = kruskal_forest(n, a, b, np.argsort(key, kind="stable"))
    # First pass: the components; each is then entered at its point farthest from its centroid.
    _, _, comp = forest_bfs(n, ta, tb, np.arange(n))
    ncomp = int(comp.max()) + 1
    counts = np.bincount(comp, minlength=ncomp).astype(np.float64)
    centroid = np.stack([np.bincount(comp, weights=pts[:, k], minlength=ncomp) for k in range(3)], 1) / counts[:, None]
    far = np.linalg.norm(pts - centroid[comp], axis=1)
    seeds = np.lexsort((np.arange(n), -far))  # farthest first
    order, parent, comp = forest_bfs(n, ta, tb, seeds.astype(np.int64))
    propagate_orientation(pts, nrm, order, parent, SHARP_DOT)
    rel = pts - centroid[comp]
    score = np.bincount(comp, weights=np.einsum("ij,ij->i", nrm, rel), minlength=ncomp)
    scale = np.bincount(comp, weights=np.linalg.norm(rel, axis=1), minlength=ncomp)
    flip = score < 0
    flat = np.abs(score) <= 1e-3 * np.where(scale > 0, scale, 1.0)
    if flat.any():  # flat sheets: point towards the dominant axis' positive side
        mean = np.stack([np.bincount(comp, weights=nrm[:, k], minlength=ncomp) for k in range(3)], 1)
        dominant = mean[np.arange(ncomp), np.argmax(np.abs(mean), axis=1)]
        flip = np.where(flat, dominant < 0, flip)
    nrm[flip[comp]] *= -1.0
    return nrm


def estimate_normals(points: Any, k: int = 16) -> np.ndarray:
    """Unit normals (N,3) of a point cloud: PCA over k neighbours, consistently oriented.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Points sampled on a surface (N >= 3).
    k : int
        Neighbourhood size (>= 3) for the plane fits and the orientation graph.

    Returns
    -------
    numpy.ndarray, shape (N, 3), float64
        Unit normals, outward for closed surfaces (see the module docstring).

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> pts = Sphere(radius=2.0).surfels(0.2).positions
    >>> n = estimate_normals(pts)
    >>> bool(np.all(np.einsum("ij,ij->i", n, pts / 2.0) > 0.99))
    True
    """
    from unmesh.spatial import knn

    pts = _bounded(as_points(points, "points"))
    if len(pts) < 3:
        raise InputError(f"points: expected at least 3 points to fit planes, got {len(pts)}")
    idx = knn(pts, _check_k(k, len(pts)))[1]
    return _orient(pts, _pca(pts, idx), idx)


def orient_reference(points: np.ndarray, normals: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Reference orientation with scipy's minimum spanning tree and breadth-first order (a copy).

    Same rules as :func:`orient_normals` (seed: the point farthest from its
    component's centroid; global flip by ``sum n . (x - c)``); the tree may differ
    where edge weights tie, so compare on generic inputs.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

    n = len(points)
    nrm = normals.copy()
    kg = min(idx.shape[1], GRAPH_K + 1)
    rows = np.repeat(np.arange(n), kg)
    cols = idx[:, :kg].ravel()
    ok = (cols >= 0) & (cols != rows)
    a, b = np.minimum(rows[ok], cols[ok]), np.maximum(rows[ok], cols[ok])
    key = np.unique(a * n + b)
    a, b = key // n, key % n
    w = 1.0 - np.abs(np.einsum("ij,ij->i", nrm[a], nrm[b])) + 1e-12
    tree = minimum_spanning_tree(coo_matrix((w, (a, b)), shape=(n, n)).tocsr())
    tree = tree + tree.T
    ncomp, labels = connected_components(tree, directed=False)
    for c in range(ncomp):
        members = np.flatnonzero(labels == c)
        cen = points[members].mean(axis=0)
        seed = int(members[np.argmax(np.linalg.norm(points[members] - cen, axis=1))])
        order, pred = breadth_first_order(tree, seed, directed=False, return_predecessors=True)
        parent = np.full(n, -1, np.int64)
        parent[order[1:]] = pred[order[1:]]
        nrm = propagate_reference(points, nrm, order, parent, SHARP_DOT)
        rel = points[members] - cen
        s = float(np.einsum("ij,ij->", nrm[members], rel))
        if abs(s) <= 1e-3 * (float(np.linalg.norm(rel, axis=1).sum()) or 1.0):
            mean = nrm[members].sum(axis=0)
            s = float(mean[np.argmax(np.abs(mean))])
        if s < 0:
            nrm[members] *= -1.0
    return nrm


def covariance_reference(points: np.ndarray, nbrs: np.ndarray) -> np.ndarray:
    """Numpy reference of :func:`unmesh.surfels._normals_kernels.neighbour_covariances`."""
    out = np.zeros((len(points), 3, 3))
    for i, row in enumerate(nbrs):
        sel = points[row[row >= 0]]
        if len(sel):
            d = sel - sel.mean(axis=0)
            out[i] = d.T @ d / len(sel)
    return out


def propagate_reference(points: np.ndarray, normals: np.ndarray, order: np.ndarray, parent: np.ndarray,
                        min_dot: float = 0.3) -> np.ndarray:
    """Python reference of :func:`unmesh.surfels._normals_kernels.propagate_orientation` (returns a copy)."""
    out = normals.copy()
    for i in order:
        p = parent[i]
        if p < 0:
            continue
        dot = out[i] @ out[p]
        agree = dot >= 0
        if abs(dot) < min_dot:
            d = points[i] - points[p]
            prod = (out[p] @ d) * (-(out[i] @ d))
            if prod != 0:
                agree = prod > 0
        if not agree:
            out[i] = -out[i]
    return out
