"""SPH fluid equations as plain numpy references (thesis section 8.1).

Brute-force (all pairs within ``h``) versions of what the numba passes in
:mod:`unmesh.sph._kernels` compute, for tests and for readers:

- density (8.4): ``ρ_i = Σ_j m_j W_ij`` (poly6, self included);
- pressure (8.15) with the negative-pressure scale (8.16);
- pressure acceleration (8.17): ``−Σ_j m_j (p_i/ρ_i² + p_j/ρ_j² + R_ij (f_ij⁴ − 1)₊) ∇W_ij``
  (spiky), with Monaghan's (2000) tensile correction ``R_ij = ε (|p_i⁻|/ρ_i² + |p_j⁻|/ρ_j² + B c_i²/ρ_i
  + B c_j²/ρ_j)`` (negative parts of the pressure, plus a small background pressure) and ``f_ij = W(r_ij)/W(d/2)`` (poly6), here only for pairs closer than
  ``d/2``: it keeps tension from pulling particles onto each other (pairing);
- viscosity (8.18): ``μ∇²v/ρ`` in Monaghan's form
  ``2(n+2) Σ_j m_j μ̄/(ρ_iρ_j) (v_ij·x_ij)/(r² + 0.01h²) ∇W_ij`` — the kernel
  Laplacian of (8.12) is not sign-definite for poly6 or spiky (NOTES.md gives the
  true Laplacian ``w'' + (n−1)w'/r``); this first-derivative form is, and it is a
  central force, so it conserves linear and angular momentum;
- XSPH (8.19): ``Δv_i = ξ Σ_j 2m_j/(ρ_i+ρ_j) (v_j − v_i) W_ij`` (``(1−ξ)v + ξ⟨v⟩``
  written with the symmetric, momentum-conserving SPH average of ``v_j − v_i``);
- penalty collisions (8.37, :mod:`unmesh.sph.collisions`);
- the δ-SPH density filter (Molteni & Colagrossi 2009, Antuono et al. 2010) of
  :mod:`unmesh.sph._diffusion_kernels`, :func:`density_diffusion_reference`.

Example
-------
>>> import numpy as np
>>> x = np.array([[0.0, 0, 0], [0.05, 0, 0]])
>>> rho = density_reference(x, np.ones(2), 0.1, 2)
>>> bool(rho[0] == rho[1])
True
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points
from unmesh.kernels import poly6, spiky_derivative, spiky_gradient
from unmesh.sph._kernels import FROZEN_BAND, SOLID_TENSION_SUPPORT, TENSILE_BACKGROUND, TENSION_SUPPORT
from unmesh.sph.collisions import penalty_projection

__all__ = ["acceleration_reference", "density_diffusion_reference", "density_reference", "pressure", "xsph_reference"]


def _pairs(x: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    i, j = np.nonzero((d < h) & ~np.eye(len(x), dtype=bool))
    return i, j


def density_reference(x: Any, m: Any, h: float, dim: int) -> np.ndarray:
    """Summation density (8.4), shape (N,).

    Example
    -------
    >>> float(density_reference([[0.0, 0, 0]], [2.0], 1.0, 3)[0]) == 2 * 315 / (64 * np.pi)
    True
    """
    pts = as_points(x)
    mm = as_array(m, "m", (None,), length=len(pts))
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    return (np.asarray(poly6(d, h, dim)) * mm[None, :]).sum(axis=1)


def pressure(rho: Any, rho0: float, k: float, gamma: float = 1.0, zeta: float = 1.0,
             counts: Any = None, full: float = 0.0, fluid: bool = True, rho_t: Any = None) -> np.ndarray:
    """Eq. (8.15) ``K((ρ/ρ0)^Γ − 1)`` with negative values (tension) scaled by ζ (8.16).

    For fluids the tension is bounded as in :func:`unmesh.sph._kernels.fluid_pressure`: scaled by
    ``(ρ/ρ0)²`` and, with the neighbour ``counts`` (N,) of the particles and the count ``full`` on
    the rest lattice, by the share :data:`~unmesh.sph._kernels.TENSION_SUPPORT` that ramps linearly
    from 0 (``counts ≤ full/8``) to 1 (``counts ≥ full/4``). ``fluid=False`` (solids,
    :func:`unmesh.sph._kernels.solid_pressure`): the tension is measured from the tension reference
    density ``rho_t`` (N,) or scalar (None: ρ0; values above ρ0 count as ρ0): the law ``p_law`` at ``ρ ≥ ρ0``,
    ``p_law (ρ − ρ_b)/(ρ0 − ρ_b)`` in the band ``ρ_b = max(rho_t, FROZEN_BAND ρ0) ≤ ρ < ρ0``, 0 for
    ``rho_t ≤ ρ < ρ_b``, ``ζK((ρ/rho_t)^Γ − 1)`` below; that tension is scaled by the
    share of :data:`~unmesh.sph._kernels.SOLID_TENSION_SUPPORT` (0 up to ``full/16``, 1 from ``full/8``)
    and, below ``full/8``, capped at ``ζK (ρ/ρ0)²`` (acts below ``ρ ≈ 0.62 ρ0``).

    Example
    -------
    >>> pressure(np.array([1.1, 0.9]), 1.0, 100.0, zeta=0.5).round(9).tolist()
    [10.0, -4.05]
    >>> pressure(np.array([0.6, 0.3]), 1.0, 100.0, zeta=0.5, fluid=False, rho_t=0.5).round(9).tolist()
    [0.0, -20.0]
    """
    r = np.asarray(rho, dtype=np.float64)
    p = k * ((r / rho0) ** gamma - 1.0)
    by_count = np.ones_like(r)
    if counts is not None and full > 0:
        lo, hi = TENSION_SUPPORT if fluid else SOLID_TENSION_SUPPORT
        by_count = np.clip((np.asarray(counts, dtype=np.float64) / full - lo) / (hi - lo), 0.0, 1.0)
    if not fluid:
        ref = np.minimum(np.broadcast_to(np.asarray(rho0 if rho_t is None else rho_t, np.float64), r.shape), rho0)
        lo = np.maximum(ref, FROZEN_BAND * rho0)
        band = (r >= ref) & (r < rho0)  # the band back to the law, ramped from ρ_b = lo up to ρ0
        scale = np.where(band, np.clip(r - lo, 0.0, None) / np.where(band, rho0 - lo, 1.0), 1.0)
        ref = np.where(band, rho0, ref)
        t = k * ((r / ref) ** gamma - 1.0)  # the tension measured from the reference density
        capped = np.where(by_count < 1.0, np.maximum(zeta * by_count * t, -zeta * by_count * k * (r / rho0) ** 2), zeta * t)
        return np.where(p >= 0, p, scale * capped) + 0.0
    share = (r / rho0) ** 2 * by_count
    return np.where(p < 0, zeta * share * p, p)


def acceleration_reference(x: Any, v: Any, m: Any, rho: Any, p: Any, mu: Any, h: float, dim: int,
                           objects: Any = None, phases: Any = None, tensile: float = 0.0,
                           spacing: float | None = None, sound: Any = None, rest_density: Any = None) -> np.ndarray:
    """Pressure (8.17) + viscosity (8.18) accelerations by brute force, shape (N, 3).

    ``mu`` (N,) per-particle dynamic viscosity (pairs use the mean). With
    ``objects``/``phases`` the pair force between particles of different objects
    (one of them solid) is reduced to its repulsive part (8.37). ``tensile`` is ε of the tensile
    correction with the reference distance ``spacing`` (``d``); ``sound`` (N,) the particles' speeds of
    sound ``c`` of its background ``B c²/ρ`` (:data:`unmesh.sph._kernels.TENSILE_BACKGROUND`; None: 0).
    ``rest_density`` (N,) or scalar ρ0: the viscosity divides by ``max(ρ_i, ρ0_i) max(ρ_j, ρ0_j)`` (a
    summation density below ρ0 is the kernel's empty support; None: by ``ρ_i ρ_j``). The kernel
    (:func:`unmesh.sph._kernels.force_pass`) bounds fluid particles and solid fragments (fewer than 1/8 of
    the rest count of neighbours) only; this reference bounds every particle.

    Example
    -------
    >>> x = np.array([[0.0, 0, 0], [0.05, 0, 0]])
    >>> a = acceleration_reference(x, np.zeros((2, 3)), np.ones(2), np.ones(2), np.ones(2), np.zeros(2), 0.1, 2)
    >>> bool(a[0, 0] < 0 < a[1, 0])   # positive pressure pushes the pair apart
    True
    """
    pts = as_points(x)
    n = len(pts)
    vv = as_points(v, "v", length=n)
    mm, rr, pp, uu = (as_array(a, nm, (None,), length=n) for a, nm in ((m, "m"), (rho, "rho"), (p, "p"), (mu, "mu")))
    i, j = _pairs(pts, h)
    xij = pts[i] - pts[j]
    r2 = np.einsum("ij,ij->i", xij, xij)
    grad = spiky_gradient(xij[:, :dim], h)
    if dim == 2:
        grad = np.hstack([grad, np.zeros((len(grad), 1))])
    vx = np.einsum("ij,ij->i", vv[i] - vv[j], xij)
    mubar = 0.5 * (uu[i] + uu[j])
    pr = pp / rr ** 2
    rt = np.zeros(len(i))
    if tensile:
        f = np.asarray(poly6(np.sqrt(r2), h, dim)) / float(poly6(0.5 * spacing, h, dim))
        bg = np.zeros(n) if sound is None else TENSILE_BACKGROUND * np.asarray(sound, float) ** 2 / rr
        rt = tensile * (np.maximum(-pr[i], 0) + np.maximum(-pr[j], 0) + bg[i] + bg[j]) * np.maximum(f ** 4 - 1, 0)
    rv = rr if rest_density is None else np.maximum(rr, np.broadcast_to(np.asarray(rest_density, float), (n,)))
    bracket = -(pr[i] + pr[j] + rt) + 2.0 * (dim + 2) * mubar / (rv[i] * rv[j]) * vx / (r2 + 0.01 * h * h)
    f = (mm[j] * bracket)[:, None] * grad
    if objects is not None:
        ob = np.asarray(objects)
        ph = np.asarray(phases)
        other = (ob[i] != ob[j]) & ((ph[i] == 1) | (ph[j] == 1))
        f[other] = penalty_projection(xij[other], f[other])
    acc = np.zeros((n, 3))
    np.add.at(acc, i, f)
    return acc


def xsph_reference(x: Any, v: Any, m: Any, rho: Any, xi: float, h: float, dim: int) -> np.ndarray:
    """XSPH velocity corrections (8.19), shape (N, 3).

    Example
    -------
    >>> x = np.array([[0.0, 0, 0], [0.05, 0, 0]])
    >>> dv = xsph_reference(x, [[1.0, 0, 0], [0, 0, 0]], np.ones(2), np.ones(2), 0.5, 0.1, 2)
    >>> bool(dv[0, 0] < 0 < dv[1, 0])
    True
    """
    pts = as_points(x)
    n = len(pts)
    vv = as_points(v, "v", length=n)
    mm = as_array(m, "m", (None,), length=n)
    rr = as_array(rho, "rho", (None,), length=n)
    i, j = _pairs(pts, h)
    w = np.asarray(poly6(np.linalg.norm(pts[i] - pts[j], axis=1), h, dim))
    out = np.zeros((n, 3))
    np.add.at(out, i, (xi * 2.0 * mm[j] / (rr[i] + rr[j]) * w)[:, None] * (vv[j] - vv[i]))
    return out


def density_diffusion_reference(x: Any, m: Any, rho: Any, delta: float, h: float, dim: int,
                                fluid: Any = None) -> np.ndarray:
    """The δ-SPH filtered density ``ρ + δ D/Λ`` (Antuono-corrected diffusion), shape (N,).

    Brute force over all pairs within ``h``; ``fluid`` (N,) bool marks the particles that
    are filtered and serve as neighbours (default: all). Definitions of ``D``, ``Λ`` and
    the renormalised gradient: :mod:`unmesh.sph._diffusion_kernels`.

    Example
    -------
    >>> from unmesh.sph.sampling import closest_packing
    >>> x = closest_packing([0, 0, 0], [0.2, 0.2, 0], 0.02, 2)
    >>> rho = 1.0 + 0.01 * x[:, 1]                     # a linear (hydrostatic) field
    >>> out = density_diffusion_reference(x, np.ones(len(x)), rho, 1.0, 0.04, 2)
    >>> bool(np.abs(out - rho).max() < 1e-12)
    True
    """
    pts = as_points(x)
    n = len(pts)
    mm = as_array(m, "m", (None,), length=n)
    rr = as_array(rho, "rho", (None,), length=n)
    fl = np.ones(n, bool) if fluid is None else np.asarray(fluid, bool)
    i, j = _pairs(pts, h)
    keep = fl[i] & fl[j]
    i, j = i[keep], j[keep]
    xij = pts[i] - pts[j]
    r = np.linalg.norm(xij, axis=1)
    gf = np.asarray(spiky_derivative(r, h, dim)) / r        # w'(r)/r
    vj = mm[j] / rr[j]
    # L_i = (Σ_j V_j x_ji ⊗ ∇W_ij)⁻¹, ⟨∇ρ⟩_i = L_i Σ_j V_j (ρ_j − ρ_i) ∇W_ij
    amat = np.zeros((n, 3, 3))
    np.add.at(amat, i, (-vj * gf)[:, None, None] * xij[:, :, None] * xij[:, None, :])
    gsum = np.zeros((n, 3))
    np.add.at(gsum, i, (vj * gf * (rr[j] - rr[i]))[:, None] * xij)
    grad = np.zeros((n, 3))
    for a in np.flatnonzero(fl):
        sub = amat[a, :dim, :dim]
        if abs(np.linalg.det(sub)) > 1e-12 * np.prod(np.diag(sub)):
            grad[a, :dim] = np.linalg.solve(sub, gsum[a, :dim])
    psi = (rr[j] - rr[i]) + 0.5 * np.einsum("ij,ij->i", grad[i] + grad[j], xij)   # x_ji = −x_ij
    d = np.zeros(n)
    np.add.at(d, i, 2.0 * mm[j] / (rr[i] + rr[j]) * 2.0 * psi * (-gf))
    lam = (60.0 if dim == 3 else 80.0) / (h * h)
    return np.where(fl, rr + delta * d / lam, rr)
