"""Surfel clouds and particles in PLY: round trips, layout, precision, estimation hooks."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import unmesh.surfels
from unmesh.errors import FormatError, InputError
from unmesh.io import load, load_particles, load_surfels, save
from unmesh.io.ply import encode_surfels
from unmesh.particles import Particles
from unmesh.surfels import SurfelCloud


def _attributes(rng, n):
    return {
        "flag": rng.random(n) > 0.5,
        "label": rng.integers(0, 255, n).astype(np.uint8),
        "small": rng.integers(-300, 300, n).astype(np.int16),
        "count": rng.integers(-(2**31), 2**31 - 1, n).astype(np.int32),
        "ids": rng.integers(0, 2**31 - 1, n).astype(np.int64),
        "weight": rng.random(n).astype(np.float32),
        "temperature": rng.normal(size=n) * 100.0,
        "velocity": rng.normal(size=(n, 3)),
        "stress": rng.normal(size=(n, 6)).astype(np.float32),
        "band": rng.integers(0, 9, (n, 1)).astype(np.int32),
    }


def _cloud(rng, n=200, elliptical=False, attributes=True):
    pos = rng.normal(size=(n, 3)) * 3.0
    nrm = rng.normal(size=(n, 3))
    colors = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    attrs = _attributes(rng, n) if attributes else {}
    if elliptical:
        axes = rng.normal(size=(n, 2, 3)) * 0.1
        return SurfelCloud(pos, nrm, axes=axes, colors=colors, attributes=attrs)
    return SurfelCloud(pos, nrm, radii=rng.random(n) + 0.01, colors=colors, attributes=attrs)


def _assert_same_cloud(a: SurfelCloud, b: SurfelCloud):
    assert len(a) == len(b)
    np.testing.assert_array_equal(b.positions, a.positions)
    np.testing.assert_allclose(b.normals, a.normals, rtol=0, atol=4e-16)
    np.testing.assert_allclose(b.radii, a.radii, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(b.colors, a.colors)
    assert b.is_elliptical == a.is_elliptical
    if a.axes is not None:
        np.testing.assert_allclose(b.axes, a.axes, rtol=0, atol=1e-16)
    assert list(b.attributes) == list(a.attributes)
    for k, v in a.attributes.items():
        assert b.attributes[k].dtype == v.dtype, k
        assert b.attributes[k].shape == v.shape, k
        np.testing.assert_array_equal(b.attributes[k], v)


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("elliptical", [False, True])
def test_surfel_round_trip(tmp_path, rng, binary, elliptical):
    cloud = _cloud(rng, elliptical=elliptical)
    path = tmp_path / "cloud.ply"
    save(path, cloud, binary=binary)
    back = load(path)
    assert isinstance(back, SurfelCloud)
    _assert_same_cloud(cloud, back)
    assert load_surfels(path).attributes.keys() == cloud.attributes.keys()


@pytest.mark.parametrize("binary", [True, False])
def test_empty_cloud_and_particles_round_trip(tmp_path, binary):
    empty = SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0),
                        attributes={"t": np.zeros(0), "v": np.zeros((0, 3), np.float32)})
    save(tmp_path / "e.ply", empty, binary=binary)
    back = load(tmp_path / "e.ply")
    assert isinstance(back, SurfelCloud) and len(back) == 0
    assert back.attributes["v"].shape == (0, 3) and back.attributes["v"].dtype == np.float32
    ell = SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), axes=np.zeros((0, 2, 3)))
    save(tmp_path / "ee.ply", ell, binary=binary)
    assert load(tmp_path / "ee.ply").is_elliptical
    save(tmp_path / "p.ply", Particles(np.zeros((0, 3)), attributes={"density": np.zeros(0)}), binary=binary)
    p = load(tmp_path / "p.ply")
    assert isinstance(p, Particles) and len(p) == 0 and list(p.attributes) == ["density"]


def test_surfel_header_is_standard(tmp_path, rng):
    cloud = _cloud(rng, n=10, attributes=False)
    save(tmp_path / "c.ply", cloud)
    ply = plyfile.PlyData.read(str(tmp_path / "c.ply"))
    el = ply["vertex"]
    names = [p.name for p in el.properties]
    assert names == ["x", "y", "z", "nx", "ny", "nz", "radius", "red", "green", "blue"]
    types = {p.name: p.val_dtype for p in el.properties}
    assert all(types[c] == "u1" for c in ("red", "green", "blue"))
    assert all(types[c] in ("f4", "f8") for c in names[:7])
    assert not ply.text and ply.byte_order == "<"
    # a third-party reader sees the same values
    np.testing.assert_array_equal(np.stack([el["x"], el["y"], el["z"]], axis=1), cloud.positions)
    np.testing.assert_array_equal(el["red"], np.rint(cloud.colors[:, 0] * 255))
    header = (tmp_path / "c.ply").read_bytes().split(b"end_header")[0].decode()
    assert header.startswith("ply\nformat binary_little_endian 1.0\n")
    assert "property uchar red\nproperty uchar green\nproperty uchar blue\n" in header


def test_geometry_precision_float_or_double(rng):
    pos32 = rng.normal(size=(5, 3)).astype(np.float32).astype(np.float64)
    up = np.tile([0.0, 0.0, 1.0], (5, 1))
    c = SurfelCloud(pos32, up, radii=np.full(5, 0.25))
    head = encode_surfels(c).split(b"end_header")[0].decode()
    assert "property float x" in head and "property float nx" in head and "property float radius" in head
    c = SurfelCloud(pos32 + 1e-9, up, radii=np.full(5, 0.1))
    head = encode_surfels(c).split(b"end_header")[0].decode()
    assert "property double x" in head and "property double radius" in head and "property float nz" in head


def test_elliptical_layout(tmp_path, rng):
    save(tmp_path / "e.ply", _cloud(rng, n=5, elliptical=True, attributes=False))
    names = [p.name for p in plyfile.PlyData.read(str(tmp_path / "e.ply"))["vertex"].properties]
    assert names[7:] == ["red", "green", "blue", "t1x", "t1y", "t1z", "t2x", "t2y", "t2z"]


def test_attribute_columns_convention(tmp_path, rng):
    c = SurfelCloud(np.zeros((4, 3)), np.tile([0, 0, 1.0], (4, 1)), radii=np.ones(4),
                    attributes={"velocity": rng.normal(size=(4, 3)), "flag": np.array([1, 0, 1, 1], bool)})
    save(tmp_path / "a.ply", c, binary=False)
    ply = plyfile.PlyData.read(str(tmp_path / "a.ply"))
    names = [p.name for p in ply["vertex"].properties]
    assert names[-4:] == ["velocity_0", "velocity_1", "velocity_2", "flag"]
    assert ply["vertex"].properties[-1].val_dtype == "u1"
    back = load(tmp_path / "a.ply")
    assert back.attributes["flag"].dtype == bool


@pytest.mark.parametrize("attrs,match", [
    ({"w_0": np.zeros(3)}, r"attributes\['w_0'\]: name would read back as 'w'"),
    ({"a b": np.zeros(3)}, r"attributes\['a b'\]: PLY property names"),
    ({"t": np.zeros((3, 2, 2))}, r"attributes\['t'\]: PLY stores arrays of shape"),
    ({"s": np.array(["a", "b", "c"])}, r"attributes\['s'\]: expected a numeric or bool array"),
    ({"big": np.array([0, 1, 2**40])}, r"attributes\['big'\]: int64 values outside the 32-bit range"),
])
def test_attribute_names_and_types_refused(tmp_path, attrs, match):
    for obj in (Particles(np.zeros((3, 3)), attributes=attrs),
                *([SurfelCloud(np.zeros((3, 3)), np.tile([0, 0, 1.0], (3, 1)), radii=np.ones(3), attributes=attrs)]
                  if all(k.isidentifier() for k in attrs) else [])):
        with pytest.raises(InputError, match=match):
            save(tmp_path / "x.ply", obj)
        assert not (tmp_path / "x.ply").exists()


def test_attribute_may_not_shadow_axis_properties(tmp_path):
    ell = SurfelCloud(np.zeros((3, 3)), np.tile([0, 0, 1.0], (3, 1)), axes=np.tile([[1.0, 0, 0], [0, 1.0, 0]], (3, 1, 1)),
                      attributes={"t1x": np.zeros(3)})
    with pytest.raises(InputError, match=r"attributes\['t1x'\]: property name 't1x' is already used"):
        save(tmp_path / "x.ply", ell)


def test_normals_without_radius_estimates_radii(tmp_path, monkeypatch):
    calls = []

    def fake_radii(points, normals):
        calls.append((points.shape, normals.shape))
        return np.full(len(points), 0.5)

    monkeypatch.setattr(unmesh.surfels, "estimate_radii", fake_radii, raising=False)
    path = tmp_path / "n.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                    "property float nx\nproperty float ny\nproperty float nz\nend_header\n"
                    "0 0 0 0 0 1\n1 0 0 0 0 2\n")
    cloud = load(path)
    assert isinstance(cloud, SurfelCloud)
    assert calls == [((2, 3), (2, 3))]
    np.testing.assert_array_equal(cloud.radii, [0.5, 0.5])
    np.testing.assert_array_equal(cloud.normals, [[0, 0, 1], [0, 0, 1]])


def test_points_only_become_particles_or_estimated_surfels(tmp_path, monkeypatch):
    path = tmp_path / "pts.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "property float radius\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                    "property int phase\nend_header\n"
                    "0 0 0 0.5 255 0 0 1\n1 0 0 0.5 0 0 0 2\n0 1 0 0.25 10 0 0 1\n")
    p = load(path)
    assert isinstance(p, Particles)
    np.testing.assert_array_equal(p.radii, [0.5, 0.5, 0.25])
    assert list(p.attributes) == ["red", "green", "blue", "phase"] and p.attributes["phase"].dtype == np.int32

    monkeypatch.setattr(unmesh.surfels, "estimate_normals",
                        lambda points: np.tile([0.0, 1.0, 0.0], (len(points), 1)), raising=False)
    monkeypatch.setattr(unmesh.surfels, "estimate_radii", lambda points, normals: np.full(len(points), 9.0),
                        raising=False)
    s = load_surfels(path)
    np.testing.assert_array_equal(s.normals[:, 1], 1.0)
    np.testing.assert_array_equal(s.radii, [0.5, 0.5, 0.25])  # stored radii win over estimates
    np.testing.assert_allclose(s.colors[:, 0], [1.0, 0.0, 10 / 255])
    assert list(s.attributes) == ["phase"]


def test_sph_particles_keep_attribute_order(tmp_path, rng):
    n = 50
    names = ["vx", "vy", "vz", "density", "pressure", "temperature", "phase", "object"]
    attrs = {k: rng.normal(size=n) for k in names[:6]}
    attrs["phase"] = rng.integers(0, 3, n)
    attrs["object"] = rng.integers(0, 5, n).astype(np.int32)
    p = Particles(rng.normal(size=(n, 3)), radii=np.full(n, 0.01), attributes=attrs)
    for binary in (True, False):
        save(tmp_path / "frame.ply", p, binary=binary)
        props = [q.name for q in plyfile.PlyData.read(str(tmp_path / "frame.ply"))["vertex"].properties]
        assert props == ["x", "y", "z", "radius", *names]
        back = load_particles(tmp_path / "frame.ply")
        assert list(back.attributes) == names
        np.testing.assert_array_equal(back.positions, p.positions)
        np.testing.assert_array_equal(back.radii, p.radii)
        for k in names:
            np.testing.assert_array_equal(back.attributes[k], attrs[k])
            assert back.attributes[k].dtype == attrs[k].dtype


def test_particle_attribute_clashes(tmp_path):
    with pytest.raises(InputError, match=r"attributes\['x'\]"):
        save(tmp_path / "p.ply", Particles(np.zeros((2, 3)), attributes={"x": np.zeros(2)}))
    with pytest.raises(InputError, match=r"attributes\['radius'\]"):
        save(tmp_path / "p.ply", Particles(np.zeros((2, 3)), attributes={"radius": np.ones(2)}))


def test_surfel_file_as_particles_and_big_endian(tmp_path, rng):
    cloud = _cloud(rng, n=20)
    (tmp_path / "be.ply").write_bytes(encode_surfels(cloud, byte_order=">"))
    assert b"binary_big_endian" in (tmp_path / "be.ply").read_bytes()[:40]
    _assert_same_cloud(cloud, load(tmp_path / "be.ply"))
    p = load_particles(tmp_path / "be.ply")
    assert {"nx", "ny", "nz", "red", "velocity"} <= set(p.attributes)
    np.testing.assert_array_equal(p.radii, cloud.radii)


def test_foreign_property_names_become_identifiers(tmp_path):
    path = tmp_path / "cc.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                    "property float nx\nproperty float ny\nproperty float nz\nproperty float radius\n"
                    "property float class\nproperty float scalar-Intensity\nproperty uchar alpha\n"
                    "property float normals\nend_header\n0 0 0 0 0 1 1 2 3 255 7\n")
    with pytest.warns(UserWarning, match="renamed"):
        c = load(path)
    assert c.attributes == {"class_": 2.0, "scalar_Intensity": 3.0, "normals_": 7.0}


def test_bad_surfel_values_raise_format_error(tmp_path):
    head = ("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\nproperty float radius\nend_header\n")
    cases = {
        "0 0 0 0 0 1 1\n0 0 nan 0 0 1 1\n": r"nan\.ply: element 'vertex': row 1: position is NaN",
        "0 0 0 0 0 1 1\n0 0 0 0 0 0 1\n": r"zero\.ply: element 'vertex': row 1: normal is a zero vector",
        "0 0 0 0 0 1 1\n0 0 0 0 0 1 -1\n": r"neg\.ply: element 'vertex': row 1: radius must be positive",
    }
    for (body, match), name in zip(cases.items(), ["nan", "zero", "neg"], strict=True):
        (tmp_path / f"{name}.ply").write_text(head + body)
        with pytest.raises(FormatError, match=match):
            load(tmp_path / f"{name}.ply")
    (tmp_path / "nox.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nend_header\n1\n")
    with pytest.raises(FormatError, match=r"nox\.ply: element 'vertex': no property 'x'"):
        load(tmp_path / "nox.ply")
    (tmp_path / "nov.ply").write_text("ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(FormatError, match=r"nov\.ply: no 'vertex' element"):
        load(tmp_path / "nov.ply")


_DTYPES = [np.bool_, np.uint8, np.int8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.float16,
           np.float32, np.float64]


@settings(max_examples=25, deadline=None)
@given(n=st.integers(0, 6), specs=st.lists(st.tuples(st.sampled_from(_DTYPES), st.sampled_from([0, 1, 2, 4])),
                                           min_size=0, max_size=4),
       binary=st.booleans(), seed=st.integers(0, 2**31))
def test_attribute_round_trip_property(tmp_path_factory, n, specs, binary, seed):
    rng = np.random.default_rng(seed)
    attrs = {}
    for i, (dt, k) in enumerate(specs):
        shape = (n,) if k == 0 else (n, k)
        if np.dtype(dt).kind == "f":
            vals = rng.normal(size=shape) * 1e3
        elif np.dtype(dt).kind == "b":
            vals = rng.random(shape) > 0.5
        else:
            info = np.iinfo(dt)
            vals = rng.integers(max(info.min, -(2**31)), min(info.max, 2**31 - 1), shape, endpoint=True)
        attrs[f"a{i}"] = np.asarray(vals).astype(dt)
    cloud = SurfelCloud(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) + 0.1, radii=rng.random(n) + 0.1,
                        attributes=attrs)
    path = tmp_path_factory.mktemp("h") / "h.ply"
    save(path, cloud, binary=binary)
    _assert_same_cloud(cloud, load(path))


def test_particle_attribute_names_kept_verbatim(tmp_path):
    p = Particles(np.zeros((2, 3)), attributes={"class": np.array([1, 2]), "scalar-Intensity": np.ones(2)})
    save(tmp_path / "p.ply", p)
    assert list(load(tmp_path / "p.ply").attributes) == ["class", "scalar-Intensity"]


def test_point_file_to_surfels_with_real_estimators(tmp_path, rng):
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    save(tmp_path / "sphere.ply", Particles(d))
    cloud = load_surfels(tmp_path / "sphere.ply")
    assert len(cloud) == 400 and np.all(cloud.radii > 0)
    assert np.abs(np.einsum("ij,ij->i", cloud.normals, d)).min() > 0.9  # normals ~ radial
