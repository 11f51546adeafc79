"""Issue 24: ``read_vtu`` validates components, base64 lengths, shapes and offsets."""

from __future__ import annotations

import base64
import re
import struct

import numpy as np
import pytest

from unmesh.errors import FormatError
from unmesh.fem import hex_grid
from unmesh.fem.vtk_io import read_vtu, write_vtu


@pytest.fixture
def vtu(tmp_path):
    p = tmp_path / "m.vtu"
    write_vtu(p, hex_grid((2, 1, 1)))
    return p


def _payload(arr: np.ndarray, nbytes: int | None = None) -> str:
    raw = arr.tobytes()
    return base64.b64encode(struct.pack("<Q", len(raw) if nbytes is None else nbytes) + raw).decode()


def _replace_array(text: str, name: str, payload: str, attrs: str | None = None) -> str:
    pat = re.compile(r'(<DataArray [^>]*Name="' + name + r'"[^>]*>)([^<]*)(</DataArray>)')
    m = pat.search(text)
    head = m.group(1) if attrs is None else attrs
    return text[:m.start()] + head + payload + m.group(3) + text[m.end():]


def _points_components(text: str, value: str) -> str:
    return re.sub(r'(Name="Points" NumberOfComponents=)"3"', rf'\1"{value}"', text)


def test_bad_number_of_components(vtu):
    vtu.write_text(_points_components(vtu.read_text(), "0"))
    with pytest.raises(FormatError, match=r"m\.vtu: DataArray 'Points': NumberOfComponents: expected an integer"):
        read_vtu(vtu)


def test_points_with_two_components(vtu):
    vtu.write_text(_points_components(vtu.read_text(), "2"))
    with pytest.raises(FormatError, match=r"m\.vtu: DataArray 'Points': expected NumberOfComponents=\"3\""):
        read_vtu(vtu)


def test_base64_length_header_mismatch(vtu):
    text = vtu.read_text()
    vtu.write_text(_replace_array(text, "faces", _payload(np.arange(10, dtype=np.int64), nbytes=10**12)))
    with pytest.raises(FormatError, match=r"m\.vtu: DataArray 'faces': the length header says 1000000000000 bytes"):
        read_vtu(vtu)


def test_bad_base64(vtu):
    vtu.write_text(_replace_array(vtu.read_text(), "types", "!!!not base64!!!"))
    with pytest.raises(FormatError, match=r"m\.vtu: DataArray 'types': bad base64 data"):
        read_vtu(vtu)


@pytest.mark.parametrize("offsets", [[5, 3], [10**9, 10**9 + 1], [-1, 4]])
def test_bad_faceoffsets(vtu, offsets):
    vtu.write_text(_replace_array(vtu.read_text(), "faceoffsets", _payload(np.array(offsets, dtype=np.int64))))
    with pytest.raises(FormatError, match=r"m\.vtu: cell [01]: "):
        read_vtu(vtu)


def test_face_vertex_out_of_range(vtu):
    mesh_faces = np.array([1, 3, 0, 1, 99], dtype=np.int64)
    text = _replace_array(vtu.read_text(), "faces", _payload(mesh_faces))
    text = _replace_array(text, "faceoffsets", _payload(np.array([5], dtype=np.int64)))
    text = _replace_array(text, "types", _payload(np.array([42], dtype=np.uint8)))
    vtu.write_text(text.replace('NumberOfCells="2"', 'NumberOfCells="1"'))
    with pytest.raises(FormatError, match=r"m\.vtu: cell 0: a vertex index outside \[0, 12\)"):
        read_vtu(vtu)


def test_types_count_must_match_the_cells(vtu):
    vtu.write_text(_replace_array(vtu.read_text(), "types", _payload(np.array([42], dtype=np.uint8))))
    with pytest.raises(FormatError, match=r"m\.vtu: DataArray 'types': 1 cell types for 2 cells"):
        read_vtu(vtu)


def test_displacement_rows_must_match_the_points(vtu):
    vtu.write_text(_replace_array(vtu.read_text(), "displacement", _payload(np.zeros((2, 3)))))
    with pytest.raises(FormatError, match=r"m\.vtu: point data 'displacement': 2 rows for 12 points"):
        read_vtu(vtu)


def test_ascii_garbage_values(vtu):
    text = vtu.read_text()
    m = re.search(r'<DataArray type="UInt8" Name="types"[^>]*>', text)
    head = m.group(0).replace('format="binary"', 'format="ascii"')
    vtu.write_text(_replace_array(text, "types", "42 4x2", attrs=head))
    with pytest.raises(FormatError, match=r"m\.vtu: DataArray 'types': values that are not UInt8 numbers"):
        read_vtu(vtu)


# -- PVD series ---------------------------------------------------------------------------------
def _series(tmp_path):
    from unmesh.fem.vtk_io import write_pvd

    for k in range(2):
        write_vtu(tmp_path / f"m{k}.vtu", hex_grid((k + 1, 1, 1)))
    p = tmp_path / "s.pvd"
    write_pvd(p, ["m0.vtu", "m1.vtu"], [0.0, 0.25])
    return p


def test_pvd_series_round_trip(tmp_path):
    from unmesh.fem.vtk_io import read_pvd, read_series

    p = _series(tmp_path)
    assert [(t, f.name) for t, f in read_pvd(p)] == [(0.0, "m0.vtu"), (0.25, "m1.vtu")]
    assert [(t, m.n_elements) for t, m, _ in read_series(p)] == [(0.0, 1), (0.25, 2)]


@pytest.mark.parametrize(("old", "new", "message"), [
    ('timestep="0.25"', 'timestep="nan"', r"s\.pvd: DataSet 1: timestep: expected a finite number, got 'nan'"),
    ('timestep="0.25"', 'timestep="x"', r"s\.pvd: DataSet 1: timestep: expected a finite number, got 'x'"),
    (' timestep="0.25"', "", r"s\.pvd: DataSet 1: timestep: expected a finite number, got '\(none\)'"),
    ('file="m1.vtu"', 'file="gone.vtu"', r"s\.pvd: DataSet 1: file 'gone\.vtu' not found next to the \.pvd"),
    ('file="m1.vtu"', 'file="' + "m" * 300 + '.vtu"', r"s\.pvd: DataSet 1: file 'mmm+' not found"),
    ('file="m1.vtu"', 'file=""', r"s\.pvd: DataSet 1: no 'file' attribute"),
    ('type="Collection"', 'type="UnstructuredGrid"', r"s\.pvd: expected a VTK Collection \(\.pvd\) file"),
    ("<Collection>", "<Collection", r"s\.pvd: not a valid XML file"),
])
def test_pvd_errors_name_file_and_entry(tmp_path, old, new, message):
    from unmesh.fem.vtk_io import read_pvd

    p = _series(tmp_path)
    p.write_text(p.read_text().replace(old, new))
    with pytest.raises(FormatError, match=message):
        read_pvd(p)


def test_pvd_listing_a_broken_vtu_names_the_vtu(tmp_path):
    from unmesh.fem.vtk_io import read_series

    p = _series(tmp_path)
    (tmp_path / "m1.vtu").write_text("<VTKFile")
    with pytest.raises(FormatError, match=r"m1\.vtu: not a valid XML file"):
        list(read_series(p))
