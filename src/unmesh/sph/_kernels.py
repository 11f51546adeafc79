"""Numba kernels of the weakly compressible SPH fluid (thesis section 8.1).

Particles are sorted by grid cell (``unmesh.spatial`` cell grid of edge ``h/2``,
:data:`CELL_FRACTION`); each particle scans only the cells that intersect its
support. Every pass is parallel over particles and writes only its own rows.
Numpy references: :mod:`unmesh.sph.fluid`.

Pass 1 ``density_pass``: neighbour lists (fixed capacity rows, self excluded),
density (8.4) with boundary-particle (Akinci et al. 2012) and analytic-wall
contributions, pressure (8.15) with the negative-pressure scale (8.16).

Pass 2 ``force_pass``: symmetric pressure acceleration (8.17, spiky gradient),
viscosity (8.18, Monaghan's central form of ``μ∇²v``, divided by ``max(ρ, ρ0)`` of fluid particles, plus Monaghan's artificial
viscosity between approaching particles, Monaghan's tensile correction below ``d/2`` with a
background pressure :data:`TENSILE_BACKGROUND`), XSPH
velocity correction (8.19), heat conduction (Cleary & Monaghan), penalty collisions between objects
(8.37: the repulsive part of the pair force plus, between two solids, a contact spring
``CONTACT · 2 min(K_e,i, K_e,j) m_j/ρ0 W (d − r)₊`` towards the rest distance), elastic forces gathered from the neighbourhoods (section
8.2), gravity.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.kernels._kernels import poly6_2d, poly6_3d, spiky_gradf_2d, spiky_gradf_3d
from unmesh.spatial._kernels import point_cell, stencil_ranges
from unmesh.sph import materials as M

#: Flags of helpers that the fast-math pair loops call: numba passes a caller's ``fastmath`` and
#: ``error_model`` on to callees that do not set them, so helpers (and the shared kernels they call)
#: set them explicitly and compile the same whoever calls them first.
PLAIN = {"cache": True, "fastmath": False, "error_model": "python"}

SOLID = 1
#: Contact springs between solid objects (8.37): ``CONTACT · 2 min(K_e,i, K_e,j)`` is their stiffness, half the
#: mean lattice stiffness (so that a particle touching several particles of another body stays
#: within the elastic step limit ``Δt √K_e ≲ 1.2``); 0.05 still let stiff dice come within 0.18 d.
CONTACT = 0.25
#: Regularisation ε h² of the viscosity and heat-conduction denominators.
EPS = 0.01
#: Background ``B`` of the tensile correction: besides the negative pressures it repels pairs closer
#: than ``d/2`` with ``B c_i²/ρ_i + B c_j²/ρ_j`` (about ``2 p_b/ρ²``, background pressure ``p_b = B ρ0 c² = B Γ K``,
#: 4 Pa in the dam break), so that particles at ``p ≈ 0`` (thin films, splashes) cannot be carried onto each
#: other either: with the negative pressures alone a pair in the film spreading on the dam break's floor
#: (p between −0.3 and 0 Pa) came within 0.299 d.
TENSILE_BACKGROUND = 0.002


@njit(**PLAIN)
def kernel_w(r2, h, dim):
    """poly6 W (C.1/C.4) for squared distance ``r2``."""
    if dim == 3:
        return poly6_3d(r2, h)
    return poly6_2d(r2, h)


@njit(**PLAIN)
def kernel_gradf(r, h, dim):
    """Spiky ``w'(r)/r`` (C.8/C.11): ``∇_i W_ij = gradf · x_ij``."""
    if dim == 3:
        return spiky_gradf_3d(r, h)
    return spiky_gradf_2d(r, h)




@njit(**PLAIN)
def poly6_coef(h, dim):
    """``c`` with ``W(r) = c (h² − r²)³`` for ``r < h`` (poly6, C.1/C.4): no division per pair."""
    h2 = h * h
    return kernel_w(0.0, h, dim) / (h2 * h2 * h2)


@njit(**PLAIN)
def spiky_coef(h, dim):
    """``c`` with ``w'(r)/r = c (h − r)²/r`` for ``0 < r < h`` (spiky, C.8/C.11)."""
    return 2.0 * kernel_gradf(0.5 * h, h, dim) / h


@njit(**PLAIN)
def _table(tab, dist, h):
    """Linear interpolation of a wall table sampled on [-h, h]."""
    if dist >= h:
        return 0.0
    n = tab.shape[0] - 1
    t = (dist + h) / (2.0 * h) * n
    if t <= 0.0:
        return tab[0]
    k = int(t)
    if k >= n:
        return tab[n]
    f = t - k
    return tab[k] * (1.0 - f) + tab[k + 1] * f


@njit(**PLAIN)
def _table2(tab, d1, d2, h):
    """Bilinear interpolation of a corner table sampled on [-h, h]² (0 beyond h)."""
    if d1 >= h or d2 >= h:
        return 0.0
    n = tab.shape[0] - 1
    t1 = min(max((d1 + h) / (2.0 * h) * n, 0.0), n - 1e-9)
    t2 = min(max((d2 + h) / (2.0 * h) * n, 0.0), n - 1e-9)
    i = int(t1)
    j = int(t2)
    f = t1 - i
    g = t2 - j
    return ((tab[i, j] * (1.0 - g) + tab[i, j + 1] * g) * (1.0 - f)
            + (tab[i + 1, j] * (1.0 - g) + tab[i + 1, j + 1] * g) * f)


@njit(**PLAIN)
def _plane_dist(x0, x1, x2, plane_p, plane_n, k):
    return ((x0 - plane_p[k, 0]) * plane_n[k, 0] + (x1 - plane_p[k, 1]) * plane_n[k, 1]
            + (x2 - plane_p[k, 2]) * plane_n[k, 2])


@njit(**PLAIN)
def _corner_hydrostatic(ka, kb, da, db, h, hyd, gravity, plane_n, corner_mom, out):
    """``hyd · M_Q g`` into ``out`` (3,): the hydrostatic wall pressure of the quarter-space behind the
    walls ``ka`` and ``kb`` (moments of :func:`unmesh.sph.boundary.corner_moment_tables`)."""
    q11 = _table2(corner_mom[0], da, db, h)
    q22 = _table2(corner_mom[0], db, da, h)
    q12 = _table2(corner_mom[1], da, db, h)
    qee = _table2(corner_mom[2], da, db, h)
    ga = gravity[0] * plane_n[ka, 0] + gravity[1] * plane_n[ka, 1] + gravity[2] * plane_n[ka, 2]
    gb = gravity[0] * plane_n[kb, 0] + gravity[1] * plane_n[kb, 1] + gravity[2] * plane_n[kb, 2]
    for c in range(3):
        ge = gravity[c] - ga * plane_n[ka, c] - gb * plane_n[kb, c]  # the edge component of g
        out[c] = hyd * ((q11 * ga + q12 * gb) * plane_n[ka, c] + (q12 * ga + q22 * gb) * plane_n[kb, c] + qee * ge)


#: Fractions of the rest lattice's neighbour count between which a particle's tension (negative
#: pressure, 8.16) fades in: none at or below the first (a particle of spray, an isolated pair or a
#: clump of a few particles is not a continuum that can be under tension), all of it from the second.
TENSION_SUPPORT = (0.125, 0.25)


