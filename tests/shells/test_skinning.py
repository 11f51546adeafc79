"""Surface animation by local frames (7.26-7.30): kernel vs reference, rigid motions, interpolation."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shells.conftest import sphere_with_nodes
from unmesh.shells import CrackSet
from unmesh.shells.skinning import SkinnedSurface, bind_points, deform_reference, skin_weight


@pytest.fixture(scope="module")
def surface():
    cloud, idx = sphere_with_nodes(200, 1500)
    return cloud, idx, SkinnedSurface(cloud, cloud.positions[idx], cloud.normals[idx])


def rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_weight_function_7_30():
    assert np.isinf(skin_weight(np.array([0.0]))[0]) or skin_weight(np.array([0.0]))[0] > 1e20
    np.testing.assert_allclose(skin_weight(np.array([1.0, 1.5])), 0.0)
    w = skin_weight(np.linspace(0.05, 0.95, 10))
    assert np.all(np.diff(w) < 0)


def test_rigid_motion_is_reproduced_exactly(surface, rng):
    cloud, idx, surf = surface
    q = rotation(rng)
    x = cloud.positions[idx] @ q.T + [1.0, -2.0, 0.5]
    out = surf.deform(x, cloud.normals[idx] @ q.T)
    np.testing.assert_allclose(out.positions, cloud.positions @ q.T + [1.0, -2.0, 0.5], atol=1e-10)
    np.testing.assert_allclose(out.normals, cloud.normals @ q.T, atol=1e-8)
    np.testing.assert_allclose(out.radii, cloud.radii, rtol=1e-8)


def test_stretch_is_followed_along_the_frames(surface):
    """Each frame stretches only along e1 (7.26: e2, e3 are unit vectors); a uniformly scaled
    sphere is followed to within the surfel-to-node distance times the stretch."""
    cloud, idx, surf = surface
    out = surf.deform(cloud.positions[idx] * 1.5, cloud.normals[idx])
    r = np.linalg.norm(out.positions, axis=1)
    assert np.abs(r - 1.5).max() < 0.5 * 0.25    # node spacing ~0.25
    assert abs(r.mean() - 1.5) < 0.02
    np.testing.assert_allclose(out.normals, cloud.normals, atol=0.2)


def test_kernel_matches_reference(surface, rng):
    cloud, idx, surf = surface
    x = cloud.positions[idx] * (1 + 0.1 * np.sin(3 * cloud.positions[idx][:, :1])) + rng.normal(scale=0.01,
                                                                                              size=(len(idx), 3))
    n = cloud.normals[idx] + rng.normal(scale=0.05, size=(len(idx), 3))
    out = surf.deform(x, n)
    sel = rng.choice(len(surf), 200, replace=False)
    ref_p, ref_a = deform_reference(surf.node_rest, x, n, surf.node_normals, surf.bind[sel], surf.weights[sel],
                                    surf.points[sel], surf.axes[sel])
    np.testing.assert_allclose(out.positions[sel], ref_p, atol=1e-10)
    np.testing.assert_allclose(out.radii[sel], np.linalg.norm(ref_a, axis=2).max(axis=1), rtol=1e-8)


def test_surfels_at_nodes_follow_their_node(surface, rng):
    """(7.29) interpolates: a surfel at a node moves exactly with it."""
    cloud, idx, surf = surface
    x = cloud.positions[idx] + rng.normal(scale=0.05, size=(len(idx), 3))
    out = surf.deform(x, cloud.normals[idx])
    np.testing.assert_allclose(out.positions[idx], x, atol=1e-12)


def test_deformation_is_smooth(surface):
    """A smooth deformation field moves nearby surfels by nearly the same amount."""
    cloud, idx, surf = surface
    disp = lambda p: 0.1 * np.stack([np.sin(p[:, 1]), np.cos(p[:, 2]), p[:, 0] ** 2], axis=1)  # noqa: E731
    out = surf.deform(cloud.positions[idx] + disp(cloud.positions[idx]), cloud.normals[idx])
    err = np.linalg.norm(out.positions - cloud.positions - disp(cloud.positions), axis=1)
    assert err.max() < 0.02   # node spacing ~0.25: interpolation error second order


def test_visibility_binds_to_one_side_of_a_crack():
    nodes = np.array([[x, 0.0, z] for x in np.linspace(-1, 1, 9) for z in np.linspace(-1, 1, 9)])
    cracks = CrackSet()
    cracks.add([0.0, 0, 0], [1.0, 0, 0], 5.0, 0, 0.0)
    pts = np.array([[-0.1, 0.0, 0.05], [0.1, 0.0, -0.05]])
    bind, _w = bind_points(pts, nodes, 6, blocked=cracks.blocked)
    assert np.all(nodes[bind[0][bind[0] >= 0], 0] < 0)
    assert np.all(nodes[bind[1][bind[1] >= 0], 0] >= 0)
