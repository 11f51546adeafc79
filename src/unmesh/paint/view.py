"""Rendering of a painted surface with differential updates (thesis 5.7, Fig. 5.11).

:class:`PaintView` keeps a :class:`unmesh.render.SplatRenderer` for one camera and, per surface
row, what it last splatted. A render after paint events *unsplats* the rows whose appearance
changed (their old splats, exactly) and *splats* their new state; the depth buffer is not
changed, so the image equals a full re-render wherever that re-render's depth is the same. A
full update runs when the camera moved, when the update list passes :data:`FULL_FRACTION`
of the visible surfels, or when a row was updated differentially more than
:data:`MAX_PARTIAL` times since the last full update (the per-surfel update counter of 5.7).

Closed models are drawn with back-face culling (:attr:`PaintView.cull_backfaces`): surfels
facing away from the camera are never splatted, in full and differential updates alike, so the
far side's splats do not poke out dark past thin features; open surfaces turn it off.
:meth:`PaintView.preview` is a level-of-detail image for a moving view, and ``result(overlay=)``
draws the palette's inset (:mod:`unmesh.paint.palette`) into the same image.

Reflective paint is environment mapped per surfel (5.7: "reflectivity is evaluated per surfel
using a cube map"); the environment is a procedural sky (:func:`environment`). The brush is
drawn into the same image with a shadow map from it onto the object.

Example
-------
>>> environment(np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])).shape
(2, 3)
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from unmesh._threads import serial_if_small
from unmesh.errors import InputError
from unmesh.paint._paint_kernels import gather_surfels, scatter_surfels
from unmesh.paint._view_kernels import brush_discs, shadow_lookup
from unmesh.paint.surface import PaintSurface, fresh_zeros
from unmesh.render import Camera, SplatOptions, SplatRenderer
from unmesh.render._kernels import facing_rows
from unmesh.render.shading import GBuffer, RenderResult, shade
from unmesh.render.splat import SurfelArrays

__all__ = ["FULL_FRACTION", "MAX_PARTIAL", "PaintView", "environment", "same_camera", "shadow_test"]

FULL_FRACTION = 0.4
#: Splat radius factor of :meth:`PaintView.preview` beyond ``sqrt(stride)``: a subset of an
#: irregular sampling has gaps wider than its mean spacing.
PREVIEW_GROWTH = 1.8
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


class _Probe:
    pass


def _refs(owner: Any, name: str) -> int:
    """References to the array ``owner.<name>`` (less this function's own)."""
    return sys.getrefcount(getattr(owner, name))


_p = _Probe()
_p.a = np.empty(0)
#: :func:`_refs` of an array referred to by its owner's attribute only: more means a caller still
#: holds it (a result handed out earlier, or a view derived from one: views refer to their base).
_FREE = _refs(_p, "a")
del _p


#: The arrays of a G-buffer (a full update reuses the view's last G-buffer when no caller holds any).
GBUFFER_FIELDS = ("albedo", "normal", "depth", "coverage", "weight")


def _held(owner: Any, name: str) -> bool:
    """True when something besides ``owner`` refers to its array ``name``."""
    return _refs(owner, name) > _FREE


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
    if not surface.metal.any():
        return col
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
        self._used = 0  # rows < _used may hold state (the largest surface.n seen)
        self.last_update = "none"
        self.last_count = 0
        #: Pixel windows ``(r0, r1, c0, c1)`` of the composed image that the last :meth:`result`
        #: rewrote (None: all of it); outside them its colour equals the result before it.
        self.last_windows: list[tuple[int, int, int, int]] | None = None
        #: Number of :meth:`result` calls so far (a caller that uses :attr:`last_windows` checks
        #: that no other result came between its own two).
        self.results = 0
        self.max_partial = MAX_PARTIAL
        self._mark = 0
        self._g: GBuffer | None = None
        self._color = np.zeros((0, 0, 3))
        # the composed image handed out by result(): the object with the brush and its shadow
        self._out_color = np.zeros((0, 0, 3))
        self._out_depth = np.zeros((0, 0))
        self._out_cov = np.zeros((0, 0), bool)
        # windows where the composed image is behind the object image (None: all of it)
        self._stale: list[tuple[int, int, int, int]] | None = None
        self.shading: Any = "phong"
        self.background: Any = (1.0, 1.0, 1.0)
        self._style = (repr(self.shading), repr(self.background))
        #: Back-face culling (closed models): surfels facing away from the camera are not
        #: splatted, in full and differential updates alike. False for open sheets seen from
        #: both sides (a palette plane, scans); a change forces a full update.
        self.cull_backfaces = True
        self._culled_with: bool | None = None

    def _facing(self, rows: np.ndarray, camera: Camera | None = None) -> np.ndarray:
        """``rows`` less those facing away from ``camera`` (default: the view's) when culling (the
        surface's current state)."""
        if not self.cull_backfaces or not len(rows):
            return rows
        s = self.surface
        cam = camera or self.camera
        return facing_rows(np.ascontiguousarray(rows, dtype=np.int64), s.pos, s.nrm, np.asarray(cam.eye, dtype=np.float64),
                           np.asarray(cam.forward, dtype=np.float64), bool(cam.is_ortho))

    def _grow(self, n: int) -> None:
        """Room for rows ``< n`` and as many as the surface's capacity (which grows rarely, by
        a factor: fresh zero pages cost no memory until written), copying the rows used so far."""
        m = max(n, self.surface.capacity)
        used = self._used
        self._used = max(used, n)
        if len(self._on) >= m:
            return

        def g(a: np.ndarray) -> np.ndarray:
            out = fresh_zeros((m, *a.shape[1:]), a.dtype)
            out[:used] = a[:used]
            return out
        self._on, self._pos, self._nrm, self._rad, self._col, self._partial = (
            g(self._on), g(self._pos), g(self._nrm), g(self._rad), g(self._col), g(self._partial))

    def _arrays(self, rows: np.ndarray, old: bool) -> SurfelArrays:
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        src = (self._pos, self._nrm, self._rad) if old else (self.surface.pos, self.surface.nrm, self.surface.rad)
        pos, nrm, rad = np.empty((len(rows), 3)), np.empty((len(rows), 3)), np.empty(len(rows))
        with serial_if_small(len(rows)):
            gather_surfels(rows, *src, pos, nrm, rad)
        col = self._col[rows] if old else reflect_colors(self.surface, rows, self.camera)
        return SurfelArrays(pos, nrm, rad, None, col)

    def _store(self, rows: np.ndarray, arrays: SurfelArrays) -> None:
        self._on[rows] = True
        with serial_if_small(len(rows)):
            scatter_surfels(np.ascontiguousarray(rows, dtype=np.int64), arrays.positions, arrays.normals, arrays.radii,
                            np.ascontiguousarray(arrays.colors), self._pos, self._nrm, self._rad, self._col)

    def update(self, camera: Camera, force_full: bool = False, cull_backfaces: bool | None = None) -> SplatRenderer:
        """Bring the buffers up to date with the surface for ``camera`` (full or differential).

        ``cull_backfaces`` sets :attr:`cull_backfaces` (None keeps it); only front-facing
        surfels are splatted while it is on."""
        if cull_backfaces is not None:
            self.cull_backfaces = bool(cull_backfaces)
        s = self.surface
        self._grow(s.n)
        dirty = np.fromiter(s.dirty, np.int64, len(s.dirty)) if s.dirty else np.zeros(0, np.int64)
        s.dirty.clear()
        full = (force_full or not same_camera(self.camera, camera) or self.renderer is None
                or self._culled_with != self.cull_backfaces)
        if not full and len(dirty):  # (counting the visible rows is O(n): only when something changed)
            full = len(dirty) > FULL_FRACTION * max(1, np.count_nonzero(s.active & s.alive))
        if not full and len(dirty):
            dirty = np.sort(dirty)
            # the per-surfel update counter: rows updated in place, and resampled rows (whose
            # counter is inherited from the surfels they replaced) since the last full update
            cur = dirty[dirty < s.n]  # rows past s.n were removed by an undo
            full = bool(self._partial[dirty].max() >= self.max_partial
                        or (len(cur) and s.updates[cur].max() >= self._mark + self.max_partial))
        if full:
            self.camera = camera
            self.renderer = self.renderer if self.renderer is not None and same_camera(self.renderer.camera, camera) \
                else SplatRenderer(camera, self.options)
            self._culled_with = self.cull_backfaces
            rows = s.visible_rows()
            mark = int(s.updates[rows].max()) if len(rows) else 0
            rows = self._facing(rows)
            arr = self._arrays(rows, False)
            self.renderer.render(arr)
            self._on[:self._used] = False
            self._partial[:self._used] = 0
            self._mark = mark
            self._store(rows, arr)
            self.last_update, self.last_count = "full", len(rows)
            self._resolve(None)
            return self.renderer
        old = dirty[self._on[dirty]]
        touched = []
        if len(old):
            a_old = self._arrays(old, True)
            touched.append(a_old)
            self.renderer.unsplat(a_old)
            self._on[old] = False
        cur = dirty[dirty < s.n]
        new = self._facing(cur[s.active[cur] & s.alive[cur]])
        if len(new):
            arr = self._arrays(new, False)
            touched.append(arr)
            self.renderer.splat(arr)
            self._store(new, arr)
        win = self._window(touched) if touched else None
        if win is not None:
            if any(_held(self._g, a) for a in ("albedo", "normal", "weight")):
                self._g = self._g.copy()  # a caller keeps an earlier result's buffers
            self._resolve(win)
        self._partial[dirty] += 1
        self.last_update, self.last_count = "differential", int(len(old) + len(new))
        return self.renderer

    def preview(self, camera: Camera, stride: int = 1) -> RenderResult:
        """A quick image for ``camera`` from every ``stride``-th visible surfel, its radius times
        ``PREVIEW_GROWTH * sqrt(stride)`` (no holes): a level of detail for dragging the view. It
        does not touch the view's buffers (the next :meth:`update` is unaffected); with
        ``stride`` 1 it equals a full update's image without the brush.

        Parameters
        ----------
        camera : Camera
        stride : int >= 1
        """
        stride = int(stride)
        if stride < 1:
            raise InputError(f"stride: expected a positive integer, got {stride}")
        s = self.surface
        rows = np.ascontiguousarray(self._facing(s.visible_rows()[::stride], camera), dtype=np.int64)
        pos, nrm, rad = np.empty((len(rows), 3)), np.empty((len(rows), 3)), np.empty(len(rows))
        with serial_if_small(len(rows)):
            gather_surfels(rows, s.pos, s.nrm, s.rad, pos, nrm, rad)
        if stride > 1:
            rad *= PREVIEW_GROWTH * np.sqrt(stride)
        renderer = SplatRenderer(camera, self.options)
        renderer.render(SurfelArrays(pos, nrm, rad, None, reflect_colors(s, rows, camera)))
        h, w = camera.shape
        g = renderer.resolve_window(GBuffer.empty(h, w), (0, h, 0, w))
        color = shade(g, camera, self.shading, self.background, window=(0, h, 0, w))
        return RenderResult.from_gbuffer(g, camera, color, copy=False)

    def _window(self, arrays: list[SurfelArrays]) -> tuple[int, int, int, int] | None:
        """Pixel rectangle (r0, r1, c0, c1) covering the splats of ``arrays`` (None: nothing)."""
        cam = self.camera
        assert cam is not None
        pos = np.concatenate([a.positions for a in arrays if len(a)]) if any(len(a) for a in arrays) else None
        if pos is None:
            return None
        rad = np.concatenate([a.radii for a in arrays if len(a)])
        row, col, z = cam.project(pos)
        ok = np.isfinite(row) & np.isfinite(col) & (z > 0)
        if not ok.any():
            return None
        f = cam.pixels_per_unit
        rpx = rad[ok] * (f if cam.is_ortho else f / z[ok]) + self.options.filter_radius + 2.0
        h, w = cam.shape
        r0 = int(max(0, np.floor((row[ok] - rpx).min())))
        r1 = int(min(h, np.ceil((row[ok] + rpx).max()) + 1))
        c0 = int(max(0, np.floor((col[ok] - rpx).min())))
        c1 = int(min(w, np.ceil((col[ok] + rpx).max()) + 1))
        if r0 >= r1 or c0 >= c1:
            return None
        return r0, r1, c0, c1

    def _resolve(self, win: tuple[int, int, int, int] | None) -> None:
        """Normalise (and shade) the whole image or only the window ``win`` of it."""
        r = self.renderer
        cam = self.camera
        assert r is not None and cam is not None
        h, w = cam.shape
        if win is None or self._g is None:
            # a full update: the last buffers again unless a caller holds them (resolve_window resets them)
            if self._g is None or self._g.depth.shape != (h, w) or any(_held(self._g, a) for a in GBUFFER_FIELDS):
                self._g = GBuffer.empty(h, w)
            if self._color.shape != (h, w, 3):
                self._color = np.empty((h, w, 3))
            win = (0, h, 0, w)
            self._stale = None
        elif self._stale is not None:
            self._stale.append(win)
        r.resolve_window(self._g, win)
        self._shade(win)

    def _shade(self, win: tuple[int, int, int, int], origin: tuple[int, int] = (0, 0)) -> None:
        """Shade the window ``win`` of the G-buffer; ``origin`` is the buffer's offset in the image."""
        r0, r1, c0, c1 = win
        if win == (0, self._color.shape[0], 0, self._color.shape[1]) and self._color.flags.c_contiguous:
            shade(self._g, self.camera, self.shading, self.background, window=win, origin=origin, out=self._color)
            return
        self._color[r0:r1, c0:c1] = shade(self._g, self.camera, self.shading, self.background, window=win,
                                          origin=origin)

    def set_style(self, shading: Any, background: Any) -> None:
        """Shading and background of the image; a change re-shades the whole image."""
        key = (repr(shading), repr(background))
        if key != self._style:
            self._style = key
            self.shading, self.background = shading, background
            if self._g is not None:
                h, w = self.camera.shape
                self._shade((0, h, 0, w))
                self._stale = None

    def result(self, brush: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
               overlay: tuple[int, int, np.ndarray] | None = None) -> RenderResult:
        """The shaded image; ``brush`` = (positions, normals, colours) is drawn with its shadow,
        and ``overlay`` = (row, column, image (h, w, 3)) replaces the colour of the pixels it
        covers (the palette's inset, 5.7), after the brush; depth and coverage stay the object's.

        The arrays are read-only views of the view's buffers, and a frame pays only for what
        changed: the composed image (object, brush and shadow) is kept, and each call rewrites
        the windows the last differential updates touched and those of the old and the new
        brush. The buffers are never changed under a caller: when a result handed out earlier
        (or any view of its arrays) is still referenced at the next update, the view continues
        in fresh buffers (one copy of the image), so a kept result stays as it was.
        """
        assert self._g is not None and self.camera is not None
        g = self._g
        h, w = self.camera.shape
        names = ("_out_color", "_out_depth", "_out_cov")
        if self._out_depth.shape != (h, w) or any(_held(self, a) for a in names):
            self._out_color, self._out_depth = np.empty((h, w, 3)), np.empty((h, w))
            self._out_cov = np.empty((h, w), bool)
            self._stale = None
        whole = self._stale is None
        stale = [(0, h, 0, w)] if whole else self._stale
        for r0, r1, c0, c1 in stale:
            self._compose((slice(r0, r1), slice(c0, c1)))
        self._stale = []
        if brush is not None and len(brush[0]):
            win = _draw_brush(g, self._out_color, self._out_depth, self._out_cov, self.camera, brush, self)
            if win is not None:
                self._stale.append(win)
        if overlay is not None:
            win = _draw_overlay(self._out_color, *overlay)
            if win is not None:
                self._stale.append(win)
        self.last_windows = None if whole else [*stale, *self._stale]
        self.results += 1
        out = []
        for a in (self._out_color, self._out_depth, self._out_cov, g.normal, g.albedo, g.weight):
            v = a.view()
            v.flags.writeable = False
            out.append(v)
        return RenderResult(color=out[0], depth=out[1], normal=out[3], coverage=out[2], weight=out[5],
                            albedo=out[4], camera=self.camera)

    def _compose(self, sl: tuple[slice, slice]) -> None:
        """Copy the object image into the composed image within ``sl`` (depth ``inf`` where uncovered)."""
        g = self._g
        cov = g.coverage[sl]
        self._out_color[sl] = self._color[sl]
        self._out_cov[sl] = cov
        depth = self._out_depth[sl]
        depth[...] = g.depth[sl]
        np.copyto(depth, np.inf, where=~cov)


def _draw_overlay(color: np.ndarray, r0: int, c0: int, image: np.ndarray) -> tuple[int, int, int, int] | None:
    """Copy ``image`` (h, w, 3) into ``color`` at row ``r0``, column ``c0`` (clipped to it);
    the window it rewrote, or None."""
    h, w = color.shape[:2]
    ih, iw = image.shape[:2]
    r0, c0 = int(r0), int(c0)
    r1, c1 = min(h, r0 + ih), min(w, c0 + iw)
    a0, b0 = max(r0, 0), max(c0, 0)
    if a0 >= r1 or b0 >= c1:
        return None
    color[a0:r1, b0:c1] = image[a0 - r0:r1 - r0, b0 - c0:c1 - c0]
    return a0, r1, b0, c1


def unproject(cam: Camera, rows: np.ndarray, cols: np.ndarray, z: np.ndarray) -> np.ndarray:
    """World points (N,3) at camera depth ``z`` seen through pixel centres ``(rows, cols)``."""
    f, cx, cy, ortho, _ = cam.kernel_params()
    X = (np.asarray(cols, float) + 0.5 - cx) / f
    Y = -(np.asarray(rows, float) + 0.5 - cy) / f
    if not ortho:
        X, Y = X * z, Y * z
    pc = np.stack([X, Y, np.asarray(z, float)], axis=-1)
    return cam.eye + pc @ cam.rotation


#: Reach (in map cells of half a brush surfel radius) of a brush surfel's shadow, and its disc
#: of cell offsets (du, dv).
_SHADOW_REACH = 4
_SHADOW_STENCIL = tuple(a[np.hypot(*np.mgrid[-4:5, -4:5]).ravel() <= _SHADOW_REACH]
                        for a in (np.mgrid[-4:5, -4:5][0].ravel(), np.mgrid[-4:5, -4:5][1].ravel()))


def shadow_test(brush: np.ndarray, points: np.ndarray, rad: float) -> np.ndarray:
    """A shadow map of the brush along the light (the local z axis): which ``points`` lie in shadow.

    The map has cells of ``rad / 2`` in local (x, y); each brush surfel raises the cells within
    4 cells of its own (a disc: its shadow reaches about 2 ``rad``, as the brush's splats) to its
    height; a point is shadowed where the map is above it.

    Parameters
    ----------
    brush, points : (N, 3), (M, 3) float64
        Brush surfels and surface points in the light frame (x, y across, z towards the light).
    rad : float
        Brush surfel radius.

    Returns
    -------
    (M,) bool

    Example
    -------
    >>> shadow_test(np.array([[0.0, 0, 1]]), np.array([[0.0, 0, 0], [0, 0, 2], [1, 0, 0]]), 0.1).tolist()
    [True, False, False]
    """
    cell = 0.5 * rad
    lo = brush[:, :2].min(axis=0) - (_SHADOW_REACH + 0.5) * cell
    cells = np.floor((brush[:, :2] - lo) / cell).astype(np.int64)
    nu, nv = (int(v) + _SHADOW_REACH + 1 for v in cells.max(axis=0))
    out = np.empty(len(points), bool)
    shadow_lookup(cells, np.ascontiguousarray(brush[:, 2]), _SHADOW_STENCIL[0], _SHADOW_STENCIL[1], nu, nv,
                  np.ascontiguousarray(points, dtype=np.float64), float(lo[0]), float(lo[1]), cell, out)
    return out


def shadow_test_reference(brush: np.ndarray, points: np.ndarray, rad: float) -> np.ndarray:
    """:func:`shadow_test` in numpy (the reference of its kernel)."""
    cell = 0.5 * rad
    lo = brush[:, :2].min(axis=0) - (_SHADOW_REACH + 0.5) * cell
    cells = np.floor((brush[:, :2] - lo) / cell).astype(np.int64)
    nu, nv = (int(v) + _SHADOW_REACH + 1 for v in cells.max(axis=0))
    du, dv = _SHADOW_STENCIL
    flat = ((cells[:, 0, None] + du) * nv + (cells[:, 1, None] + dv)).ravel()
    smap = np.full(nu * nv, -np.inf)
    np.maximum.at(smap, flat, np.repeat(brush[:, 2], len(du)))
    pc = np.floor((points[:, :2] - lo) / cell).astype(np.int64)
    inside = (pc[:, 0] >= 0) & (pc[:, 1] >= 0) & (pc[:, 0] < nu) & (pc[:, 1] < nv)
    out = np.zeros(len(points), bool)
    out[inside] = smap[pc[inside, 0] * nv + pc[inside, 1]] > points[inside, 2] + 1e-9
    return out


def brush_discs_reference(pr: np.ndarray, pc: np.ndarray, thr: np.ndarray, z: np.ndarray, src: np.ndarray, R: int,
                          r0: int, r1: int, c0: int, c1: int, col: np.ndarray, nrm: np.ndarray, albedo: np.ndarray,
                          normal: np.ndarray, depth: np.ndarray, coverage: np.ndarray) -> None:
    """:func:`unmesh.paint._view_kernels.brush_discs` in numpy (its reference): surfel ``i``'s
    disc of pixels ``(pr[i] + oy, pc[i] + ox)``, ``oy^2 + ox^2 <= thr[i]``, nearest fragment in
    front of ``depth`` per pixel; ``albedo``, ``normal`` (P, 3), ``depth``, ``coverage`` (P,) are
    the flat window, written in place."""
    oy, ox = np.mgrid[-R:R + 1, -R:R + 1]
    oy, ox = oy.ravel(), ox.ravel()
    pr = pr[:, None] + oy[None]
    pc = pc[:, None] + ox[None]
    inside = (oy[None] ** 2 + ox[None] ** 2 <= thr[:, None]) & (pr >= r0) & (pr < r1) & (pc >= c0) & (pc < c1)
    src = np.broadcast_to(src[:, None], pr.shape)[inside]
    flat = (pr[inside] - r0) * (c1 - c0) + (pc[inside] - c0)
    zz = z[src]
    # nearest fragment per pixel (a z-buffer), in front of the object
    zb = np.full((r1 - r0) * (c1 - c0), np.inf)
    np.minimum.at(zb, flat, zz)
    front = (zz == zb[flat]) & (zz < depth[flat])
    flat, src, zz = flat[front], src[front], zz[front]
    albedo[flat] = col[src]
    normal[flat] = nrm[src]
    depth[flat] = zz
    coverage[flat] = True


def _draw_brush(g: GBuffer, color: np.ndarray, depth: np.ndarray, coverage: np.ndarray, camera: Camera,
                brush: tuple[np.ndarray, np.ndarray, np.ndarray], view: PaintView
                ) -> tuple[int, int, int, int] | None:
    """Brush surfels over the object (nearest wins) and the brush's shadow on the object, from a
    light straight above the brush (a shadow map along the brush's mean normal), in the window
    around the brush only; that window ``(r0, r1, c0, c1)`` of ``color``, ``depth``, ``coverage``
    is rewritten and returned (None: the brush is not in view; the object G-buffer ``g`` is not
    changed)."""
    pos, nrm, col = brush
    n = len(pos)
    ext = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))
    rad = max(ext / np.sqrt(n) * 1.5, 1e-9)
    row, cl, z = camera.project(pos)
    ok = np.isfinite(row) & np.isfinite(cl) & (z > 0)
    if not ok.any():
        return None
    h, w = camera.shape
    f = camera.pixels_per_unit
    rpx = rad * (np.full(int(ok.sum()), f) if camera.is_ortho else f / z[ok])
    span_r = row[ok].max() - row[ok].min()
    span_c = cl[ok].max() - cl[ok].min()
    pad = 0.5 * max(span_r, span_c) + rpx.max() + 2
    r0, r1 = int(max(0, row[ok].min() - pad)), int(min(h, row[ok].max() + pad + 1))
    c0, c1 = int(max(0, cl[ok].min() - pad)), int(min(w, cl[ok].max() + pad + 1))
    if r0 >= r1 or c0 >= c1:
        return None
    sl = (slice(r0, r1), slice(c0, c1))
    win = GBuffer(g.albedo[sl].copy(), g.normal[sl].copy(), g.depth[sl].copy(), g.coverage[sl].copy(),
                  g.weight[sl].copy())
    cov = win.coverage
    # shadow
    if cov.any():
        rr, cc = np.nonzero(cov)
        world = unproject(camera, rr + r0, cc + c0, win.depth[cov])
        up = nrm.mean(axis=0)
        up = up / max(np.linalg.norm(up), 1e-12)
        e = np.zeros(3)
        e[np.argmin(np.abs(up))] = 1.0
        t1 = np.cross(e, up)
        t1 /= np.linalg.norm(t1)
        frame = np.stack([t1, np.cross(up, t1), up])  # light frame: rows t1, t2, up
        centre = pos.mean(axis=0)
        shadow = shadow_test((pos - centre) @ frame.T, (world - centre) @ frame.T, rad)
        win.albedo[rr[shadow], cc[shadow]] *= 0.55
    # brush surfels as small discs with a z-test (nearest fragment per pixel, in front of the object)
    brush_discs(np.floor(row[ok]).astype(np.int64), np.floor(cl[ok]).astype(np.int64), (rpx + 0.5) ** 2,
                np.ascontiguousarray(z), np.flatnonzero(ok), int(np.ceil(rpx.max())), r0, r1, c0, c1,
                np.ascontiguousarray(col, dtype=np.float64), np.ascontiguousarray(nrm, dtype=np.float64),
                win.albedo.reshape(-1, 3), win.normal.reshape(-1, 3), win.depth.reshape(-1), win.coverage.reshape(-1))
    # shade the window
    out = np.empty((r1 - r0, c1 - c0, 3))
    saved_g, saved_c = view._g, view._color
    view._g, view._color = win, out
    try:
        view._shade((0, r1 - r0, 0, c1 - c0), origin=(r0, c0))
    finally:
        view._g, view._color = saved_g, saved_c
    color[sl] = out
    depth[sl] = win.depth
    np.copyto(depth[sl], np.inf, where=~win.coverage)
    coverage[sl] = win.coverage
    return r0, r1, c0, c1
