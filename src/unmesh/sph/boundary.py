"""Solid walls: boundary particles (Akinci et al. 2012) and analytic planes.

Boundary particles
    Static particles sampled on the surface of a shape or mesh. Each carries the
    volume ``V_b = 1 / Σ_b' W(x_b − x_b')`` (Akinci et al., "Versatile rigid-fluid
    coupling for incompressible SPH", 2012), so a single, possibly irregular layer
    contributes ``ρ0 V_b W_ib`` to the density of a fluid particle (completing its
    neighbourhood) and repels it with ``−ρ0 V_b (p_i/ρ_i²) ∇W_ib``.

Analytic planes
    Infinite walls ``(x − p)·n ≥ 0`` (``n`` points into the fluid). Their density
    and pressure terms are the continuum limits of the boundary-particle sums over
    the half-space behind the wall: ``ρ0 Φ(d)`` with ``Φ(d) = ∫_{wall} W`` (poly6)
    and the force ``ρ0 (p_i/ρ_i²) P(|d|) n`` with ``P(d) = ∫_{plane at d} Ŵ`` (spiky;
    divergence theorem). Both depend only on the distance ``d`` and are tabulated
    once (:func:`wall_tables`). A box container is six (2D: four) planes.

Wall friction (``no_slip``)
    By default walls are free-slip: they only push along the normal. A no-slip wall
    also applies the fluid's own viscous term to the relative velocity of the wall
    (at rest), the boundary viscosity of Akinci et al. 2012 (eq. 11) written in the
    linear form of eq. (8.18): ``a_i = 2(n+2) ν_i Σ_b (ρ0 V_b/ρ_i) (v_i·x_ib)/(r² + 0.01h²) ∇W_ib``
    with the fluid's effective shear viscosity ``ν_i = μ/ρ0 + α c h / (4(n+2))`` (physical
    viscosity plus the shear part of Monaghan's artificial viscosity, which acts on the
    approaching half of the pairs only). So the wall shears the fluid exactly as a layer
    of the same fluid at rest would: no free parameter. For analytic planes the sum is
    the half-space integral ``∫ x xᵀ w'(r)/(r (r² + 0.01h²))``, diagonal in the wall
    frame and tabulated by :func:`wall_friction_tables`.

Example
-------
>>> rho_tab, grad_tab = wall_tables(1.0, 3)
>>> round(float(rho_tab[len(rho_tab) // 2]), 6)   # half the kernel mass at the wall
0.5
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, positive_scalar
from unmesh.errors import InputError
from unmesh.kernels import poly6, spiky, spiky_derivative

__all__ = [
    "BoundaryParticles",
    "Plane",
    "boundary_volumes",
    "box_planes",
    "corner_moment_tables",
    "corner_pairs",
    "corner_tables",
    "sample_boundary",
    "wall_friction_tables",
    "wall_moment_tables",
    "wall_tables",
]

#: Number of samples of the wall tables on [-h, h].
TABLE_SIZE = 1025


@dataclass(frozen=True)
class Plane:
    """An analytic wall through ``point`` with unit ``normal`` pointing into the fluid.

    ``no_slip``: the wall applies the fluid's viscosity to the fluid sliding along it
    (module docstring); default free-slip.

    Example
    -------
    >>> Plane((0, 0, 0), (0, 2, 0)).normal.tolist()
    [0.0, 1.0, 0.0]
    """

    point: np.ndarray
    normal: np.ndarray
    no_slip: bool = False

    def __post_init__(self) -> None:
        p = as_array(self.point, "point", (3,))
        n = as_array(self.normal, "normal", (3,))
        length = float(np.linalg.norm(n))
        if not length > 0:
            raise InputError("normal: expected a non-zero vector")
        object.__setattr__(self, "point", p)
        object.__setattr__(self, "normal", n / length)

    def distance(self, x: Any) -> np.ndarray:
        """Signed distance (N,) of points (N, 3), positive on the fluid side."""
        return (as_points(x) - self.point) @ self.normal


def box_planes(lower: Any, upper: Any, dim: int, open_top: bool = False, no_slip: bool = False) -> list[Plane]:
    """The walls of an axis-aligned box container (normals pointing inwards).

    Parameters
    ----------
    lower, upper : array_like, shape (3,)
    dim : int
        2: only the four walls normal to x and y.
    open_top : bool
        Omit the wall at ``upper[1]`` (gravity along −y).
    no_slip : bool
        Walls with friction (see :class:`Plane`).

    Example
    -------
    >>> len(box_planes([0, 0, 0], [1, 1, 1], 3)), len(box_planes([0, 0, 0], [1, 1, 0], 2, open_top=True))
    (6, 3)
    """
    lo = as_array(lower, "lower", (3,))
    hi = as_array(upper, "upper", (3,))
    axes = range(2) if dim == 2 else range(3)
    planes = []
    for a in axes:
        if not hi[a] > lo[a]:
            raise InputError(f"box: expected max > min along axis {a}, got {lo[a]} and {hi[a]}")
        n = np.zeros(3)
        n[a] = 1.0
        planes.append(Plane(lo.copy(), n, no_slip))
        if not (open_top and a == 1):
            planes.append(Plane(hi.copy(), -n, no_slip))
    return planes


def wall_tables(h: float, dim: int, size: int = TABLE_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Tabulated half-space integrals of the kernels for analytic walls.

    Parameters
    ----------
    h : float
        Support radius.
    dim : int
        2 or 3.
    size : int
        Samples on ``d ∈ [−h, h]`` (uniform).

    Returns
    -------
    rho : ndarray (size,)
        ``Φ(d) = ∫_{(y−p)·n < 0} W_poly6(x − y) dy`` for a particle at signed
        distance ``d`` (1 deep inside the wall, ½ on it, 0 beyond ``h``).
    grad : ndarray (size,)
        ``P(|d|) = ∫_{plane} Ŵ_spiky`` — the magnitude of ``∫_{wall} ∇Ŵ``.

    Example
    -------
    >>> r, g = wall_tables(0.1, 2)
    >>> bool(r[0] > 0.999 and r[-1] == 0.0 and g[-1] == 0.0)
    True
    """
    hh = positive_scalar(h, "h")
    z = np.linspace(-hh, hh, size)
    # plane integrals P(z) for z in [0, h] by Gauss-Legendre in the in-plane radius
    xg, wg = np.polynomial.legendre.leggauss(64)

    def plane_integral(kernel: Any, zz: np.ndarray) -> np.ndarray:
        zz = np.abs(zz)
        span = np.sqrt(np.maximum(hh * hh - zz * zz, 0.0))  # in-plane radius of the support
        s = 0.5 * (xg[None, :] + 1.0) * span[:, None]
        r = np.sqrt(s * s + zz[:, None] ** 2)
        vals = np.asarray(kernel(r, hh, dim=dim), dtype=np.float64)
        if dim == 3:
            vals = vals * 2.0 * np.pi * s
        else:
            vals = vals * 2.0
        return 0.5 * span * (vals * wg[None, :]).sum(axis=1)

    grad = plane_integral(spiky, z)
    # Phi(d) = ∫_d^h P_poly6(z) dz for d >= 0, 1 - Phi(-d) for d < 0
    fine = np.linspace(0.0, hh, 4 * size + 1)
    p6 = plane_integral(poly6, fine)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (p6[1:] + p6[:-1]) * np.diff(fine))])
    tail = cum[-1] - cum  # ∫_z^h
    tail = tail / (2.0 * cum[-1])  # exact normalisation: ∫_0^h P = 1/2
    phi_pos = np.interp(np.abs(z), fine, tail)
    rho = np.where(z >= 0.0, phi_pos, 1.0 - phi_pos)
    grad[z >= hh] = 0.0
    rho[z >= hh] = 0.0
    return np.ascontiguousarray(rho), np.ascontiguousarray(grad)


