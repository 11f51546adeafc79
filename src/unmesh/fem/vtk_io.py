"""VTU files with VTK polyhedron cells, and PVD series, for ParaView.

:func:`write_vtu` writes an UnstructuredGrid (XML, inline base64 binary, UInt64
headers) with one VTK_POLYHEDRON (type 42) cell per element, its faces in the
``faces``/``faceoffsets`` arrays (each face counter-clockwise seen from outside
the cell). Points are the current (deformed) positions; the point array
``displacement`` holds ``current - rest``. :func:`read_vtu` reads such files back
into a :class:`PolyMesh` (rest positions = points - displacement when present).
:func:`write_pvd` lists a frame series with times; :func:`read_pvd` reads such a
list back (checked: every entry a finite time and an existing file next to it) and
:func:`read_series` loads the meshes it lists. Every problem is a
:class:`~unmesh.errors.FormatError` naming the file and the element.

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
import math
import os
import struct
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import FormatError, InputError
from unmesh.fem.cellparse import parse_face_stream
from unmesh.fem.mesh import PolyMesh
from unmesh.io.atomic import atomic_write_text

__all__ = ["read_pvd", "read_series", "read_vtu", "write_pvd", "write_vtu"]

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
    """One DataArray as (n,) or (n, NumberOfComponents); every inconsistency is a FormatError."""
    name = el.get("Name")
    where = f"{path}: DataArray {name!r}"
    dtype = _NP.get(el.get("type", ""))
    if dtype is None:
        raise FormatError(f"{where}: unsupported type {el.get('type')!r}")
    raw_comp = el.get("NumberOfComponents", "1")
    try:
        ncomp = int(raw_comp)
    except ValueError:
        ncomp = 0
    if not 1 <= ncomp <= 64:
        raise FormatError(f"{where}: NumberOfComponents: expected an integer from 1 to 64, got {raw_comp[:40]!r}")
    fmt = el.get("format", "ascii")
    text = (el.text or "").strip()
    if fmt == "ascii":
        try:
            arr = np.array(text.split(), dtype=dtype)
        except (ValueError, OverflowError):
            raise FormatError(f"{where}: values that are not {el.get('type')} numbers") from None
    elif fmt == "binary":
        try:
            raw = base64.b64decode(text, validate=True)
        except ValueError:
            raise FormatError(f"{where}: bad base64 data") from None
        if len(raw) < 8:
            raise FormatError(f"{where}: binary data shorter than its 8-byte length header")
        nbytes = struct.unpack("<Q", raw[:8])[0]
        if nbytes != len(raw) - 8:
            raise FormatError(f"{where}: the length header says {nbytes} bytes, the data has {len(raw) - 8}")
        if nbytes % dtype.itemsize:
            raise FormatError(f"{where}: {nbytes} bytes is not a whole number of {el.get('type')} values")
        arr = np.frombuffer(raw, dtype=dtype.newbyteorder("<"), offset=8).astype(dtype)
    else:
        raise FormatError(f"{where}: format {fmt!r} not supported (ascii or binary)")
    if arr.size % ncomp:
        raise FormatError(f"{where}: {arr.size} values are not a whole number of tuples of {ncomp} components")
    return arr.reshape(-1, ncomp) if ncomp > 1 else arr


def _count(piece: ET.Element, key: str, path: Path) -> int | None:
    raw = piece.get(key)
    if raw is None:
        return None
    try:
        n = int(raw)
    except ValueError:
        n = -1
    if n < 0:
        raise FormatError(f"{path}: Piece {key}: expected a count >= 0, got {raw[:40]!r}")
    return n


def _face_stream(faces: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The ``faces`` / ``faceoffsets`` stream -> (nodes, face_offsets, cell_offsets) flat arrays
    (see :func:`unmesh.fem.cellparse.parse_face_stream`), or None when the stream is malformed
    (then :func:`_polyhedra` says where). All cells are walked together, one face at a time."""
    if ends.ndim != 1 or faces.ndim != 1 or len(ends) == 0:
        return None
    begin = np.concatenate([[0], ends[:-1]])
    if np.any(ends <= begin) or ends[-1] > len(faces):
        return None
    n_faces = faces[begin]
    if np.any(n_faces < 1) or np.any(n_faces > ends - begin - 1):
        return None
    width = int(n_faces.max())
    face_start = np.zeros((len(ends), width), dtype=np.int64)
    face_size = np.zeros((len(ends), width), dtype=np.int64)
    k = begin + 1
    for j in range(width):
        act = np.flatnonzero(n_faces > j)
        at, end = k[act], ends[act]
        if np.any(at >= end):
            return None
        size = faces[at]
        if np.any(size < 0) or np.any(size > end - at - 1):
            return None
        face_start[act, j], face_size[act, j] = at + 1, size
        k[act] = at + 1 + size
    if np.any(k != ends):
        return None
    used = np.arange(width) < n_faces[:, None]
    start, size = face_start[used], face_size[used]
    offsets = np.concatenate([[0], np.cumsum(size)]).astype(np.int64)
    take = np.repeat(start - offsets[:-1], size) + np.arange(offsets[-1])
    return faces[take], offsets, np.concatenate([[0], np.cumsum(n_faces)]).astype(np.int64)