@njit(**PLAIN)
def tension_scale(count, full):
    """Share of the tension ζ a particle with ``count`` neighbours carries (:data:`TENSION_SUPPORT`).

    ``full``: the neighbour count on the rest lattice (0: always 1).
    """
    if full <= 0.0:
        return 1.0
    f = (count / full - TENSION_SUPPORT[0]) / (TENSION_SUPPORT[1] - TENSION_SUPPORT[0])
    return min(max(f, 0.0), 1.0)


@njit(**PLAIN)
def pressure_eos(rho, rho0, k, gamma, zeta):
    """Eq. (8.15) with the negative-pressure scale ζ of eq. (8.16)."""
    if gamma == 1.0:
        p = k * (rho / rho0 - 1.0)
    else:
        p = k * ((rho / rho0) ** gamma - 1.0)
    if p < 0.0:
        p *= zeta
    return p


#: Share of the tension a solid particle carries by its neighbour count (fractions of the count on the
#: rest lattice): none up to 1/16 (3 in 3D), all from 1/8 (:func:`solid_pressure`).
SOLID_TENSION_SUPPORT = (0.0625, 0.125)
#: Lower end of the band below ρ0 (fraction of ρ0) in which a solid that froze at a lower density ramps back to
#: the law (8.16) (:func:`solid_pressure`).
FROZEN_BAND = 0.9


@njit(**PLAIN)
def solid_pressure(rho, rho0, k, gamma, zeta, count, full, rho_t):
    """:func:`pressure_eos` of a solid particle with ``count`` neighbours, its tension bounded.

    Solids keep the law (8.16) in their bulk and at their surfaces (their lattice forces carry tension;
    ``fluid_pressure``'s bounds broke the fracture scene's beam and the melting blob's ear), measured from
    the state the solid froze in: ``rho_t`` (≤ ρ0) is the particle's tension reference density, ρ0 for a
    solid from the start, the density its own object gave it at the step a fluid particle froze (at a free
    surface that is the kernel's empty support, not a stretched solid). With ``ρ_b = max(rho_t, FROZEN_BAND ρ0)``
    the pressure is the law ``p_law = K((ρ/ρ0)^Γ − 1)`` (ζ on its negative part) at ``ρ ≥ ρ0``, ``p_law (ρ − ρ_b)/(ρ0 − ρ_b)``
    for ``ρ_b ≤ ρ < ρ0``, 0 for ``rho_t ≤ ρ < ρ_b`` and ``ζK((ρ/rho_t)^Γ − 1)`` below ``rho_t`` (continuous; with
    ``rho_t = ρ0`` the law itself). So a freshly frozen surface particle has no tension until it is stretched
    beyond the state it froze in, and ice in the bulk (ρ near ρ0, e.g. among fluid) keeps most of the law's
    small tension, whose tensile correction keeps the fluid off it (with none there a slime particle came within
    0.27 d of the ice). Surface ice of the freezing rod that froze at ρ ≈ 0.4–0.6 ρ0 got the full tension
    (``p/ρ²`` to −700) the moment it froze and was pulled into the ice at 6–14 m/s.

    A fragment of a few particles is not a continuum either: the tension fades in with the neighbour
    count between :data:`SOLID_TENSION_SUPPORT` (half the fluid's thresholds, ``full`` the count on the
    rest lattice), and while it fades ``|p|/ρ² ≤ ζK/ρ0²`` (acts only below ``ρ ≈ 0.62 ρ0`` for Γ = 1; with
    the cap on every solid the fracture scene's beam broke off at another place). Ice fragments
    of 2–5 particles broken off the freezing rod (ζK = 150, ρ ≈ 0.35–0.6 ρ0, ``p/ρ²`` down to −700) were
    pulled onto each other (0.4 d) and rang at the time step, flying off at 8–11 m/s.
    """
    if rho >= rho0:
        return pressure_eos(rho, rho0, k, gamma, zeta)
    ref = min(rho_t, rho0)
    scale = 1.0
    if rho >= ref:  # the band near ρ0 back to the law (ref < ρ0 here)
        lo = max(ref, FROZEN_BAND * rho0)
        scale = max(rho - lo, 0.0) / (rho0 - lo)
        if scale == 0.0:
            return 0.0
        ref = rho0
    if full <= 0.0 or count >= SOLID_TENSION_SUPPORT[1] * full:
        return scale * pressure_eos(rho, ref, k, gamma, zeta)
    s = rho / rho0
    share = max((count / full - SOLID_TENSION_SUPPORT[0]) / (SOLID_TENSION_SUPPORT[1] - SOLID_TENSION_SUPPORT[0]), 0.0)
    return scale * max(pressure_eos(rho, ref, k, gamma, zeta * share), -zeta * share * k * s * s)


@njit(**PLAIN)
def fluid_pressure(rho, rho0, k, gamma, zeta, count, full):
    """:func:`pressure_eos` of a fluid particle with ``count`` neighbours, its tension bounded.

    A negative pressure is scaled by ``(ρ/ρ0)²``: the pair forces (8.17) divide it by ``ρ²``, so at
    the summation densities of a free surface (ρ far below ρ0) the linear law would give a tension
    force growing like ``1/ρ²``, stiffer than the time step (set by the speed of sound) resolves;
    scaled, ``|p|/ρ² ≤ ζK/ρ0²``. And ζ is scaled by :func:`tension_scale` (``full``: the neighbour
    count on the rest lattice). Near ``ρ0`` in the bulk both changes are of second order.
    """
    s = rho / rho0
    return pressure_eos(rho, rho0, k, gamma, zeta * tension_scale(count, full) * s * s)


@njit(cache=True, parallel=True)
def partner_pressure(rho, p, phase, obj, matid, mats, nbr, nnbr, full, rho_t):
    """Pressure (8.15–8.16) with the tension's share by count taken over the particle's tension partners.

    Particles of different objects, one of them solid, only repel each other (8.37): they carry no tension
    between them. The share of the tension by neighbour count (:func:`fluid_pressure`,
    :func:`solid_pressure`) therefore counts only the neighbours of the same object (or, between fluids,
    any): a clump of slime in a pocket of the freezing rod's ice, or a fragment of ice in the slime, is no
    more a continuum than in the air. Rewrites ``p`` (N,) of the particles that have other neighbours
    (run after the density pass when objects may collide; ``nbr``/``nnbr`` its neighbour lists; ``rho_t`` (N,) the
    solids' tension reference densities of :func:`solid_pressure`).
    """
    cap = nbr.shape[1] - 1
    for i in prange(rho.shape[0]):
        cnt = min(nnbr[i], cap)
        part = 0
        solid_i = phase[i] == SOLID
        for t in range(cnt):
            j = nbr[i, t]
            part += obj[j] == obj[i] or not (solid_i or phase[j] == SOLID)
        if part == cnt:
            continue
        part += nnbr[i] - cnt
        mt = matid[i]
        if solid_i:
            p[i] = solid_pressure(rho[i], mats[mt, M.RHO0], mats[mt, M.K], mats[mt, M.GAMMA], mats[mt, M.ZETA], part,
                                  full, rho_t[i])
        else:
            p[i] = fluid_pressure(rho[i], mats[mt, M.RHO0], mats[mt, M.K], mats[mt, M.GAMMA], mats[mt, M.ZETA], part,
                                  full)


#: Cell edge of the particle grid in units of ``h``: with ``h/2`` cells the per-particle
#: stencil of :func:`density_pass` visits about a third of the points of the 27 cells of edge ``h``.
CELL_FRACTION = 0.5
#: Largest virtual grid (cells per particle) for which :func:`dense_starts` is built.
DENSE_CELLS_PER_PARTICLE = 32


