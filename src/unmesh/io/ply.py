"""PLY files of surfel clouds, particles and triangle meshes.

Reading (:func:`read_ply_object`) decides by content: a ``face`` or ``tristrips``
element makes a :class:`~unmesh.meshes.TriangleMesh`; otherwise vertex normals
(``nx ny nz``) make a :class:`~unmesh.surfels.SurfelCloud` and their absence
:class:`~unmesh.particles.Particles`.

Surfel layout written (MeshLab / CloudCompare read it as a point cloud with
normals, per-vertex radius and colours)::

    element vertex N
    property float x / y / z          (double when float would not be exact)
    property float nx / ny / nz       (idem)
    property float radius             (idem)
    property uchar red / green / blue
    property float t1x t1y t1z t2x t2y t2z   (elliptical surfels only: tangent axes)
    property <type> <attribute> ...   (every attribute, see unmesh.io._common)

Geometry precision: each group (positions, normals, radius, axes, uv) is written as
``float`` when every value is exactly a float32 (e.g. data that came from a float
file) and as ``double`` otherwise, so that what is written reads back bit for bit.
Colours are quantised to 8 bits (``round(255 c)``); ``alpha`` is ignored on reading.

Particles: ``x y z`` [``radius``] then every attribute in insertion order.
Meshes: ``x y z`` [``nx ny nz``] [``red green blue`` uchar] [``s t``] [attributes]
and ``face`` with ``property list uchar int vertex_indices``; a texture is written as
a PNG next to the file and named in a ``comment TextureFile NAME.png`` line (the
MeshLab convention).

Reading also accepts normals ``normal_x ...``, colours ``diffuse_red ...`` (uchar,
ushort or float), uv ``s t`` / ``u v`` / ``texture_u texture_v`` /
``texture_s texture_t``, per-corner ``texcoord`` lists on faces (vertices are
split so that uv is per vertex), polygon faces (fan triangulation) and
``tristrips`` (strips separated by -1, alternating winding, degenerate triangles
dropped).
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.io._common import (
    check_finite,
    colors_from_file,
    fail,
    float32_exact,
    pack_attributes,
    read_image,
    regroup_attributes,
    to_uchar_colors,
)
from unmesh.io._meshbuild import decode_strips, fan_triangulate, split_corners
from unmesh.io._plyformat import Header, ListColumn, encode_ply, read_ply
from unmesh.meshes import TriangleMesh
from unmesh.particles import Particles
from unmesh.surfels import SurfelCloud
from unmesh.surfels.cloud import RESERVED_NAMES

__all__ = ["encode_mesh", "encode_particles", "encode_surfels", "ply_kind", "read_ply_object"]

NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))
COLOR_NAMES = (("red", "green", "blue"), ("diffuse_red", "diffuse_green", "diffuse_blue"))
AXES_NAMES = ("t1x", "t1y", "t1z", "t2x", "t2y", "t2z")
UV_NAMES = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
ALPHA_NAMES = ("alpha", "diffuse_alpha")
FACE_LISTS = ("vertex_indices", "vertex_index")
_DTYPE_COMMENT = re.compile(r"^unmesh dtype (\S+) (\S+)$")


def ply_kind(header: Header) -> str:
    """``'mesh'``, ``'surfels'`` or ``'particles'`` from the elements and vertex properties.

    Example
    -------
    >>> from unmesh.io._plyformat import parse_header
    >>> h = parse_header(b"ply\\nformat ascii 1.0\\nelement vertex 0\\nproperty float x\\nend_header\\n", "p.ply")
    >>> ply_kind(h)
    'particles'
    """
    if header.element("face") is not None or header.element("tristrips") is not None:
        return "mesh"
    vertex = header.element("vertex")
    names = {p.name for p in vertex.props} if vertex is not None else set()
    if any(set(group) <= names for group in NORMAL_NAMES):
        return "surfels"
    return "particles"


def read_ply_object(path: str | os.PathLike[str], kind: str | None = None,
                    estimate: bool = False) -> tuple[str, Any]:
    """Read a PLY file as the object its content describes.

    Parameters
    ----------
    path : path
    kind : {'mesh', 'surfels', 'particles'}, optional
        Force the interpretation of a vertex-only file (``'surfels'`` with
        ``estimate=True`` estimates missing normals).
    estimate : bool
        Estimate normals of a point-only file (``unmesh.surfels.estimate_normals``).

    Returns
    -------
    kind : str
        What the file holds (before forcing).
    obj : SurfelCloud, TriangleMesh or Particles

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "p.ply"
    >>> _ = p.write_bytes(encode_particles(Particles([[0, 0, 0]])))
    >>> read_ply_object(p)
    ('particles', Particles(1 particles, attributes=[]))
    """
    header, tables = read_ply(path)
    found = ply_kind(header)
    want = kind or found
    if want == "mesh":
        return found, _to_mesh(path, header, tables)
    if want == "surfels":
        return found, _to_surfels(path, header, tables, estimate)
    return found, _to_particles(path, header, tables)


# -- reading ----------------------------------------------------------------------------------
def _dtype_comments(header: Header) -> dict[str, str]:
    out = {}
    for c in header.comments:
        m = _DTYPE_COMMENT.match(c.strip())
        if m:
            out[m.group(1)] = m.group(2)
    return out


def _vertex_columns(path: str | os.PathLike[str], header: Header,
                    tables: dict[str, dict[str, Any]]) -> tuple[int, dict[str, np.ndarray]]:
    el = header.element("vertex")
    if el is None:
        raise fail(path, None, "no 'vertex' element")
    cols: dict[str, np.ndarray] = {}
    for p in el.props:
        if p.is_list:
            warnings.warn(f"{os.fspath(path)}: element 'vertex': list property {p.name!r} ignored", stacklevel=4)
            continue
        cols[p.name] = tables["vertex"][p.name]
    for c in ("x", "y", "z"):
        if c not in cols:
            raise fail(path, "vertex", f"no property {c!r}")
    return el.count, cols


def _take(cols: dict[str, np.ndarray], groups: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, ...], np.ndarray] | None:
    for group in groups:
        if all(g in cols for g in group):
            return group, np.stack([cols[g].astype(np.float64) for g in group], axis=1)
    return None


def _positions(path: str | os.PathLike[str], cols: dict[str, np.ndarray]) -> np.ndarray:
    pos = np.stack([cols[c].astype(np.float64) for c in ("x", "y", "z")], axis=1)
    check_finite(path, "vertex", "position", pos)
    return pos


def _attributes(path: str | os.PathLike[str], header: Header, cols: dict[str, np.ndarray],
                used: set[str], reserved: frozenset[str] = frozenset()) -> dict[str, np.ndarray]:
    rest = [(n, c) for n, c in cols.items() if n not in used]
    attrs = regroup_attributes(rest, _dtype_comments(header), path, "vertex", identifiers=bool(reserved))
    for name in [k for k in attrs if k in reserved]:
        new = name + "_"
        while new in attrs:
            new += "_"
        warnings.warn(f"{os.fspath(path)}: element 'vertex': property {name!r} renamed to attribute {new!r} "
                      "(the name is reserved)", stacklevel=4)
        attrs[new] = attrs.pop(name)
    return attrs


def _nonzero_rows(path: str | os.PathLike[str], what: str, vec: np.ndarray) -> None:
    check_finite(path, "vertex", what, vec)
    bad = ~(np.linalg.norm(vec, axis=1) > 1e-12)
    if bad.any():
        raise fail(path, "vertex", f"row {int(np.flatnonzero(bad)[0])}: {what} is a zero vector")


def _to_surfels(path: str | os.PathLike[str], header: Header, tables: dict[str, dict[str, Any]],
                estimate: bool) -> SurfelCloud:
    n, cols = _vertex_columns(path, header, tables)
    pos = _positions(path, cols)
    used = {"x", "y", "z", *ALPHA_NAMES}
    got = _take(cols, NORMAL_NAMES)
    if got is not None:
        used.update(got[0])
        normals = got[1]
        _nonzero_rows(path, "normal", normals)
    elif estimate:
        from unmesh.surfels import estimate_normals

        normals = np.asarray(estimate_normals(pos), dtype=np.float64)
    else:
        raise fail(path, "vertex", "no normals (nx ny nz) for surfels")
    axes = None
    radii = None
    if all(a in cols for a in AXES_NAMES):
        axes = np.stack([cols[a].astype(np.float64) for a in AXES_NAMES], axis=1).reshape(n, 2, 3)
        used.update(AXES_NAMES)
        check_finite(path, "vertex", "tangent axis", axes)
        used.add("radius")
    elif "radius" in cols:
        radii = cols["radius"].astype(np.float64)
        used.add("radius")
        check_finite(path, "vertex", "radius", radii)
        bad = ~(radii > 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise fail(path, "vertex", f"row {i}: radius must be positive, got {radii[i]}")
    else:
        from unmesh.surfels import estimate_radii

        radii = np.asarray(estimate_radii(pos, normals), dtype=np.float64)
    colors = None
    got = _take(cols, COLOR_NAMES)
    if got is not None:
        used.update(got[0])
        colors = colors_from_file(np.stack([cols[c] for c in got[0]], axis=1))
    attrs = _attributes(path, header, cols, used, RESERVED_NAMES)
    try:
        return SurfelCloud(pos, normals, radii=radii, axes=axes, colors=colors, attributes=attrs)
    except InputError as exc:
        raise fail(path, "vertex", str(exc)) from None


def _to_particles(path: str | os.PathLike[str], header: Header, tables: dict[str, dict[str, Any]]) -> Particles:
    _, cols = _vertex_columns(path, header, tables)
    pos = _positions(path, cols)
    used = {"x", "y", "z"}
    radii = None
    if "radius" in cols:
        radii = cols["radius"].astype(np.float64)
        used.add("radius")
        check_finite(path, "vertex", "radius", radii)
        bad = ~(radii > 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise fail(path, "vertex", f"row {i}: radius must be positive, got {radii[i]}")
    attrs = _attributes(path, header, cols, used)
    try:
        return Particles(pos, radii=radii, attributes=attrs)
    except InputError as exc:
        raise fail(path, "vertex", str(exc)) from None


def _face_list(path: str | os.PathLike[str], header: Header, tables: dict[str, dict[str, Any]],
               element: str) -> ListColumn | None:
    el = header.element(element)
    if el is None:
        return None
    for name in FACE_LISTS:
        col = tables[element].get(name)
        if isinstance(col, ListColumn):
            break
    else:
        lists = [p.name for p in el.props if p.is_list]
        if not lists:
            raise fail(path, element, "no vertex index list (property list ... vertex_indices)")
        col = tables[element][lists[0]]
    if col.values.dtype.kind == "f":
        vals = col.values
        if vals.size and not np.all(vals == np.trunc(vals)):
            raise fail(path, element, "vertex indices are not integers")
    return ListColumn(col.offsets, col.values.astype(np.int64))


def _check_range(path: str | os.PathLike[str], element: str, tri: np.ndarray, row: np.ndarray, nverts: int) -> None:
    bad = (tri < 0) | (tri >= nverts)
    if bad.any():
        t = int(np.flatnonzero(bad.any(axis=1))[0])
        value = int(tri[t][bad[t]][0])
        raise fail(path, element, f"row {int(row[t])}: vertex index {value} out of range [0, {nverts})")


def _to_mesh(path: str | os.PathLike[str], header: Header, tables: dict[str, dict[str, Any]]) -> TriangleMesh:
    n, cols = _vertex_columns(path, header, tables)
    pos = _positions(path, cols)
    used = {"x", "y", "z", *ALPHA_NAMES}
    normals = uv = colors = None
    got = _take(cols, NORMAL_NAMES)
    if got is not None:
        used.update(got[0])
        normals = got[1]
        check_finite(path, "vertex", "normal", normals)
    got = _take(cols, COLOR_NAMES)
    if got is not None:
        used.update(got[0])
        colors = colors_from_file(np.stack([cols[c] for c in got[0]], axis=1))
    got = _take(cols, UV_NAMES)
    if got is not None:
        used.update(got[0])
        uv = got[1]
        check_finite(path, "vertex", "texture coordinate", uv)
    attrs = _attributes(path, header, cols, used)

    tris = []
    corner_uv = None
    faces = _face_list(path, header, tables, "face")
    if faces is not None:
        tri, cidx = fan_triangulate(faces.offsets, faces.values, path, "face")
        row = np.searchsorted(faces.offsets, cidx[:, 0], side="right") - 1
        _check_range(path, "face", tri, row, n)
        tris.append(tri)
        tex = tables["face"].get("texcoord")
        if isinstance(tex, ListColumn) and uv is None and len(faces):
            if not np.array_equal(tex.lengths(), 2 * faces.lengths()):
                bad = int(np.flatnonzero(tex.lengths() != 2 * faces.lengths())[0])
                raise fail(path, "face", f"row {bad}: texcoord has {int(tex.lengths()[bad])} values for "
                                         f"{int(faces.lengths()[bad])} vertices")
            cuv = tex.values.astype(np.float64).reshape(-1, 2)
            check_finite(path, "face", "texcoord", cuv)
            corner_uv = cuv[cidx]
    strips = _face_list(path, header, tables, "tristrips")
    if strips is not None:
        bad = strips.values < -1
        if bad.any():
            row = int(np.searchsorted(strips.offsets, int(np.flatnonzero(bad)[0]), side="right") - 1)
            raise fail(path, "tristrips", f"row {row}: vertex index {int(strips.values[bad][0])} out of range")
        tri, row = decode_strips(strips.offsets, strips.values)
        _check_range(path, "tristrips", tri, row, n)
        tris.append(tri)
        if corner_uv is not None:
            corner_uv = np.concatenate([corner_uv, np.zeros((len(tri), 3, 2))])
    faces_arr = np.concatenate(tris).astype(np.int64) if tris else np.empty((0, 3), np.int64)
    if corner_uv is not None:
        cv, src, key = split_corners(faces_arr.reshape(-1), corner_uv.reshape(-1, 2), n)
        faces_arr = cv.reshape(-1, 3)
        pos = pos[src]
        uv = np.nan_to_num(key, nan=0.0)
        normals = None if normals is None else normals[src]
        colors = None if colors is None else colors[src]
        attrs = {k: v[src] for k, v in attrs.items()}
    if normals is not None:
        normals = _repair_normals(path, pos, faces_arr, normals)
    texture = None
    for c in header.comments:
        parts = c.split(None, 1)
        if len(parts) == 2 and parts[0] == "TextureFile":
            texture = read_image(Path(path).parent / parts[1].strip(), path, "texture")
            break
    try:
        return TriangleMesh(pos, faces_arr, uv=uv, vertex_normals=normals, vertex_colors=colors,
                            texture=texture, attributes=attrs)
    except InputError as exc:
        raise fail(path, "vertex", str(exc)) from None


def _repair_normals(path: str | os.PathLike[str], pos: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Replace zero normals (often written for unused vertices) by area-weighted ones."""
    bad = ~(np.linalg.norm(normals, axis=1) > 1e-12)
    if not bad.any():
        return normals
    warnings.warn(f"{os.fspath(path)}: element 'vertex': {int(bad.sum())} zero normals replaced by "
                  "area-weighted face normals", stacklevel=4)
    computed = TriangleMesh(pos, faces).computed_vertex_normals()
    out = normals.copy()
    out[bad] = computed[bad]
    return out


