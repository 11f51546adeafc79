"""MLS ray casting of a cloud whose radii vary 5x: geometry, and colours = unmesh.mls.interpolate at the hits."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import SurfelCloud, mls
from unmesh.render import Camera, render


def _varying_sphere(h0: float = 0.04, ratio: float = 5.0) -> SurfelCloud:
    """Golden-spiral unit sphere whose spacing and radii grow ``ratio``-fold from z = -1 to z = 1."""
    b = (ratio - 1.0) / 2.0
    total = (1.0 - 1.0 / ratio) / b
    n = int(np.rint(4 * np.pi / (np.sqrt(3) * h0**2) * total))
    i = np.arange(n) + 0.5
    z = (1.0 / (1.0 - b * i / n * total) - 1.0 - b) / b
    rr = np.sqrt(np.clip(1 - z * z, 0, None))
    p = np.stack([rr * np.cos(2.399963 * i), rr * np.sin(2.399963 * i), z], 1)
    col = np.stack([0.5 + 0.5 * p[:, 0], 0.5 + 0.5 * np.sin(3 * p[:, 1]), 0.5 + 0.5 * p[:, 2]], 1)
    return SurfelCloud(p, p, radii=0.65 * h0 * (1 + b * (z + 1)), colors=col)


def test_raycast_of_varying_radii_matches_the_sphere_and_interpolated_colours():
    cloud = _varying_sphere()
    cam = Camera((3.0, 0.0, 0.0), (0, 0, 0), up=(0, 0, 1), width=80, height=80, ortho=2.4)
    res = render(cloud, cam, method="raycast", shading="none")
    o, d = cam.rays()
    y, z = o[..., 1], o[..., 2]
    r2 = y * y + z * z
    assert res.coverage[r2 < 0.97**2].all()  # both the dense (z < 0) and the coarse (z > 0) half
    assert not res.coverage[r2 > 1.03**2].any()
    inner = r2 < 0.97**2
    exact = 3.0 - np.sqrt(1 - r2[inner])
    assert np.abs(res.depth[inner] - exact).max() < 0.01
    hits = o[res.coverage] + res.depth[res.coverage][:, None] * d[res.coverage]
    want = np.clip(mls.interpolate(cloud, hits, cloud.colors), 0, 1)
    np.testing.assert_allclose(res.color[res.coverage], want, atol=1e-6)


def _isolated_holes(coverage: np.ndarray) -> int:
    """Uncovered pixels with at least 6 of their 8 neighbours covered (speckles inside the silhouette)."""
    p = np.pad(coverage, 1).astype(int)
    nb = sum(np.roll(np.roll(p, i, 0), j, 1) for i in (-1, 0, 1) for j in (-1, 0, 1) if (i, j) != (0, 0))
    return int((~coverage & (nb[1:-1, 1:-1] >= 6)).sum())


@pytest.mark.slow
def test_raycast_of_the_ldc_bunny_has_no_speckles(models_dir):
    """Plain plane steps of Algorithm 3.1 fall into 2-cycles in the bunny's folds (isolated unhit pixels);
    the bracketed iteration of unmesh.mls.intersect hits there."""
    from unmesh.io import load_mesh
    from unmesh.surfels import sample_mesh

    mesh = load_mesh(models_dir / "stanford-bunny.obj")
    cloud = sample_mesh(mesh, float(np.ptp(mesh.vertices, axis=0).max()) / 150)
    res = render(cloud, Camera.framing(cloud.bounds(), 400, 300), method="raycast", shading="none")
    assert res.coverage.sum() > 15000
    assert _isolated_holes(res.coverage) <= 2