@njit(cache=True, parallel=True)
def dense_starts(cell_keys, cell_start, nkeys, out):
    """Start of every virtual cell: ``out[key]`` = first sorted point with cell key ``>= key``.

    ``cell_keys`` (C,) / ``cell_start`` (C+1,) are the grid's non-empty cells; ``out``
    (nkeys+1,) int64, so the points of cells ``key0..key1`` are ``out[key0]:out[key1 + 1]``.
    """
    nc = cell_keys.shape[0]
    for c in prange(nc + 1):
        lo = cell_keys[c - 1] + 1 if c > 0 else 0
        hi = cell_keys[c] if c < nc else nkeys
        val = cell_start[c]
        for key in range(lo, hi + 1):
            out[key] = val


@njit(**PLAIN)
def _cell_index(t, n):
    """``floor(t)`` clamped to ``[0, n - 1]`` (as :func:`unmesh.spatial._kernels.point_cell`)."""
    if not t > 0.0:
        return 0
    if t >= n - 1:
        return n - 1
    return int(t)


@njit(**PLAIN)
def _gap(x, k, origin, cell, n):
    """Distance from coordinate ``x`` to cell slab ``k`` (0 inside; edge cells are unbounded)."""
    if k > 0:
        lo = origin + k * cell
        if x < lo:
            return lo - x
    if k < n - 1:
        hi = origin + (k + 1) * cell
        if x > hi:
            return x - hi
    return 0.0


#: Particles per block of the parallel passes (the unit that owns per-thread scratch buffers).
BLOCK = 64


@njit(cache=True)
def _axis_gaps(xa, c, reach, origin, cell, n, out):
    """Squared distance from coordinate ``xa`` to the cell slabs ``c - reach .. c + reach``
    (0 for the own slab, ``inf`` for slabs outside the grid)."""
    for s in range(2 * reach + 1):
        k = c - reach + s
        if k < 0 or k >= n:
            out[s] = np.inf
        else:
            g = _gap(xa, k, origin, cell, n)
            out[s] = g * g


@njit(**PLAIN)
def _density_rest(r0, r1, x, matid, mats, h, dim, bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr, nbnbr,
                  plane_p, plane_n, wall_rho, corners, corner_rho, nnbr, rho, p, phase, full, rho_t):
    """Particles ``r0 .. r1 - 1`` of :func:`density_pass` once ``rho`` holds their particle sums and ``nnbr``
    their neighbour counts: boundary particles, analytic walls, density and pressure (one call per block:
    a call per particle would pass its two dozen arguments each time)."""
    h2 = h * h
    c6 = poly6_coef(h, dim)
    bcap = bnbr.shape[1]
    branges = np.empty((9, 2), np.int64)
    for a in range(r0, r1):
        rho_a = rho[a]
        cnt = nnbr[a]
        xa0 = x[a, 0]
        xa1 = x[a, 1]
        xa2 = x[a, 2]
        mt = matid[a]
        rho0 = mats[mt, M.RHO0]
        bcnt = 0
        if bx.shape[0] > 0:
            bi, bj, bk = point_cell(x[a], borigin, binv_cell, bdims)
            nbs = stencil_ranges(bi, bj, bk, 1, bdims, bkeys, bstart, branges)
            for s in range(nbs):
                for b in range(branges[s, 0], branges[s, 1]):
                    d0 = xa0 - bx[b, 0]
                    d1 = xa1 - bx[b, 1]
                    d2 = xa2 - bx[b, 2]
                    r2 = d0 * d0 + d1 * d1 + d2 * d2
                    if r2 < h2:
                        t6 = h2 - r2
                        rho_a += rho0 * bvol[b] * (c6 * t6 * t6 * t6)
                        if bcnt < bcap:
                            bnbr[a, bcnt] = b
                        bcnt += 1
        nbnbr[a] = bcnt
        for k in range(plane_p.shape[0]):
            dist = _plane_dist(xa0, xa1, xa2, plane_p, plane_n, k)
            if dist < h:
                rho_a += rho0 * _table(wall_rho, dist, h)
        for k in range(corners.shape[0]):
            da = _plane_dist(xa0, xa1, xa2, plane_p, plane_n, corners[k, 0])
            db = _plane_dist(xa0, xa1, xa2, plane_p, plane_n, corners[k, 1])
            if da < h and db < h:
                rho_a -= rho0 * _table2(corner_rho, da, db, h)
        rho[a] = rho_a
        if phase[a] == SOLID:
            p[a] = solid_pressure(rho_a, rho0, mats[mt, M.K], mats[mt, M.GAMMA], mats[mt, M.ZETA], cnt, full, rho_t[a])
        else:
            p[a] = fluid_pressure(rho_a, rho0, mats[mt, M.K], mats[mt, M.GAMMA], mats[mt, M.ZETA], cnt, full)


@njit(**PLAIN)
def _density_block(r0, r1, x, xm, matid, mats, h, dim, origin, inv_cell, dims, cell_keys, cell_start, dense, nbr, nnbr,
                   bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr, nbnbr, plane_p, plane_n, wall_rho, corners,
                   corner_rho, rho, p, phase, full, rho_t, hs, cand, ncand):
    """Particles ``r0 .. r1 - 1`` of :func:`density_pass` (one block, serial)."""
    h2 = h * h
    want = cand.shape[0] > 0  # also store the candidates within hs (Verlet lists)
    reach_r = hs if want else h
    hs2 = hs * hs
    hr = reach_r * (1.0 + 1e-9)  # conservative reach (round-off of the cell bounds)
    hr2 = hr * hr
    cell = 1.0 / inv_cell
    cap = nbr.shape[1] - 1
    ccap = cand.shape[1] - 1
    c6 = poly6_coef(h, dim)
    use_dense = dense.shape[0] > 0
    reach = math.ceil(hr * inv_cell)
    width = 2 * reach + 1
    rows = width * width
    d0_, d1_, d2_ = dims[0], dims[1], dims[2]
    o0, o1, o2 = origin[0], origin[1], origin[2]
    g0 = np.empty(width)
    g1 = np.empty(width)
    g2 = np.empty(width)
    ranges = np.empty((rows, 2), np.int64)
    for a in range(r0, r1):
        xa0 = xm[a, 0]
        xa1 = xm[a, 1]
        xa2 = xm[a, 2]
        rho_a = 0.0
        cnt = 0
        cc = 0
        if use_dense:
            c0 = _cell_index((xa0 - o0) * inv_cell, d0_)
            c1 = _cell_index((xa1 - o1) * inv_cell, d1_)
            c2 = _cell_index((xa2 - o2) * inv_cell, d2_)
            _axis_gaps(xa0, c0, reach, o0, cell, d0_, g0)
            _axis_gaps(xa1, c1, reach, o1, cell, d1_, g1)
            _axis_gaps(xa2, c2, reach, o2, cell, d2_, g2)
            for si in range(width):
                rem = hr2 - g0[si]
                if not rem > 0.0:
                    continue
                ii = c0 - reach + si
                for sj in range(width):
                    rem2 = rem - g1[sj]
                    if not rem2 > 0.0:
                        continue
                    # the z slabs within reach: squared gaps grow away from c2 on both sides
                    klo = c2 - reach
                    khi = c2 + reach
                    for s in range(reach):
                        klo += g2[s] >= rem2
                        khi -= g2[width - 1 - s] >= rem2
                    base = (ii * d1_ + sj + c1 - reach) * d2_
                    if want:
                        for b in range(dense[base + klo], dense[base + khi + 1]):
                            d0 = xa0 - xm[b, 0]
                            d1 = xa1 - xm[b, 1]
                            d2 = xa2 - xm[b, 2]
                            r2 = d0 * d0 + d1 * d1 + d2 * d2
                            t6 = max(h2 - r2, 0.0)
                            rho_a += xm[b, 3] * (c6 * t6 * t6 * t6)
                            nbr[a, min(cnt, cap)] = b
                            cnt += (r2 < h2) & (b != a)
                            cand[a, min(cc, ccap)] = b
                            cc += r2 < hs2
                    else:
                        for b in range(dense[base + klo], dense[base + khi + 1]):
                            d0 = xa0 - xm[b, 0]
                            d1 = xa1 - xm[b, 1]
                            d2 = xa2 - xm[b, 2]
                            r2 = d0 * d0 + d1 * d1 + d2 * d2
                            t6 = max(h2 - r2, 0.0)
                            rho_a += xm[b, 3] * (c6 * t6 * t6 * t6)
                            nbr[a, min(cnt, cap)] = b
                            cnt += (r2 < h2) & (b != a)
        else:
            ci, cj, ck = point_cell(x[a], origin, inv_cell, dims)
            ns = stencil_ranges(ci, cj, ck, reach, dims, cell_keys, cell_start, ranges)
            for s in range(ns):
                for b in range(ranges[s, 0], ranges[s, 1]):
                    d0 = xa0 - xm[b, 0]
                    d1 = xa1 - xm[b, 1]
                    d2 = xa2 - xm[b, 2]
                    r2 = d0 * d0 + d1 * d1 + d2 * d2
                    t6 = max(h2 - r2, 0.0)
                    rho_a += xm[b, 3] * (c6 * t6 * t6 * t6)
                    nbr[a, min(cnt, cap)] = b
                    cnt += (r2 < h2) & (b != a)
                    if want:
                        cand[a, min(cc, ccap)] = b
                        cc += r2 < hs2
        nnbr[a] = cnt
        rho[a] = rho_a
        if want:
            ncand[a] = cc
    _density_rest(r0, r1, x, matid, mats, h, dim, bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr, nbnbr,
                  plane_p, plane_n, wall_rho, corners, corner_rho, nnbr, rho, p, phase, full, rho_t)


