"""Triangle meshes in PLY, OBJ (+MTL+PNG) and OFF."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import FormatError, InputError
from unmesh.io import load, load_mesh, load_surfels, save
from unmesh.meshes import TriangleMesh


def _mesh(rng, uv=True, normals=True, colors=True, texture=False, normal_map=False, attributes=False):
    """A closed octahedron with per-vertex data drawn from rng (colours on the 8-bit grid)."""
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float) * 1.5
    v = v + rng.normal(size=v.shape) * 0.1
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    kw = {}
    if uv:
        kw["uv"] = rng.random((6, 2))
    if normals:
        kw["vertex_normals"] = v / np.linalg.norm(v, axis=1, keepdims=True)
    if colors:
        kw["vertex_colors"] = rng.integers(0, 256, (6, 3)).astype(np.uint8)
    if texture:
        kw["texture"] = rng.integers(0, 256, (8, 16, 3)).astype(np.uint8)
    if normal_map:
        kw["normal_map"] = rng.integers(0, 256, (4, 4, 3)).astype(np.uint8)
    if attributes:
        kw["attributes"] = {"curvature": rng.normal(size=6), "frame": rng.normal(size=(6, 3)).astype(np.float32)}
    return TriangleMesh(v, f, **kw)


def _assert_same_mesh(a, b, *, colors_exact=True):
    np.testing.assert_array_equal(b.vertices, a.vertices)
    np.testing.assert_array_equal(b.faces, a.faces)
    for name in ("uv", "vertex_normals", "vertex_colors", "texture", "normal_map"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_allclose(y, x, rtol=0, atol=4e-16, err_msg=name)


@pytest.mark.parametrize("binary", [True, False])
def test_ply_mesh_round_trip(tmp_path, rng, binary):
    mesh = _mesh(rng, texture=True, attributes=True)
    save(tmp_path / "m.ply", mesh, binary=binary)
    assert (tmp_path / "m.png").is_file()
    assert b"comment TextureFile m.png" in (tmp_path / "m.ply").read_bytes()[:600]
    back = load(tmp_path / "m.ply")
    assert isinstance(back, TriangleMesh)
    _assert_same_mesh(mesh, back)
    assert list(back.attributes) == ["curvature", "frame"]
    np.testing.assert_array_equal(back.attributes["frame"], mesh.attributes["frame"])
    assert back.attributes["frame"].dtype == np.float32
    head = (tmp_path / "m.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property list uchar int vertex_indices" in head
    assert "property uchar red" in head and "s\n" in head and "property" in head


def test_obj_round_trip_with_texture_and_normal_map(tmp_path, rng):
    mesh = _mesh(rng, texture=True, normal_map=True)
    save(tmp_path / "cow.obj", mesh)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["cow.mtl", "cow.obj", "cow.png", "cow_normal.png"]
    mtl = (tmp_path / "cow.mtl").read_text()
    assert "map_Kd cow.png" in mtl and "norm cow_normal.png" in mtl and "map_Bump cow_normal.png" in mtl
    obj = (tmp_path / "cow.obj").read_text()
    assert "mtllib cow.mtl" in obj and "usemtl material0" in obj and "\nf 1/1/1 3/3/3 5/5/5\n" in obj
    back = load(tmp_path / "cow.obj")
    _assert_same_mesh(mesh, back)


@pytest.mark.parametrize("fmt", ["obj", "off"])
@pytest.mark.parametrize("parts", [(False, False, False), (True, False, False), (False, True, False),
                                   (False, False, True), (True, True, True)])
def test_text_formats_round_trip(tmp_path, rng, fmt, parts):
    uv, normals, colors = parts
    mesh = _mesh(rng, uv=uv, normals=normals, colors=colors)
    save(tmp_path / f"m.{fmt}", mesh)
    _assert_same_mesh(mesh, load_mesh(tmp_path / f"m.{fmt}"))


def test_float32_vertices_print_short(tmp_path):
    mesh = TriangleMesh(np.array([[0.1, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), [[0, 1, 2]])
    save(tmp_path / "s.obj", mesh)
    assert "v 0.100000001 0 0" in (tmp_path / "s.obj").read_text()
    mesh = TriangleMesh([[0.1, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    save(tmp_path / "d.obj", mesh)
    assert "v 0.1 0.0 0.0" in (tmp_path / "d.obj").read_text()


def test_ply_polygons_strips_and_corner_texcoords(tmp_path):
    quad = ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 2\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
            "0 0 0\n1 0 0\n1 1 0\n0 1 0\n9 9 9\n"
            "4 0 1 2 3 8 0 0 1 0 1 1 0 1\n3 0 2 1 6 0.5 0.5 1 1 1 0\n")
    (tmp_path / "q.ply").write_text(quad)
    m = load(tmp_path / "q.ply")
    # vertex 0 has uv (0,0) and (0.5,0.5) -> split; vertex 4 is unreferenced but kept
    assert m.faces.shape == (3, 3) and len(m.vertices) == 6
    np.testing.assert_array_equal(m.vertices[:5], [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [9, 9, 9]])
    np.testing.assert_array_equal(m.faces[:2], [[0, 1, 2], [0, 2, 3]])
    assert m.faces[2, 0] == 5 and np.array_equal(m.vertices[5], [0, 0, 0])
    np.testing.assert_allclose(m.uv[m.faces[2]], [[0.5, 0.5], [1, 1], [1, 0]])
    np.testing.assert_allclose(m.uv[[0, 1, 2, 3]], [[0, 0], [1, 0], [1, 1], [0, 1]])

    strips = ("ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
              "element tristrips 2\nproperty list int int vertex_indices\nend_header\n"
              "0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 2 0\n1 2 0\n"
              "6 0 1 2 3 -1 4\n7 2 3 4 4 5 -1 -1\n")
    (tmp_path / "s.ply").write_text(strips)
    m = load_mesh(tmp_path / "s.ply")
    # strip 0 1 2 3: (0,1,2), (2,1,3); strip 2 3 4 4 5: (2,3,4), degenerate x2, dropped
    assert m.faces.tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4]]


def test_ply_colours_float_and_uv_aliases_and_zero_normals(tmp_path):
    text = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            "property float red\nproperty float green\nproperty float blue\nproperty float alpha\n"
            "property float texture_u\nproperty float texture_v\n"
            "element face 1\nproperty list uchar uint vertex_index\nend_header\n"
            "0 0 0 0 0 1 1 0.5 0 1 0 0\n1 0 0 0 0 1 0 0 0 1 1 0\n0 1 0 0 0 1 0 0 0 1 0 1\n5 5 5 0 0 0 0 0 0 1 0 0\n"
            "3 0 1 2\n")
    (tmp_path / "c.ply").write_text(text)
    with pytest.warns(UserWarning, match="1 zero normals replaced"):
        m = load(tmp_path / "c.ply")
    np.testing.assert_allclose(m.vertex_colors[0], [1, 0.5, 0])
    np.testing.assert_allclose(m.uv[2], [0, 1])
    np.testing.assert_allclose(m.vertex_normals[3], [0, 0, 1])  # isolated vertex: default normal
    assert m.attributes == {}


OBJ_FEATURES = """# a comment
mtllib box.mtl
v 0 0 0 1 0 0
v 1 0 0 0 1 0
v 1 1 0 0 0 1
v 0 1 0 \\
  1 1 1
