"""Marching cubes: the iso-surface of values sampled on a regular grid (the one implementation).

Used by the implicit shapes (``unmesh.shapes``: the blob, with the exact function to
refine the vertices) and by the SPH density surfaces (``unmesh.sph.surface``, section
8.2.7). The triangulation is scikit-image's (Lewiner et al. 2003, topologically
consistent, degenerate triangles removed); every vertex lies on a grid edge whose end
values bracket the level, and it is then placed on that edge

- at the exact root of ``function - level`` (Illinois regula falsi, to ``1e-14`` times
  the spacing) when the sampled function is given: vertices are on the surface to
  round-off, and every triangle stays in its cube (no folds);
- otherwise by linear interpolation of the two float64 end values: vertices are
  exactly at the level of the grid's (trilinear) interpolant.

Faces are counter-clockwise seen from outside, "inside" being where the values are
below the level (signed distances, ``inside="below"``) or above it (densities,
``inside="above"``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar, scalar
from unmesh.errors import InputError
from unmesh.meshes.triangles import TriangleMesh

__all__ = ["marching_cubes"]


def marching_cubes(values: Any, origin: Any = (0.0, 0.0, 0.0), spacing: float = 1.0, level: float = 0.0, *,
                   inside: str = "below", function: Callable[[np.ndarray], np.ndarray] | None = None) -> TriangleMesh:
    """Triangle mesh of the iso-surface ``values = level`` of a grid of samples.

    Parameters
    ----------
    values : array_like, shape (nx, ny, nz)
        Samples at the grid nodes ``origin + spacing * (i, j, k)`` (at least 2 per axis).
    origin : array_like, shape (3,)
        Position of node ``(0, 0, 0)``.
    spacing : float
        Edge of the (cubic) grid cells.
    level : float
        Iso-value.
    inside : {"below", "above"}
        Which side of the level is the solid; faces are oriented counter-clockwise
        seen from the other side (outward).
    function : callable, optional
        ``function(x)`` with ``x`` (N, 3) returns the sampled function (N,) at any
        points; vertices are then moved along their grid edge to its exact root.

    Returns
    -------
    TriangleMesh
        Empty (no vertices, no faces) when the values do not straddle the level.

    Example
    -------
    >>> import numpy as np
    >>> axis = np.linspace(-1.5, 1.5, 13)
    >>> x = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)
    >>> sdf = lambda p: np.linalg.norm(p, axis=-1) - 1.0
    >>> mesh = marching_cubes(sdf(x), origin=(-1.5, -1.5, -1.5), spacing=0.25, function=sdf)
    >>> bool(np.allclose(np.linalg.norm(mesh.vertices, axis=1), 1.0)), mesh.volume() > 4.0
    (True, True)
    """
    from skimage.measure import marching_cubes as skimage_marching_cubes

    vals = as_array(values, "values", (None, None, None))
    if min(vals.shape) < 2:
        raise InputError(f"values: expected at least 2 samples along every axis, got shape {vals.shape}")
    org = as_array(origin, "origin", (3,))
    step = positive_scalar(spacing, "spacing")
    lev = scalar(level, "level")
    if inside not in ("below", "above"):
        raise InputError(f"inside: expected 'below' or 'above', got {inside!r}")
    if not (vals.min() < lev < vals.max()):
        return TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    # skimage's default ("descent") faces are outward when the solid is below the level
    verts, faces, _, _ = skimage_marching_cubes(vals, level=lev, allow_degenerate=False)
    faces = faces.astype(np.int64)
    if inside == "above":
        faces = faces[:, ::-1].copy()
    counts = np.array(vals.shape, dtype=np.int64)
    base = np.floor(verts)
    frac = verts - base
    axis = np.argmax(frac, axis=1)
    on_edge = frac[np.arange(len(verts)), axis] > 0
    i0 = np.minimum(base.astype(np.int64), counts - 1)
    i1 = i0.copy()
    i1[np.arange(len(verts)), axis] += on_edge
    i1 = np.minimum(i1, counts - 1)
    f0 = vals[i0[:, 0], i0[:, 1], i0[:, 2]]
    f1 = vals[i1[:, 0], i1[:, 1], i1[:, 2]]
    if lev != 0.0:
        f0 = f0 - lev
        f1 = f1 - lev
    p0 = org + step * i0
    p1 = org + step * i1
    bracket = on_edge & (f0 * f1 <= 0)
    out = org + step * verts
    if bracket.any():
        if function is not None:
            func = function if lev == 0.0 else (lambda x: function(x) - lev)
            out[bracket] = _edge_roots(func, p0[bracket], p1[bracket], f0[bracket], f1[bracket], 1e-14 * step)
        else:
            a, b = f0[bracket], f1[bracket]
            t = np.where(a == b, 0.5, a / np.where(a == b, 1.0, a - b))
            out[bracket] = p0[bracket] + t[:, None] * (p1[bracket] - p0[bracket])
    return TriangleMesh(np.ascontiguousarray(out), np.ascontiguousarray(faces))


def _edge_roots(func: Callable[[np.ndarray], np.ndarray], p0: np.ndarray, p1: np.ndarray,
                f0: np.ndarray, f1: np.ndarray, tol: float, iterations: int = 60) -> np.ndarray:
    """Zero of ``func`` (values (N,)) on each segment p0 -> p1 (N,3) with ``f0 * f1 <= 0`` (Illinois regula falsi)."""
    ta = np.zeros(len(p0))
    tb = np.ones(len(p0))
    fa = f0.astype(np.float64).copy()
    fb = f1.astype(np.float64).copy()
    t = np.where(fa == fb, 0.5, fa / np.where(fa == fb, 1.0, fa - fb))
    active = np.flatnonzero((fa != 0) & (fb != 0))
    t[fa == 0] = 0.0
    t[(fb == 0) & (fa != 0)] = 1.0
    side = np.zeros(len(p0), np.int64)
    for _ in range(iterations):
        if not len(active):
            break
        ta_, tb_, fa_, fb_ = ta[active], tb[active], fa[active], fb[active]
        tt = (ta_ * fb_ - tb_ * fa_) / (fb_ - fa_)
        tt = np.clip(tt, np.minimum(ta_, tb_), np.maximum(ta_, tb_))
        ft = func(p0[active] + tt[:, None] * (p1[active] - p0[active]))
        t[active] = tt
        same_a = np.sign(ft) == np.sign(fa_)
        # replace the endpoint on the same side; halve the other value if it is kept twice (Illinois)
        ta[active] = np.where(same_a, tt, ta_)
        fa[active] = np.where(same_a, ft, np.where(side[active] == -1, 0.5 * fa_, fa_))
        tb[active] = np.where(same_a, tb_, tt)
        fb[active] = np.where(same_a, np.where(side[active] == 1, 0.5 * fb_, fb_), ft)
        side[active] = np.where(same_a, 1, -1)
        done = (np.abs(ft) <= tol) | (np.abs(tb[active] - ta[active]) <= 1e-15)
        active = active[~done]
    return p0 + t[:, None] * (p1 - p0)
