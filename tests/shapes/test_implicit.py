"""Implicit functions of the built-in shapes: exact distances, exact normals, signs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.shapes import Blob, Box, Cylinder, Disc, Plane, Sphere, Torus, euler_rotation
from unmesh.shapes.blob import _blob_unit, blob_reference
from unmesh.spatial import knn

ROT = euler_rotation([20.0, -35.0, 50.0])


def sdf_shapes():
    return [
        Sphere(center=(0.3, -0.2, 0.1), radius=0.8),
        Box(center=(0.1, 0.2, -0.3), size=(1.2, 0.7, 0.5), rotation=ROT),
        Cylinder(center=(-0.2, 0.1, 0.0), radius=0.4, height=1.1, axis=(1.0, 2.0, 0.5)),
        Torus(center=(0.0, 0.1, 0.2), major=0.7, minor=0.25, axis=(0.3, 1.0, -0.2)),
        Disc(center=(0.1, 0.0, 0.0), radius=0.6, normal=(0.2, 1.0, 0.3)),
        Plane(center=(0.0, 0.2, 0.1), size=(1.0, 0.6), normal=(1.0, 0.5, 0.0)),
    ]


def inside_analytic(shape, x):
    """Independent inside predicates in the shape's local frame."""
    p = (x - shape.center) @ shape.rotation
    if isinstance(shape, Sphere):
        return np.linalg.norm(p, axis=1) < shape.radius
    if isinstance(shape, Box):
        return np.all(np.abs(p) < shape.half, axis=1)
    if isinstance(shape, Cylinder):
        return (np.hypot(p[:, 0], p[:, 1]) < shape.radius) & (np.abs(p[:, 2]) < shape.height / 2)
    if isinstance(shape, Torus):
        return (np.hypot(p[:, 0], p[:, 1]) - shape.major) ** 2 + p[:, 2] ** 2 < shape.minor**2
    return p[:, 2] < 0  # sheets: the half-space behind the supporting plane


def queries(shape, n, rng):
    lo, hi = shape.bounds()
    pad = 0.3 * (hi - lo).max()
    return rng.uniform(lo - pad, hi + pad, size=(n, 3))


