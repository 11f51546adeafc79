"""Curvature-adaptive Poisson-disk sampling of the blob (issue #23 item 8: the ear-tip splats)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.shapes import Blob, Sphere, Torus
from unmesh.shapes._meshing import marching_mesh, project_to_zero
from unmesh.shapes._sampling import _adaptive_conflicts, local_spacing, poisson_surface, principal_curvatures
from unmesh.shapes.blob import _part_bounds, _parts
from unmesh.spatial import radius_neighbors

from ..surfels.helpers import uncovered


def _ear_tips(blob):
    """The apexes (2,3) of the ear ellipsoids (end of their long semi-axis), projected on the blob."""
    centers, semi, rots, _ = _parts()
    tips = blob.scale * np.array([centers[k] + rots[k] @ np.array([0.0, semi[k, 1], 0.0]) for k in (4, 5)])
    return project_to_zero(blob._implicit_local, tips, 0.01 * blob.scale, 20)


def test_principal_curvatures_match_analytic_values():
    s = Sphere(radius=0.5)
    p = np.array([[0.5, 0.0, 0.0], [0.0, 0.3, 0.4], [-0.3, -0.4, 0.0]])
    np.testing.assert_allclose(principal_curvatures(s.implicit, p, s.implicit(p)[1], 1e-4), 2.0, rtol=1e-6)
    # torus (major R, minor r, axis z): outer equator (1/r, 1/(R+r)); inner equator a saddle (1/r, -1/(R-r));
    # top circle (1/r, 0)
    t = Torus(major=0.6, minor=0.2, axis=(0.0, 0.0, 1.0))
    p = np.array([[0.8, 0.0, 0.0], [0.0, 0.4, 0.0], [0.6, 0.0, 0.2]])
    k = principal_curvatures(t.implicit, p, t.implicit(p)[1], 1e-4)
    np.testing.assert_allclose(k, [[5.0, 1 / 0.8], [5.0, -1 / 0.4], [5.0, 0.0]], atol=1e-5)
    # an ear of the blob far from the blends: the apex of an ellipsoid with semi-axes (a, b, c) along b
    # has curvatures b / a^2 and b / c^2 (the blend changes them by far less than 1 %)
    b = Blob()
    tips = _ear_tips(b)
    _, semi, _, _ = _parts()
    a_, b_, c_ = semi[4]
    k = principal_curvatures(b._implicit_local, tips, b._implicit_local(tips)[1], 1e-5)
    np.testing.assert_allclose(k, [[b_ / c_**2, b_ / a_**2]] * 2, rtol=1e-2)


def test_local_spacing_refines_only_caps_sharper_than_the_spacing():
    h = 0.1
    k = np.array([[5.0, 5.0],      # cap of radius 0.2 > h: unchanged
                  [20.0, 20.0],    # cap of radius 0.05: half the spacing
                  [20.0, 0.0],     # ridge (cylinder): unchanged
                  [20.0, -3.0],    # saddle: unchanged
                  [-20.0, -20.0],  # concave: unchanged
                  [1e6, 1.0]])     # needle: the floor
    np.testing.assert_allclose(local_spacing(k, h, factor=1.0, floor=0.25), [0.1, 0.05, 0.1, 0.1, 0.1, 0.025])


def test_adaptive_conflicts_match_brute_force(rng):
    pts = rng.random((600, 3))
    h = 0.12
    local = np.where(rng.random(600) < 0.5, h, h * rng.uniform(0.25, 1.0, 600))
    off, ind = radius_neighbors(pts, 0.9 * h)
    off2, ind2 = _adaptive_conflicts(pts, local, h, off, ind)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    want = d <= 0.9 * (0.5 * (local[:, None] + local[None]))
    for i in range(len(pts)):
        np.testing.assert_array_equal(np.sort(ind2[off2[i]:off2[i + 1]]), np.flatnonzero(want[i]))


# plastic drop (0.3235 at scale 20), studio, sampling-shapes (size/60 ~ 0.029), plastic drop quick (0.6 at scale 20)
@pytest.mark.parametrize("h", [0.0162, 0.02, 0.028, 0.03])
def test_blob_ear_tips_get_no_oversized_splat_and_stay_covered(h):
    """At the gallery's spacings the ear apex (curvature radius ~0.007, below the spacing) used to
    get one sample with a splat 1.9-2.55x the median radius; the adaptive sampling gives the cap
    several samples with ordinary splats, and the splats still cover the exact surface there."""
    b = Blob()
    cloud = b.surfels(h)
    tips = _ear_tips(b)
    d = np.linalg.norm(cloud.positions[:, None] - tips[None], axis=2).min(axis=1)
    near = d < 3 * h
    assert near.sum() >= 30
    assert cloud.radii[near].max() <= 1.5 * np.median(cloud.radii)
    # projected marching-cubes vertices of boxes round the tips: on the exact surface
    pts = np.concatenate([marching_mesh(b._implicit_local, t - 4 * h, t + 4 * h, h / 5)[0] for t in tips])
    pts = pts[np.linalg.norm(pts[:, None] - tips[None], axis=2).min(axis=1) < 4 * h]
    assert len(pts) > 1000
    bad = uncovered(cloud, pts, b.implicit(pts)[1], offset_frac=0.5, min_dot=0.0)
    assert len(bad) == 0, f"{len(bad)} of {len(pts)} points uncovered"


@pytest.mark.parametrize("h", [0.02, 0.03])
def test_adaptive_sampling_changes_nothing_away_from_the_caps(h):
    """Candidates and conflict rule equal those of the uniform sampling where the local spacing is
    the nominal one, so the samples away from the ears are the same points."""
    b = Blob()
    lo, hi = _part_bounds()
    verts, faces = marching_mesh(b._implicit_local, lo, hi, 0.7 * h, lipschitz=True)
    uniform = poisson_surface(verts, faces, h, b._implicit_local, adaptive=False)
    adaptive = poisson_surface(verts, faces, h, b._implicit_local)
    tips = _ear_tips(b)
    far_u = uniform[np.linalg.norm(uniform[:, None] - tips[None], axis=2).min(axis=1) > 0.35]
    far_a = adaptive[np.linalg.norm(adaptive[:, None] - tips[None], axis=2).min(axis=1) > 0.35]
    assert len(far_u) > 0.9 * len(uniform)
    np.testing.assert_array_equal(far_a, far_u)
    assert 0 < len(adaptive) - len(uniform) < 0.04 * len(uniform)
