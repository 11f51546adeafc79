"""Maximal Poisson-disk sampling of an implicit surface (used by the blob's surfels)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["greedy_poisson_reference", "poisson_surface"]


def greedy_poisson_reference(order: np.ndarray, offsets: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Plain Python reference of :func:`unmesh.shapes._kernels.greedy_poisson`."""
    n = len(offsets) - 1
    keep = np.zeros(n, bool)
    blocked = np.zeros(n, bool)
    for i in order:
        if blocked[i]:
            continue
        keep[i] = True
        blocked[indices[offsets[i]:offsets[i + 1]]] = True
    return keep


def poisson_surface(vertices: np.ndarray, faces: np.ndarray, spacing: float,
                    implicit: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                    density: float = 6.0, seed: int = 0, iterations: int = 10) -> np.ndarray:
    """Blue-noise points (N,3) on the zero set of ``implicit``, about ``spacing`` apart.

    ``density`` candidates per ``spacing**2`` of area are drawn uniformly on the
    (fine) mesh ``vertices/faces``, projected onto the exact surface by Newton steps,
    and thinned greedily in a seeded random order with disk radius
    ``0.9 * spacing``: kept points are at least that far apart, and every candidate
    is within that distance of a kept point (a maximal Poisson-disk set).
    Deterministic for a given ``seed``.
    """
    from unmesh.shapes._kernels import greedy_poisson
    from unmesh.shapes._meshing import project_to_zero
    from unmesh.spatial import radius_neighbors

    rng = np.random.default_rng(seed)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    total = float(areas.sum())
    count = max(16, int(np.ceil(density * total / spacing**2)))
    tri = rng.choice(len(faces), size=count, p=areas / total)
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    pts = (1 - r1)[:, None] * a[tri] + (r1 * (1 - r2))[:, None] * b[tri] + (r1 * r2)[:, None] * c[tri]
    pts = project_to_zero(implicit, pts, spacing, iterations)
    radius = 0.9 * spacing
    offsets, indices = radius_neighbors(pts, radius)
    keep = greedy_poisson(rng.permutation(count).astype(np.int64), offsets, indices)
    return np.ascontiguousarray(pts[keep])
