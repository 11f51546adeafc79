"""Meshes and surfel samplings of the built-in shapes."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.shapes import Blob, Box, Cylinder, Disc, Plane, Sphere, Torus, euler_rotation
from unmesh.spatial import knn

from ..surfels.helpers import uncovered

ROT = euler_rotation([10.0, 25.0, -40.0])
CLOSED = [
    Sphere(center=(0.2, 0.0, -0.1), radius=0.7),
    Box(size=(1.0, 0.6, 0.4), rotation=ROT),
    Cylinder(radius=0.35, height=0.9, axis=(0.0, 0.0, 1.0)),
    Torus(major=0.6, minor=0.2, axis=(1.0, 1.0, 0.0)),
]
OPEN = [Disc(radius=0.5, normal=(0, 0, 1)), Plane(size=(1.0, 0.5), normal=(0.0, 1.0, 1.0))]


def euler_characteristic(mesh):
    return len(mesh.vertices) - len(mesh.edges()) + len(mesh.faces)


@pytest.mark.parametrize("shape", CLOSED, ids=lambda s: type(s).__name__)
def test_closed_meshes_are_watertight_outward_and_converge(shape):
    errors = []
    for res in (12, 24, 48):
        m = shape.mesh(resolution=res)
        assert len(m.boundary_edges()) == 0
        assert euler_characteristic(m) == (0 if isinstance(shape, Torus) else 2)
        np.testing.assert_allclose(shape.implicit(m.vertices)[0], 0.0, atol=1e-12)
        # every face points outward: its normal agrees with the implicit gradient at its centroid
        cen = m.vertices[m.faces].mean(axis=1)
        assert np.all(np.einsum("ij,ij->i", m.face_normals(), shape.implicit(cen)[1]) > 0.5)
        errors.append((abs(m.volume() - shape.volume()) / shape.volume(), abs(m.area() - shape.area()) / shape.area()))
    errors = np.array(errors)
    assert errors[-1, 0] < 5e-3 and errors[-1, 1] < 5e-3
    if not isinstance(shape, Box):  # the box mesh is exact at every resolution
        assert np.all(errors[1:, 0] < errors[:-1, 0] / 3)  # second-order convergence
        assert np.all(errors[1:, 1] < errors[:-1, 1] / 3)
    else:
        assert errors.max() < 1e-12


def test_blob_mesh_is_closed_genus_zero_and_converges():
    b = Blob(scale=0.5)
    vols, areas = [], []
    for h in (0.04, 0.02, 0.01):
        m = b.mesh(h)
        assert len(m.boundary_edges()) == 0 and euler_characteristic(m) == 2
        np.testing.assert_allclose(b.implicit(m.vertices)[0], 0.0, atol=1e-13)
        cen = m.vertices[m.faces].mean(axis=1)  # no folded (inward) faces
        assert np.all(np.einsum("ij,ij->i", m.face_normals(), b.implicit(cen)[1]) > 0)
        vols.append(m.volume())
        areas.append(m.area())
    err_v = np.abs(np.array(vols) / b.volume() - 1)
    err_a = np.abs(np.array(areas) / b.area() - 1)
    assert np.all(err_v[1:] < err_v[:-1] / 2.5) and np.all(err_a[1:] < err_a[:-1] / 2.5)  # ~second order
    assert err_v[-1] < 3e-3 and err_a[-1] < 3e-3
    assert b.volume() > 0 and vols[-1] > 0


@pytest.mark.parametrize("shape", OPEN, ids=lambda s: type(s).__name__)
def test_open_meshes(shape):
    m = shape.mesh(resolution=20)
    assert len(m.boundary_edges()) > 0
    assert euler_characteristic(m) == 1  # a topological disc
    np.testing.assert_allclose(shape.implicit(m.vertices)[0], 0.0, atol=1e-12)
    assert np.all(m.face_normals() @ shape.normal > 0.999)
    np.testing.assert_allclose(m.area(), shape.area(), rtol=2e-2)


@pytest.mark.parametrize("shape", [*CLOSED, *OPEN, Blob(scale=0.6, rotation=ROT)], ids=lambda s: type(s).__name__)
def test_surfels_on_the_surface_with_exact_normals_covering_it(shape):
    blob = isinstance(shape, Blob)
    h = shape.size() / (40 if blob else 20)  # the blob's ears are ~size/30 thick: sample them
    cloud = shape.surfels(h, color=(1.0, 0.5, 0.0))
    v, n = shape.implicit(cloud.positions)
    np.testing.assert_allclose(v, 0.0, atol=1e-12 * shape.size())
    assert np.all(np.einsum("ij,ij->i", n, cloud.normals) > 1 - 1e-12)
    np.testing.assert_allclose(cloud.colors, np.tile([1.0, 0.5, 0.0], (len(cloud), 1)))
    # near-uniform: nearest-neighbour distances are about the spacing
    d, _ = knn(cloud.positions, 2)
    med = np.median(d[:, 1])
    assert 0.5 * h < med < 1.2 * h
    # coverage of a dense sampling of the same exact surface, by splats of the same face; the
    # blob's concave blends have curvature radii ~h, where a splat deviates by ~kappa r^2 / 2
    if blob:  # projected marching-cubes vertices: exactly on the surface, cheaper than a fine sampling
        pts = shape.mesh(h / 5).vertices
        nrm = shape.implicit(pts)[1]
    else:
        dense = shape.surfels(h / 6)
        pts, nrm = dense.positions, dense.normals
    bad = uncovered(cloud, pts, nrm, offset_frac=0.5 if blob else 0.2, min_dot=0.0 if blob else 0.5)
    assert len(bad) == 0, f"{len(bad)} of {len(pts)} points uncovered"


def test_box_and_cylinder_surfels_keep_sharp_edges():
    b = Box(size=(1.0, 1.0, 1.0))
    c = b.surfels(0.1)
    # every normal is one of the six face normals
    assert np.all(np.isclose(np.abs(c.normals).max(axis=1), 1.0))
    assert len(np.unique(np.round(c.normals, 9), axis=0)) == 6
    cyl = Cylinder(radius=0.5, height=1.0)
    cc = cyl.surfels(0.1)
    caps = np.abs(cc.normals[:, 1]) > 0.999
    side = np.abs(cc.normals[:, 1]) < 1e-12
    assert np.all(caps | side) and caps.sum() > 0 and side.sum() > 0


def test_mesh_arguments():
    s = Sphere()
    assert len(s.mesh(0.2).faces) < len(s.mesh(0.1).faces)
    with pytest.raises(ValueError, match="not both"):
        s.mesh(0.1, resolution=10)
    with pytest.raises(ValueError, match="resolution"):
        s.mesh(resolution=0)
    with pytest.raises(ValueError, match="spacing"):
        s.surfels(-1.0)
    m = Box().mesh()
    assert m.vertex_normals is None  # sharp edges: no single vertex normal
    assert Sphere().mesh().vertex_normals is not None


def test_blob_candidate_mesh_is_capped_and_the_sampling_still_covers(monkeypatch):
    """Fine samplings draw their candidates from a mesh of at most ``CANDIDATE_CELLS`` cells
    along the blob (memory), and the projected, thinned samples still cover the surface."""
    import unmesh.shapes.blob as blob_mod

    shape = Blob(scale=0.6, rotation=ROT)
    h = shape.size() / 50
    monkeypatch.setattr(blob_mod, "CANDIDATE_CELLS", 30)   # 2.4x coarser than 0.7 h
    seen = []
    real = blob_mod.marching_mesh
    monkeypatch.setattr(blob_mod, "marching_mesh", lambda *a, **k: seen.append(a[3]) or real(*a, **k))
    cloud = shape.surfels(h)
    assert seen == [pytest.approx(shape.size() / 30)]
    v = shape.implicit(cloud.positions)[0]
    np.testing.assert_allclose(v, 0.0, atol=1e-12 * shape.size())
    d, _ = knn(cloud.positions, 2)
    assert 0.5 * h < np.median(d[:, 1]) < 1.2 * h
    monkeypatch.undo()
    pts = shape.mesh(h / 3).vertices          # projected marching-cubes vertices: on the exact surface
    bad = uncovered(cloud, pts, shape.implicit(pts)[1], offset_frac=0.5, min_dot=0.0)
    assert len(bad) == 0, f"{len(bad)} of {len(pts)} points uncovered"
