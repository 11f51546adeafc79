"""Hierarchical clustering simplification (Pauly, Gross, Kobbelt 2002)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.shapes import Blob, Disc, Sphere
from unmesh.surfels import SurfelCloud, cluster, representatives, simplify
from unmesh.surfels.simplify import cluster_reference


def covariance_stats(p):
    d = p - p.mean(axis=0)
    w = np.linalg.eigvalsh(d.T @ d / len(p))
    return w, (w[0] / w.sum() if w.sum() > 0 else 0.0)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 400), target=st.integers(1, 400), seed=st.integers(0, 10_000))
def test_exactly_target_clusters_every_point_labelled(n, target, seed):
    target = min(target, n)
    pts = np.random.default_rng(seed).normal(size=(n, 3))
    labels = cluster(pts, target=target)
    assert labels.shape == (n,) and labels.dtype == np.int64
    assert labels.min() == 0 and labels.max() == target - 1
    assert np.all(np.bincount(labels, minlength=target) > 0)
    np.testing.assert_array_equal(labels, cluster(pts, target=target))  # deterministic


def test_kernel_matches_reference(rng):
    cloud = Blob().surfels(0.06)
    pts, nrm = cloud.positions, cloud.normals
    for kwargs in ({"target": 57}, {"max_size": 20}, {"max_variation": 0.02}, {"max_size": 50, "max_variation": 0.05}):
        ref = cluster_reference(pts, None, kwargs.get("target", 0), kwargs.get("max_size", 0),
                                kwargs.get("max_variation", -1.0))
        np.testing.assert_array_equal(cluster(pts, **kwargs), ref)
    np.testing.assert_array_equal(cluster(pts, nrm, target=80), cluster_reference(pts, nrm, 80))


def test_split_criteria_are_met():
    pts = Sphere().surfels(0.05).positions
    labels = cluster(pts, max_size=30, max_variation=0.03)
    for c in range(labels.max() + 1):
        sel = pts[labels == c]
        assert len(sel) <= 30
        assert len(sel) < 2 or covariance_stats(sel)[1] <= 0.03


def test_target_mode_gives_clusters_of_similar_extent():
    pts = Sphere().surfels(0.02).positions
    labels = cluster(pts, target=200)
    ext = np.array([covariance_stats(pts[labels == c])[0][2] for c in range(200)])
    assert ext.max() < 4 * np.median(ext)


def test_normals_keep_thin_sheets_apart():
    top = Disc(center=(0, 0.005, 0), radius=1.0).surfels(0.05)
    bottom = Disc(center=(0, -0.005, 0), radius=1.0, normal=(0, -1, 0)).surfels(0.05)
    pts = np.concatenate([top.positions, bottom.positions])
    nrm = np.concatenate([top.normals, bottom.normals])
    labels = cluster(pts, nrm, target=40)
    side = np.r_[np.zeros(len(top)), np.ones(len(bottom))]
    for c in range(40):
        assert len(np.unique(side[labels == c])) == 1


def test_coincident_points_still_split():
    pts = np.zeros((10, 3))
    labels = cluster(pts, target=10)
    assert sorted(labels.tolist()) == list(range(10))


def test_representatives():
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [10, 0, 0], [11, 0, 0]])
    assert representatives(pts, [0, 0, 0, 1, 1]).tolist() == [1, 3]  # tie at 10/11: lowest index
    cloud = Blob().surfels(0.05)
    labels = cluster(cloud.positions, target=100)
    rep = representatives(cloud.positions, labels)
    assert rep.shape == (100,)
    np.testing.assert_array_equal(labels[rep], np.arange(100))
    for c in (0, 37, 99):
        sel = np.flatnonzero(labels == c)
        cen = cloud.positions[sel].mean(axis=0)
        best = sel[np.argmin(np.linalg.norm(cloud.positions[sel] - cen, axis=1))]
        assert rep[c] == best
    with pytest.raises(InputError, match="every label"):
        representatives(pts, [0, 0, 2, 2, 2])


def test_simplify_preserves_the_surface():
    cloud = Blob().surfels(0.03, color=(0.2, 0.4, 0.6))
    cloud = cloud.replace(attributes={"temperature": np.arange(len(cloud), dtype=float),
                                      "id": np.arange(len(cloud))})
    small, labels = simplify(cloud, target=300, return_labels=True)
    assert isinstance(small, SurfelCloud) and len(small) == 300
    np.testing.assert_allclose(small.colors, 0.2 * np.array([[1, 2, 3]]).repeat(300, 0), atol=1e-12)
    # centroids and mean normals
    for c in (0, 150, 299):
        sel = labels == c
        np.testing.assert_allclose(small.positions[c], cloud.positions[sel].mean(axis=0), atol=1e-12)
        m = cloud.normals[sel].sum(axis=0)
        np.testing.assert_allclose(small.normals[c], m / np.linalg.norm(m), atol=1e-12)
        np.testing.assert_allclose(small.attributes["temperature"][c], cloud.attributes["temperature"][sel].mean())
    # each member splat lies inside its cluster's splat (in the new tangent plane)
    rel = cloud.positions - small.positions[labels]
    n = small.normals[labels]
    tang = np.linalg.norm(rel - np.einsum("ij,ij->i", rel, n)[:, None] * n, axis=1)
    assert np.all(tang + cloud.radii <= small.radii[labels] + 1e-12)
    # still on the surface (to the cluster size) and facing outward
    v, nn = Blob().implicit(small.positions)
    assert np.abs(v).max() < 0.05 and np.all(np.einsum("ij,ij->i", nn, small.normals) > 0.5)
    assert np.array_equal(small.attributes["id"], np.asarray(cloud.attributes["id"])[representatives(cloud.positions, labels)])


def test_argument_errors():
    pts = np.random.default_rng(0).random((20, 3))
    with pytest.raises(InputError, match="give target"):
        cluster(pts)
    with pytest.raises(InputError, match="do not combine"):
        cluster(pts, target=3, max_size=4)
    with pytest.raises(InputError, match="at most the number of points"):
        cluster(pts, target=21)
    with pytest.raises(InputError, match="positive integer"):
        cluster(pts, target=0)
    with pytest.raises(InputError, match="max_variation"):
        cluster(pts, max_variation=0.5)
    with pytest.raises(InputError, match="SurfelCloud"):
        simplify(pts, target=3)