def _half_space_moments(h: float, dim: int, eps: float | None, size: int, order: int) -> np.ndarray:
    """``M(d) = ∫_{s·n > d, |s| < h} s sᵀ G(|s|) ds = Mt (I − n nᵀ) + Mn n nᵀ`` on ``d ∈ [−h, h]``,
    ``G(r) = ŵ'(r)/r`` (spiky), divided by ``r² + eps`` unless ``eps`` is None; shape (2, size)."""
    from unmesh.kernels import spiky_derivative

    hh = positive_scalar(h, "h")
    xg, wg = np.polynomial.legendre.leggauss(order)
    d = np.linspace(-hh, hh, size)
    out = np.zeros((2, size))
    for k, dk in enumerate(d[:-1]):
        z = dk + 0.5 * (xg + 1.0) * (hh - dk)  # s_n from d to h
        wz = 0.5 * (hh - dk) * wg
        span = np.sqrt(np.maximum(hh * hh - z * z, 0.0))  # in-plane radius of the support
        rho_in = 0.5 * (xg[None, :] + 1.0) * span[:, None]
        wr = 0.5 * span[:, None] * wg[None, :]
        r = np.sqrt(rho_in * rho_in + z[:, None] ** 2)
        g = np.asarray(spiky_derivative(r, hh, dim=dim)) / np.maximum(r, 1e-300)
        if eps is not None:
            g = g / (r * r + eps)
        if dim == 3:
            meas = 2.0 * np.pi * rho_in * wr * wz[:, None]
            out[0, k] = np.sum(0.5 * rho_in * rho_in * g * meas)
        else:
            meas = 2.0 * wr * wz[:, None]
            out[0, k] = np.sum(rho_in * rho_in * g * meas)
        out[1, k] = np.sum(z[:, None] ** 2 * g * meas)
    return np.ascontiguousarray(out)