@njit(cache=True, parallel=True)
def density_pass(x, m, matid, mats, h, dim, origin, inv_cell, dims, cell_keys, cell_start, dense, xm, nbr, nnbr,
                 bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr, nbnbr,
                 plane_p, plane_n, wall_rho, corners, corner_rho, rho, p, phase, full, rho_t, hs, cand, ncand):
    """Neighbour lists, density (8.4) and pressure (8.15–8.16) of every particle.

    ``x`` (N, 3) must be the grid's sorted points (z = 0 in 2D); any cell size works.
    With ``dense`` (:func:`dense_starts`; empty: use the sparse cell list) each particle
    visits only the cells that intersect its support sphere: along every grid row
    ``(i, j)`` in reach, the run of cells within ``√(h² − d_ij²)`` in z (found by comparing
    squared slab gaps, no square roots), one contiguous slice of the sorted points.
    ``xm`` (N, 4) is scratch: ``(x, y, z, m)`` rows, one 32-byte load per candidate. The candidate loop is branch-free:
    every candidate adds ``m_b c (h² − r²)₊³`` (which is 0 beyond ``h`` and the self term
    ``m_a W(0)`` for ``b = a``) and is written at the next free position of the row, which
    advances only for neighbours. ``nbr`` (N, cap + 1) int32 therefore receives the
    neighbours within ``h`` (self excluded, ascending) in its first ``cap`` columns (the
    last column is scratch); ``nnbr`` the true counts (may exceed ``cap``: the caller grows
    ``nbr`` and repeats). ``bnbr`` / ``nbnbr`` the same for boundary particles ``bx``
    (static grid ``b*``; ``bnbr`` has no scratch column). Fluid particles (``phase``) get
    :func:`fluid_pressure` with ``full``, the neighbour count on the rest lattice (0: no share by
    count); solid ones :func:`solid_pressure` with their tension reference densities ``rho_t`` (N,) (their
    lattice forces carry tension: either bound of the fluid changed how the fracture scene's beam breaks or the
    melting blob's ear holds on; only the cap far below ρ0).

    Verlet lists: with ``cand`` (N, ccap + 1) int32 non-empty (``(0, 1)``: none) the scan reaches
    ``hs >= h`` instead of ``h`` and also stores every particle within ``hs`` (itself included, ascending)
    in ``cand`` and their true count in ``ncand`` (N,) int64 (may exceed ``ccap``: grow and repeat), for
    :func:`density_list_pass`. Density, pressure and neighbour lists are the same as without.
    """
    n = x.shape[0]
    for a in prange(n):
        xm[a, 0] = x[a, 0]
        xm[a, 1] = x[a, 1]
        xm[a, 2] = x[a, 2]
        xm[a, 3] = m[a]
    nblk = (n + BLOCK - 1) // BLOCK
    for blk in prange(nblk):
        _density_block(blk * BLOCK, min(n, (blk + 1) * BLOCK), x, xm, matid, mats, h, dim, origin, inv_cell, dims,
                       cell_keys, cell_start, dense, nbr, nnbr, bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr,
                       nbnbr, plane_p, plane_n, wall_rho, corners, corner_rho, rho, p, phase, full, rho_t, hs, cand, ncand)


@njit(**PLAIN)
def _density_list_block(r0, r1, x, xm, matid, mats, h, dim, cand, ncand, nbr, nnbr, bx, bvol, borigin, binv_cell,
                        bdims, bkeys, bstart, bnbr, nbnbr, plane_p, plane_n, wall_rho, corners, corner_rho, rho, p,
                        phase, full, rho_t):
    """Particles ``r0 .. r1 - 1`` of :func:`density_list_pass` (one block, serial)."""
    h2 = h * h
    cap = nbr.shape[1] - 1
    c6 = poly6_coef(h, dim)
    for a in range(r0, r1):
        xa0 = xm[a, 0]
        xa1 = xm[a, 1]
        xa2 = xm[a, 2]
        rho_a = 0.0
        cnt = 0
        for t in range(ncand[a]):
            b = cand[a, t]
            d0 = xa0 - xm[b, 0]
            d1 = xa1 - xm[b, 1]
            d2 = xa2 - xm[b, 2]
            r2 = d0 * d0 + d1 * d1 + d2 * d2
            t6 = max(h2 - r2, 0.0)
            rho_a += xm[b, 3] * (c6 * t6 * t6 * t6)
            nbr[a, min(cnt, cap)] = b
            cnt += (r2 < h2) & (b != a)
        nnbr[a] = cnt
        rho[a] = rho_a
    _density_rest(r0, r1, x, matid, mats, h, dim, bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr, nbnbr,
                  plane_p, plane_n, wall_rho, corners, corner_rho, nnbr, rho, p, phase, full, rho_t)


