"""Rendering of a painted surface with differential updates (thesis 5.7, Fig. 5.11).

:class:`PaintView` keeps a :class:`unmesh.render.SplatRenderer` for one camera and, per surface
row, what it last splatted. A render after paint events *unsplats* the rows whose appearance
changed (their old splats, exactly) and *splats* their new state; the depth buffer is not
changed, so the image equals a full re-render wherever that re-render's depth is the same. A
full update runs when the camera moved, when the update list passes :data:`FULL_FRACTION`
of the visible surfels, or when a row was updated differentially more than
:data:`MAX_PARTIAL` times since the last full update (the per-surfel update counter of 5.7).

Reflective paint is environment mapped per surfel (5.7: "reflectivity is evaluated per surfel
using a cube map"); the environment is a procedural sky (:func:`environment`). The brush is
drawn into the same image with a shadow map from it onto the object.

Example
-------
>>> environment(np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])).shape
(2, 3)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh.paint.surface import PaintSurface
from unmesh.render import Camera, SplatOptions, SplatRenderer
from unmesh.render.shading import RenderResult, shade
from unmesh.render.splat import SurfelArrays

__all__ = ["FULL_FRACTION", "MAX_PARTIAL", "PaintView", "environment", "same_camera"]

FULL_FRACTION = 0.25
MAX_PARTIAL = 64
_SKY = np.array([0.75, 0.85, 1.0])
_HORIZON = np.array([1.0, 0.97, 0.9])
_GROUND = np.array([0.25, 0.2, 0.16])


def environment(directions: np.ndarray) -> np.ndarray:
    """Procedural environment map: sky above, a bright horizon band, dark ground (world +Y up).

    Parameters
    ----------
    directions : (N, 3) unit float64

    Returns
    -------
    (N, 3) float64 radiance in [0, 1]
    """
    y = directions[:, 1]
    band = np.exp(-(y / 0.12) ** 2)[:, None]
    sky = np.where((y >= 0)[:, None], _SKY * (0.55 + 0.45 * np.clip(y, 0, 1))[:, None], _GROUND)
    stripe = 0.25 * (np.sin(6.0 * np.arctan2(directions[:, 2], directions[:, 0])) > 0.6)[:, None] * (y > 0)[:, None]
    return np.clip(sky * (1 - band) + _HORIZON * band + stripe, 0.0, 1.0)


def same_camera(a: Camera | None, b: Camera) -> bool:
    if a is None:
        return False
    for f in ("eye", "target", "up"):
        if not np.array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f))):
            return False
    return (a.width, a.height, a.fov, a.ortho, a.near) == (b.width, b.height, b.fov, b.ortho, b.near)


def reflect_colors(surface: PaintSurface, rows: np.ndarray, camera: Camera) -> np.ndarray:
    """Visible colour (5.8) with environment-mapped reflection of metallic paint (5.7)."""
    col = surface.colors(rows)
    k = surface.refl[rows] * surface.metal[rows]
    m = k > 0
    if m.any():
        r = rows[m]
        p = surface.pos[r]
        n = surface.nrm[r]
        v = np.broadcast_to(camera.forward, p.shape) if camera.is_ortho else p - camera.eye
        v = v / np.linalg.norm(v, axis=1, keepdims=True)
        refl = v - 2.0 * np.einsum("ij,ij->i", v, n)[:, None] * n
        env = environment(refl)
        c = col[m]
        col[m] = np.clip((1 - k[m, None]) * c + k[m, None] * c * (0.35 + 1.1 * env), 0.0, 1.0)
    return col


class PaintView:
    """Splatting buffers of one camera over a :class:`PaintSurface`, updated differentially.

    Attributes
    ----------
    last_update : str
        ``"full"`` or ``"differential"`` (the kind of the last :meth:`update`), and
        ``last_count`` the number of rows it splatted or unsplatted.
    """

    def __init__(self, surface: PaintSurface, options: SplatOptions | None = None) -> None:
        self.surface = surface
        self.options = options or SplatOptions(precision="double")
        self.camera: Camera | None = None
        self.renderer: SplatRenderer | None = None
        self._on = np.zeros(0, bool)
        self._pos = np.zeros((0, 3))
        self._nrm = np.zeros((0, 3))
        self._rad = np.zeros(0)
        self._col = np.zeros((0, 3))
        self._partial = np.zeros(0, np.int64)
        self.last_update = "none"
        self.last_count = 0

    def _grow(self, n: int) -> None:
        if len(self._on) >= n:
            return
        m = max(n, int(1.5 * len(self._on)) + 16)

        def g(a: np.ndarray) -> np.ndarray:
            out = np.zeros((m, *a.shape[1:]), a.dtype)
            out[:len(a)] = a
            return out
        self._on, self._pos, self._nrm, self._rad, self._col, self._partial = (
            g(self._on), g(self._pos), g(self._nrm), g(self._rad), g(self._col), g(self._partial))

    def _arrays(self, rows: np.ndarray, old: bool) -> SurfelArrays:
        if old:
            return SurfelArrays(self._pos[rows], self._nrm[rows], self._rad[rows], None, self._col[rows])
        s = self.surface
        return SurfelArrays(np.ascontiguousarray(s.pos[rows]), np.ascontiguousarray(s.nrm[rows]),
                            np.ascontiguousarray(s.rad[rows]), None, reflect_colors(s, rows, self.camera))

    def _store(self, rows: np.ndarray, arrays: SurfelArrays) -> None:
        self._on[rows] = True
        self._pos[rows] = arrays.positions
        self._nrm[rows] = arrays.normals
        self._rad[rows] = arrays.radii
        self._col[rows] = arrays.colors

    def update(self, camera: Camera, force_full: bool = False) -> SplatRenderer:
        """Bring the buffers up to date with the surface for ``camera`` (full or differential)."""
        s = self.surface
        self._grow(s.n)
        dirty = np.fromiter(s.dirty, np.int64, len(s.dirty)) if s.dirty else np.zeros(0, np.int64)
        s.dirty.clear()
        nvis = max(1, len(s.visible_rows()))
        full = (force_full or not same_camera(self.camera, camera) or self.renderer is None
                or len(dirty) > FULL_FRACTION * nvis)
        if not full and len(dirty):
            dirty = np.sort(dirty)
            full = bool(self._partial[dirty].max() >= MAX_PARTIAL)
        if full:
            self.camera = camera
            self.renderer = self.renderer if self.renderer is not None and same_camera(self.renderer.camera, camera) \
                else SplatRenderer(camera, self.options)
            rows = s.visible_rows()
            arr = self._arrays(rows, False)
            self.renderer.render(arr)
            self._on[:] = False
            self._partial[:] = 0
            self._store(rows, arr)
            self.last_update, self.last_count = "full", len(rows)
            return self.renderer
        dirty = dirty[dirty < len(self._on)]
        old = dirty[self._on[dirty]]
        if len(old):
            self.renderer.unsplat(self._arrays(old, True))
            self._on[old] = False
        vis = s.active[dirty] & s.alive[dirty] if len(dirty) else np.zeros(0, bool)
        new = dirty[vis]
        if len(new):
            arr = self._arrays(new, False)
            self.renderer.splat(arr)
            self._store(new, arr)
        self._partial[dirty] += 1
        self.last_update, self.last_count = "differential", int(len(old) + len(new))
        return self.renderer

    def result(self, shading: Any = "phong", background: Any = (1.0, 1.0, 1.0),
               brush: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> RenderResult:
        """The shaded image; ``brush`` = (positions, normals, colours) is drawn with its shadow."""
        assert self.renderer is not None and self.camera is not None
        g = self.renderer.gbuffer()
        if brush is not None and len(brush[0]):
            _draw_brush(g, self.camera, brush, self.options)
        return RenderResult.from_gbuffer(g, self.camera, shade(g, self.camera, shading, background))


def _draw_brush(g: Any, camera: Camera, brush: tuple[np.ndarray, np.ndarray, np.ndarray], options: SplatOptions) -> None:
    """Brush surfels over the object G-buffer (nearest wins) plus the shadow of the brush on the
    object from a light straight above the brush (a shadow map along the brush's mean normal)."""
    pos, nrm, col = brush
    rad = np.full(len(pos), 0.0)
    if len(pos) > 1:
        ext = np.linalg.norm(pos.max(axis=0) - pos.min(axis=0))
        rad[:] = max(ext / np.sqrt(len(pos)) * 1.2, 1e-6)
    bg = SplatRenderer(camera, options).render(SurfelArrays(pos, nrm, rad, None, col)).gbuffer()
    # shadow: object pixels whose point is below a brush point when seen from above the brush
    cov = g.coverage
    if cov.any():
        o, d = camera.rays()
        fwd = camera.forward
        t = g.depth / np.maximum(np.einsum("hwi,i->hw", d, fwd), 1e-12)
        world = o + d * np.where(cov, t, 0.0)[..., None]
        up = nrm.mean(axis=0)
        up = up / max(np.linalg.norm(up), 1e-12)
        centre = pos.mean(axis=0)
        from unmesh.surfels import tangent_frame
        t1, t2 = tangent_frame(up[None])
        rel_b = pos - centre
        bu = np.stack([rel_b @ t1[0], rel_b @ t2[0]], axis=1)
        bh = rel_b @ up
        rel = world[cov] - centre
        pu = np.stack([rel @ t1[0], rel @ t2[0]], axis=1)
        ph = rel @ up
        from unmesh.spatial import KDTree
        dist, idx = KDTree(bu).knn(pu, 1)
        shadow = (dist[:, 0] < 2.0 * rad.max()) & (bh[idx[:, 0]] > ph + 1e-9)
        alb = g.albedo[cov]
        alb[shadow] *= 0.55
        g.albedo[cov] = alb
    front = bg.coverage & (bg.depth < g.depth)
    for name in ("albedo", "normal", "depth", "weight"):
        a = getattr(g, name)
        b = getattr(bg, name)
        a[front] = b[front]
    g.coverage[front] = True
