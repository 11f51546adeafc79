"""Numba kernels of the phase transitions (thesis section 8.2.4).

Numpy reference: :func:`unmesh.sph.phase.transition_rates_reference`.
"""

from __future__ import annotations

import math

from numba import njit, prange

from unmesh.sph import materials as M
from unmesh.sph._kernels import PLAIN, kernel_w
from unmesh.sph._rng import STREAM_FREEZE, STREAM_MELT, uniform
from unmesh.sph._slot_kernels import nearest_slot

FLUID = 0
SOLID = 1


@njit(cache=True, fastmath=False, error_model="python")
def melting_rate(lam0, temp, t_melt):
    """Eq. (8.35): ``λ_m = max(0, λ_m^0 (T − T_m))``."""
    if lam0 <= 0.0:
        return 0.0
    return max(0.0, lam0 * (temp - t_melt))


@njit(cache=True, fastmath=False, error_model="python")
def freezing_rate(lam0, temp, t_freeze, n_solid, n_min, dv, v_max, force, f_max):
    """Eq. (8.36): ``λ_f = max(0, λ_f^0 (T_f − T)(n_s − n_min + 1) min(1, c_v) min(1, c_F))``.

    ``n_min`` is the *minimum* number of solid neighbours (the factor is 0 below
    it, ≥ 1 from it on, so ``n_min = 0`` allows spontaneous freezing as the thesis
    states). ``c_v = v_max/‖v_i − v̄‖`` and ``c_F = F_max/‖ΣF‖`` are guarded: a zero
    denominator gives ``c = ∞``, i.e. no reduction (NOTES.md).
    """
    if lam0 <= 0.0 or temp >= t_freeze or n_solid < n_min:
        return 0.0
    cv = 1.0 if dv <= v_max else v_max / dv
    cf = 1.0 if force <= f_max else f_max / force
    return max(0.0, lam0 * (t_freeze - temp) * (n_solid - n_min + 1) * cv * cf)


#: A particle closer than this (in units of d) to a solid particle lies in that particle's lattice site
#: whatever the site's orientation: half the nearest-neighbour distance, the inradius of the rest
#: lattice's Voronoi cell (hexagon in 2D, rhombic dodecahedron in 3D).
SITE_RADIUS = 0.5


@njit(**PLAIN)
def _in_occupied_site(i, x, phase, obj, matid, uid, mats, nbr, nnbr, ainv, spacing, tmat, table, dim):
    """Whether frozen particle ``i`` lies in the lattice site of a solid neighbour of its object: its nearest
    lattice point in that neighbour's lattice (eq. 8.21) is the neighbour's own, or it is closer to the
    neighbour than :data:`SITE_RADIUS` d. Of two frozen particles of freezing materials in one site by the
    distance only the one with the larger id counts as intruder (exactly one of them thaws)."""
    r_site = (SITE_RADIUS * spacing) ** 2
    for t in range(min(nnbr[i], nbr.shape[1])):
        j = nbr[i, t]
        if phase[j] != SOLID or obj[j] != obj[i]:
            continue
        r0 = x[i, 0] - x[j, 0]
        r1 = x[i, 1] - x[j, 1]
        r2 = x[i, 2] - x[j, 2]
        if r0 * r0 + r1 * r1 + r2 * r2 < r_site and (mats[matid[j], M.FREEZE_RATE] <= 0.0 or uid[j] < uid[i]):
            return True
        y0 = (ainv[j, 0, 0] * r0 + ainv[j, 0, 1] * r1 + ainv[j, 0, 2] * r2) / spacing
        y1 = (ainv[j, 1, 0] * r0 + ainv[j, 1, 1] * r1 + ainv[j, 1, 2] * r2) / spacing
        y2 = (ainv[j, 2, 0] * r0 + ainv[j, 2, 1] * r1 + ainv[j, 2, 2] * r2) / spacing if dim == 3 else 0.0
        q, _d2 = nearest_slot(y0, y1, y2, tmat, table, dim)
        if q < 0 and y0 * y0 + y1 * y1 + y2 * y2 < 1.0:
            return True
    return False


