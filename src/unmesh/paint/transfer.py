"""Paint transfer in a paint buffer, with resampling of the surface (thesis 5.5, Fig. 5.6).

One paint event at one brush tip:

1. The least-squares plane of the original surfels around the tip carries the *paint buffer*,
   a pixel grid with pixels one brush-surfel spacing wide.
2. Object surfels and brush surfels are splatted into it with the renderer's EWA kernels
   (:class:`unmesh.render.SplatRenderer`, orthographic cameras above and below the plane); the
   depth test ``h_brush < h_object`` gives the penetrated pixels.
3. Every buffer pixel belongs to the object surfel nearest to it in the plane (and, where
   penetrated, to the nearest brush surfel): each surfel's paint volume is shared equally by
   its pixels, so the pixel state is exact and every sum is conserved.
4. Transfer per penetrated pixel is bidirectional (5.9-5.11) at a rate set by pressure and
   penetration depth.
5. The object surfels that own a penetrated pixel are replaced by one child per pixel of their
   cells (attached to the father, on the replaced surfel's plane, offset by impasto relief);
   originals are disabled, children deleted. The brush surfels get their pixels' paint back
   (volume sum, volume-weighted colour).

Example
-------
>>> plane_frame(np.array([0.0, 0.0, 1.0]))[0].round(6).tolist()
[0.0, -1.0, 0.0]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh._threads import serial_if_small
from unmesh.paint import _transfer_kernels as tk
from unmesh.paint._buffer_kernels import grid_knn2d, pixel_owners
from unmesh.paint.brush import BrushState, cross3
from unmesh.paint.model import transfer
from unmesh.paint.strokes import Paint
from unmesh.paint.surface import PaintSurface
from unmesh.render import Camera, SplatOptions, SplatRenderer
from unmesh.render.splat import SurfelArrays
from unmesh.spatial import KDTree

__all__ = ["TransferResult", "lsq_plane", "paint_event", "plane_frame"]

#: Child radius in pixels (>= sqrt(2)/2 covers the grid; 1.5 also covers the staircase between
#: the pixel cells and the unreplaced neighbours).
CHILD_RADIUS = 1.5
#: Largest paint buffer edge in pixels.
MAX_BUFFER = 192
#: Impasto: relief height per unit paint thickness, hair-imprint amplitude (of the thickness)
#: and wavelength (in brush spacings); beaten-gold patch size (pixels) and tilt (degrees).
IMPASTO = 0.3
HAIR_AMPLITUDE = 0.6
HAIR_WAVELENGTH = 2.0
BEATEN_PATCH = 4
BEATEN_TILT = 14.0

_PROPS = ("rho", "kappa", "diff", "refl", "shin", "metal")
_SPLAT = SplatOptions(filter_radius=0.0, precision="double", depth_tolerance=0.5)
#: the brush's lower surface: the low-pass filter closes gaps between its rings of surfels
_SPLAT_BRUSH = SplatOptions(filter_radius=1.0, precision="double", depth_tolerance=0.5)


@dataclass(frozen=True)
class TransferResult:
    """Outcome of one paint event: rows removed (disabled/deleted), rows added, penetrated pixels."""

    removed: np.ndarray
    added: np.ndarray
    pixels: int


def plane_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents of a plane with unit ``normal`` (t1 x t2 = normal): those of
    :func:`unmesh.surfels.tangent_frame` (the same operations for one normal)."""
    n = np.asarray(normal, float).reshape(3)
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(n)))] = 1.0
    t1 = cross3(helper, n)
    t1 = t1 / np.sqrt(np.add.reduce(t1 * t1))
    return t1, cross3(n, t1)


