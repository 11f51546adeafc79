"""Splat radii: the restricted Voronoi rule gives overlapping, covering splats."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.shapes import Disc, Sphere, Torus
from unmesh.spatial import knn
from unmesh.surfels import SurfelCloud, estimate_radii, tangent_frame
from unmesh.surfels._radii_kernels import voronoi_radii
from unmesh.surfels.radii import voronoi_radii_reference

from .helpers import uncovered


def test_kernel_matches_the_reference(rng):
    pts = Torus().surfels(0.15).positions + rng.normal(scale=0.01, size=(1, 3))
    nrm = Torus().surfels(0.15).normals
    sub = slice(0, 120)
    _, idx = knn(pts, 9)
    clip = np.full(len(pts), 0.4)
    for oriented in (True, False):
        r, o = voronoi_radii(pts, nrm, idx, clip, oriented, 0.25, 0.0)
        r_ref, o_ref = voronoi_radii_reference(pts, nrm, idx, clip, oriented, 0.25, rows=range(120))
        np.testing.assert_allclose(r[sub], r_ref[sub], rtol=1e-9)
        np.testing.assert_array_equal(o[sub], o_ref[sub])
    # the smooth-surface variant: facing-away threshold -0.5, bounds pulled in to the tangential offset
    r, o = voronoi_radii(pts, nrm, idx, clip, True, -0.5, 1.0)
    r_ref, o_ref = voronoi_radii_reference(pts, nrm, idx, clip, True, -0.5, rows=range(40), reach=1.0)
    np.testing.assert_allclose(r[:40], r_ref[:40], rtol=1e-9)
    np.testing.assert_array_equal(o[:40], o_ref[:40])


def test_reach_pulls_in_a_steep_neighbour():
    # one neighbour at tangential offset 1 and 3 below the plane: the plain 3-D bisector is at
    # (1 + 9) / 2 = 5 along it, the smooth variant stops at its tangential offset 1
    pts = np.array([[0.0, 0, 0], [1.0, 0, -3.0]] + [[np.cos(a), np.sin(a), 0.0] for a in (1.6, 3.2, 4.8)])
    nrm = np.tile([0.0, 0.0, 1.0], (5, 1))
    nbrs = np.array([[1, 2, 3, 4]] + [[-1] * 4] * 4)
    clip = np.full(5, 100.0)
    plain, _ = voronoi_radii(pts, nrm, nbrs, clip, True, -0.5, 0.0)
    pulled, _ = voronoi_radii(pts, nrm, nbrs, clip, True, -0.5, 1.0)
    ref, _ = voronoi_radii_reference(pts, nrm, nbrs, clip, True, -0.5, rows=[0], reach=1.0)
    assert plain[0] > 4.0 and pulled[0] < plain[0]
    np.testing.assert_allclose(pulled[0], ref[0], rtol=1e-9)


def test_regular_grids_give_the_exact_voronoi_radius():
    g = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0), indexing="ij"), -1).reshape(-1, 2)
    pts = np.c_[g, np.zeros(len(g))]
    nrm = np.tile([0.0, 0.0, 1.0], (len(g), 1))
    r = estimate_radii(pts, nrm, margin=1.0)
    interior = (g.min(axis=1) > 0) & (g.max(axis=1) < 11)
    np.testing.assert_allclose(r[interior], np.sqrt(0.5), rtol=1e-12)
    # hexagonal lattice: circumradius of the hexagonal cell, 1/sqrt(3) of the spacing
    rows = [np.c_[np.arange(12) + 0.5 * (j % 2), np.full(12, j * np.sqrt(3) / 2)] for j in range(12)]
    h = np.concatenate(rows)
    hp = np.c_[h, np.zeros(len(h))]
    rh = estimate_radii(hp, nrm, margin=1.0)
    inner = (h[:, 0] > 1) & (h[:, 0] < 10) & (h[:, 1] > 1) & (h[:, 1] < 8.5)
    np.testing.assert_allclose(rh[inner], 1 / np.sqrt(3), rtol=1e-9)
    # boundary samples reach past the last row: the corner of the square grid is covered
    assert r[0] >= np.sqrt(2) and np.all(r[~interior] >= 1.0)


def test_random_planar_points_are_covered(rng):
    pts = np.c_[rng.random((3000, 2)), np.zeros(3000)]
    nrm = np.tile([0.0, 0.0, 1.0], (3000, 1))
    cloud = SurfelCloud(pts, nrm, radii=estimate_radii(pts, nrm))
    q = np.c_[rng.random((50000, 2)), np.zeros(50000)]
    assert len(uncovered(cloud, q)) == 0
    # never larger than needed by much: the mean radius is about the Voronoi cell size
    assert np.mean(cloud.radii) < 1.5 / np.sqrt(3000)


@pytest.mark.parametrize("oriented", [True, False])
def test_curved_surfaces_with_and_without_normals(oriented, rng):
    cloud = Sphere(radius=1.0).surfels(0.08)
    pts = cloud.positions
    r = estimate_radii(pts, cloud.normals if oriented else None)
    splats = SurfelCloud(pts, cloud.normals, radii=r)
    dense = Sphere(radius=1.0).surfels(0.01)
    assert len(uncovered(splats, dense.positions, dense.normals, 0.1, 0.5)) == 0
    # neighbouring splats overlap: each disc reaches past half the way to its nearest neighbours
    d, i = knn(pts, 4)
    assert np.all(r[:, None] + r[i[:, 1:]] > d[:, 1:])


def test_thin_parts_ignore_the_other_side():
    # two parallel sheets 0.02 apart sampled at 0.1: the other sheet must not shrink the cells
    top = Disc(center=(0, 0.01, 0), radius=1.0).surfels(0.1)
    bottom = Disc(center=(0, -0.01, 0), radius=1.0, normal=(0, -1, 0)).surfels(0.1)
    pts = np.concatenate([top.positions, bottom.positions])
    nrm = np.concatenate([top.normals, bottom.normals])
    r = estimate_radii(pts, nrm)
    alone = estimate_radii(top.positions, top.normals)
    np.testing.assert_allclose(r[: len(top)], alone, rtol=1e-9)


def test_radius_rule_input_checks():
    pts = np.random.default_rng(0).random((20, 3))
    with pytest.raises(InputError, match="k"):
        estimate_radii(pts, k=2)
    with pytest.raises(InputError, match="margin"):
        estimate_radii(pts, margin=0.5)
    with pytest.raises(InputError, match="normals"):
        estimate_radii(pts, np.zeros((20, 3)))
    assert estimate_radii(np.zeros((1, 3))).tolist() == [1.0]
    assert estimate_radii(np.zeros((0, 3))).shape == (0,)
    t1, _ = tangent_frame(np.array([[0.0, 0.0, 1.0]]))
    assert t1.shape == (1, 3)
