"""Closest-packing lattices and particle sampling of shapes (thesis section 8.2.1).

The material is sampled on a closest sphere packing: the hexagonal lattice in 2D
and the cubic closest packed (CCP, face-centred cubic) lattice of eq. (8.20) in
3D, both with nearest-neighbour distance ``d``. Both are Bravais lattices, so
every particle sees the same neighbourhood — the *lattice* ``L`` of eq. (8.21),
whose points within the kernel support are the particle's *slots*.

Fluids may instead be sampled on the simple cubic grid of spacing ``d``
(:func:`cubic_grid`, ``lattice="cubic"``), the usual initial state of SPH fluid
codes (e.g. SPlisHSPlasH): with ``h = 2d`` a particle has 26 neighbours at rest
(42 on the closest packing), so the fluid passes do less work per particle. Solids
need the closest packing: the lattice shape matching of section 8.2 assigns
neighbours to its slots.

Lattice coordinates are expressed in the lattice's own frame ``e1, e2, e3``
(eq. 8.20); a sampled object places that frame in the world with the rotation
:data:`LAYERS_HORIZONTAL` (3D: close-packed layers horizontal, ``e3`` = +y, so
objects rest flat on a floor), which is also the initial lattice transformation
``A_i`` of every particle.

Example
-------
>>> import numpy as np
>>> pts = closest_packing([0, 0, 0], [1, 1, 0], 0.25, dim=2)
>>> len(pts), float(pts[:, 2].max())
(16, 0.0)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError

__all__ = [
    "LATTICES",
    "LAYERS_HORIZONTAL",
    "closest_packing",
    "cubic_grid",
    "gradient_moment",
    "lattice_basis",
    "lattice_frame",
    "lattice_points",
    "lattice_slots",
    "nearest_lattice_point",
    "plane_spacings",
    "sample_shape",
]

#: Sampling lattices: ``"closest"`` (hexagonal / CCP, eq. 8.20; needed by solids) and ``"cubic"`` (fluids).
LATTICES = ("closest", "cubic")

#: World rotation of the 3D lattice frame: e1 -> +x, e2 -> -z, e3 -> +y (layers horizontal).
LAYERS_HORIZONTAL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _dim(dim: Any) -> int:
    if isinstance(dim, bool) or dim not in (2, 3):
        raise InputError(f"dim: expected 2 or 3, got {dim!r}")
    return int(dim)


def _lattice(lattice: Any) -> str:
    if lattice not in LATTICES:
        raise InputError(f"lattice: expected one of {', '.join(map(repr, LATTICES))}, got {lattice!r}")
    return str(lattice)


def lattice_basis(dim: int) -> np.ndarray:
    """Basis vectors (columns) of the unit closest packing, shape (3, 3).

    3D: eq. (8.20), ``b1 = e1``, ``b2 = ½e1 + √¾ e2``, ``b3 = ½e1 + √(1/12) e2 + √(2/3) e3``.
    2D: the hexagonal lattice ``b1 = e1``, ``b2 = ½e1 + √¾ e2``; the third column
    is ``e3`` (unused). A lattice point is ``d · B @ (i, j, k)`` for integers i, j, k.

    Example
    -------
    >>> B = lattice_basis(3)
    >>> np.round(np.linalg.norm(B, axis=0), 12)
    array([1., 1., 1.])
    """
    n = _dim(dim)
    b = np.zeros((3, 3))
    b[:, 0] = (1.0, 0.0, 0.0)
    b[:, 1] = (0.5, math.sqrt(0.75), 0.0)
    b[:, 2] = (0.5, math.sqrt(1.0 / 12.0), math.sqrt(2.0 / 3.0)) if n == 3 else (0.0, 0.0, 1.0)
    return b


def lattice_frame(dim: int) -> np.ndarray:
    """World rotation (3, 3) of the lattice frame used for sampling (initial ``A_i / d``).

    2D: the identity (rows along x). 3D: :data:`LAYERS_HORIZONTAL`.

    Example
    -------
    >>> (lattice_frame(3) @ lattice_basis(3)[:, 2]).round(3).tolist()   # third basis vector points up
    [0.5, 0.816, -0.289]
    """
    return np.eye(3) if _dim(dim) == 2 else LAYERS_HORIZONTAL.copy()


def lattice_slots(dim: int, radius_in_spacings: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lattice points ``0 < |l| < radius`` around a particle (its slots).

    Parameters
    ----------
    dim : int
        2 or 3.
    radius_in_spacings : float
        Support radius ``h / d`` (> 1). With the thesis' ``h = 2d`` there are 12
        slots in 2D (two shells) and 42 in 3D (three shells).

    Returns
    -------
    vectors : ndarray, shape (Q, 3), float64
        Slot vectors in lattice-frame coordinates, in units of ``d``, sorted by length.
    coords : ndarray, shape (Q, 3), int64
        Integer lattice coordinates (``vectors = coords @ B.T``).
    table : ndarray, shape (T, T, T), int64
        Slot index of integer coordinates ``c`` at ``table[c + T//2]``, -1 for
        non-slots (including the origin); ``T = 2 * ceil(2 radius) + 5`` covers every
        coordinate the nearest-point search can return for a slot.

    Example
    -------
    >>> v, c, t = lattice_slots(3, 2.0)
    >>> len(v), float(np.linalg.norm(v[0]))
    (42, 1.0)
    """
    n = _dim(dim)
    rad = positive_scalar(radius_in_spacings, "radius_in_spacings")
    if rad <= 1.0:
        raise InputError(f"radius_in_spacings: expected h/d > 1 so that nearest neighbours interact, got {rad}")
    b = lattice_basis(n)
    half = math.ceil(2.0 * rad) + 2
    rng = np.arange(-half, half + 1)
    if n == 2:
        ii, jj = np.meshgrid(rng, rng, indexing="ij")
        coords = np.stack([ii.ravel(), jj.ravel(), np.zeros(ii.size, np.int64)], axis=1)
    else:
        ii, jj, kk = np.meshgrid(rng, rng, rng, indexing="ij")
        coords = np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1)
    vecs = coords @ b.T
    length = np.linalg.norm(vecs, axis=1)
    keep = (length > 1e-9) & (length < rad * (1.0 - 1e-9))
    coords, vecs, length = coords[keep], vecs[keep], length[keep]
    order = np.lexsort((coords[:, 2], coords[:, 1], coords[:, 0], np.round(length, 9)))
    coords = np.ascontiguousarray(coords[order].astype(np.int64))
    vecs = np.ascontiguousarray(vecs[order])
    size = 2 * half + 1
    table = np.full((size, size, size), -1, np.int64)
    for q, c in enumerate(coords):
        table[c[0] + half, c[1] + half, c[2] + half] = q
    return vecs, coords, table