def wall_friction_tables(h: float, dim: int, size: int = 513, order: int = 96) -> np.ndarray:
    """Half-space integrals of the no-slip wall viscosity, shape (2, size), on ``d ∈ [−h, h]``.

    For a particle at signed distance ``d`` from a wall, with offsets ``s = x − y``
    to the points ``y`` behind the wall (``s·n > d``, ``|s| < h``),
    ``M(d) = ∫ s sᵀ G(|s|) dy`` with ``G(r) = ŵ'(r) / (r (r² + 0.01h²))`` (spiky)
    is ``Mt (I − n nᵀ) + Mn n nᵀ``; row 0 holds ``Mt``, row 1 ``Mn`` (both ≤ 0, 0 beyond
    ``h``). The wall friction acceleration is ``2(n+2) ν (ρ0/ρ_i) M(d) v_i``: the continuum
    limit of the boundary-particle sum of the module docstring.

    Example
    -------
    >>> m = wall_friction_tables(1.0, 3, size=65)
    >>> bool(np.all(m <= 0) and m[0, -1] == 0 and m[0, 0] < m[0, 32] < 0)
    True
    """
    hh = positive_scalar(h, "h")
    return _half_space_moments(hh, dim, 0.01 * hh * hh, size, order)


def wall_moment_tables(h: float, dim: int, size: int = 513, order: int = 96) -> np.ndarray:
    """Half-space moments of the kernel gradient, shape (2, size), on ``d ∈ [−h, h]``.

    ``M(d) = ∫_{wall} s ⊗ ∇Ŵ(s) dy = ∫ s sᵀ ŵ'(|s|)/|s| dy = Mt (I − n nᵀ) + Mn n nᵀ``
    (offsets ``s = x − y`` to the points behind the wall; row 0 ``Mt``, row 1 ``Mn``, both
    in ``[−1, 0]``: ``−I`` deep inside the wall, ``−I/2`` on it, 0 beyond ``h``). It is the
    part of the pressure gradient that the fluid behind the wall would contribute to a linear
    pressure field: the hydrostatic wall pressure ``p_b(y) = p_i + ρ_i g·(y − x_i)``
    (Adami et al. 2012, walls at rest) adds ``(ρ0/ρ_i) M(d) g`` to the acceleration.

    Example
    -------
    >>> m = wall_moment_tables(1.0, 3, size=65)
    >>> round(float(m[0, 0]), 3), round(float(m[1, 32]), 3), float(m[0, -1])
    (-1.0, -0.5, 0.0)
    """
    return _half_space_moments(h, dim, None, size, order)


#: Samples per axis of the corner tables on [-h, h]².
CORNER_SIZE = 129


