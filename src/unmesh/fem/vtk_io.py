"""VTU files with VTK polyhedron cells, and PVD series, for ParaView.

:func:`write_vtu` writes an UnstructuredGrid (XML, inline base64 binary, UInt64
headers) with one VTK_POLYHEDRON (type 42) cell per element, its faces in the
``faces``/``faceoffsets`` arrays (each face counter-clockwise seen from outside
the cell). Points are the current (deformed) positions; the point array
``displacement`` holds ``current - rest``. :func:`read_vtu` reads such files back
into a :class:`PolyMesh` (rest positions = points - displacement when present).
:func:`write_pvd` lists a frame series with times.

Example
-------
>>> import tempfile, pathlib
>>> from unmesh.fem import hex_grid
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> write_vtu(d / "m.vtu", hex_grid((2, 1, 1)))
>>> read_vtu(d / "m.vtu")[0].n_elements
2
"""

from __future__ import annotations

import base64
import os
import struct
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import FormatError, InputError
from unmesh.fem.mesh import PolyMesh
from unmesh.io.atomic import atomic_write_text

__all__ = ["read_vtu", "write_pvd", "write_vtu"]

VTK_POLYHEDRON = 42
_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.float32): "Float32", np.dtype(np.int64): "Int64",
          np.dtype(np.int32): "Int32", np.dtype(np.uint8): "UInt8"}
_NP = {v: k for k, v in _TYPES.items()}


def _array(name: str, data: np.ndarray, ncomp: int = 1) -> str:
    arr = np.ascontiguousarray(data)
    if arr.dtype not in _TYPES:
        arr = arr.astype(np.float64 if np.issubdtype(arr.dtype, np.floating) else np.int64)
    raw = arr.tobytes()
    payload = base64.b64encode(struct.pack("<Q", len(raw)) + raw).decode("ascii")
    comp = f' NumberOfComponents="{ncomp}"' if ncomp > 1 else ""
    return f'<DataArray type="{_TYPES[arr.dtype]}" Name="{name}"{comp} format="binary">{payload}</DataArray>'