# -- writing ------------------------------------------------------------------------------------
def _float_group(*arrays: np.ndarray) -> str:
    return "f4" if float32_exact(*arrays) else "f8"


def _comment() -> str:
    from unmesh._version import __version__

    return f"written by unmesh {__version__}"


def encode_surfels(cloud: SurfelCloud, binary: bool = True, byte_order: str = "<") -> bytes:
    """PLY bytes of a surfel cloud (layout in the module docstring).

    Example
    -------
    >>> c = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5])
    >>> encode_surfels(c, binary=False).decode().splitlines()[-1]
    '0 0 0 0 0 1 0.5 204 204 204'
    """
    n = len(cloud)
    props: list[tuple[str, np.ndarray, str, None]] = []
    code = _float_group(cloud.positions)
    props += [(c, cloud.positions[:, i], code, None) for i, c in enumerate("xyz")]
    code = _float_group(cloud.normals)
    props += [(c, cloud.normals[:, i], code, None) for i, c in enumerate(("nx", "ny", "nz"))]
    radii = np.asarray(cloud.radii)
    props.append(("radius", radii, _float_group(radii), None))
    rgb = to_uchar_colors(cloud.colors)
    props += [(c, rgb[:, i], "u1", None) for i, c in enumerate(("red", "green", "blue"))]
    if cloud.axes is not None:
        ax = cloud.axes.reshape(n, 6)
        code = _float_group(ax)
        props += [(c, ax[:, i], code, None) for i, c in enumerate(AXES_NAMES)]
    extra, comments = pack_attributes(cloud.attributes, [p[0] for p in props])
    props += [(a, v, c, None) for a, v, c in extra]
    return encode_ply([("vertex", n, props)], [_comment(), *comments], binary, byte_order)


