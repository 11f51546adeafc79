"""Background work on a painted surface: drying (5.6.1), diffusion (5.6.2), downsampling (5.5.2).

All three are deterministic functions of the surface and ``dt``; the session runs them in
:meth:`unmesh.paint.Session.advance`, bounded by a budget in interactive use.

Example
-------
>>> import numpy as np
>>> vw = np.array([2.0, 0.0]); wet = np.array([[1.0, 0, 0], [0, 0, 1.0]]); props = np.zeros((2, 1))
>>> diffuse_pairs_reference(np.array([0]), np.array([1]), np.array([1.0]), vw, np.ones(2), wet, props, False)
>>> vw.tolist(), wet[1].tolist()
([1.0, 1.0], [1.0, 0.0, 0.0])
"""

from __future__ import annotations

import numpy as np

from unmesh.paint._paint_kernels import diffuse_pairs
from unmesh.paint.model import diffusion_coefficient, mix
from unmesh.paint.model import dry as dry_model
from unmesh.paint.surface import PaintSurface
from unmesh.spatial import KDTree

__all__ = ["DIFFUSION_NEIGHBOURS", "diffuse", "diffuse_pairs_reference", "downsample", "dry"]

#: Neighbours each wet surfel exchanges with per diffusion step (the "small neighbourhood").
DIFFUSION_NEIGHBOURS = 8
#: Columns of the surface blended with the diffusing paint.
PROPS = ("rho", "kappa", "diff", "refl", "shin", "metal")


def dry(surface: PaintSurface, dt: float, km: bool = False) -> int:
    """Dry the wet paint of the visible rows over ``dt`` (5.12/5.13); returns rows changed.

    Reflectivity and shininess drop with the dried fraction (the drying function G)."""
    if dt <= 0:
        return 0
    rows = surface.visible_rows()
    rows = rows[(surface.vw[rows] > 0) & (surface.kappa[rows] > 0)]
    if len(rows) == 0:
        return 0
    vw, dc, vd = dry_model(surface.wet[rows], surface.vw[rows], surface.dry[rows], surface.vd[rows],
                           surface.kappa[rows], dt, km)
    frac = 1.0 - np.exp(-surface.kappa[rows] * dt)
    surface.set("vw", rows, vw)
    surface.set("dry", rows, dc)
    surface.set("vd", rows, vd)
    surface.set("refl", rows, surface.refl[rows] * (1.0 - 0.5 * frac))
    surface.set("shin", rows, surface.shin[rows] * (1.0 - 0.3 * frac))
    return len(rows)


def diffuse_pairs_reference(pi: np.ndarray, pj: np.ndarray, coef: np.ndarray, vw: np.ndarray, area: np.ndarray,
                            wet: np.ndarray, props: np.ndarray, km: bool) -> None:
    """Plain reference of :func:`unmesh.paint._paint_kernels.diffuse_pairs` (in place)."""
    for p in range(len(pi)):
        i, j = int(pi[p]), int(pj[p])
        dv = 0.5 * (vw[i] / area[i] - vw[j] / area[j]) * min(area[i], area[j]) * coef[p]
        if dv == 0:
            continue
        s, r = (i, j) if dv > 0 else (j, i)
        dv = abs(dv)
        c, _ = mix(wet[r:r + 1], vw[r:r + 1], wet[s:s + 1], np.array([dv]), km)
        tot = vw[r] + dv
        props[r] = (vw[r] * props[r] + dv * props[s]) / tot
        wet[r] = c[0]
        vw[s] -= dv
        vw[r] = tot


def _local_rows(surface: PaintSurface, fathers: np.ndarray) -> np.ndarray:
    return surface.rows_of(fathers)


