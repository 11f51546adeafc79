"""Rendering: EWA surface splatting, MLS ray casting, triangle and particle rasterisation.

One renderer serves the gallery, CSG (clipped splatting, ch. 4), painting (partial updates,
5.7), conversion (ch. 6) and every simulation's video. Every method writes the same G-buffer
(albedo, world normal, depth, coverage, weight) and shares the camera and the deferred shading.

Image conventions
-----------------
* Pixel ``(row 0, column 0)`` is the top-left corner; columns grow to camera right, rows grow
  down; pixel centres are at ``+0.5`` (``floor`` of a projected coordinate is the pixel).
* Camera frame: ``forward = normalize(target - eye)``, ``right = forward x up``,
  ``up' = right x forward``; default ``up`` is +Y. Perspective cameras take the vertical field
  of view ``fov`` (degrees), orthographic ones the world height ``ortho`` of the image.
* Depth is the camera-space ``z`` (distance along the viewing direction, positive in front),
  ``inf`` where nothing is hit. Normals are world-space unit vectors, zeros in the background.
* Colours are float RGB in [0, 1]. Texture coordinates (0, 0) are the bottom-left of a texture.

Main API
--------
``Camera(eye, target, up=(0, 1, 0), width=..., height=..., fov=None, ortho=None)``
    :class:`~unmesh.render.camera.Camera`; ``Camera.framing(bounds, width, height)`` frames a
    bounding box, ``Camera.fit(scene_points(objects), width, height)`` the objects themselves,
    ``.orbit(deg)``, ``.zoomed(k)``, ``.project(points)``, ``.rays()``.
``render(objects, camera, method="splat", shading="phong", **options) -> RenderResult``
    Any mix of :class:`~unmesh.SurfelCloud`, :class:`~unmesh.TriangleMesh`,
    :class:`~unmesh.Particles` and registered drawable kinds; ``method="raycast"`` ray-casts the
    MLS surface of the surfels. Options: ``background``, ``lights``, ``color_by``, ``colormap``,
    ``color_range``, ``legend``, ``splat=SplatOptions(...)``, ``particle_radius``,
    ``particle_style``, ``supersample``..., folded into one :class:`RenderOptions`
    (or pass ``options=RenderOptions(...)``).
    ``RenderResult`` has ``.color`` (H,W,3), ``.depth`` (H,W), ``.normal`` (H,W,3),
    ``.coverage`` (H,W) bool, ``.weight`` (H,W), ``.albedo``, ``.save(path)``,
    ``.save_buffers(dir)``.
``SplatRenderer(camera, options)``
    Persistent splatting buffers: ``.render(clouds)`` (full update), ``.splat(cloud)`` /
    ``.unsplat(cloud)`` (partial updates, 5.7), ``.gbuffer()``; with :func:`shade` for colours.
``Light(direction, color, intensity, space="camera")``, ``Shading(model, lights, ...)``,
``shade(gbuffer, camera, shading, background)``.
``register_drawable(name, accepts, draw, stage="opaque", order=0)``
    Adds a kind of drawable object (:mod:`unmesh.render.drawables`): ``draw(gbuffer, objects,
    context)`` fills the G-buffer; ``collect(objects)`` sorts objects into a :class:`DrawList`
    by kind (discontinuity surfels, 4.3, go to ``DrawList.clip`` and reach the splatter as
    :class:`ClipSurfels`). ``Scene`` is a deprecated alias of ``DrawList``.

Helpers (stable names, used by other capabilities)
--------------------------------------------------
``save_image(path, color) -> Path``
    PNG (or other Pillow format by extension), atomic.
``write_video(frames, path, fps=30) -> Path``
    MP4 (H.264 yuv420p via imageio-ffmpeg, padded to even size) or GIF (Pillow), atomic;
    frames are consumed one at a time.
``render_sequence(frames_dir_or_paths, out_path, camera=None, fps=30, progress=True, ...) -> Path``
    Simulation output (``OUTDIR/frames/*_NNNNN.ply|obj`` + ``OUTDIR/boundary.ply``) to a video
    with one fixed camera framing all frames.
``turntable(objects, n, path=None, ...)``
    An orbit of ``n`` frames (list of images, or a written video).
``Floor(point, normal, extent, grid, casters)``, ``Box(lo, hi, opacity)``, ``Polygon(vertices, opacity)``
    Context geometry (:mod:`unmesh.render.context`): floors with a grid and a contact shadow,
    walls, tanks, blades; opaque or translucent.
``colormap(name)``, ``map_colors``, ``draw_legend``: colour maps and colour bars.

Example
-------
>>> import numpy as np
>>> from unmesh import SurfelCloud
>>> cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5])
>>> res = render(cloud, Camera((0, 0, 3), (0, 0, 0), width=32, height=32, fov=30))
>>> res.color.shape, bool(res.coverage[16, 16]), round(float(res.depth[16, 16]), 6)
((32, 32, 3), True, 3.0)
"""

import warnings
from typing import Any

from unmesh.render.camera import Camera
from unmesh.render.colormap import COLORMAPS, colormap, draw_legend, map_colors
from unmesh.render.context import Box, Floor, Polygon
from unmesh.render.drawables import (
    DrawableKind,
    DrawContext,
    drawable_kinds,
    register_drawable,
    unregister_drawable,
)
from unmesh.render.image import save_image, to_uint8, write_video
from unmesh.render.options import ColorOptions, ParticleOptions, RenderOptions
from unmesh.render.pipeline import DrawList, collect, render, scene_bounds, scene_points
from unmesh.render.sequence import find_frames, render_sequence, turntable, turntable_camera
from unmesh.render.shading import DEFAULT_LIGHTS, GBuffer, Light, RenderResult, Shading, shade
from unmesh.render.splat import ClipPlanes, ClipSurfels, ClipTree, SplatOptions, SplatRenderer

__all__ = [
    "COLORMAPS",
    "DEFAULT_LIGHTS",
    "Box",
    "Camera",
    "ClipPlanes",
    "ClipSurfels",
    "ClipTree",
    "ColorOptions",
    "DrawContext",
    "DrawList",
    "DrawableKind",
    "Floor",
    "GBuffer",
    "Light",
    "ParticleOptions",
    "Polygon",
    "RenderOptions",
    "RenderResult",
    "Shading",
    "SplatOptions",
    "SplatRenderer",
    "collect",
    "colormap",
    "draw_legend",
    "drawable_kinds",
    "find_frames",
    "map_colors",
    "register_drawable",
    "render",
    "render_sequence",
    "save_image",
    "scene_bounds",
    "scene_points",
    "shade",
    "to_uint8",
    "turntable",
    "turntable_camera",
    "unregister_drawable",
    "write_video",
]


def __getattr__(name: str) -> Any:
    if name == "Scene":
        warnings.warn("unmesh.render.Scene is deprecated; use unmesh.render.DrawList (the draw list of one frame)",
                      DeprecationWarning, stacklevel=2)
        return DrawList
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
