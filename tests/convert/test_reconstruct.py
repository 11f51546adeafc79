"""Reconstruction (6.1): closed inputs give closed manifold meshes, open ones keep their holes."""

import numpy as np
import pytest

from unmesh.convert.reconstruct import MIN_POINTS, clean_mesh, disc_distance, reconstruct
from unmesh.convert.simplify import mesh_distance, simplify_mesh, simplify_to_error, topology
from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.spatial import TriangleBVH
from unmesh.surfels import SurfelCloud


def test_closed_sphere_gives_closed_manifold_mesh_on_the_surface(sphere_cloud):
    mesh = reconstruct(sphere_cloud)
    euler, boundary, manifold = topology(mesh)
    assert (euler, boundary, manifold) == (2, 0, True)
    assert np.abs(np.linalg.norm(mesh.vertices, axis=1) - 1).max() < 2e-3
    assert mesh.volume() > 0  # outward faces


def test_open_hemisphere_keeps_its_boundary(sphere_cloud):
    cap = sphere_cloud.subset(sphere_cloud.positions[:, 2] > 0.0)
    mesh = reconstruct(cap)
    _, boundary, manifold = topology(mesh)
    assert boundary > 0 and manifold
    h = 3.0 * np.median(cap.radii)
    # no cap over the hole (it would reach z = -1): the rim ends within a cell of the discs
    assert mesh.vertices[:, 2].min() > -(h + 2 * cap.radii.max())
    inner = mesh.vertices[mesh.vertices[:, 2] > h]  # away from the rim, where MLS extrapolates
    assert np.abs(np.linalg.norm(inner, axis=1) - 1).max() < 2e-3


def test_too_few_points_is_a_one_line_error():
    c = SurfelCloud(np.eye(3) * [1, 2, 3], np.eye(3), radii=[1.0, 1.0, 1.0])
    with pytest.raises(InputError, match=f"at least {MIN_POINTS}"):
        reconstruct(c)


def test_disc_distance_matches_brute_force():
    rng = np.random.default_rng(3)
    pos = rng.normal(size=(50, 3))
    nrm = rng.normal(size=(50, 3))
    c = SurfelCloud(pos, nrm, radii=rng.uniform(0.1, 0.4, 50))
    q = rng.normal(size=(30, 3))
    d = q[:, None] - c.positions[None]
    dn = np.einsum("qkj,kj->qk", d, c.normals)
    tang = np.linalg.norm(d - dn[..., None] * c.normals[None], axis=2)
    ref = np.sqrt(np.maximum(tang - c.radii, 0) ** 2 + dn**2).min(axis=1)
    assert np.allclose(disc_distance(q, c, k=50), ref)


def test_clean_mesh_drops_degenerate_faces_and_small_components():
    m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], [[0, 1, 2], [0, 0, 1]])
    out = clean_mesh(m, min_component=1)
    assert len(out.faces) == 1 and len(out.vertices) == 3
    assert len(clean_mesh(m, min_component=2).faces) == 0


def test_simplification_meets_the_bound_both_ways_and_keeps_topology(sphere_cloud):
    mesh = reconstruct(sphere_cloud)
    bound = 0.01 * np.linalg.norm(np.ptp(sphere_cloud.positions, axis=0))
    small, rec = simplify_to_error(mesh, sphere_cloud, bound)
    assert rec["met"] and len(small.faces) < len(mesh.faces) / 4
    assert topology(small) == topology(mesh)
    # Hausdorff both ways, brute force over the surfel centres and dense mesh samples
    d_sm, _, _, _ = TriangleBVH(small.vertices, small.faces).closest(sphere_cloud.positions)
    assert d_sm.max() <= bound
    rng = np.random.default_rng(0)
    f = small.faces[rng.integers(0, len(small.faces), 5000)]
    b = rng.dirichlet(np.ones(3), 5000)
    pts = np.einsum("nk,nkj->nj", b, small.vertices[f])
    assert disc_distance(pts, sphere_cloud).max() <= bound
    assert max(mesh_distance(small, sphere_cloud)) == pytest.approx(rec["error"])


def test_face_target():
    from unmesh.shapes import Sphere

    mesh = Sphere().mesh(0.1)
    small = simplify_mesh(mesh, 120)
    assert len(small.faces) <= 120 and topology(small) == topology(mesh)