def _polyhedra(faces: np.ndarray, ends: np.ndarray, npts: int, path: Path) -> list[list[list[int]]]:
    """The ``faces`` / ``faceoffsets`` arrays -> cells as lists of faces (vertex lists), checked."""
    if ends.ndim != 1 or faces.ndim != 1:
        raise FormatError(f"{path}: DataArray 'faces' / 'faceoffsets': expected one component")
    cells = []
    start = 0
    nfaces = len(faces)
    for e, end in enumerate(ends.tolist()):
        if not start < end <= nfaces:
            raise FormatError(f"{path}: cell {e}: faceoffsets {end} outside ({start}, {nfaces}] "
                              "(offsets must increase and stay inside the faces array)")
        k = start
        nf = int(faces[k])
        k += 1
        if not 1 <= nf <= end - k:
            raise FormatError(f"{path}: cell {e}: {nf} faces announced in {end - start} values")
        cell = []
        for _ in range(nf):
            if k >= end:
                raise FormatError(f"{path}: cell {e}: faces array ends inside the cell")
            sz = int(faces[k])
            if not 0 <= sz <= end - k - 1:
                raise FormatError(f"{path}: cell {e}: a face of {sz} vertices does not fit in the cell's values")
            cell.append(faces[k + 1:k + 1 + sz].tolist())
            k += 1 + sz
        if k != end:
            raise FormatError(f"{path}: cell {e}: faceoffsets does not match the faces array")
        if len(cell) and (min(min(f, default=0) for f in cell) < 0 or max(max(f, default=0) for f in cell) >= npts):
            raise FormatError(f"{path}: cell {e}: a vertex index outside [0, {npts})")
        cells.append(cell)
        start = end
    return cells


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
    root = _parse_xml(p)
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
    pts = arrays["Points"]
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise FormatError(f"{p}: DataArray 'Points': expected NumberOfComponents=\"3\", got shape {pts.shape}")
    pts = pts.astype(np.float64)
    if not np.all(np.isfinite(pts)):
        raise FormatError(f"{p}: DataArray 'Points': NaN or infinite coordinates")
    types = arrays["types"]
    ends = arrays["faceoffsets"].astype(np.int64)
    if types.ndim != 1 or len(types) != len(ends):
        raise FormatError(f"{p}: DataArray 'types': {len(types)} cell types for {len(ends)} cells ('faceoffsets')")
    for key, n in (("NumberOfPoints", len(pts)), ("NumberOfCells", len(ends))):
        want = _count(piece, key, p)
        if want is not None and want != n:
            raise FormatError(f"{p}: Piece {key}={want} but the arrays hold {n}")
    if np.any(types != VTK_POLYHEDRON):
        raise FormatError(f"{p}: cell {int(np.flatnonzero(types != VTK_POLYHEDRON)[0])}: expected polyhedron (42)")
    pd_el = piece.find("PointData")
    pdata = {a.get("Name"): _read_array(a, p) for a in pd_el.iter("DataArray")} if pd_el is not None else {}
    for name, arr in pdata.items():
        if len(arr) != len(pts):
            raise FormatError(f"{p}: point data {name!r}: {len(arr)} rows for {len(pts)} points")
    if "displacement" in pdata:
        disp = pdata["displacement"]
        if disp.shape != pts.shape or not np.all(np.isfinite(disp)):
            raise FormatError(f"{p}: point data 'displacement': expected finite (N, 3) values, got shape {disp.shape}")
        pts = pts - disp
    faces = arrays["faces"].astype(np.int64)
    flat = _face_stream(faces, ends)
    csr = parse_face_stream(*flat, len(pts)) if flat is not None else None
    try:
        if csr is not None:
            return PolyMesh.from_arrays(pts, *csr, tolerance=tolerance, abs_tolerance=abs_tolerance,
                                        check=check), pdata
        # something is irregular: the checked list path names it
        cells = _polyhedra(faces, ends, len(pts), p)
        return PolyMesh(pts, cells, tolerance=tolerance, abs_tolerance=abs_tolerance, check=check), pdata
    except (InputError, ValueError, IndexError) as exc:  # the mesh's own validation
        raise FormatError(f"{p}: {exc}") from None


