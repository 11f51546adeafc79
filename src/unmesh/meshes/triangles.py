"""Triangle meshes: the input of sampling (3.3) and the output of conversion (ch. 6)
and of simulation surfaces.

Conventions: vertices (V,3) float64, faces (F,3) int64 counter-clockwise seen from
outside. Texture coordinates are per vertex (V,2) with (0,0) at the *bottom-left*
of the image, as in OBJ; texture images are (H,W,3) float in [0,1] with row 0 at
the top. Vertices that carry several uv coordinates in a file are split on load.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_indices, as_points, first_index
from unmesh.errors import InputError

__all__ = ["TriangleMesh"]


def _image(value: Any, name: str) -> np.ndarray | None:
    if value is None:
        return None
    img = np.asarray(value)
    if img.dtype == np.uint8:
        img = img.astype(np.float64) / 255.0
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    img = as_array(img, name, (None, None, 3))
    if img.shape[0] == 0 or img.shape[1] == 0:
        raise InputError(f"{name}: expected a non-empty image, got shape {img.shape}")
    if (img < 0).any() or (img > 1).any():
        raise InputError(f"{name}: expected values in [0, 1]")
    return img


@dataclass(frozen=True, eq=False, repr=False)
class TriangleMesh:
    """A triangle mesh with optional per-vertex data and textures.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
    faces : array_like, shape (F, 3)
        Vertex indices, counter-clockwise seen from outside.
    uv : array_like, shape (V, 2), optional
        Texture coordinates per vertex, (0, 0) = bottom-left of the texture.
    vertex_normals : array_like, shape (V, 3), optional
        Normalised on construction.
    vertex_colors : array_like, shape (V, 3), optional
        RGB in [0, 1] (uint8 is divided by 255).
    texture : array_like, shape (H, W, 3), optional
        Colour texture, row 0 at the top.
    normal_map : array_like, shape (H, W, 3), optional
        Tangent-space normal map encoded in [0, 1] (``n = 2 c - 1``).
    attributes : mapping of str to array_like, optional
        Extra per-vertex arrays (first axis V).

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> float(m.area())
    0.5
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    vertex_normals: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    texture: np.ndarray | None = None
    normal_map: np.ndarray | None = None
    attributes: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = as_points(self.vertices, "vertices")
        nv = v.shape[0]
        f = as_indices(self.faces, "faces", (None, 3), upper=nv)
        uv = None if self.uv is None else as_array(self.uv, "uv", (None, 2), length=nv)
        vn = None
        if self.vertex_normals is not None:
            vn = as_points(self.vertex_normals, "vertex_normals", length=nv)
            lengths = np.linalg.norm(vn, axis=1)
            bad = ~(lengths > 1e-12)
            if bad.any():
                raise InputError(f"vertex_normals: expected non-zero vectors, got a zero normal at index {first_index(bad)}")
            vn = np.ascontiguousarray(vn / lengths[:, None])
        vc = None
        if self.vertex_colors is not None:
            raw = np.asarray(self.vertex_colors)
            if raw.dtype == np.uint8:
                raw = raw.astype(np.float64) / 255.0
            vc = as_array(raw, "vertex_colors", (None, 3), length=nv)
            bad = (vc < 0) | (vc > 1)
            if bad.any():
                raise InputError(f"vertex_colors: expected values in [0, 1], got {vc[first_index(bad)].tolist()} at index {first_index(bad)}")
        attrs: dict[str, np.ndarray] = {}
        for key, value in dict(self.attributes).items():
            arr = np.ascontiguousarray(value)
            if arr.ndim == 0 or arr.shape[0] != nv:
                raise InputError(f"attributes[{key!r}]: expected first axis of length {nv}, got shape {arr.shape}")
            attrs[str(key)] = arr
        for name, value in (("vertices", v), ("faces", f), ("uv", uv), ("vertex_normals", vn),
                            ("vertex_colors", vc), ("texture", _image(self.texture, "texture")),
                            ("normal_map", _image(self.normal_map, "normal_map")), ("attributes", attrs)):
            object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        extras = [n for n in ("uv", "vertex_normals", "vertex_colors", "texture", "normal_map") if getattr(self, n) is not None]
        return f"TriangleMesh({len(self.vertices)} vertices, {len(self.faces)} faces" + (f", {', '.join(extras)}" if extras else "") + ")"

    def replace(self, **changes: Any) -> TriangleMesh:
        """A copy with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    # -- derived data ---------------------------------------------------------------
    def _face_cross(self) -> np.ndarray:
        v = self.vertices
        f = self.faces
        return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])

    def face_areas(self) -> np.ndarray:
        """Triangle areas (F,)."""
        return 0.5 * np.linalg.norm(self._face_cross(), axis=1)

    def face_normals(self) -> np.ndarray:
        """Unit face normals (F,3); zero rows for degenerate triangles."""
        c = self._face_cross()
        n = np.linalg.norm(c, axis=1, keepdims=True)
        return np.divide(c, n, out=np.zeros_like(c), where=n > 0)

    def area(self) -> float:
        """Total surface area."""
        return float(self.face_areas().sum())

    def volume(self) -> float:
        """Signed enclosed volume (divergence theorem); positive for outward faces of a closed mesh."""
        v = self.vertices
        f = self.faces
        return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0)

    def computed_vertex_normals(self) -> np.ndarray:
        """Area-weighted vertex normals (V,3); the stored ones when present."""
        if self.vertex_normals is not None:
            return self.vertex_normals
        acc = np.zeros_like(self.vertices)
        c = self._face_cross()
        for k in range(3):
            np.add.at(acc, self.faces[:, k], c)
        n = np.linalg.norm(acc, axis=1, keepdims=True)
        out = np.divide(acc, n, out=np.zeros_like(acc), where=n > 0)
        out[n[:, 0] == 0] = (0.0, 0.0, 1.0)
        return out

    def edges(self) -> np.ndarray:
        """Unique undirected edges (E,2) int64, each sorted."""
        e = np.sort(self.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        return np.unique(e, axis=0)

    def boundary_edges(self) -> np.ndarray:
        """Edges used by exactly one face (B,2)."""
        e = np.sort(self.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        uniq, counts = np.unique(e, axis=0, return_counts=True)
        return uniq[counts == 1]

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2,3) ``[min, max]`` of the vertices used by faces."""
        used = self.vertices[np.unique(self.faces)] if len(self.faces) else self.vertices
        if len(used) == 0:
            return np.array([[np.inf] * 3, [-np.inf] * 3])
        return np.stack([used.min(axis=0), used.max(axis=0)])

    def transformed(self, matrix: Any) -> TriangleMesh:
        """Apply a 4x4 affine (or 3x3 linear) transform; normals use the inverse transpose."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape == (3, 3):
            lin, trans = m, np.zeros(3)
        elif m.shape == (4, 4):
            lin, trans = m[:3, :3], m[:3, 3]
        else:
            raise InputError(f"matrix: expected shape (4, 4) or (3, 3), got {m.shape}")
        det = np.linalg.det(lin)
        if abs(det) < 1e-300:
            raise InputError("matrix: expected an invertible linear part")
        faces = self.faces if det > 0 else self.faces[:, ::-1]
        vn = None if self.vertex_normals is None else self.vertex_normals @ np.linalg.inv(lin)
        return dataclasses.replace(self, vertices=self.vertices @ lin.T + trans, faces=faces, vertex_normals=vn)
