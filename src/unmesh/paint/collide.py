"""Collision of points with the static original surface (thesis 5.4.1, eqs. 5.2-5.5).

Inside/outside by the closest original surfel (3.1.4); penetration depth and direction by
force shading over the ``n`` (10) nearest samples with weights (5.4)
``w_i = (d_max - d_i) / sum_j (d_max - d_j)``.

Example
-------
>>> from unmesh.spatial import KDTree
>>> pts = np.array([[x, y, 0.0] for x in range(-3, 4) for y in range(-3, 4)], float)
>>> nrm = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
>>> inside, d, n = collide(KDTree(pts), pts, nrm, np.array([[0.2, 0.1, -0.25]]))
>>> bool(inside[0]), round(float(d[0]), 6), n[0].tolist()
(True, 0.25, [0.0, 0.0, 1.0])
"""

from __future__ import annotations

import numpy as np

from unmesh.paint._collide_kernels import ball_knn
from unmesh.spatial import KDTree

__all__ = ["BallKnn", "collide", "force_shading"]


class BallKnn:
    """Exact k-nearest queries of a kd-tree's points near a place (the brush during one paint
    event): the points within ``radius`` of ``centre`` are fetched once, queries are answered
    by a brute force over them where that is provably exact, by the tree elsewhere. Results are
    those of ``tree.knn`` (same distances, ties by index). ``len()`` is the tree's.

    Example
    -------
    >>> pts = np.array([[x, y, 0.0] for x in range(-3, 4) for y in range(-3, 4)], float)
    >>> t = KDTree(pts)
    >>> b = BallKnn(t, np.zeros(3), 2.5)
    >>> bool((b.knn(np.array([[0.2, 0.1, 0.3]]), 4)[1] == t.knn([[0.2, 0.1, 0.3]], 4)[1]).all())
    True
    """

    def __init__(self, tree: KDTree, centre: np.ndarray, radius: float) -> None:
        self.tree = tree
        self.centre = np.ascontiguousarray(centre, dtype=np.float64).reshape(3)
        self.radius = float(radius)
        off, ind = tree.radius_neighbors(self.centre[None], self.radius)
        self.ids = np.ascontiguousarray(ind[off[0]:off[1]])
        self.points = np.ascontiguousarray(tree.points[self.ids])

    def __len__(self) -> int:
        return len(self.tree)

    def knn(self, x: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`unmesh.spatial.KDTree.knn` for (M, 3) ``x`` and ``1 <= k <= len(self)``."""
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
        if len(self.ids) < k:
            return self.tree.knn(x, k)
        dist = np.empty((len(x), k))
        idx = np.empty((len(x), k), np.int64)
        ok = np.empty(len(x), np.bool_)
        ball_knn(self.points, self.ids, x, k, self.centre, self.radius, dist, idx, ok)
        if not ok.all():
            bad = np.flatnonzero(~ok)
            dist[bad], idx[bad] = self.tree.knn(x[bad], k)
        return dist, idx


def _shading(tree: KDTree | BallKnn, positions: np.ndarray, normals: np.ndarray, x: np.ndarray,
             n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    k = min(n, len(tree))
    dist, idx = tree.knn(x, k)
    dmax = dist.max(axis=1, keepdims=True)
    w = dmax - dist
    s = w.sum(axis=1, keepdims=True)
    flat = s[:, 0] <= 0
    if flat.any():
        w[flat] = 1.0
        s[flat] = k
    w = w / s
    nn = normals[idx]
    d = np.einsum("mk,mk->m", w, np.einsum("mki,mki->mk", nn, positions[idx] - x[:, None, :]))
    N = np.einsum("mk,mki->mi", w, nn)
    ln = np.sqrt(np.add.reduce(N * N, axis=1))  # np.linalg.norm(N, axis=1) without its checks
    bad = ln < 1e-12
    if bad.any():
        N[bad] = nn[bad, 0]
        ln[bad] = 1.0
    return d, N / ln[:, None], idx[:, 0]


def force_shading(tree: KDTree | BallKnn, positions: np.ndarray, normals: np.ndarray, x: np.ndarray,
                  n: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Penetration depth ``d`` (5.2) and unit direction ``N`` (5.3) at points ``x`` (M, 3).

    ``d > 0`` means ``x`` lies below the surface by ``d`` along ``N``; ``x + d N`` is on it (5.5).

    Returns
    -------
    d : (M,) float64
    N : (M, 3) float64, unit
    """
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    d, N, _ = _shading(tree, positions, normals, x, n)
    return d, N


def collide(tree: KDTree | BallKnn, positions: np.ndarray, normals: np.ndarray, x: np.ndarray,
            n: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest-surfel inside test plus force shading (one k-nearest query).

    Returns
    -------
    inside : (M,) bool
        ``N_c . (x - x_c) < 0`` for the closest original surfel ``c``.
    d : (M,) float64
        Penetration depth (5.2), meaningful where ``inside``.
    N : (M, 3) float64
        Unit surface direction (5.3).
    """
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    d, N, c = _shading(tree, positions, normals, x, n)
    inside = np.einsum("mi,mi->m", normals[c], x - positions[c]) < 0
    return inside, d, N
