"""The painter's palette (chapter 5): a paintable surfel plane, drawn into the model's image.

A :class:`Palette` is a second painting :class:`~unmesh.paint.session.Session` over a flat grid
of off-white surfels (:func:`palette_cloud`): paint is put on it and mixed with the brush exactly
as on the object, and :meth:`Palette.color_at` reads the mixed paint back to load the brush.
It is seen straight from above by an orthographic camera (:meth:`Palette.camera`), and it is
open (one-sided), so it is rendered without back-face culling and unshaded (paint as it is).

Thesis 5.7 draws the palette in the same image as the object, in the final normalisation pass.
``Session.render(camera, palette=p)`` does that: the palette's own image at the size of its
inset (:class:`PaletteInset`: a corner viewport of the model image) replaces the model image's
pixels there, after the object and the brush. :meth:`Palette.overlay` gives that image and its
place; the palette is rendered differentially like the object (its own view), so an unchanged
palette costs a copy of its inset.

Example
-------
>>> PaletteInset(corner="top-right", width=0.25).window(400, 300)
(8, 68, 292, 392)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.render.camera import Camera
from unmesh.render.shading import RenderResult
from unmesh.surfels.cloud import SurfelCloud

__all__ = ["PALETTE_COLOR", "PALETTE_EXTENT", "PALETTE_SIZE", "Palette", "PaletteInset", "palette_cloud"]

#: Default palette image size in pixels (width, height); the plane's aspect ratio.
PALETTE_SIZE = (300, 180)
#: The bare palette's colour (off-white).
PALETTE_COLOR = (0.95, 0.94, 0.91)
#: Height (world units) the palette camera shows (its ortho extent); the plane is 1.06 high.
PALETTE_EXTENT = 1.04
_CORNERS = ("top-left", "top-right", "bottom-left", "bottom-right")


def palette_cloud(width: float = 1.76, height: float = 1.06, spacing: float = 0.02) -> SurfelCloud:
    """The palette plane: a grid of surfels in z = 0 facing +z, ``width`` x ``height``, off-white.

    Returns
    -------
    SurfelCloud
        ``(N,3)`` float64 positions on a ``spacing`` grid, normals +z, radii ``0.75 spacing``.
    """
    for name, v in (("width", width), ("height", height), ("spacing", spacing)):
        if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
            raise InputError(f"{name}: expected a positive number, got {v!r}")
    xs = np.arange(-width / 2, width / 2 + 1e-9, spacing)
    ys = np.arange(-height / 2, height / 2 + 1e-9, spacing)
    X, Y = np.meshgrid(xs, ys)
    pos = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    nrm = np.tile([0.0, 0.0, 1.0], (len(pos), 1))
    return SurfelCloud(pos, nrm, radii=np.full(len(pos), 0.75 * spacing), colors=np.tile(PALETTE_COLOR, (len(pos), 1)))


@dataclass(frozen=True)
class PaletteInset:
    """Where the palette goes in the model's image: a corner viewport.

    Parameters
    ----------
    corner : {"top-left", "top-right", "bottom-left", "bottom-right"}
    width : float
        Inset width as a fraction of the image width (0, 1]; the height follows the palette's
        aspect ratio, capped at the image height less the margins.
    margin : int
        Pixels between the inset and the image border.
    """

    corner: str = "bottom-left"
    width: float = 0.3
    margin: int = 8

    def __post_init__(self) -> None:
        if self.corner not in _CORNERS:
            raise InputError(f"inset.corner: expected one of {', '.join(_CORNERS)}, got {self.corner!r}")
        if not (isinstance(self.width, int | float) and 0 < self.width <= 1):
            raise InputError(f"inset.width: expected a fraction in (0, 1], got {self.width!r}")
        if isinstance(self.margin, bool) or not isinstance(self.margin, int) or self.margin < 0:
            raise InputError(f"inset.margin: expected a non-negative integer, got {self.margin!r}")

    def window(self, width: int, height: int) -> tuple[int, int, int, int]:
        """Pixel rectangle ``(r0, r1, c0, c1)`` of the inset in a ``width x height`` image."""
        aspect = PALETTE_SIZE[1] / PALETTE_SIZE[0]
        w = max(8, min(round(self.width * width), width - 2 * self.margin))
        h = max(8, min(round(w * aspect), height - 2 * self.margin))
        c0 = self.margin if self.corner.endswith("left") else width - self.margin - w
        r0 = self.margin if self.corner.startswith("top") else height - self.margin - h
        return r0, r0 + h, c0, c0 + w


class Palette:
    """A paintable palette plane and where it is drawn (see the module notes).

    Parameters
    ----------
    session : unmesh.paint.Session, optional
        The palette's painting session (default: a new one over :func:`palette_cloud`, without
        a haptic loop).
    inset : PaletteInset, optional
        Its viewport in the model's image (``Session.render(camera, palette=...)``).

    Example
    -------
    >>> # p = Palette(); p.session.stroke(samples, brush, paint); s.render(cam, palette=p)
    """

    def __init__(self, session: Any = None, inset: PaletteInset | None = None) -> None:
        if session is None:
            from unmesh.paint.session import PaintOptions, Session

            session = Session(palette_cloud(), PaintOptions(haptics=False))
        self.session = session
        self.inset = inset if inset is not None else PaletteInset()
        if not isinstance(self.inset, PaletteInset):
            raise InputError(f"inset: expected a PaletteInset, got {type(self.inset).__name__}")

    @staticmethod
    def camera(width: int = PALETTE_SIZE[0], height: int = PALETTE_SIZE[1]) -> Camera:
        """The orthographic camera straight above the palette for an image of ``width x height``."""
        return Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=width, height=height, ortho=PALETTE_EXTENT)

    def render(self, width: int = PALETTE_SIZE[0], height: int = PALETTE_SIZE[1], brush: bool = False) -> RenderResult:
        """The palette's own image (unshaded, no culling); ``brush`` draws a brush painting on it."""
        return self.session.render(self.camera(width, height), shading="none", brush=brush, cull=False)

    def color_at(self, x: float, y: float, width: int = PALETTE_SIZE[0], height: int = PALETTE_SIZE[1]) -> np.ndarray:
        """The paint (3,) float64 in [0, 1] at column ``x``, row ``y`` of the palette image."""
        if not (isinstance(x, int | float) and isinstance(y, int | float) and 0 <= x < width and 0 <= y < height):
            raise InputError(f"x, y: expected a palette pixel within {width}x{height}, got {x!r}, {y!r}")
        albedo = self.render(width, height).albedo
        return np.clip(np.asarray(albedo[int(y), int(x)], dtype=np.float64), 0.0, 1.0)

    def overlay(self, width: int, height: int, brush: bool = True) -> tuple[int, int, np.ndarray]:
        """``(r0, c0, image)``: the palette's image (h, w, 3) for its inset in a ``width x height``
        model image, placed at row ``r0``, column ``c0``."""
        r0, r1, c0, c1 = self.inset.window(width, height)
        return r0, c0, self.render(c1 - c0, r1 - r0, brush=brush).color
