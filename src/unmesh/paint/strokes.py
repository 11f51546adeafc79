"""Stroke descriptions: brushes, paints, pen samples and the stroke file (thesis 5.4-5.6).

A stroke is a brush, a paint and a list of pen samples. The stroke file (JSON, documented
in ``docs/paint.md``) records everything painted in a session::

    {"version": 1,
     "strokes": [{"brush": {"type": "round", "size": 0.04},
                  "paint": {"type": "oil", "color": [0.8, 0.1, 0.1]},
                  "samples": [{"t": 0.0, "point": [0.1, 0.2, 0.3], "pressure": 0.6, "tilt": [0.0, 0.0]}]}]}

Extra keys are ignored by readers (``"advance"`` lists the ``Session.advance`` steps taken after
a stroke, so a replay reproduces drying and diffusion exactly).

Example
-------
>>> b = Brush("round", 0.05)
>>> p = Paint("oil", (1.0, 0.0, 0.0))
>>> s = Sample(0.0, (0.0, 0.0, 1.0), 0.5)
>>> stroke_dict(b, p, [s])["brush"]
{'type': 'round', 'size': 0.05, 'stiffness': 0.35}
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, fields
from typing import Any

from unmesh.errors import FormatError, InputError

__all__ = [
    "BRUSH_TYPES",
    "PAINT_TYPES",
    "Brush",
    "Paint",
    "Sample",
    "load_strokes",
    "parse_strokes",
    "read_stroke_json",
    "stroke_dict",
]

#: Default spring stiffness K_s (5.1, in units of the brush mass per step^2) by brush type.
BRUSH_TYPES: dict[str, float] = {"round": 0.35, "flat": 0.5, "pencil": 0.9}

#: Paint types and their defaults: optical density rho (5.8, per unit layer thickness), drying
#: rate kappa (5.12, 1/s), transfer rates tau brush->surface and surface->brush (5.9/5.10, 1/s),
#: isotropic diffusion coefficient (5.15, area/s), layer thickness on the brush (world units),
#: viscous (impasto, 5.6.3), reflectivity, shininess, metallic (environment mapped).
PAINT_TYPES: dict[str, dict[str, Any]] = {
    "oil": {"density": 2.0, "drying": 0.02, "transfer": 1.5, "back_transfer": 0.5, "diffusion": 0.0,
            "thickness": 0.002, "viscous": True, "reflectivity": 0.25, "shininess": 40.0, "metallic": 0.0},
    "watercolor": {"density": 0.5, "drying": 0.15, "transfer": 2.0, "back_transfer": 1.0, "diffusion": 2e-4,
                   "thickness": 0.001, "viscous": False, "reflectivity": 0.05, "shininess": 5.0, "metallic": 0.0},
    "metallic": {"density": 4.0, "drying": 0.05, "transfer": 1.5, "back_transfer": 0.5, "diffusion": 0.0,
                 "thickness": 0.002, "viscous": False, "reflectivity": 0.8, "shininess": 80.0, "metallic": 1.0},
}

_RELIEFS = ("auto", "none", "hair", "beaten")


def _finite(value: Any, key: str, lo: float | None = None, hi: float | None = None, positive: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{key}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise InputError(f"{key}: expected a finite number, got {value!r}")
    if positive and not v > 0:
        raise InputError(f"{key}: expected a positive number, got {v!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise InputError(f"{key}: expected a number in [{lo}, {hi}], got {v!r}")
    return v


def _vector(value: Any, key: str, n: int, lo: float | None = None, hi: float | None = None) -> tuple[float, ...]:
    if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != n:
        raise InputError(f"{key}: expected {n} numbers, got {value!r}")
    return tuple(_finite(v, f"{key}[{i}]", lo, hi) for i, v in enumerate(value))


@dataclass(frozen=True)
class Brush:
    """A brush (5.4, Fig. 5.3).

    Parameters
    ----------
    type : {"round", "flat", "pencil"}
        Round brush (one active tip mass), flat brush (three active masses in a row, can
        split, 5.4.3) or a hard pencil tip (one very stiff mass).
    size : float
        Radius of the bristle body (half the width of a flat brush), world units (> 0).
        The bristles are ``3 * size`` long.
    stiffness : float, optional
        Spring constant K_s of (5.1); default by type (:data:`BRUSH_TYPES`).
    friction : float
        Friction coefficient eta of (5.7).

    Example
    -------
    >>> Brush("flat", 0.02).stiffness
    0.5
    """

    type: str = "round"
    size: float = 0.04
    stiffness: float | None = None
    friction: float = 0.5

    def __post_init__(self) -> None:
        if self.type not in BRUSH_TYPES:
            raise InputError(f"brush.type: expected one of {sorted(BRUSH_TYPES)}, got {self.type!r}")
        object.__setattr__(self, "size", _finite(self.size, "brush.size", positive=True))
        k = BRUSH_TYPES[self.type] if self.stiffness is None else _finite(self.stiffness, "brush.stiffness", 1e-6, 1.5)
        object.__setattr__(self, "stiffness", k)
        object.__setattr__(self, "friction", _finite(self.friction, "brush.friction", 0.0, 1.0))

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type, "size": self.size, "stiffness": self.stiffness}


@dataclass(frozen=True)
class Paint:
    """A paint (5.6): colour, type and the paint-model parameters.

    Parameters
    ----------
    type : {"oil", "watercolor", "metallic"}
        Sets the defaults of the other parameters (:data:`PAINT_TYPES`).
    color : (3,) floats in [0, 1]
        Wet colour C_w (RGB).
    drying : float, optional
        Drying rate kappa of (5.12), 1/s.
    density, transfer, back_transfer, diffusion, thickness : float, optional
        Optical density rho (5.8), transfer rates tau brush->surface and surface->brush
        (5.9/5.10; ``back_transfer=0`` gives no back-transfer, Fig. 5.8), isotropic diffusion
        coefficient (5.15), layer thickness loaded on the brush.
    relief : {"auto", "none", "hair", "beaten"}
        Geometric detail (5.6.3): hair imprints (default of viscous oil), small patches with one
        normal ("beaten" gold, default of metallic) or none.

    Example
    -------
    >>> Paint("watercolor", (0, 0, 1)).diffusion > 0
    True
    """

    type: str = "oil"
    color: tuple[float, float, float] = (0.8, 0.1, 0.1)
    drying: float | None = None
    density: float | None = None
    transfer: float | None = None
    back_transfer: float | None = None
    diffusion: float | None = None
    thickness: float | None = None
    relief: str = "auto"

    def __post_init__(self) -> None:
        if self.type not in PAINT_TYPES:
            raise InputError(f"paint.type: expected one of {sorted(PAINT_TYPES)}, got {self.type!r}")
        object.__setattr__(self, "color", _vector(self.color, "paint.color", 3, 0.0, 1.0))
        d = PAINT_TYPES[self.type]
        for name in ("drying", "density", "transfer", "back_transfer", "diffusion", "thickness"):
            v = getattr(self, name)
            v = d[name] if v is None else _finite(v, f"paint.{name}", 0.0)
            object.__setattr__(self, name, float(v))
        if self.thickness <= 0:
            raise InputError(f"paint.thickness: expected a positive number, got {self.thickness!r}")
        if self.relief not in _RELIEFS:
            raise InputError(f"paint.relief: expected one of {list(_RELIEFS)}, got {self.relief!r}")
        if self.relief == "auto":
            object.__setattr__(self, "relief", "hair" if d["viscous"] else "beaten" if self.type == "metallic" else "none")

    @property
    def reflectivity(self) -> float:
        return float(PAINT_TYPES[self.type]["reflectivity"])

    @property
    def shininess(self) -> float:
        return float(PAINT_TYPES[self.type]["shininess"])

    @property
    def metallic(self) -> float:
        return float(PAINT_TYPES[self.type]["metallic"])

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": self.type, "color": list(self.color)}
        for f in fields(self):
            if f.name not in ("type", "color"):
                out[f.name] = getattr(self, f.name)
        return out


@dataclass(frozen=True)
class Sample:
    """One pen sample of a stroke.

    Parameters
    ----------
    t : float
        Time in seconds (drives drying and diffusion; samples of a stroke must not go back).
    point : (3,) floats
        The surface point the pen aims at.
    pressure : float in [0, 1]
        Sets how far the handle is pushed towards the surface (penetration) and the transfer.
    tilt : (2,) floats
        Degrees about the view's x and y axes by which the handle leans away from the normal.

    Example
    -------
    >>> Sample(0.5, (0, 0, 1)).pressure
    0.5
    """

    t: float = 0.0
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pressure: float = 0.5
    tilt: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _finite(self.t, "t", 0.0))
        object.__setattr__(self, "point", _vector(self.point, "point", 3))
        object.__setattr__(self, "pressure", _finite(self.pressure, "pressure", 0.0, 1.0))
        object.__setattr__(self, "tilt", _vector(self.tilt, "tilt", 2, -80.0, 80.0))

    def to_dict(self) -> dict[str, Any]:
        return {"t": self.t, "point": list(self.point), "pressure": self.pressure, "tilt": list(self.tilt)}


def _where(where: str, key: str) -> str:
    return f"{where}{key}"


def _brush_from(d: Any, where: str) -> Brush:
    if not isinstance(d, dict):
        raise InputError(f"{where}brush: expected an object, got {d!r}")
    try:
        return Brush(type=d.get("type", "round"), size=d.get("size", 0.04), stiffness=d.get("stiffness"),
                     friction=d.get("friction", 0.5))
    except InputError as exc:
        raise InputError(f"{where}{exc}") from None


def _paint_from(d: Any, where: str) -> Paint:
    if not isinstance(d, dict):
        raise InputError(f"{where}paint: expected an object, got {d!r}")
    known = {f.name for f in fields(Paint)}
    try:
        return Paint(**{k: v for k, v in d.items() if k in known})
    except InputError as exc:
        raise InputError(f"{where}{exc}") from None


def _sample_from(d: Any, where: str) -> Sample:
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected an object, got {d!r}")
    if "point" not in d:
        raise InputError(f"{where}point: missing")
    try:
        return Sample(t=d.get("t", 0.0), point=d["point"], pressure=d.get("pressure", 0.5), tilt=d.get("tilt", (0.0, 0.0)))
    except InputError as exc:
        raise InputError(f"{where}{exc}") from None


def check_samples(samples: Any, where: str = "") -> list[Sample]:
    """Samples as a list of :class:`Sample` (dicts accepted); errors name the sample index.

    Example
    -------
    >>> check_samples([{"t": 0, "point": [0, 0, 0]}])[0].point
    (0.0, 0.0, 0.0)
    """
    if isinstance(samples, Sample):
        samples = [samples]
    if isinstance(samples, str | bytes | dict) or not hasattr(samples, "__iter__"):
        raise InputError(f"{where}samples: expected a list of samples, got {type(samples).__name__}")
    out = []
    prev = -math.inf
    for i, s in enumerate(samples):
        key = f"{where}samples[{i}]."
        smp = s if isinstance(s, Sample) else _sample_from(s, key)
        if smp.t < prev:
            raise InputError(f"{key}t: expected times that do not decrease, got {smp.t} after {prev}")
        prev = smp.t
        out.append(smp)
    return out


def stroke_dict(brush: Brush, paint: Paint, samples: list[Sample]) -> dict[str, Any]:
    """The stroke-file entry of one stroke."""
    return {"brush": brush.to_dict(), "paint": paint.to_dict(), "samples": [s.to_dict() for s in samples]}


def parse_strokes(data: Any, source: str = "strokes") -> list[tuple[Brush, Paint, list[Sample], list[float]]]:
    """Validate a stroke-file dict; returns ``(brush, paint, samples, advance)`` per stroke.

    Raises
    ------
    InputError
        One line naming the file, the key and the stroke/sample index.

    Example
    -------
    >>> parse_strokes({"version": 1, "strokes": []})
    []
    """
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a JSON object with 'version' and 'strokes', got {type(data).__name__}")
    if data.get("version") != 1:
        raise InputError(f"{source}: version: expected 1, got {data.get('version')!r}")
    strokes = data.get("strokes")
    if not isinstance(strokes, list):
        raise InputError(f"{source}: strokes: expected a list, got {type(strokes).__name__}")
    out = []
    for k, st in enumerate(strokes):
        where = f"{source}: strokes[{k}]."
        if not isinstance(st, dict):
            raise InputError(f"{where[:-1]}: expected an object, got {st!r}")
        brush = _brush_from(st.get("brush", {}), where)
        paint = _paint_from(st.get("paint", {}), where)
        if "samples" not in st:
            raise InputError(f"{where}samples: missing")
        samples = check_samples(st["samples"], where)
        if not samples:
            raise InputError(f"{where}samples: expected at least one sample, got none")
        adv = st.get("advance", [])
        if not isinstance(adv, list):
            raise InputError(f"{where}advance: expected a list of seconds, got {adv!r}")
        advance = [a if isinstance(a, dict) else _finite(a, f"{where}advance[{i}]", 0.0) for i, a in enumerate(adv)]
        out.append((brush, paint, samples, advance))
    return out


def read_stroke_json(path: str | os.PathLike[str]) -> Any:
    """The JSON document of a stroke file, not yet validated (see :func:`parse_strokes`).

    Raises
    ------
    InputError
        The file cannot be read.
    FormatError
        The file is empty or not JSON (message names the file and line).
    """
    name = os.fspath(path)
    try:
        with open(name, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as exc:
        raise InputError(f"{name}: cannot read the stroke file ({exc.strerror})") from None
    if not text.strip():
        raise FormatError(f"{name}: the stroke file is empty")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(f"{name}: line {exc.lineno}: not valid JSON ({exc.msg})") from None
    return data


def load_strokes(path: str | os.PathLike[str]) -> list[tuple[Brush, Paint, list[Sample], list[float]]]:
    """Read and validate a stroke file (see :func:`parse_strokes`).

    Raises
    ------
    FormatError
        The file is empty or not JSON (message names the file and line).
    """
    return parse_strokes(read_stroke_json(path), os.fspath(path))