v 7 7 7 0 0 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
usemtl red
f 1/1/1 2/2/1 3/3/1 4/4/1
g second  # inline comment
usemtl blue
f -5/-1/-1 -3/-2/-1 -4/-3/-1
l 1 2
"""


def test_obj_features(tmp_path):
    (tmp_path / "box.obj").write_text(OBJ_FEATURES)
    (tmp_path / "box.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n")
    m = load(tmp_path / "box.obj")
    assert len(m.faces) == 3
    np.testing.assert_array_equal(m.vertices[:5], [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [7, 7, 7]])
    np.testing.assert_array_equal(m.faces[:2], [[0, 1, 2], [0, 2, 3]])
    # the last face reuses vertex 0 with uv (0,1): split into a new vertex
    assert m.faces[2].tolist() == [5, 2, 1] and np.array_equal(m.vertices[5], [0, 0, 0])
    np.testing.assert_array_equal(m.uv[:4], [[0, 0], [1, 0], [1, 1], [0, 1]])
    np.testing.assert_array_equal(m.uv[5], [0, 1])
    np.testing.assert_array_equal(m.vertex_normals[:4], np.tile([0, 0, 1.0], (4, 1)))
    # file vertex colours win over material Kd
    np.testing.assert_array_equal(m.vertex_colors[:4], [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])


def test_obj_material_colours_split_vertices(tmp_path):
    obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 2 4 3\n"
    (tmp_path / "k.obj").write_text(obj)
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    m = load(tmp_path / "k.obj")
    assert len(m.vertices) == 6  # vertices 2 and 3 (1-based) are shared by both materials
    np.testing.assert_array_equal(m.vertex_colors[m.faces[0]], np.tile([1.0, 0, 0], (3, 1)))
    np.testing.assert_array_equal(m.vertex_colors[m.faces[1]], np.tile([0, 1.0, 0], (3, 1)))


def test_obj_missing_texture_and_mtl_warn(tmp_path):
    obj = "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl tex\nf 1/1 2/2 3/3\n"
    (tmp_path / "t.obj").write_text(obj)
    with pytest.warns(UserWarning, match="material file 't.mtl' not found"):
        m = load(tmp_path / "t.obj")
    assert m.texture is None and m.uv is not None
    (tmp_path / "t.mtl").write_text("newmtl tex\nKd 1 1 1\nmap_Kd -s 1 1 1 -clamp on gone.png\n")
    with pytest.warns(UserWarning, match="texture file .*gone.png.* not found"):
        m = load(tmp_path / "t.obj")
    assert m.texture is None and m.vertex_colors is None


def test_off_variants(tmp_path):
    cases = {
        "OFF\n# comment\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n3 0 2 1 255 0 0\n": None,
        "OFF 4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n\n4 0 1 2 3\n3 0 2 1\n": None,
        "COFF\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 0 0 0 255\n"
        "4 0 1 2 3\n3 0 2 1\n": "colors",
        "NOFF\n4 2 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n4 0 1 2 3\n3 0 2 1\n": "normals",
    }
    for i, (text, extra) in enumerate(cases.items()):
        (tmp_path / f"{i}.off").write_text(text)
        m = load(tmp_path / f"{i}.off")
        assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 2, 1]]
        if extra == "colors":
            np.testing.assert_array_equal(m.vertex_colors[:2], [[1, 0, 0], [0, 1, 0]])
        if extra == "normals":
            np.testing.assert_array_equal(m.vertex_normals[:, 2], 1.0)


def test_point_ply_is_not_a_mesh_and_mesh_is_not_surfels(tmp_path, rng):
    save(tmp_path / "p.ply", TriangleMesh(rng.random((3, 3)), [[0, 1, 2]]))
    with pytest.raises(InputError, match=r"unmesh sample"):
        load_surfels(tmp_path / "p.ply")
    save(tmp_path / "m.obj", TriangleMesh(rng.random((3, 3)), [[0, 1, 2]]))
    with pytest.raises(InputError, match=r"unmesh sample m\.obj"):
        load_surfels(tmp_path / "m.obj")
    (tmp_path / "pts.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                      "property float z\nend_header\n0 0 0\n")
    with pytest.raises(InputError, match=r"pts\.ply.* without faces, not a mesh"):
        load_mesh(tmp_path / "pts.ply")


def test_empty_mesh_round_trip(tmp_path):
    m = TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), int))
    for ext in ("ply", "obj", "off"):
        save(tmp_path / f"e.{ext}", m)
        back = load(tmp_path / f"e.{ext}")
        assert isinstance(back, TriangleMesh) and back.faces.shape == (0, 3)


def test_formats_detected_by_content(tmp_path, rng):
    save(tmp_path / "m.off", TriangleMesh(rng.random((3, 3)), [[0, 1, 2]]))
    (tmp_path / "m.off").rename(tmp_path / "m.mesh")
    assert isinstance(load(tmp_path / "m.mesh"), TriangleMesh)
    (tmp_path / "x.xyz").write_text("1 2 3\n")
    with pytest.raises(InputError, match=r"cannot tell the format"):
        load(tmp_path / "x.xyz")
    with pytest.raises(FileNotFoundError):
        load(tmp_path / "missing.ply")


def test_save_refuses_bad_arguments(tmp_path, rng):
    mesh = TriangleMesh(rng.random((3, 3)), [[0, 1, 2]])
    with pytest.raises(InputError, match=r"path: expected extension .ply, .obj or .off, got '.stl'"):
        save(tmp_path / "m.stl", mesh)
    with pytest.raises(InputError, match=r"obj: expected a SurfelCloud, TriangleMesh or Particles, got dict"):
        save(tmp_path / "m.ply", {"vertices": 1})
    from unmesh.particles import Particles

    with pytest.raises(InputError, match=r"obj: .obj files hold triangle meshes, got Particles"):
        save(tmp_path / "m.obj", Particles(np.zeros((1, 3))))
    with pytest.raises(InputError, match=r"path: expected a file path"):
        save(3, mesh)
    with pytest.raises(InputError, match=r"binary"):
        save(tmp_path / "m.ply", mesh, binary="yes")


def test_malformed_obj_and_off_raise_format_error(tmp_path):
    bad = {
        "a.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"a\.obj: element 'f': line 4: vertex index 4 out of range \[1, 3\]"),
        "b.obj": ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", r"b\.obj: element 'v': line 2: expected at least 3 numbers"),
        "c.obj": ("v 0 0 0\nv 1 0 x\nv 0 1 0\nf 1 2 3\n", r"c\.obj: element 'v': line 2: cannot parse"),
        "d.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"d\.obj: element 'f': line 4: a face needs at least 3"),
        "e.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/a 2 3\n", r"e\.obj: element 'f': line 4: cannot parse vertex reference '1/a'"),
        "f.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n", r"f\.obj: element 'f': line 4: vertex index -4 reaches before"),
        "g.obj": ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"g\.obj: element 'v': line 1: NaN"),
        "h.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/2 2/1 3/1\n", r"h\.obj: element 'f': line 5: texture index 2 out of range \[1, 1\]"),
        "i.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", r"i\.obj: element 'f': line 4: vertex index 0"),
        "a.off": ("OFF\n3 1 0\n0 0 0\n1 0 0\n", r"a\.off: element 'vertex': file ends after 2 of 3 rows"),
        "b.off": ("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", r"b\.off: element 'face': file ends after 1 of 2 rows"),
        "c.off": ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", r"c\.off: element 'face': row 0: vertex index 3 out of range"),
        "d.off": ("OFFX\n3 1 0\n", r"d\.off: element 'header'"),
        "e.off": ("OFF\nthree 1 0\n", r"e\.off: element 'header': expected 'NVERTICES NFACES NEDGES'"),
        "f.off": ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", r"f\.off: element 'face': row 0: 4 vertices announced, 3 values"),
        "g.off": ("OFF\n3 1 0\n0 0 0\n1 0 0 5\n0 1 0\n3 0 1 2\n", r"g\.off: element 'vertex': row 1: 4 values, the rows before have 3"),
        "h.off": ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n", r"h\.off: element 'face': 1 unexpected lines"),
        "i.off": ("4OFF\n3 1 0\n", r"i\.off: element 'header': '4OFF': only 3-D"),
        "a.ply": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
                  r"a\.ply: element 'face': row 0: vertex index 3 out of range \[0, 3\)"),
        "b.ply": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
                  r"b\.ply: element 'face': row 0: a face needs at least 3 vertices, got 2"),
        "c.ply": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 7\n",
                  r"c\.ply: element 'tristrips': row 0: vertex index 7 out of range"),
        "d.ply": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty uchar flags\nend_header\n0 0 0\n1 0 0\n0 1 0\n1\n",
                  r"d\.ply: element 'face': no vertex index list"),
        "e.ply": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\n"
                  "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 4 0 0 1 1\n",
                  r"e\.ply: element 'face': row 0: texcoord has 4 values for 3 vertices"),
    }
    for name, (text, match) in bad.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(FormatError, match=match):
            load(tmp_path / name)


def test_obj_texture_and_bump_map_with_options(tmp_path):
    from PIL import Image

    Image.fromarray(np.full((2, 3, 3), 255, np.uint8)).save(tmp_path / "my tex.png")
    Image.fromarray(np.full((4, 4, 3), 128, np.uint8)).save(tmp_path / "n.png")
    (tmp_path / "t.mtl").write_text("newmtl plain\nKd 0.5 0.5 0.5\n"
                                    "newmtl tex\nKd 1 1 1\nmap_Kd -o 0 0 -blendu on my tex.png\nmap_Bump -bm 1 n.png\n")
    (tmp_path / "t.obj").write_text("mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                    "usemtl plain\nusemtl tex\nf 1/1 2/2 3/3\n")
    m = load(tmp_path / "t.obj")
    assert m.texture.shape == (2, 3, 3) and np.all(m.texture == 1.0)
    np.testing.assert_allclose(m.normal_map, 128 / 255)
    assert m.vertex_colors is None  # a texture replaces Kd colours
