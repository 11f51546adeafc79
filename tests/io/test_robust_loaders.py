"""Issue 24 reproducers: every loader raises only documented errors, before allocating."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from unmesh import io
from unmesh.errors import FormatError, InputError
from unmesh.io.budget import budget_problem, format_bytes, memory_budget, parse_size
from unmesh.meshes import TriangleMesh

TRI_PLY_HEAD = "ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"


def test_obj_index_beyond_int64_is_a_format_error(tmp_path):
    p = tmp_path / "big.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n")
    with pytest.raises(FormatError, match=r"big\.obj: element 'f': line 4: vertex reference .* out of range"):
        io.load(p)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/99999999999999999999\nvt 0 0\n")
    with pytest.raises(FormatError, match=r"big\.obj"):
        io.load(p)


def test_off_face_index_beyond_int64_is_a_format_error(tmp_path):
    p = tmp_path / "big.off"
    p.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999999999999\n")
    with pytest.raises(FormatError, match=r"big\.off: element 'face': row 0: vertex index .* out of range"):
        io.load(p)


def test_ascii_ply_list_length_1e999(tmp_path):
    p = tmp_path / "inf.ply"
    p.write_text(TRI_PLY_HEAD.format(fmt="ascii") + "element face 1\nproperty list uchar int vertex_indices\n"
                 "end_header\n0 0 0\n1 0 0\n0 1 0\n1e999 0 1 2\n")
    with pytest.raises(FormatError, match=r"inf\.ply: element 'face': row 0: property 'vertex_indices'"):
        io.load(p)


def test_binary_ply_list_length_2_31_is_refused_before_allocating(tmp_path):
    head = TRI_PLY_HEAD.format(fmt="binary_little_endian") + \
        "element face 1\nproperty list int int vertex_indices\nend_header\n"
    body = np.zeros(9, "<f4").tobytes() + struct.pack("<i", 2**31 - 1) + struct.pack("<3i", 0, 1, 2)
    p = tmp_path / "long.ply"
    p.write_bytes(head.encode() + body)
    with pytest.raises(FormatError, match=r"long\.ply: element 'face': row 0: .* runs past the end of the file"):
        io.load(p)


@pytest.mark.parametrize("ragged", [False, True])
def test_huge_element_count_is_checked_against_the_file_length(tmp_path, ragged):
    head = TRI_PLY_HEAD.format(fmt="binary_little_endian") + \
        "element face 1000000000000\nproperty list uchar int vertex_indices\nend_header\n"
    face = struct.pack("<B3i", 3, 0, 1, 2)
    if ragged:
        face += struct.pack("<B4i", 4, 0, 1, 2, 0)
    p = tmp_path / "count.ply"
    p.write_bytes(head.encode() + np.zeros(9, "<f4").tobytes() + face)
    with pytest.raises(FormatError, match=r"count\.ply: element 'face': file ends after at most \d+ of "
                                          r"1000000000000 rows \(the header announces 931 GiB or more"):
        io.load(p)


def test_unknown_recorded_dtype_is_refused(tmp_path):
    p = tmp_path / "obj.ply"
    p.write_text("ply\nformat ascii 1.0\ncomment unmesh dtype w object\nelement vertex 1\nproperty float x\n"
                 "property float y\nproperty float z\nproperty float w\nend_header\n0 0 0 1\n")
    with pytest.raises(FormatError, match=r"obj\.ply: element 'vertex': comment 'unmesh dtype w object'"):
        io.load(p)


def test_overlong_material_and_texture_names_are_missing_files(tmp_path):
    name = "m" * 300
    p = tmp_path / "long.obj"
    p.write_text(f"mtllib {name}.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.warns(UserWarning, match="not found"):
        assert len(io.load(p).faces) == 1
    mesh = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    q = tmp_path / "tex.ply"
    io.save(q, mesh, binary=False)
    text = q.read_text().replace("end_header", f"comment TextureFile {name}.png\nend_header")
    q.write_text(text)
    with pytest.warns(UserWarning, match="not found"):
        assert len(io.load(q).faces) == 1


def test_random_bytes_are_not_an_empty_obj(tmp_path):
    rng = np.random.default_rng(3)
    p = tmp_path / "junk.obj"
    p.write_bytes(rng.integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(FormatError, match=r"junk\.obj: not an OBJ|junk\.obj: binary data"):
        io.load(p)
    p.write_text("hello world\nthis is text\n")
    with pytest.raises(FormatError, match=r"junk\.obj: no OBJ statement"):
        io.load(p)
    p.write_text("# only a comment\n")
    assert len(io.load(p).vertices) == 0  # an empty OBJ stays a valid, empty mesh


def test_knn_point_at_1e200_and_normals(rng):
    from unmesh.spatial import knn
    from unmesh.surfels import estimate_normals

    pts = rng.random((30, 3))
    pts[7] = [1e200, 1.0, 0.0]
    _, i = knn(pts, 6)
    assert i.min() >= 0 and i.max() < len(pts)
    # brute force with the same distance formula (overflowing distances are inf, ties by index)
    with np.errstate(over="ignore"):
        full = np.sqrt(((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2))
    order = np.lexsort((np.broadcast_to(np.arange(30), (30, 30)), full), axis=1)[:, :6]
    np.testing.assert_array_equal(i, order)
    with pytest.raises(InputError, match=r"points: expected coordinates of magnitude <= 1e\+150 .* at row 7"):
        estimate_normals(pts)


def test_point_file_at_1e200_without_normals_is_a_documented_error(tmp_path, rng):
    from unmesh.particles import Particles

    pts = rng.random((30, 3))
    pts[7] = [1e200, 1.0, 0.0]
    p = tmp_path / "far.ply"
    io.save(p, Particles(pts))
    with pytest.raises(InputError, match="row 7"):
        io.load_surfels(p)


def test_memory_budget_parsing(monkeypatch):
    assert parse_size("4GiB") == 4 * 2**30 and parse_size("1.5k") == 1536 and parse_size("100") == 100
    assert format_bytes(8 * 10**12) == "7.28 TiB"
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "1M")
    assert memory_budget() == 2**20
    assert "more than the memory budget of 1 MiB" in budget_problem(2**21, "x")
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "0")
    assert budget_problem(2**60, "x") is None
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "lots")
    with pytest.raises(ValueError, match="UNMESH_MEMORY_BUDGET"):
        memory_budget()


def _points_ply(n: int, binary: bool) -> bytes:
    from unmesh.io._plyformat import encode_ply

    pts = np.zeros((n, 3), np.float32)
    return encode_ply([("vertex", n, [(c, pts[:, i], "f4", None) for i, c in enumerate("xyz")])], binary=binary)


def test_ply_decoded_size_is_checked_against_the_budget(tmp_path, monkeypatch):
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "4K")
    p = tmp_path / "pts.ply"
    # ASCII "0 0 0" rows: 6 bytes of text decode to 12 bytes of values, a 24-byte float table and a line
    p.write_bytes(_points_ply(1000, binary=False))
    with pytest.raises(FormatError, match=r"pts\.ply: element 'vertex': the decoded rows up to element 'vertex' "
                                          r"\(1000 rows\) would need about 89\.8 KiB, more than the memory budget"):
        io.load(p)
    # binary rows decode to their own size: a file over the budget is bounded by its length already
    p.write_bytes(_points_ply(1000, binary=True))
    assert len(p.read_bytes()) > 4096 and len(io.load(p)) == 1000
    # 10000 empty binary lists: 1-byte lengths become 8-byte offsets
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 10000\nproperty list uchar int vertex_indices\nend_header\n")
    p.write_bytes(head.encode() + bytes(36) + bytes(10000))
    with pytest.raises(FormatError, match=r"element 'face': .* would need about 78\.2 KiB, more than the memory"):
        io.load(p)
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "1M")
    with pytest.raises(FormatError, match=r"element 'face': row 0: a face needs at least 3 vertices, got 0"):
        io.load(p)  # within the budget, the file's own problem
    p.write_bytes(_points_ply(1000, binary=False))
    assert len(io.load(p)) == 1000


def test_ascii_ply_with_a_huge_count_reports_where_the_file_ends(tmp_path, monkeypatch):
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "4K")
    p = tmp_path / "huge.ply"
    text = _points_ply(3, binary=False).replace(b"element vertex 3", b"element vertex 1000000000000")
    p.write_bytes(text)
    with pytest.raises(FormatError, match=r"huge\.ply: element 'vertex': file ends after 3 of 1000000000000 rows"):
        io.load(p)


@pytest.mark.parametrize(("body", "message"), [
    ("0 0 0\n1 0 0\n0 1 0\n3 0 1 1e999\n", r"element 'face': row 0: property 'vertex_indices': value '1e999' is not"),
    ("0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999999999999\n", r"element 'face': row 0: property 'vertex_indices': value "
                                                          r"'99999999999999999999' is not a valid int"),
    ("1e999 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", r"element 'vertex': row 0: position is NaN or infinite"),
])
def test_ascii_ply_values_1e999_and_beyond_int64(tmp_path, body, message):
    """Issue 24's OverflowError reproducers in ASCII PLY: face indices and coordinates."""
    p = tmp_path / "big.ply"
    p.write_text(TRI_PLY_HEAD.format(fmt="ascii") + "element face 1\nproperty list uchar int vertex_indices\n"
                 "end_header\n" + body)
    with pytest.raises(FormatError, match=r"big\.ply: " + message):
        io.load(p)
