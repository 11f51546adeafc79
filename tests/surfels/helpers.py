"""Shared checks for the sampling tests: splat coverage and random surface points."""

from __future__ import annotations

import numpy as np

from unmesh.spatial import knn, radius_neighbors


def _covered(cloud, points, normals, rows, idx, offset_frac, min_dot):
    d = points[rows] - cloud.positions[idx]
    n = cloud.normals[idx]
    h = np.einsum("ij,ij->i", d, n)
    tang = np.sqrt(np.maximum(0.0, np.einsum("ij,ij->i", d, d) - h * h))
    ok = (tang <= cloud.radii[idx]) & (np.abs(h) <= offset_frac * cloud.radii[idx])
    if normals is not None:
        ok &= np.einsum("ij,ij->i", n, normals[rows]) > min_dot
    covered = np.zeros(len(points), bool)
    np.logical_or.at(covered, rows, ok)
    return covered


def uncovered(cloud, points, normals=None, offset_frac=0.25, min_dot=0.0):
    """Indices of ``points`` covered by no splat.

    A point y is covered by surfel i when its tangential distance in the splat's
    plane is at most r_i, its offset along n_i at most ``offset_frac * r_i``, and
    (when ``normals`` are given) n_i . n(y) > ``min_dot``. The 12 nearest surfels are
    tried first, then every surfel within the largest radius (exhaustive).
    """
    k = min(12, len(cloud))
    _, idx = knn(cloud.positions, k, queries=points)
    rows = np.repeat(np.arange(len(points)), k)
    covered = _covered(cloud, points, normals, rows, idx.ravel(), offset_frac, min_dot)
    rest = np.flatnonzero(~covered)
    if len(rest):
        rmax = float(cloud.radii.max())
        off, ind = radius_neighbors(cloud.positions, rmax * (1 + 1e-9), queries=points[rest])
        rows = np.repeat(np.arange(len(rest)), np.diff(off))
        sub = _covered(cloud, points[rest], None if normals is None else normals[rest], rows, ind, offset_frac, min_dot)
        rest = rest[~sub]
    return rest


def random_surface_points(mesh, count, rng):
    """Area-uniform random points (count,3) on a mesh and their face normals."""
    areas = mesh.face_areas()
    tri = rng.choice(len(areas), count, p=areas / areas.sum())
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    v = mesh.vertices
    f = mesh.faces[tri]
    p = (1 - r1)[:, None] * v[f[:, 0]] + (r1 * (1 - r2))[:, None] * v[f[:, 1]] + (r1 * r2)[:, None] * v[f[:, 2]]
    return p, mesh.face_normals()[tri]
