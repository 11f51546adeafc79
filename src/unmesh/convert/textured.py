"""The result of a conversion: a triangle mesh with atlas pages, drawable by the renderer.

A :class:`TexturedMesh` is one :class:`~unmesh.meshes.TriangleMesh` per atlas page (6.3): each
part holds the triangles whose patches are on that page, with per-corner texture coordinates
(every triangle has its own three vertices, as every patch is separate), smooth vertex
normals, the colour page as ``texture`` and the tangent-space normal page as ``normal_map``
(OpenGL convention, green = +v, tangent = direction of +u). Importing :mod:`unmesh.convert`
registers the kind ``"textured_mesh"`` with :func:`unmesh.render.register_drawable`, so
``render(textured_mesh, camera)`` rasterises its parts, with the rasteriser's trilinear
(mip-mapped) texture lookup; with ``regions`` (the patch of every page texel) its filtered
levels never mix two patches (6.5).

Example
-------
>>> import numpy as np
>>> from unmesh.meshes import TriangleMesh
>>> part = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=[[0, 0], [1, 0], [0, 1]],
...                     texture=np.ones((4, 4, 3)))
>>> tm = TexturedMesh((part,))
>>> tm.face_count, tm.bounds().tolist()
(1, [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.render import register_drawable
from unmesh.render.drawables import DrawContext, drawable_kinds
from unmesh.render.raster import draw_meshes
from unmesh.render.shading import GBuffer

__all__ = ["TexturedMesh"]


@dataclass(frozen=True, eq=False)
class TexturedMesh:
    """A textured triangle mesh split into one part per atlas page.

    Parameters
    ----------
    parts : sequence of TriangleMesh
        Each with ``uv`` and ``texture`` (and ``normal_map`` when normal maps were baked).
    mip_levels : sequence of tuples of (H, W, 3) arrays, optional
        Per part, the half- and quarter-resolution colour pages (6.5).
    depth_pages : sequence of (H, W) float64 arrays, optional
        Per part, the depth (displacement) page (6.2): the height of the surface above each
        triangle's plane along its face normal, in world units (0 outside the patches).
    regions : sequence of (H, W) int64 arrays, optional
        Per part, the patch (triangle) of every page texel, -1 outside the patches; the
        rasteriser's filtered texture levels stay within a patch
        (:func:`unmesh.render.raster.texture_levels`).
    """

    parts: tuple[TriangleMesh, ...]
    mip_levels: tuple[tuple[np.ndarray, ...], ...] = field(default=())
    depth_pages: tuple[np.ndarray, ...] = field(default=())
    regions: tuple[np.ndarray, ...] = field(default=())

    def __post_init__(self) -> None:
        parts = tuple(self.parts)
        if not parts:
            raise InputError("parts: expected at least one TriangleMesh, got none")
        for i, p in enumerate(parts):
            if not isinstance(p, TriangleMesh):
                raise InputError(f"parts[{i}]: expected a TriangleMesh, got {type(p).__name__}")
            if p.uv is None or p.texture is None:
                raise InputError(f"parts[{i}]: expected uv coordinates and a texture")
        object.__setattr__(self, "parts", parts)
        object.__setattr__(self, "mip_levels", tuple(tuple(m) for m in self.mip_levels))
        depth = tuple(np.asarray(d, dtype=np.float64) for d in self.depth_pages)
        if depth and len(depth) != len(parts):
            raise InputError(f"depth_pages: expected one page per part ({len(parts)}), got {len(depth)}")
        object.__setattr__(self, "depth_pages", depth)
        regions = tuple(np.asarray(r, dtype=np.int64) for r in self.regions)
        if regions and len(regions) != len(parts):
            raise InputError(f"regions: expected one page per part ({len(parts)}), got {len(regions)}")
        for i, (r, p) in enumerate(zip(regions, parts, strict=False)):
            if r.shape != p.texture.shape[:2]:  # type: ignore[union-attr]
                raise InputError(f"regions[{i}]: expected the page's shape {p.texture.shape[:2]}, got {r.shape}")  # type: ignore[union-attr]
        object.__setattr__(self, "regions", regions)

    def __repr__(self) -> str:
        pages = ", ".join(f"{p.texture.shape[1]}x{p.texture.shape[0]}" for p in self.parts)  # type: ignore[union-attr]
        return f"TexturedMesh({self.face_count} faces, pages {pages})"

    @property
    def face_count(self) -> int:
        """Number of triangles over all parts."""
        return int(sum(len(p.faces) for p in self.parts))

    @property
    def vertices(self) -> np.ndarray:
        """All part vertices (V, 3) (for framing)."""
        return np.concatenate([p.vertices for p in self.parts])

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2, 3)."""
        b = np.stack([p.bounds() for p in self.parts])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    def without_normal_map(self) -> TexturedMesh:
        """The same mesh without its normal maps (e.g. Fig. 6.6, middle row)."""
        return TexturedMesh(tuple(p.replace(normal_map=None) for p in self.parts), self.mip_levels, self.depth_pages,
                            self.regions)


def _draw(gbuffer: GBuffer, objects: Sequence[Any], context: DrawContext) -> None:
    parts = [p for obj in objects for p in obj.parts]
    regions = [r for obj in objects for r in (obj.regions or (None,) * len(obj.parts))]
    draw_meshes(gbuffer, parts, context.camera, texture_regions=regions)


if not any(k.name == "textured_mesh" for k in drawable_kinds()):
    register_drawable("textured_mesh", TexturedMesh, _draw, stage="opaque", order=1)
