"""The PLY container layer, checked against the independent ``plyfile`` package."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest

from unmesh.errors import FormatError
from unmesh.io._plyformat import ListColumn, encode_ply, read_ply


def _plyfile_tables(path):
    data = plyfile.PlyData.read(str(path), mmap=False)
    out = {}
    for el in data.elements:
        cols = {}
        for p in el.properties:
            v = el.data[p.name]
            if isinstance(p, plyfile.PlyListProperty):
                cols[p.name] = [np.asarray(x) for x in v]
            else:
                cols[p.name] = np.asarray(v)
        out[el.name] = cols
    return data, out


def _assert_same(ours, theirs):
    assert set(ours) == set(theirs)
    for el, cols in theirs.items():
        assert list(ours[el]) == list(cols)
        for name, ref in cols.items():
            got = ours[el][name]
            if isinstance(got, ListColumn):
                assert len(got) == len(ref)
                for i, row in enumerate(ref):
                    np.testing.assert_array_equal(got.values[got.offsets[i]:got.offsets[i + 1]], row)
                    assert got.values.dtype == row.dtype.newbyteorder("=")
            else:
                assert got.dtype == ref.dtype.newbyteorder("=")
                np.testing.assert_array_equal(got, ref)


def _plyfile_mixed(rng, n=50, nf=40):
    vdt = [("x", "f4"), ("y", "f8"), ("flag", "u1"), ("id", "i4"), ("s", "i2"), ("u", "u2"), ("c", "i1"),
           ("big", "u4")]
    v = np.empty(n, vdt)
    for name, code in vdt:
        info = np.iinfo(code) if code[0] in "iu" else None
        v[name] = rng.integers(info.min, info.max, n) if info else rng.normal(size=n)
    sizes = rng.integers(3, 7, nf)
    f = np.empty(nf, [("vertex_indices", object), ("quality", "f4")])
    f["vertex_indices"] = [rng.integers(0, n, k).astype("i4") for k in sizes]
    f["quality"] = rng.random(nf)
    return [plyfile.PlyElement.describe(v, "vertex"),
            plyfile.PlyElement.describe(f, "face", len_types={"vertex_indices": "u1"})]


@pytest.mark.parametrize("text,byte_order", [(True, "="), (False, "<"), (False, ">")])
def test_reads_files_written_by_plyfile(tmp_path, rng, text, byte_order):
    path = tmp_path / "mixed.ply"
    plyfile.PlyData(_plyfile_mixed(rng), text=text, byte_order=byte_order, comments=["hello"]).write(str(path))
    header, tables = read_ply(path)
    assert header.comments == ["hello"]
    _, ref = _plyfile_tables(path)
    _assert_same(tables, ref)


@pytest.mark.parametrize("binary,byte_order", [(False, "<"), (True, "<"), (True, ">")])
def test_plyfile_reads_what_we_write(tmp_path, rng, binary, byte_order):
    n = 30
    vals = {"x": rng.normal(size=n).astype("f4"), "d": rng.normal(size=n), "k": rng.integers(-5, 5, n).astype("i4"),
            "red": rng.integers(0, 256, n).astype("u1")}
    props = [(k, v, v.dtype.str[1:], None) for k, v in vals.items()]
    faces = rng.integers(0, n, (20, 3)).astype("i4")
    data = encode_ply([("vertex", n, props), ("face", 20, [("vertex_indices", faces, "i4", "u1")])],
                      ["c1"], binary=binary, byte_order=byte_order)
    path = tmp_path / "ours.ply"
    path.write_bytes(data)
    _, ref = _plyfile_tables(path)
    for k, v in vals.items():
        np.testing.assert_array_equal(ref["vertex"][k], v)
    np.testing.assert_array_equal(np.stack(ref["face"]["vertex_indices"]), faces)
    _, tables = read_ply(path)
    _assert_same(tables, ref)


def test_ascii_values_read_back_exactly(tmp_path, rng):
    n = 1000
    f4 = (rng.normal(size=n) * 10.0 ** rng.integers(-30, 30, n)).astype(np.float32)
    f8 = rng.normal(size=n) * 10.0 ** rng.integers(-200, 200, n)
    data = encode_ply([("vertex", n, [("a", f4, "f4", None), ("b", f8, "f8", None)])], binary=False)
    (tmp_path / "a.ply").write_bytes(data)
    _, t = read_ply(tmp_path / "a.ply")
    np.testing.assert_array_equal(t["vertex"]["a"], f4)
    np.testing.assert_array_equal(t["vertex"]["b"], f8)


def _triangle_file(fmt, n=4, faces=((0, 1, 2), (0, 2, 3))):
    head = f"ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n" \
           f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    return head


@pytest.mark.parametrize("binary", [True, False])
def test_truncated_files_name_file_element_and_rows(tmp_path, binary):
    n = 3000
    pts = np.arange(3 * n, dtype=np.float32).reshape(n, 3)
    faces = np.arange(30, dtype=np.int32).reshape(10, 3)
    data = encode_ply([("vertex", n, [(c, pts[:, i], "f4", None) for i, c in enumerate("xyz")]),
                       ("face", 10, [("vertex_indices", faces, "i4", "u1")])], binary=binary)
    body = data.index(b"end_header\n") + 11
    if binary:
        cut_vertex = body + 120 * 12 + 5
        cut_face = len(data) - 13 * 3 + 5
    else:
        lines = data.split(b"\n")
        head_lines = data[:body].count(b"\n")
        cut_vertex = len(b"\n".join(lines[:head_lines + 120])) + 1
        cut_face = len(b"\n".join(lines[:head_lines + n + 7])) + 1
    path = tmp_path / "bunny.ply"
    path.write_bytes(data[:cut_vertex])
    with pytest.raises(FormatError, match=r"bunny\.ply: element 'vertex': file ends after 120 of 3000 rows"):
        read_ply(path)
    path.write_bytes(data[:cut_face])
    with pytest.raises(FormatError, match=r"bunny\.ply: element 'face': file ends after 7 of 10 rows"):
        read_ply(path)
    path.write_bytes(data[:body])
    with pytest.raises(FormatError, match=r"element 'vertex': file ends after 0 of 3000 rows"):
        read_ply(path)


def test_ragged_binary_lists_truncated_and_negative(tmp_path):
    faces = [np.array([0, 1, 2], "i4"), np.array([0, 1, 2, 3], "i4"), np.array([3, 2, 1], "i4")]
    f = np.empty(3, [("vertex_indices", object)])
    f["vertex_indices"] = faces
    v = np.zeros(4, [("x", "f4"), ("y", "f4"), ("z", "f4")])
    path = tmp_path / "poly.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex"),
                     plyfile.PlyElement.describe(f, "face", len_types={"vertex_indices": "i4"})],
                    byte_order="<").write(str(path))
    _, t = read_ply(path)
    col = t["face"]["vertex_indices"]
    assert col.offsets.tolist() == [0, 3, 7, 10]
    data = path.read_bytes()
    path.write_bytes(data[:-6])
    with pytest.raises(FormatError, match=r"poly\.ply: element 'face': file ends after 2 of 3 rows"):
        read_ply(path)
    # negative list length in the second row
    start = data.index(b"end_header\n") + 11 + 4 * 12 + 4 + 12
    bad = data[:start] + np.int32(-4).tobytes() + data[start + 4:]
    path.write_bytes(bad)
    with pytest.raises(FormatError, match=r"element 'face': row 1: property 'vertex_indices': negative list length"):
        read_ply(path)


MALFORMED_HEADERS = [
    (b"plx\nformat ascii 1.0\nend_header\n", r"not a PLY file"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", r"no 'end_header'"),
    (b"ply\nformat ascii 2.0\nend_header\n", r"version"),
    (b"ply\nformat binary_middle_endian 1.0\nend_header\n", r"header line 2"),
    (b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", r"negative count"),
    (b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n", r"not an integer"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty flaot x\nend_header\n1\n", r"element 'vertex': header line 4: property 'x': unknown type 'flaot'"),
    (b"ply\nformat ascii 1.0\nelement face 1\nproperty list float int v\nend_header\n", r"element 'face'.*integer type"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nend_header\n1 2\n", r"declared twice"),
    (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n", r"before any 'element'"),
    (b"ply\nelement vertex 1\nend_header\n", r"before 'format'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nbogus line\nend_header\n", r"unexpected header line"),
]


@pytest.mark.parametrize("data,message", MALFORMED_HEADERS)
def test_malformed_headers(tmp_path, data, message):
    path = tmp_path / "bad.ply"
    path.write_bytes(data)
    with pytest.raises(FormatError, match=r"bad\.ply: .*" + message):
        read_ply(path)


ASCII_BODIES = [
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n", None),
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n\n\n", None),  # trailing blank lines are fine
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n", r"element 'face': file ends after 1 of 2 rows"),
    ("0 0 0\n1 0\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n", r"element 'vertex': row 1: property 'z': line ends early"),
    ("0 0 0\n1 0 0 7\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n", r"element 'vertex': row 1: 1 extra values"),
    ("0 0 0\n1 0 abc\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n", r"element 'vertex': row 1: property 'z': value 'abc'"),
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n4 0 2 3\n", r"element 'face': row 1: property 'vertex_indices': list of 4 values but only 3"),
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3.5\n", r"element 'face': row 1: property 'vertex_indices': value '3.5' is not a valid int"),
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n300 0 2 3\n", r"element 'face': row 1: property 'vertex_indices'"),
    ("0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n3 1 2 3\n", r"element 'face': 1 unexpected lines after the last row"),
    ("0 0 0\n\n0 1 0\n1 1 0\n3 0 1 2\n3 0 2 3\n", r"element 'vertex': row 1: property 'x': line ends early"),
]


@pytest.mark.parametrize("body,message", ASCII_BODIES)
def test_ascii_bodies(tmp_path, body, message):
    path = tmp_path / "quad.ply"
    path.write_text(_triangle_file("ascii") + body)
    if message is None:
        _, t = read_ply(path)
        assert t["face"]["vertex_indices"].values.tolist() == [0, 1, 2, 0, 2, 3]
        assert t["vertex"]["x"].dtype == np.float32
    else:
        with pytest.raises(FormatError, match=r"quad\.ply: " + message):
            read_ply(path)


def test_binary_trailing_garbage_and_uchar_overflow(tmp_path):
    pts = np.zeros((4, 3), np.float32)
    faces = np.array([[0, 1, 2]], np.int32)
    data = encode_ply([("vertex", 4, [(c, pts[:, i], "f4", None) for i, c in enumerate("xyz")]),
                       ("face", 1, [("vertex_indices", faces, "i4", "u1")])])
    path = tmp_path / "g.ply"
    path.write_bytes(data + b"\n")  # a trailing newline is tolerated
    read_ply(path)
    path.write_bytes(data + b"\x01\x02\x03\x04")
    with pytest.raises(FormatError, match=r"g\.ply: element 'face': 4 bytes of unexpected data"):
        read_ply(path)
