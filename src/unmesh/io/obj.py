"""Wavefront OBJ (+ MTL + PNG textures) for triangle meshes.

Reading understands ``v x y z [w]`` and ``v x y z r g b`` (vertex colours, floats in
[0, 1]; values above 1 are taken as 0-255), ``vt u v [w]``, ``vn``, faces
``f v``, ``v/vt``, ``v//vn``, ``v/vt/vn`` with positive or negative (relative)
indices, polygons (fan triangulation), ``mtllib`` + ``usemtl``, ``#`` comments and
``\\`` line continuations; other statements (``o g s l p`` ...) are ignored.

Vertices referenced with several uv / normal combinations are split so that uv and
normals are per vertex (a vertex keeps its index for its first combination in
sorted order, extra copies are appended); vertices no face uses are kept. Corners
without ``vt`` get uv (0, 0); corners without ``vn`` (when others have one) get the
area-weighted normal of the mesh.

Materials: the texture is the ``map_Kd`` of the first material (in order of
``usemtl``, then of the MTL file) that has one, and the normal map the ``norm`` /
``map_Bump`` / ``bump`` of that material (or of the first material with one). When
no material has a texture and the file has no vertex colours, the ``Kd`` colours of
the materials become vertex colours (vertices shared by faces of different
materials are split). A missing ``.mtl`` or image gives a warning and no texture.

Writing (:func:`write_obj`) emits ``v`` (with ``r g b`` when the mesh has vertex
colours), ``vt``, ``vn`` and ``f a/a/a`` lines; with a texture or normal map it also
writes ``NAME.mtl`` (``map_Kd NAME.png``, ``norm`` and ``map_Bump NAME_normal.png``)
and the PNGs, all atomically (nothing is replaced unless every file was written).
Coordinates print with 9 significant digits when they are exactly float32 and as the
shortest exact decimal otherwise, so they read back bit for bit.

Parsing is vectorised (statements are grouped by keyword and parsed with numpy);
the 4 MB armadillo loads in well under a second.
"""

from __future__ import annotations

import contextlib
import os
import re
import warnings
from pathlib import Path

import numpy as np

from unmesh.errors import FormatError, InputError
from unmesh.io._common import colors_from_file, fail, float32_exact, format_rows, is_file, read_image, write_png
from unmesh.io._meshbuild import fan_triangulate, split_corners
from unmesh.io.atomic import atomic_path
from unmesh.meshes import TriangleMesh

__all__ = ["read_obj", "write_obj"]

_COMMENT = re.compile(r"#[^\n\r]*")
_CONTINUATION = re.compile(r"\\[ \t]*(\r\n|\n|\r)")
#: map_* options with a fixed number of arguments (-o, -s, -t take 1 to 3 numbers).
_MAP_FIXED = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1, "-imfchan": 1,
              "-mm": 2, "-texres": 1, "-type": 1}
DEFAULT_KD = (0.8, 0.8, 0.8)
#: Statement keywords of the OBJ specification (a file with none of them is not an OBJ file).
_STATEMENTS = frozenset("v vt vn vp f l p o g s mg mtllib usemtl cstype deg bmat step curv curv2 surf parm "
                        "trim hole scrv sp end con bevel c_interp d_interp lod maptype usemap shadow_obj "
                        "trace_obj ctech stech call csh".split())
#: Largest index magnitude accepted (larger ones cannot address any file's rows).
_MAX_INDEX = 2**62


def _parse_floats(rows: list[str], lines: list[int], path: str | os.PathLike[str], element: str,
                  minimum: int) -> list[np.ndarray] | np.ndarray:
    """Rows of numbers -> (R, k) array when every row has k values, else a list of 1-D arrays."""
    if not rows:
        return np.empty((0, minimum))
    try:
        arr = np.loadtxt(rows, dtype=np.float64, ndmin=2, comments=None)
        if arr.shape[0] == len(rows) and arr.shape[1] >= minimum:
            return arr
    except ValueError:
        pass
    out = []
    for r, row in enumerate(rows):
        try:
            vals = np.array([float(t) for t in row.split()])
        except ValueError:
            raise fail(path, element, f"line {lines[r] + 1}: cannot parse {row.strip()[:60]!r}") from None
        if len(vals) < minimum:
            raise fail(path, element, f"line {lines[r] + 1}: expected at least {minimum} numbers, got {len(vals)}")
        out.append(vals)
    return out


