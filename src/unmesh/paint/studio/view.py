"""The studio's orbit view: yaw, pitch, zoom and pan around the model, turned into cameras.

The page owns the view while the user drags and sends it whole (:class:`View`), so a lost or
late message never leaves the server with a half-applied rotation. The server frames the model
once (:class:`Framing`: centre and bounding radius) and builds a :class:`~unmesh.render.Camera`
for every view.

Angles: ``yaw`` turns about +y (0 looks at the model from +z, 90 from +x), ``pitch`` raises the
eye (90 is straight above); ``zoom`` > 1 moves closer; ``pan`` shifts the target in units of
the framed radius along the camera's right and up.

Example
-------
>>> import numpy as np
>>> fr = Framing(center=np.zeros(3), radius=1.0)
>>> cam = fr.camera(View(yaw=0, pitch=0), 200, 100)
>>> np.round(cam.eye / np.linalg.norm(cam.eye), 6).tolist(), cam.shape
([0.0, 0.0, 1.0], (100, 200))
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.render.camera import Camera

__all__ = ["FOV", "PRESETS", "Framing", "View", "view_from_message"]

#: Vertical field of view of the studio camera (degrees).
FOV = 30.0

#: Preset views by name (yaw, pitch); "home" is the reset view.
PRESETS: dict[str, tuple[float, float]] = {
    "home": (60.0, 20.0), "front": (90.0, 0.0), "back": (-90.0, 0.0), "left": (0.0, 0.0),
    "right": (180.0, 0.0), "top": (90.0, 89.0),
}


@dataclass(frozen=True)
class View:
    """An orbit view: angles in degrees, ``zoom`` factor, ``pan`` in framed radii."""

    yaw: float = PRESETS["home"][0]
    pitch: float = PRESETS["home"][1]
    zoom: float = 1.0
    pan: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("yaw", "pitch", "zoom"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(f"view.{name}: expected a finite number, got {v!r}")
        if not -90.0 <= self.pitch <= 90.0:
            raise InputError(f"view.pitch: expected degrees in [-90, 90], got {self.pitch}")
        if not 0.05 <= self.zoom <= 50.0:
            raise InputError(f"view.zoom: expected a factor in [0.05, 50], got {self.zoom}")
        pan = self.pan
        if (not isinstance(pan, list | tuple) or len(pan) != 2
                or not all(isinstance(p, int | float) and not isinstance(p, bool) and math.isfinite(p) and abs(p) <= 100
                           for p in pan)):
            raise InputError(f"view.pan: expected two finite numbers within ±100, got {pan!r}")
        object.__setattr__(self, "pan", (float(pan[0]), float(pan[1])))


def view_from_message(msg: Any) -> View:
    """A :class:`View` from a message's ``view`` dict (``yaw``, ``pitch``, ``zoom``, ``pan``)."""
    if not isinstance(msg, dict):
        raise InputError(f"view: expected an object, got {type(msg).__name__}")
    unknown = set(msg) - {"yaw", "pitch", "zoom", "pan"}
    if unknown:
        raise InputError(f"view: unknown keys {sorted(unknown)}")
    return View(**msg)


@dataclass(frozen=True, eq=False)
class Framing:
    """Centre (3,) and bounding radius of what the studio shows."""

    center: np.ndarray
    radius: float

    @classmethod
    def of_points(cls, points: np.ndarray) -> Framing:
        """The framing of points (N,3): bounding-box centre and the largest distance from it."""
        pts = np.asarray(points, dtype=np.float64)
        center = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        radius = float(np.linalg.norm(pts - center, axis=1).max()) if len(pts) else 1.0
        return cls(center, max(radius, 1e-9))

    def camera(self, view: View, width: int, height: int) -> Camera:
        """The perspective camera of ``view`` with an image of ``width x height`` pixels."""
        yaw, pitch = math.radians(view.yaw), math.radians(view.pitch)
        direction = np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch), math.cos(yaw) * math.cos(pitch)])
        aspect = width / height
        half = math.radians(FOV) / 2
        fit = math.atan(math.tan(half) * min(aspect, 1.0))
        dist = 1.1 * self.radius / math.sin(fit)
        # camera axes for the pan (the same construction Camera uses, with up = +y)
        fwd = -direction
        right = np.cross(fwd, (0.0, 1.0, 0.0))
        if np.linalg.norm(right) < 1e-6:
            right = np.array([math.cos(yaw), 0.0, -math.sin(yaw)])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        target = self.center + self.radius * (view.pan[0] * right + view.pan[1] * up)
        eye = target + direction * dist
        up_hint = up if abs(view.pitch) > 85 else (0.0, 1.0, 0.0)
        cam = Camera(eye, target, up=up_hint, width=width, height=height, fov=FOV)
        return cam.zoomed(view.zoom) if view.zoom != 1.0 else cam
