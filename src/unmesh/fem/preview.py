"""Quick flat-shaded previews of FEM surfaces with Pillow (painter's algorithm).

Used by the gallery examples when :mod:`unmesh.render` cannot draw triangle
meshes, and handy for looking at a run without ParaView.

Example
-------
>>> from unmesh.fem import hex_grid
>>> img = preview_image(hex_grid((2, 2, 2)).surface(), eye=(2.5, 2.0, 3.0), target=(0.5, 0.5, 0.5))
>>> img.size
(480, 360)
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["preview_image"]


def preview_image(mesh: Any, eye: Any = (3.0, 2.0, 4.0), target: Any = (0.0, 0.5, 0.0), *, size: tuple[int, int] = (480, 360),
                  fov: float = 40.0, ground: float | None = 0.0, edges: bool = True, color: Any = (0.85, 0.55, 0.35),
                  colors: Any | None = None) -> Any:
    """Render a TriangleMesh (flat shading, optional outlines and ground grid) to a PIL image.

    Parameters
    ----------
    mesh : TriangleMesh
    eye, target : (3,) floats
        Camera position and look-at point (y up).
    size : (width, height)
    fov : float
        Vertical field of view in degrees.
    ground : float or None
        Height of a ground grid to draw (None: none).
    edges : bool
        Draw triangle outlines.
    color : RGB in [0, 1]
    colors : (F, 3) array, optional
        Per-face colours.

    Returns
    -------
    PIL.Image.Image

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> preview_image(hex_grid((1, 1, 1)).surface(), size=(64, 48)).size
    (64, 48)
    """
    from PIL import Image, ImageDraw

    w, h = size
    eye = np.asarray(eye, float)
    fwd = np.asarray(target, float) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    f = 0.5 * h / np.tan(np.radians(fov) / 2)

    def project(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = p - eye
        z = d @ fwd
        x = d @ right
        y = d @ up
        zz = np.maximum(z, 1e-6)
        return np.c_[w / 2 + f * x / zz, h / 2 - f * y / zz], z

    img = Image.new("RGB", size, (235, 238, 242))
    draw = ImageDraw.Draw(img)
    if ground is not None:
        for k in np.linspace(-3, 3, 25):
            for a, b in (([k, ground, -3], [k, ground, 3]), ([-3, ground, k], [3, ground, k])):
                pts, z = project(np.array([a, b], float))
                if np.all(z > 0.05):
                    draw.line([tuple(pts[0]), tuple(pts[1])], fill=(200, 204, 210))
    v = np.asarray(mesh.vertices)
    t = np.asarray(mesh.faces)
    if len(t) == 0:
        return img
    p2, z = project(v)
    tri = v[t]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    light = np.array([0.4, 0.8, 0.45])
    light /= np.linalg.norm(light)
    shade = 0.35 + 0.65 * np.abs(n @ light)
    base = np.broadcast_to(np.asarray(color, float), (len(t), 3)) if colors is None else np.asarray(colors, float)
    depth = z[t].mean(axis=1)
    for k in np.argsort(-depth):
        if np.any(z[t[k]] <= 0.05):
            continue
        c = tuple(int(255 * min(1.0, x)) for x in base[k] * shade[k])
        poly = [tuple(p2[i]) for i in t[k]]
        draw.polygon(poly, fill=c, outline=(60, 40, 30) if edges else None)
    return img
