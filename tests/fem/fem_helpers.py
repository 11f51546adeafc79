"""Shared helpers of the FEM tests."""

from __future__ import annotations

import numpy as np

from unmesh.fem import convex_polyhedron


def random_polyhedron(rng: np.random.Generator, n: int = 20, flat: float = 1.0):
    """A random convex polyhedron (convex hull of random points), scaled along z by ``flat``."""
    pts = rng.normal(size=(n, 3)) * np.array([1.0, 0.7, flat])
    return convex_polyhedron(pts)


def interior_points(poly, rng: np.random.Generator, count: int = 20) -> np.ndarray:
    """Random convex combinations of the vertices (strictly inside)."""
    w = rng.random((count, poly.n_nodes)) ** 3
    w /= w.sum(axis=1, keepdims=True)
    return w @ poly.points