def encode_particles(particles: Particles, binary: bool = True, byte_order: str = "<") -> bytes:
    """PLY bytes of particles: ``x y z`` [``radius``] then the attributes in insertion order.

    Example
    -------
    >>> p = Particles([[0, 0, 0]], attributes={"density": [1000.0]})
    >>> encode_particles(p, binary=False).decode().splitlines()[-1]
    '0 0 0 1000.0'
    """
    n = len(particles)
    code = _float_group(particles.positions)
    props: list[tuple[str, np.ndarray, str, None]] = [(c, particles.positions[:, i], code, None)
                                                      for i, c in enumerate("xyz")]
    if particles.radii is not None:
        props.append(("radius", particles.radii, _float_group(particles.radii), None))
    if "radius" in particles.attributes:
        raise InputError("obj.attributes['radius']: name is reserved for particle radii in PLY; use Particles.radii")
    extra, comments = pack_attributes(particles.attributes, [p[0] for p in props], "obj.attributes")
    props += [(a, v, c, None) for a, v, c in extra]
    return encode_ply([("vertex", n, props)], [_comment(), *comments], binary, byte_order)


def encode_mesh(mesh: TriangleMesh, binary: bool = True, byte_order: str = "<",
                texture_file: str | None = None) -> bytes:
    """PLY bytes of a triangle mesh (``texture_file`` adds a ``TextureFile`` comment).

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> encode_mesh(m, binary=False).decode().splitlines()[-1]
    '3 0 1 2'
    """
    nv = len(mesh.vertices)
    code = _float_group(mesh.vertices)
    props: list[tuple[str, np.ndarray, str, str | None]] = [(c, mesh.vertices[:, i], code, None)
                                                            for i, c in enumerate("xyz")]
    if mesh.vertex_normals is not None:
        code = _float_group(mesh.vertex_normals)
        props += [(c, mesh.vertex_normals[:, i], code, None) for i, c in enumerate(("nx", "ny", "nz"))]
    if mesh.vertex_colors is not None:
        rgb = to_uchar_colors(mesh.vertex_colors)
        props += [(c, rgb[:, i], "u1", None) for i, c in enumerate(("red", "green", "blue"))]
    if mesh.uv is not None:
        code = _float_group(mesh.uv)
        props += [(c, mesh.uv[:, i], code, None) for i, c in enumerate("st")]
    extra, comments = pack_attributes(mesh.attributes, [p[0] for p in props], "obj.attributes")
    props += [(a, v, c, None) for a, v, c in extra]
    if nv > 2**31 - 1:
        raise InputError(f"obj: PLY int indices cannot address {nv} vertices")
    face = [("vertex_indices", mesh.faces.astype(np.int32), "i4", "u1")]
    comments = [_comment(), *comments]
    if texture_file is not None:
        comments.append(f"TextureFile {texture_file}")
    return encode_ply([("vertex", nv, props), ("face", len(mesh.faces), face)], comments, binary, byte_order)
