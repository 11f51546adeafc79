"""Normal estimation: PCA plane fits and MST orientation (Hoppe et al. 1992)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh._linalg_kernels import smallest_eigenvectors
from unmesh.errors import InputError
from unmesh.shapes import Blob, Box, Plane, Sphere, Torus
from unmesh.spatial import knn
from unmesh.surfels import estimate_normals, orient_normals, pca_normals
from unmesh.surfels._normals_kernels import forest_bfs, kruskal_forest, neighbour_covariances, propagate_orientation
from unmesh.surfels.normals import covariance_reference, orient_reference, propagate_reference


def angles_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def test_covariance_kernel_matches_reference(rng):
    pts = rng.normal(size=(500, 3))
    _, idx = knn(pts, 10)
    idx[::7, -3:] = -1  # padding is ignored
    np.testing.assert_allclose(neighbour_covariances(pts, idx), covariance_reference(pts, idx), atol=1e-12)


def test_smallest_eigenvectors_match_eigh(rng):
    a = rng.normal(size=(20000, 3, 3))
    cov = a @ a.transpose(0, 2, 1)
    flat = rng.normal(size=(2000, 12, 3)) * [1.0, 0.3, 1e-5]  # nearly planar neighbourhoods
    cov[:2000] = np.einsum("nki,nkj->nij", flat, flat)
    b = rng.normal(size=(500, 3))
    cov[2000:2500] = b[:, :, None] * b[:, None, :]  # rank 1: a 2-D eigenspace
    cov[2500:2600] = np.eye(3)
    cov[2600:2700] = 0.0
    v = smallest_eigenvectors(cov)
    w, vec = np.linalg.eigh(cov)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    generic = np.r_[0:2000, 2700:20000]
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", v[generic], vec[generic, :, 0])), 1.0, atol=1e-9)
    # degenerate eigenspaces: any unit vector in it (residual of A v = l_min v)
    res = np.linalg.norm(np.einsum("nij,nj->ni", cov, v) - w[:, :1] * v, axis=1)
    assert np.all(res <= 1e-7 * np.maximum(np.abs(w).max(axis=1), 1e-300))


def test_propagation_kernel_matches_reference(rng):
    x = rng.normal(size=(300, 3))
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    order = rng.permutation(300).astype(np.int64)
    parent = np.full(300, -1, np.int64)
    parent[order[1:]] = order[rng.integers(0, np.arange(1, 300))]  # every parent comes earlier
    np.testing.assert_array_equal(propagate_orientation(x, n.copy(), order, parent, 0.3),
                                  propagate_reference(x, n, order, parent, 0.3))


def test_kruskal_matches_scipy_minimum_spanning_tree(rng):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components, minimum_spanning_tree

    n = 400
    pts = rng.random((n, 3))
    _, idx = knn(pts, 5)
    a = np.repeat(np.arange(n), 4)
    b = idx[:, 1:].ravel()
    w = np.linalg.norm(pts[a] - pts[b], axis=1)  # symmetric, generic: a unique tree
    ta, tb = kruskal_forest(n, a, b, np.argsort(w, kind="stable"))
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key, first = np.unique(lo * n + hi, return_index=True)
    ref = minimum_spanning_tree(coo_matrix((w[first], (key // n, key % n)), shape=(n, n)))
    ncomp = connected_components(ref, directed=False)[0]
    assert len(ta) == n - ncomp == ref.nnz
    mine = np.linalg.norm(pts[ta] - pts[tb], axis=1).sum()
    assert abs(mine - ref.sum()) < 1e-9
    order, parent, comp = forest_bfs(n, ta, tb, np.arange(n))
    assert sorted(order.tolist()) == list(range(n)) and comp.max() + 1 == ncomp
    pos = np.empty(n, int)
    pos[order] = np.arange(n)
    has = parent >= 0
    assert np.all(pos[parent[has]] < pos[has])  # parents come first


def test_orientation_matches_the_scipy_reference():
    from unmesh.surfels.normals import _orient, _pca

    for shape in (Torus(), Box(size=(1.0, 0.8, 0.6))):
        pts = shape.surfels(shape.size() / 50).positions
        _, idx = knn(pts, 16)
        n0 = _pca(pts, idx)
        np.testing.assert_array_equal(np.sign(np.einsum("ij,ij->i", _orient(pts, n0.copy(), idx),
                                                        orient_reference(pts, n0, idx))), 1.0)


@pytest.mark.parametrize("shape,div,p95,worst", [(Sphere(radius=1.5), 60, 0.5, 1.0), (Torus(), 60, 2.0, 3.0),
                                                  (Blob(), 120, 6.0, 60.0)], ids=["sphere", "torus", "blob"])
def test_normals_of_sampled_surfaces_are_accurate_and_outward(shape, div, p95, worst):
    cloud = shape.surfels(shape.size() / div)
    n = estimate_normals(cloud.positions, k=16)
    err = angles_deg(n, cloud.normals)
    assert np.all(err < 90), f"{(err >= 90).sum()} normals point inward"
    # the blob's ear tips have curvature radii below the spacing: PCA is off there
    assert np.percentile(err, 95) < p95 and err.max() < worst, (np.percentile(err, 95), err.max())


def test_noisy_sphere_within_a_few_degrees(rng):
    cloud = Sphere(radius=1.0).surfels(0.04)
    noisy = cloud.positions + rng.normal(scale=0.002, size=cloud.positions.shape)
    n = estimate_normals(noisy, k=24)
    err = angles_deg(n, cloud.normals)
    assert np.all(err < 90) and np.median(err) < 3.0 and np.percentile(err, 99) < 8.0


def test_orientation_of_randomly_flipped_normals(rng):
    for shape in (Torus(), Box(size=(1.0, 0.8, 0.6))):
        cloud = shape.surfels(shape.size() / 40)
        flipped = cloud.normals * rng.choice([-1.0, 1.0], size=(len(cloud), 1))
        out = orient_normals(cloud.positions, flipped)
        np.testing.assert_allclose(out, cloud.normals, atol=1e-12)


def test_flat_sheet_points_to_its_positive_side():
    cloud = Plane(size=(2.0, 1.0), normal=(0.0, -1.0, 0.0)).surfels(0.05)
    n = estimate_normals(cloud.positions)
    np.testing.assert_allclose(n, np.tile([0.0, 1.0, 0.0], (len(n), 1)), atol=1e-9)


def test_separate_components_are_each_oriented_outward():
    a = Sphere(center=(-3.0, 0.0, 0.0), radius=1.0).surfels(0.1)
    b = Sphere(center=(3.0, 0.0, 0.0), radius=0.5).surfels(0.05)
    pts = np.concatenate([a.positions, b.positions])
    exact = np.concatenate([a.normals, b.normals])
    n = estimate_normals(pts, k=12)
    assert np.all(np.einsum("ij,ij->i", n, exact) > 0.99)


def test_input_errors():
    with pytest.raises(InputError, match="at least 3"):
        estimate_normals(np.zeros((2, 3)))
    with pytest.raises(InputError, match="k"):
        pca_normals(np.random.default_rng(0).random((10, 3)), k=2)
    with pytest.raises(InputError, match="non-zero"):
        orient_normals(np.random.default_rng(0).random((10, 3)), np.zeros((10, 3)))
