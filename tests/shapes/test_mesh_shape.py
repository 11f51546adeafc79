"""MeshShape: BVH closest points and winding numbers against brute force."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.shapes import Blob, Box, MeshShape, Sphere, Torus
from unmesh.shapes._kernels import greedy_poisson
from unmesh.shapes._sampling import greedy_poisson_reference
from unmesh.shapes.mesh_shape import closest_point_reference, winding_reference


def test_closest_points_match_brute_force(rng):
    mesh = Torus(major=0.6, minor=0.25).mesh(resolution=14)
    shape = MeshShape(mesh)
    x = rng.uniform(-1.2, 1.2, size=(400, 3))
    d, p, f = shape.closest_points(x)
    d_ref, p_ref = closest_point_reference(x, mesh.vertices, mesh.faces)
    np.testing.assert_allclose(d, d_ref, atol=1e-12)
    np.testing.assert_allclose(p, p_ref, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(x - p, axis=1), d, atol=1e-12)
    # the reported face holds the point
    own = [closest_point_reference(x[i:i + 1], mesh.vertices, mesh.faces[f[i]:f[i] + 1])[0][0] for i in range(50)]
    np.testing.assert_allclose(own, d[:50], atol=1e-12)


def test_winding_numbers_match_exact_sum(rng):
    mesh = Blob().mesh(0.08)
    shape = MeshShape(mesh)
    lo, hi = mesh.bounds()
    x = rng.uniform(lo - 0.2, hi + 0.2, size=(300, 3))
    w_ref = winding_reference(x, mesh.vertices, mesh.faces)
    assert np.all((w_ref > 0.5) == (np.abs(w_ref - 1) < 1e-6))  # closed mesh: exactly 0 or 1
    w = shape.winding_number(x)
    # First-order far field (Barill et al. 2018) with beta = 3: about a per cent ...
    assert np.abs(w - w_ref).max() < 0.025
    np.testing.assert_array_equal(w > 0.5, w_ref > 0.5)
    # ... converging to the exact sum as the acceptance ratio beta grows.
    errs = [np.abs(shape.bvh.winding_number(x, beta) - w_ref).max() for beta in (2.0, 4.0, 8.0, 1e9)]
    assert errs[1] < errs[0] / 2 and errs[2] < errs[1] / 2 and errs[3] < 1e-12


def test_signed_distance_and_inside_on_a_sphere_mesh(rng):
    sphere = Sphere(radius=1.0)
    shape = MeshShape(sphere.mesh(resolution=24))
    assert shape.closed
    x = rng.uniform(-1.6, 1.6, size=(2000, 3))
    r = np.linalg.norm(x, axis=1)
    far = np.abs(r - 1) > 0.02  # mesh-to-sphere error is below 0.01
    v, n = shape.implicit(x)
    np.testing.assert_array_equal((v < 0)[far], (r < 1)[far])
    np.testing.assert_array_equal(shape.contains(x)[far], (r < 1)[far])
    np.testing.assert_allclose(v, r - 1, atol=0.01)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    # normals: unit gradient of the signed distance (finite differences)
    h = 1e-6
    grad = np.stack([(shape.implicit(x + h * e)[0] - shape.implicit(x - h * e)[0]) / (2 * h) for e in np.eye(3)], 1)
    ok = np.abs(np.linalg.norm(grad, axis=1) - 1) < 1e-4
    assert ok.mean() > 0.9
    assert np.all(np.einsum("ij,ij->i", grad[ok], n[ok]) > 1 - 1e-6)
    np.testing.assert_allclose(shape.volume(), sphere.volume(), rtol=0.01)


def test_winding_number_is_robust_to_holes(rng):
    mesh = Sphere().mesh(resolution=20)
    keep = rng.random(len(mesh.faces)) > 0.03  # punch holes: remove 3 % of the triangles
    holey = MeshShape(TriangleMesh(mesh.vertices, mesh.faces[keep]))
    assert not holey.closed
    x = rng.uniform(-1.5, 1.5, size=(3000, 3))
    r = np.linalg.norm(x, axis=1)
    sure = np.abs(r - 1) > 0.15
    np.testing.assert_array_equal(holey.contains(x)[sure], (r < 1)[sure])


def test_degenerate_and_unreferenced_input():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [2, 0, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 4]])  # second triangle is degenerate (collinear)
    shape = MeshShape(TriangleMesh(v, f))
    d, _, _ = shape.closest_points([[0.2, 0.2, 1.0], [3.0, 0.0, 0.0]])
    np.testing.assert_allclose(d, [1.0, 1.0])
    np.testing.assert_allclose(shape.bounds(), [[0, 0, 0], [2, 1, 0]])
    with pytest.raises(InputError):
        MeshShape(TriangleMesh(v, np.zeros((0, 3), int)))
    with pytest.raises(InputError):
        MeshShape("bunny.obj")


def test_bunny_mesh_shape(models_dir):
    from unmesh.io import load_mesh

    mesh = load_mesh(models_dir / "stanford-bunny.obj")
    shape = MeshShape(mesh)
    assert not shape.closed
    lo, hi = shape.bounds()
    rng = np.random.default_rng(7)
    x = rng.uniform(lo, hi, size=(200, 3))
    v, _ = shape.implicit(x)
    d_ref = np.concatenate([closest_point_reference(x[i:i + 5], mesh.vertices, mesh.faces)[0] for i in range(0, 20, 5)])
    np.testing.assert_allclose(np.abs(v[:20]), d_ref, atol=1e-12)
    centre = np.array([[-0.02, 0.1, 0.0]])  # inside the body
    assert shape.contains(centre)[0]
    assert not shape.contains([[0.5, 0.5, 0.5]])[0]
    # the winding number agrees with the exact sum everywhere, holes included
    np.testing.assert_allclose(shape.winding_number(x[:20]), winding_reference(x[:20], mesh.vertices, mesh.faces),
                               atol=0.025)


def test_mesh_shape_transform_and_surfels():
    shape = MeshShape(Box(size=(1, 1, 1)).mesh(resolution=4))
    m = np.diag([2.0, 1.0, 0.5, 1.0])  # any affine map is fine for meshes
    moved = shape.transformed(m)
    np.testing.assert_allclose(moved.volume(), 1.0)
    np.testing.assert_allclose(moved.implicit([[0.0, 0.0, 0.0]])[0], [-0.25])
    cloud = shape.surfels(0.1, color=(0, 1, 0))
    assert len(cloud) == 600 and np.allclose(cloud.colors, [0, 1, 0])


def test_greedy_poisson_matches_reference(rng):
    from unmesh.spatial import radius_neighbors

    pts = rng.random((3000, 3))
    off, ind = radius_neighbors(pts, 0.05)
    order = rng.permutation(len(pts)).astype(np.int64)
    keep = greedy_poisson(order, off, ind)
    np.testing.assert_array_equal(keep, greedy_poisson_reference(order, off, ind))
    kept = pts[keep]
    from unmesh.spatial import knn

    d, _ = knn(kept, 2)
    assert d[:, 1].min() > 0.05  # a Poisson-disk set
    d2, _ = knn(kept, 1, queries=pts)
    assert d2.max() <= 0.05  # maximal: every candidate is within the radius of a kept point