@njit(cache=True, parallel=True)
def density_list_pass(x, m, matid, mats, h, dim, cand, ncand, xm, nbr, nnbr, bx, bvol, borigin, binv_cell, bdims,
                      bkeys, bstart, bnbr, nbnbr, plane_p, plane_n, wall_rho, corners, corner_rho, rho, p, phase, full,
                      rho_t):
    """:func:`density_pass` over stored candidates (Verlet lists) instead of the cell scan.

    ``cand`` / ``ncand``: the candidates of :func:`density_pass` (radius ``hs``), stored when the
    particles were in the same order; as long as no particle has moved more than ``(hs − h)/2`` since,
    they contain every pair closer than ``h``, and the exact test ``r < h`` gives the same neighbour
    lists, densities and pressures as the cell scan (the same sums in the same order: a candidate
    beyond ``h`` adds exactly 0). The caller checks the displacement (:func:`max_displacement`).
    Other arguments and outputs as :func:`density_pass`.
    """
    n = x.shape[0]
    for a in prange(n):
        xm[a, 0] = x[a, 0]
        xm[a, 1] = x[a, 1]
        xm[a, 2] = x[a, 2]
        xm[a, 3] = m[a]
    nblk = (n + BLOCK - 1) // BLOCK
    for blk in prange(nblk):
        _density_list_block(blk * BLOCK, min(n, (blk + 1) * BLOCK), x, xm, matid, mats, h, dim, cand, ncand, nbr, nnbr,
                            bx, bvol, borigin, binv_cell, bdims, bkeys, bstart, bnbr, nbnbr, plane_p, plane_n,
                            wall_rho, corners, corner_rho, rho, p, phase, full, rho_t)


@njit(cache=True, parallel=True)
def max_displacement(x, xref):
    """Largest ``|x_i − xref_i|`` over the particles ((N, 3) float64 both; 0 for none)."""
    d2 = 0.0
    for i in prange(x.shape[0]):
        a = x[i, 0] - xref[i, 0]
        b = x[i, 1] - xref[i, 1]
        c = x[i, 2] - xref[i, 2]
        d2 = max(d2, a * a + b * b + c * c)
    return math.sqrt(d2)


def cell_starts(grid, buffer=None):
    """:func:`dense_starts` of an ``unmesh.spatial`` cell grid, or an empty array when the
    virtual grid has more than ``DENSE_CELLS_PER_PARTICLE`` cells per point (sparse fallback).

    ``buffer``: a previous result to reuse when large enough. Returns int64 (nkeys+1,) or (0,).

    Example
    -------
    >>> from unmesh.spatial import build_cell_grid
    >>> g = build_cell_grid(np.array([[0.0, 0, 0], [0.25, 0, 0], [0.26, 0, 0]]), 0.1)
    >>> cell_starts(g).tolist()
    [0, 1, 1, 3]
    """
    nkeys = int(grid.dims[0]) * int(grid.dims[1]) * int(grid.dims[2])
    if nkeys > DENSE_CELLS_PER_PARTICLE * len(grid.points) + 4096:
        return np.zeros(0, np.int64)
    out = buffer[: nkeys + 1] if buffer is not None and buffer.shape[0] >= nkeys + 1 else np.empty(nkeys + 1, np.int64)
    dense_starts(grid.cell_keys, grid.cell_start, nkeys, out)
    return out


#: Columns of the per-particle rows that the force pass gathers for every neighbour.
PK_X, PK_PR, PK_V, PK_M, PK_RHO, PK_RINV, PK_VRINV = 0, 3, 4, 7, 8, 9, 10
PK_VISC, PK_ALPHA, PK_SOUND, PK_OBJ, PK_SOLID, PK_KE = 11, 12, 13, 14, 15, 16
PK_COLS = 17
#: Fast-math flags of the pair loops: reassociation lets LLVM vectorise the sums over neighbours
#: (no ``nnan``/``ninf``: NaN and infinity keep their meaning for the stability checks).
PAIR_FASTMATH = {"nsz", "arcp", "contract", "reassoc"}


