"""Shared helpers of the FEM tests."""

from __future__ import annotations

import numpy as np

from unmesh.fem import convex_polyhedron


def random_polyhedron(rng: np.random.Generator, n: int = 20, flat: float = 1.0):
    """A random convex polyhedron (convex hull of random points), scaled along z by ``flat``."""
    pts = rng.normal(size=(n, 3)) * np.array([1.0, 0.7, flat])
    return convex_polyhedron(pts)


def interior_points(poly, rng: np.random.Generator, count: int = 20) -> np.ndarray:
    """Random convex combinations of the vertices (strictly inside).

    Cubed weights put many points close to faces and edges; the floor 1e-9 keeps every
    point strictly inside (a weight of 1e-13 put a point within round-off of a face, where
    the coordinates are exactly the boundary triangle's barycentric ones, zero elsewhere).
    """
    w = rng.random((count, poly.n_nodes)) ** 3 + 1e-9
    w /= w.sum(axis=1, keepdims=True)
    return w @ poly.points


