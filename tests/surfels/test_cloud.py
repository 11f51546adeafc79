import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import SurfelCloud
from unmesh.errors import InputError, UnmeshError
from unmesh.surfels import tangent_frame


def _cloud(n=5, **kw):
    rng = np.random.default_rng(0)
    args = dict(positions=rng.normal(size=(n, 3)), normals=rng.normal(size=(n, 3)), radii=rng.uniform(0.1, 1, n))
    args.update(kw)
    return SurfelCloud(**args)


def test_construction_normalises_and_defaults():
    c = _cloud()
    np.testing.assert_allclose(np.linalg.norm(c.normals, axis=1), 1.0)
    assert c.colors.shape == (5, 3) and np.all(c.colors == 0.8)
    assert c.positions.flags.c_contiguous and c.positions.dtype == np.float64
    assert not c.is_elliptical and len(c) == 5


@pytest.mark.parametrize(
    "changes, message",
    [
        (dict(radii=[1, 1, 0, 1, 1]), "radii: expected positive values, got 0.0 at index 2"),
        (dict(radii=[1, 1, 1, -2, 1]), "radii: expected positive values, got -2.0 at index 3"),
        (dict(normals=[[0, 0, 1]] * 3 + [[0, 0, 0]] + [[0, 0, 1]]), "normals: expected non-zero vectors, got length 0 at index 3"),
        (dict(positions=[[0, 0, 0]] * 4 + [[np.nan, 0, 0]]), "positions: expected finite values, got NaN or infinity at index 4"),
        (dict(positions=np.zeros((5, 2))), "positions: expected shape (N, 3), got (5, 2)"),
        (dict(normals=np.ones((4, 3))), "normals: expected 5 rows"),
        (dict(colors=np.full((5, 3), 1.5)), "colors: expected values in [0, 1], got [1.5, 1.5, 1.5] at index 0"),
        (dict(radii=None), "radii: expected radii (N,) or tangent axes"),
        (dict(attributes={"temp": np.zeros(4)}), "attributes['temp']: expected first axis of length 5"),
        (dict(attributes={"radius": np.zeros(5)}), "reserved"),
        (dict(attributes={"not valid": np.zeros(5)}), "identifier"),
    ],
)
def test_validation_names_field_and_index(changes, message):
    with pytest.raises(UnmeshError) as info:
        _cloud(**changes)
    assert isinstance(info.value, InputError) and isinstance(info.value, ValueError)
    assert message in str(info.value)


def test_uint8_colors_are_scaled():
    c = _cloud(colors=np.full((5, 3), 255, dtype=np.uint8))
    np.testing.assert_array_equal(c.colors, 1.0)


def test_elliptical_axes_are_projected_and_give_radii():
    n = np.array([[0.0, 0.0, 1.0]])
    axes = np.array([[[0.3, 0.0, 0.5], [0.0, 0.1, 0.0]]])
    c = SurfelCloud([[0, 0, 0]], n, axes=axes)
    np.testing.assert_allclose(c.axes[0, 0], [0.3, 0, 0])
    np.testing.assert_allclose(c.radii, [0.3])
    assert c.is_elliptical
    with pytest.raises(InputError, match="axes: expected non-zero tangent axes"):
        SurfelCloud([[0, 0, 0]], n, axes=[[[0, 0, 1.0], [0, 1.0, 0]]])
    with pytest.raises(InputError, match="radii: expected radii equal"):
        SurfelCloud([[0, 0, 0]], n, axes=axes, radii=[0.5])


def test_subset_keeps_attributes_and_validates_index():
    c = _cloud(attributes={"temp": np.arange(5.0), "vel": np.arange(15.0).reshape(5, 3)})
    s = c.subset([4, 1])
    np.testing.assert_array_equal(s.attributes["temp"], [4, 1])
    np.testing.assert_array_equal(s.attributes["vel"], [[12, 13, 14], [3, 4, 5]])
    np.testing.assert_array_equal(s.radii, c.radii[[4, 1]])
    m = c.subset(np.array([True, False, True, False, False]))
    assert len(m) == 2
    with pytest.raises(InputError, match="index"):
        c.subset([7])
    with pytest.raises(InputError, match="boolean mask"):
        c.subset(np.array([True, False]))


def test_concatenate_and_mixed_kinds():
    a = _cloud(3)
    b = SurfelCloud([[0, 0, 0]], [[0, 1, 0]], axes=[[[0.2, 0, 0], [0, 0, 0.1]]])
    c = SurfelCloud.concatenate([a, b])
    assert len(c) == 4 and c.is_elliptical
    np.testing.assert_allclose(np.linalg.norm(c.axes[:3], axis=2), np.repeat(a.radii[:, None], 2, axis=1))
    with pytest.raises(InputError, match="attributes"):
        SurfelCloud.concatenate([a, _cloud(2, attributes={"t": np.zeros(2)})])
    with pytest.raises(InputError, match="at least one"):
        SurfelCloud.concatenate([])