@njit(cache=True, fastmath=PAIR_FASTMATH, error_model="numpy")
def _force_block(r0, r1, ncol, mat0, obj0, x, v, m, rho, p, temp, phase, matid, mats, h, dim, gravity, nbr, nnbr,
                 bx, bvol, bnbr, nbnbr, plane_p, plane_n, wall_grad, corners, corner_grad, wall_mirror,
                 plane_noslip, wall_visc, wall_mom, corner_mom, bnoslip, grad_scale, tensile, damping, spacing, elastic,
                 fel, fown, pk, acc, xsph, dtemp):
    """Particles ``r0 .. r1 - 1`` of :func:`force_pass` (one block, serial): the first ``ncol`` columns
    of the neighbours' ``pk`` rows are gathered, the others are the constants of material ``mat0``
    and object ``obj0``."""
    cap = nbr.shape[1]
    bcap = bnbr.shape[1]
    visc_c = 2.0 * (dim + 2)
    eh2 = EPS * h * h
    h2 = h * h
    c6 = poly6_coef(h, dim)
    cg = spiky_coef(h, dim)
    buf = np.empty((PK_COLS, cap))
    acc_c = np.empty(3)
    # contact stiffness between objects (8.37): the lattice force (8.31) towards the rest distance d
    dsp = spacing
    tensile_inv = 1.0 / (h2 - 0.25 * spacing * spacing)  # W(r)/W(d/2) = ((h² − r²)/(h² − d²/4))³
    gmag = math.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2])
    if r1 > r0:
        for t in range(cap):
            buf[PK_VISC, t] = mats[mat0, M.VISC]
            buf[PK_ALPHA, t] = mats[mat0, M.ALPHA]
            buf[PK_SOUND, t] = mats[mat0, M.SOUND]
            buf[PK_OBJ, t] = obj0
            buf[PK_SOLID, t] = 0.0
            buf[PK_KE, t] = 0.0
    for i in range(r0, r1):
        cnt = min(nnbr[i], cap)
        if ncol == PK_VISC:  # one material, no collisions: the first eleven columns, unrolled
            for t in range(cnt):
                j = nbr[i, t]
                buf[0, t] = pk[j, 0]
                buf[1, t] = pk[j, 1]
                buf[2, t] = pk[j, 2]
                buf[3, t] = pk[j, 3]
                buf[4, t] = pk[j, 4]
                buf[5, t] = pk[j, 5]
                buf[6, t] = pk[j, 6]
                buf[7, t] = pk[j, 7]
                buf[8, t] = pk[j, 8]
                buf[9, t] = pk[j, 9]
                buf[10, t] = pk[j, 10]
        else:
            for t in range(cnt):
                j = nbr[i, t]
                for c in range(ncol):
                    buf[c, t] = pk[j, c]
        fe0 = 0.0
        fe1 = 0.0
        fe2 = 0.0
        xi0 = pk[i, PK_X]
        xi1 = pk[i, PK_X + 1]
        xi2 = pk[i, PK_X + 2]
        vi0 = pk[i, PK_V]
        vi1 = pk[i, PK_V + 1]
        vi2 = pk[i, PK_V + 2]
        rhoi = pk[i, PK_RHO]
        rinv_i = pk[i, PK_RINV]
        vrinv_i = pk[i, PK_VRINV]
        pi_ = pk[i, PK_PR]
        oi = pk[i, PK_OBJ]
        si = pk[i, PK_SOLID]
        kei = pk[i, PK_KE]
        mt = matid[i]
        mui = mats[mt, M.VISC]
        xii = mats[mt, M.XI]
        difi = mats[mt, M.DIFF]
        rho0 = mats[mt, M.RHO0]
        alphai = mats[mt, M.ALPHA]
        ci = mats[mt, M.SOUND]
        ai0 = 0.0
        ai1 = 0.0
        ai2 = 0.0
        xs0 = 0.0
        xs1 = 0.0
        xs2 = 0.0
        dti = 0.0
        solid_i = phase[i] == SOLID
        bgi = TENSILE_BACKGROUND * ci * ci * rinv_i
        for t in range(cnt):
            d0 = xi0 - buf[PK_X, t]
            d1 = xi1 - buf[PK_X + 1, t]
            d2 = xi2 - buf[PK_X + 2, t]
            r2 = d0 * d0 + d1 * d1 + d2 * d2
            r = math.sqrt(r2)
            hr = h - r
            gf = cg * hr * hr / r  # spiky w'(r)/r
            gf = gf if r > 0.0 else 0.0
            mj = buf[PK_M, t]
            vij0 = vi0 - buf[PK_V, t]
            vij1 = vi1 - buf[PK_V + 1, t]
            vij2 = vi2 - buf[PK_V + 2, t]
            vx = vij0 * d0 + vij1 * d1 + vij2 * d2
            ire = 1.0 / (r2 + eh2)
            rsum = 2.0 / (rhoi + buf[PK_RHO, t])
            t6 = h2 - r2
            # Monaghan's (2000) tensile correction, closer than d/2 only: negative pressures repel at short
            # range, ε (|p_i⁻|/ρ_i² + |p_j⁻|/ρ_j²) ((W(r)/W(d/2))⁴ − 1)₊, so they cannot pull particles onto
            # each other (pairing); pairs at least d/2 apart (a fluid at rest) are not affected
            fw = t6 * tensile_inv
            fw3 = fw * fw * fw
            fw6 = fw3 * fw3
            # (plus a background B c²/ρ of each particle: pairs at p ≈ 0, e.g. in thin films, are kept apart too)
            rt = tensile * (max(-pi_, 0.0) + max(-buf[PK_PR, t], 0.0) + bgi
                            + TENSILE_BACKGROUND * buf[PK_SOUND, t] * buf[PK_SOUND, t] * buf[PK_RINV, t]) \
                * max(fw6 * fw6 - 1.0, 0.0)
            # pressure (8.17) + viscosity (8.18, divided by max(ρ, ρ0) of fluids: see force_pass) + Monaghan's
            # artificial viscosity (approaching pairs only: min(v_ij·x_ij, 0)), all along x_ij
            bracket = (-(pi_ + buf[PK_PR, t] + rt)
                       + visc_c * (0.5 * (mui + buf[PK_VISC, t])) * vrinv_i * buf[PK_VRINV, t] * vx * ire
                       + (0.5 * (alphai + buf[PK_ALPHA, t])) * (0.5 * (ci + buf[PK_SOUND, t])) * h
                       * min(vx, 0.0) * ire * rsum)
            coef = mj * bracket * gf * grad_scale
            # penalty collision between objects (8.37): repulsive part only; XSPH (8.19) within one body
            other = oi != buf[PK_OBJ, t] and si + buf[PK_SOLID, t] > 0.0
            w6 = c6 * t6 * t6 * t6
            # and, between two solids, a contact spring that pushes the pair back to the rest distance d,
            # as stiff as the softer one's lattice force (8.31): K_e m_j/ρ0 W (d − r)₊ / r along x_ij. A fluid
            # (K_e = 0) meets a solid with the repulsive SPH force alone: springs as stiff as the ice's
            # K_e squeezed the fluid particles in a pocket of ice onto each other (0.05 d, freezing rod)
            kc = CONTACT * 2.0 * min(kei, buf[PK_KE, t]) * mj / rho0 * w6
            pen = kc * max(dsp - r, 0.0) / max(r, 1e-12 * h)
            # and a dashpot on the normal relative velocity while in contact (r < d): 2ζ√k_c (v_ij·x̂_ij)
            pen -= (2.0 * damping * math.sqrt(kc) * vx / max(r2, 1e-24 * h2)) if r < dsp else 0.0
            coef = max(coef, 0.0) + pen if other else coef
            wx = 0.0 if other else xii * mj * rsum * w6
            xs0 -= wx * vij0
            xs1 -= wx * vij1
            xs2 -= wx * vij2
            ai0 += coef * d0
            ai1 += coef * d1
            ai2 += coef * d2
        # heat conduction (Cleary & Monaghan)
        if difi > 0.0:
            for t in range(cnt):
                j = nbr[i, t]
                difj = mats[matid[j], M.DIFF]
                if difj > 0.0:
                    d0 = xi0 - x[j, 0]
                    d1 = xi1 - x[j, 1]
                    d2 = xi2 - x[j, 2]
                    r2 = d0 * d0 + d1 * d1 + d2 * d2
                    r = math.sqrt(r2)
                    gf = 0.0
                    if r > 0.0:
                        hr = h - r
                        gf = cg * hr * hr / r
                    dbar = 2.0 * difi * difj / (difi + difj)
                    dti += (2.0 * m[j] / (rhoi * rho[j])) * rho0 * dbar * (temp[i] - temp[j]) * gf * r2 / (r2 + eh2)
        # elastic forces: own share + the neighbourhoods i is a member of
        if elastic and solid_i:
            fe0 = fown[i, 0] + fel[i, 0]
            fe1 = fown[i, 1] + fel[i, 1]
            fe2 = fown[i, 2] + fel[i, 2]
        # boundary particles (Akinci et al. 2012)
        bcnt = min(nbnbr[i], bcap)
        pb = max(p[i], 0.0) / (rhoi * rhoi) * wall_mirror
        # no-slip walls: the fluid's effective shear viscosity (physical + artificial)
        nu_wall = visc_c * (mui / rho0 + alphai * ci * h / (2.0 * visc_c)) / rhoi
        for t in range(bcnt):
            b = bnbr[i, t]
            d0 = xi0 - bx[b, 0]
            d1 = xi1 - bx[b, 1]
            d2 = xi2 - bx[b, 2]
            r2 = d0 * d0 + d1 * d1 + d2 * d2
            r = math.sqrt(r2)
            hb = h - r
            gf = cg * hb * hb / r if r > 0.0 else 0.0  # spiky w'(r)/r
            psi = rho0 * bvol[b]
            bracket = -pb
            noslip = bnoslip[b] != 0
            if mui > 0.0 and not noslip:
                vx = vi0 * d0 + vi1 * d1 + vi2 * d2
                bracket += visc_c * mui / (rhoi * rho0) * vx / (r2 + eh2)
            coef = psi * bracket * gf * grad_scale
            if coef < 0.0:
                coef = 0.0
            if noslip:
                vx = vi0 * d0 + vi1 * d1 + vi2 * d2
                coef += psi * nu_wall * vx / (r2 + eh2) * gf * grad_scale
            ai0 += coef * d0
            ai1 += coef * d1
            ai2 += coef * d2
        # analytic walls; a solid particle in contact (closer than d) is damped like the contacts
        # between objects: ``−2ζ√(CONTACT K_e) v`` (normal: restitution; tangential: friction)
        cw = 2.0 * damping * math.sqrt(CONTACT * kei) if solid_i else 0.0
        # hydrostatic wall pressure (pressure mirroring, fluids): the mirrored pressure grows with depth behind
        # the wall, p_b(y) = p_i + ρ_i g·(y − x_i) (Adami et al. 2012, walls at rest), which adds
        # (ρ0/ρ_i) M(d) g (half-space moment M = Mt (I − n nᵀ) + Mn n nᵀ); weighted by
        # χ = min(p_i⁺/(ρ_i |g| h), 1): full in the bulk, none for films and splashes at p ≤ 0
        hyd = 0.0
        if wall_mirror >= 2.0 and not solid_i and gmag > 0.0 and p[i] > 0.0:
            hyd = min(p[i] / (rhoi * gmag * h), 1.0) * rho0 / rhoi
        for k in range(plane_p.shape[0]):
            dist = _plane_dist(xi0, xi1, xi2, plane_p, plane_n, k)
            if dist < dsp and cw > 0.0:
                ai0 -= cw * vi0
                ai1 -= cw * vi1
                ai2 -= cw * vi2
            if dist < h and hyd > 0.0:
                gn = gravity[0] * plane_n[k, 0] + gravity[1] * plane_n[k, 1] + gravity[2] * plane_n[k, 2]
                mt = hyd * _table(wall_mom[0], dist, h)
                mn = hyd * _table(wall_mom[1], dist, h)
                ai0 += mt * (gravity[0] - gn * plane_n[k, 0]) + mn * gn * plane_n[k, 0]
                ai1 += mt * (gravity[1] - gn * plane_n[k, 1]) + mn * gn * plane_n[k, 1]
                ai2 += mt * (gravity[2] - gn * plane_n[k, 2]) + mn * gn * plane_n[k, 2]
            if dist < h:
                s = rho0 * pb * _table(wall_grad, dist, h)
                if plane_noslip[k] != 0:
                    # no-slip: ν ρ0/ρ_i (Mt v_t + Mn v_n n)
                    mtan = rho0 * nu_wall * _table(wall_visc[0], dist, h)
                    vn = vi0 * plane_n[k, 0] + vi1 * plane_n[k, 1] + vi2 * plane_n[k, 2]
                    s += (rho0 * nu_wall * _table(wall_visc[1], dist, h) - mtan) * vn
                    ai0 += mtan * vi0
                    ai1 += mtan * vi1
                    ai2 += mtan * vi2
                ai0 += s * plane_n[k, 0]
                ai1 += s * plane_n[k, 1]
                ai2 += s * plane_n[k, 2]
        for k in range(corners.shape[0]):
            ka = corners[k, 0]
            kb = corners[k, 1]
            da = _plane_dist(xi0, xi1, xi2, plane_p, plane_n, ka)
            db = _plane_dist(xi0, xi1, xi2, plane_p, plane_n, kb)
            if da < h and db < h:
                ga = rho0 * pb * _table2(corner_grad, da, db, h)
                gb = rho0 * pb * _table2(corner_grad, db, da, h)
                ai0 += ga * plane_n[ka, 0] + gb * plane_n[kb, 0]
                ai1 += ga * plane_n[ka, 1] + gb * plane_n[kb, 1]
                ai2 += ga * plane_n[ka, 2] + gb * plane_n[kb, 2]
                if hyd > 0.0:
                    # the quarter-space behind both walls is in both half-space moments: subtract it once
                    _corner_hydrostatic(ka, kb, da, db, h, hyd, gravity, plane_n, corner_mom, acc_c)
                    ai0 -= acc_c[0]
                    ai1 -= acc_c[1]
                    ai2 -= acc_c[2]
        if elastic and solid_i:
            ai0 += fe0 / m[i]
            ai1 += fe1 / m[i]
            ai2 += fe2 / m[i]
        acc[i, 0] = ai0 + gravity[0]
        acc[i, 1] = ai1 + gravity[1]
        acc[i, 2] = ai2 + gravity[2]
        xsph[i, 0] = xs0
        xsph[i, 1] = xs1
        xsph[i, 2] = xs2
        dtemp[i] = dti


