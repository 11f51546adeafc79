"""LDC sampling of triangle meshes (thesis section 3.3 and chapter 6)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.shapes import Blob, Box, Cylinder, Disc, MeshShape, Sphere, Torus, euler_rotation
from unmesh.spatial import knn
from unmesh.surfels import SurfelCloud, from_points, sample_mesh
from unmesh.surfels.sampling import _texture_lookup, ldc_reference, ldc_samples

from .helpers import random_surface_points, uncovered

SQRT3 = np.sqrt(3.0)


def unique_rows(p):
    return np.unique(np.round(p, 10), axis=0)


# long thin diagonal triangles (generic coordinates: no ray passes exactly through the open boundary)
SLIVERS = TriangleMesh([[0.0123, 0.0071, 0.0], [1.0123, 1.0031, 0.3], [0.0223, -0.0029, 0.02], [1.0223, 0.9931, 0.32]],
                       [[0, 1, 2], [2, 1, 3]])


@pytest.mark.parametrize("mesh", [Sphere(radius=0.8).mesh(resolution=10), Box(size=(1, 0.6, 0.4)).mesh(resolution=6),
                                  Torus(major=0.6, minor=0.2, axis=(1, 1, 0)).mesh(resolution=12), SLIVERS],
                         ids=["sphere", "box", "torus", "slivers"])
def test_kernel_matches_reference(mesh):
    for d in (0.1, 0.037, 0.0031):
        p, face, bary = ldc_samples(mesh.vertices, mesh.faces, d)
        if d < 0.01 and len(mesh.faces) > 2:
            continue  # the reference is slow; fine spacings only for the slivers
        ref = ldc_reference(mesh.vertices, mesh.faces, d)
        # The reference counts a ray through a shared edge once per triangle; the kernel exactly once.
        np.testing.assert_allclose(unique_rows(p), unique_rows(ref), atol=1e-9)
        assert len(unique_rows(p)) == len(p)
        # positions are the barycentric combinations of the face's vertices
        np.testing.assert_allclose(np.einsum("nk,nki->ni", bary, mesh.vertices[mesh.faces[face]]), p, atol=1e-12)
        np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)
        assert bary.min() >= -1e-12


def test_samples_lie_on_the_mesh_and_on_lattice_rays():
    mesh = Blob().mesh(0.05)
    d = 0.03
    cloud = sample_mesh(mesh, d)
    dist, _, _ = MeshShape(mesh).closest_points(cloud.positions)
    assert dist.max() < 1e-12
    # two of the three coordinates of every sample are lattice coordinates (i + 1/2) d
    frac = np.abs(cloud.positions / d - 0.5 - np.round(cloud.positions / d - 0.5))
    assert np.all((frac < 1e-9).sum(axis=1) >= 2)


@pytest.mark.parametrize("shape,d", [(Sphere(radius=1.0), 0.1), (Sphere(radius=0.5, center=(0.3, 0.1, 0)), 0.07),
                                     (Box(size=(1.0, 1.0, 1.0)), 0.1), (Box(size=(1.0, 0.7, 0.3)), 0.05),
                                     (Box(size=(1.0, 0.8, 0.6), rotation=euler_rotation([30, 40, 50])), 0.08)],
                         ids=["sphere", "sphere-off", "cube-aligned", "box", "box-rotated"])
def test_maximum_sample_distance_is_at_most_sqrt3_d(shape, d):
    mesh = shape.mesh(resolution=40)
    cloud = sample_mesh(mesh, d)
    pts, _ = random_surface_points(mesh, 60000, np.random.default_rng(0))
    corners = mesh.vertices  # include every vertex (box corners are the worst case)
    dist, _ = knn(cloud.positions, 1, queries=np.concatenate([pts, corners]))
    assert dist.max() <= SQRT3 * d
    assert dist.max() > 0.3 * d  # and the bound is not vacuous


@settings(max_examples=12, deadline=None)
@given(angles=st.lists(st.floats(-180, 180), min_size=3, max_size=3), d=st.floats(0.06, 0.2),
       shift=st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_sqrt3_bound_under_any_placement(angles, d, shift):
    m = np.eye(4)
    m[:3, :3] = euler_rotation(angles)
    m[:3, 3] = shift
    mesh = Torus(major=0.7, minor=0.3).mesh(resolution=30).transformed(m)
    cloud = sample_mesh(mesh, d)
    pts, _ = random_surface_points(mesh, 20000, np.random.default_rng(1))
    dist, _ = knn(cloud.positions, 1, queries=pts)
    assert dist.max() <= SQRT3 * d


@pytest.mark.parametrize("shape", [Sphere(), Box(size=(1.0, 0.6, 0.4), rotation=euler_rotation([10, 20, 30])),
                                   Cylinder(radius=0.4, height=1.0), Torus(), Disc(), Blob()],
                         ids=lambda s: type(s).__name__)
def test_splats_cover_meshes_of_the_built_in_shapes(shape):
    mesh = shape.mesh(resolution=96 if isinstance(shape, Blob) else 48)  # resolve the blob's ear tips
    d = shape.size() / 40
    cloud = sample_mesh(mesh, d)
    pts, nrm = random_surface_points(mesh, 100000, np.random.default_rng(2))
    bad = uncovered(cloud, pts, nrm, offset_frac=0.25, min_dot=0.5)
    assert len(bad) == 0, f"{len(bad)} uncovered"
    np.testing.assert_allclose(np.linalg.norm(cloud.normals, axis=1), 1.0)
    assert np.all(np.einsum("ij,ij->i", cloud.normals, shape.implicit(cloud.positions)[1]) > 0.9)


def test_normals_from_vertex_normals_and_orientation():
    m = Sphere().mesh(resolution=8)  # carries exact vertex normals
    cloud = sample_mesh(m.replace(vertex_normals=None), 0.2)
    flat = cloud.normals
    _, face, _ = ldc_samples(m.vertices, m.faces, 0.2)  # same order as the cloud
    np.testing.assert_allclose(flat, m.face_normals()[face], atol=1e-12)
    smooth = sample_mesh(m, 0.2).normals
    # interpolated vertex normals of a sphere are closer to the exact normal than face normals
    exact = cloud.positions / np.linalg.norm(cloud.positions, axis=1, keepdims=True)
    assert np.mean(np.einsum("ij,ij->i", smooth, exact)) > np.mean(np.einsum("ij,ij->i", flat, exact))
    # vertex normals that point inward are flipped to agree with the faces
    inward = sample_mesh(m.replace(vertex_normals=-m.vertex_normals), 0.2).normals
    np.testing.assert_allclose(inward, smooth, atol=1e-12)


def test_colors_from_vertex_colors_and_texture():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2]])
    vc = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    cloud = sample_mesh(TriangleMesh(v, f, vertex_colors=vc), 0.1)
    bary = np.c_[1 - cloud.positions[:, 0] - cloud.positions[:, 1], cloud.positions[:, :2]]
    np.testing.assert_allclose(cloud.colors, bary @ vc, atol=1e-12)
    # texture: left half red, right half blue; uv = xy
    tex = np.zeros((4, 8, 3))
    tex[:, :4, 0] = 1.0
    tex[:, 4:, 2] = 1.0
    cloud = sample_mesh(TriangleMesh(v, f, uv=v[:, :2], texture=tex), 0.05)
    x = cloud.positions[:, 0]
    assert np.all(cloud.colors[x < 0.4, 0] > 0.99) and np.all(cloud.colors[(x > 0.6) & (x < 0.9), 2] > 0.99)
    # bilinear: halfway between texel centres, row 0 at the top (v = 1)
    img = np.zeros((2, 2, 3))
    img[0, 0] = 1.0  # top-left texel
    np.testing.assert_allclose(_texture_lookup(img, np.array([[0.25, 0.75], [0.5, 0.5], [0.25, 0.25]]))[:, 0],
                               [1.0, 0.25, 0.0])
    assert np.allclose(sample_mesh(TriangleMesh(v, f), 0.1).colors, 0.8)


def test_open_meshes_degenerate_triangles_and_unreferenced_vertices():
    mesh = Sphere().mesh(resolution=12)
    keep = np.ones(len(mesh.faces), bool)
    keep[::17] = False  # holes
    v = np.concatenate([mesh.vertices, [[9.0, 9.0, 9.0]]])  # unreferenced vertex far away
    f = np.concatenate([mesh.faces[keep], [[0, 0, 1], [1, 2, 1]]])  # degenerate triangles
    holey = TriangleMesh(v, f)
    cloud = sample_mesh(holey, 0.08)
    assert len(cloud) > 100 and np.all(np.isfinite(cloud.positions))
    assert np.abs(cloud.positions).max() < 1.01
    pts, nrm = random_surface_points(holey, 50000, np.random.default_rng(3))
    assert len(uncovered(cloud, pts, nrm, 0.25, 0.5)) == 0


def test_spacing_errors():
    m = Sphere().mesh(resolution=8)
    with pytest.raises(InputError, match="spacing"):
        sample_mesh(m, 0.0)
    with pytest.raises(InputError, match="would create about"):
        sample_mesh(m, 1e-6)
    with pytest.raises(InputError, match="too coarse"):
        sample_mesh(TriangleMesh([[0.01, 0.01, 0], [0.02, 0.01, 0], [0.01, 0.02, 0]], [[0, 1, 2]]), 10.0)
    with pytest.raises(InputError, match="TriangleMesh"):
        sample_mesh(np.zeros((3, 3)), 0.1)


def test_from_points_estimates_what_is_missing(rng):
    pts = Sphere(radius=2.0).surfels(0.15).positions
    cloud = from_points(pts, colors=np.tile([0.1, 0.2, 0.3], (len(pts), 1)))
    assert isinstance(cloud, SurfelCloud) and len(cloud) == len(pts)
    assert np.all(np.einsum("ij,ij->i", cloud.normals, pts / 2.0) > 0.99)
    given_r = np.full(len(pts), 0.5)
    assert np.all(from_points(pts, normals=pts, radii=given_r).radii == 0.5)
    with pytest.raises(InputError):
        from_points(pts, radii=np.ones(3))
