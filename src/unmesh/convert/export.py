"""Writing a :class:`TexturedMesh`: OBJ + MTL + PNG pages, or binary glTF (.glb).

OBJ (:func:`write_textured_obj`): one OBJ with a ``usemtl pageK`` group per atlas page, the
MTL with one material per page (``map_Kd`` colour page; the tangent-space normal page as both
``norm`` and ``map_Bump``, the two spellings tools read), and the PNGs. One page: ``NAME.png``
and ``NAME_normal.png`` (as :func:`unmesh.io.obj.write_obj`); several: ``NAME_pK.png`` and
``NAME_pK_normal.png``; with mip levels (6.5) also ``NAME[_pK]_mip1.png`` and ``_mip2.png``
(half and quarter resolution, same layout; MTL has no statement for them); with depth maps
``NAME[_pK]_depth.png`` (16-bit grey) and ``disp -mm base gain`` in the MTL (height above the
triangle's plane = base + gain * grey, world units). The text comes from
:func:`unmesh.io.obj.encode_obj`. glTF has no displacement texture: .glb files carry none.

glTF (:func:`write_glb`, needs the ``convert`` extra: trimesh): one primitive per page with a
PBR material, ``baseColorTexture`` and ``normalTexture`` (tangent-space, OpenGL convention as
glTF specifies), per-vertex normals and texture coordinates.

Every file of a result is first written to a temporary name next to its target; only when all
of them were written are they renamed (:func:`unmesh.io.atomic.atomic_path`), so a failure
leaves no half-written set.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.convert.textured import TexturedMesh
from unmesh.errors import InputError, MissingDependencyError
from unmesh.io.atomic import atomic_path
from unmesh.io.obj import encode_obj
from unmesh.meshes import TriangleMesh

__all__ = ["write_glb", "write_textured", "write_textured_obj"]


def _png(path: Path, image: np.ndarray) -> None:
    from PIL import Image

    data = np.clip(np.rint(np.asarray(image) * 255.0), 0, 255).astype(np.uint8)
    Image.fromarray(data, mode="RGB").save(path, format="PNG")


def _png16(path: Path, image: np.ndarray) -> None:
    """A (H, W) array of values in [0, 1] as a 16-bit greyscale PNG."""
    from PIL import Image

    data = np.clip(np.rint(np.asarray(image) * 65535.0), 0, 65535).astype(np.uint16)
    Image.fromarray(data).save(path, format="PNG")  # uint16 -> mode "I;16"


def _merged(tm: TexturedMesh) -> tuple[TriangleMesh, list[int]]:
    """All parts as one mesh (vertices and faces concatenated) and the face count per part."""
    verts, faces, uv, vn = [], [], [], []
    off = 0
    counts = []
    for p in tm.parts:
        verts.append(p.vertices)
        faces.append(p.faces + off)
        uv.append(p.uv)
        vn.append(p.computed_vertex_normals())
        off += len(p.vertices)
        counts.append(len(p.faces))
    return TriangleMesh(np.concatenate(verts), np.concatenate(faces), uv=np.concatenate(uv),
                        vertex_normals=np.concatenate(vn)), counts


def write_textured_obj(path: str | os.PathLike[str], tm: TexturedMesh) -> list[Path]:
    """Write OBJ + MTL + PNG pages (atomically as a set); returns the files, OBJ first.

    Example
    -------
    >>> import tempfile, pathlib
    >>> part = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=[[0, 0], [1, 0], [0, 1]],
    ...                     texture=np.ones((4, 4, 3)), normal_map=np.full((4, 4, 3), 0.5))
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> [p.name for p in write_textured_obj(d / "m.obj", TexturedMesh((part,)))]
    ['m.obj', 'm.mtl', 'm.png', 'm_normal.png']
    """
    target = Path(path)
    stem = target.stem
    merged, counts = _merged(tm)
    text = encode_obj(merged, f"{stem}.mtl")
    head, _, faces = text.partition("usemtl material0\n")
    lines = faces.splitlines()
    out = [head.rstrip("\n")]
    start = 0
    for k, n in enumerate(counts):
        out.append(f"usemtl page{k}")
        out += lines[start:start + n]
        start += n
    files: list[tuple[Path, Any]] = [(target, "\n".join(out) + "\n")]
    mtl = ["# written by unmesh: one material per atlas page (map_Kd colour, norm/map_Bump tangent-space normals)"]
    single = len(tm.parts) == 1
    for k, p in enumerate(tm.parts):
        name = stem if single else f"{stem}_p{k}"
        mtl += [f"newmtl page{k}", "Ka 0 0 0", "Kd 1 1 1", "Ks 0 0 0", "illum 1", f"map_Kd {name}.png"]
        files.append((target.with_name(f"{name}.png"), p.texture))
        if p.normal_map is not None:
            mtl += [f"norm {name}_normal.png", f"map_Bump {name}_normal.png"]
            files.append((target.with_name(f"{name}_normal.png"), p.normal_map))
        if k < len(tm.depth_pages):
            # MTL ``disp -mm base gain``: height = base + gain * grey (grey in [0, 1])
            d = tm.depth_pages[k]
            base, gain = float(d.min()), float(np.ptp(d)) or 1.0
            mtl.append(f"disp -mm {base:.9g} {gain:.9g} {name}_depth.png")
            files.append((target.with_name(f"{name}_depth.png"), (d - base) / gain))
        if k < len(tm.mip_levels):
            for j, mip in enumerate(tm.mip_levels[k], start=1):
                files.append((target.with_name(f"{name}_mip{j}.png"), mip))
    files.insert(1, (target.with_name(f"{stem}.mtl"), "\n".join(mtl) + "\n"))
    _write_all(files)
    return [f for f, _ in files]


def _write_all(files: list[tuple[Path, Any]]) -> None:
    with contextlib.ExitStack() as stack:
        for dest, content in files:
            tmp = stack.enter_context(atomic_path(dest))
            if isinstance(content, str):
                tmp.write_text(content, encoding="utf-8")
            elif isinstance(content, bytes):
                tmp.write_bytes(content)
            elif np.asarray(content).ndim == 2:
                _png16(tmp, content)
            else:
                _png(tmp, content)


def glb_bytes(tm: TexturedMesh) -> bytes:
    """The binary glTF of a textured mesh (needs trimesh, the ``convert`` extra)."""
    try:
        import trimesh
        from PIL import Image
        from trimesh.visual.material import PBRMaterial
        from trimesh.visual.texture import TextureVisuals
    except ImportError:
        raise MissingDependencyError("glb output: needs trimesh (pip install 'unmesh[convert]')") from None

    def img(a: np.ndarray) -> Any:
        return Image.fromarray(np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8), mode="RGB")

    scene = trimesh.Scene()
    for k, p in enumerate(tm.parts):
        mat = PBRMaterial(name=f"page{k}", baseColorTexture=img(p.texture), metallicFactor=0.0, roughnessFactor=1.0,
                          normalTexture=None if p.normal_map is None else img(p.normal_map))
        mesh = trimesh.Trimesh(vertices=p.vertices, faces=p.faces, vertex_normals=p.computed_vertex_normals(),
                               visual=TextureVisuals(uv=p.uv, material=mat), process=False)
        scene.add_geometry(mesh, geom_name=f"page{k}")
    return scene.export(file_type="glb")


def write_glb(path: str | os.PathLike[str], tm: TexturedMesh) -> list[Path]:
    """Write binary glTF (atomically); returns ``[path]``."""
    target = Path(path)
    _write_all([(target, glb_bytes(tm))])
    return [target]


def write_textured(path: str | os.PathLike[str], tm: TexturedMesh, extra: list[tuple[Path, Any]] | None = None) -> list[Path]:
    """Write ``.obj`` (with MTL and PNGs) or ``.glb`` by extension, plus ``extra`` files, as one set.

    ``extra`` is a list of (path, str | bytes) written in the same atomic set (e.g. the report).
    """
    target = Path(path)
    ext = target.suffix.lower()
    files: list[tuple[Path, Any]]
    if ext == ".obj":
        files = _obj_files(target, tm)
    elif ext == ".glb":
        files = [(target, glb_bytes(tm))]
    else:
        raise InputError(f"path: expected a .obj or .glb output, got {os.fspath(path)!r}")
    files += list(extra or [])
    _write_all(files)
    return [f for f, _ in files]


def _obj_files(target: Path, tm: TexturedMesh) -> list[tuple[Path, Any]]:
    """The (path, content) list :func:`write_textured_obj` writes."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        names = write_textured_obj(Path(d) / target.name, tm)
        out: list[tuple[Path, Any]] = []
        for n in names:
            data = n.read_bytes()
            out.append((target.with_name(n.name), data))
    return out