@njit(cache=True, parallel=True, error_model="numpy")
def force_pass(x, v, m, rho, p, temp, phase, obj, matid, uid, mats, h, dim, gravity, nbr, nnbr,
               bx, bvol, bnbr, nbnbr, plane_p, plane_n, wall_grad, corners, corner_grad, wall_mirror,
               plane_noslip, wall_visc, wall_mom, corner_mom, bnoslip, grad_scale, tensile, damping, spacing, elastic,
               fel, fown, pk, acc, xsph, dtemp, full):
    """Accelerations, XSPH corrections and temperature rates of every particle.

    See the module docstring for the terms. ``elastic`` (bool) adds the lattice forces
    on solid particles: ``fown[i] + fel[i]``, the particle's own share and the forces of
    the neighbourhoods it is a member of (outputs of
    :func:`unmesh.sph._elastic_kernels.lattice_update`).
    ``wall_mirror`` scales the boundary pressure term (2: pressure mirroring
    ``p_b = p_i``; 1: Akinci et al. 2012, ``p_i/ρ_i²``). ``plane_noslip`` (P,) and ``bnoslip``
    (NB,) uint8 mark no-slip walls: they apply the viscous term of (8.18) with the fluid's
    effective shear viscosity ``ν = μ/ρ0 + αch/(4(n+2))`` to the wall at rest (Akinci et al.
    2012, eq. 11; :mod:`unmesh.sph.boundary`), for planes through the half-space integrals
    ``wall_visc`` (2, S) of :func:`unmesh.sph.boundary.wall_friction_tables`. With pressure mirroring
    the mirrored pressure of a fluid particle behind an analytic wall is extrapolated hydrostatically
    (Adami et al. 2012): ``(ρ0/ρ_i) χ M(d) g`` with the half-space moments ``wall_mom`` (2, S) of
    :func:`unmesh.sph.boundary.wall_moment_tables`, ``χ = min(p_i⁺/(ρ_i |g| h), 1)``, less the quarter-spaces at box
    edges (``corner_mom`` (3, S, S) of :func:`unmesh.sph.boundary.corner_moment_tables`). ``grad_scale`` multiplies the kernel
    gradient of particle pairs (the lattice correction, see
    :func:`unmesh.sph.sampling.gradient_moment`).

    The viscosity (8.18) divides by ``ρ̂_i ρ̂_j`` with ``ρ̂ = max(ρ, ρ0)`` for fluid particles and for solid ones
    with fewer than ``SOLID_TENSION_SUPPORT[1] · full`` neighbours (fragments; ``full`` the count on the rest
    lattice; other solids: ρ, their surfaces' damping brings a plastic block to rest): where the summation density is
    below ρ0 (free surfaces, spray, pockets) that is the kernel's empty support, not a lighter fluid, and
    ``1/(ρ_i ρ_j)`` made the explicit viscous coupling of close pairs there several times stiffer than the
    time step resolves: a tetrahedron of four slime particles 0.42–0.7 d apart, released at rest, rang
    up to 2.6–10.6 m/s (step-to-step alternating accelerations), and the freezing rod threw such clumps
    out of its ice at 2 m/s. In the bulk (ρ ≈ ρ0 within 1 %) the change is of second order.

    Layout: ``pk`` (N, :data:`PK_COLS`) is scratch that first receives every particle's
    pair data (position, ``p/ρ²``, velocity, mass, ``ρ``, ``1/ρ``, ``1/ρ̂``, its material's ``μ``, ``α``,
    ``c``, object, solid flag): one row per neighbour instead of a dozen scattered arrays, of
    which only the first 88 bytes are read when all particles share one material and no
    collisions can occur. Per particle the rows of its neighbours are copied into a small column buffer,
    and the pair loop over that buffer is branch-free (collisions and XSPH by selects), so
    it is vectorised. Heat conduction runs in a second loop only for conducting particles.
    """
    n = x.shape[0]
    mat0 = matid[0] if n > 0 else 0
    obj0 = obj[0] if n > 0 else 0
    mixed = 0
    solids = 0
    bodies = 0
    for i in prange(n):
        mt = matid[i]
        mixed += mt != mat0
        solids += phase[i] == SOLID
        bodies += obj[i] != obj0
        pk[i, PK_X] = x[i, 0]
        pk[i, PK_X + 1] = x[i, 1]
        pk[i, PK_X + 2] = x[i, 2]
        pk[i, PK_PR] = p[i] / (rho[i] * rho[i])
        pk[i, PK_V] = v[i, 0]
        pk[i, PK_V + 1] = v[i, 1]
        pk[i, PK_V + 2] = v[i, 2]
        pk[i, PK_M] = m[i]
        pk[i, PK_RHO] = rho[i]
        pk[i, PK_RINV] = 1.0 / rho[i]
        solid_bulk = phase[i] == SOLID and nnbr[i] >= SOLID_TENSION_SUPPORT[1] * full
        pk[i, PK_VRINV] = 1.0 / (rho[i] if solid_bulk else max(rho[i], mats[mt, M.RHO0]))
        pk[i, PK_VISC] = mats[mt, M.VISC]
        pk[i, PK_ALPHA] = mats[mt, M.ALPHA]
        pk[i, PK_SOUND] = mats[mt, M.SOUND]
        pk[i, PK_OBJ] = obj[i]
        pk[i, PK_SOLID] = 1.0 if phase[i] == SOLID else 0.0
        pk[i, PK_KE] = mats[mt, M.KE] if phase[i] == SOLID else 0.0
    # columns to gather: the material columns only with several materials, the collision columns
    # only when solids of different objects may meet; otherwise their (constant) buffer rows are set
    # once per block (with one object, or without solids, no pair is a collision)
    collide = solids > 0 and bodies > 0
    ncol = PK_KE + 1 if collide else (PK_OBJ if mixed > 0 else PK_VISC)
    nblk = (n + BLOCK - 1) // BLOCK
    for blk in prange(nblk):
        _force_block(blk * BLOCK, min(n, (blk + 1) * BLOCK), ncol, mat0, obj0, x, v, m, rho, p, temp, phase, matid,
                     mats, h, dim, gravity, nbr, nnbr, bx, bvol, bnbr, nbnbr, plane_p, plane_n, wall_grad, corners,
                     corner_grad, wall_mirror, plane_noslip, wall_visc, wall_mom, corner_mom, bnoslip, grad_scale,
                     tensile, damping, spacing, elastic, fel, fown, pk, acc, xsph, dtemp)


