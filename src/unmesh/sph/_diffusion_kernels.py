"""Numba kernel of the δ-SPH density diffusion filter (Molteni & Colagrossi 2009, Antuono et al. 2010).

The fluid's density is the summation density (8.4), recomputed from the positions at
every step, so the δ-SPH diffusion term of the continuity equation has nothing to
accumulate into. It is applied instead as a filter of the summation density, once per
force evaluation, before the pressure (8.15) is taken from it:

``ρ̃_i = ρ_i + δ D_i / Λ`` (repeated ``density_passes`` times), with

``D_i = Σ_j 2 m_j/(ρ_i + ρ_j) · 2 ψ_ij · (x_ji·∇W_ij)/r_ij²``,
``ψ_ij = (ρ_j − ρ_i) − ½ (⟨∇ρ⟩_i + ⟨∇ρ⟩_j)·x_ji`` (Antuono's correction),
``⟨∇ρ⟩_i = L_i Σ_j V_j (ρ_j − ρ_i) ∇W_ij``, ``L_i = (Σ_j V_j x_ji ⊗ ∇W_ij)⁻¹`` (renormalised gradient),

``V_j = m_j/ρ_j``, spiky gradient ``∇W_ij = w'(r)/r · x_ij``. ``D_i`` approximates ``∇²ρ``;
``Λ = 4 ∫ −w'(r)/r dV`` (``80/h²`` in 2D, ``60/h²`` in 3D) is its largest eigenvalue on a
uniform neighbourhood, so ``δ ∈ [0, 1]`` is the fraction of the way from ``ρ_i`` to the
(linearly corrected) neighbour average: the particle-scale noise of a disordered
arrangement is removed while a linear density field (the hydrostatic column) passes
unchanged (``ψ_ij = 0`` exactly, the renormalised gradient being exact for linear fields).
The pair weights ``2 m_i m_j/(ρ_i + ρ_j)`` are symmetric and ``ψ_ij (x_ji·∇W_ij)`` is
antisymmetric, so ``Σ_i m_i (ρ̃_i − ρ_i) = 0`` to round-off.

Only fluid particles are filtered, and only with fluid neighbours of the same material
(same ``ρ0``); solid particles keep their summation density. Numpy reference:
:func:`unmesh.sph.fluid.density_diffusion_reference`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.sph import materials as M
from unmesh.sph._kernels import PLAIN, SOLID, fluid_pressure, kernel_gradf

__all__ = ["density_diffusion_pass", "laplacian_scale"]


@njit(**PLAIN)
def laplacian_scale(h, dim):
    """``Λ = 4 ∫ −w'(r)/r dV`` of the spiky kernel: ``80/h²`` (2D), ``60/h²`` (3D)."""
    return (60.0 if dim == 3 else 80.0) / (h * h)


@njit(**PLAIN)
def _pairs_ok(i, j, phase, matid):
    return phase[j] != SOLID and matid[j] == matid[i]


@njit(**PLAIN)
def _gradient(i, x, m, rho, phase, matid, nbr, nnbr, h, dim, out):
    """Renormalised density gradient ``⟨∇ρ⟩_i`` into ``out[i]`` (0 when ``L_i`` is singular)."""
    cap = nbr.shape[1]
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    g0 = g1 = g2 = 0.0
    for t in range(min(nnbr[i], cap)):
        j = nbr[i, t]
        if not _pairs_ok(i, j, phase, matid):
            continue
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if not r > 0.0:
            continue
        # V_j x_ji ⊗ ∇W_ij = −V_j gf x_ij ⊗ x_ij (symmetric)
        wv = -m[j] / rho[j] * kernel_gradf(r, h, dim)
        a00 += wv * d0 * d0
        a01 += wv * d0 * d1
        a02 += wv * d0 * d2
        a11 += wv * d1 * d1
        a12 += wv * d1 * d2
        a22 += wv * d2 * d2
        s = -wv * (rho[j] - rho[i])
        g0 += s * d0
        g1 += s * d1
        g2 += s * d2
    out[i, 0] = 0.0
    out[i, 1] = 0.0
    out[i, 2] = 0.0
    if dim == 2:
        det = a00 * a11 - a01 * a01
        if not abs(det) > 1e-12 * (a00 * a11 + 1e-300):
            return
        out[i, 0] = (a11 * g0 - a01 * g1) / det
        out[i, 1] = (a00 * g1 - a01 * g0) / det
        return
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if not abs(det) > 1e-12 * (a00 * a11 * a22 + 1e-300):
        return
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    out[i, 0] = (c00 * g0 + c01 * g1 + c02 * g2) / det
    out[i, 1] = (c01 * g0 + c11 * g1 + c12 * g2) / det
    out[i, 2] = (c02 * g0 + c12 * g1 + c22 * g2) / det


