"""``render``: one call that draws any mix of surfel clouds, triangle meshes, particles and
every other registered kind of drawable object (:mod:`unmesh.render.drawables`).

Order of work: the objects are sorted into a :class:`DrawList` by kind (:func:`collect`); the
``"opaque"`` kinds (meshes by z-buffered rasterisation, particles as ray-cast spheres) are drawn
into a G-buffer; then the ``"splat"`` kinds: surfels, either EWA-splatted with the opaque depth as
the initial visibility buffer (so meshes and particles occlude splats per fragment) or MLS
ray-cast with a depth test; then deferred shading; then the colour-bar legend. Every option
travels in one :class:`~unmesh.render.options.RenderOptions`.

Discontinuity surfels (attribute ``discontinuity`` != 0, thesis 4.3, see
:mod:`unmesh.surfels.cloud`) are not surface samples: :func:`collect` separates them from their
clouds into :attr:`DrawList.clip`, and the splatter receives them as
:class:`~unmesh.render.splat.ClipSurfels` beside :class:`~unmesh.render.splat.ClipPlanes`, the
splatter's clipped splatting: geometry discontinuity surfels cut clean edges, texture ones
clip the colour only (a second splatting pass whose albedo replaces the first's). They are
never drawn.

Example
-------
>>> import numpy as np
>>> from unmesh import SurfelCloud
>>> from unmesh.render import Camera
>>> cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5], colors=[[1, 0, 0]])
>>> res = render(cloud, Camera((0, 0, 3), (0, 0, 0), width=32, height=32, ortho=2.0), shading="none")
>>> res.color[16, 16].tolist(), res.color[0, 0].tolist()
([1.0, 0.0, 0.0], [1.0, 1.0, 1.0])
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.particles import Particles
from unmesh.render.camera import Camera
from unmesh.render.colormap import attribute_values, draw_legend, map_colors, value_range
from unmesh.render.context import draw_opaque, draw_translucent, is_opaque_context, is_translucent_context
from unmesh.render.drawables import DrawContext, draw_order, drawable_kind, drawable_kinds, register_drawable
from unmesh.render.options import DEFAULT_BACKGROUND, METHODS, RenderOptions
from unmesh.render.particles import draw_particles
from unmesh.render.raster import draw_meshes
from unmesh.render.shading import GBuffer, Light, RenderResult, Shading, shade
from unmesh.render.splat import ClipSurfels, SplatOptions, SplatRenderer, discontinuity_clip, surfel_arrays
from unmesh.surfels import SurfelCloud
from unmesh.surfels.cloud import DISCONTINUITY_ATTRIBUTE, SURFACE, TEXTURE_DISCONTINUITY

__all__ = ["METHODS", "DrawList", "RenderResult", "collect", "render", "scene_bounds", "scene_points"]

Renderable = SurfelCloud | TriangleMesh | Particles


@dataclass
class DrawList:
    """The objects of one frame sorted by drawable kind (see :func:`collect`).

    Attributes
    ----------
    groups : dict of str to list
        Objects per kind name (:mod:`unmesh.render.drawables`), each list in the order given.
        Surfel clouds hold their surface samples only (:meth:`SurfelCloud.visible`).
    clip : list of SurfelCloud
        The discontinuity surfels separated from the clouds (4.3): clip information for the
        splatter (:meth:`clip_surfels`), never drawn.

    Example
    -------
    >>> d = collect([SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]] * 2, radii=[1.0, 1.0],
    ...                          attributes={"discontinuity": [0, 1]})])
    >>> len(d.clouds[0]), len(d.clip[0]), len(d)
    (1, 1, 1)
    """

    groups: dict[str, list[Any]] = field(default_factory=dict)
    clip: list[SurfelCloud] = field(default_factory=list)

    def of_kind(self, name: str) -> list[Any]:
        """The (mutable) list of objects of kind ``name``."""
        return self.groups.setdefault(name, [])

    @property
    def clouds(self) -> list[SurfelCloud]:
        """Surfel clouds (kind ``"surfels"``)."""
        return self.of_kind("surfels")

    @property
    def meshes(self) -> list[TriangleMesh]:
        """Triangle meshes (kind ``"meshes"``)."""
        return self.of_kind("meshes")

    @property
    def particles(self) -> list[Particles]:
        """Particle sets (kind ``"particles"``)."""
        return self.of_kind("particles")

    def __len__(self) -> int:
        return sum(len(v) for v in self.groups.values())

    def _names(self) -> Iterator[str]:
        known = [k.name for k in drawable_kinds()]
        yield from (n for n in known if n in self.groups)
        yield from (n for n in self.groups if n not in known)

    def all(self) -> list[Any]:
        """Every object, kind by kind in registration order (clouds, meshes, particles first)."""
        return [obj for name in self._names() for obj in self.groups[name]]

    def clip_surfels(self) -> ClipSurfels | None:
        """The discontinuity surfels as :class:`ClipSurfels`, or None when there are none."""
        clip = [c for c in self.clip if len(c)]
        return ClipSurfels.from_clouds(clip) if clip else None


def collect(objects: Renderable | Iterable[Any] | None) -> DrawList:
    """Sort a drawable object or a (nested) list of them into a :class:`DrawList`.

    Each object goes to the first registered kind that accepts it
    (:func:`~unmesh.render.drawables.register_drawable`); lists, tuples and draw lists are
    flattened. The discontinuity surfels of surfel clouds (attribute ``discontinuity`` != 0,
    4.3) go to :attr:`DrawList.clip` instead of being drawn.

    Example
    -------
    >>> s = collect([SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]), [Particles([[1, 1, 1]])]])
    >>> len(s.clouds), len(s.particles)
    (1, 1)
    """
    out = DrawList()

    def add(obj: Any, where: str) -> None:
        if isinstance(obj, DrawList):
            for k, o in enumerate(obj.all()):
                add(o, f"{where}[{k}]")
            out.clip.extend(obj.clip)
            return
        if isinstance(obj, list | tuple):
            for k, o in enumerate(obj):
                add(o, f"{where}[{k}]")
            return
        kind = drawable_kind(obj)
        if kind is not None:
            if kind.clip is not None:
                clip = kind.clip(obj)
                if clip is not None:
                    out.clip.append(clip)
            out.of_kind(kind.name).append(kind.prepare(obj) if kind.prepare is not None else obj)
        else:
            names = ", ".join(k.name for k in drawable_kinds())
            raise InputError(f"{where}: expected a SurfelCloud, TriangleMesh, Particles (or another registered "
                             f"drawable kind: {names}) or a list of them, got {type(obj).__name__}")

    if objects is not None:
        add(objects, "objects")
    return out


def __getattr__(name: str) -> Any:
    if name == "Scene":
        warnings.warn("unmesh.render.pipeline.Scene is deprecated; use unmesh.render.DrawList", DeprecationWarning,
                      stacklevel=2)
        return DrawList
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def scene_bounds(objects: Any) -> np.ndarray:
    """Axis-aligned bounds (2,3) of all objects (surfel and particle radii included);
    ``[inf, -inf]`` when empty.

    Example
    -------
    >>> scene_bounds(Particles([[0, 0, 0], [1, 2, 3]])).tolist()
    [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]
    """
    scene = objects if isinstance(objects, DrawList) else collect(objects)
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for obj in scene.all():
        if not callable(getattr(obj, "bounds", None)):  # a registered kind without bounds
            continue
        b = np.asarray(obj.bounds(), dtype=np.float64)
        if not np.all(np.isfinite(b)):
            continue
        pad = 0.0
        radii = getattr(obj, "radii", None)
        if radii is not None and len(radii):
            pad = float(np.max(radii))
        lo = np.minimum(lo, b[0] - pad)
        hi = np.maximum(hi, b[1] + pad)
    return np.stack([lo, hi])


def scene_points(objects: Any, max_points: int = 20000) -> np.ndarray:
    """A subsample (M,3) of the scene's points (surfel and particle centres padded by their
    radius along the axes in which the data is not flat, mesh vertices), for :meth:`Camera.fit`.

    Example
    -------
    >>> scene_points(Particles([[0, 0, 0], [1, 1, 0]], radii=[0.5, 0.5])).max(axis=0).tolist()
    [1.5, 1.5, 0.0]
    """
    scene = objects if isinstance(objects, DrawList) else collect(objects)
    items = [o for o in scene.all() if len(getattr(o, "positions", getattr(o, "vertices", ())))]
    if not items:
        return np.zeros((0, 3))
    per = max(1, max_points // (7 * len(items)))
    out = []
    for obj in items:
        pts = obj.vertices[np.unique(obj.faces)] if isinstance(obj, TriangleMesh) and len(obj.faces) else \
            getattr(obj, "positions", getattr(obj, "vertices", None))
        pts = np.asarray(pts)
        step = max(1, len(pts) // per)
        sub = pts[::step]
        radii = getattr(obj, "radii", None)
        if radii is None and isinstance(obj, Particles):
            from unmesh.render.particles import estimate_radius

            pad = estimate_radius(pts)
        else:
            pad = float(np.max(radii)) if radii is not None and len(radii) else 0.0
        out.append(sub)
        ext = np.ptp(pts, axis=0) if len(pts) else np.zeros(3)
        if pad > 0:
            for axis in range(3):
                if ext[axis] <= 1e-6 * ext.max():  # flat (2D) data stays flat: framed head-on
                    continue
                for sign in (-1.0, 1.0):
                    shifted = sub.copy()
                    shifted[:, axis] += sign * pad
                    out.append(shifted)
    return np.concatenate(out)


def _object_colors(scene: DrawList, options: RenderOptions) -> tuple[dict[int, np.ndarray], tuple[float, float] | None]:
    """Colour overrides per object id for ``color_by`` and the range used."""
    copt = options.color
    if copt.by is None:
        return {}, None
    values: dict[int, np.ndarray] = {}
    errors = []
    for obj in scene.all():
        try:
            values[id(obj)] = attribute_values(obj, copt.by)
        except InputError as exc:
            errors.append(str(exc))
    if not values:
        if errors:
            raise InputError(errors[0])
        return {}, None
    lo, hi = value_range(list(values.values()), copt.range)
    return {k: map_colors(v, lo, hi, copt.colormap) for k, v in values.items()}, (lo, hi)


def _with_legend(color: np.ndarray, options: RenderOptions, crange: tuple[float, float] | None) -> np.ndarray:
    """``color`` with the colour bar of ``color_by`` when it is shown."""
    copt = options.color
    if copt.show_legend and crange is not None:
        return draw_legend(color, crange[0], crange[1], copt.colormap, label=copt.by or "")
    return color


def _downsample(hi: RenderResult, camera: Camera, k: int, options: RenderOptions) -> RenderResult:
    """Average ``k x k`` blocks of a supersampled result (see ``render(supersample=k)``)."""
    h, w = camera.shape

    def blocks(a: np.ndarray) -> np.ndarray:
        return a.reshape(h, k, w, k, *a.shape[2:])

    coverage = blocks(hi.coverage).any(axis=(1, 3))
    color = _with_legend(blocks(hi.color).mean(axis=(1, 3)), options, hi.color_range)
    depth = blocks(np.where(hi.coverage, hi.depth, np.inf)).min(axis=(1, 3))
    nsum = blocks(hi.normal).sum(axis=(1, 3))
    length = np.linalg.norm(nsum, axis=-1, keepdims=True)
    normal = np.divide(nsum, length, out=np.zeros_like(nsum), where=length > 0)
    gbuf = GBuffer(albedo=blocks(hi.albedo).mean(axis=(1, 3)), normal=normal, depth=depth, coverage=coverage,
                   weight=blocks(hi.weight).mean(axis=(1, 3)))
    return RenderResult.from_gbuffer(gbuf, camera, color, hi.color_range)


# -- the built-in drawable kinds ------------------------------------------------------------------
def _draw_meshes(gbuffer: GBuffer, meshes: Sequence[TriangleMesh], context: DrawContext) -> None:
    draw_meshes(gbuffer, meshes, context.camera, [context.colors_for(m) for m in meshes])


def _draw_particles(gbuffer: GBuffer, particles: Sequence[Particles], context: DrawContext) -> None:
    popt = context.options.particles
    radii = popt.radii or {}
    draw_particles(gbuffer, particles, context.camera, [context.colors_for(p) for p in particles],
                   radius=popt.radius, style=popt.style, filter_radius=max(context.options.splat.filter_radius, 0.71),
                   radii=[radii.get(id(p)) for p in particles])


def _draw_surfels(gbuffer: GBuffer, clouds: Sequence[SurfelCloud], context: DrawContext) -> GBuffer | None:
    """EWA splatting against the opaque G-buffer (3.2), or MLS ray casting (3.1.3)."""
    clouds = [c for c in clouds if len(c)]
    if not clouds:
        return None
    opts = context.options
    own = [context.colors.get(id(c)) for c in clouds]
    if opts.method == "splat" and opts.splat.cull_backfaces:
        keep = [_front_facing(c, context.camera) for c in clouds]
        own = [None if o is None else np.asarray(o)[k] for o, k in zip(own, keep, strict=True)]
        clouds = [c.subset(k) for c, k in zip(clouds, keep, strict=True)]
        own = [o for o, c in zip(own, clouds, strict=True) if len(c)]
        clouds = [c for c in clouds if len(c)]
        if not clouds:
            return None
    colors = None
    if any(o is not None for o in own):
        colors = np.concatenate([np.asarray(c.colors) if o is None else o for c, o in zip(clouds, own, strict=True)])
    if opts.method == "splat":
        arrays = surfel_arrays(clouds, colors)
        clip = context.clip_surfels
        texture = None
        if clip is not None and (clip.kind == TEXTURE_DISCONTINUITY).any():
            # texture discontinuities (4.3, Fig. 4.6) clip the colour only: the colour is the
            # normalised sum over the fragments they keep, normals and depth blend over all
            texture = discontinuity_clip(arrays, clip, TEXTURE_DISCONTINUITY)
        if texture is None:
            renderer = SplatRenderer(context.camera, opts.splat)
            return renderer._render_in_place(arrays, gbuffer, clip_surfels=clip)
        renderer = SplatRenderer(context.camera, opts.splat)
        out = renderer._render_in_place(arrays, gbuffer, clip_surfels=clip)
        colour = SplatRenderer(context.camera, opts.splat)
        colour.zvis = renderer.zvis  # the same visible fragments, read only (a partial update, 5.7)
        coloured = colour.splat(arrays, clip=texture).gbuffer()
        both = coloured.coverage & (coloured.weight > 0) & out.coverage
        out.albedo[both] = coloured.albedo[both]
        return out
    from unmesh.render.raycast import draw_mls

    draw_mls(gbuffer, clouds, context.camera, colors=colors, mls_options=opts.mls, progress=opts.progress)
    return None


def _front_facing(cloud: SurfelCloud, camera: Camera) -> np.ndarray:
    """Mask (N,) of the surfels whose normal faces the camera (``n . (eye - x) > 0``)."""
    return camera.facing(cloud.positions, cloud.normals)


def _discontinuities(cloud: SurfelCloud) -> SurfelCloud | None:
    """The discontinuity surfels of ``cloud`` (4.3), or None."""
    if DISCONTINUITY_ATTRIBUTE not in cloud.attributes:
        return None
    clip = cloud.surfel_kinds() != SURFACE
    return cloud.subset(clip) if clip.any() else None


register_drawable("surfels", SurfelCloud, _draw_surfels, stage="splat", order=0, prepare=SurfelCloud.visible,
                  clip=_discontinuities)
register_drawable("meshes", TriangleMesh, _draw_meshes, stage="opaque", order=0)
register_drawable("particles", Particles, _draw_particles, stage="opaque", order=10)
register_drawable("context", is_opaque_context, draw_opaque, stage="opaque", order=20)
register_drawable("translucent", is_translucent_context, draw_translucent, stage="splat", order=100)


# -- render ---------------------------------------------------------------------------------------
#: The keywords of :func:`render` that :meth:`RenderOptions.from_keywords` folds, with their defaults.
_KEYWORD_DEFAULTS: dict[str, Any] = {name: p.default for name, p in
                                     inspect.signature(RenderOptions.from_keywords).parameters.items()}


def _is_default(value: Any, default: Any) -> bool:
    if value is default:
        return True
    if isinstance(default, str | bool | int | tuple) and type(value) is type(default):
        return bool(value == default)
    return False


def render(
    objects: Renderable | Iterable[Any] | None,
    camera: Camera,
    method: str = "splat",
    shading: str | Shading = "phong",
    *,
    options: RenderOptions | None = None,
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
) -> RenderResult:
    """Render surfel clouds, triangle meshes, particles (and registered kinds) with one camera.

    The keywords are folded once into a :class:`~unmesh.render.options.RenderOptions`
    (:meth:`~unmesh.render.options.RenderOptions.from_keywords`); or pass that object as
    ``options`` (then leave the other keywords out).

    Parameters
    ----------
    objects : SurfelCloud, TriangleMesh, Particles, a registered drawable, or a (nested) list of them
        An empty list renders the background. Discontinuity surfels (4.3) are not drawn.
    camera : Camera
    method : {"splat", "raycast"}
        Surfels by EWA splatting (3.2) or by ray casting their MLS surface (3.1.3).
    shading : {"phong", "none"} or Shading
        Deferred two-sided Blinn-Phong with ``lights`` (default: a key light from the upper left
        front plus ambient), or the unlit colour.
    options : RenderOptions, optional
        All options in one object (instead of the keywords).
    background : colour
        RGB triple, grey level or ``"#rrggbb"``.
    lights : sequence of Light, optional
    color_by : str, optional
        Attribute shown through ``colormap`` on every object that has it (vectors by length;
        also ``x``, ``y``, ``z``, ``radius``). Objects without it keep their colour.
    colormap : str
        See :data:`unmesh.render.colormap.COLORMAPS`.
    color_range : (lo, hi), optional
        Fixed range (default: min and max over the scene).
    legend : bool, optional
        Draw a colour bar (default: when ``color_by`` is given).
    splat : SplatOptions, optional
    particle_radius : float, optional
        Drawing radius for all particles (default: stored radii or half the median spacing).
    particle_style : {"sphere", "disc"}
    particle_radii : mapping id(Particles) -> (N,) array, optional
        Precomputed radii (used by sequences to keep sizes fixed over frames).
    mls : mapping, optional
        Options for ray casting (:func:`unmesh.render.raycast.draw_mls`).
    supersample : int
        Anti-aliasing: render ``k x k`` samples per pixel and average them (``.color``,
        ``.albedo``, ``.weight``); ``.coverage`` is any sample covered, ``.depth`` the nearest
        sample, ``.normal`` the normalised mean over covered samples. 1 (default) is exact.
    progress : bool
        Progress bar for ray casting.

    Returns
    -------
    RenderResult
        ``.color`` (H,W,3) in [0,1], ``.depth`` (H,W) camera z (``inf`` = background),
        ``.normal`` (H,W,3) world (zeros in background), ``.coverage`` (H,W) bool, ``.weight``.

    Example
    -------
    >>> from unmesh import Particles
    >>> res = render([Particles([[0, 0, 0]], radii=[0.4])], Camera((0, 0, 2), (0, 0, 0), width=16, height=16))
    >>> res.coverage.sum() > 0, bool(np.isinf(res.depth[0, 0]))
    (np.True_, True)
    """
    if not isinstance(camera, Camera):
        raise InputError(f"camera: expected a Camera, got {type(camera).__name__}")
    keywords = {"method": method, "shading": shading, "background": background, "lights": lights,
                "color_by": color_by, "colormap": colormap, "color_range": color_range, "legend": legend,
                "splat": splat, "particle_radius": particle_radius, "particle_style": particle_style,
                "particle_radii": particle_radii, "mls": mls, "supersample": supersample, "progress": progress}
    if options is None:
        options = RenderOptions.from_keywords(**keywords)
    else:
        if not isinstance(options, RenderOptions):
            raise InputError(f"options: expected RenderOptions, got {type(options).__name__}")
        given = [k for k, v in keywords.items() if not _is_default(v, _KEYWORD_DEFAULTS[k])]
        if given:
            raise InputError(f"options: expected either a RenderOptions or keywords, got both (keywords: {', '.join(given)})")
    k = options.supersample
    if k > 1:
        hi = render(objects, camera.resized(camera.width * k, camera.height * k), options=options.single_sample())
        return _downsample(hi, camera, k, options)
    scene = collect(objects)
    overrides, crange = _object_colors(scene, options)
    h, w = camera.shape
    context = DrawContext(camera, options, overrides, scene.clip_surfels())
    gbuf = GBuffer.empty(h, w)
    for kind in draw_order():
        items = scene.groups.get(kind.name)
        if items:
            drawn = kind.draw(gbuf, items, context)
            if drawn is not None:
                # render() owns gbuf (the splatter and from_gbuffer write into it in place): a
                # buffer returned by a registered kind is copied, the splatter's own is not
                gbuf = drawn if kind.draw is _draw_surfels else drawn.copy()
    color = _with_legend(shade(gbuf, camera, options.shading, options.background_rgb), options, crange)
    return RenderResult.from_gbuffer(gbuf, camera, color, crange, copy=False)
