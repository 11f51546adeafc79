"""Validation of the page's JSON messages into engine objects; every error names the key.

Messages from the page (one JSON object each, at most :data:`MAX_MESSAGE` bytes)::

    {"type": "hello", "width": 800, "height": 600, "view": {...}}
    {"type": "view", "view": {"yaw": 30, "pitch": 10, "zoom": 1.2, "pan": [0, 0]}, "preview": true}
    {"type": "resize", "width": 800, "height": 600}
    {"type": "begin", "target": "model" | "palette", "brush": {"type": "round", "size": 0.05},
     "paint": {"type": "oil", "color": [0.8, 0.1, 0.1], "drying": 0.2}}
    {"type": "samples", "samples": [[t_ms, x_px, y_px, pressure, tilt_x_deg, tilt_y_deg], ...], "ts": 1234.5}
    {"type": "end"}
    {"type": "undo"} | {"type": "redo"}
    {"type": "save", "name": "x.ply"} | {"type": "load", "name": "x.ply"} | {"type": "export", "name": "x.png"}
    {"type": "record", "name": "x.json"} | {"type": "replay", "name": "x.json"}
    {"type": "pick_color", "x": 10, "y": 20}    (palette pixel: load the brush with its paint)
    {"type": "sync", "id": 3}    (replied after the frames of every earlier message were sent)

``samples`` rows are compact arrays: time in milliseconds (the page's clock), the pen position in
pixels of the rendered image, pressure in [0, 1], and tilt about the view's x and y axes in
degrees (the Pointer Events ``tiltY`` and ``tiltX``).

Example
-------
>>> parse_message('{"type": "undo"}')
{'type': 'undo'}
>>> parse_message('{"type": "nope"}')
Traceback (most recent call last):
...
unmesh.errors.InputError: type: expected one of begin, end, export, hello, load, pick_color, record, redo, replay, resize, samples, save, sync, undo, view, got 'nope'
"""

from __future__ import annotations

import json
import math
from typing import Any

from unmesh.errors import InputError

__all__ = ["BRUSH_TYPES", "MAX_MESSAGE", "MAX_SAMPLES", "PAINT_TYPES", "brush_spec", "paint_spec", "parse_message",
           "samples_spec"]

#: Largest accepted message (bytes); the WebSocket refuses bigger ones.
MAX_MESSAGE = 1 << 20
#: Most samples in one ``samples`` message.
MAX_SAMPLES = 4096
BRUSH_TYPES = ("round", "flat", "pencil")
PAINT_TYPES = ("oil", "watercolor", "metallic")
TYPES = ("begin", "end", "export", "hello", "load", "pick_color", "record", "redo", "replay", "resize", "samples",
         "save", "sync", "undo", "view")


def _number(value: Any, key: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or not lo <= value <= hi:
        raise InputError(f"{key}: expected a number in [{lo}, {hi}], got {value!r}")
    return float(value)


def parse_message(text: str | bytes) -> dict[str, Any]:
    """The message object of ``text``, with a known ``type``; InputError otherwise."""
    if len(text) > MAX_MESSAGE:
        raise InputError(f"message: expected at most {MAX_MESSAGE} bytes, got {len(text)}")
    try:
        msg = json.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"message: expected JSON, got a parse error ({exc})") from None
    if not isinstance(msg, dict):
        raise InputError(f"message: expected a JSON object, got {type(msg).__name__}")
    kind = msg.get("type")
    if kind not in TYPES:
        raise InputError(f"type: expected one of {', '.join(TYPES)}, got {kind!r}")
    return msg


def brush_spec(value: Any) -> dict[str, Any]:
    """``{"type", "size"}`` checked: a brush type of :data:`BRUSH_TYPES`, size in (0, 10]."""
    if not isinstance(value, dict):
        raise InputError(f"brush: expected an object, got {value!r}")
    kind = value.get("type")
    if kind not in BRUSH_TYPES:
        raise InputError(f"brush.type: expected one of {', '.join(BRUSH_TYPES)}, got {kind!r}")
    size = _number(value.get("size"), "brush.size", 1e-6, 10.0)
    return {"type": kind, "size": size}


def paint_spec(value: Any) -> dict[str, Any]:
    """``{"type", "color", "drying"}`` checked: colour three numbers in [0, 1], drying in [0, 100]."""
    if not isinstance(value, dict):
        raise InputError(f"paint: expected an object, got {value!r}")
    kind = value.get("type")
    if kind not in PAINT_TYPES:
        raise InputError(f"paint.type: expected one of {', '.join(PAINT_TYPES)}, got {kind!r}")
    color = value.get("color")
    if not isinstance(color, list) or len(color) != 3:
        raise InputError(f"paint.color: expected [r, g, b] in [0, 1], got {color!r}")
    rgb = tuple(_number(c, f"paint.color[{i}]", 0.0, 1.0) for i, c in enumerate(color))
    drying = _number(value.get("drying", 0.1), "paint.drying", 0.0, 100.0)
    return {"type": kind, "color": rgb, "drying": drying}


def samples_spec(value: Any, width: int, height: int) -> list[tuple[float, float, float, float, float, float]]:
    """Rows ``(t_ms, x, y, pressure, tilt_x, tilt_y)`` checked; pixels within the image."""
    if not isinstance(value, list) or len(value) > MAX_SAMPLES:
        raise InputError(f"samples: expected a list of at most {MAX_SAMPLES} rows, got {type(value).__name__}"
                         + (f" of {len(value)}" if isinstance(value, list) else ""))
    rows = []
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != 6:
            raise InputError(f"samples[{i}]: expected [t_ms, x, y, pressure, tilt_x, tilt_y], got {row!r}")
        rows.append((_number(row[0], f"samples[{i}].t", -1e12, 1e12),
                     _number(row[1], f"samples[{i}].x", -1e4, width + 1e4),
                     _number(row[2], f"samples[{i}].y", -1e4, height + 1e4),
                     _number(row[3], f"samples[{i}].pressure", 0.0, 1.0),
                     _number(row[4], f"samples[{i}].tilt_x", -90.0, 90.0),
                     _number(row[5], f"samples[{i}].tilt_y", -90.0, 90.0)))
    return rows