def corner_pairs(planes: list[Plane]) -> np.ndarray:
    """Index pairs (P, 2) int64 of perpendicular planes (box edges) for the corner correction.

    Example
    -------
    >>> corner_pairs(box_planes([0, 0, 0], [1, 1, 0], 2)).tolist()
    [[0, 2], [0, 3], [1, 2], [1, 3]]
    """
    pairs = [(a, b) for a in range(len(planes)) for b in range(a + 1, len(planes))
             if abs(float(planes[a].normal @ planes[b].normal)) < 1e-9]
    return np.asarray(pairs, dtype=np.int64).reshape(-1, 2)


def corner_tables(h: float, dim: int, size: int = CORNER_SIZE, fine: int = 800) -> tuple[np.ndarray, np.ndarray]:
    """Kernel integrals over the quarter-space behind two perpendicular walls.

    For a particle at signed distances ``d1, d2`` from walls with normals ``n1, n2``
    the region behind both is ``Q = {s : s·n1 < −d1, s·n2 < −d2}`` (offsets ``s``
    from the particle).

    Returns
    -------
    rho : ndarray (size, size)
        ``∫_Q W_poly6`` at ``(d1, d2)`` sampled on ``[−h, h]²`` (index 0 = −h).
    grad : ndarray (size, size)
        ``n1 · ∫_Q ∇_x Ŵ_spiky(x − y) dy`` (the ``n2`` component is ``grad.T``).

    Example
    -------
    >>> r, g = corner_tables(1.0, 2, size=33, fine=200)
    >>> round(float(r[16, 16]), 2), bool(r[0, 0] > 0.99)   # a quarter of the kernel at the corner
    (0.25, True)
    """
    hh = positive_scalar(h, "h")
    step = 2.0 * hh / fine
    c = -hh + (np.arange(fine) + 0.5) * step  # cell centres on [-h, h]
    s1, s2 = np.meshgrid(c, c, indexing="ij")
    rho_in = np.sqrt(s1 * s1 + s2 * s2)
    if dim == 2:
        w = np.asarray(poly6(rho_in, hh, dim=2))
        dspiky = np.asarray(spiky_derivative(rho_in, hh, dim=2))
        gfun = np.where(rho_in > 0, dspiky / np.where(rho_in > 0, rho_in, 1.0), 0.0)
        area = step * step
        wcol = w * area
        gcol = -s1 * gfun * area  # n1 component of ∇_x W(x - y) = -s/|s| w'
    else:
        xg, wg = np.polynomial.legendre.leggauss(48)
        span = np.sqrt(np.maximum(hh * hh - rho_in * rho_in, 0.0))
        t = 0.5 * (xg[None, None, :] + 1.0) * span[..., None]
        r = np.sqrt(rho_in[..., None] ** 2 + t * t)
        w3 = np.asarray(poly6(r, hh, dim=3))
        d3 = np.asarray(spiky_derivative(r, hh, dim=3))
        g3 = np.where(r > 0, d3 / np.where(r > 0, r, 1.0), 0.0)
        # integrate over t in [-span, span] (even integrands: twice [0, span])
        wcol = (w3 * wg).sum(axis=-1) * span * step * step
        gcol = -s1 * (g3 * wg).sum(axis=-1) * span * step * step
    # cumulative sums: value at cell (i, j) = sum over s1 <= c_i, s2 <= c_j
    cw = np.cumsum(np.cumsum(wcol, axis=0), axis=1)
    cg = np.cumsum(np.cumsum(gcol, axis=0), axis=1)
    edges = -hh + np.arange(1, fine + 1) * step  # upper edges of the cumulative cells
    d = np.linspace(-hh, hh, size)
    from scipy.interpolate import RegularGridInterpolator

    ew = np.concatenate([[-hh], edges])
    cw = np.pad(cw, ((1, 0), (1, 0)))
    cg = np.pad(cg, ((1, 0), (1, 0)))
    q1, q2 = np.meshgrid(-d, -d, indexing="ij")
    pts = np.stack([q1.ravel(), q2.ravel()], axis=1)
    rho = RegularGridInterpolator((ew, ew), cw)(pts).reshape(size, size)
    grad = RegularGridInterpolator((ew, ew), cg)(pts).reshape(size, size)
    return np.ascontiguousarray(rho), np.ascontiguousarray(grad)