@njit(cache=True, parallel=True)
def phase_pass(x, v, m, phase, obj, matid, uid, temp, mats, nbr, nnbr, h, dim, spacing,
               slot_vecs, tmat, table, ainv, gmat, occ, valid, seed, step, dt,
               new_phase, donor, rates):
    """Poisson-process melting and freezing (eq. 8.34) of every particle.

    Writes ``new_phase`` (N,) int8, ``donor`` (N,) int64 — for a particle that
    freezes, its closest solid neighbour (whose object and lattice it joins), else
    -1 — and ``rates`` (N,) the transition rate ``λ`` used.

    A fluid particle whose nearest lattice point in the lattice of a solid neighbour ``j`` is ``j``'s
    own (``A_j⁻¹ x_ij / d`` rounds to the origin, eq. 8.21) sits in an occupied site and does not
    freeze (rate 0): frozen, it would have no slot in ``j``'s neighbourhood nor ``j`` one in its own,
    and the lattice forces of the other neighbours would pull it onto ``j`` (frozen particles 0.07 d
    from rod particles in the freezing-rod scene). For the same reason a frozen particle of a
    freezing material that the flow has pushed into such a site thaws (becomes fluid, so that
    pressure pushes it out again instead of the lattice forces pulling it in).

    A particle closer than ``SITE_RADIUS`` d = 0.5 d to a solid particle is in that particle's site
    whatever its lattice: a surface particle with few lattice members can have a degenerate lattice
    (singular values 2.7, 1.7, 0.22 in the freezing rod, seed 3), in which a particle 0.45-0.75 d away
    rounds to a slot: a particle froze 0.75 d from such a one and, bound to it as a lattice neighbour
    in that lattice, was drawn to 0.45 d, one site, until the lattice forces threw the two apart at
    36 m/s. Of two frozen particles of freezing materials closer than that, the one with the larger
    id thaws.
    """
    n = x.shape[0]
    cap = nbr.shape[1]
    r_site = (SITE_RADIUS * spacing) ** 2
    for i in prange(n):
        new_phase[i] = phase[i]
        donor[i] = -1
        rates[i] = 0.0
        mt = matid[i]
        if phase[i] == SOLID:
            lam = melting_rate(mats[mt, M.MELT_RATE], temp[i], mats[mt, M.MELT_T])
            rates[i] = lam
            if lam > 0.0 and uniform(seed, step, uid[i], 0, STREAM_MELT) < 1.0 - math.exp(-lam * dt):
                new_phase[i] = FLUID
            elif mats[mt, M.FREEZE_RATE] > 0.0 and _in_occupied_site(i, x, phase, obj, matid, uid, mats, nbr, nnbr,
                                                                      ainv, spacing, tmat, table, dim):
                new_phase[i] = FLUID  # frozen, but pushed into the site of a solid neighbour: it thaws
            continue
        lam0 = mats[mt, M.FREEZE_RATE]
        if lam0 <= 0.0 or temp[i] >= mats[mt, M.FREEZE_T]:
            continue
        ns = 0
        vb0 = 0.0
        vb1 = 0.0
        vb2 = 0.0
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        best = 1e300
        near = -1
        taken = False
        for t in range(min(nnbr[i], cap)):
            j = nbr[i, t]
            if phase[j] != SOLID:
                continue
            ns += 1
            vb0 += v[j, 0]
            vb1 += v[j, 1]
            vb2 += v[j, 2]
            r0 = x[i, 0] - x[j, 0]
            r1 = x[i, 1] - x[j, 1]
            r2 = x[i, 2] - x[j, 2]
            rr = r0 * r0 + r1 * r1 + r2 * r2
            if rr < best:
                best = rr
                near = j
            # the slot of i in j's lattice: i's lattice point is j's own (i sits in j's site) -> i cannot freeze
            y0 = (ainv[j, 0, 0] * r0 + ainv[j, 0, 1] * r1 + ainv[j, 0, 2] * r2) / spacing
            y1 = (ainv[j, 1, 0] * r0 + ainv[j, 1, 1] * r1 + ainv[j, 1, 2] * r2) / spacing
            y2 = (ainv[j, 2, 0] * r0 + ainv[j, 2, 1] * r1 + ainv[j, 2, 2] * r2) / spacing if dim == 3 else 0.0
            q, _d2 = nearest_slot(y0, y1, y2, tmat, table, dim)
            if (q < 0 and y0 * y0 + y1 * y1 + y2 * y2 < 1.0) or rr < r_site:
                taken = True
            if valid[j] == 0:
                continue
            # hypothetical lattice force of i in j's slot q, if free
            if q < 0 or (occ[j, q] >= 0 and occ[j, q] != uid[i]):
                continue
            mtj = matid[j]
            coef = mats[mtj, M.KE] * m[i] * m[j] / mats[mtj, M.RHO0] * kernel_w(rr, h, dim)
            l0 = slot_vecs[q, 0] * spacing
            l1 = slot_vecs[q, 1] * spacing
            l2 = slot_vecs[q, 2] * spacing
            f0 += coef * (gmat[j, 0, 0] * l0 + gmat[j, 0, 1] * l1 + gmat[j, 0, 2] * l2 - r0)
            f1 += coef * (gmat[j, 1, 0] * l0 + gmat[j, 1, 1] * l1 + gmat[j, 1, 2] * l2 - r1)
            f2 += coef * (gmat[j, 2, 0] * l0 + gmat[j, 2, 1] * l1 + gmat[j, 2, 2] * l2 - r2)
        dv = 0.0
        if ns > 0:
            d0 = v[i, 0] - vb0 / ns
            d1 = v[i, 1] - vb1 / ns
            d2 = v[i, 2] - vb2 / ns
            dv = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        force = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2) / m[i]
        lam = freezing_rate(lam0, temp[i], mats[mt, M.FREEZE_T], ns, mats[mt, M.FREEZE_NMIN], dv,
                            mats[mt, M.FREEZE_VMAX], force, mats[mt, M.FREEZE_FMAX])
        if taken:
            lam = 0.0
        rates[i] = lam
        if lam > 0.0 and uniform(seed, step, uid[i], 0, STREAM_FREEZE) < 1.0 - math.exp(-lam * dt):
            new_phase[i] = SOLID
            donor[i] = near


@njit(cache=True, parallel=True)
def heat_relax(temp, mask, target, factor):
    """``T += (T_s − T)·factor`` for masked particles (heat source or sink)."""
    for i in prange(temp.shape[0]):
        if mask[i]:
            temp[i] += (target - temp[i]) * factor