def test_replace_revalidates():
    c = _cloud()
    with pytest.raises(InputError, match="radii"):
        c.replace(radii=np.zeros(5))
    e = c.replace(axes=c.tangent_axes())
    np.testing.assert_allclose(e.radii, c.radii)
    back = e.replace(radii=np.ones(5))
    assert not back.is_elliptical


def test_empty_cloud():
    c = SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0))
    assert len(c) == 0 and np.all(np.isinf(c.bounds()))
    assert c.tangent_axes().shape == (0, 2, 3)


unit = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3)


@settings(max_examples=60, deadline=None)
@given(unit)
def test_tangent_frame_is_orthonormal_right_handed(v):
    n = np.asarray([v], dtype=np.float64)
    n /= np.linalg.norm(n)
    t1, t2 = tangent_frame(n)
    for a, b in ((t1, t2), (t1, n), (t2, n)):
        assert abs(float(np.sum(a * b))) < 1e-12
    np.testing.assert_allclose(np.cross(t1, t2), n, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.1, 5), unit, st.tuples(*[st.floats(-3, 3)] * 3))
def test_similarity_transform_keeps_circular_and_geometry(scale, axis, shift):
    c = _cloud(4)
    a = np.asarray(axis) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    rot = np.eye(3) + np.sin(0.7) * k + (1 - np.cos(0.7)) * k @ k
    m = np.eye(4)
    m[:3, :3] = scale * rot
    m[:3, 3] = shift
    t = c.transformed(m)
    assert not t.is_elliptical
    np.testing.assert_allclose(t.radii, scale * c.radii, rtol=1e-9)
    np.testing.assert_allclose(t.normals, c.normals @ rot.T, atol=1e-9)
    np.testing.assert_allclose(t.positions, scale * c.positions @ rot.T + shift, atol=1e-9)


def test_nonuniform_scale_makes_elliptical_and_normals_stay_perpendicular():
    c = _cloud(6)
    t = c.transformed(np.diag([2.0, 1.0, 0.5]))
    assert t.is_elliptical
    dots = np.einsum("nki,ni->nk", t.axes, t.normals)
    np.testing.assert_allclose(dots, 0, atol=1e-9)


def test_surfel_kinds_from_the_discontinuity_attribute():
    """Discontinuity surfels (thesis 4.3): 0 surface sample, 1 geometry, 2 texture discontinuity."""
    from unmesh.surfels.cloud import GEOMETRY_DISCONTINUITY, SURFACE, TEXTURE_DISCONTINUITY

    plain = _cloud(4)
    assert plain.surfel_kinds().tolist() == [SURFACE] * 4 and plain.surfel_kinds().dtype == np.int8
    assert plain.visible() is plain and len(plain.discontinuity_surfels()) == 0
    c = _cloud(6, attributes={"discontinuity": np.array([0, 1, 2, 0, 7, 0], dtype=np.uint8)})
    assert c.surfel_kinds().tolist() == [0, GEOMETRY_DISCONTINUITY, TEXTURE_DISCONTINUITY, 0, GEOMETRY_DISCONTINUITY, 0]
    vis = c.visible()
    np.testing.assert_array_equal(vis.positions, c.positions[[0, 3, 5]])
    assert vis.attributes["discontinuity"].tolist() == [0, 0, 0]
    disc = c.discontinuity_surfels()
    np.testing.assert_array_equal(disc.radii, c.radii[[1, 2, 4]])
    assert disc.surfel_kinds().tolist() == [1, 2, 1]
    # float flags (as written by PLY readers) and a cloud of surface samples only
    f = _cloud(3, attributes={"discontinuity": np.zeros(3)})
    assert f.visible() is f and f.surfel_kinds().tolist() == [0, 0, 0]
    # computed, not stored: the attribute is the only record
    assert set(c.attributes) == {"discontinuity"}


def test_concatenate_attribute_policies():
    a = _cloud(2, attributes={"t": np.ones(2), "s": np.zeros(2)})
    b = _cloud(3, attributes={"t": np.full(3, 2.0)})
    with pytest.raises(InputError, match="expected attributes"):
        SurfelCloud.concatenate([a, b])
    common = SurfelCloud.concatenate([a, b], attributes="common")
    assert set(common.attributes) == {"t"} and common.attributes["t"].tolist() == [1, 1, 2, 2, 2]
    none = SurfelCloud.concatenate([a, b], attributes="none")
    assert none.attributes == {} and len(none) == 5
    # the same construction as the default policy when names agree (bit for bit)
    same = SurfelCloud.concatenate([a, a])
    np.testing.assert_array_equal(SurfelCloud.concatenate([a, a], attributes="none").normals, same.normals)
    with pytest.raises(InputError, match="attributes: expected 'same', 'common' or 'none'"):
        SurfelCloud.concatenate([a], attributes="all")
