"""radius_neighbors / radius_pairs against numpy brute force."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from unmesh.errors import InputError
from unmesh.spatial import choose_method, radius_neighbors, radius_pairs

from .reference import brute_pairs, brute_radius

METHODS = ["grid", "kdtree", "auto"]


def assert_csr_equal(got, want):
    off, ind = got
    assert off.dtype == np.int64 and ind.dtype == np.int64
    np.testing.assert_array_equal(off, want[0])
    np.testing.assert_array_equal(ind, want[1])


def clustered(rng, n, dim):
    centers = rng.random((5, dim)) * 10
    return centers[rng.integers(0, 5, n)] + rng.normal(scale=0.05, size=(n, dim))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dim", [2, 3])
def test_uniform_random_self(rng, method, dim):
    p = rng.random((1500, dim))
    r = 0.12 if dim == 3 else 0.05
    assert_csr_equal(radius_neighbors(p, r, method=method), brute_radius(p, r))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dim", [2, 3])
def test_queries_and_far_queries(rng, method, dim):
    p = rng.random((800, dim))
    q = np.concatenate([rng.random((300, dim)) * 1.4 - 0.2, rng.random((20, dim)) * 1e6 + 1e3, -rng.random((5, dim)) * 1e8])
    r = 0.1
    got = radius_neighbors(p, r, q, method=method)
    assert_csr_equal(got, brute_radius(p, r, q))
    assert np.all(np.diff(got[0])[-25:] == 0)


@pytest.mark.parametrize("method", METHODS)
def test_clustered(rng, method):
    p = clustered(rng, 2000, 3)
    assert_csr_equal(radius_neighbors(p, 0.03, method=method), brute_radius(p, 0.03))
    np.testing.assert_array_equal(radius_pairs(p, 0.03, method=method), brute_pairs(p, 0.03))


@pytest.mark.parametrize("method", METHODS)
def test_duplicates_and_exact_boundary(method):
    # integer lattice with duplicates: many distances exactly equal to the radius
    g = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), -1).reshape(-1, 3) * 0.25
    p = np.concatenate([g, g[::3], g[::7]])
    for r in (0.25, 0.5, np.sqrt(2) * 0.25, 0.3):
        assert_csr_equal(radius_neighbors(p, r, method=method), brute_radius(p, r))
        np.testing.assert_array_equal(radius_pairs(p, r, method=method), brute_pairs(p, r))


@pytest.mark.parametrize("method", METHODS)
def test_radius_larger_than_extent(rng, method):
    p = rng.random((300, 3))
    off, ind = radius_neighbors(p, 100.0, method=method)
    assert np.all(np.diff(off) == 300)
    np.testing.assert_array_equal(ind.reshape(300, 300), np.tile(np.arange(300), (300, 1)))
    assert len(radius_pairs(p, 100.0, method=method)) == 300 * 299 // 2


@pytest.mark.parametrize("method", METHODS)
def test_empty_inputs(method):
    p = np.random.default_rng(1).random((10, 3))
    off, ind = radius_neighbors(np.empty((0, 3)), 1.0, p, method=method)
    assert off.tolist() == [0] * 11 and ind.size == 0
    off, ind = radius_neighbors(p, 1.0, np.empty((0, 3)), method=method)
    assert off.tolist() == [0] and ind.size == 0
    off, ind = radius_neighbors(np.empty((0, 2)), 1.0, method=method)
    assert off.tolist() == [0]
    assert radius_pairs(np.empty((0, 3)), 1.0, method=method).shape == (0, 2)
    assert radius_pairs(p[:1], 1.0, method=method).shape == (0, 2)
    off, ind = radius_neighbors([], 1.0, [[0.0, 0.0]], method=method)
    assert off.tolist() == [0, 0]


def test_single_point_and_list_input():
    off, ind = radius_neighbors([[1.0, 2.0, 3.0]], 0.1)
    assert off.tolist() == [0, 1] and ind.tolist() == [0]
    off, ind = radius_neighbors([[0.0, 0.0]], 0.1, [0.05, 0.0])
    assert ind.tolist() == [0]


@pytest.mark.parametrize("method", METHODS)
def test_pairs_match_query_pairs(rng, method):
    p = rng.random((3000, 3))
    r = 0.07
    want = cKDTree(p).query_pairs(r, output_type="ndarray")
    want = want[np.lexsort((want[:, 1], want[:, 0]))]
    got = radius_pairs(p, r, method=method)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_far_apart_clusters_and_huge_extent_use_kdtree(rng):
    p = np.concatenate([rng.random((500, 3)) * 1e-3, rng.random((500, 3)) * 1e-3 + 1e6])
    r = 1e-4
    assert choose_method(p, r) == "kdtree"
    assert_csr_equal(radius_neighbors(p, r), brute_radius(p, r))
    assert_csr_equal(radius_neighbors(p, r, method="grid"), brute_radius(p, r))
    assert choose_method(rng.random((500, 3)), 0.1) == "grid"


def test_nonuniform_density_uses_kdtree(rng):
    # queries in a shell just outside the radius around a very dense cluster: every
    # grid candidate is a miss, the kd-tree prunes the cluster as a whole
    dense = rng.normal(size=(20000, 3)) * 1e-4
    r = 0.1
    u = rng.normal(size=(300, 3))
    q = u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(1.05 * r, 1.5 * r, (300, 1))
    assert choose_method(dense, r) == "grid"  # self queries: all hits
    assert choose_method(dense, r, q) == "kdtree"
    want = brute_radius(dense, r, q)
    assert want[0][-1] == 0
    assert_csr_equal(radius_neighbors(dense, r, q), want)
    assert_csr_equal(radius_neighbors(dense, r, q, method="grid"), want)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(points=np.zeros((3, 3)), radius=0.0), "radius"),
        (dict(points=np.zeros((3, 3)), radius=-1.0), "radius"),
        (dict(points=np.zeros((3, 3)), radius=np.nan), "radius"),
        (dict(points=np.zeros((3, 3)), radius=np.inf), "radius"),
        (dict(points=np.zeros((3, 3)), radius="a"), "radius"),
        (dict(points=np.zeros((3, 4)), radius=1.0), "points"),
        (dict(points=np.zeros((2, 3, 3)), radius=1.0), "points"),
        (dict(points=[[0, 0, np.nan]], radius=1.0), "points"),
        (dict(points=np.zeros((3, 3)), radius=1.0, queries=np.zeros((2, 2))), "queries"),
        (dict(points=np.zeros((3, 2)), radius=1.0, queries=np.zeros((2, 3))), "queries"),
        (dict(points=np.zeros((3, 3)), radius=1.0, queries=[[0, 0, np.inf]]), "queries"),
        (dict(points=np.zeros((3, 3)), radius=1.0, method="octree"), "method"),
    ],
)
def test_input_errors(kwargs, match):
    with pytest.raises(InputError, match=match):
        radius_neighbors(**kwargs)


def test_pairs_input_errors():
    with pytest.raises(InputError, match="radius"):
        radius_pairs(np.zeros((3, 3)), 0)
    with pytest.raises(InputError, match="points"):
        radius_pairs(np.zeros((3, 5)), 1.0)


coords = st.integers(-6, 6).map(lambda v: v * 0.125)


@settings(max_examples=60, deadline=None)
@given(
    dim=st.sampled_from([2, 3]),
    n=st.integers(0, 40),
    nq=st.integers(0, 10),
    radius=st.sampled_from([0.125, 0.25, 0.3, 0.5, 1.0, 5.0]),
    method=st.sampled_from(METHODS),
    data=st.data(),
)
def test_hypothesis_matches_brute_force(dim, n, nq, radius, method, data):
    p = np.array(data.draw(st.lists(st.tuples(*[coords] * dim), min_size=n, max_size=n)), float).reshape(n, dim)
    q = np.array(data.draw(st.lists(st.tuples(*[coords] * dim), min_size=nq, max_size=nq)), float).reshape(nq, dim)
    assert_csr_equal(radius_neighbors(p, radius, method=method), brute_radius(p, radius))
    assert_csr_equal(radius_neighbors(p, radius, q, method=method), brute_radius(p, radius, q))
    np.testing.assert_array_equal(radius_pairs(p, radius, method=method).reshape(-1, 2), brute_pairs(p, radius))


@pytest.mark.parametrize("method", ["grid", "kdtree", "auto"])
@pytest.mark.parametrize("dim", [2, 3])
def test_unsorted_pairs_are_the_same_set(rng, method, dim):
    pts = rng.random((3000, dim))
    pts[100:110] = pts[0]  # duplicates
    r = 0.05 if dim == 3 else 0.02
    ref = brute_pairs(pts, r)
    got = radius_pairs(pts, r, method=method, sort=False)
    assert got.dtype == np.int64 and got.shape == ref.shape
    assert (got[:, 0] < got[:, 1]).all()
    np.testing.assert_array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], ref)
    assert radius_pairs(pts[:1], r, sort=False).shape == (0, 2)


@pytest.mark.parametrize("dim", [2, 3])
def test_kdtree_one_and_few_queries_match_brute_force(rng, dim):
    # one query and up to 16 (asked of SciPy per query, unsorted) on a lattice with duplicates:
    # many distances exactly equal to the radius
    from unmesh.spatial import KDTree

    g = np.stack(np.meshgrid(*[np.arange(6)] * dim, indexing="ij"), -1).reshape(-1, dim) * 0.25
    p = np.concatenate([g, g[::3], rng.random((400, dim)) * 1.25])
    tree = KDTree(p)
    for nq in (1, 2, 16):
        q = np.concatenate([g[rng.integers(0, len(g), nq - nq // 2)], rng.random((nq // 2, dim)) * 1.25])
        for r in (0.25, 0.5, 0.3):
            assert_csr_equal(tree.radius_neighbors(q, r), brute_radius(p, r, q))
