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

from unmesh.spatial import KDTree

__all__ = ["collide", "force_shading"]


def _shading(tree: KDTree, positions: np.ndarray, normals: np.ndarray, x: np.ndarray,
             n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    k = min(n, len(tree))
    dist, idx = tree.knn(x, k)
    dmax = dist.max(axis=1, keepdims=True)
    w = dmax - dist
    s = w.sum(axis=1, keepdims=True)
    flat = s[:, 0] <= 0
    w[flat] = 1.0
    s[flat] = k
    w = w / s
    nn = normals[idx]
    d = np.einsum("mk,mk->m", w, np.einsum("mki,mki->mk", nn, positions[idx] - x[:, None, :]))
    N = np.einsum("mk,mki->mi", w, nn)
    ln = np.linalg.norm(N, axis=1)
    bad = ln < 1e-12
    N[bad] = nn[bad, 0]
    ln[bad] = 1.0
    return d, N / ln[:, None], idx[:, 0]


def force_shading(tree: KDTree, positions: np.ndarray, normals: np.ndarray, x: np.ndarray,
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


def collide(tree: KDTree, positions: np.ndarray, normals: np.ndarray, x: np.ndarray,
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
