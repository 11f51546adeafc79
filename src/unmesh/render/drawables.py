"""The table of drawable kinds: what :func:`unmesh.render.render` can draw, and how.

Every kind of object the renderer accepts is one :class:`DrawableKind` in a registry: a name,
which objects belong to it (a type or a predicate), the function that draws a list of them into
the G-buffer, and its place in the order of work. Rendering is two stages:

``"opaque"``
    Z-buffered primitives (triangle meshes, particles, ...) drawn into the G-buffer in place,
    each kind in increasing ``order``.
``"splat"``
    Drawn afterwards, against the finished opaque G-buffer: EWA splatting uses its depth as the
    initial visibility buffer (3.2.1), so opaque geometry occludes splats per fragment. A splat
    draw function may return a new G-buffer that replaces the old one.

The built-in kinds are registered by :mod:`unmesh.render.pipeline`: ``"surfels"``
(:class:`~unmesh.SurfelCloud`, stage ``"splat"``), ``"meshes"`` (:class:`~unmesh.TriangleMesh`,
opaque, order 0), ``"particles"`` (:class:`~unmesh.Particles`, opaque, order 10) and the context
geometry of :mod:`unmesh.render.context` (``"context"``, opaque, order 20; ``"translucent"``,
splat stage, order 100). A new
capability adds its kind with :func:`register_drawable`, without editing ``render()``.

A draw function is ``draw(gbuffer, objects, context) -> GBuffer | None`` with ``objects`` the
list of this kind's objects in the order they were given and ``context`` a
:class:`DrawContext` (camera, :class:`~unmesh.render.options.RenderOptions`, colour overrides of
``color_by``, clip surfels). Objects of any kind may also provide ``bounds()`` (2,3) and
``positions`` or ``vertices`` (N,3), read by :func:`unmesh.render.scene_bounds` and
:func:`unmesh.render.scene_points`, and ``attributes`` for ``color_by``.

Example
-------
>>> import numpy as np
>>> from unmesh.render import Camera, render
>>> class Backdrop:  # an opaque quad filling the screen at depth 10
...     def bounds(self):
...         return np.zeros((2, 3))
>>> def draw_backdrop(gbuffer, objects, context):
...     nearer = gbuffer.depth > 10.0
...     gbuffer.depth[nearer], gbuffer.coverage[nearer], gbuffer.weight[nearer] = 10.0, True, 1.0
...     gbuffer.albedo[nearer], gbuffer.normal[nearer] = (0.0, 0.0, 1.0), (0.0, 0.0, 1.0)
>>> kind = register_drawable("backdrop", Backdrop, draw_backdrop, stage="opaque", order=50)
>>> res = render(Backdrop(), Camera((0, 0, 3), (0, 0, 0), width=4, height=4), shading="none")
>>> res.color[0, 0].tolist(), float(res.depth[0, 0])
([0.0, 0.0, 1.0], 10.0)
>>> unregister_drawable("backdrop") is kind
True
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.render.camera import Camera
from unmesh.render.options import RenderOptions
from unmesh.render.shading import GBuffer
from unmesh.render.splat import ClipSurfels

__all__ = [
    "STAGES",
    "DrawContext",
    "DrawableKind",
    "draw_order",
    "drawable_kind",
    "drawable_kinds",
    "register_drawable",
    "unregister_drawable",
]

#: The stages of a render, in the order they are drawn.
STAGES = ("opaque", "splat")

DrawFunction = Callable[[GBuffer, Sequence[Any], "DrawContext"], "GBuffer | None"]


@dataclass(frozen=True, eq=False)
class DrawContext:
    """What a draw function may read besides the G-buffer and its objects.

    Attributes
    ----------
    camera : Camera
    options : RenderOptions
    colors : mapping id(object) -> array
        Colour overrides of ``color_by`` (per surfel, vertex or particle) for the objects that
        have the attribute; see :meth:`colors_for`.
    clip_surfels : ClipSurfels or None
        The discontinuity surfels of the scene (4.3), for clipped splatting (chapter 4).
    """

    camera: Camera
    options: RenderOptions
    colors: Mapping[int, np.ndarray] = field(default_factory=dict)
    clip_surfels: ClipSurfels | None = None

    def colors_for(self, obj: Any) -> np.ndarray | None:
        """The ``color_by`` colours of ``obj``, or None when it keeps its own."""
        return self.colors.get(id(obj))


@dataclass(frozen=True, eq=False)
class DrawableKind:
    """One entry of the drawable table (see :func:`register_drawable`).

    Attributes
    ----------
    name : str
    accepts : type, tuple of types, or callable
        ``isinstance`` test, or a predicate ``accepts(obj) -> bool``.
    draw : callable
        ``draw(gbuffer, objects, context) -> GBuffer | None``.
    stage : {"opaque", "splat"}
    order : float
        Place within the stage (lower first; equal orders draw in registration order).
    prepare : callable, optional
        ``prepare(obj) -> obj`` applied when the object is collected (e.g. surfel clouds keep
        their surface samples, :meth:`SurfelCloud.visible`).
    clip : callable, optional
        ``clip(obj) -> SurfelCloud | None``: the discontinuity surfels (4.3) the object adds to
        the clip information of the splatter (:attr:`DrawContext.clip_surfels`).
    """

    name: str
    accepts: type | tuple[type, ...] | Callable[[Any], bool]
    draw: DrawFunction
    stage: str = "opaque"
    order: float = 0.0
    prepare: Callable[[Any], Any] | None = None
    clip: Callable[[Any], Any] | None = None

    def matches(self, obj: Any) -> bool:
        """Whether ``obj`` is of this kind."""
        if isinstance(self.accepts, type | tuple):
            return isinstance(obj, self.accepts)
        return bool(self.accepts(obj))


_KINDS: dict[str, DrawableKind] = {}


def register_drawable(name: str, accepts: type | tuple[type, ...] | Callable[[Any], bool], draw: DrawFunction, *,
                      stage: str = "opaque", order: float = 0.0, prepare: Callable[[Any], Any] | None = None,
                      clip: Callable[[Any], Any] | None = None, replace: bool = False) -> DrawableKind:
    """Add a kind of drawable object to :func:`unmesh.render.render`.

    Parameters
    ----------
    name : str
        Unique name of the kind (also the key of :attr:`unmesh.render.DrawList.groups`).
    accepts : type, tuple of types, or callable
        Objects of these types (or for which the predicate is true) are of this kind. Kinds are
        tried in registration order; the first that accepts an object takes it.
    draw : callable
        ``draw(gbuffer, objects, context)`` draws the kind's objects (a non-empty list, in the
        order given) into ``gbuffer``; it may return a new :class:`GBuffer` that replaces it.
    stage : {"opaque", "splat"}
        ``"opaque"`` kinds are z-buffered into the G-buffer first; ``"splat"`` kinds afterwards,
        against the opaque depth.
    order : float
        Place within the stage (built-ins: meshes 0, particles 10; surfels 0 in ``"splat"``).
    prepare : callable, optional
        Applied to every object of the kind when it is collected.
    clip : callable, optional
        ``clip(obj) -> SurfelCloud | None``: discontinuity surfels the object contributes as clip
        information for the splatter (chapter 4); they are not drawn.
    replace : bool
        Allow replacing an existing kind of the same name.

    Returns
    -------
    DrawableKind

    Raises
    ------
    unmesh.errors.InputError
        On an unknown stage, a non-callable ``draw``, or a name already registered.
    """
    if not isinstance(name, str) or not name:
        raise InputError(f"name: expected a non-empty string, got {name!r}")
    if stage not in STAGES:
        raise InputError(f"stage: expected one of {', '.join(STAGES)}, got {stage!r}")
    if not callable(draw):
        raise InputError(f"draw: expected a callable, got {type(draw).__name__}")
    if not (isinstance(accepts, type | tuple) or callable(accepts)):
        raise InputError(f"accepts: expected a type, a tuple of types or a predicate, got {type(accepts).__name__}")
    for hook_name, hook in (("prepare", prepare), ("clip", clip)):
        if hook is not None and not callable(hook):
            raise InputError(f"{hook_name}: expected a callable, got {type(hook).__name__}")
    if name in _KINDS and not replace:
        raise InputError(f"name: drawable kind {name!r} is already registered (pass replace=True to replace it)")
    kind = DrawableKind(name, accepts, draw, stage, float(order), prepare, clip)
    _KINDS[name] = kind
    return kind


def unregister_drawable(name: str) -> DrawableKind:
    """Remove a registered kind; returns it."""
    try:
        return _KINDS.pop(name)
    except KeyError:
        raise InputError(f"name: no drawable kind {name!r}; registered: {', '.join(_KINDS)}") from None


def drawable_kinds() -> tuple[DrawableKind, ...]:
    """The registered kinds in registration order."""
    return tuple(_KINDS.values())


def drawable_kind(obj: Any) -> DrawableKind | None:
    """The first registered kind that accepts ``obj``, or None."""
    for kind in _KINDS.values():
        if kind.matches(obj):
            return kind
    return None


def draw_order() -> tuple[DrawableKind, ...]:
    """The registered kinds in drawing order: by stage, then ``order``, then registration."""
    kinds = list(_KINDS.values())
    return tuple(sorted(kinds, key=lambda k: (STAGES.index(k.stage), k.order, kinds.index(k))))