@njit(cache=True, parallel=True)
def kick_drift(x, v, acc, xsph, half_dt, dt, fixed, plane_p, plane_n, margin):
    """Half kick ``v += half_dt · a``, then drift ``x += dt (v + Δv_XSPH)`` (one pass).

    Fixed particles stay where they are, at rest. A particle closer than ``margin``
    to an analytic wall (or behind it) is moved to ``margin`` and its velocity component
    into the wall removed. Returns the number of particles with non-finite positions.
    """
    bad = 0
    for i in prange(x.shape[0]):
        if fixed[i]:
            v[i, 0] = 0.0
            v[i, 1] = 0.0
            v[i, 2] = 0.0
            continue
        for a in range(3):
            v[i, a] += half_dt * acc[i, a]
        for a in range(3):
            x[i, a] += dt * (v[i, a] + xsph[i, a])
        for k in range(plane_p.shape[0]):
            dist = ((x[i, 0] - plane_p[k, 0]) * plane_n[k, 0] + (x[i, 1] - plane_p[k, 1]) * plane_n[k, 1]
                    + (x[i, 2] - plane_p[k, 2]) * plane_n[k, 2])
            if dist < margin:
                for a in range(3):
                    x[i, a] += (margin - dist) * plane_n[k, a]
                vn = v[i, 0] * plane_n[k, 0] + v[i, 1] * plane_n[k, 1] + v[i, 2] * plane_n[k, 2]
                if vn < 0.0:
                    for a in range(3):
                        v[i, a] -= vn * plane_n[k, a]
        if not math.isfinite(x[i, 0] + x[i, 1] + x[i, 2]):
            bad += 1
    return bad


@njit(**PLAIN)
def _particle_stats(x, v, acc, rho, matid, mats, i):
    """``(|v_i|², |a_i|², |ρ_i/ρ0 − 1|, finite)`` of particle i for the diagnostics reductions."""
    v2 = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
    a2 = acc[i, 0] * acc[i, 0] + acc[i, 1] * acc[i, 1] + acc[i, 2] * acc[i, 2]
    d = abs(rho[i] / mats[matid[i], M.RHO0] - 1.0)
    ok = math.isfinite(v2) and math.isfinite(a2) and math.isfinite(x[i, 0] + x[i, 1] + x[i, 2])
    return v2, a2, d, ok


@njit(cache=True, parallel=True)
def kick_diagnostics(x, v, acc, half_dt, fixed, m, rho, matid, mats):
    """Half kick ``v += half_dt · a`` (fixed particles at rest), then :func:`diagnostics` (one pass)."""
    n = x.shape[0]
    ke = 0.0
    vmax = 0.0
    amax = 0.0
    derr = 0.0
    bad = 0
    for i in prange(n):
        if fixed[i]:
            v[i, 0] = 0.0
            v[i, 1] = 0.0
            v[i, 2] = 0.0
        else:
            v[i, 0] += half_dt * acc[i, 0]
            v[i, 1] += half_dt * acc[i, 1]
            v[i, 2] += half_dt * acc[i, 2]
        v2, a2, d, ok = _particle_stats(x, v, acc, rho, matid, mats, i)
        ke += 0.5 * m[i] * v2
        vmax = max(vmax, v2)
        amax = max(amax, a2)
        derr = max(derr, d)
        if not ok:
            bad += 1
    return ke, math.sqrt(vmax), math.sqrt(amax), derr, bad


@njit(cache=True, parallel=True)
def diagnostics(x, v, acc, m, rho, matid, mats):
    """Kinetic energy, max speed, max |a|, max |ρ/ρ0 − 1| and a NaN flag."""
    n = x.shape[0]
    ke = 0.0
    vmax = 0.0
    amax = 0.0
    derr = 0.0
    bad = 0
    for i in prange(n):
        v2, a2, d, ok = _particle_stats(x, v, acc, rho, matid, mats, i)
        ke += 0.5 * m[i] * v2
        vmax = max(vmax, v2)
        amax = max(amax, a2)
        derr = max(derr, d)
        if not ok:
            bad += 1
    return ke, math.sqrt(vmax), math.sqrt(amax), derr, bad


@njit(cache=True, parallel=True)
def permute_rows(src, order, dst):
    """``dst[a] = src[order[a]]`` for 2D row views (the re-sort of every per-particle array).

    The caller passes any C-contiguous per-particle array as a (N, B) view of raw
    words (``uint64`` or ``uint8``), so one compiled kernel copies all dtypes
    bit-exactly, in parallel, into a reused buffer.
    """
    nb = src.shape[1]
    for a in prange(order.shape[0]):
        o = order[a]
        for k in range(nb):
            dst[a, k] = src[o, k]
