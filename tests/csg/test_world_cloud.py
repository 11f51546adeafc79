"""The concatenated world cloud of a CSG frame against the general transform path."""

import numpy as np

from unmesh import SurfelCloud
from unmesh.csg import Patch
from unmesh.csg.frame import world_cloud
from unmesh.shapes import Sphere


def _rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _moved(patch, lin, t):
    m = np.eye(4)
    m[:3, :3] = lin
    m[:3, 3] = t
    return patch.moved(m)


def test_world_cloud_equals_concatenated_transformed_clouds():
    rng = np.random.default_rng(0)
    s = Sphere(radius=1.0).surfels(0.2)
    base = Patch(s.replace(colors=rng.uniform(0, 1, (len(s), 3))))
    cases = [
        [base, _moved(base, np.eye(3), (1e-9, 0, 0))],  # untransformed and translated
        [_moved(base, 2.5 * _rotation((1, 2, 3), 0.7), (0.1, -2, 3)), _moved(base, _rotation((0, 0, 1), 2.0), (1, 1, 1)),
         Patch.halfspace((0, 0, 0), (0, 0, 1), 2.0, 0.5)],  # similarities
        [base, _moved(base, np.diag([1.0, 2.0, 1.0]), (0, 0, 0))],  # not a similarity: general path
    ]
    for leaves in cases:
        want = SurfelCloud.concatenate([p.world_cloud() for p in leaves], attributes="none")
        got = world_cloud(leaves)
        assert got.is_elliptical == want.is_elliptical
        np.testing.assert_array_equal(got.positions, want.positions)
        np.testing.assert_allclose(got.normals, want.normals, rtol=0, atol=1e-14)
        np.testing.assert_allclose(np.linalg.norm(got.normals, axis=1), 1.0, rtol=0, atol=1e-14)
        np.testing.assert_allclose(got.radii, want.radii, rtol=1e-15)
        np.testing.assert_array_equal(got.colors, want.colors)
        for a in (got.positions, got.normals, got.radii, got.colors):
            assert a.dtype == np.float64 and a.flags.c_contiguous
