"""The paint buffer's pixel-ownership kernels against the kd-tree (exact, ties by index)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.paint._buffer_kernels import grid_knn2d
from unmesh.paint.transfer import nearest, owners, pixel_owners_reference
from unmesh.spatial import KDTree


def _pixels(W, H, h, lo):
    cu = ((np.arange(W) + 0.5) - 0.5 * W) * h + (lo[0] + 0.5 * W * h)
    cv = (0.5 * H - (np.arange(H) + 0.5)) * h + (lo[1] + 0.5 * H * h)
    U, V = np.meshgrid(cu, cv)
    return np.stack([U.ravel(), V.ravel()], axis=1)


def _clouds():
    rng = np.random.default_rng(3)
    yield rng.random((300, 2)) - 0.5, _pixels(60, 50, 0.02, (-0.6, -0.5))
    # a dense cluster (children) inside sparse originals, queries reaching beyond the points
    dense = 0.05 * rng.random((400, 2))
    sparse = rng.random((80, 2)) * 2 - 1
    yield np.concatenate([sparse, dense]), _pixels(40, 70, 0.04, (-1.2, -1.5))
    # a lattice: many exact ties (equal distances), duplicated points
    g = np.stack(np.meshgrid(np.arange(12.0), np.arange(9.0)), axis=-1).reshape(-1, 2) * 0.125
    yield np.concatenate([g, g[:20]]), _pixels(30, 30, 0.0625, (-0.3, -0.2))
    # fewer points than k, and a single point
    yield rng.random((5, 2)), rng.random((40, 2)) * 3
    yield np.array([[0.3, 0.1]]), rng.random((10, 2))


@pytest.mark.parametrize("k", [1, 3, 8])
def test_grid_knn2d_equals_the_kd_tree(k):
    for pts, q in _clouds():
        kk = min(k, len(pts))
        dist, idx = np.empty((len(q), kk)), np.empty((len(q), kk), np.int64)
        grid_knn2d(pts, q, kk, dist, idx)
        rd, ri = KDTree(pts).knn(q, kk)
        np.testing.assert_array_equal(idx, ri)
        np.testing.assert_array_equal(dist, rd)


def test_pixel_owners_and_nearest_equal_their_references():
    rng = np.random.default_rng(4)
    for pts, q in _clouds():
        rad = 0.01 + 0.1 * rng.random(len(pts))
        rad[::7] = rad[0]  # equal ratios: the first in (distance, index) order wins
        kk = min(8, len(pts))
        own, ratio = owners(pts, rad, q, kk)
        ro, rr = pixel_owners_reference(pts, rad, q, kk)
        np.testing.assert_array_equal(own, ro)
        np.testing.assert_array_equal(ratio, rr)
        d, i = nearest(pts, q)
        rd, ri = KDTree(pts).knn(q, 1)
        np.testing.assert_array_equal(i, ri[:, 0])
        np.testing.assert_array_equal(d, rd[:, 0])


def test_ball_knn_equals_the_kd_tree_inside_and_outside_its_ball():
    from unmesh.paint.collide import BallKnn

    rng = np.random.default_rng(7)
    g = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), axis=-1).reshape(-1, 2) * 0.05
    pts = np.concatenate([np.c_[g, np.zeros(len(g))], np.c_[g[:50], np.zeros(50)]])  # ties and duplicates
    tree = KDTree(pts)
    ball = BallKnn(tree, np.array([0.5, 0.5, 0.0]), 0.3)
    q = np.concatenate([np.array([0.5, 0.5, 0.0]) + 0.1 * rng.standard_normal((60, 3)),
                        rng.random((20, 3)) * 1.2, np.c_[g[:10], np.full(10, 0.02)]])
    for k in (1, 10):
        d, i = ball.knn(q, k)
        rd, ri = tree.knn(q, k)
        np.testing.assert_array_equal(i, ri)
        np.testing.assert_array_equal(d, rd)


def test_radius_neighbors_few_queries_equal_the_paired_trees():
    import unmesh.spatial.kdtree as kd

    rng = np.random.default_rng(8)
    tree = KDTree(rng.random((3000, 3)))
    q = rng.random((kd._FEW_QUERIES, 3))
    a = tree.radius_neighbors(q, 0.1)
    old = kd._FEW_QUERIES
    try:
        kd._FEW_QUERIES = 0
        b = tree.radius_neighbors(q, 0.1)
    finally:
        kd._FEW_QUERIES = old
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(-6, 6), st.integers(-6, 6)), min_size=1, max_size=60),
       st.lists(st.tuples(st.integers(-20, 20), st.integers(-20, 20)), min_size=1, max_size=30),
       st.integers(1, 8), st.sampled_from([0.25, 0.1, 1.0 / 3.0]))
def test_grid_knn2d_equals_the_kd_tree_on_lattices(points, queries, k, scale):
    # lattice points (many equal distances, duplicates) and queries on a finer lattice, in and
    # far outside the points' box
    pts = np.array(points, float) * scale
    q = np.array(queries, float) * (0.5 * scale)
    k = min(k, len(pts))
    dist, idx = np.empty((len(q), k)), np.empty((len(q), k), np.int64)
    grid_knn2d(pts, q, k, dist, idx)
    rd, ri = KDTree(pts).knn(q, k)
    np.testing.assert_array_equal(idx, ri)
    np.testing.assert_array_equal(dist, rd)


def test_spring_forces_equal_the_numpy_reference_bit_for_bit():
    from unmesh.paint._brush_kernels import spring_forces
    from unmesh.paint.brush import skeleton, spring_forces_reference
    from unmesh.paint.strokes import Brush

    rng = np.random.default_rng(9)
    for kind in ("round", "flat", "pencil"):
        sk = skeleton(Brush(kind, 0.03))
        for _ in range(20):
            x = sk.active + 0.01 * rng.standard_normal(sk.active.shape)
            h = sk.handles + 0.01 * rng.standard_normal(sk.handles.shape)
            out = np.empty((len(x) + len(h), 3))
            spring_forces(x, h, sk.springs, sk.rest, 7.5, out)
            np.testing.assert_array_equal(out, spring_forces_reference(x, h, sk.springs, sk.rest, 7.5))