def _cell_arrays(mesh: PolyMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    noff, nodes = mesh.element_nodes()
    fo = mesh.face_offsets
    sizes = np.diff(fo)[mesh.elem_faces]
    eo = mesh.elem_offsets
    nfaces = np.diff(eo)
    # per element: [nfaces, (size, nodes...)*]
    per_face = sizes + 1
    per_elem = np.add.reduceat(per_face, eo[:-1]) + 1 if len(per_face) else np.ones(mesh.n_elements, np.int64)
    total = int(per_elem.sum())
    faces = np.empty(total, np.int64)
    elem_start = np.r_[0, np.cumsum(per_elem)[:-1]]
    faces[elem_start] = nfaces
    # face headers and node lists
    face_rank = np.arange(len(mesh.elem_faces)) - np.repeat(eo[:-1], nfaces)
    eid = np.repeat(np.arange(mesh.n_elements), nfaces)
    within_elem = np.cumsum(per_face) - per_face - np.repeat(np.r_[0, np.cumsum(per_elem - 1)[:-1]], nfaces)
    head = elem_start[eid] + 1 + within_elem
    del face_rank
    faces[head] = sizes
    starts = fo[mesh.elem_faces]
    flip = mesh.elem_signs < 0
    k = np.arange(sizes.sum()) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    sz = np.repeat(sizes, sizes)
    # reversed faces keep the first node: (0, n-1, n-2, ..., 1)
    src_k = np.where(np.repeat(flip, sizes), (sz - k) % sz, k)
    vals = mesh.face_nodes[np.repeat(starts, sizes) + src_k]
    faces[np.repeat(head + 1, sizes) + k] = vals
    faceoffsets = np.cumsum(per_elem)
    return noff, nodes, faces, faceoffsets


def write_vtu(path: str | os.PathLike[str], mesh: PolyMesh, displacement: Any | None = None,
              point_data: Mapping[str, Any] | None = None, cell_data: Mapping[str, Any] | None = None) -> None:
    """Write a mesh as a VTU file with polyhedron cells (atomically).

    Parameters
    ----------
    path : path
    mesh : PolyMesh
    displacement : (n, 3) array, optional
        Written as point data ``displacement``; points are ``rest + displacement``.
    point_data, cell_data : mapping of name to array, optional
        Extra arrays, first axis n (nodes) or E (elements).

    Example
    -------
    >>> import tempfile, pathlib, numpy as np
    >>> from unmesh.fem import hex_grid
    >>> m = hex_grid((1, 1, 1))
    >>> write_vtu(pathlib.Path(tempfile.mkdtemp()) / "a.vtu", m, np.zeros((8, 3)))
    """
    n, ne = mesh.n_nodes, mesh.n_elements
    disp = np.zeros((n, 3)) if displacement is None else np.asarray(displacement, dtype=np.float64)
    if disp.shape != (n, 3):
        raise InputError(f"displacement: expected shape ({n}, 3), got {disp.shape}")
    noff, nodes, faces, faceoffsets = _cell_arrays(mesh)
    pd = {"displacement": disp, **dict(point_data or {})}
    cd = {"element": np.arange(ne, dtype=np.int64), "nodes": np.diff(noff).astype(np.int64),
          "volume": mesh.volumes(), **dict(cell_data or {})}
    parts = ['<?xml version="1.0"?>',
             '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
             "<UnstructuredGrid>", f'<Piece NumberOfPoints="{n}" NumberOfCells="{ne}">', "<PointData>"]
    for name, arr in pd.items():
        a = np.asarray(arr)
        if a.shape[0] != n:
            raise InputError(f"point_data[{name!r}]: expected first axis {n}, got {a.shape}")
        parts.append(_array(name, a.reshape(n, -1) if a.ndim > 1 else a, a.shape[1] if a.ndim > 1 else 1))
    parts.append("</PointData><CellData>")
    for name, arr in cd.items():
        a = np.asarray(arr)
        if a.shape[0] != ne:
            raise InputError(f"cell_data[{name!r}]: expected first axis {ne}, got {a.shape}")
        parts.append(_array(name, a, a.shape[1] if a.ndim > 1 else 1))
    parts.append("</CellData><Points>")
    parts.append(_array("Points", mesh.points + disp, 3))
    parts.append("</Points><Cells>")
    parts.append(_array("connectivity", nodes))
    parts.append(_array("offsets", noff[1:]))
    parts.append(_array("types", np.full(ne, VTK_POLYHEDRON, np.uint8)))
    parts.append(_array("faces", faces))
    parts.append(_array("faceoffsets", faceoffsets))
    parts.append("</Cells></Piece></UnstructuredGrid></VTKFile>\n")
    atomic_write_text(path, "\n".join(parts))


def write_pvd(path: str | os.PathLike[str], files: Sequence[str], times: Sequence[float]) -> None:
    """Write a ParaView collection listing ``files`` (relative to the .pvd) at ``times``.

    Example
    -------
    >>> import tempfile, pathlib
    >>> write_pvd(pathlib.Path(tempfile.mkdtemp()) / "mesh.pvd", ["mesh_00000.vtu"], [0.0])
    """
    if len(files) != len(times):
        raise InputError(f"times: expected {len(files)} values, got {len(times)}")
    rows = "\n".join(f'<DataSet timestep="{float(t):.9g}" group="" part="0" file="{f}"/>' for f, t in zip(files, times,
                                                                                                       strict=True))
    atomic_write_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                      f"<Collection>\n{rows}\n</Collection>\n</VTKFile>\n")


