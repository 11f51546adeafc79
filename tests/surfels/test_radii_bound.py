"""The radius bound (``MAX_FACTOR``) keeps splats at thin features small and the surface closed."""

import numpy as np

from unmesh.shapes import Blob
from unmesh.spatial import KDTree
from unmesh.surfels.radii import MAX_FACTOR
from unmesh.surfels.sampling import sample_mesh


def _surface_points(mesh, count, rng):
    areas = mesh.face_areas()
    tri = rng.choice(len(areas), count, p=areas / areas.sum())
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    f, v = mesh.faces[tri], mesh.vertices
    return (1 - r1)[:, None] * v[f[:, 0]] + (r1 * (1 - r2))[:, None] * v[f[:, 1]] + (r1 * r2)[:, None] * v[f[:, 2]]


def test_ldc_radii_are_bounded_and_cover_the_blob():
    rng = np.random.default_rng(0)
    mesh = Blob().mesh(0.04)
    d = 0.06
    cloud = sample_mesh(mesh, d)
    tree = KDTree(cloud.positions)
    dist, _ = tree.knn(None, 9)  # the point itself and its k = 8 nearest neighbours
    ratio = cloud.radii / dist[:, 8]
    assert ratio.max() <= MAX_FACTOR * 1.05 * (1 + 1e-12)  # the bound, with the default margin
    assert cloud.radii.max() <= np.sqrt(3.0) * d * (1 + 1e-12)  # LDC's covering distance
    # Brute-force covering: every dense random surface point lies in some splat's disc (near its plane).
    pts = _surface_points(mesh, 20_000, rng)
    _, near = tree.knn(pts, 16)
    rel = pts[:, None, :] - cloud.positions[near]
    h = np.einsum("qki,qki->qk", rel, cloud.normals[near])
    tang2 = np.einsum("qki,qki->qk", rel, rel) - h * h
    inside = (tang2 <= cloud.radii[near] ** 2) & (np.abs(h) <= 0.5 * d)
    assert inside.any(axis=1).all()


def test_poisson_blob_radii_are_bounded_and_cover_the_ears():
    rng = np.random.default_rng(1)
    blob = Blob()
    d = 0.05
    cloud = blob.surfels(d)
    tree = KDTree(cloud.positions)
    dist, _ = tree.knn(None, 9)
    assert (cloud.radii / dist[:, 8]).max() <= MAX_FACTOR * 1.05 * (1 + 1e-12)
    pts = _surface_points(blob.mesh(0.02), 20_000, rng)  # the fine mesh is within 0.1 d of the surface
    _, near = tree.knn(pts, 16)
    rel = pts[:, None, :] - cloud.positions[near]
    h = np.einsum("qki,qki->qk", rel, cloud.normals[near])
    tang2 = np.einsum("qki,qki->qk", rel, rel) - h * h
    inside = (tang2 <= cloud.radii[near] ** 2) & (np.abs(h) <= 0.5 * d)
    assert inside.any(axis=1).all()


def test_blob_ear_tips_get_no_oversized_splats():
    """Issue 23 item 8: at the gallery's density (size / 60) the ear tips (curvature radius ~0.01,
    below the spacing ~0.03) got splats up to 2.95x the median neighbour distance (18 above 2x,
    99.9th percentile 2.7x). With ``smooth=True`` the samples round the tip bound the cells:
    at most 0.1 % of the radii above 2x, 99.9th percentile <= 1.8x, maximum <= 2.7x; and the
    splats still cover the surface."""
    rng = np.random.default_rng(3)
    blob = Blob()
    h = blob.size() / 60
    cloud = blob.surfels(h)
    tree = KDTree(cloud.positions)
    dist, _ = tree.knn(None, 2)
    ratio = cloud.radii / np.median(dist[:, 1])
    assert np.mean(ratio > 2.0) <= 1e-3
    assert np.percentile(ratio, 99.9) <= 1.8
    assert ratio.max() <= 2.7
    pts = _surface_points(blob.mesh(0.4 * h), 20_000, rng)
    _, near = tree.knn(pts, 16)
    rel = pts[:, None, :] - cloud.positions[near]
    hh = np.einsum("qki,qki->qk", rel, cloud.normals[near])
    tang2 = np.einsum("qki,qki->qk", rel, rel) - hh * hh
    inside = (tang2 <= cloud.radii[near] ** 2) & (np.abs(hh) <= 0.5 * h)
    assert inside.any(axis=1).all()