def diffusion_pairs(surface: PaintSurface, dt: float, tensor: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ordered pairs (i, j) and coefficients c_ij of one diffusion step: each visible row with
    wet paint and a diffusion coefficient, with its :data:`DIFFUSION_NEIGHBOURS` nearest visible
    rows (ordered by row, then neighbour distance)."""
    rows = surface.visible_rows()
    wet = rows[(surface.vw[rows] > 0) & (surface.diff[rows] > 0)]
    if len(wet) == 0 or dt <= 0:
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0)
    no = surface.n_original
    fathers = np.unique(surface.father[wet])
    reach = 3.0 * float(surface.rad[:no][fathers].max())
    _, ind = surface.tree.radius_neighbors(surface.pos[fathers], reach)
    local = _local_rows(surface, np.unique(ind))
    k = min(DIFFUSION_NEIGHBOURS + 1, len(local))
    _, nb = KDTree(surface.pos[local]).knn(surface.pos[wet], k)
    pi = np.repeat(wet, k)
    pj = local[nb.ravel()]
    keep = pi != pj
    pi, pj = pi[keep], pj[keep]
    x = surface.pos[pj] - surface.pos[pi]
    A = np.eye(3) if tensor is None else np.asarray(tensor, float)
    D = np.maximum(surface.diff[pi], surface.diff[pj])[:, None, None] * A
    c = diffusion_coefficient(x, D, dt)
    return pi, pj, c


def diffuse(surface: PaintSurface, dt: float, km: bool = False, tensor: np.ndarray | None = None) -> int:
    """One diffusion step (5.15) over ``dt``; returns the number of pair exchanges."""
    pi, pj, c = diffusion_pairs(surface, dt, tensor)
    if len(pi) == 0:
        return 0
    rows = np.unique(np.concatenate([pi, pj]))
    loc = {int(r): k for k, r in enumerate(rows)}
    li = np.array([loc[int(r)] for r in pi], np.int64)
    lj = np.array([loc[int(r)] for r in pj], np.int64)
    vw = surface.vw[rows].copy()
    wet = surface.wet[rows].copy()
    props = np.stack([getattr(surface, p)[rows] for p in PROPS], axis=1)
    diffuse_pairs(li, lj, c, vw, surface.area[rows].copy(), wet, props, km)
    surface.set("vw", rows, vw)
    surface.set("wet", rows, wet)
    for k, p in enumerate(PROPS):
        surface.set(p, rows, props[:, k])
    return len(pi)


def downsample(surface: PaintSurface, color_variance: float, normal_variance: float, budget: int | None = None,
               cursor: int = 0) -> int:
    """Merge the children of fathers whose children's colour and normal variance are below the
    thresholds back into the father (5.5.2); paint volumes are summed (conserved), colours mixed
    by volume. Checks ``budget`` fathers from ``cursor`` on (all when None); returns the next cursor."""
    n, no = surface.n, surface.n_original
    kids = np.arange(no, n)
    kids = kids[surface.alive[no:n]]
    if len(kids) == 0:
        return 0
    fa = surface.father[kids]
    fathers = np.unique(fa)
    if budget is not None:
        start = int(np.searchsorted(fathers, cursor))
        fathers = np.concatenate([fathers[start:], fathers[:start]])[:budget]
        nxt = int(fathers[-1]) + 1 if len(fathers) else 0
        sel = np.isin(fa, fathers)
        kids, fa = kids[sel], fa[sel]
    else:
        nxt = 0
    if len(kids) == 0:
        return nxt
    # per-father statistics by grouping (bincount over a compact father index)
    uf, g = np.unique(fa, return_inverse=True)
    m = len(uf)
    cnt = np.bincount(g, minlength=m).astype(np.float64)
    col = surface.colors(kids)
    mean = np.stack([np.bincount(g, col[:, c], m) for c in range(3)], axis=1) / cnt[:, None]
    sq = np.stack([np.bincount(g, col[:, c] ** 2, m) for c in range(3)], axis=1) / cnt[:, None]
    cvar = np.maximum(sq - mean ** 2, 0.0).sum(axis=1)
    nm = np.stack([np.bincount(g, surface.nrm[kids, c], m) for c in range(3)], axis=1) / cnt[:, None]
    nvar = 1.0 - np.linalg.norm(nm, axis=1)
    ok = (cvar <= color_variance) & (nvar <= normal_variance)
    if not ok.any():
        return nxt
    take = ok[g]
    kids, g = kids[take], g[take]
    remap = np.cumsum(ok) - 1
    g = remap[g]
    f = uf[ok]
    k = len(f)

    def gsum(v: np.ndarray) -> np.ndarray:
        return np.bincount(g, v, k)

    vw, vd, a = surface.vw[kids], surface.vd[kids], surface.area[kids]
    twv, tdv, ta = gsum(vw), gsum(vd), gsum(a)
    cnt = gsum(np.ones(len(kids)))
    wet = np.stack([gsum(vw * surface.wet[kids, c]) for c in range(3)], axis=1)
    wet_mean = np.stack([gsum(surface.wet[kids, c]) for c in range(3)], axis=1) / cnt[:, None]
    wet = np.where(twv[:, None] > 0, wet / np.where(twv > 0, twv, 1.0)[:, None], wet_mean)
    dryc = np.stack([gsum(vd * surface.dry[kids, c]) for c in range(3)], axis=1)
    dry_mean = np.stack([gsum(surface.dry[kids, c]) for c in range(3)], axis=1) / cnt[:, None]
    dryc = np.where(tdv[:, None] > 0, dryc / np.where(tdv > 0, tdv, 1.0)[:, None], dry_mean)
    surface.set("wet", f, np.clip(wet, 0, 1))
    surface.set("dry", f, np.clip(dryc, 0, 1))
    surface.set("vw", f, twv)
    surface.set("vd", f, tdv)
    for p in PROPS:
        surface.set(p, f, gsum(a * getattr(surface, p)[kids]) / ta)
    # the father stands for the children's area (the visible colour 5.8 stays the same); it is
    # reactivated as it was sampled (5.5.2): its children are those closest to it among the hidden
    # originals, so its own splat covers their region together with its neighbours' (enlarging it
    # to reach every child drew rings of oversized splats between painted strokes)
    surface.set("area", f, ta)
    surface.set("active", f, True)
    surface.delete(kids)
    return nxt