def _read_array(el: ET.Element, path: Path) -> np.ndarray:
    dtype = _NP.get(el.get("type", ""))
    if dtype is None:
        raise FormatError(f"{path}: DataArray {el.get('Name')!r}: unsupported type {el.get('type')!r}")
    fmt = el.get("format", "ascii")
    text = (el.text or "").strip()
    if fmt == "ascii":
        arr = np.array(text.split(), dtype=dtype)
    elif fmt == "binary":
        try:
            raw = base64.b64decode(text)
        except ValueError:
            raise FormatError(f"{path}: DataArray {el.get('Name')!r}: bad base64 data") from None
        nbytes = struct.unpack("<Q", raw[:8])[0]
        arr = np.frombuffer(raw[8:8 + nbytes], dtype=dtype).copy()
    else:
        raise FormatError(f"{path}: DataArray {el.get('Name')!r}: format {fmt!r} not supported (ascii or binary)")
    ncomp = int(el.get("NumberOfComponents", "1"))
    return arr.reshape(-1, ncomp) if ncomp > 1 else arr


def read_vtu(path: str | os.PathLike[str], *, tolerance: float = 1e-6, abs_tolerance: float = 0.0,
             check: bool = True) -> tuple[PolyMesh, dict[str, np.ndarray]]:
    """Read a polyhedron VTU (as written by :func:`write_vtu`, uncompressed).

    Parameters
    ----------
    path : path
    tolerance, abs_tolerance : float
        Convexity tolerances of the validation (cut meshes are convex only within
        their snapping distance; pass ``check=False`` to skip the geometric checks).
    check : bool

    Returns
    -------
    mesh : PolyMesh
        Rest positions (points minus ``displacement`` when present).
    point_data : dict of str to ndarray

    Example
    -------
    >>> import tempfile, pathlib
    >>> from unmesh.fem import hex_grid
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "m.vtu"; write_vtu(p, hex_grid((1, 1, 1)))
    >>> sorted(read_vtu(p)[1])
    ['displacement']
    """
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise FormatError(f"{p}: not a valid XML file ({exc})") from None
    if root.get("type") != "UnstructuredGrid":
        raise FormatError(f"{p}: expected a VTK UnstructuredGrid file, got type {root.get('type')!r}")
    if root.get("compressor"):
        raise FormatError(f"{p}: compressed VTU files are not supported")
    if root.get("header_type", "UInt32") != "UInt64":
        raise FormatError(f"{p}: only header_type UInt64 is supported")
    piece = root.find("UnstructuredGrid/Piece")
    if piece is None:
        raise FormatError(f"{p}: missing UnstructuredGrid/Piece")
    arrays = {a.get("Name"): _read_array(a, p) for a in piece.iter("DataArray")}
    for need in ("Points", "faces", "faceoffsets", "types"):
        if need not in arrays:
            raise FormatError(f"{p}: missing DataArray {need!r} (expected polyhedron cells)")
    if np.any(arrays["types"] != VTK_POLYHEDRON):
        raise FormatError(f"{p}: cell {int(np.flatnonzero(arrays['types'] != VTK_POLYHEDRON)[0])}: expected polyhedron (42)")
    pd_el = piece.find("PointData")
    pdata = {a.get("Name"): _read_array(a, p) for a in pd_el.iter("DataArray")} if pd_el is not None else {}
    pts = arrays["Points"].astype(np.float64)
    if "displacement" in pdata:
        pts = pts - pdata["displacement"]
    faces = arrays["faces"].astype(np.int64)
    ends = arrays["faceoffsets"].astype(np.int64)
    cells = []
    start = 0
    for e, end in enumerate(ends):
        k = start
        if k >= len(faces):
            raise FormatError(f"{p}: cell {e}: faces array truncated")
        nf = int(faces[k])
        k += 1
        cell = []
        for _ in range(nf):
            sz = int(faces[k])
            cell.append(faces[k + 1:k + 1 + sz].tolist())
            k += 1 + sz
        if k != end:
            raise FormatError(f"{p}: cell {e}: faceoffsets does not match the faces array")
        cells.append(cell)
        start = end
    try:
        return PolyMesh(pts, cells, tolerance=tolerance, abs_tolerance=abs_tolerance, check=check), pdata
    except InputError as exc:
        raise FormatError(f"{p}: {exc}") from None
