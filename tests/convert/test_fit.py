"""Least-squares vertex fit of the simplified mesh (6.1) and the refinement stall rule (6.2.1)."""

import numpy as np

from unmesh.convert.fit import fit_vertices
from unmesh.convert.patches import render_patches, spacings
from unmesh.convert.simplify import mesh_distance
from unmesh.meshes import TriangleMesh
from unmesh.shapes import Sphere
from unmesh.spatial import TriangleBVH
from unmesh.surfels import SurfelCloud

from .conftest import fibonacci_sphere


def _signed(mesh: TriangleMesh, pts: np.ndarray) -> np.ndarray:
    d, f, q, _ = TriangleBVH(mesh.vertices, mesh.faces).closest(pts)
    return np.sign(np.einsum("ij,ij->i", pts - q, mesh.face_normals()[f])) * d


def test_fit_centres_an_inscribed_sphere_mesh_on_the_surfels():
    p = fibonacci_sphere(6000)
    cloud = SurfelCloud(p, p, radii=np.full(len(p), 0.05))
    mesh = Sphere().mesh(0.4)  # vertices on the unit sphere: every face is a chord inside it
    fit = fit_vertices(mesh, cloud)
    before, after = _signed(mesh, p), _signed(fit, p)
    assert (fit.faces == mesh.faces).all()
    assert before.mean() > 0.01  # all surfels outside the inscribed mesh
    assert abs(after.mean()) < 0.02 * before.mean()  # least squares: mean signed distance ~ 0
    # a chord's deviation d splits into about +-d/2 (here 0.040 -> 0.029, the corners stay exact)
    assert np.abs(after).max() < 0.8 * np.abs(before).max()
    assert max(mesh_distance(fit, cloud)) < max(mesh_distance(mesh, cloud))
    r = np.linalg.norm(fit.vertices, axis=1)
    assert r.min() > 1.0 and r.std() < 0.01 * r.mean()  # every vertex moved outwards alike


def test_fit_keeps_a_mesh_that_already_lies_on_flat_surfels():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 1, size=(3000, 2))
    pts = np.c_[xy, np.zeros(3000)]
    cloud = SurfelCloud(pts, np.tile([0.0, 0, 1], (3000, 1)), radii=np.full(3000, 0.03))
    mesh = TriangleMesh([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]],
                        [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    assert np.abs(fit_vertices(mesh, cloud).vertices - mesh.vertices).max() < 1e-9


def test_refinement_stalls_on_normals_the_surfels_do_not_resolve():
    """A flat square whose surfel normals jitter by ~10 degrees at random: the normal error
    (6.2) has a floor of ~0.015 > 0.005 at every level, so without the stall rule every
    patch went on to max_level; with it they stop one level after the texels became as fine
    as the surfels and are reported capped."""
    rng = np.random.default_rng(2)
    n = 20000
    pts = np.c_[rng.uniform(0, 1, size=(n, 2)), np.zeros(n)]
    nrm = np.c_[rng.normal(scale=0.17, size=(n, 2)), np.ones(n)]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    radius = 0.012
    cloud = SurfelCloud(pts, nrm, radii=np.full(n, radius), colors=np.full((n, 3), 0.5))
    mesh = TriangleMesh([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    max_level = 9
    pa = render_patches(mesh, cloud, texture_error=0.02, normal_error=0.005, max_level=max_level)
    spacing = np.sqrt(2.0) / spacings(pa.level)  # the longest edge is the diagonal
    assert (pa.level < max_level).all()
    assert pa.capped.all() and (pa.normal_error > 0.005).all()
    assert (spacing <= radius).all() and (spacing > radius / 4).all()
