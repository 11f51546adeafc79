"""Acceptance: LDC sampling of the Stanford bunny and igea covers them without holes."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.spatial import knn
from unmesh.surfels import sample_mesh

from .helpers import random_surface_points, uncovered

#: A surface point counts as covered by a splat within its radius whose plane passes within
#: half a radius of it; scanned meshes have creases where neighbouring triangles differ by
#: tens of degrees, so the plane of the nearest splat can be ~0.3 r off the crease.
OFFSET = 0.5


def check_model(models_dir, name, divisions, count):
    from unmesh.io import load_mesh

    mesh = load_mesh(models_dir / name)
    lo, hi = mesh.bounds()
    d = float(np.linalg.norm(hi - lo)) / divisions
    cloud = sample_mesh(mesh, d)
    pts, nrm = random_surface_points(mesh, count, np.random.default_rng(11))
    bad = uncovered(cloud, pts, nrm, offset_frac=OFFSET, min_dot=0.0)
    assert len(bad) == 0, f"{name}: {len(bad)} of {count} surface points uncovered"
    dist, _ = knn(cloud.positions, 1, queries=pts)
    assert dist.max() <= np.sqrt(3) * d
    # splats stay local: no radius beyond a few spacings
    assert cloud.radii.max() < 6 * d and np.median(cloud.radii) < d
    return cloud


def test_bunny_is_covered(models_dir):
    check_model(models_dir, "stanford-bunny.obj", 200, 200_000)


def test_igea_is_covered(models_dir):
    check_model(models_dir, "igea.ply", 200, 200_000)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stanford-bunny.obj", "igea.ply"])
def test_models_are_covered_at_fine_spacing(models_dir, name):
    check_model(models_dir, name, 600, 1_000_000)
