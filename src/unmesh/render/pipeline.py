"""``render``: one call that draws any mix of surfel clouds, triangle meshes and particles.

Order of work: opaque geometry first (meshes by z-buffered rasterisation, particles as ray-cast
spheres) into a G-buffer; then surfels, either EWA-splatted with the opaque depth as the initial
visibility buffer (so meshes and particles occlude splats per fragment) or MLS ray-cast with a
depth test; then deferred shading; then the colour-bar legend.

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

import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.particles import Particles
from unmesh.render.camera import Camera
from unmesh.render.colormap import attribute_values, draw_legend, map_colors, value_range
from unmesh.render.particles import draw_particles
from unmesh.render.raster import draw_meshes
from unmesh.render.shading import GBuffer, Light, Shading, as_shading, background_color, shade
from unmesh.render.splat import SplatOptions, SplatRenderer, surfel_arrays
from unmesh.surfels import SurfelCloud

__all__ = ["METHODS", "RenderResult", "Scene", "collect", "render", "scene_bounds", "scene_points"]

#: Surfel rendering methods.
METHODS = ("splat", "raycast")
Renderable = SurfelCloud | TriangleMesh | Particles


@dataclass
class Scene:
    """Objects of one frame sorted by kind (see :func:`collect`)."""

    clouds: list[SurfelCloud] = field(default_factory=list)
    meshes: list[TriangleMesh] = field(default_factory=list)
    particles: list[Particles] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.clouds) + len(self.meshes) + len(self.particles)

    def all(self) -> list[Any]:
        """Every object, clouds first."""
        return [*self.clouds, *self.meshes, *self.particles]


def _surface_samples(cloud: SurfelCloud) -> SurfelCloud:
    """``cloud`` without its discontinuity surfels (attribute ``discontinuity`` == 1).

    Thin-shell frames (thesis 7.4) carry pairs of such surfels along every crack; they mark the
    crack edge for clipped splatting (section 4.3) and are not samples of the surface, so they are
    not splatted.
    """
    flag = cloud.attributes.get("discontinuity")
    if flag is None:
        return cloud
    keep = np.asarray(flag) == 0
    return cloud if keep.all() else cloud.subset(keep)


def collect(objects: Renderable | Iterable[Any] | None) -> Scene:
    """Sort a renderable or a (nested) list of them into a :class:`Scene`.

    Surfels flagged by a ``discontinuity`` attribute equal to 1 are left out (crack-edge markers
    of the thin-shell simulation, not surface samples).

    Example
    -------
    >>> s = collect([SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]), [Particles([[1, 1, 1]])]])
    >>> len(s.clouds), len(s.particles)
    (1, 1)
    """
    scene = Scene()

    def add(obj: Any, where: str) -> None:
        if isinstance(obj, SurfelCloud):
            scene.clouds.append(_surface_samples(obj))
        elif isinstance(obj, TriangleMesh):
            scene.meshes.append(obj)
        elif isinstance(obj, Particles):
            scene.particles.append(obj)
        elif isinstance(obj, Scene):
            for k, o in enumerate(obj.all()):
                add(o, f"{where}[{k}]")
        elif isinstance(obj, list | tuple):
            for k, o in enumerate(obj):
                add(o, f"{where}[{k}]")
        else:
            raise InputError(f"{where}: expected a SurfelCloud, TriangleMesh, Particles or a list of them, got {type(obj).__name__}")

    if objects is not None:
        add(objects, "objects")
    return scene


def scene_bounds(objects: Any) -> np.ndarray:
    """Axis-aligned bounds (2,3) of all objects (surfel and particle radii included);
    ``[inf, -inf]`` when empty.

    Example
    -------
    >>> scene_bounds(Particles([[0, 0, 0], [1, 2, 3]])).tolist()
    [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]
    """
    scene = objects if isinstance(objects, Scene) else collect(objects)
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for obj in scene.all():
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
    scene = objects if isinstance(objects, Scene) else collect(objects)
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


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered image and its buffers, in the conventions of :mod:`unmesh.render.camera`.

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

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write :attr:`color` as an image file (atomic); returns the path.

        Example
        -------
        >>> import tempfile, pathlib
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


def _object_colors(scene: Scene, color_by: str | None, cmap: str, color_range: Sequence[float] | None
                   ) -> tuple[dict[int, np.ndarray], tuple[float, float] | None]:
    """Colour overrides per object id for ``color_by`` and the range used."""
    if color_by is None:
        return {}, None
    values: dict[int, np.ndarray] = {}
    errors = []
    for obj in scene.all():
        try:
            values[id(obj)] = attribute_values(obj, color_by)
        except InputError as exc:
            errors.append(str(exc))
    if not values:
        if errors:
            raise InputError(errors[0])
        return {}, None
    lo, hi = value_range(list(values.values()), color_range)
    return {k: map_colors(v, lo, hi, cmap) for k, v in values.items()}, (lo, hi)


def _downsample(hi: RenderResult, camera: Camera, k: int, legend: bool, cmap: str, label: str | None) -> RenderResult:
    """Average ``k x k`` blocks of a supersampled result (see ``render(supersample=k)``)."""
    h, w = camera.shape

    def blocks(a: np.ndarray) -> np.ndarray:
        return a.reshape(h, k, w, k, *a.shape[2:])

    cov = blocks(hi.coverage)
    coverage = cov.any(axis=(1, 3))
    color = blocks(hi.color).mean(axis=(1, 3))
    if legend and hi.color_range is not None:
        color = draw_legend(color, hi.color_range[0], hi.color_range[1], cmap, label=label or "")
    depth = blocks(np.where(hi.coverage, hi.depth, np.inf)).min(axis=(1, 3))
    nsum = blocks(hi.normal).sum(axis=(1, 3))
    length = np.linalg.norm(nsum, axis=-1, keepdims=True)
    normal = np.divide(nsum, length, out=np.zeros_like(nsum), where=length > 0)
    return RenderResult(color=color, depth=depth, normal=normal, coverage=coverage,
                        weight=blocks(hi.weight).mean(axis=(1, 3)), albedo=blocks(hi.albedo).mean(axis=(1, 3)),
                        camera=camera, color_range=hi.color_range)


def render(
    objects: Renderable | Iterable[Any] | None,
    camera: Camera,
    method: str = "splat",
    shading: str | Shading = "phong",
    *,
    background: Any = (1.0, 1.0, 1.0),
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
    """Render surfel clouds, triangle meshes and particles with one camera.

    Parameters
    ----------
    objects : SurfelCloud, TriangleMesh, Particles, or a (nested) list of them
        An empty list renders the background.
    camera : Camera
    method : {"splat", "raycast"}
        Surfels by EWA splatting (3.2) or by ray casting their MLS surface (3.1.3).
    shading : {"phong", "none"} or Shading
        Deferred two-sided Blinn-Phong with ``lights`` (default: a key light from the upper left
        front plus ambient), or the unlit colour.
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
    k = int(supersample)
    if k != supersample or k < 1 or k > 16:
        raise InputError(f"supersample: expected an integer in [1, 16], got {supersample!r}")
    if k > 1:
        hi = render(objects, camera.resized(camera.width * k, camera.height * k), method, shading,
                    background=background, lights=lights, color_by=color_by, colormap=colormap,
                    color_range=color_range, legend=False, splat=splat, particle_radius=particle_radius,
                    particle_style=particle_style, particle_radii=particle_radii, mls=mls, progress=progress)
        return _downsample(hi, camera, k, legend if legend is not None else color_by is not None, colormap, color_by)
    if method not in METHODS:
        raise InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    sh = as_shading(shading, lights)
    bg = background_color(background)
    scene = collect(objects)
    overrides, crange = _object_colors(scene, color_by, colormap, color_range)
    h, w = camera.shape
    opts = splat if splat is not None else SplatOptions()
    gbuf = GBuffer.empty(h, w)
    if scene.meshes:
        draw_meshes(gbuf, scene.meshes, camera, [overrides.get(id(m)) for m in scene.meshes])
    if scene.particles:
        radii_map = particle_radii or {}
        draw_particles(gbuf, scene.particles, camera, [overrides.get(id(p)) for p in scene.particles],
                       radius=particle_radius, style=particle_style, filter_radius=max(opts.filter_radius, 0.71),
                       radii=[radii_map.get(id(p)) for p in scene.particles])
    clouds = [c for c in scene.clouds if len(c)]
    if clouds:
        colors = None
        if any(id(c) in overrides for c in clouds):
            colors = np.concatenate([overrides.get(id(c), np.asarray(c.colors)) for c in clouds])
        if method == "splat":
            renderer = SplatRenderer(camera, opts)
            renderer.render(surfel_arrays(clouds, colors), opaque=gbuf)
            gbuf = renderer.gbuffer()
        else:
            from unmesh.render.raycast import draw_mls

            draw_mls(gbuf, clouds, camera, colors=colors, mls_options=mls, progress=progress)
    color = shade(gbuf, camera, sh, bg)
    show_legend = (color_by is not None) if legend is None else bool(legend)
    if show_legend and crange is not None:
        color = draw_legend(color, crange[0], crange[1], colormap, label=color_by or "")
    normal = np.where(gbuf.coverage[..., None], gbuf.normal, 0.0)
    depth = np.where(gbuf.coverage, gbuf.depth, np.inf)
    return RenderResult(color=color, depth=depth, normal=normal, coverage=gbuf.coverage.copy(),
                        weight=np.where(gbuf.coverage, gbuf.weight, 0.0), albedo=gbuf.albedo, camera=camera,
                        color_range=crange)