def lattice_points(dim: int, radius_in_spacings: float, lattice: str = "closest") -> np.ndarray:
    """The points ``0 < |l| < radius`` of a sampling lattice around a particle, in units of ``d``.

    ``"closest"``: the slots of :func:`lattice_slots` (lattice-frame coordinates);
    ``"cubic"``: the integer vectors of the simple cubic grid (2D: z = 0).

    Returns
    -------
    ndarray, shape (Q, 3), float64

    Example
    -------
    >>> len(lattice_points(3, 2.0)), len(lattice_points(3, 2.0, "cubic")), len(lattice_points(2, 2.0, "cubic"))
    (42, 26, 8)
    """
    n = _dim(dim)
    if _lattice(lattice) == "closest":
        return lattice_slots(n, radius_in_spacings)[0]
    rad = positive_scalar(radius_in_spacings, "radius_in_spacings")
    k = math.ceil(rad)
    rng = np.arange(-k, k + 1, dtype=np.float64)
    grids = np.meshgrid(rng, rng, rng if n == 3 else np.zeros(1), indexing="ij")
    vecs = np.stack([g.ravel() for g in grids], axis=1)
    length = np.linalg.norm(vecs, axis=1)
    keep = (length > 1e-9) & (length < rad * (1.0 - 1e-9))
    return np.ascontiguousarray(vecs[keep][np.argsort(length[keep], kind="stable")])