@pytest.mark.parametrize("shape", sdf_shapes(), ids=lambda s: type(s).__name__)
def test_values_are_exact_signed_distances(shape, rng):
    x = queries(shape, 3000, rng)
    v, n = shape.implicit(x)
    assert v.shape == (3000,) and n.shape == (3000, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    # The closest point x - v n lies on the surface ...
    closest = x - v[:, None] * n
    np.testing.assert_allclose(shape.implicit(closest)[0], 0.0, atol=1e-9)
    # ... and no surface point is closer than |v|; dense samples come within their radius.
    dense = shape.surfels(0.01)
    d, _ = knn(dense.positions, 1, queries=x)
    assert np.all(d[:, 0] >= np.abs(v) - 1e-9)
    assert np.all(d[:, 0] <= np.abs(v) + dense.radii.max())
    # Sign: negative exactly inside.
    np.testing.assert_array_equal(v < 0, inside_analytic(shape, x))
    np.testing.assert_array_equal(shape.contains(x), inside_analytic(shape, x))


@pytest.mark.parametrize("shape", [*sdf_shapes(), Blob(center=(0.1, 0.0, 0.2), scale=0.8, rotation=ROT)],
                         ids=lambda s: type(s).__name__)
def test_normals_are_the_finite_difference_gradient(shape, rng):
    x = queries(shape, 2000, rng)
    _, n = shape.implicit(x)
    h = 1e-6
    grad = np.stack([(shape.implicit(x + h * e)[0] - shape.implicit(x - h * e)[0]) / (2 * h) for e in np.eye(3)], 1)
    norm = np.linalg.norm(grad, axis=1)
    if isinstance(shape, Blob):
        # Lipschitz 1 (a conservative distance bound), smooth everywhere.
        assert norm.max() <= 1.0 + 1e-6
        smooth = norm > 1e-3
    else:
        # Away from the medial axis (and the sheets' rim plane) the gradient has unit length.
        smooth = np.abs(norm - 1.0) < 1e-5
        assert smooth.mean() > 0.8
    cos = np.einsum("ij,ij->i", grad[smooth] / norm[smooth, None], n[smooth])
    assert np.all(cos > 1 - 1e-8)


def test_blob_kernel_matches_numpy_reference(rng):
    p = rng.uniform(-1.0, 1.2, size=(5000, 3))
    v1, n1 = _blob_unit(p)
    v2, n2 = blob_reference(p)
    np.testing.assert_allclose(v1, v2, atol=1e-13)
    np.testing.assert_allclose(n1, n2, atol=1e-12)


def test_blob_is_bunny_like_and_well_behaved():
    b = Blob()
    lo, hi = b.bounds()
    size = hi - lo
    assert 1.3 < size.max() < 1.8 and size.min() > 0.5  # a few units of size ~1
    # ears above the head, tail behind the body, paws below
    assert b.contains([[0.0, 0.0, 0.0], [0.3, 0.7, 0.13], [0.3, 0.7, -0.13], [-0.66, 0.08, 0.0],
                       [0.42, -0.36, 0.12]]).all()
    assert not b.contains([[0.3, 0.7, 0.0]])[0]  # the gap between the ears
    # the implicit never overestimates the distance (Lipschitz 1)
    mesh = b.mesh(0.02)
    x = np.random.default_rng(3).uniform(lo - 0.3, hi + 0.3, size=(2000, 3))
    d, _ = knn(mesh.vertices, 1, queries=x)
    v = b.implicit(x)[0]
    assert np.all(np.abs(v) <= d[:, 0] + 1e-9)


def test_sheet_convention():
    d = Disc(radius=1.0)  # normal +y
    v, n = d.implicit([[0.0, 0.5, 0.0], [0.0, -0.5, 0.0], [3.0, 0.0, 0.0], [3.0, -4.0, 0.0]])
    np.testing.assert_allclose(v, [0.5, -0.5, 2.0, -np.hypot(2.0, 4.0)])
    np.testing.assert_allclose(n[0], [0, 1, 0])
    np.testing.assert_allclose(n[1], [0, 1, 0])
    np.testing.assert_allclose(n[2], [1, 0, 0])
    with pytest.raises(ValueError, match="open surface"):
        d.volume()
    p = Plane(size=(2.0, 4.0))  # size[0] along x, size[1] along z
    np.testing.assert_allclose(p.bounds(), [[-1, 0, -2], [1, 0, 2]], atol=1e-12)
    assert p.contains([[5.0, -1.0, 5.0]])[0] and not p.closed


@settings(max_examples=25, deadline=None)
@given(
    angles=st.lists(st.floats(-180, 180), min_size=3, max_size=3),
    shift=st.lists(st.floats(-2, 2), min_size=3, max_size=3),
    scale=st.floats(0.2, 5.0),
    kind=st.sampled_from(["sphere", "box", "cylinder", "torus", "disc", "plane", "blob"]),
)
def test_similarity_transforms_commute_with_implicit(angles, shift, scale, kind):
    from unmesh.shapes import by_name

    shape = by_name(kind)
    m = np.eye(4)
    m[:3, :3] = scale * euler_rotation(angles)
    m[:3, 3] = shift
    moved = shape.transformed(m)
    x = np.random.default_rng(0).uniform(-1.5, 1.5, size=(50, 3))
    y = x @ m[:3, :3].T + m[:3, 3]
    v0, n0 = shape.implicit(x)
    v1, n1 = moved.implicit(y)
    np.testing.assert_allclose(v1, scale * v0, atol=1e-9 * scale)
    np.testing.assert_allclose(n1, n0 @ (m[:3, :3] / scale).T, atol=1e-7)
    b0, b1 = shape.bounds(), moved.bounds()
    corners = np.array(np.meshgrid(*b0.T, indexing="ij")).reshape(3, -1).T @ m[:3, :3].T + m[:3, 3]
    assert np.all(b1[0] >= corners.min(axis=0) - 1e-9) and np.all(b1[1] <= corners.max(axis=0) + 1e-9)


def test_transform_rejects_shear():
    with pytest.raises(ValueError, match="similarity"):
        Sphere().transformed(np.diag([1.0, 2.0, 1.0, 1.0]))