def _parse_faces(rows: list[str], lines: list[int], path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Face rows -> (offsets (F+1,), corners (C, 3) int64 with columns v, vt, vn; 0 = absent)."""
    if not rows:
        return np.zeros(1, np.int64), np.zeros((0, 3), np.int64)
    first = rows[0].split(None, 1)[0] if rows[0].split() else ""
    nslash = first.count("/")
    double = "//" in first
    m = 1 + nslash - (1 if double else 0)
    text = "\n".join(rows)
    try:
        arr = np.loadtxt(text.replace("//", " ").replace("/", " ").split("\n"), dtype=np.int64, ndmin=2,
                         comments=None)
        ok = arr.shape[0] == len(rows) and arr.shape[1] % m == 0 and arr.shape[1] // m >= 3
        if ok:
            k = arr.shape[1] // m
            total = len(rows) * k
            ok = text.count("//") == (total if double else 0) and text.count("/") == total * nslash
    except (ValueError, OverflowError):
        ok = False
    if ok:
        corners = np.zeros((total, 3), np.int64)
        flat = arr.reshape(total, m)
        corners[:, 0] = flat[:, 0]
        if nslash == 1:
            corners[:, 1] = flat[:, 1]
        elif double:
            corners[:, 2] = flat[:, 1]
        elif nslash == 2:
            corners[:, 1:] = flat[:, 1:]
        return np.arange(len(rows) + 1, dtype=np.int64) * k, corners
    counts = np.empty(len(rows), np.int64)
    out: list[tuple[int, int, int]] = []
    for r, row in enumerate(rows):
        toks = row.split()
        if len(toks) < 3:
            raise fail(path, "f", f"line {lines[r] + 1}: a face needs at least 3 vertices, got {len(toks)}")
        counts[r] = len(toks)
        try:
            for t in toks:
                p = t.split("/")
                if len(p) > 3:
                    raise ValueError
                ref = (int(p[0]), int(p[1]) if len(p) > 1 and p[1] else 0,
                       int(p[2]) if len(p) > 2 and p[2] else 0)
                if max(abs(x) for x in ref) > _MAX_INDEX:
                    raise fail(path, "f", f"line {lines[r] + 1}: vertex reference {t[:40]!r} out of range")
                out.append(ref)
        except FormatError:
            raise
        except ValueError:
            raise fail(path, "f", f"line {lines[r] + 1}: cannot parse vertex reference {t[:40]!r}") from None
    offsets = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets, np.array(out, dtype=np.int64).reshape(-1, 3)


def _resolve(idx: np.ndarray, offsets: np.ndarray, f_lines: np.ndarray, def_lines: list[int], total: int,
             path: str | os.PathLike[str], what: str, required: bool) -> np.ndarray:
    """OBJ 1-based / negative indices -> 0-based, -1 where absent; range-checked."""
    out = idx - 1
    neg = idx < 0
    face_of = None
    if neg.any():
        face_of = np.searchsorted(offsets, np.arange(len(idx)), side="right") - 1
        before = np.searchsorted(np.asarray(def_lines, dtype=np.int64), f_lines[face_of])
        out = np.where(neg, before + idx, out)
    bad = (idx != 0) & ((out < 0) | (out >= total))
    if required:
        bad |= idx == 0
    if bad.any():
        c = int(np.flatnonzero(bad)[0])
        face = int(np.searchsorted(offsets, c, side="right") - 1)
        line = int(f_lines[face]) + 1
        if idx[c] == 0:
            msg = f"line {line}: {what} index 0 (OBJ indices start at 1)"
        elif idx[c] < 0:
            msg = f"line {line}: {what} index {int(idx[c])} reaches before the first {what} entry"
        else:
            msg = f"line {line}: {what} index {int(idx[c])} out of range [1, {total}]"
        raise fail(path, "f", msg)
    out[idx == 0] = -1
    return out


def _map_file(args: str) -> str:
    """The file name of a ``map_Kd [options] file`` statement (options skipped)."""
    toks = args.split()
    i = 0
    while i < len(toks) - 1 and (toks[i] in _MAP_FIXED or toks[i] in ("-o", "-s", "-t")):
        opt = toks[i]
        i += 1
        if opt in _MAP_FIXED:
            i += _MAP_FIXED[opt]
            continue
        for _ in range(3):
            if i >= len(toks) - 1:
                break
            try:
                float(toks[i])
            except ValueError:
                break
            i += 1
    return " ".join(toks[i:]).replace("\\", "/")


def _read_mtl(path: Path, obj_path: str | os.PathLike[str]) -> dict[str, dict[str, object]]:
    """Materials of one MTL file: name -> {'Kd': (3,), 'map_Kd': Path, 'normal': Path}."""
    mats: dict[str, dict[str, object]] = {}
    cur: dict[str, object] | None = None
    text = _COMMENT.sub("", path.read_text(encoding="utf-8", errors="replace"))
    text = _CONTINUATION.sub(" ", text)
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.strip().split(None, 1)
        if not parts:
            continue
        key = parts[0].lower()
        rest = parts[1].strip() if len(parts) > 1 else ""
        if key == "newmtl":
            cur = mats.setdefault(rest, {})
            continue
        if cur is None:
            continue
        if key == "kd":
            try:
                vals = [float(t) for t in rest.split()[:3]]
            except ValueError:
                raise fail(path, "Kd", f"line {lineno}: cannot parse {rest!r} (material file of {os.fspath(obj_path)})") from None
            if len(vals) == 1:
                vals = vals * 3
            if len(vals) != 3:
                raise fail(path, "Kd", f"line {lineno}: expected 3 numbers, got {rest!r}")
            cur["Kd"] = np.clip(np.array(vals), 0.0, 1.0)
        elif key == "map_kd":
            cur["map_Kd"] = path.parent / _map_file(rest)
        elif key in ("norm", "map_bump", "bump") and "normal" not in cur:
            cur["normal"] = path.parent / _map_file(rest)
    return mats


def read_obj(path: str | os.PathLike[str]) -> TriangleMesh:
    """Read an OBJ file (and its MTL and textures) as a TriangleMesh.

    Parameters
    ----------
    path : str or PathLike

    Returns
    -------
    TriangleMesh
        vertices (V,3), faces (F,3) int64, and uv (V,2), vertex_normals (V,3),
        vertex_colors (V,3), texture / normal_map (H,W,3) when present.

    Raises
    ------
    FormatError
        Naming the file, the statement (``v``, ``f``, ...) and the line.

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "q.obj"
    >>> _ = p.write_text("v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nf 1 2 3 4\\n")
    >>> read_obj(p).faces.tolist()
    [[0, 1, 2], [0, 2, 3]]
    """
    raw = Path(path).read_bytes()
    if b"\0" in raw:
        raise fail(path, None, "binary data (NUL bytes): not an OBJ text file")
    text = raw.decode("utf-8", errors="replace")
    if "\\" in text:
        text = _CONTINUATION.sub(" ", text)
    if "#" in text:
        text = _COMMENT.sub("", text)
    v: list[str] = []
    vt: list[str] = []
    vn: list[str] = []
    f: list[str] = []
    v_line: list[int] = []
    vt_line: list[int] = []
    vn_line: list[int] = []
    f_line: list[int] = []
    f_mat: list[int] = []
    mtllibs: list[str] = []
    used: dict[str, int] = {}
    cur = -1
    unknown = known = 0
    for i, line in enumerate(text.splitlines()):
        parts = line.split(None, 1)
        if not parts:
            continue
        key = parts[0]
        if key in _STATEMENTS:
            known += 1
        else:
            unknown += 1
        if key == "v":
            v.append(parts[1] if len(parts) > 1 else "")
            v_line.append(i)
        elif key == "f":
            f.append(parts[1] if len(parts) > 1 else "")
            f_line.append(i)
            f_mat.append(cur)
        elif key == "vt":
            vt.append(parts[1] if len(parts) > 1 else "")
            vt_line.append(i)
        elif key == "vn":
            vn.append(parts[1] if len(parts) > 1 else "")
            vn_line.append(i)
        elif key == "usemtl":
            cur = used.setdefault(parts[1].strip() if len(parts) > 1 else "", len(used))
        elif key == "mtllib" and len(parts) > 1:
            mtllibs.append(parts[1].strip())

    if unknown and not known:
        raise fail(path, None, f"no OBJ statement (v, vt, vn, f, ...) in {unknown} non-empty lines: "
                               "not an OBJ file")
    vals = _parse_floats(v, v_line, path, "v", 3)
    colors = None
    if isinstance(vals, np.ndarray):
        pos = np.ascontiguousarray(vals[:, :3])
        if vals.shape[1] in (6, 7):
            colors = colors_from_file(vals[:, -3:])
    else:
        pos = np.array([a[:3] for a in vals]).reshape(-1, 3)
        if all(len(a) in (6, 7) for a in vals):
            colors = colors_from_file(np.array([a[-3:] for a in vals]))
        elif any(len(a) in (6, 7) for a in vals):
            warnings.warn(f"{os.fspath(path)}: element 'v': only some vertices have colours; colours ignored",
                          stacklevel=3)
    _finite(path, "v", pos, v_line)
    nv = len(pos)
    tvals = _parse_floats(vt, vt_line, path, "vt", 1)
    if isinstance(tvals, np.ndarray):
        tex = np.zeros((len(tvals), 2))
        tex[:, :min(2, tvals.shape[1])] = tvals[:, :2]
    else:
        tex = np.array([np.pad(a[:2], (0, 2 - len(a[:2]))) for a in tvals]).reshape(-1, 2)
    _finite(path, "vt", tex, vt_line)
    nvals = _parse_floats(vn, vn_line, path, "vn", 3)
    nrm = nvals[:, :3] if isinstance(nvals, np.ndarray) else np.array([a[:3] for a in nvals]).reshape(-1, 3)
    _finite(path, "vn", nrm, vn_line)

    offsets, corners = _parse_faces(f, f_line, path)
    fl = np.asarray(f_line, dtype=np.int64)
    cv = _resolve(corners[:, 0], offsets, fl, v_line, nv, path, "vertex", True)
    cvt = _resolve(corners[:, 1], offsets, fl, vt_line, len(tex), path, "texture", False)
    cvn = _resolve(corners[:, 2], offsets, fl, vn_line, len(nrm), path, "normal", False)

    materials = _load_materials(path, mtllibs)
    order = [m for m in used if m in materials] + [m for m in materials if m not in used]
    texture = normal_map = None
    tex_mat = next((m for m in order if "map_Kd" in materials[m]), None)
    if tex_mat is not None:
        texture = read_image(materials[tex_mat]["map_Kd"], path, "texture")  # type: ignore[arg-type]
    nmat = tex_mat if tex_mat is not None and "normal" in materials[tex_mat] else \
        next((m for m in order if "normal" in materials[m]), None)
    if nmat is not None:
        normal_map = read_image(materials[nmat]["normal"], path, "normal map")  # type: ignore[arg-type]
    kd_colors = None
    if tex_mat is None and colors is None and any("Kd" in materials.get(m, {}) for m in used):
        names = list(used)
        kd_colors = np.array([materials.get(m, {}).get("Kd", DEFAULT_KD) for m in names] + [DEFAULT_KD], dtype=np.float64)

    has_vt = bool((cvt >= 0).any())
    has_vn = bool((cvn >= 0).any())
    keys = []
    if has_vt:
        keys.append(cvt)
    if has_vn:
        keys.append(cvn)
    if kd_colors is not None:
        face_mat = np.asarray(f_mat, dtype=np.int64)
        face_mat[face_mat < 0] = len(kd_colors) - 1
        keys.append(np.repeat(face_mat, np.diff(offsets)))
    uv = vnormals = None
    if keys:
        cnew, src, key = split_corners(cv, np.stack(keys, axis=1), nv)
        verts = pos[src]
        colors = None if colors is None else colors[src]
        j = 0
        if has_vt:
            uv = np.where((key[:, j] >= 0)[:, None], tex[np.maximum(key[:, j], 0)], 0.0)
            j += 1
        if has_vn:
            vnormals = np.where((key[:, j] >= 0)[:, None], nrm[np.maximum(key[:, j], 0)], 0.0) if len(nrm) else None
            j += 1
        if kd_colors is not None:
            colors = np.where((key[:, j] >= 0)[:, None], kd_colors[np.maximum(key[:, j], 0)], kd_colors[-1])
    else:
        cnew, verts = cv, pos
    tri, _ = fan_triangulate(offsets, cnew, path, "f")
    faces = tri.astype(np.int64).reshape(-1, 3)
    if vnormals is not None:
        bad = ~(np.linalg.norm(vnormals, axis=1) > 1e-12)
        if bad.any():
            computed = TriangleMesh(verts, faces).computed_vertex_normals()
            vnormals[bad] = computed[bad]
    try:
        return TriangleMesh(verts, faces, uv=uv, vertex_normals=vnormals, vertex_colors=colors,
                            texture=texture, normal_map=normal_map)
    except InputError as exc:
        raise fail(path, "v", str(exc)) from None


def _finite(path: str | os.PathLike[str], element: str, arr: np.ndarray, lines: list[int]) -> None:
    if arr.size:
        bad = ~np.isfinite(arr).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise fail(path, element, f"line {lines[i] + 1}: NaN or infinite value")


def _load_materials(path: str | os.PathLike[str], mtllibs: list[str]) -> dict[str, dict[str, object]]:
    mats: dict[str, dict[str, object]] = {}
    base = Path(path).parent
    for spec in mtllibs:
        spec = spec.replace("\\", "/")
        files = [spec] if is_file(base / spec) else spec.split()
        for name in files:
            p = base / name
            if not is_file(p):
                warnings.warn(f"{os.fspath(path)}: material file {name[:200]!r} not found; loading without materials",
                              stacklevel=3)
                continue
            for k, m in _read_mtl(p, path).items():
                mats.setdefault(k, m)
    return mats


def _coord_columns(arr: np.ndarray) -> list[np.ndarray]:
    a = arr.astype(np.float32) if float32_exact(arr) else arr
    return [a[:, i] for i in range(a.shape[1])]


def encode_obj(mesh: TriangleMesh, mtl_name: str | None = None) -> str:
    """OBJ text of a mesh (``mtl_name`` adds ``mtllib`` / ``usemtl`` lines).

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> encode_obj(m).splitlines()[-1]
    'f 1 2 3'
    """
    from unmesh._version import __version__

    out = [f"# written by unmesh {__version__}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces"]
    if mtl_name is not None:
        out.append(f"mtllib {mtl_name}")
    cols = _coord_columns(mesh.vertices)
    if mesh.vertex_colors is not None:
        cols += [mesh.vertex_colors[:, i] for i in range(3)]
    out += format_rows(cols, prefix="v ")
    if mesh.uv is not None:
        out += format_rows(_coord_columns(mesh.uv), prefix="vt ")
    if mesh.vertex_normals is not None:
        out += format_rows(_coord_columns(mesh.vertex_normals), prefix="vn ")
    if mtl_name is not None:
        out.append("usemtl material0")
    ref = "%d"
    reps = 1
    if mesh.uv is not None and mesh.vertex_normals is not None:
        ref, reps = "%d/%d/%d", 3
    elif mesh.uv is not None:
        ref, reps = "%d/%d", 2
    elif mesh.vertex_normals is not None:
        ref, reps = "%d//%d", 2
    fmt = "f " + " ".join([ref] * 3)
    idx = np.repeat(mesh.faces + 1, reps, axis=1)
    out += [fmt % tuple(r) for r in idx.tolist()]
    return "\n".join(out) + "\n"


def write_obj(path: str | os.PathLike[str], mesh: TriangleMesh) -> list[Path]:
    """Write a mesh as OBJ, plus ``NAME.mtl`` and PNGs when it has a texture or normal map.

    All files are written to temporary names first and renamed only when every one
    of them was written, so a failure leaves the previous files (or none).

    Returns
    -------
    list of Path
        The files written (OBJ first).

    Example
    -------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=[[0, 0], [1, 0], [0, 1]],
    ...                  texture=np.ones((2, 2, 3)))
    >>> [p.name for p in write_obj(d / "tri.obj", m)]
    ['tri.obj', 'tri.mtl', 'tri.png']
    """
    target = Path(path)
    if mesh.attributes:
        warnings.warn(f"{os.fspath(path)}: OBJ cannot store vertex attributes {sorted(mesh.attributes)}; "
                      "they are not written (use .ply)", stacklevel=3)
    stem = target.stem
    files: list[tuple[Path, object]] = []
    mtl_name = None
    if mesh.texture is not None or mesh.normal_map is not None:
        mtl_name = f"{stem}.mtl"
        mtl = ["# written by unmesh", "newmtl material0", "Ka 0 0 0", "Kd 1 1 1", "Ks 0 0 0", "illum 1"]
        if mesh.texture is not None:
            mtl.append(f"map_Kd {stem}.png")
            files.append((target.with_name(f"{stem}.png"), mesh.texture))
        if mesh.normal_map is not None:
            mtl += [f"norm {stem}_normal.png", f"map_Bump {stem}_normal.png"]
            files.append((target.with_name(f"{stem}_normal.png"), mesh.normal_map))
        files.insert(0, (target.with_name(mtl_name), "\n".join(mtl) + "\n"))
    files.insert(0, (target, encode_obj(mesh, mtl_name)))
    with contextlib.ExitStack() as stack:
        for dest, content in files:
            tmp = stack.enter_context(atomic_path(dest))
            if isinstance(content, str):
                tmp.write_text(content, encoding="utf-8")
            else:
                write_png(tmp, content)  # type: ignore[arg-type]
    return [d for d, _ in files]