def nearest_lattice_point(y: Any, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point of the unit closest packing to each ``y`` (the minimisation of eq. 8.21).

    Rounds the lattice coordinates and searches the ``3^dim`` integer neighbours of
    the rounded point (exact for these reduced bases).

    Parameters
    ----------
    y : array_like, shape (K, 3)
        Points in lattice-frame coordinates, in units of ``d``.
    dim : int

    Returns
    -------
    coords : ndarray, shape (K, 3), int64
        Integer coordinates of the nearest lattice point (ties: first in search order).
    dist2 : ndarray, shape (K,), float64
        Squared distance to it.

    Example
    -------
    >>> c, d2 = nearest_lattice_point([[0.9, 0.1, 0.0]], 2)
    >>> c.tolist(), round(float(d2[0]), 6)
    ([[1, 0, 0]], 0.02)
    """
    n = _dim(dim)
    pts = as_array(y, "y", (None, 3))
    b = lattice_basis(n)
    c0 = np.rint(np.linalg.solve(b, pts.T).T)
    if n == 2:
        c0[:, 2] = 0.0
    offs = [(a, bb, cc) for a in (-1, 0, 1) for bb in (-1, 0, 1) for cc in ((-1, 0, 1) if n == 3 else (0,))]
    best = np.full(len(pts), np.inf)
    coords = np.zeros((len(pts), 3), np.int64)
    for o in offs:
        c = c0 + np.asarray(o, dtype=np.float64)
        d2 = np.sum((c @ b.T - pts) ** 2, axis=1)
        better = d2 < best
        best[better] = d2[better]
        coords[better] = c[better].astype(np.int64)
    return coords, best


def plane_spacings(dim: int, frame: Any = None) -> np.ndarray:
    """Spacing (3,) of the lattice planes perpendicular to the world axes, in units of d.

    The projections of the lattice points onto axis ``a`` form a 1D lattice of
    spacing ``s_a`` (0 when dense, e.g. for a rotated frame). Sampling a box puts
    the first plane ``s_a/2`` inside each face, so the particles fill the box the
    way the continuum walls of :mod:`unmesh.sph.boundary` assume.

    Example
    -------
    >>> np.round(plane_spacings(2), 4).tolist()
    [0.5, 0.866, 0.0]
    """
    n = _dim(dim)
    rot = lattice_frame(n) if frame is None else as_array(frame, "frame", (3, 3))
    m = rot @ lattice_basis(n)
    rng = np.arange(-4, 5)
    if n == 2:
        ii, jj = np.meshgrid(rng, rng, indexing="ij")
        coords = np.stack([ii.ravel(), jj.ravel(), np.zeros(ii.size)], axis=1)
    else:
        ii, jj, kk = np.meshgrid(rng, rng, rng, indexing="ij")
        coords = np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1)
    pts = coords @ m.T
    out = np.zeros(3)
    for a in range(n if n == 3 else 2):
        vals = np.unique(np.round(pts[:, a], 9))
        gaps = np.diff(vals)
        gaps = gaps[gaps > 1e-6]
        out[a] = float(gaps.min()) if len(gaps) and gaps.min() > 0.05 else 0.0
    return out


def closest_packing(lower: Any, upper: Any, spacing: float, dim: int = 3,
                    frame: Any = None, centered: bool = False) -> np.ndarray:
    """Closest-packing lattice points filling the box ``[lower, upper]``.

    Along each axis the lattice planes perpendicular to it (spacing ``s_a``,
    :func:`plane_spacings`) start ``s_a/2`` inside the box faces, so each
    particle stands for the volume around it and the box holds exactly its
    volume's worth of particles (a wall at the box face completes their density).

    Parameters
    ----------
    lower, upper : array_like, shape (3,)
        Box corners; in 2D only x and y are used and z = 0.
    spacing : float
        Nearest-neighbour distance ``d`` (> 0).
    dim : int
        2 (hexagonal lattice) or 3 (CCP, eq. 8.20).
    frame : array_like, shape (3, 3), optional
        World rotation of the lattice frame; default :func:`lattice_frame`.
    centered : bool
        Put a lattice point on the box's vertical centre line (x, and z in 3D, at the centre),
        so that the points are mirror-symmetric about the vertical plane ``x = centre`` (with the
        default frame). The box then holds its volume's worth of particles only up to one row,
        but a body dropped flat has no lopsided first row: solids are sampled this way.

    Returns
    -------
    ndarray, shape (N, 3), float64

    Example
    -------
    >>> p = closest_packing([-0.5, 0, 0], [0.5, 1, 0], 0.1, dim=2, centered=True)
    >>> bool(np.allclose(np.sort(p[:, 0]), np.sort(-p[:, 0])))
    True
    >>> p = closest_packing([0, 0, 0], [1, 1, 1], 0.1, dim=3)
    >>> d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(len(p))
    >>> round(float(d.min()), 12)
    0.1
    """
    n = _dim(dim)
    lo = as_array(lower, "lower", (3,)).copy()
    hi = as_array(upper, "upper", (3,)).copy()
    d = positive_scalar(spacing, "spacing")
    if n == 2:
        lo[2] = hi[2] = 0.0
    if np.any(hi < lo):
        raise InputError(f"upper: expected upper >= lower, got {lo.tolist()} and {hi.tolist()}")
    rot = lattice_frame(n) if frame is None else as_array(frame, "frame", (3, 3))
    margin = 0.5 * d * plane_spacings(n, rot)
    anchor = lo + margin
    if centered:
        anchor[0] = 0.5 * (lo[0] + hi[0])
        anchor[2] = 0.5 * (lo[2] + hi[2])
    if n == 2:
        anchor[2] = 0.0
    m = rot @ lattice_basis(n) * d  # world vectors of the integer coordinates
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    cc = np.linalg.solve(m, (corners - anchor).T).T
    cmin = np.floor(cc.min(axis=0)) - 1
    cmax = np.ceil(cc.max(axis=0)) + 1
    if n == 2:
        cmin[2] = cmax[2] = 0
    count = np.prod(cmax - cmin + 1)
    if count > 5e8:
        raise InputError(f"spacing: {d} gives about {count:.3g} lattice candidates in the box; use a larger spacing")
    axes = [np.arange(cmin[k], cmax[k] + 1) for k in range(3)]
    gi, gj, gk = np.meshgrid(*axes, indexing="ij")
    coords = np.stack([gi.ravel(), gj.ravel(), gk.ravel()], axis=1)
    pts = anchor + coords @ m.T
    tol = 1e-9 * max(1.0, float(np.abs(hi - lo).max()))
    inside = np.all((pts[:, :n] >= lo[:n] + margin[:n] - tol) & (pts[:, :n] <= hi[:n] - margin[:n] + tol), axis=1)
    out = pts[inside]
    if n == 2:
        out[:, 2] = 0.0
    order = np.lexsort((out[:, 0], out[:, 2], out[:, 1]))
    return np.ascontiguousarray(out[order])


def cubic_grid(lower: Any, upper: Any, spacing: float, dim: int = 3) -> np.ndarray:
    """Points of the simple cubic grid of spacing ``d`` filling the box ``[lower, upper]``.

    The grid planes start ``d/2`` inside the box faces (as in :func:`closest_packing`),
    so a box whose edges are multiples of ``d`` holds exactly ``volume / d³`` particles.

    Parameters
    ----------
    lower, upper : array_like, shape (3,)
        Box corners; in 2D only x and y are used and z = 0.
    spacing : float
        Grid spacing ``d`` (> 0).
    dim : int
        2 or 3.

    Returns
    -------
    ndarray, shape (N, 3), float64
        Sorted by height (y), then z, then x.

    Example
    -------
    >>> p = cubic_grid([0, 0, 0], [0.4, 0.2, 0.3], 0.1)
    >>> len(p), p.min(axis=0).round(6).tolist()
    (24, [0.05, 0.05, 0.05])
    """
    n = _dim(dim)
    lo = as_array(lower, "lower", (3,)).copy()
    hi = as_array(upper, "upper", (3,)).copy()
    d = positive_scalar(spacing, "spacing")
    if np.any(hi[:n] < lo[:n]):
        raise InputError(f"upper: expected upper >= lower, got {lo.tolist()} and {hi.tolist()}")
    tol = 1e-9 * max(1.0, float(np.abs(hi - lo).max()))
    counts = [math.floor((hi[a] - lo[a]) / d + tol / d) if a < n else 1 for a in range(3)]
    if float(np.prod(counts, dtype=np.float64)) > 5e8:
        raise InputError(f"spacing: {d} gives about {np.prod(counts, dtype=np.float64):.3g} grid points in the box; "
                         "use a larger spacing")
    axes = [lo[a] + (np.arange(counts[a]) + 0.5) * d if a < n else np.zeros(1) for a in range(3)]
    gi, gj, gk = np.meshgrid(*axes, indexing="ij")
    out = np.stack([gi.ravel(), gj.ravel(), gk.ravel()], axis=1)
    order = np.lexsort((out[:, 0], out[:, 2], out[:, 1]))
    return np.ascontiguousarray(out[order])


def sample_shape(shape: Any, spacing: float, dim: int = 3, frame: Any = None, lattice: str = "closest",
                 centered: bool = False) -> np.ndarray:
    """Particles on a closest packing (or the cubic grid) inside a shape (``shape.contains``).

    Parameters
    ----------
    shape : unmesh.shapes shape
        Anything with ``bounds() -> (2, 3)`` and ``contains(points) -> bool (N,)``,
        e.g. :class:`unmesh.shapes.Box` or a ``MeshShape``.
    spacing : float
        Nearest-neighbour distance ``d``.
    dim : int
        2: the shape's cross-section with the plane z = 0 is sampled.
    frame : array_like, shape (3, 3), optional
        Lattice frame rotation (default :func:`lattice_frame`; closest packing only).
    lattice : {"closest", "cubic"}
        :func:`closest_packing` or :func:`cubic_grid` (axis-aligned).
    centered : bool
        Closest packing centred on the bounds (see :func:`closest_packing`).

    Returns
    -------
    ndarray, shape (N, 3), float64
        Sorted by height (y), then z, then x.

    Example
    -------
    >>> from unmesh.shapes import Box
    >>> len(sample_shape(Box(size=(1.0, 1.0, 1.0)), 0.25, dim=2)), len(sample_shape(Box(size=(1.0, 1.0, 1.0)), 0.25, 2, lattice="cubic"))
    (16, 16)
    """
    bounds = np.asarray(shape.bounds(), dtype=np.float64)
    if _lattice(lattice) == "cubic":
        pts = cubic_grid(bounds[0], bounds[1], spacing, dim)
    else:
        pts = closest_packing(bounds[0], bounds[1], spacing, dim, frame, centered)
    if len(pts) == 0:
        return pts
    return np.ascontiguousarray(pts[np.asarray(shape.contains(pts), dtype=bool)])


def gradient_moment(dim: int, radius_in_spacings: float, lattice: str = "closest") -> float:
    """``−(1/n) tr Σ_j V_j (x_j − x_i) ⊗ ∇W_ij`` of the spiky kernel on the rest lattice.

    1 for a consistent gradient; SPH sums over a closest packing with ``h = 2d``
    give 0.872 (2D) and 0.949 (3D), i.e. pressure gradients (8.17) are
    underestimated by that factor (cubic grid: 0.874 and 0.947). Volumes ``V_j = m/ρ0``
    with the lattice mass (density exactly ``ρ0`` on the lattice, eq. 8.4).

    Example
    -------
    >>> round(gradient_moment(2, 2.0), 3), round(gradient_moment(3, 2.0), 3), round(gradient_moment(3, 2.0, "cubic"), 3)
    (0.872, 0.949, 0.947)
    """
    from unmesh.kernels import poly6, spiky_derivative

    vecs = lattice_points(dim, radius_in_spacings, lattice)
    r = np.linalg.norm(vecs, axis=1)
    h = float(radius_in_spacings)
    vol = 1.0 / (float(poly6(0.0, h, dim)) + float(np.sum(poly6(r, h, dim))))
    return float(-vol * np.sum(np.asarray(spiky_derivative(r, h, dim)) * r) / dim)