def _parse_xml(p: Path) -> ET.Element:
    try:
        return ET.parse(p).getroot()
    except (ET.ParseError, UnicodeError, ValueError) as exc:
        raise FormatError(f"{p}: not a valid XML file ({exc})") from None


def read_pvd(path: str | os.PathLike[str]) -> list[tuple[float, Path]]:
    """The ``(time, file)`` entries of a ParaView collection (as written by :func:`write_pvd`).

    Parameters
    ----------
    path : path
        A ``.pvd`` file; its ``DataSet`` files are relative to its folder.

    Returns
    -------
    list of (float, Path)
        In file order; times are finite, files exist.

    Raises
    ------
    FormatError
        Naming the file and the ``DataSet`` entry (0-based): not XML, not a
        ``Collection``, a missing or non-finite ``timestep``, a missing ``file``
        attribute, or a listed file that does not exist.

    Example
    -------
    >>> import tempfile, pathlib
    >>> from unmesh.fem import hex_grid
    >>> d = pathlib.Path(tempfile.mkdtemp()); write_vtu(d / "m0.vtu", hex_grid((1, 1, 1)))
    >>> write_pvd(d / "s.pvd", ["m0.vtu"], [0.5])
    >>> [(t, f.name) for t, f in read_pvd(d / "s.pvd")]
    [(0.5, 'm0.vtu')]
    """
    p = Path(path)
    root = _parse_xml(p)
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        raise FormatError(f"{p}: expected a VTK Collection (.pvd) file, got {root.tag[:40]!r} "
                          f"of type {(root.get('type') or '')[:40]!r}")
    coll = root.find("Collection")
    if coll is None:
        raise FormatError(f"{p}: missing the Collection element")
    out = []
    for i, ds in enumerate(coll.findall("DataSet")):
        where = f"{p}: DataSet {i}"
        raw = ds.get("timestep")
        try:
            t = float(raw) if raw is not None else math.nan
        except ValueError:
            t = math.nan
        if not math.isfinite(t):
            raise FormatError(f"{where}: timestep: expected a finite number, got {(raw or '(none)')[:40]!r}")
        name = ds.get("file")
        if not name:
            raise FormatError(f"{where}: no 'file' attribute")
        f = p.parent / name
        try:
            exists = f.is_file()
        except (OSError, ValueError):  # over-long names, NUL bytes
            exists = False
        if not exists:
            raise FormatError(f"{where}: file {name[:80]!r} not found next to the .pvd")
        out.append((t, f))
    return out


def read_series(path: str | os.PathLike[str], **options: Any) -> Iterator[tuple[float, PolyMesh, dict[str, np.ndarray]]]:
    """Load the meshes of a ``.pvd`` series one by one: ``(time, mesh, point_data)``.

    ``options`` go to :func:`read_vtu` (e.g. ``check=False`` for cut meshes). The
    collection is read and checked first (:func:`read_pvd`), so a bad entry fails
    before any mesh is loaded.

    Example
    -------
    >>> import tempfile, pathlib
    >>> from unmesh.fem import hex_grid
    >>> d = pathlib.Path(tempfile.mkdtemp()); write_vtu(d / "m0.vtu", hex_grid((2, 1, 1)))
    >>> write_pvd(d / "s.pvd", ["m0.vtu"], [0.0])
    >>> [(t, m.n_elements) for t, m, _ in read_series(d / "s.pvd")]
    [(0.0, 2)]
    """
    for t, f in read_pvd(path):
        mesh, pdata = read_vtu(f, **options)
        yield t, mesh, pdata
