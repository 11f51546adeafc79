"""Reading and writing surfel clouds, particles and triangle meshes.

Formats
-------
- **PLY** (``.ply``; ASCII, binary little and big endian): surfel clouds
  (``x y z nx ny nz radius red green blue`` + elliptical axes + every attribute),
  particles (``x y z [radius]`` + attributes) and meshes (vertices with optional
  normals, colours, uv and attributes; ``face`` lists of any polygon size or
  ``tristrips``). Layout and precision rules: :mod:`unmesh.io.ply`; attribute
  convention (``name_0 ... name_{k-1}`` for (N, k) arrays): :mod:`unmesh.io._common`.
- **OBJ** (``.obj`` + ``.mtl`` + PNG textures): meshes with uv, normals, vertex
  colours, texture and normal map (:mod:`unmesh.io.obj`).
- **OFF** (``.off``; ``OFF COFF NOFF CNOFF STOFF``): meshes (:mod:`unmesh.io.off`).

Every malformed, truncated or inconsistent file raises
:class:`unmesh.errors.FormatError` whose message names the file and the element
(``bunny.ply: element 'vertex': file ends after 120 of 3000 rows``); nothing is
returned half-read. Counts and lengths read from a header are checked against the
file's length before anything is allocated; scenes check the sizes they imply
against the memory budget of :mod:`unmesh.io.budget` (environment variable
``UNMESH_MEMORY_BUDGET``, default 4 GiB). Every file is written atomically (temporary file + rename, see
:mod:`unmesh.io.atomic`): a failure leaves the previous file, or none.

Example
-------
>>> import tempfile, pathlib
>>> from unmesh.surfels import SurfelCloud
>>> path = pathlib.Path(tempfile.mkdtemp()) / "disc.ply"
>>> cloud = SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1], [0, 0, 1]], radii=[0.5, 0.5],
...                     attributes={"temperature": np.array([20.0, 25.0])})
>>> save(path, cloud)
>>> back = load(path)
>>> type(back).__name__, back.attributes["temperature"].tolist()
('SurfelCloud', [20.0, 25.0])
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import FormatError, InputError
from unmesh.io._common import as_path
from unmesh.io.atomic import atomic_path, atomic_write_bytes, atomic_write_text
from unmesh.meshes import TriangleMesh
from unmesh.particles import Particles
from unmesh.surfels import SurfelCloud

__all__ = ["MESH_EXTENSIONS", "load", "load_mesh", "load_particles", "load_surfels", "save"]

#: Extensions read as meshes (besides PLY files that have faces).
MESH_EXTENSIONS = (".obj", ".off")
_EXTENSIONS = (".ply", ".obj", ".off")


def _existing(path: Any) -> Path:
    p = as_path(path)
    if not p.is_file():
        if p.exists():
            raise InputError(f"path: {os.fspath(p)!r} is not a file")
        raise FileNotFoundError(2, f"No such file: {os.fspath(p)!r}", os.fspath(p))
    return p


def _sniff(p: Path) -> str:
    ext = p.suffix.lower()
    if ext in _EXTENSIONS:
        return ext
    with open(p, "rb") as fh:
        head = fh.read(64)
    if head.startswith(b"ply"):
        return ".ply"
    first = head.lstrip().split(None, 1)[0].decode("latin-1") if head.strip() else ""
    if first.endswith("OFF") and len(first) <= 8:
        return ".off"
    raise InputError(f"path: cannot tell the format of {os.fspath(p)!r}; expected extension .ply, .obj or .off")


def load(path: str | os.PathLike[str]) -> SurfelCloud | TriangleMesh | Particles:
    """Load a file as the object its content describes.

    - PLY with a ``face`` or ``tristrips`` element -> :class:`TriangleMesh`;
    - vertex-only PLY with normals ``nx ny nz`` -> :class:`SurfelCloud` (radii from
      ``radius``, elliptical axes from ``t1x t1y t1z t2x t2y t2z``, or estimated with
      :func:`unmesh.surfels.estimate_radii` when neither is stored);
    - vertex-only PLY without normals -> :class:`Particles` (``radius`` -> radii,
      every other property an attribute);
    - OBJ, OFF -> :class:`TriangleMesh`.

    Parameters
    ----------
    path : str or os.PathLike
        The extension chooses the format (``.ply .obj .off``); other extensions are
        recognised by content (PLY and OFF).

    Returns
    -------
    SurfelCloud, TriangleMesh or Particles

    Raises
    ------
    FormatError
        The file is malformed, truncated or inconsistent (message names file and element).
    InputError
        ``path`` is not a path or the format is unknown.
    FileNotFoundError
        The file does not exist.

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tri.off"
    >>> _ = p.write_text("OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> load(p)
    TriangleMesh(3 vertices, 1 faces)
    """
    p = _existing(path)
    ext = _sniff(p)
    if ext == ".ply":
        from unmesh.io.ply import read_ply_object

        return read_ply_object(p)[1]
    return _load_mesh_file(p, ext)


def _load_mesh_file(p: Path, ext: str) -> TriangleMesh:
    if ext == ".obj":
        from unmesh.io.obj import read_obj

        return read_obj(p)
    from unmesh.io.off import read_off

    return read_off(p)


def load_mesh(path: str | os.PathLike[str]) -> TriangleMesh:
    """Load a triangle mesh from PLY (with faces or triangle strips), OBJ or OFF.

    Raises
    ------
    InputError
        The file is a PLY point set without faces.
    FormatError
        The file is malformed.

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tri.off"
    >>> _ = p.write_text("OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> load_mesh(p).faces.shape
    (1, 3)
    """
    p = _existing(path)
    ext = _sniff(p)
    if ext != ".ply":
        return _load_mesh_file(p, ext)
    kind, obj = _read_ply(p, None)
    if kind != "mesh":
        raise InputError(f"path: {os.fspath(p)!r} holds a point set ({kind}) without faces, not a mesh")
    return obj


def _read_ply(p: Path, kind: str | None, estimate: bool = False) -> tuple[str, Any]:
    from unmesh.io._plyformat import read_ply
    from unmesh.io.ply import ply_kind, read_ply_object

    if kind is None:
        return read_ply_object(p)
    # peek at the header only to refuse meshes before decoding their faces
    with open(p, "rb") as fh:
        head = fh.read(1 << 16)
    try:
        from unmesh.io._plyformat import parse_header

        found = ply_kind(parse_header(head, p))
    except FormatError:
        read_ply(p)  # re-raise the real problem (e.g. a header longer than 64 KiB is fine)
        found = None
    if found == "mesh":
        return "mesh", None
    return read_ply_object(p, kind=kind, estimate=estimate)


def load_surfels(path: str | os.PathLike[str]) -> SurfelCloud:
    """Load a surfel cloud from a PLY point file.

    A file without normals becomes surfels with normals from
    :func:`unmesh.surfels.estimate_normals` and radii from
    :func:`unmesh.surfels.estimate_radii`; a file with normals but no radius gets
    estimated radii.

    Raises
    ------
    InputError
        The file is a mesh (OBJ, OFF, or PLY with faces): sample it first with
        ``unmesh sample`` (or :func:`unmesh.surfels.sample_mesh`).
    FormatError
        The file is malformed.

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.ply"
    >>> save(p, SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.1]))
    >>> load_surfels(p).radii
    array([0.1])
    """
    p = _existing(path)
    ext = _sniff(p)
    hint = (f"path: {os.fspath(p)!r} is a triangle mesh, not a surfel cloud; convert it with "
            f"'unmesh sample {p.name}' (or unmesh.surfels.sample_mesh)")
    if ext != ".ply":
        raise InputError(hint)
    kind, obj = _read_ply(p, "surfels", estimate=True)
    if kind == "mesh":
        raise InputError(hint)
    return obj


def load_particles(path: str | os.PathLike[str]) -> Particles:
    """Load particles from a PLY point file (``radius`` -> radii, other properties -> attributes).

    A surfel file is accepted too: its normals and colours become attributes.

    Raises
    ------
    InputError
        The file is a mesh.
    FormatError
        The file is malformed.

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "p.ply"
    >>> save(p, Particles([[0, 0, 0]], attributes={"density": [1000.0]}))
    >>> load_particles(p).attributes["density"]
    array([1000.])
    """
    p = _existing(path)
    ext = _sniff(p)
    if ext != ".ply":
        raise InputError(f"path: {os.fspath(p)!r} is a triangle mesh, not a particle file (.ply points)")
    kind, obj = _read_ply(p, "particles")
    if kind == "mesh":
        raise InputError(f"path: {os.fspath(p)!r} is a triangle mesh, not a particle file (.ply points)")
    return obj


def save(path: str | os.PathLike[str], obj: SurfelCloud | TriangleMesh | Particles, *, binary: bool = True) -> None:
    """Save a surfel cloud, mesh or particles; the extension chooses the format.

    ``.ply`` takes all three (``binary=False`` writes ASCII); ``.obj`` and ``.off``
    take a :class:`TriangleMesh` (text formats; ``binary`` is ignored). An OBJ of a
    textured mesh also writes ``NAME.mtl`` and ``NAME.png`` (``NAME_normal.png`` for a
    normal map); a PLY of a textured mesh writes ``NAME.png`` and names it in a
    ``TextureFile`` comment. All files are written atomically.

    Parameters
    ----------
    path : str or os.PathLike
    obj : SurfelCloud, TriangleMesh or Particles
    binary : bool, keyword-only
        Binary little-endian PLY (default) or ASCII PLY.

    Raises
    ------
    InputError
        Unknown extension, unsupported object for the format, or attributes PLY
        cannot hold (names, shapes or dtypes; the message names the attribute).

    Example
    -------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tri.obj"
    >>> save(p, TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]))
    >>> load(p).faces.tolist()
    [[0, 1, 2]]
    """
    p = as_path(path)
    ext = p.suffix.lower()
    if ext not in _EXTENSIONS:
        raise InputError(f"path: expected extension .ply, .obj or .off, got {ext or 'none'!r} ({os.fspath(p)!r})")
    if not isinstance(obj, SurfelCloud | TriangleMesh | Particles):
        raise InputError(f"obj: expected a SurfelCloud, TriangleMesh or Particles, got {type(obj).__name__}")
    if ext in MESH_EXTENSIONS and not isinstance(obj, TriangleMesh):
        raise InputError(f"obj: {ext} files hold triangle meshes, got {type(obj).__name__}; use .ply")
    if not isinstance(binary, bool | np.bool_):
        raise InputError(f"binary: expected True or False, got {binary!r}")
    if ext == ".ply":
        from unmesh.io import ply

        if isinstance(obj, SurfelCloud):
            atomic_write_bytes(p, ply.encode_surfels(obj, binary=bool(binary)))
        elif isinstance(obj, Particles):
            atomic_write_bytes(p, ply.encode_particles(obj, binary=bool(binary)))
        else:
            _save_mesh_ply(p, obj, bool(binary))
    elif ext == ".obj":
        from unmesh.io.obj import write_obj

        write_obj(p, obj)  # type: ignore[arg-type]
    else:
        from unmesh.io.off import encode_off

        atomic_write_text(p, encode_off(obj, p))  # type: ignore[arg-type]


def _save_mesh_ply(p: Path, mesh: TriangleMesh, binary: bool) -> None:
    import contextlib

    from unmesh.io import ply
    from unmesh.io._common import write_png

    if mesh.normal_map is not None:
        warnings.warn(f"{os.fspath(p)}: PLY has no normal-map slot; the normal map is not written (use .obj)",
                      stacklevel=3)
    if mesh.texture is None:
        atomic_write_bytes(p, ply.encode_mesh(mesh, binary=binary))
        return
    png = p.with_name(f"{p.stem}.png")
    data = ply.encode_mesh(mesh, binary=binary, texture_file=png.name)
    with contextlib.ExitStack() as stack:
        tmp_ply = stack.enter_context(atomic_path(p))
        tmp_png = stack.enter_context(atomic_path(png))
        write_png(tmp_png, mesh.texture)
        tmp_ply.write_bytes(data)
