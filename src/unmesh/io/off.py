"""Object File Format (OFF) for triangle meshes.

Reads the headers ``OFF``, ``COFF``, ``NOFF``, ``CNOFF``, ``STOFF`` and their
combinations (``[ST][C][N]OFF``), with the counts on the header line or the next
one, ``#`` comments and blank lines anywhere. Each vertex line holds
``x y z [nx ny nz] [r g b [a]] [s t]`` as the prefixes announce (colours as floats in
[0, 1] or integers 0-255); each face line ``n i_1 ... i_n [colour]`` (polygons are
fan-triangulated, face colours ignored). ``4OFF`` / ``nOFF`` (other dimensions)
are refused.

Writing emits ``OFF`` (``NOFF`` / ``COFF`` / ``CNOFF`` / ``ST...`` when the mesh has
normals / vertex colours / uv), one vertex per line, then ``3 a b c`` faces. OFF has
no textures or attributes; they are left out with a warning.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np

from unmesh.errors import FormatError, InputError
from unmesh.io._common import colors_from_file, fail, float32_exact, format_rows
from unmesh.io._meshbuild import fan_triangulate
from unmesh.meshes import TriangleMesh

__all__ = ["encode_off", "read_off"]

_HEADER = re.compile(r"^(ST)?(C)?(N)?(4)?(n)?OFF$")
_COMMENT = re.compile(r"#[^\n\r]*")


def read_off(path: str | os.PathLike[str]) -> TriangleMesh:
    """Read an OFF file as a TriangleMesh.

    Raises
    ------
    FormatError
        Naming the file, the element (``header``, ``vertex``, ``face``) and the row.

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.off"
    >>> _ = p.write_text("OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> read_off(p).faces.tolist()
    [[0, 1, 2]]
    """
    text = Path(path).read_bytes().decode("utf-8", errors="replace")
    if "#" in text:
        text = _COMMENT.sub("", text)
    lines = [ln for ln in (x.strip() for x in text.splitlines()) if ln]
    if not lines:
        raise fail(path, "header", "empty file")
    head = lines[0].split()
    m = _HEADER.match(head[0])
    if m is None:
        raise fail(path, "header", f"expected OFF, COFF, NOFF, CNOFF or STOFF, got {head[0][:20]!r}")
    st, has_c, has_n, dim4, ndim = m.groups()
    if dim4 or ndim:
        raise fail(path, "header", f"{head[0]!r}: only 3-D OFF files are supported")
    counts = head[1:]
    body = 1
    if not counts:
        if len(lines) < 2:
            raise fail(path, "header", "file ends before the vertex and face counts")
        counts = lines[1].split()
        body = 2
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise fail(path, "header", f"expected 'NVERTICES NFACES NEDGES', got {' '.join(counts)!r}") from None
    if nv < 0 or nf < 0:
        raise fail(path, "header", f"negative counts {nv} {nf}")
    vrows = lines[body:body + nv]
    if len(vrows) < nv:
        raise fail(path, "vertex", f"file ends after {len(vrows)} of {nv} rows")
    frows = lines[body + nv:body + nv + nf]
    if len(frows) < nf:
        raise fail(path, "face", f"file ends after {len(frows)} of {nf} rows")
    extra = len(lines) - (body + nv + nf)
    if extra > 0:
        raise fail(path, "face", f"{extra} unexpected lines after the last face (wrong count in the header?)")

    vals = _vertex_table(path, vrows)
    fixed = 3 + (3 if has_n else 0) + (2 if st else 0)
    ncol = vals.shape[1] if len(vals) else fixed
    ncolor = ncol - fixed
    if len(vals) and (ncolor < 0 or (has_c and ncolor not in (3, 4)) or (not has_c and ncolor != 0)):
        raise fail(path, "vertex", f"row 0: {ncol} values do not match the header {head[0]!r}")
    pos = np.ascontiguousarray(vals[:, :3]) if len(vals) else np.empty((0, 3))
    bad = ~np.isfinite(vals).all(axis=1) if len(vals) else np.zeros(0, bool)
    if bad.any():
        raise fail(path, "vertex", f"row {int(np.flatnonzero(bad)[0])}: NaN or infinite value")
    c = 3
    normals = colors = uv = None
    if has_n:
        normals = vals[:, c:c + 3]
        c += 3
    if has_c:
        colors = colors_from_file(vals[:, c:c + 3]) if len(vals) else None
        c += ncolor
    if st:
        uv = vals[:, c:c + 2]

    offsets, idx = _face_table(path, frows)
    tri, cidx = fan_triangulate(offsets, idx, path, "face")
    bad = (tri < 0) | (tri >= nv)
    if bad.any():
        t = int(np.flatnonzero(bad.any(axis=1))[0])
        row = int(np.searchsorted(offsets, cidx[t, 0], side="right") - 1)
        raise fail(path, "face", f"row {row}: vertex index {int(tri[t][bad[t]][0])} out of range [0, {nv})")
    faces = tri.astype(np.int64).reshape(-1, 3)
    if normals is not None:
        zero = ~(np.linalg.norm(normals, axis=1) > 1e-12)
        if zero.any():
            normals = normals.copy()
            normals[zero] = TriangleMesh(pos, faces).computed_vertex_normals()[zero]
    try:
        return TriangleMesh(pos, faces, uv=uv, vertex_normals=normals, vertex_colors=colors)
    except InputError as exc:
        raise fail(path, "vertex", str(exc)) from None


def _vertex_table(path: str | os.PathLike[str], rows: list[str]) -> np.ndarray:
    if not rows:
        return np.empty((0, 3))
    try:
        arr = np.loadtxt(rows, dtype=np.float64, ndmin=2, comments=None)
        if arr.shape[0] == len(rows) and arr.shape[1] >= 3:
            return arr
    except ValueError:
        pass
    width = None
    for r, row in enumerate(rows):
        toks = row.split()
        try:
            [float(t) for t in toks]
        except ValueError:
            raise fail(path, "vertex", f"row {r}: cannot parse {row[:60]!r}") from None
        if len(toks) < 3:
            raise fail(path, "vertex", f"row {r}: expected at least 3 values, got {len(toks)}")
        if width is not None and len(toks) != width:
            raise fail(path, "vertex", f"row {r}: {len(toks)} values, the rows before have {width}")
        width = len(toks)
    raise fail(path, "vertex", "malformed vertex rows")  # pragma: no cover - loadtxt accepted nothing odd


def _face_table(path: str | os.PathLike[str], rows: list[str]) -> tuple[np.ndarray, np.ndarray]:
    if not rows:
        return np.zeros(1, np.int64), np.empty(0, np.int64)
    try:
        arr = np.loadtxt(rows, dtype=np.int64, ndmin=2, comments=None)
        if arr.shape[0] == len(rows) and arr.shape[1] >= 4 and np.all(arr[:, 0] == arr.shape[1] - 1):
            k = arr.shape[1] - 1
            return np.arange(len(rows) + 1, dtype=np.int64) * k, arr[:, 1:].reshape(-1)
    except (ValueError, OverflowError):
        pass
    counts = np.empty(len(rows), np.int64)
    out: list[int] = []
    for r, row in enumerate(rows):
        toks = row.split()
        try:
            n = int(toks[0])
            ok = 0 <= n <= len(toks) - 1
            if ok:
                ids = [int(t) for t in toks[1:n + 1]]
                if ids and max(abs(i) for i in ids) > 2**62:
                    raise fail(path, "face", f"row {r}: vertex index {max(ids, key=abs)} out of range")
                out.extend(ids)
        except FormatError:
            raise
        except ValueError:
            raise fail(path, "face", f"row {r}: cannot parse {row[:60]!r}") from None
        if not ok:
            raise fail(path, "face", f"row {r}: {n} vertices announced, {len(toks) - 1} values given")
        counts[r] = n
    offsets = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets, np.array(out, dtype=np.int64)


def encode_off(mesh: TriangleMesh, path: str | os.PathLike[str] = "mesh.off") -> str:
    """OFF text of a mesh.

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> encode_off(m).splitlines()[:2]
    ['OFF', '3 1 0']
    """
    lost = [n for n in ("texture", "normal_map") if getattr(mesh, n) is not None] + sorted(mesh.attributes)
    if lost:
        warnings.warn(f"{os.fspath(path)}: OFF cannot store {', '.join(lost)}; not written (use .ply or .obj)",
                      stacklevel=3)
    head = ("ST" if mesh.uv is not None else "") + ("C" if mesh.vertex_colors is not None else "") + \
           ("N" if mesh.vertex_normals is not None else "") + "OFF"
    cols: list = []
    for arr in (mesh.vertices, mesh.vertex_normals):
        if arr is not None:
            a = arr.astype(np.float32) if float32_exact(arr) else arr
            cols += [a[:, i] for i in range(3)]
    if mesh.vertex_colors is not None:
        rgb = np.clip(np.rint(mesh.vertex_colors * 255.0), 0, 255).astype(np.int64)
        cols += [rgb[:, i] for i in range(3)] + ["255"]
    if mesh.uv is not None:
        a = mesh.uv.astype(np.float32) if float32_exact(mesh.uv) else mesh.uv
        cols += [a[:, 0], a[:, 1]]
    out = [head, f"{len(mesh.vertices)} {len(mesh.faces)} 0"]
    out += format_rows(cols, count=len(mesh.vertices))
    out += format_rows([mesh.faces[:, 0], mesh.faces[:, 1], mesh.faces[:, 2]], prefix="3 ")
    return "\n".join(out) + "\n"