def corner_moment_tables(h: float, dim: int, size: int = CORNER_SIZE, fine: int = 400) -> np.ndarray:
    """Kernel-gradient moments over the quarter-space behind two perpendicular walls, shape (3, size, size).

    With the region ``Q = {s : s·n1 < −d1, s·n2 < −d2}`` of :func:`corner_tables` and
    ``G(r) = ŵ'(r)/r`` (spiky), ``∫_Q s sᵀ G = Q11 n1n1ᵀ + Q22 n2n2ᵀ + Q12 (n1n2ᵀ + n2n1ᵀ) + Qee eeᵀ``
    (``e`` the edge direction, 3D): row 0 holds ``Q11`` (``Q22`` is its transpose), row 1 ``Q12``,
    row 2 ``Qee`` (0 in 2D), sampled at ``(d1, d2)`` on ``[−h, h]²``. Both walls' half-space moments
    (:func:`wall_moment_tables`) contain this region, so the hydrostatic wall pressure subtracts it once.

    Example
    -------
    >>> q = corner_moment_tables(1.0, 3, size=33, fine=200)
    >>> round(float(q[0, 0, 0]), 2), round(float(q[2, 0, 0]), 2), abs(round(float(q[1, 0, 0]), 3))  # the whole kernel: −I
    (-1.0, -1.0, 0.0)
    """
    hh = positive_scalar(h, "h")
    step = 2.0 * hh / fine
    c = -hh + (np.arange(fine) + 0.5) * step
    s1, s2 = np.meshgrid(c, c, indexing="ij")
    rho_in = np.sqrt(s1 * s1 + s2 * s2)
    if dim == 2:
        d2 = np.asarray(spiky_derivative(rho_in, hh, dim=2))
        g = np.where(rho_in > 0, d2 / np.where(rho_in > 0, rho_in, 1.0), 0.0) * step * step
        gt2 = np.zeros_like(g)
    else:
        xg, wg = np.polynomial.legendre.leggauss(48)
        span = np.sqrt(np.maximum(hh * hh - rho_in * rho_in, 0.0))
        t = 0.5 * (xg[None, None, :] + 1.0) * span[..., None]
        r = np.sqrt(rho_in[..., None] ** 2 + t * t)
        d3 = np.asarray(spiky_derivative(r, hh, dim=3))
        g3 = np.where(r > 0, d3 / np.where(r > 0, r, 1.0), 0.0)
        # ∫ over t in [−span, span] (even integrands): twice [0, span], Gauss weights on [0, span] carry span/2
        g = (g3 * wg).sum(axis=-1) * span * step * step
        gt2 = (g3 * t * t * wg).sum(axis=-1) * span * step * step
    cols = [s1 * s1 * g, s1 * s2 * g, gt2]
    ew = np.concatenate([[-hh], -hh + np.arange(1, fine + 1) * step])
    d = np.linspace(-hh, hh, size)
    q1, q2 = np.meshgrid(-d, -d, indexing="ij")
    pts = np.stack([q1.ravel(), q2.ravel()], axis=1)
    from scipy.interpolate import RegularGridInterpolator

    out = np.zeros((3, size, size))
    for k, col in enumerate(cols):
        cum = np.pad(np.cumsum(np.cumsum(col, axis=0), axis=1), ((1, 0), (1, 0)))
        out[k] = RegularGridInterpolator((ew, ew), cum)(pts).reshape(size, size)
    return np.ascontiguousarray(out)


def boundary_volumes(points: Any, h: float, dim: int) -> np.ndarray:
    """Akinci volumes ``V_b = 1 / Σ_b' W(x_b − x_b')`` (poly6, self included), shape (NB,).

    Example
    -------
    >>> v = boundary_volumes([[0.0, 0, 0], [0.05, 0, 0]], 0.1, 2)
    >>> bool(v[0] == v[1] and v[0] > 0)
    True
    """
    from unmesh.spatial import radius_neighbors

    pts = as_points(points)
    hh = positive_scalar(h, "h")
    off, ind = radius_neighbors(pts[:, :dim], hh)
    rows = np.repeat(np.arange(len(pts)), np.diff(off))
    r = np.linalg.norm(pts[rows] - pts[ind], axis=1)
    sums = np.bincount(rows, weights=np.asarray(poly6(r, hh, dim=dim)), minlength=len(pts))
    return 1.0 / sums