def lsq_plane(points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane (centroid, unit normal oriented like the mean of ``normals``)."""
    c = points.mean(axis=0)
    cov = (points - c).T @ (points - c)
    _, v = np.linalg.eigh(cov)
    n = v[:, 0]
    ref = normals.mean(axis=0)
    if np.dot(n, ref) < 0:
        n = -n
    if np.linalg.norm(ref) > 0 and np.dot(n, ref / np.linalg.norm(ref)) < 0.5:
        n = ref / np.linalg.norm(ref)  # too few or degenerate samples: the mean normal
    return c, n / np.linalg.norm(n)


def _hash01(a: np.ndarray, b: np.ndarray, salt: int) -> np.ndarray:
    """Deterministic pseudo-random numbers in [0, 1) from integer pairs."""
    h = (a.astype(np.int64) * 73856093) ^ (b.astype(np.int64) * 19349663) ^ (salt * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    return ((h ^ (h >> 16)) & 0xFFFFFF).astype(np.float64) / float(0x1000000)


def _height_map(cam: Camera, pos: np.ndarray, nrm: np.ndarray, rad: np.ndarray, Z: float,
                options: SplatOptions = _SPLAT) -> tuple[np.ndarray, np.ndarray]:
    """Heights along the camera's backward axis (``Z - depth``) and coverage, by splatting."""
    arr = SurfelArrays(np.ascontiguousarray(pos), np.ascontiguousarray(nrm), np.ascontiguousarray(rad), None,
                       np.zeros((len(pos), 3)))
    g = SplatRenderer(cam, options).render(arr).gbuffer()
    return np.where(g.coverage, Z - g.depth, -np.inf), g.coverage


def pixel_owners_reference(points: np.ndarray, radius: np.ndarray, queries: np.ndarray,
                           k: int) -> tuple[np.ndarray, np.ndarray]:
    """Plain reference of :func:`owners` (kd-tree k-nearest, then the smallest distance / radius)."""
    dist, cand = KDTree(points).knn(queries, k)
    ratio = dist / radius[cand]
    best = np.argmin(ratio, axis=1)
    r = np.arange(len(queries))
    return cand[r, best], ratio[r, best]


def owners(points: np.ndarray, radius: np.ndarray, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Owner of each paint-buffer pixel: among the ``k`` nearest surfel centres ``points`` (P, 2)
    of each pixel centre ``queries`` (Q, 2), the one covering it best (smallest distance /
    ``radius``), so cells of small children and large originals tile what they cover.

    Returns
    -------
    own : (Q,) int64
        Index into ``points``.
    ratio : (Q,) float64
        Its distance / radius (<= 1: the pixel is covered).
    """
    own = np.empty(len(queries), np.int64)
    ratio = np.empty(len(queries))
    with serial_if_small(len(queries) * k):
        pixel_owners(np.ascontiguousarray(points), np.ascontiguousarray(radius), np.ascontiguousarray(queries),
                     k, own, ratio)
    return own, ratio


def nearest(points: np.ndarray, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to and index of the nearest of ``points`` (P, 2) for each of ``queries`` (Q, 2),
    ties by index (as ``KDTree(points).knn(queries, 1)``), (Q,) float64 and (Q,) int64."""
    dist = np.empty((len(queries), 1))
    idx = np.empty((len(queries), 1), np.int64)
    with serial_if_small(len(queries)):
        grid_knn2d(np.ascontiguousarray(points), np.ascontiguousarray(queries), 1, dist, idx)
    return dist[:, 0], idx[:, 0]


def _merge_orphans(surface: PaintSurface, ks: np.ndarray, rr: np.ndarray, cw: np.ndarray, vw: np.ndarray,
                   dc: np.ndarray, vd: np.ndarray, props: dict[str, np.ndarray]) -> None:
    """Add the paint of surface rows ``rr`` (surfels that own no pixel) to the pixel state at
    distinct pixels ``ks`` (in place): volumes summed, colours and paint attributes mixed by volume."""
    a = vw[ks] + vd[ks]
    b = surface.vw[rr] + surface.vd[rr]
    t = a + b
    m = t > 0
    for f in _PROPS:
        props[f][ks[m]] = (a[m] * props[f][ks[m]] + b[m] * surface.__getattr__(f)[rr[m]]) / t[m]
    a, b = vw[ks], surface.vw[rr]
    t = a + b
    m = t > 0
    cw[ks[m]] = (a[m, None] * cw[ks[m]] + b[m, None] * surface.wet[rr[m]]) / t[m, None]
    vw[ks] = t
    a, b = vd[ks], surface.vd[rr]
    t = a + b
    m = t > 0
    dc[ks[m]] = (a[m, None] * dc[ks[m]] + b[m, None] * surface.dry[rr[m]]) / t[m, None]
    vd[ks] = t


def merge_orphans(surface: PaintSurface, ks: np.ndarray, rr: np.ndarray, cw: np.ndarray, vw: np.ndarray,
                  dc: np.ndarray, vd: np.ndarray, props: dict[str, np.ndarray]) -> None:
    """Merge surface rows ``rr`` (K,) into the pixel state at pixels ``ks`` (K,), in order (a
    pixel may take several): the result of merging them one after the other, computed in rounds
    of distinct pixels (round r merges the r-th row of every pixel)."""
    order = np.argsort(ks, kind="stable")
    sk = ks[order]
    first = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    occ = np.empty(len(ks), np.int64)
    occ[order] = np.arange(len(ks)) - np.repeat(first, np.diff(np.r_[first, len(ks)]))
    for r in range(int(occ.max()) + 1 if len(ks) else 0):
        j = np.flatnonzero(occ == r)
        _merge_orphans(surface, ks[j], rr[j], cw, vw, dc, vd, props)


# -- the paint event's step chains: numpy references of the kernels in _transfer_kernels -----

def near_rows_reference(rows: np.ndarray, pos: np.ndarray, nrm: np.ndarray, rad: np.ndarray, o: np.ndarray,
                        N: np.ndarray, t1: np.ndarray, t2: np.ndarray, reach: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference of :func:`near_rows`."""
    pos_r = pos[rows]
    nrm_r = nrm[rows]
    rel = pos_r - o
    rh = rel @ N
    ok = (nrm_r @ N > 0.2) & (np.abs(rh) < reach)
    return rows[ok], pos_r[ok], nrm_r[ok], rad[rows[ok]], np.stack([rel[ok] @ t1, rel[ok] @ t2], axis=1)


def near_rows(rows: np.ndarray, pos: np.ndarray, nrm: np.ndarray, rad: np.ndarray, o: np.ndarray, N: np.ndarray,
              t1: np.ndarray, t2: np.ndarray, reach: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The surface rows ``rows`` (R,) int64 that face the plane (origin ``o``, unit normal ``N``,
    tangents ``t1``, ``t2``; ``nrm . N > 0.2``) within ``reach`` of it, in order: their rows,
    positions (M, 3), normals (M, 3), radii (M,) and plane coordinates (M, 2) (of the surface
    fields ``pos``, ``nrm``, ``rad``)."""
    n = len(rows)
    out = np.empty(n, np.int64)
    pos_r, nrm_r, rad_r, ou = np.empty((n, 3)), np.empty((n, 3)), np.empty(n), np.empty((n, 2))
    m = tk.near_rows(np.ascontiguousarray(rows, np.int64), pos, nrm, rad, o, N, t1, t2, float(reach), out, pos_r,
                     nrm_r, rad_r, ou)
    return out[:m], pos_r[:m], nrm_r[:m], rad_r[:m], ou[:m]


def hidden_fathers_reference(fathers: np.ndarray, replaced: np.ndarray, n_original: int, active: np.ndarray,
                             pos: np.ndarray, nrm: np.ndarray, o: np.ndarray, N: np.ndarray, t1: np.ndarray,
                             t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference of :func:`hidden_fathers`."""
    hidden = ~active[fathers] | np.isin(fathers, replaced[replaced < n_original])
    fcand = fathers[hidden & (nrm[fathers] @ N > 0.2)]
    rel_f = pos[fcand] - o
    return fcand, np.stack([rel_f @ t1, rel_f @ t2], axis=1)


def hidden_fathers(fathers: np.ndarray, replaced: np.ndarray, n_original: int, active: np.ndarray,
                   pos: np.ndarray, nrm: np.ndarray, o: np.ndarray, N: np.ndarray, t1: np.ndarray,
                   t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The originals among ``fathers`` (F,) int64 that are hidden (not ``active``, or among the
    ``replaced`` rows) and face the plane, in order, (M,) int64, and their plane coordinates (M, 2)."""
    n = len(fathers)
    idx, uv = np.empty(n, np.int64), np.empty((n, 2))
    m = tk.hidden_fathers(np.ascontiguousarray(fathers, np.int64), np.ascontiguousarray(replaced, np.int64),
                          n_original, active, pos, nrm, o, N, t1, t2, idx, uv)
    return idx[:m], uv[:m]


def replaced_pixels_reference(own: np.ndarray, pen: np.ndarray, covered: np.ndarray, ou: np.ndarray,
                              rad_r: np.ndarray, lo0: float, lo1: float, W: int, H: int, h: float
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference of :func:`unmesh.paint._transfer_kernels.replaced_pixels`."""
    # replaced surfels: owners of penetrated pixels whose cell lies inside the buffer
    r15 = 1.5 * rad_r
    inner = (ou[:, 0] - r15 > lo0) & (ou[:, 0] + r15 < lo0 + W * h)
    inner &= (ou[:, 1] - r15 > lo1) & (ou[:, 1] + r15 < lo1 + H * h)
    # ... and surfels whose centre lies on a penetrated pixel but own no pixel (denser than the
    # buffer): their paint goes to the pixel under their centre
    ci = np.floor((ou[:, 0] - lo0) / h).astype(np.int64)
    cj = np.floor((lo1 + H * h - ou[:, 1]) / h).astype(np.int64)
    inside_buf = (ci >= 0) & (ci < W) & (cj >= 0) & (cj < H)
    cpix = np.where(inside_buf, cj * W + ci, 0)
    on_pen = inside_buf & pen[cpix]
    rep_local = np.unique(np.concatenate([own[pen], np.flatnonzero(on_pen)]))
    rep_local = rep_local[inner[rep_local]]
    is_rep = np.zeros(len(rad_r), bool)
    is_rep[rep_local] = True
    Q = np.flatnonzero(covered & is_rep[own])
    npix = np.bincount(own[Q], minlength=len(rad_r)).astype(np.float64)
    return is_rep, cpix, Q, npix


def pixels_near_reference(ou: np.ndarray, rad_r: np.ndarray, sel: np.ndarray, pix: np.ndarray, skip: np.ndarray,
                          lo0: float, lo1: float, W: int, H: int, h: float) -> np.ndarray:
    """Reference of :func:`unmesh.paint._transfer_kernels.pixels_near` (every pixel against
    every row of ``sel``)."""
    r = rad_r[sel] * (1.0 + 1e-9)
    dx = pix[:, None, 0] - ou[sel][None, :, 0]
    dy = pix[:, None, 1] - ou[sel][None, :, 1]
    return np.flatnonzero((dx * dx + dy * dy <= r * r).any(axis=1) & ~skip)


def pixel_state_reference(surface: PaintSurface, Q: np.ndarray, own: np.ndarray, rows: np.ndarray,
                          npix: np.ndarray, pix: np.ndarray) -> tuple[np.ndarray, ...]:
    """Reference of :func:`pixel_state`."""
    oq = own[Q]
    rq = rows[oq]
    share = 1.0 / npix[oq]
    props = np.stack([surface.__getattr__(f)[rq] for f in _PROPS])
    return rq, surface.wet[rq].copy(), surface.vw[rq] * share, surface.vd[rq] * share, surface.dry[rq].copy(), props, pix[Q]


def pixel_state(surface: PaintSurface, Q: np.ndarray, own: np.ndarray, rows: np.ndarray, npix: np.ndarray,
                pix: np.ndarray) -> tuple[np.ndarray, ...]:
    """Surface pixel state of buffer pixels ``Q`` (K,) (owned by ``rows[own[Q]]``, each owner's
    paint shared equally by its ``npix`` pixels): owner rows (K,) int64, wet colour (K, 3),
    wet and dry volume (K,), dry colour (K, 3), paint attributes (6, K) (rows in the order of
    ``_PROPS``) and pixel centres (K, 2)."""
    K = len(Q)
    rq = np.empty(K, np.int64)
    cw, vw, vd, dc = np.empty((K, 3)), np.empty(K), np.empty(K), np.empty((K, 3))
    props, pu = np.empty((len(_PROPS), K)), np.empty((K, 2))
    s = surface
    tk.pixel_state(Q, own, rows, npix, s.wet, s.vw, s.vd, s.dry, s.rho, s.kappa, s.diff, s.refl, s.shin, s.metal,
                   pix, rq, cw, vw, vd, dc, props, pu)
    return rq, cw, vw, vd, dc, props, pu


def brush_pixels_reference(Q: np.ndarray, P: np.ndarray, bown: np.ndarray, depth: np.ndarray, sel: np.ndarray,
                           brush_wet: np.ndarray, brush_vw: np.ndarray, pressure: float, lower: float
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference of :func:`unmesh.paint._transfer_kernels.brush_pixels`."""
    bq = bown[Q][P]
    bsel = sel[bq]
    nb = np.bincount(bq, minlength=len(sel)).astype(np.float64)
    bshare = 1.0 / nb[bq]
    press = pressure * np.clip(depth[Q][P] / max(lower, 1e-300), 0.0, 1.0)
    return bsel, brush_wet[bsel], brush_vw[bsel] * bshare, press


def brush_write_back_reference(bsel: np.ndarray, vb2: np.ndarray, cb2: np.ndarray, brush_wet: np.ndarray,
                               brush_vw: np.ndarray) -> None:
    """Reference of :func:`unmesh.paint._transfer_kernels.brush_write_back` (in place)."""
    touched = np.unique(bsel)
    tot = np.zeros(len(brush_vw))
    np.add.at(tot, bsel, vb2)
    acc = np.zeros((len(brush_vw), 3))
    np.add.at(acc, bsel, vb2[:, None] * cb2)
    safe = np.where(tot[touched] > 0, tot[touched], 1.0)[:, None]
    brush_wet[touched] = np.where(tot[touched][:, None] > 0, acc[touched] / safe, brush_wet[touched])
    brush_vw[touched] = tot[touched]


def blend_props_reference(props: np.ndarray, P: np.ndarray, fb: np.ndarray, values: np.ndarray) -> None:
    """Reference of :func:`unmesh.paint._transfer_kernels.blend_props` (``P`` indices or a mask; in place)."""
    for f in range(len(props)):
        props[f, P] = (1.0 - fb) * props[f, P] + fb * values[f]


def child_frames_reference(surface: PaintSurface, rq: np.ndarray, pu: np.ndarray, o: np.ndarray, t1: np.ndarray,
                           t2: np.ndarray) -> tuple[np.ndarray, ...]:
    """Reference of :func:`child_frames`."""
    base_pt = o + pu[:, :1] * t1 + pu[:, 1:] * t2
    onr = surface.nrm[rq]
    fnr = surface.nrm[surface.father[rq]]
    owner_lift = surface.lift[rq]
    opl = surface.pos[rq] - owner_lift[:, None] * fnr
    return base_pt, onr, fnr, opl, owner_lift


def child_frames(surface: PaintSurface, rq: np.ndarray, pu: np.ndarray, o: np.ndarray, t1: np.ndarray,
                 t2: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per child of owner row ``rq`` (K,) at pixel centre ``pu`` (K, 2): the pixel centre in space
    (K, 3), the owner's normal (K, 3), its father's normal (K, 3), its father-surface point
    (``pos - lift * father normal``, (K, 3)) and its lift (K,)."""
    K = len(rq)
    base_pt, onr, fnr, opl, owner_lift = np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3)), \
        np.empty(K)
    tk.child_frames(rq, pu, o, t1, t2, surface.pos, surface.nrm, surface.lift, surface.father, base_pt, onr, fnr, opl,
                    owner_lift)
    return base_pt, onr, fnr, opl, owner_lift


def merge_orphan_rows(surface: PaintSurface, ks: np.ndarray, rr: np.ndarray, cw: np.ndarray, vw: np.ndarray,
                      dc: np.ndarray, vd: np.ndarray, props: np.ndarray) -> None:
    """:func:`merge_orphans` (its reference) in one pass, the attributes as the rows of ``props``
    (6, Q) in the order of ``_PROPS``; in place."""
    s = surface
    tk.merge_orphan_rows(np.ascontiguousarray(ks, np.int64), np.ascontiguousarray(rr, np.int64), s.vw, s.vd, s.wet,
                         s.dry, s.rho, s.kappa, s.diff, s.refl, s.shin, s.metal, cw, vw, dc, vd, props)


def paint_event(surface: PaintSurface, brush: BrushState, paint: Paint, pressure: float, dt: float,
                direction: np.ndarray, tip: np.ndarray | None = None, body: np.ndarray | None = None,
                km: bool = False) -> TransferResult:
    """One paint event at the brush tip(s) ``tip`` (default: colliding active masses' mean).

    Parameters
    ----------
    surface : PaintSurface
    brush : BrushState
        Its surfels (or the subset ``body`` of a split brush's tip) carry the brush paint.
    paint : Paint
        The paint loaded on the brush (sets the transfer rates and the new paint attributes).
    pressure : float in [0, 1]
    dt : float
        Interaction time (s) of (5.9/5.10).
    direction : (3,) float64
        Brush motion since the last event (hair imprints run along it).
    """
    empty = TransferResult(np.empty(0, np.int64), np.empty(0, np.int64), 0)
    bpos, bnrm = brush.surfels()
    sel = np.arange(len(bpos)) if body is None else body
    if tip is None:
        tip = brush.x[brush.colliding].mean(axis=0) if brush.colliding.any() else brush.x.mean(axis=0)
    tree = surface.tree
    no = surface.n_original
    opos, onrm = surface.pos[:no], surface.nrm[:no]
    ball = brush.ball if brush.ball is not None and brush.ball.tree is tree else tree
    _, near = ball.knn(tip[None], min(20, no))
    o, N = lsq_plane(opos[near[0]], onrm[near[0]])
    t1, t2 = plane_frame(N)
    h = brush.sk.spacing
    # brush surfels near the plane
    bh = (bpos[sel] - o) @ N
    reach = 3.0 * brush.brush.size
    # the brush's lower surface (facing the object) near the plane
    sel = sel[(bh < 2.0 * brush.sk.lower + reach * 0.25) & (bnrm[sel] @ N < 0.0)]
    if len(sel) == 0:
        return empty
    bu = np.stack([(bpos[sel] - o) @ t1, (bpos[sel] - o) @ t2], axis=1)
    # object rows near the tip: originals within reach, replaced by their children
    rmax = float(surface.rad[:no][near[0]].max())
    ext = float(np.abs(bu).max()) + 3.0 * rmax
    off, ind = tree.radius_neighbors(o[None], ext * 1.5)
    fathers = ind[off[0]:off[1]]
    # those facing the plane within reach, their fields fetched once, and plane coordinates
    rows, pos_r, nrm_r, rad_r, ou = near_rows(surface.rows_of(fathers), surface.pos, surface.nrm, surface.rad, o, N,
                                              t1, t2, reach)
    if len(rows) == 0:
        return empty
    # pixels about one brush surfel, but never coarser than the surface already is there
    h = min(h, 0.7 * float(np.median(rad_r)))
    # the buffer: centred on the brush footprint, margin of 3 object radii
    lo = bu.min(axis=0) - 3.0 * rmax
    hi = bu.max(axis=0) + 3.0 * rmax
    size = hi - lo
    if max(size) / h > MAX_BUFFER:
        h = float(max(size)) / MAX_BUFFER
    W = int(np.ceil(size[0] / h))
    H = int(np.ceil(size[1] / h))
    centre = o + t1 * (lo[0] + 0.5 * W * h) + t2 * (lo[1] + 0.5 * H * h)
    Z = 4.0 * reach + 1.0
    above = Camera(centre + N * Z, centre, up=t2, width=W, height=H, ortho=H * h)
    below = Camera(centre - N * Z, centre, up=t2, width=W, height=H, ortho=H * h)
    ho, cov_o = _height_map(above, pos_r, nrm_r, rad_r, Z)
    hb, cov_b = _height_map(below, bpos[sel], bnrm[sel], np.full(len(sel), brush.sk.spacing), Z, _SPLAT_BRUSH)
    hb = -hb  # heights along +N of the brush's lowest surface
    if np.dot(below.right, above.right) < 0:
        hb, cov_b = hb[:, ::-1], cov_b[:, ::-1]
    # pixel centres in plane coordinates (u along t1 = above.right, v along t2 = up)
    if np.dot(above.right, t1) < 0:  # keep (u, v) consistent with the image columns
        t1 = -t1
        ou[:, 0] = -ou[:, 0]
        bu[:, 0] = -bu[:, 0]
        lo[0], hi[0] = -hi[0], -lo[0]
    cu = ((np.arange(W) + 0.5) - 0.5 * W) * h + (lo[0] + 0.5 * W * h)
    cv = (0.5 * H - (np.arange(H) + 0.5)) * h + (lo[1] + 0.5 * H * h)
    U, V = np.meshgrid(cu, cv)
    pix = np.stack([U.ravel(), V.ravel()], axis=1)
    # ownership: among the nearest object surfels, the one covering the pixel best (smallest
    # distance / radius), so cells of small children and large originals tile what they cover.
    # Asked first where the brush may penetrate (it covers the pixel, and the splatted height is
    # above the brush's or the splats leave the pixel centre uncovered: penetration needs the
    # owner there), then (below) around the replaced surfels; the other pixels own nothing that
    # is used (not covered)
    kk = min(8, len(rows))
    need = (cov_b.ravel() & (ho.ravel() - hb.ravel() > 0)) | ~cov_o.ravel()
    own = np.zeros(W * H, np.int64)
    ratio = np.full(W * H, np.inf)
    first = np.flatnonzero(need)
    if len(first):
        own[first], ratio[first] = owners(ou, rad_r, pix[first], kk)
    covered = ratio <= 1.0
    # the object's height: splatted, or (where the clipped kernels leave a pixel centre
    # uncovered, e.g. at a corner of touching splats) the owner's plane (row-wise arithmetic:
    # computed for those pixels only)
    ho = ho.ravel()
    unc = np.flatnonzero(~cov_o.ravel())
    if len(unc):
        on = nrm_r[own[unc]]
        pu_ = pix[unc]
        foot = o + pu_[:, :1] * t1 + pu_[:, 1:] * t2
        ho[unc] = np.einsum("ij,ij->i", on, pos_r[own[unc]] - foot) / np.maximum(on @ N, 0.2)
    # penetration and brush ownership
    depth = ho - hb.ravel()
    pen = covered & cov_b.ravel() & (depth > 0)
    # the nearest brush surfel of the pixels that may be penetrated (only those are used)
    cand = np.flatnonzero(pen)
    if len(cand) == 0:
        return empty
    bdist, bown_c = nearest(bu, pix[cand])
    pen[cand[bdist > 1.5 * brush.sk.spacing]] = False
    bown = np.zeros(len(pix), np.int64)
    bown[cand] = bown_c
    if not pen.any():
        return empty
    # replaced surfels: owners of penetrated pixels whose cell lies inside the buffer, and
    # surfels whose centre lies on a penetrated pixel but own no pixel (denser than the buffer:
    # their paint goes to the pixel under their centre, cpix); the pixels Q of the replaced
    is_rep, cpix, Q, npix = tk.replaced_pixels(own, pen, covered, ou, rad_r, float(lo[0]), float(lo[1]), W, H, h)
    rep_local = np.flatnonzero(is_rep)
    if len(rep_local) == 0:
        return empty
    # the other pixels a replaced surfel may own (within its radius): their owners, then Q again
    # (is_rep depends only on the penetrated pixels' owners: unchanged)
    more = tk.pixels_near(ou, rad_r, rep_local, pix, need, float(lo[0]), float(lo[1]), W, H, h)
    if len(more):
        own[more], ratio[more] = owners(ou, rad_r, pix[more], kk)
        covered[more] = ratio[more] <= 1.0
        is_rep, cpix, Q, npix = tk.replaced_pixels(own, pen, covered, ou, rad_r, float(lo[0]), float(lo[1]), W, H, h)
    P = pen[Q]
    # surface pixel state (exact shares of the owners)
    rq, cw, vw, vd, dc, props_a, pu = pixel_state(surface, Q, own, rows, npix, pix)
    orphans = rep_local[npix[rep_local] == 0]
    if len(orphans):
        qpos = np.full(W * H, -1, np.int64)
        qpos[Q] = np.arange(len(Q))
        ks = qpos[cpix[orphans]]
        is_rep[orphans[ks < 0]] = False  # its pixel is not part of the resampled region: keep it
        orphans, ks = orphans[ks >= 0], ks[ks >= 0]
        merge_orphan_rows(surface, ks, rows[orphans], cw, vw, dc, vd, props_a)
        rep_local = np.flatnonzero(is_rep)
    # brush pixel state on penetrated pixels
    bsel, cbp, vbp, press = tk.brush_pixels(Q, P, bown, depth, sel, brush.wet, brush.vw, float(pressure),
                                            float(brush.sk.lower))
    cs2, vs2, cb2, vb2, fb = transfer(cw[P], vw[P], cbp, vbp, paint.back_transfer, paint.transfer, press, dt, km)
    cw[P] = cs2
    vw[P] = vs2
    # brush write-back: per brush surfel, total volume and volume-weighted colour
    tk.brush_write_back(bsel, vb2, cb2, brush.wet, brush.vw)
    # new paint attributes blend by the fraction of brush paint in the pixel
    tk.blend_props(props_a, np.flatnonzero(P), fb, np.array([paint.density / paint.thickness, paint.drying,
                                                             paint.diffusion, paint.reflectivity, paint.shininess,
                                                             paint.metallic], np.float64))
    rho, kap, dif, refl, shin, met = props_a
    # children: pixel centres on the owner's plane
    # geometry and relief are relative to the original surface: the father's normal fnr (so
    # relief tilts never accumulate); the owner's plane is its father-surface point opl with that normal
    base_pt, onr, fnr, opl, owner_lift = child_frames(surface, rq, pu, o, t1, t2)
    cosn = np.maximum(fnr @ N, 0.2)
    s = np.einsum("ij,ij->i", fnr, opl - base_pt) / cosn
    cpos = base_pt + s[:, None] * N
    area = np.full(len(Q), h * h) / cosn
    lift = owner_lift
    nrm = onr
    if paint.relief == "hair" and P.any():
        thick = (vw[P] + vd[P]) / area[P]
        dirn = direction - np.dot(direction, N) * N
        ln = np.linalg.norm(dirn)
        across = cross3(N, dirn / ln) if ln > 1e-12 else t1
        coord = (pu[P] @ np.array([across @ t1, across @ t2]))
        lam = HAIR_WAVELENGTH * brush.sk.spacing
        phase = 2 * np.pi * coord / lam
        lift[P] = IMPASTO * thick * (1.0 + HAIR_AMPLITUDE * np.sin(phase))
        # the normal of the offset surface: tilted against the slope of the imprints
        slope = np.clip(IMPASTO * thick * HAIR_AMPLITUDE * (2 * np.pi / lam) * np.cos(phase), -0.35, 0.35)
        a3 = across - np.einsum("ij,j->i", fnr[P], across)[:, None] * fnr[P]
        nn = fnr[P] - slope[:, None] * a3
        nrm[P] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
    elif paint.relief == "beaten" and P.any():
        gi = np.floor(pu[P] / (BEATEN_PATCH * h)).astype(np.int64)
        a = np.radians(BEATEN_TILT) * _hash01(gi[:, 0], gi[:, 1], 1)
        phi = 2 * np.pi * _hash01(gi[:, 0], gi[:, 1], 2)
        tilt_dir = np.cos(phi)[:, None] * t1 + np.sin(phi)[:, None] * t2
        tilt_dir = tilt_dir - np.einsum("ij,ij->i", tilt_dir, fnr[P])[:, None] * fnr[P]
        tilt_dir /= np.maximum(np.linalg.norm(tilt_dir, axis=1, keepdims=True), 1e-300)
        nn = np.cos(a)[:, None] * fnr[P] + np.sin(a)[:, None] * tilt_dir
        nrm[P] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
    cpos = cpos + lift[:, None] * fnr
    # each child is attached to its closest original (5.3), in the buffer's plane, among the
    # originals around the buffer that face it and are replaced (disabled, or by this event: a
    # visible original never has children); the owner's father is one of them. (A child that
    # inherited its owner's father drifted from it over repeated repaints, and downsampling then
    # grew the father to cover far children.)
    replaced = rows[rep_local]
    fcand, fuv = hidden_fathers(fathers, replaced, no, surface.active, surface.pos, surface.nrm, o, N, t1, t2)
    if len(fcand):
        _, nf = nearest(fuv, pu)
        fat = fcand[nf]
    else:
        fat = surface.father[rq]
    rad = CHILD_RADIUS * h / cosn
    new = {
        "pos": cpos, "nrm": nrm, "rad": rad, "father": fat, "active": np.ones(len(Q), bool),
        "alive": np.ones(len(Q), bool), "base": surface.base[rq], "wet": cw, "dry": dc,
        "vw": vw, "vd": vd, "area": area, "rho": rho, "kappa": kap, "diff": dif,
        "refl": refl, "shin": shin, "metal": met, "lift": lift, "updates": surface.updates[rq] + 1,
    }
    surface.delete(replaced)
    added = surface.append(new)
    return TransferResult(replaced, added, int(P.sum()))

