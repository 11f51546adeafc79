"""Context geometry: floors, boxes and polygons drawn around the objects of a scene.

A simulation image needs what the objects act against: the floor they bounce on (with a grid
and a soft contact shadow, so heights and impacts can be read), the walls of a tank, a blade,
a rod or a clamp. These are drawn exactly, by ray casting their analytic shapes per pixel, as
two drawable kinds of :func:`unmesh.render.render` (:mod:`unmesh.render.drawables`), registered
with the built-in kinds by :mod:`unmesh.render.pipeline`:

``"context"`` (stage ``"opaque"``, order 20)
    Objects with ``opacity == 1``: z-buffered like meshes, so they occlude and are occluded
    per pixel.
``"translucent"`` (stage ``"splat"``, order 100)
    Objects with ``opacity < 1``, composited over the finished G-buffer after every other kind:
    where the object is nearer than what was drawn, the albedo becomes
    ``(1 - opacity) * albedo + opacity * color`` (over the background where nothing was
    drawn); the normals and depths of the surfaces behind are kept, so they stay shaded as
    before. Edges are drawn darker (``edge`` pixels wide), so a glass wall reads as a wall.

Context objects have no ``bounds()`` or points: :meth:`Camera.fit` and
:func:`~unmesh.render.scene_points` frame the objects, not their surroundings.

Example
-------
>>> import numpy as np
>>> from unmesh.render import Camera, render
>>> cam = Camera((0, 2, 4), (0, 0, 0), width=32, height=24, fov=40)
>>> res = render([Floor(grid=None), Box((-0.5, 0, -0.5), (0.5, 1, 0.5), color=(1, 0, 0))], cam, shading="none")
>>> res.color[12, 16].tolist(), res.coverage[23, 2]
([1.0, 0.0, 0.0], np.True_)
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from unmesh._validate import as_points
from unmesh.errors import InputError
from unmesh.render.camera import Camera
from unmesh.render.drawables import DrawContext
from unmesh.render.shading import GBuffer, background_color

__all__ = ["Box", "Floor", "Polygon", "context_hits", "draw_opaque", "draw_translucent", "is_opaque_context",
           "is_translucent_context", "open_box"]


def _rgb(value: Any, name: str) -> np.ndarray:
    c = np.asarray(value, dtype=np.float64).reshape(-1)
    if c.shape != (3,) or not np.all(np.isfinite(c)) or c.min() < 0 or c.max() > 1:
        raise InputError(f"{name}: expected an RGB triple in [0, 1], got {value!r}")
    return c


def _opacity(value: Any) -> float:
    a = float(value)
    if not 0.0 < a <= 1.0:
        raise InputError(f"opacity: expected a number in (0, 1], got {value!r}")
    return a


def _unit(value: Any, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    n = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not np.isfinite(n) or n == 0.0:
        raise InputError(f"{name}: expected a non-zero 3-vector, got {value!r}")
    return v / n


def _in_plane_axes(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(a, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


@dataclass(frozen=True, eq=False)
class Floor:
    """A square floor with an anti-aliased grid and a soft contact shadow.

    Parameters
    ----------
    point : (3,) float
        Centre of the square, on the floor plane.
    normal : (3,) float
        Up direction of the floor (default +y).
    extent : float
        Half the side of the square.
    color, grid_color : RGB in [0, 1]
    grid : float or None
        Spacing of the grid lines (world units, lines one pixel wide, faded out where they would
        be closer than 14 pixels); None draws no grid.
    casters : (N,3) float, optional
        Points that cast the contact shadow: each darkens the floor below it (along
        ``-normal``) in a Gaussian of width ``shadow_radius``, fading with its height over
        ``shadow_falloff``. Pass e.g. the positions of a frame.
    shadow_radius, shadow_falloff : float
        Default: 3 % and 20 % of ``extent``.
    shadow_strength : float
        Darkening in [0, 1] under a dense layer of casters touching the floor.
    opacity : float
        1 (default) draws it opaque.
    """

    point: Any = (0.0, 0.0, 0.0)
    normal: Any = (0.0, 1.0, 0.0)
    extent: float = 10.0
    color: Any = (0.86, 0.86, 0.84)
    grid: float | None = 0.5
    grid_color: Any = (0.62, 0.62, 0.62)
    casters: Any = None
    shadow_radius: float | None = None
    shadow_falloff: float | None = None
    shadow_strength: float = 0.55
    opacity: float = 1.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "point", as_points(np.reshape(np.asarray(self.point, dtype=np.float64), (1, 3)), "point")[0])
        set_(self, "normal", _unit(self.normal, "normal"))
        if not (np.isfinite(self.extent) and self.extent > 0):
            raise InputError(f"extent: expected a positive number, got {self.extent!r}")
        if self.grid is not None and not (np.isfinite(self.grid) and self.grid > 0):
            raise InputError(f"grid: expected a positive number or None, got {self.grid!r}")
        set_(self, "color", _rgb(self.color, "color"))
        set_(self, "grid_color", _rgb(self.grid_color, "grid_color"))
        set_(self, "opacity", _opacity(self.opacity))
        if self.casters is not None:
            set_(self, "casters", as_points(self.casters, "casters"))
        if not 0.0 <= self.shadow_strength <= 1.0:
            raise InputError(f"shadow_strength: expected a number in [0, 1], got {self.shadow_strength!r}")
        for name in ("shadow_radius", "shadow_falloff"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise InputError(f"{name}: expected a positive number or None, got {v!r}")

    def with_casters(self, points: Any) -> Floor:
        """The same floor with the contact shadow of ``points`` (N,3)."""
        from dataclasses import replace

        return replace(self, casters=points)

    def hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Ray parameter (H,W) (inf on a miss), normal (H,W,3), albedo (H,W,3) with the grid and
        the shadow, and the distance to the nearest edge (H,W) (inf: a floor has no drawn edges)."""
        t, normal, albedo, edge, u, v = self.surface(origins, directions)
        return t, normal, self.shade_shadow(albedo, u, v, np.isfinite(t)), edge

    def surface(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, ...]:
        """:meth:`hit` without the shadow, and the in-plane coordinates ``u, v`` (H,W) of the hits."""
        u_ax, v_ax = _in_plane_axes(self.normal)
        t, x = _plane_hit(origins, directions, self.point, self.normal)
        rel = x - self.point
        u, v = rel @ u_ax, rel @ v_ax
        t[(np.abs(u) > self.extent) | (np.abs(v) > self.extent)] = np.inf
        hit = np.isfinite(t)
        albedo = np.broadcast_to(self.color, x.shape).copy()
        if self.grid is not None and hit.any():
            line = _grid_lines(u, v, hit, self.grid)
            albedo += line[..., None] * (self.grid_color - self.color)
        return t, np.broadcast_to(self.normal, x.shape).copy(), albedo, np.full(t.shape, np.inf), u, v

    def shade_shadow(self, albedo: np.ndarray, u: np.ndarray, v: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """``albedo`` darkened by the contact shadow of the casters (a copy)."""
        if self.casters is None or not len(self.casters) or not hit.any():
            return albedo
        return albedo * (1.0 - self._shadow(u, v, hit)[..., None])

    def _shadow(self, u: np.ndarray, v: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """Darkening (H,W) in [0, strength] by the casters above the floor."""
        from scipy.ndimage import gaussian_filter, map_coordinates

        u_ax, v_ax = _in_plane_axes(self.normal)
        radius = self.shadow_radius or 0.03 * self.extent
        falloff = self.shadow_falloff or 0.2 * self.extent
        rel = self.casters - self.point
        height = rel @ self.normal
        above = height > -radius
        cu, cv, h = rel[above] @ u_ax, rel[above] @ v_ax, np.maximum(height[above], 0.0)
        if not len(cu):
            return np.zeros(u.shape)
        cell = radius / 2.0
        lo = np.array([cu.min(), cv.min()]) - 4 * radius
        n = np.minimum(np.ceil((np.array([cu.max(), cv.max()]) + 4 * radius - lo) / cell).astype(int) + 1, 2048)
        iu = np.clip(((cu - lo[0]) / cell).astype(int), 0, n[0] - 1)
        iv = np.clip(((cv - lo[1]) / cell).astype(int), 0, n[1] - 1)
        weighted = np.zeros(n)
        flat = np.zeros(n)
        np.add.at(weighted, (iu, iv), np.exp(-h / falloff))
        np.add.at(flat, (iu, iv), 1.0)
        weighted, flat = gaussian_filter(weighted, 2.0), gaussian_filter(flat, 2.0)
        ref = 0.5 * float(flat.max())  # a layer resting on the floor saturates
        coords = np.stack([(u[hit] - lo[0]) / cell, (v[hit] - lo[1]) / cell])
        occ = np.zeros(u.shape)
        occ[hit] = map_coordinates(weighted, coords, order=1, mode="constant", cval=0.0) / max(ref, 1e-300)
        return self.shadow_strength * np.clip(occ, 0.0, 1.0)


@dataclass(frozen=True, eq=False)
class Box:
    """An axis-aligned box ``lo <= x <= hi`` (walls, tanks, rods, clamps, slabs of ground).

    Parameters
    ----------
    lo, hi : (3,) float
        Corners; ``hi - lo`` may be 0 along one axis (a rectangle).
    color : RGB in [0, 1]
    opacity : float
        1 draws it opaque; less draws it translucent (after every other object).
    edge : float
        Width in pixels of the darker lines along its edges (0: none).
    """

    lo: Any
    hi: Any
    color: Any = (0.75, 0.75, 0.78)
    opacity: float = 1.0
    edge: float = 1.0

    def __post_init__(self) -> None:
        lo = as_points(np.reshape(np.asarray(self.lo, dtype=np.float64), (1, 3)), "lo")[0]
        hi = as_points(np.reshape(np.asarray(self.hi, dtype=np.float64), (1, 3)), "hi")[0]
        if np.any(hi < lo):
            raise InputError(f"hi: expected hi >= lo on every axis, got lo={lo.tolist()}, hi={hi.tolist()}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)
        object.__setattr__(self, "color", _rgb(self.color, "color"))
        object.__setattr__(self, "opacity", _opacity(self.opacity))
        if not (np.isfinite(self.edge) and self.edge >= 0):
            raise InputError(f"edge: expected a non-negative number of pixels, got {self.edge!r}")

    def hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Ray parameter (H,W), normal (H,W,3), albedo (H,W,3) and the world distance to the
        nearest edge of the face hit (H,W)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (self.lo - origins) / directions
            t2 = (self.hi - origins) / directions
        inside = (origins >= self.lo) & (origins <= self.hi)
        zero = directions == 0
        t1 = np.where(zero, np.where(inside, -np.inf, np.inf), t1)
        t2 = np.where(zero, np.where(inside, np.inf, np.inf), t2)
        tmin, tmax = np.minimum(t1, t2), np.maximum(t1, t2)
        near, far = tmin.max(axis=-1), tmax.min(axis=-1)
        ok = (near <= far) & (far > 0)
        t = np.where(ok, np.where(near > 0, near, far), np.inf)
        axis = np.where(near > 0, tmin.argmax(axis=-1), tmax.argmin(axis=-1))
        normal = np.zeros(origins.shape)
        sign = -np.sign(np.take_along_axis(directions, axis[..., None], axis=-1)[..., 0])
        np.put_along_axis(normal, axis[..., None], np.where(sign == 0, 1.0, sign)[..., None], axis=-1)
        x = origins + np.where(np.isfinite(t), t, 0.0)[..., None] * directions
        # distance to the face's edges: the smaller margin over the two in-face axes
        margin = np.minimum(x - self.lo, self.hi - x)
        margin = np.where(np.arange(3) == axis[..., None], np.inf, margin)
        margin = np.where(self.hi - self.lo > 0, margin, np.inf)  # a flat box has no edges along its thin axis
        edge = margin.min(axis=-1)
        return t, normal, np.broadcast_to(self.color, x.shape).copy(), edge


@dataclass(frozen=True, eq=False)
class Polygon:
    """A planar convex polygon (a blade, a wall, a sign), given by its corners in order.

    Parameters
    ----------
    vertices : (K,3) float, K >= 3
        Corners of a convex planar polygon, in order around it.
    color : RGB in [0, 1]
    opacity : float
        1 draws it opaque; less draws it translucent.
    edge : float
        Width in pixels of the darker outline (0: none).
    """

    vertices: Any
    color: Any = (0.55, 0.62, 0.72)
    opacity: float = 1.0
    edge: float = 1.0

    def __post_init__(self) -> None:
        v = as_points(self.vertices, "vertices")
        if len(v) < 3:
            raise InputError(f"vertices: expected at least 3 corners, got {len(v)}")
        n = np.cross(v[1] - v[0], v[2] - v[0])
        for k in range(3, len(v)):
            if np.linalg.norm(n) > 0:
                break
            n = np.cross(v[1] - v[0], v[k] - v[0])
        size = float(np.ptp(v, axis=0).max())
        if np.linalg.norm(n) <= 1e-12 * size * size:
            raise InputError("vertices: expected a polygon with non-zero area, got collinear corners")
        n /= np.linalg.norm(n)
        if np.abs((v - v[0]) @ n).max() > 1e-6 * size:
            raise InputError("vertices: expected the corners to lie in one plane")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "color", _rgb(self.color, "color"))
        object.__setattr__(self, "opacity", _opacity(self.opacity))
        if not (np.isfinite(self.edge) and self.edge >= 0):
            raise InputError(f"edge: expected a non-negative number of pixels, got {self.edge!r}")

    @property
    def normal(self) -> np.ndarray:
        """Unit normal (3,) (right-handed with the corner order)."""
        v = self.vertices
        n = np.sum(np.cross(v - v.mean(axis=0), np.roll(v, -1, axis=0) - v.mean(axis=0)), axis=0)
        return n / np.linalg.norm(n)

    def hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Ray parameter (H,W), normal (H,W,3), albedo (H,W,3), world distance to the outline (H,W)."""
        v, n = self.vertices, self.normal
        t, x = _plane_hit(origins, directions, v[0], n)
        edge = np.full(t.shape, np.inf)
        for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
            inward = np.cross(n, b - a)
            inward /= np.linalg.norm(inward)
            d = (x - a) @ inward
            edge = np.minimum(edge, d)
        t[edge < 0] = np.inf
        return t, np.broadcast_to(n, x.shape).copy(), np.broadcast_to(self.color, x.shape).copy(), edge


ContextObject = Floor | Box | Polygon


def _plane_hit(origins: np.ndarray, directions: np.ndarray, point: np.ndarray,
               normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    denom = directions @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((point - origins) @ normal) / denom
    t = np.where(np.isfinite(t) & (t > 0), t, np.inf)
    x = origins + np.where(np.isfinite(t), t, 0.0)[..., None] * directions
    return t, x


def _footprint(s: np.ndarray) -> np.ndarray:
    """Change (H,W) of ``s`` (NaN off the object) from one pixel to the next, |ds/dx| + |ds/dy|."""
    with np.errstate(invalid="ignore"):
        gy, gx = np.gradient(s) if min(s.shape) > 1 else (np.zeros_like(s), np.zeros_like(s))
        fw = np.abs(gx) + np.abs(gy)
    fw = np.where(np.isfinite(fw) & (fw > 0), fw, np.nan)
    return np.where(np.isnan(fw), np.nanmedian(fw) if np.isfinite(fw).any() else 1.0, fw)


def _grid_lines(u: np.ndarray, v: np.ndarray, hit: np.ndarray, spacing: float) -> np.ndarray:
    """Coverage (H,W) in [0, 1] of the lines one pixel wide at multiples of ``spacing`` along ``u``
    and ``v``, box-filtered by the pixel footprint and faded out (with the larger footprint of
    the two, so the fade depends on the distance only) where lines would be under 14 pixels apart."""
    su, sv = np.where(hit, u / spacing, np.nan), np.where(hit, v / spacing, np.nan)
    fu, fv = _footprint(su), _footprint(sv)
    fade = np.clip((1.0 / 14.0 - np.maximum(fu, fv)) / (1.0 / 28.0), 0.0, 1.0)
    lines = []
    for s, fw in ((su, fu), (sv, fv)):
        dist = np.abs(s - np.round(s))  # in grid units
        lines.append(np.clip(1.0 - dist / np.maximum(fw, 1e-12) + 0.5, 0.0, 1.0) * np.clip(1.0 - fw, 0.0, 1.0))
    return np.where(hit, np.nan_to_num(np.maximum(*lines) * fade), 0.0)


def _pixel_size(camera: Camera, depth: np.ndarray) -> np.ndarray:
    """World size of one pixel at camera depth ``depth``."""
    f = camera.kernel_params()[0]
    return np.full(depth.shape, 1.0 / f) if camera.is_ortho else depth / f


_CACHE: dict[tuple[Any, ...], tuple[Any, ...]] = {}
_CACHE_SIZE = 32


def _camera_key(camera: Camera) -> tuple[Any, ...]:
    return (np.asarray(camera.eye).tobytes(), np.asarray(camera.target).tobytes(), np.asarray(camera.up).tobytes(),
            camera.width, camera.height, camera.fov, camera.ortho, camera.near)


def _object_key(obj: ContextObject) -> tuple[Any, ...]:
    """The fields that fix an object's surface (a floor's casters only shade it)."""
    skip = {"casters", "shadow_radius", "shadow_falloff", "shadow_strength"}
    return (type(obj).__name__, *(np.asarray(getattr(obj, f.name)).tobytes() if getattr(obj, f.name) is not None
                                  else None for f in fields(obj) if f.name not in skip))


def _surface_hits(obj: ContextObject, camera: Camera) -> tuple[np.ndarray, ...]:
    """Depth, normal, albedo, edge coverage (and a floor's ``u, v``), cached per object and camera:
    the context of a video is ray-cast once, not per frame."""
    key = (_object_key(obj), _camera_key(camera))
    if key in _CACHE:
        return _CACHE[key]
    origins, directions = camera.rays()
    if isinstance(obj, Floor):
        t, normal, albedo, edge, u, v = obj.surface(origins, directions)
        extra: tuple[np.ndarray, ...] = (u, v)
    else:
        t, normal, albedo, edge = obj.hit(origins, directions)
        extra = ()
    depth = t * (directions @ camera.forward)
    flip = np.sum(normal * directions, axis=-1) > 0
    normal[flip] *= -1.0
    width = float(getattr(obj, "edge", 0.0))
    line = np.zeros(t.shape)
    if width > 0:
        px = _pixel_size(camera, np.where(np.isfinite(depth), depth, 0.0))
        line = np.where(np.isfinite(depth), np.clip(width - edge / np.maximum(px, 1e-300) + 0.5, 0.0, 1.0), 0.0)
        albedo *= 1.0 - 0.45 * line[..., None]
    facing = -directions  # what a translucent pixel over the background is shaded with
    out = (depth, normal, albedo, line, facing, *extra)
    for a in out:
        a.setflags(write=False)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = out
    return out


def context_hits(obj: ContextObject, camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Depth (H,W) (inf on a miss), normal (H,W,3) facing the camera, albedo (H,W,3) with edges
    darkened (and a floor's shadow), and coverage of the edge lines (H,W) of one context object
    seen by ``camera``. The results are read-only arrays.

    Example
    -------
    >>> cam = Camera((0, 0, 5), (0, 0, 0), width=8, height=8, ortho=2.0)
    >>> depth, normal, albedo, _ = context_hits(Box((-2, -2, -1), (2, 2, 1)), cam)
    >>> float(depth[4, 4]), normal[4, 4].tolist()
    (4.0, [0.0, 0.0, 1.0])
    """
    depth, normal, albedo, line, _, *extra = _surface_hits(obj, camera)
    if isinstance(obj, Floor):
        albedo = obj.shade_shadow(albedo, extra[0], extra[1], np.isfinite(depth))
    return depth, normal, albedo, line


def draw_opaque(gbuffer: GBuffer, objects: list[ContextObject], context: DrawContext) -> None:
    for obj in objects:
        depth, normal, albedo, _ = context_hits(obj, context.camera)
        near = depth < gbuffer.depth
        gbuffer.depth[near] = depth[near]
        gbuffer.normal[near] = normal[near]
        gbuffer.albedo[near] = albedo[near]
        gbuffer.coverage[near] = True
        gbuffer.weight[near] = 1.0


def draw_translucent(gbuffer: GBuffer, objects: list[ContextObject], context: DrawContext) -> None:
    bg = background_color(context.options.background)
    hits = [(obj, *context_hits(obj, context.camera)) for obj in objects]
    # far to near (by the median depth of each object's pixels), so nearer glass tints last
    hits.sort(key=lambda h: -float(np.median(h[1][np.isfinite(h[1])])) if np.isfinite(h[1]).any() else 0.0)
    for obj, depth, _normal, albedo, line in hits:
        front = depth < gbuffer.depth  # only the object's own pixels (inf elsewhere) are touched
        empty = front & ~gbuffer.coverage
        over = np.nonzero(front & gbuffer.coverage)
        a = np.clip(obj.opacity + (1.0 - obj.opacity) * 0.6 * line[over], 0.0, 1.0)[:, None]
        gbuffer.albedo[over] = (1.0 - a) * gbuffer.albedo[over] + a * albedo[over]
        bare = np.nonzero(empty)
        a = np.clip(obj.opacity + (1.0 - obj.opacity) * 0.6 * line[bare], 0.0, 1.0)[:, None]
        gbuffer.albedo[bare] = (1.0 - a) * bg + a * albedo[bare]
        gbuffer.normal[bare] = _surface_hits(obj, context.camera)[4][bare]  # lit head-on: an even tint
        gbuffer.depth[bare] = depth[bare]
        gbuffer.coverage[bare] = True
        gbuffer.weight[bare] = 1.0


def is_opaque_context(obj: Any) -> bool:
    return isinstance(obj, Floor | Box | Polygon) and obj.opacity >= 1.0


def is_translucent_context(obj: Any) -> bool:
    return isinstance(obj, Floor | Box | Polygon) and obj.opacity < 1.0



def open_box(lo: Any, hi: Any, color: Any = (0.70, 0.80, 0.95), opacity: float = 0.15,
             edge: float = 1.0) -> list[Polygon]:
    """The four side walls (x and z faces) of the box ``lo <= x <= hi``, open at the top and the
    bottom: a tank standing on a :class:`Floor`. Translucent by default.

    Example
    -------
    >>> walls = open_box((0, 0, 0), (1, 0.5, 0.2))
    >>> len(walls), walls[0].opacity
    (4, 0.15)
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    faces = [[(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)],
             [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],
             [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],
             [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)]]
    return [Polygon(f, color=color, opacity=opacity, edge=edge) for f in faces]
