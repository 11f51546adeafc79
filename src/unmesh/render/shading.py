"""Deferred per-pixel shading (thesis 3.2: "normals are averaged using the splat weight
functions, and shading is performed in a second pass"; 5.7 deferred shading).

Every renderer (splats, MLS ray casting, triangles, particles) fills the same G-buffer: albedo,
world-space normal, depth and coverage. :func:`shade` turns it into colours with a two-sided
Blinn-Phong model and directional lights, or passes the albedo through (``"none"``).

Example
-------
>>> s = Shading(lights=(Light((0, 0, -1), intensity=0.5),), ambient=0.5)
>>> s.model
'phong'
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, scalar
from unmesh.errors import InputError
from unmesh.render._kernels import SERIAL_BELOW, serial_if_small, shade_pixels
from unmesh.render.camera import Camera

__all__ = ["DEFAULT_LIGHTS", "GBuffer", "Light", "Shading", "as_shading", "background_color", "shade"]


@dataclass(frozen=True)
class Light:
    """A directional light.

    Parameters
    ----------
    direction : array_like, shape (3,)
        Direction *towards* the light (normalised on construction).
    color : array_like, shape (3,)
        RGB in [0, 1].
    intensity : float
        Multiplies ``color``.
    space : {"camera", "world"}
        ``"camera"``: ``direction`` is in camera coordinates (x right, y up, z forward, so a
        light in front of the object, near the viewer, has negative z) and moves with the camera;
        ``"world"``: fixed in the scene.

    Example
    -------
    >>> Light((0, 2, 0), space="world").direction
    array([0., 1., 0.])
    """

    direction: Any
    color: Any = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    space: str = "camera"

    def __post_init__(self) -> None:
        d = as_array(self.direction, "direction", (3,))
        if not np.linalg.norm(d) > 0:
            raise InputError("direction: expected a non-zero vector")
        c = as_array(self.color, "color", (3,))
        if np.any(c < 0):
            raise InputError(f"color: expected non-negative values, got {c.tolist()}")
        if self.space not in ("camera", "world"):
            raise InputError(f"space: expected 'camera' or 'world', got {self.space!r}")
        object.__setattr__(self, "direction", d / np.linalg.norm(d))
        object.__setattr__(self, "color", c)
        object.__setattr__(self, "intensity", scalar(self.intensity, "intensity", 0.0))

    def world_direction(self, camera: Camera) -> np.ndarray:
        """Unit direction towards the light in world space (3,).

        Example
        -------
        >>> Light((0, 0, -1)).world_direction(Camera((0, 0, 5), (0, 0, 0))).tolist()  # a headlight
        [0.0, 0.0, 1.0]
        """
        return self.direction @ camera.rotation if self.space == "camera" else self.direction


#: Default lighting: a key light from the upper left front of the viewer (plus the ambient term
#: of :class:`Shading`).
DEFAULT_LIGHTS: tuple[Light, ...] = (Light((-0.6, 0.7, -1.0), intensity=0.75),)


@dataclass(frozen=True)
class Shading:
    """How the G-buffer becomes colours.

    Parameters
    ----------
    model : {"phong", "none"}
        Two-sided Blinn-Phong with :attr:`lights`, or the unlit albedo.
    lights : sequence of Light
    ambient : float
        Ambient term (fraction of the albedo).
    specular : float
        Strength of the white Blinn highlight (0 disables it).
    shininess : float
        Blinn exponent.

    Example
    -------
    >>> Shading("none").model
    'none'
    """

    model: str = "phong"
    lights: Sequence[Light] = field(default_factory=lambda: DEFAULT_LIGHTS)
    ambient: float = 0.3
    specular: float = 0.25
    shininess: float = 40.0

    def __post_init__(self) -> None:
        if self.model not in ("phong", "none"):
            raise InputError(f"shading: expected 'phong' or 'none', got {self.model!r}")
        lights = tuple(self.lights)
        for i, light in enumerate(lights):
            if not isinstance(light, Light):
                raise InputError(f"lights[{i}]: expected a Light, got {type(light).__name__}")
        object.__setattr__(self, "lights", lights)
        object.__setattr__(self, "ambient", scalar(self.ambient, "ambient", 0.0))
        object.__setattr__(self, "specular", scalar(self.specular, "specular", 0.0))
        object.__setattr__(self, "shininess", scalar(self.shininess, "shininess", 0.0))


def as_shading(shading: str | Shading | None, lights: Sequence[Light] | None = None) -> Shading:
    """Normalise a ``shading`` argument (``"phong"``, ``"none"``, a :class:`Shading` or None).

    Example
    -------
    >>> as_shading("none").model, len(as_shading(None, lights=[Light((0, 1, 0))]).lights)
    ('none', 1)
    """
    if shading is None:
        shading = "phong"
    if isinstance(shading, str):
        shading = Shading(shading.lower())
    if not isinstance(shading, Shading):
        raise InputError(f"shading: expected 'phong', 'none' or a Shading, got {type(shading).__name__}")
    if lights is not None:
        shading = Shading(shading.model, tuple(lights), shading.ambient, shading.specular, shading.shininess)
    return shading


def background_color(value: Any) -> np.ndarray:
    """A background colour (3,) in [0, 1] from an RGB triple, a grey level or a ``#rrggbb`` string.

    Example
    -------
    >>> background_color("#ff8000").tolist()
    [1.0, 0.5019607843137255, 0.0]
    """
    if isinstance(value, str):
        text = value.strip().lstrip("#")
        if len(text) != 6:
            raise InputError(f"background: expected '#rrggbb' or r,g,b, got {value!r}")
        try:
            return np.array([int(text[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])
        except ValueError:
            raise InputError(f"background: expected '#rrggbb' or r,g,b, got {value!r}") from None
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.repeat(arr, 3)
    arr = as_array(arr, "background", (3,))
    if np.any(arr < 0) or np.any(arr > 1):
        raise InputError(f"background: expected values in [0, 1], got {arr.tolist()}")
    return arr


@dataclass
class GBuffer:
    """Per-pixel surface data every renderer writes before shading.

    Attributes
    ----------
    albedo : (H, W, 3) float64
    normal : (H, W, 3) float64
        World-space unit normal, zeros where uncovered.
    depth : (H, W) float64
        Camera-space z, ``inf`` where uncovered.
    coverage : (H, W) bool
    weight : (H, W) float64
        Accumulated splat weight; 1 where an opaque primitive (mesh, particle) is visible.
    """

    albedo: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    coverage: np.ndarray
    weight: np.ndarray

    @classmethod
    def empty(cls, height: int, width: int) -> GBuffer:
        """An empty G-buffer (nothing covered)."""
        return cls(np.zeros((height, width, 3)), np.zeros((height, width, 3)), np.full((height, width), np.inf),
                   np.zeros((height, width), dtype=bool), np.zeros((height, width)))

    def copy(self) -> GBuffer:
        """A deep copy."""
        return GBuffer(self.albedo.copy(), self.normal.copy(), self.depth.copy(), self.coverage.copy(), self.weight.copy())


def shade(gbuffer: GBuffer, camera: Camera, shading: str | Shading = "phong", background: Any = (1.0, 1.0, 1.0)) -> np.ndarray:
    """Colour image (H,W,3) float64 in [0,1] from a G-buffer (deferred shading).

    Blinn-Phong: ``c = a (ambient + sum_l I_l max(0, n.l)) + specular sum_l I_l max(0, n.h)^shininess``
    with ``h = normalize(l + v)`` and ``v`` towards the eye; normals facing away from the viewer
    are flipped (two-sided lighting), so open surfaces are lit from both sides.

    Parameters
    ----------
    gbuffer : GBuffer
    camera : Camera
    shading : {"phong", "none"} or Shading
    background : colour
        Written where ``gbuffer.coverage`` is false.

    Returns
    -------
    numpy.ndarray, shape (H, W, 3), float64

    Example
    -------
    >>> cam = Camera((0, 0, 1), (0, 0, 0), width=2, height=2)
    >>> g = GBuffer.empty(2, 2)
    >>> shade(g, cam, "none", background=0.0).max()
    np.float64(0.0)
    """
    sh = as_shading(shading)
    bg = background_color(background)
    h, w = gbuffer.depth.shape
    if sh.model == "none":
        out = np.where(gbuffer.coverage[..., None], np.clip(gbuffer.albedo, 0.0, 1.0), bg)
        return np.ascontiguousarray(out)
    out = np.empty((h, w, 3))
    dirs = np.array([light.world_direction(camera) for light in sh.lights]).reshape(-1, 3)
    cols = np.array([light.color * light.intensity for light in sh.lights]).reshape(-1, 3)
    f, cx, cy, ortho, _ = camera.kernel_params()
    with serial_if_small(h * w, 4 * SERIAL_BELOW):
        shade_pixels(np.ascontiguousarray(gbuffer.albedo), np.ascontiguousarray(gbuffer.normal),
                     np.ascontiguousarray(gbuffer.depth), np.ascontiguousarray(gbuffer.coverage), f, cx, cy, ortho,
                     camera.rotation, np.ascontiguousarray(dirs), np.ascontiguousarray(cols), sh.ambient, sh.specular,
                     sh.shininess, bg, out)
    return out
