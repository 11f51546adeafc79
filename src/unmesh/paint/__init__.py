"""3D painting on surfels with a physically simulated brush (thesis chapter 5).

The surface is resampled wherever paint lands (children surfels attached to the original
"fathers"), so painted detail is not limited by a texture's resolution and has no seams.

Main API
--------
``Session(cloud, options=PaintOptions(...))``
    :class:`~unmesh.paint.session.Session`: ``stroke(samples, brush=, paint=)``, the incremental
    ``begin_stroke`` / ``add_samples`` / ``end_stroke``, ``undo()`` / ``redo()``, ``advance(dt)``
    (drying, diffusion, downsampling), ``render(camera)`` (differential updates, 5.7),
    ``pick(camera, x, y)``, ``render(camera, palette=Palette())`` (the palette in the same image), ``force()`` (haptic force, 5.4.2), ``save(path)`` /
    ``Session.load(path)``, ``strokes_json()``, ``replay(dict)``, ``cloud()``.
``Brush(type, size)``, ``Paint(type, color, drying)``, ``Sample(t, point, pressure, tilt)``
    Frozen descriptions (:mod:`unmesh.paint.strokes`); ``load_strokes(path)`` reads a stroke file.

Modules: :mod:`~unmesh.paint.surface` (5.3), :mod:`~unmesh.paint.brush` and
:mod:`~unmesh.paint.collide` (5.4), :mod:`~unmesh.paint.haptic` (5.4.2),
:mod:`~unmesh.paint.transfer` (5.5), :mod:`~unmesh.paint.model` (5.6),
:mod:`~unmesh.paint.background` (drying, diffusion, downsampling), :mod:`~unmesh.paint.view` (5.7),
:mod:`~unmesh.paint.palette` (the palette plane and its inset in the image).

Example
-------
>>> from unmesh.shapes import by_name
>>> s = Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))
>>> r = s.stroke([Sample(0.0, (0, 0, 0), 0.8)], brush=Brush("round", 0.04), paint=Paint("oil", (1, 0, 0)))
>>> r.added > 0 and len(s.cloud()) > 400
True
"""

from unmesh.paint.palette import Palette, PaletteInset
from unmesh.paint.session import PaintOptions, Session, StrokeResult
from unmesh.paint.strokes import BRUSH_TYPES, PAINT_TYPES, Brush, Paint, Sample, load_strokes, parse_strokes

__all__ = [
    "BRUSH_TYPES",
    "PAINT_TYPES",
    "Brush",
    "Paint",
    "PaintOptions",
    "Palette",
    "PaletteInset",
    "Sample",
    "Session",
    "StrokeResult",
    "load_strokes",
    "parse_strokes",
]
