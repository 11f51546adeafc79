"""knn / KDTree against a brute-force stable sort (exact, including ties)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.spatial import KDTree, knn

from .reference import brute_knn


def assert_knn_equal(got, want):
    d, i = got
    assert d.dtype == np.float64 and i.dtype == np.int64
    np.testing.assert_array_equal(i, want[1])
    np.testing.assert_array_equal(d, want[0])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("k", [1, 7, 16])
def test_random(rng, dim, k):
    p = rng.random((1000, dim))
    assert_knn_equal(knn(p, k), brute_knn(p, k))
    q = rng.random((200, dim)) * 3 - 1
    assert_knn_equal(knn(p, k, q), brute_knn(p, k, q))


def test_self_is_first_at_distance_zero(rng):
    p = rng.random((500, 3))
    d, i = knn(p, 4)
    np.testing.assert_array_equal(i[:, 0], np.arange(500))
    assert np.all(d[:, 0] == 0)


def test_duplicates_ties_broken_by_index(rng):
    base = rng.random((50, 3))
    p = np.concatenate([base, base, base[:20], base[::-1]])  # many exact duplicates
    for k in (1, 2, 3, 5, 9):
        assert_knn_equal(knn(p, k), brute_knn(p, k))
    # lattice: equidistant neighbours everywhere
    g = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), -1).reshape(-1, 3).astype(float)
    for k in (2, 5, 7, 19, 27):
        assert_knn_equal(knn(g, k), brute_knn(g, k))
        assert_knn_equal(knn(g, k, g[::5] + 0.5), brute_knn(g, k, g[::5] + 0.5))


def test_k_larger_than_n_pads(rng):
    p = rng.random((5, 2))
    d, i = knn(p, 8)
    assert_knn_equal((d, i), brute_knn(p, 8))
    assert np.all(i[:, 5:] == -1) and np.all(np.isinf(d[:, 5:]))
    d, i = knn(p, 5)
    assert np.all(i >= 0)


def test_empty():
    d, i = knn(np.empty((0, 3)), 3, np.zeros((2, 3)))
    assert d.shape == (2, 3) and np.all(i == -1) and np.all(np.isinf(d))
    d, i = knn(np.zeros((4, 3)), 3, np.empty((0, 3)))
    assert d.shape == (0, 3) and i.shape == (0, 3)


def test_kdtree_class_reuse(rng):
    p = rng.random((400, 3))
    tree = KDTree(p)
    assert len(tree) == 400 and "KDTree" in repr(tree)
    for _ in range(3):
        q = rng.random((50, 3))
        assert_knn_equal(tree.knn(q, 6), brute_knn(p, 6, q))


@pytest.mark.parametrize("leafsize", [1, 5, 64, 2000])
def test_leafsize_does_not_change_results(rng, leafsize):
    # queries near the points and far from them (a sphere seen from outside, where leaf size matters)
    p = rng.normal(size=(1500, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    q = np.concatenate([p[:100] * 1.01, rng.normal(size=(100, 3)) * 4.0])
    assert_knn_equal(KDTree(p, leafsize=leafsize).knn(q, 3), brute_knn(p, 3, q))


@pytest.mark.parametrize("leafsize", [0, -3, 2.5, True])
def test_bad_leafsize(leafsize):
    with pytest.raises(InputError, match="leafsize"):
        KDTree(np.zeros((3, 3)), leafsize=leafsize)


@pytest.mark.parametrize("k", [0, -1, 1.5, "3", None, True])
def test_bad_k(k):
    with pytest.raises(InputError, match="k"):
        knn(np.zeros((3, 3)), k)


def test_bad_points():
    with pytest.raises(InputError, match="points"):
        knn(np.zeros((3, 4)), 2)
    with pytest.raises(InputError, match="queries"):
        knn(np.zeros((3, 3)), 2, np.zeros((3, 2)))


coords = st.integers(-3, 3).map(float)


@settings(max_examples=60, deadline=None)
@given(
    dim=st.sampled_from([2, 3]), n=st.integers(1, 30), k=st.integers(1, 12), self_query=st.booleans(), data=st.data()
)
def test_hypothesis_ties(dim, n, k, self_query, data):
    p = np.array(data.draw(st.lists(st.tuples(*[coords] * dim), min_size=n, max_size=n)), float)
    q = None if self_query else np.array(data.draw(st.lists(st.tuples(*[coords] * dim), min_size=1, max_size=8)), float)
    assert_knn_equal(knn(p, k, q), brute_knn(p, k, q))


def test_kdtree_radius_methods_validate_and_match(rng):
    p = rng.random((300, 2))
    tree = KDTree(p)
    with pytest.raises(InputError, match="radius"):
        tree.radius_neighbors(None, -1.0)
    with pytest.raises(InputError, match="radius"):
        tree.radius_pairs(float("nan"))
    from .reference import brute_pairs, brute_radius

    off, ind = tree.radius_neighbors(p[:20] + 0.01, 0.1)
    want = brute_radius(p, 0.1, p[:20] + 0.01)
    np.testing.assert_array_equal(off, want[0])
    np.testing.assert_array_equal(ind, want[1])
    np.testing.assert_array_equal(tree.radius_pairs(0.1), brute_pairs(p, 0.1))
