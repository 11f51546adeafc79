"""The drawable kind ``"csg"``: :func:`unmesh.render.render` draws CSG models (chapter 4).

A model is evaluated for the frame (:func:`unmesh.csg.frame.prepare`) and its surface and edge
surfels facing the camera (back-face culling: a model is a closed oriented surface) are
splatted in one pass with their :class:`unmesh.render.ClipTree`, folded per surfel for the
camera (:mod:`unmesh.csg.fold`: the same image, less work per fragment); edge surfels are
clipped per fragment (Algorithm 4.2), and the scene's discontinuity surfels (4.3) travel with
them. Models are drawn after plain surfel clouds, against their depth, so they can be mixed with
any other objects in one image.

Example
-------
>>> from unmesh.render import Camera, render
>>> from unmesh.csg.model import Patch
>>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=2.0, spacing=0.5, color=(1, 0, 0))
>>> res = render(a, Camera((0, 0, 3), (0, 0, 0), width=16, height=16, ortho=1.0), shading="none")
>>> res.color[8, 8].tolist()
[1.0, 0.0, 0.0]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from unmesh.csg.fold import fold_for_camera
from unmesh.csg.frame import concatenate_frames, prepare, select
from unmesh.csg.model import Node
from unmesh.errors import InputError
from unmesh.render.camera import Camera
from unmesh.render.drawables import DrawContext, register_drawable
from unmesh.render.shading import GBuffer
from unmesh.render.splat import SplatRenderer

__all__ = ["draw_models", "front_facing"]


def front_facing(positions: np.ndarray, normals: np.ndarray, camera: Camera) -> np.ndarray:
    """(N,) bool: surfels whose oriented normal faces the camera (or is edge-on). A CSG model
    is a closed oriented surface, so the others are hidden by it (back-face culling; they
    would otherwise bleed into silhouettes and edges within the depth tolerance of 3.2.1)."""
    if camera.is_ortho:
        view = np.broadcast_to(camera.rotation[2], positions.shape)
    else:
        view = positions - camera.eye
    return np.einsum("ij,ij->i", view, normals) <= 0.0


def draw_models(gbuffer: GBuffer, models: Sequence[Node], context: DrawContext) -> GBuffer | None:
    """Splat CSG ``models`` into ``gbuffer`` (the draw function of the kind ``"csg"``)."""
    if context.options.method != "splat":
        raise InputError(f"method: CSG models are drawn by splatting (method='splat'), got {context.options.method!r}")
    frames = [prepare(m) for m in models]
    frames = [f for f in frames if len(f.arrays)]
    if not frames:
        return None
    arrays, clip = concatenate_frames(frames)
    arrays, clip = select(arrays, clip, front_facing(arrays.positions, arrays.normals, context.camera))
    arrays, clip = fold_for_camera(arrays, clip, context.camera, context.options.splat.filter_radius)
    renderer = SplatRenderer(context.camera, context.options.splat)
    return renderer._render_in_place(arrays, gbuffer, clip_surfels=context.clip_surfels, clip=clip)


register_drawable("csg", Node, draw_models, stage="splat", order=1)