@njit(**PLAIN)
def _diffusion(i, x, m, rho, phase, matid, nbr, nnbr, h, dim, grad):
    """``D_i`` (see the module docstring)."""
    cap = nbr.shape[1]
    acc = 0.0
    for t in range(min(nnbr[i], cap)):
        j = nbr[i, t]
        if not _pairs_ok(i, j, phase, matid):
            continue
        d0 = x[j, 0] - x[i, 0]  # x_ji
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if not r > 0.0:
            continue
        psi = (rho[j] - rho[i]) - 0.5 * ((grad[i, 0] + grad[j, 0]) * d0 + (grad[i, 1] + grad[j, 1]) * d1
                                         + (grad[i, 2] + grad[j, 2]) * d2)
        # (x_ji·∇W_ij)/r² = −gf
        acc += 2.0 * m[j] / (rho[i] + rho[j]) * 2.0 * psi * (-kernel_gradf(r, h, dim))
    return acc


@njit(cache=True, parallel=True)
def density_diffusion_pass(x, m, rho, p, phase, matid, mats, nbr, nnbr, h, dim, grad, out, full):
    """Filter the density of every fluid particle in place and recompute its pressure (8.15–8.16).

    ``nbr`` / ``nnbr``: the neighbour lists of :func:`unmesh.sph._kernels.density_pass`
    (columns beyond ``nnbr`` ignored). ``grad`` (N, 3) and ``out`` (N,) are scratch (on
    return: the renormalised gradients and the densities of the last pass). The coefficient
    ``δ`` is the material column ``DENSITY_DIFFUSION``, the number of filter passes (each
    on the result of the previous one) the column ``DENSITY_PASSES``; particles with
    ``δ = 0`` and solid particles are left unchanged (pairs are fluid–fluid of one material,
    so a pair is filtered in the same passes from both sides). ``full``: as in
    :func:`unmesh.sph._kernels.density_pass` (the tension's share by neighbour count).
    """
    n = x.shape[0]
    lam = laplacian_scale(h, dim)
    passes = 0
    for i in range(mats.shape[0]):
        if mats[i, M.DENSITY_DIFFUSION] > 0.0:
            passes = max(passes, int(mats[i, M.DENSITY_PASSES]))
    for k in range(passes):
        for i in prange(n):
            mt = matid[i]
            if phase[i] != SOLID and mats[mt, M.DENSITY_DIFFUSION] > 0.0 and k < mats[mt, M.DENSITY_PASSES]:
                _gradient(i, x, m, rho, phase, matid, nbr, nnbr, h, dim, grad)
            else:
                grad[i, 0] = 0.0
                grad[i, 1] = 0.0
                grad[i, 2] = 0.0
        for i in prange(n):
            mt = matid[i]
            delta = mats[mt, M.DENSITY_DIFFUSION]
            if phase[i] != SOLID and delta > 0.0 and k < mats[mt, M.DENSITY_PASSES]:
                out[i] = rho[i] + delta * _diffusion(i, x, m, rho, phase, matid, nbr, nnbr, h, dim, grad) / lam
            else:
                out[i] = rho[i]
        for i in prange(n):
            if out[i] != rho[i]:
                mt = matid[i]
                rho[i] = out[i]
                p[i] = fluid_pressure(out[i], mats[mt, M.RHO0], mats[mt, M.K], mats[mt, M.GAMMA], mats[mt, M.ZETA],
                                      nnbr[i], full)


def empty_scratch(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Scratch arrays ``(grad, out)`` of :func:`density_diffusion_pass` for ``n`` particles."""
    return np.empty((n, 3)), np.empty(n)
