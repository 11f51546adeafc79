"""Deferred per-pixel shading (thesis 3.2: "normals are averaged using the splat weight
functions, and shading is performed in a second pass"; 5.7 deferred shading).

Every renderer (splats, MLS ray casting, triangles, particles) fills the same G-buffer: albedo,
world-space normal, depth and coverage. :func:`shade` turns it into colours with a two-sided
Blinn-Phong model and directional lights, or passes the albedo through (``"none"``).
:meth:`RenderResult.from_gbuffer` turns a G-buffer and its colours into the result every
renderer returns.

Example
-------
>>> s = Shading(lights=(Light((0, 0, -1), intensity=0.5),), ambient=0.5)
>>> s.model
'phong'
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unmesh._validate import as_array, scalar
from unmesh.errors import InputError
from unmesh.render._kernels import SERIAL_BELOW, clear_background, serial_if_small, shade_pixels
from unmesh.render.camera import Camera

__all__ = ["DEFAULT_LIGHTS", "GBuffer", "Light", "RenderResult", "Shading", "as_shading", "background_color", "shade"]


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


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered image and its buffers, in the conventions of :mod:`unmesh.render.camera`.

    Build it with :meth:`from_gbuffer` (the one constructor every renderer uses).

    Attributes
    ----------
    color : (H, W, 3) float64 in [0, 1]
        Shaded image (legend included).
    depth : (H, W) float64
        Camera-space z; ``inf`` where nothing was hit.
    normal : (H, W, 3) float64
        World-space unit normals; zeros in the background.
    coverage : (H, W) bool
    weight : (H, W) float64
        Accumulated splat weight (1 on meshes and particles, 0 in the background).
    albedo : (H, W, 3) float64
        Unshaded surface colour.
    camera : Camera
    color_range : tuple of float or None
        The ``(lo, hi)`` range used by ``color_by``.
    """

    color: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    coverage: np.ndarray
    weight: np.ndarray
    albedo: np.ndarray
    camera: Camera
    color_range: tuple[float, float] | None = None

    @classmethod
    def from_gbuffer(cls, gbuffer: GBuffer, camera: Camera, color: np.ndarray,
                     color_range: tuple[float, float] | None = None, *, copy: bool = True) -> RenderResult:
        """The result of a G-buffer and its shaded ``color`` (H,W,3): background pixels (not
        covered) get depth ``inf``, zero normal and zero weight; coverage is copied, the albedo
        is shared. With ``copy=False`` the G-buffer's depth, normal and weight are set so in
        place and all its arrays are shared (for a caller that owns the G-buffer).

        Example
        -------
        >>> g = GBuffer.empty(2, 3)
        >>> cam = Camera((0, 0, 1), (0, 0, 0), width=3, height=2)
        >>> r = RenderResult.from_gbuffer(g, cam, shade(g, cam))
        >>> r.color.shape, bool(np.isinf(r.depth).all())
        ((2, 3, 3), True)
        """
        cov = gbuffer.coverage
        if not copy:
            arrays = (cov, gbuffer.depth, gbuffer.normal, gbuffer.weight)
            if all(a.flags.c_contiguous for a in arrays):
                with serial_if_small(cov.size, 4 * SERIAL_BELOW):
                    clear_background(*arrays)
            else:
                bg = ~cov
                np.copyto(gbuffer.depth, np.inf, where=bg)
                np.copyto(gbuffer.normal, 0.0, where=bg[..., None])
                np.copyto(gbuffer.weight, 0.0, where=bg)
            return cls(color=color, depth=gbuffer.depth, normal=gbuffer.normal, coverage=cov, weight=gbuffer.weight,
                       albedo=gbuffer.albedo, camera=camera, color_range=color_range)
        return cls(color=color, depth=np.where(cov, gbuffer.depth, np.inf), normal=np.where(cov[..., None], gbuffer.normal, 0.0),
                   coverage=cov.copy(), weight=np.where(cov, gbuffer.weight, 0.0), albedo=gbuffer.albedo, camera=camera,
                   color_range=color_range)

    def gbuffer(self) -> GBuffer:
        """The buffers as a :class:`GBuffer` (arrays shared, not copied)."""
        return GBuffer(self.albedo, self.normal, self.depth, self.coverage, self.weight)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write :attr:`color` as an image file (atomic); returns the path.

        Example
        -------
        >>> import tempfile, pathlib
        >>> from unmesh.render import render
        >>> res = render([], Camera((0, 0, 1), (0, 0, 0), width=4, height=4))
        >>> res.save(pathlib.Path(tempfile.mkdtemp()) / "empty.png").name
        'empty.png'
        """
        from unmesh.render.image import save_image

        return save_image(path, self.color)

    def save_buffers(self, directory: str | os.PathLike[str]) -> dict[str, Path]:
        """Write ``depth.npy`` (H,W float), ``normal.npy`` (H,W,3), ``coverage.npy`` (H,W bool)
        and ``weight.npy`` (H,W float) into ``directory`` (created; each file atomic).

        Example
        -------
        >>> import tempfile
        >>> from unmesh.render import render
        >>> res = render([], Camera((0, 0, 1), (0, 0, 0), width=4, height=3))
        >>> sorted(res.save_buffers(tempfile.mkdtemp()))
        ['coverage', 'depth', 'normal', 'weight']
        """
        from unmesh.io.atomic import atomic_write

        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        paths = {}
        for name, arr in (("depth", self.depth), ("normal", self.normal), ("coverage", self.coverage),
                          ("weight", self.weight)):
            p = out / f"{name}.npy"
            with atomic_write(p, "wb") as fh:
                np.save(fh, arr)
            paths[name] = p
        return paths


def shade(gbuffer: GBuffer, camera: Camera, shading: str | Shading = "phong", background: Any = (1.0, 1.0, 1.0), *,
          window: tuple[int, int, int, int] | None = None, origin: tuple[int, int] = (0, 0),
          out: np.ndarray | None = None) -> np.ndarray:
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
    window : (r0, r1, c0, c1), optional
        Shade only rows ``r0:r1`` and columns ``c0:c1`` of ``gbuffer`` (partial updates, 5.7).
    origin : (row, col)
        The image pixel of ``gbuffer[0, 0]`` when ``gbuffer`` is a part cut out of the image.
    out : numpy.ndarray, optional
        C-contiguous float64 array of the result's shape to write into (and return).

    Returns
    -------
    numpy.ndarray, shape (H, W, 3) or (r1 - r0, c1 - c0, 3), float64

    Example
    -------
    >>> cam = Camera((0, 0, 1), (0, 0, 0), width=2, height=2)
    >>> g = GBuffer.empty(2, 2)
    >>> shade(g, cam, "none", background=0.0).max()
    np.float64(0.0)
    >>> shade(g, cam, window=(0, 1, 1, 2)).shape
    (1, 1, 3)
    """
    sh = as_shading(shading)
    bg = background_color(background)
    h, w = gbuffer.depth.shape
    r0, r1, c0, c1 = (0, h, 0, w) if window is None else _window(window, h, w)
    sl = (slice(r0, r1), slice(c0, c1))
    albedo, normal, depth, coverage = gbuffer.albedo[sl], gbuffer.normal[sl], gbuffer.depth[sl], gbuffer.coverage[sl]
    shape = (r1 - r0, c1 - c0, 3)
    if out is not None and (not isinstance(out, np.ndarray) or out.shape != shape or out.dtype != np.float64
                            or not out.flags.c_contiguous):
        raise InputError(f"out: expected a C-contiguous float64 array of shape {shape}, got "
                         f"{getattr(out, 'shape', type(out).__name__)}")
    if sh.model == "none":
        flat = np.where(coverage[..., None], np.clip(albedo, 0.0, 1.0), bg)
        if out is None:
            return np.ascontiguousarray(flat)
        out[...] = flat
        return out
    if out is None:
        out = np.empty(shape)
    dirs = np.array([light.world_direction(camera) for light in sh.lights]).reshape(-1, 3)
    cols = np.array([light.color * light.intensity for light in sh.lights]).reshape(-1, 3)
    f, cx, cy, ortho, _ = camera.kernel_params()
    # the kernel's pixel (0, 0) is image pixel (origin + window start)
    cx -= c0 + int(origin[1])
    cy -= r0 + int(origin[0])
    with serial_if_small(out.shape[0] * out.shape[1], 4 * SERIAL_BELOW):
        shade_pixels(np.ascontiguousarray(albedo), np.ascontiguousarray(normal), np.ascontiguousarray(depth),
                     np.ascontiguousarray(coverage), f, cx, cy, ortho, camera.rotation, np.ascontiguousarray(dirs),
                     np.ascontiguousarray(cols), sh.ambient, sh.specular, sh.shininess, bg, out)
    return out


def _window(window: Any, h: int, w: int) -> tuple[int, int, int, int]:
    """``window`` (r0, r1, c0, c1) checked against an (h, w) image."""
    try:
        r0, r1, c0, c1 = (int(v) for v in window)
    except (TypeError, ValueError):
        raise InputError(f"window: expected (r0, r1, c0, c1), got {window!r}") from None
    if not (0 <= r0 <= r1 <= h and 0 <= c0 <= c1 <= w):
        raise InputError(f"window: expected 0 <= r0 <= r1 <= {h} and 0 <= c0 <= c1 <= {w}, got {window!r}")
    return r0, r1, c0, c1
