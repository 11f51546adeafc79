"""The options of one :func:`unmesh.render.render` call, in one frozen object.

:class:`RenderOptions` groups them in small frozen parts: :class:`ColorOptions` (``color_by``
through a colour map, with its range and legend), :class:`ParticleOptions` (how particles are
drawn), the :class:`~unmesh.render.shading.Shading` (lights folded in), the background colour,
the :class:`~unmesh.render.splat.SplatOptions` of EWA splatting (3.2), the MLS ray-casting options
(3.1.3) and the supersampling factor. ``render()`` folds its keywords into one
:class:`RenderOptions` (:meth:`RenderOptions.from_keywords`) and everything below it, including
the supersampling path and every registered drawable (:mod:`unmesh.render.drawables`), reads that
object.

Example
-------
>>> opts = RenderOptions.from_keywords(method="raycast", color_by="speed", supersample=2)
>>> opts.color.show_legend, opts.supersample, opts.single_sample().supersample
(True, 2, 1)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.render.shading import Light, Shading, as_shading, background_color
from unmesh.render.splat import SplatOptions

__all__ = ["METHODS", "STILL_SUPERSAMPLE", "ColorOptions", "ParticleOptions", "RenderOptions"]

#: Surfel rendering methods: EWA splatting (3.2) or ray casting of the MLS surface (3.1.3).
METHODS = ("splat", "raycast")
#: Default background of :func:`unmesh.render.render` (white).
DEFAULT_BACKGROUND = (1.0, 1.0, 1.0)
#: Supersampling of still images where a caller chooses for the user (``unmesh render`` stills,
#: gallery stills): 2 x 2 samples anti-alias silhouettes; ``render()`` itself defaults to 1 (exact
#: buffers) and videos stay at 1.
STILL_SUPERSAMPLE = 2


@dataclass(frozen=True)
class ColorOptions:
    """Colouring by an attribute through a colour map.

    Parameters
    ----------
    by : str, optional
        Attribute shown through ``colormap`` on every object that has it (vectors by length;
        also ``x``, ``y``, ``z``, ``radius``). None keeps the objects' colours.
    colormap : str
        See :data:`unmesh.render.colormap.COLORMAPS`.
    range : (lo, hi), optional
        Fixed range (default: min and max over the scene).
    legend : bool, optional
        Draw a colour bar (default: when ``by`` is given); see :attr:`show_legend`.

    Example
    -------
    >>> ColorOptions(by="pressure").show_legend, ColorOptions().show_legend
    (True, False)
    """

    by: str | None = None
    colormap: str = "viridis"
    range: Sequence[float] | None = None
    legend: bool | None = None

    @property
    def show_legend(self) -> bool:
        """Whether a colour bar is drawn."""
        return (self.by is not None) if self.legend is None else bool(self.legend)


@dataclass(frozen=True, eq=False)
class ParticleOptions:
    """How particles are drawn.

    Parameters
    ----------
    radius : float, optional
        Drawing radius for all particles (default: stored radii or half the median spacing).
    style : {"sphere", "disc"}
    radii : mapping id(Particles) -> (N,) array, optional
        Precomputed radii (used by sequences to keep sizes fixed over frames).
    """

    radius: float | None = None
    style: str = "sphere"
    radii: Mapping[int, np.ndarray] | None = None


@dataclass(frozen=True, eq=False)
class RenderOptions:
    """Every option of a render, grouped (see :func:`unmesh.render.render` for their meaning).

    Parameters
    ----------
    method : {"splat", "raycast"}
    shading : Shading
    background : (3,) tuple of float in [0, 1]
    color : ColorOptions
    splat : SplatOptions
    particles : ParticleOptions
    mls : mapping
        Options of ray casting (:func:`unmesh.render.raycast.draw_mls`), read-only.
    supersample : int
        Samples per pixel along each axis, in [1, 16].
    progress : bool
        Progress bar for ray casting.

    Example
    -------
    >>> RenderOptions(method="raycast").splat.filter_radius
    0.71
    """

    method: str = "splat"
    shading: Shading = field(default_factory=Shading)
    background: tuple[float, float, float] = DEFAULT_BACKGROUND
    color: ColorOptions = field(default_factory=ColorOptions)
    splat: SplatOptions = field(default_factory=SplatOptions)
    particles: ParticleOptions = field(default_factory=ParticleOptions)
    mls: Mapping[str, Any] = field(default_factory=dict)
    supersample: int = 1
    progress: bool = False

    def __post_init__(self) -> None:
        k = int(self.supersample)
        if k != self.supersample or k < 1 or k > 16:
            raise InputError(f"supersample: expected an integer in [1, 16], got {self.supersample!r}")
        if self.method not in METHODS:
            raise InputError(f"method: expected one of {', '.join(METHODS)}, got {self.method!r}")
        for name, kind in (("shading", Shading), ("color", ColorOptions), ("splat", SplatOptions),
                           ("particles", ParticleOptions)):
            value = getattr(self, name)
            if not isinstance(value, kind):
                raise InputError(f"{name}: expected {kind.__name__}, got {type(value).__name__}")
        object.__setattr__(self, "supersample", k)
        object.__setattr__(self, "background", tuple(float(v) for v in background_color(self.background)))
        object.__setattr__(self, "mls", MappingProxyType(dict(self.mls or {})))
        object.__setattr__(self, "progress", bool(self.progress))

    @classmethod
    def from_keywords(
        cls,
        method: str = "splat",
        shading: str | Shading = "phong",
        *,
        background: Any = DEFAULT_BACKGROUND,
        lights: Sequence[Light] | None = None,
        color_by: str | None = None,
        colormap: str = "viridis",
        color_range: Sequence[float] | None = None,
        legend: bool | None = None,
        splat: SplatOptions | None = None,
        particle_radius: float | None = None,
        particle_style: str = "sphere",
        particle_radii: Mapping[int, np.ndarray] | None = None,
        mls: Mapping[str, Any] | None = None,
        supersample: int = 1,
        progress: bool = False,
    ) -> RenderOptions:
        """The options from the keywords of :func:`unmesh.render.render` (same names and defaults).

        Example
        -------
        >>> RenderOptions.from_keywords(shading="none", background=0.5).background
        (0.5, 0.5, 0.5)
        """
        k = int(supersample)
        if k != supersample or k < 1 or k > 16:  # checked before the method, as render() always did
            raise InputError(f"supersample: expected an integer in [1, 16], got {supersample!r}")
        if method not in METHODS:
            raise InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
        return cls(method=method, shading=as_shading(shading, lights), background=background,
                   color=ColorOptions(color_by, colormap, color_range, legend),
                   splat=splat if splat is not None else SplatOptions(),
                   particles=ParticleOptions(particle_radius, particle_style, particle_radii),
                   mls=mls or {}, supersample=supersample, progress=progress)

    def replace(self, **changes: Any) -> RenderOptions:
        """A copy with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def single_sample(self) -> RenderOptions:
        """The options of the ``supersample x supersample`` larger render that supersampling
        averages: one sample per pixel and no legend (drawn after averaging)."""
        return self.replace(supersample=1, color=dataclasses.replace(self.color, legend=False))

    @property
    def background_rgb(self) -> np.ndarray:
        """The background colour (3,) float64."""
        return np.array(self.background)