@dataclass(frozen=True, eq=False)
class BoundaryParticles:
    """Static boundary particles with their Akinci volumes.

    Parameters
    ----------
    positions : array_like, shape (NB, 3)
    volumes : array_like, shape (NB,)
    no_slip : bool or array_like of bool, shape (NB,)
        Wall friction per particle (module docstring); default free-slip.

    Example
    -------
    >>> len(BoundaryParticles([[0.0, 0, 0], [0.1, 0, 0]], [1e-3, 1e-3]))
    2
    """

    positions: np.ndarray
    volumes: np.ndarray
    no_slip: Any = False

    def __post_init__(self) -> None:
        pos = as_points(self.positions, "positions")
        vol = as_array(self.volumes, "volumes", (None,), length=len(pos))
        slip = np.asarray(self.no_slip)
        if slip.ndim == 0:
            slip = np.full(len(pos), bool(slip))
        if slip.shape != (len(pos),):
            raise InputError(f"no_slip: expected a bool or {len(pos)} bools, got shape {slip.shape}")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "volumes", vol)
        object.__setattr__(self, "no_slip", np.ascontiguousarray(slip.astype(np.uint8)))

    def __len__(self) -> int:
        return len(self.positions)


def _contour_2d(shape: Any, spacing: float) -> np.ndarray:
    """Points with spacing ≈ ``spacing`` on the cross-section of ``shape`` with z = 0."""
    from skimage import measure

    b = np.asarray(shape.bounds(), dtype=np.float64)
    step = spacing / 4.0
    xs = np.arange(b[0, 0] - 2 * step, b[1, 0] + 2 * step, step)
    ys = np.arange(b[0, 1] - 2 * step, b[1, 1] + 2 * step, step)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    vals = np.asarray(shape.implicit(pts)[0]).reshape(gx.shape)
    out = []
    for c in measure.find_contours(vals, 0.0):
        xy = np.stack([np.interp(c[:, 0], np.arange(len(xs)), xs), np.interp(c[:, 1], np.arange(len(ys)), ys)], axis=1)
        seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        if arc[-1] <= 0:
            continue
        k = max(1, round(arc[-1] / spacing))
        closed = np.allclose(xy[0], xy[-1])
        t = np.linspace(0.0, arc[-1], k, endpoint=not closed) if closed else np.linspace(0.0, arc[-1], k + 1)
        out.append(np.stack([np.interp(t, arc, xy[:, 0]), np.interp(t, arc, xy[:, 1]), np.zeros(len(t))], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 3))


def sample_boundary(shape: Any, spacing: float, h: float, dim: int, no_slip: bool = False) -> BoundaryParticles:
    """One layer of boundary particles on a shape's surface (2D: its z = 0 contour).

    Parameters
    ----------
    shape : unmesh.shapes shape
        Uses ``surfels(spacing)`` in 3D and ``implicit`` in 2D.
    spacing : float
        Sample spacing (typically the particle spacing ``d``).
    h : float
        Support radius (for the volumes).
    dim : int
    no_slip : bool
        Wall friction (module docstring).

    Example
    -------
    >>> from unmesh.shapes import Box
    >>> b = sample_boundary(Box(size=(1.0, 1.0, 1.0)), 0.1, 0.2, 2)
    >>> 36 <= len(b) <= 44
    True
    """
    d = positive_scalar(spacing, "spacing")
    if dim == 2:
        pts = _contour_2d(shape, d)
    else:
        pts = np.asarray(shape.surfels(d).positions, dtype=np.float64)
    if len(pts) == 0:
        raise InputError(f"boundary shape {shape!r} has no surface at the sampling spacing {d}"
                         + (" in the plane z = 0" if dim == 2 else ""))
    return BoundaryParticles(pts, boundary_volumes(pts, h, dim), no_slip)
