"""Numba kernel of the lattice pass: elastic forces with an implicit rest state (thesis section 8.2).

Numpy references: :mod:`unmesh.sph.elastic` (per-neighbourhood math) and
:mod:`unmesh.sph.sampling` (nearest lattice point), which the tests compare against; the 3×3
algebra is in :mod:`unmesh.sph._polar_kernels`, the nearest lattice point in
:mod:`unmesh.sph._slot_kernels`. Arrays are in the simulation's cell-sorted order; lattice slots
are identified across steps by the *particle id* (``uid``) of their occupant, so re-sorting needs no
remapping.

Pass :func:`lattice_update` (every solid particle ``i`` writes only its own rows): assignment
(8.21) with conflict resolution, docking (section 8.2.5), shape matching (8.23–8.24), goal matrix
(8.29–8.30), strain stress (8.2.2), the forces the neighbourhood exerts on its members and the
exact torque correction. The forces on the members are added into an accumulator window per block
of particles (race-free), summed per particle in block order afterwards (the same result whatever
the thread count).

Speed notes: the neighbours of a particle are handled by row position (offset, lattice offset,
weight, member flag in columns of small buffers) in loops that run to a multiple of 8 entries and
vectorise: the D3 rounding of eq. (8.21) (in 3D ``T A⁻¹/d`` is formed once per particle, the lattice
offset of the nearest point is ``d T⁻¹ k``), the shape-matching sums, the member forces and the
torque correction. Non-members weigh 0. Only the slot conflicts, the docking and the additions into
the window are scalar loops. Particles are processed in groups of :data:`LANES`: the 3×3 algebra of a
group (``M⁻¹``, ``A``, its polar decomposition, the centroid and ``ω`` of the torque correction) runs
as loops over the group, so the division chains of different particles overlap.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.kernels._kernels import poly6_2d, poly6_3d
from unmesh.sph import materials as M
from unmesh.sph._kernels import PLAIN
from unmesh.sph._polar_kernels import SIG_HI, SIG_LO, _inv3, polar_lanes, svd_rot, sym_adjugate
from unmesh.sph._rng import STREAM_DOCK, uniform
from unmesh.sph._slot_kernels import _d3_round_k, nearest_slot

SOLID = 1
#: Singular values are clamped to at least this when forming goal positions (inverted lattices).
SIGMA_FLOOR = 0.05
#: A neighbourhood of a freezing material with fewer members than ``FIT_MEMBERS_PER_DIM * dim`` (3D: 6 of the
#: 12 lattice neighbours, 2D: 4 of 6) fits only a rotation: its lattice transformation, goal matrix (8.29-8.30) and next assignment
#: use the rotation ``R`` of the fit (8.24), not its stretch, and it has no strain stress (surface ice of a few
#: members otherwise fits a squashed lattice, singular values like 2.7 / 1.7 / 0.22, and its force rings).
FIT_MEMBERS_PER_DIM = 2
_EYE = np.eye(3)


@njit(**PLAIN)
def _w(r2, h, dim):
    if dim == 3:
        return poly6_3d(r2, h)
    return poly6_2d(r2, h)


@njit(**PLAIN)
def _w_zero(h, dim):
    """``W(0)`` of poly6 (C.1/C.4)."""
    return _w(0.0, h, dim)


# -- the update pass ---------------------------------------------------------------------


@njit(**PLAIN)
def _keep_previous(i, o, amat, ainv, amat_out, ainv_out, pmat, pmat_out):
    """Row ``i`` of the new lattice transformation, its inverse and the plastic deformation: the
    previous ones, rows ``o`` (no shape matching)."""
    for p in range(3):
        for q in range(3):
            amat_out[i, p, q] = amat[o, p, q]
            ainv_out[i, p, q] = ainv[o, p, q]
    if pmat.shape[0] > 0:
        for p in range(3):
            for q in range(3):
                pmat_out[i, p, q] = pmat[o, p, q]


@njit(**PLAIN)
def _plastic_split(k, o, pmat, la, lminv, ltot, lp, lpi, pm, pinv):
    """Lane ``k``: the elastic part ``A_e = A P⁻¹`` of the fitted lattice transformation ``A`` (8.23)
    for the stored plastic deformation ``P = pmat[o]`` (rest offsets ``P l``); ``A`` is kept in
    ``ltot``, ``P`` and ``P⁻¹`` in ``lp`` and ``lpi``; ``lminv`` becomes ``P⁻ᵀ M⁻¹`` (strain forces of
    the rest offsets ``P l``: ``(P M Pᵀ)⁻¹ P = P⁻ᵀ M⁻¹``)."""
    for p in range(3):
        for q in range(3):
            pm[p, q] = pmat[o, p, q]
    _inv3(pm, pinv)
    for e in range(9):
        ltot[e, k] = la[e, k]
        lp[e, k] = pm[e // 3, e % 3]
        lpi[e, k] = pinv[e // 3, e % 3]
    for p in range(3):
        for q in range(3):
            la[3 * p + q, k] = ltot[3 * p, k] * pinv[0, q] + ltot[3 * p + 1, k] * pinv[1, q] + ltot[3 * p + 2, k] * pinv[2, q]
    m0 = np.empty(9)
    for e in range(9):
        m0[e] = lminv[e, k]
    for p in range(3):
        for q in range(3):
            lminv[3 * p + q, k] = pinv[0, p] * m0[q] + pinv[1, p] * m0[3 + q] + pinv[2, p] * m0[6 + q]


@njit(**PLAIN)
def _det(a, dim):
    """Determinant of the leading ``dim`` x ``dim`` block of the 3x3 matrix ``a``."""
    if dim == 2:
        return a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]) - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
            + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))


@njit(**PLAIN)
def _plastic_finish(i, k, ys, ltot, lp, lpi, lg, amat_out, ainv_out, pmat_out, yld, creep, dt, dim, pm):
    """Particle ``i`` (lane ``k``) with a stored plastic deformation ``P``: the lattice transformation
    ``A = A_e P`` and its inverse ``P⁻¹ A_e⁻¹`` for the next assignment (8.21), the goal matrix
    ``U S Vᵀ P`` (goals ``g' = U S Vᵀ P l``, 8.29), and the plastic flow (the thesis' yield and creep
    rule 7.20–7.22 applied to the lattice): with the isochoric elastic stretch ``Ŷ = Y / det(Y)^(1/n)``
    (``Y = V Σ Vᵀ``, the right stretch of ``A_e``) and ``ε = ‖Ŷ − I‖_F``, a particle beyond the yield
    strain ``β`` moves its rest shape towards the current one,
    ``P ← (I + c (Ŷ − I)) P``, ``c = min(1, α Δt)(1 − β/ε)``, normalised to ``det P = 1``."""
    n = 2 if dim == 2 else 3
    for p in range(3):
        for q in range(3):
            amat_out[i, p, q] = ltot[3 * p + q, k]
    for p in range(3):
        for q in range(3):
            pm[p, q] = lpi[3 * p, k] * ainv_out[i, 0, q] + lpi[3 * p + 1, k] * ainv_out[i, 1, q] \
                + lpi[3 * p + 2, k] * ainv_out[i, 2, q]
    for p in range(3):
        for q in range(3):
            ainv_out[i, p, q] = pm[p, q]
    for p in range(3):
        g0 = lg[3 * p, k]
        g1 = lg[3 * p + 1, k]
        g2 = lg[3 * p + 2, k]
        for q in range(3):
            pm[p, q] = g0 * lp[q, k] + g1 * lp[3 + q, k] + g2 * lp[6 + q, k]
    for p in range(3):
        for q in range(3):
            lg[3 * p + q, k] = pm[p, q]
    # plastic flow
    det = _det(ys, dim)
    scale = det ** (-1.0 / n) if det > 0.0 else 1.0
    eps2 = 0.0
    for p in range(n):
        for q in range(n):
            e = ys[p, q] * scale - (1.0 if p == q else 0.0)
            eps2 += e * e
    eps = math.sqrt(eps2)
    c = 0.0
    if eps > yld:
        c = min(1.0, creep * dt) * (1.0 - yld / eps)
    for p in range(3):
        for q in range(3):
            acc = 0.0
            for r in range(3):
                fr = (ys[p, r] * scale - (1.0 if p == r else 0.0)) * c + (1.0 if p == r else 0.0)
                if p >= n or r >= n:
                    fr = 1.0 if p == r else 0.0
                acc += fr * lp[3 * r + q, k]
            pm[p, q] = acc
    pdet = _det(pm, dim)
    ps = pdet ** (-1.0 / n) if pdet > 0.0 else 1.0
    for p in range(3):
        for q in range(3):
            pmat_out[i, p, q] = pm[p, q] * ps if (p < n and q < n) else pm[p, q]


#: Blocks of the lattice pass. Each block of particles owns a window of member-force
#: accumulators (the rows of its particles' neighbours), summed in block order: the result
#: does not depend on the number of threads.
LATTICE_BLOCKS = 16
#: Rows of the member-force sum per parallel task.
SUM_ROWS = 4096
#: Fast-math flags of the lattice pass (reassociation vectorises the sums over members;
#: no ``nnan``/``ninf``).
LATTICE_FASTMATH = {"nsz", "arcp", "contract", "reassoc"}
#: Particles whose 3×3 algebra (shape matching, polar decomposition, goal matrix, torque correction) runs
#: as one loop over lanes (vectorised, no latency chain per particle).
LANES = 8


@njit(cache=True, fastmath=LATTICE_FASTMATH, error_model="numpy")
def _lattice_block(r0, r1, lo_b, win, x, m, phase, obj, matid, uid, mats, nbr, nnbr, h, dim, spacing, slot_vecs, lv, dti,
                   c6, w_self, tm, table, order, amat, ainv, occ, docked, lam, seed, step, dt, prime, onebody,
                   amat_out, ainv_out, occ_out, docked_out, gmat, fown, valid, pmat, pmat_out):
    """The particles ``r0 .. r1 - 1`` of :func:`lattice_update` (one block, serial); member forces are
    added into ``win`` (W, 3), the accumulator rows ``lo_b, lo_b + 1, ...``. ``onebody``: every
    particle is solid and of one object (no neighbour needs the phase and object test)."""
    nq = slot_vecs.shape[0]
    cap = nbr.shape[1]
    h2 = h * h
    for k in range(win.shape[0]):
        win[k, 0] = 0.0
        win[k, 1] = 0.0
        win[k, 2] = 0.0
    cap8 = (cap + 7) // 8 * 8  # loops over neighbours run to a multiple of 8 (no scalar remainder)
    far = 8.0 * h  # offset of the padding entries: beyond the support (weight 0) and ineligible
    tsize = table.shape[0]
    thalf = float(tsize // 2)
    tflat = table.reshape(tsize * tsize * tsize)
    # assignment scratch of one particle: squared lattice distance, table index, W; ids, slots, members
    at = np.empty((3, cap8))
    qt = np.empty(cap8, np.int64)
    memb = np.empty(cap8 + 1)
    bestd = np.empty(nq)
    bestt = np.empty(nq, np.int64)
    # per lane (particle of the group) and neighbour row: r (3), l (3), W·member, m_j, force (3)
    nb = np.empty((LANES, 11, cap8))
    # per lane: sums of (8.23) M (6) and B (9); A, M⁻¹, R, S, goal, strain matrices (9, row-major)
    sums = np.empty((15, LANES))
    la = np.empty((9, LANES))
    lminv = np.empty((9, LANES))
    lrot = np.empty((9, LANES))
    lsym = np.empty((9, LANES))
    lg = np.empty((9, LANES))
    le = np.empty((9, LANES))
    fast = np.empty(LANES)
    act = np.empty(LANES)
    ok = np.empty(LANES)
    cand = np.empty(LANES)
    lpad = np.empty(LANES, np.int64)
    # torque correction per lane: force sum (3), torque (3), weighted centroid (3), weight, inertia (6)
    tq = np.empty((16, LANES))
    a = np.empty((3, 3))
    u = np.empty((3, 3))
    v = np.empty((3, 3))
    sg = np.empty(3)
    work = np.empty((4, 3, 3))
    keep_goal = gmat.shape[0] > 0
    # stored plastic deformation (materials with a finite yield strain): per lane A, P, P⁻¹; flags
    plastic = pmat.shape[0] > 0
    ltot = np.empty((9, LANES))
    lp = np.empty((9, LANES))
    lpi = np.empty((9, LANES))
    lpl = np.zeros(LANES)
    rigid = np.zeros(LANES)  # lanes with too few members for a stretch: the rotation of the fit only
    few = FIT_MEMBERS_PER_DIM * dim
    pm = np.empty((3, 3))
    pinv = np.empty((3, 3))
    ys = np.empty((3, 3))
    track = lam.shape[1] > 0
    st00, st01, st02 = dti[0, 0], dti[0, 1], dti[0, 2]
    st10, st11, st12 = dti[1, 0], dti[1, 1], dti[1, 2]
    st20, st21, st22 = dti[2, 0], dti[2, 1], dti[2, 2]
    for g0 in range(r0, r1, LANES):
        nl = min(LANES, r1 - g0)
        # -- per particle: assignment (8.21), docking, shape-matching sums (8.23) --
        for k in range(LANES):
            ok[k] = 0.0
            cand[k] = 0.0
            rigid[k] = 0.0
            # an idle lane holds the identity (its algebra stays finite)
            for e in range(15):
                sums[e, k] = 0.0
            sums[0, k] = sums[3, k] = sums[5, k] = 1.0
            sums[6, k] = sums[10, k] = sums[14, k] = 1.0
        for k in range(nl):
            i = g0 + k
            o = order[i]  # the particle's row in the state of the previous step
            valid[i] = 0
            cnt = min(nnbr[i], cap)
            pad = (cnt + 7) // 8 * 8
            lpad[k] = pad
            fown[i, 0] = 0.0
            fown[i, 1] = 0.0
            fown[i, 2] = 0.0
            mt = matid[i]
            if phase[i] != SOLID or (mats[mt, M.KE] <= 0.0 and mats[mt, M.LMU] <= 0.0 and mats[mt, M.LLAM] <= 0.0):
                for q in range(nq):
                    occ_out[i, q] = -1
                    docked_out[i, q] = 0
                _keep_previous(i, o, amat, ainv, amat_out, ainv_out, pmat, pmat_out)
                continue
            rt = nb[k]
            xi0 = x[i, 0]
            xi1 = x[i, 1]
            xi2 = x[i, 2]
            oi = obj[i]
            # world offset -> lattice frame in units of d (A^(t-1)^-1 / d), in 3D straight on to D3 coordinates
            p00 = (tm[0, 0] * ainv[o, 0, 0] + tm[0, 1] * ainv[o, 1, 0] + tm[0, 2] * ainv[o, 2, 0]) / spacing
            p01 = (tm[0, 0] * ainv[o, 0, 1] + tm[0, 1] * ainv[o, 1, 1] + tm[0, 2] * ainv[o, 2, 1]) / spacing
            p02 = (tm[0, 0] * ainv[o, 0, 2] + tm[0, 1] * ainv[o, 1, 2] + tm[0, 2] * ainv[o, 2, 2]) / spacing
            p10 = (tm[1, 0] * ainv[o, 0, 0] + tm[1, 1] * ainv[o, 1, 0] + tm[1, 2] * ainv[o, 2, 0]) / spacing
            p11 = (tm[1, 0] * ainv[o, 0, 1] + tm[1, 1] * ainv[o, 1, 1] + tm[1, 2] * ainv[o, 2, 1]) / spacing
            p12 = (tm[1, 0] * ainv[o, 0, 2] + tm[1, 1] * ainv[o, 1, 2] + tm[1, 2] * ainv[o, 2, 2]) / spacing
            p20 = (tm[2, 0] * ainv[o, 0, 0] + tm[2, 1] * ainv[o, 1, 0] + tm[2, 2] * ainv[o, 2, 0]) / spacing
            p21 = (tm[2, 0] * ainv[o, 0, 1] + tm[2, 1] * ainv[o, 1, 1] + tm[2, 2] * ainv[o, 2, 1]) / spacing
            p22 = (tm[2, 0] * ainv[o, 0, 2] + tm[2, 1] * ainv[o, 1, 2] + tm[2, 2] * ainv[o, 2, 2]) / spacing
            # 1. assignment (8.21) with conflict resolution: the closest candidate keeps a slot
            for q in range(nq):
                bestt[q] = -1
            # the neighbours' data in one pass (their loads overlap): offset, mass and id by row position
            for t in range(cnt):
                j = nbr[i, t]
                rt[0, t] = x[j, 0] - xi0
                rt[1, t] = x[j, 1] - xi1
                rt[2, t] = x[j, 2] - xi2
                rt[7, t] = m[j]
            if onebody:
                for t in range(cnt):
                    qt[t] = 1
            else:
                for t in range(cnt):
                    j = nbr[i, t]
                    qt[t] = np.int64((phase[j] == SOLID) & (obj[j] == oi))
            for t in range(cnt, pad):
                rt[0, t] = far
                rt[1, t] = far
                rt[2, t] = far
                rt[7, t] = 0.0
                qt[t] = 0
            if dim == 3:
                # vectorised rounding (flat table index as a float), weights and lattice offsets
                for t in range(pad):
                    y0 = rt[0, t]
                    y1 = rt[1, t]
                    y2 = rt[2, t]
                    idx, d2, k0, k1, k2 = _d3_round_k(p00 * y0 + p01 * y1 + p02 * y2, p10 * y0 + p11 * y1 + p12 * y2,
                                                      p20 * y0 + p21 * y1 + p22 * y2, thalf, tsize)
                    at[1, t] = idx
                    at[0, t] = d2
                    hw = max(h2 - (y0 * y0 + y1 * y1 + y2 * y2), 0.0)
                    at[2, t] = c6 * hw * hw * hw
                    # the lattice offset of the nearest point (the slot's, for a slot): d T⁻¹ k
                    rt[3, t] = st00 * k0 + st01 * k1 + st02 * k2
                    rt[4, t] = st10 * k0 + st11 * k1 + st12 * k2
                    rt[5, t] = st20 * k0 + st21 * k1 + st22 * k2
            else:
                for t in range(pad):
                    y0 = rt[0, t]
                    y1 = rt[1, t]
                    y2 = rt[2, t]
                    q, d2 = nearest_slot(p00 * y0 + p01 * y1 + p02 * y2, p10 * y0 + p11 * y1 + p12 * y2, 0.0,
                                         tm, table, dim)
                    q = q if qt[t] != 0 else -1
                    qt[t] = q
                    at[0, t] = d2
                    hw = max(h2 - (y0 * y0 + y1 * y1 + y2 * y2), 0.0)
                    at[2, t] = c6 * hw * hw * hw
                    qs = max(q, 0)  # any slot's offset for non-candidates: they weigh 0
                    rt[3, t] = lv[qs, 0]
                    rt[4, t] = lv[qs, 1]
                    rt[5, t] = lv[qs, 2]
            # conflicts (3D: slots by table look-up): the first candidate of a free slot takes it, a
            # closer one replaces it (conflicts are rare: no initialised distances, a predictable branch)
            for t in range(cnt):
                if dim == 3:
                    kk = int(at[1, t])
                    q = tflat[max(kk, 0)]
                    q = q if (kk >= 0) & (qt[t] != 0) else -1
                else:
                    q = qt[t]
                if q >= 0:
                    d2 = at[0, t]
                    if bestt[q] < 0 or d2 < bestd[q]:
                        bestd[q] = d2
                        bestt[q] = t
            # 2. docking (section 8.2.5), per slot; the docked winner of a slot is a member
            for t in range(pad):
                memb[t] = 0.0
            lmax = mats[mt, M.DOCK_MAX]
            frac = mats[mt, M.FRACTURE]
            brittle = frac < np.inf
            if not track and not brittle and (lmax == np.inf or prime):
                # every assigned slot docks at once (infinite gain and rate, or the initial state)
                for q in range(nq):
                    t = bestt[q]
                    has = t >= 0
                    occ_out[i, q] = uid[nbr[i, max(t, 0)]] if has else -1
                    docked_out[i, q] = has
                for q in range(nq):
                    t = bestt[q]
                    memb[t if t >= 0 else cap8] = 1.0
            else:
                _dock(i, o, rt, nbr[i], uid, bestt, memb, occ, docked, lam, occ_out, docked_out, mats[mt], slot_vecs, uid[i],
                      spacing, seed, step, dt, prime, track)
            # 3. shape matching sums (8.23) over the members, by row position (the others weigh 0)
            s00 = 0.0
            s01 = 0.0
            s02 = 0.0
            s11 = 0.0
            s12 = 0.0
            s22 = 0.0
            b00 = 0.0
            b01 = 0.0
            b02 = 0.0
            b10 = 0.0
            b11 = 0.0
            b12 = 0.0
            b20 = 0.0
            b21 = 0.0
            b22 = 0.0
            count = 0.0
            for t in range(pad):
                y0 = rt[0, t]
                y1 = rt[1, t]
                y2 = rt[2, t]
                w = at[2, t] * memb[t]
                count += memb[t]
                l0 = rt[3, t]
                l1 = rt[4, t]
                l2 = rt[5, t]
                rt[6, t] = w
                wl0 = w * l0
                wl1 = w * l1
                wl2 = w * l2
                s00 += wl0 * l0
                s01 += wl0 * l1
                s02 += wl0 * l2
                s11 += wl1 * l1
                s12 += wl1 * l2
                s22 += wl2 * l2
                b00 += w * y0 * l0
                b01 += w * y0 * l1
                b02 += w * y0 * l2
                b10 += w * y1 * l0
                b11 += w * y1 * l1
                b12 += w * y1 * l2
                b20 += w * y2 * l0
                b21 += w * y2 * l1
                b22 += w * y2 * l2
            if count < dim:
                _keep_previous(i, o, amat, ainv, amat_out, ainv_out, pmat, pmat_out)
                continue
            if dim == 2:
                s02 = s12 = 0.0
                b02 = b12 = b20 = b21 = 0.0
                s22 = 1.0
                b22 = 1.0
            ok[k] = 1.0
            cand[k] = 1.0
            rigid[k] = 1.0 if (count < few) & (mats[mt, M.FREEZE_RATE] > 0.0) else 0.0
            lane = (s00, s01, s02, s11, s12, s22, b00, b01, b02, b10, b11, b12, b20, b21, b22)
            for e in range(15):
                sums[e, k] = lane[e]
        # -- per lane (vectorised): M⁻¹ and A = B M⁻¹ (8.23), rejected when M is near singular --
        for k in range(LANES):
            s00, s11, s22 = sums[0, k], sums[3, k], sums[5, k]
            c00, c01, c02, c11, c12, c22, det = sym_adjugate(s00, sums[1, k], sums[2, k], s11, sums[4, k], s22)
            tr = (s00 + s11 + (s22 if dim == 3 else 0.0)) / dim
            trd = tr * tr * (tr if dim == 3 else 1.0)
            ok[k] = 1.0 if (ok[k] > 0.0) & (det > 1e-6 * trd) else 0.0
            inv = 1.0 / det if ok[k] > 0.0 else 0.0
            m00 = c00 * inv
            m01 = c01 * inv
            m02 = c02 * inv
            m11 = c11 * inv
            m12 = c12 * inv
            m22 = c22 * inv
            lane = (m00, m01, m02, m01, m11, m12, m02, m12, m22)
            for e in range(9):
                lminv[e, k] = lane[e]
            use = ok[k] > 0.0  # rejected and idle lanes decompose the identity
            for p in range(3):
                bp0 = sums[6 + 3 * p, k]
                bp1 = sums[7 + 3 * p, k]
                bp2 = sums[8 + 3 * p, k]
                la[3 * p, k] = bp0 * m00 + bp1 * m01 + bp2 * m02 if use else (1.0 if p == 0 else 0.0)
                la[3 * p + 1, k] = bp0 * m01 + bp1 * m11 + bp2 * m12 if use else (1.0 if p == 1 else 0.0)
                la[3 * p + 2, k] = bp0 * m02 + bp1 * m12 + bp2 * m22 if use else (1.0 if p == 2 else 0.0)
        # stored plastic deformation: decompose the elastic part A_e = A P⁻¹ (rest offsets P l)
        for k in range(LANES):
            lpl[k] = 0.0
            if plastic and k < nl and ok[k] > 0.0 and rigid[k] == 0.0 and mats[matid[g0 + k], M.YIELD] < np.inf:
                lpl[k] = 1.0
                _plastic_split(k, order[g0 + k], pmat, la, lminv, ltot, lp, lpi, pm, pinv)
        # polar decomposition (8.24) of every lane at once (3D; the SVD where it does not apply)
        if dim == 3:
            polar_lanes(la, lrot, lsym, fast, act)
        else:
            for k in range(LANES):
                fast[k] = 0.0
        # goal matrix (8.29-8.30), stabilised inverse for the next assignment, strain stress (8.2.2)
        for k in range(nl):
            i = g0 + k
            o = order[i]
            mt = matid[i]
            if ok[k] == 0.0:
                if cand[k] > 0.0:  # M near singular: the previous transformation stays
                    _keep_previous(i, o, amat, ainv, amat_out, ainv_out, pmat, pmat_out)
                continue
            valid[i] = 1
            for p in range(3):
                for q in range(3):
                    a[p, q] = la[3 * p + q, k]
            s = mats[mt, M.GOAL]
            if fast[k] > 0.0:
                # every singular value inside the clamps: functions of S = Rᵀ A by matrix algebra
                y00, y01, y02 = lsym[0, k], lsym[1, k], lsym[2, k]
                y11, y12, y22 = lsym[4, k], lsym[5, k], lsym[8, k]
                trs = y00 + y11 + y22 - 3.0
                if lpl[k] > 0.0:
                    for e in range(9):
                        ys[e // 3, e % 3] = lsym[e, k]
                f00 = s * y00 + (1.0 - s)
                f11 = s * y11 + (1.0 - s)
                f22 = s * y22 + (1.0 - s)
                f01 = s * y01
                f02 = s * y02
                f12 = s * y12
                fdet = (f00 * (f11 * f22 - f12 * f12) - f01 * (f01 * f22 - f12 * f02)
                        + f02 * (f01 * f12 - f11 * f02))
                norm = fdet ** (1.0 / 3.0)
                for p in range(3):
                    q0 = lrot[3 * p, k]
                    q1 = lrot[3 * p + 1, k]
                    q2 = lrot[3 * p + 2, k]
                    lg[3 * p, k] = (q0 * f00 + q1 * f01 + q2 * f02) / norm
                    lg[3 * p + 1, k] = (q0 * f01 + q1 * f11 + q2 * f12) / norm
                    lg[3 * p + 2, k] = (q0 * f02 + q1 * f12 + q2 * f22) / norm
                # S⁻¹ Rᵀ
                d00, d01, d02, d11, d12, d22, ydet = sym_adjugate(y00, y01, y02, y11, y12, y22)
                sinv = 1.0 / ydet
                for p in range(3):
                    e0 = (d00 if p == 0 else (d01 if p == 1 else d02)) * sinv
                    e1 = (d01 if p == 0 else (d11 if p == 1 else d12)) * sinv
                    e2 = (d02 if p == 0 else (d12 if p == 1 else d22)) * sinv
                    for q in range(3):
                        amat_out[i, p, q] = a[p, q]
                        ainv_out[i, p, q] = e0 * lrot[3 * q, k] + e1 * lrot[3 * q + 1, k] + e2 * lrot[3 * q + 2, k]
            else:
                svd_rot(a, dim, u, sg, v, work)
                is0 = min(max(sg[0], SIG_LO), SIG_HI)
                is1 = min(max(sg[1], SIG_LO), SIG_HI)
                is2 = min(max(sg[2], SIG_LO), SIG_HI)
                for p in range(3):
                    for q in range(3):
                        amat_out[i, p, q] = a[p, q]
                        ainv_out[i, p, q] = v[p, 0] * u[q, 0] / is0 + v[p, 1] * u[q, 1] / is1 + v[p, 2] * u[q, 2] / is2
                dg0 = s * max(sg[0], SIGMA_FLOOR) + (1.0 - s)
                dg1 = s * max(sg[1], SIGMA_FLOOR) + (1.0 - s)
                if dim == 3:
                    dg2 = s * max(sg[2], SIGMA_FLOOR) + (1.0 - s)
                    norm = (dg0 * dg1 * dg2) ** (1.0 / 3.0)
                    dg2 /= norm
                else:
                    dg2 = 1.0
                    norm = (dg0 * dg1) ** 0.5
                dg0 /= norm
                dg1 /= norm
                trs = (sg[0] - 1.0) + (sg[1] - 1.0)
                if lpl[k] > 0.0:  # the right stretch V Σ Vᵀ (clamped like the goal)
                    for p in range(3):
                        for q in range(3):
                            ys[p, q] = (v[p, 0] * max(sg[0], SIGMA_FLOOR) * v[q, 0] + v[p, 1] * max(sg[1], SIGMA_FLOOR)
                                        * v[q, 1] + v[p, 2] * max(sg[2], SIGMA_FLOOR) * v[q, 2])
                if dim == 3:
                    trs += sg[2] - 1.0
                for p in range(3):
                    for q in range(3):
                        lg[3 * p + q, k] = u[p, 0] * dg0 * v[q, 0] + u[p, 1] * dg1 * v[q, 1] + u[p, 2] * dg2 * v[q, 2]
                        lrot[3 * p + q, k] = u[p, 0] * v[q, 0] + u[p, 1] * v[q, 1] + u[p, 2] * v[q, 2]
            if rigid[k] > 0.0:
                # too few members for a stretch: the fit's rotation is the transformation and the goal
                trs = 0.0
                for p in range(3):
                    for q in range(3):
                        r_pq = lrot[3 * p + q, k]
                        a[p, q] = r_pq
                        lg[3 * p + q, k] = r_pq
                        amat_out[i, p, q] = r_pq
                        ainv_out[i, q, p] = r_pq
            if lpl[k] > 0.0:
                _plastic_finish(i, k, ys, ltot, lp, lpi, lg, amat_out, ainv_out, pmat_out, mats[mt, M.YIELD],
                                mats[mt, M.CREEP], dt, dim, pm)
            elif plastic:
                for p in range(3):
                    for q in range(3):
                        pmat_out[i, p, q] = pmat[o, p, q]
            if keep_goal:
                for e in range(9):
                    gmat[i, e // 3, e % 3] = lg[e, k]
            # strain stress: E = V_i P M⁻¹, P = 2μ (A − R) + λ tr(Rᵀ A − I) R (2D: no z row and column)
            lmu = mats[mt, M.LMU]
            llam = mats[mt, M.LLAM]
            vol = m[i] / mats[mt, M.RHO0]
            for p in range(3):
                pp0 = 2.0 * lmu * (a[p, 0] - lrot[3 * p, k]) + llam * trs * lrot[3 * p, k]
                pp1 = 2.0 * lmu * (a[p, 1] - lrot[3 * p + 1, k]) + llam * trs * lrot[3 * p + 1, k]
                pp2 = 2.0 * lmu * (a[p, 2] - lrot[3 * p + 2, k]) + llam * trs * lrot[3 * p + 2, k]
                if dim == 2:
                    pp2 = 0.0
                for q in range(3):
                    le[3 * p + q, k] = vol * (pp0 * lminv[q, k] + pp1 * lminv[3 + q, k] + pp2 * lminv[6 + q, k])
                    if dim == 2 and (p == 2 or q == 2):
                        le[3 * p + q, k] = 0.0
        # -- per particle: member forces (8.31 + strain), torque about x_i, weights for the correction --
        for k in range(LANES):  # rejected and idle lanes: a unit weight and inertia (their algebra stays finite)
            for e in range(16):
                tq[e, k] = 0.0
            tq[9, k] = tq[10, k] = tq[13, k] = tq[15, k] = 1.0
        for k in range(nl):
            if ok[k] == 0.0:
                continue
            i = g0 + k
            mt = matid[i]
            rt = nb[k]
            g00, g01, g02 = lg[0, k], lg[1, k], lg[2, k]
            g10, g11, g12 = lg[3, k], lg[4, k], lg[5, k]
            g20, g21, g22 = lg[6, k], lg[7, k], lg[8, k]
            e00, e01, e02 = le[0, k], le[1, k], le[2, k]
            e10, e11, e12 = le[3, k], le[4, k], le[5, k]
            e20, e21, e22 = le[6, k], le[7, k], le[8, k]
            chalf = 0.5 * mats[mt, M.KE] * m[i] / mats[mt, M.RHO0]
            fs0 = 0.0
            fs1 = 0.0
            fs2 = 0.0
            t0 = 0.0
            t1 = 0.0
            t2 = 0.0
            wi = m[i] * w_self
            wsum = wi
            c0 = 0.0
            c1 = 0.0
            c2 = 0.0
            i00 = 0.0
            i01 = 0.0
            i02 = 0.0
            i11 = 0.0
            i12 = 0.0
            i22 = 0.0
            for t in range(lpad[k]):
                y0 = rt[0, t]
                y1 = rt[1, t]
                y2 = rt[2, t]
                l0 = rt[3, t]
                l1 = rt[4, t]
                l2 = rt[5, t]
                w = rt[6, t]
                mk = rt[7, t]
                cw = chalf * mk * w
                f0 = cw * (g00 * l0 + g01 * l1 + g02 * l2 - y0) - w * (e00 * l0 + e01 * l1 + e02 * l2)
                f1 = cw * (g10 * l0 + g11 * l1 + g12 * l2 - y1) - w * (e10 * l0 + e11 * l1 + e12 * l2)
                f2 = cw * (g20 * l0 + g21 * l1 + g22 * l2 - y2) - w * (e20 * l0 + e21 * l1 + e22 * l2)
                rt[8, t] = f0
                rt[9, t] = f1
                rt[10, t] = f2
                fs0 += f0
                fs1 += f1
                fs2 += f2
                t0 += y1 * f2 - y2 * f1
                t1 += y2 * f0 - y0 * f2
                t2 += y0 * f1 - y1 * f0
                wk = mk * w
                wsum += wk
                c0 += wk * y0
                c1 += wk * y1
                c2 += wk * y2
                i00 += wk * (y1 * y1 + y2 * y2)
                i11 += wk * (y0 * y0 + y2 * y2)
                i22 += wk * (y0 * y0 + y1 * y1)
                i01 -= wk * y0 * y1
                i02 -= wk * y0 * y2
                i12 -= wk * y1 * y2
            lane = (fs0, fs1, fs2, t0, t1, t2, c0, c1, c2, wsum, i00, i01, i02, i11, i12, i22)
            for e in range(16):
                tq[e, k] = lane[e]
        # -- per lane (vectorised): centroid, inertia about it, ω = −I⁻¹ τ --
        for k in range(LANES):
            wsum = tq[9, k]
            c0 = tq[6, k] / wsum
            c1 = tq[7, k] / wsum
            c2 = tq[8, k] / wsum
            cc = c0 * c0 + c1 * c1 + c2 * c2
            i00 = tq[10, k] - wsum * (cc - c0 * c0)
            i11 = tq[13, k] - wsum * (cc - c1 * c1)
            i22 = tq[15, k] - wsum * (cc - c2 * c2)
            i01 = tq[11, k] + wsum * c0 * c1
            i02 = tq[12, k] + wsum * c0 * c2
            i12 = tq[14, k] + wsum * c1 * c2
            t0 = tq[3, k]
            t1 = tq[4, k]
            t2 = tq[5, k]
            if dim == 2:
                om0 = 0.0
                om1 = 0.0
                om2 = -t2 / i22 if i22 > 0.0 else 0.0
            else:
                d00, d01, d02, d11, d12, d22, det = sym_adjugate(i00, i01, i02, i11, i12, i22)
                inv = -1.0 / det if det != 0.0 else 0.0
                om0 = (d00 * t0 + d01 * t1 + d02 * t2) * inv
                om1 = (d01 * t0 + d11 * t1 + d12 * t2) * inv
                om2 = (d02 * t0 + d12 * t1 + d22 * t2) * inv
            lane = (om0, om1, om2, c0, c1, c2)  # ω over the torque, the centroid over its weighted sum
            for e in range(6):
                tq[3 + e, k] = lane[e]
        # -- per particle: own share, members' forces + torque correction into the block's window --
        for k in range(nl):
            if ok[k] == 0.0:
                continue
            i = g0 + k
            rt = nb[k]
            om0 = tq[3, k]
            om1 = tq[4, k]
            om2 = tq[5, k]
            c0 = tq[6, k]
            c1 = tq[7, k]
            c2 = tq[8, k]
            wi = m[i] * w_self
            fown[i, 0] = -tq[0, k] + wi * (om1 * (-c2) - om2 * (-c1))
            fown[i, 1] = -tq[1, k] + wi * (om2 * (-c0) - om0 * (-c2))
            fown[i, 2] = -tq[2, k] + wi * (om0 * (-c1) - om1 * (-c0))
            for t in range(lpad[k]):
                y0 = rt[0, t] - c0
                y1 = rt[1, t] - c1
                y2 = rt[2, t] - c2
                wk = rt[7, t] * rt[6, t]
                rt[8, t] += wk * (om1 * y2 - om2 * y1)
                rt[9, t] += wk * (om2 * y0 - om0 * y2)
                rt[10, t] += wk * (om0 * y1 - om1 * y0)
            for t in range(min(nnbr[i], cap)):
                row = nbr[i, t] - lo_b
                win[row, 0] += rt[8, t]
                win[row, 1] += rt[9, t]
                win[row, 2] += rt[10, t]


@njit(**PLAIN)
def _dock(i, o, rt, row, uid, bestt, memb, occ, docked, lam, occ_out, docked_out, mat, slot_vecs, uid_i, spacing, seed,
          step, dt, prime, track):
    """Docking (section 8.2.5) of particle ``i``'s slots with finite rates or fracture: occupants, docking
    flags and rates (row ``i``), members flagged in ``memb`` by row position."""
    nq = slot_vecs.shape[0]
    lmax = mat[M.DOCK_MAX]
    gain = mat[M.DOCK_GAIN]
    loss = mat[M.DOCK_LOSS]
    frac = mat[M.FRACTURE]
    gain_fin = gain < np.inf
    loss_fin = loss < np.inf
    brittle = frac < np.inf
    for q in range(nq):
        t = bestt[q]
        has = t >= 0
        newocc = uid[row[max(t, 0)]] if has else -1
        dk = docked[o, q] if newocc == occ[o, q] else 0  # a new occupant starts undocked
        occ_out[i, q] = newocc
        if track:
            lq = lam[i, q]
            lup = min(lq + gain * dt, lmax) if gain_fin else lmax
            ldown = max(lq - loss * dt, 0.0) if loss_fin else 0.0
            lnew = lup if has else ldown
            if lnew != lq:  # a settled rate is not rewritten (no dirty cache lines)
                lam[i, q] = lnew
        else:  # an infinite gain: the rate of an assigned slot is the maximum, whatever it was
            lnew = lmax
        if has and dk == 0:
            if prime:
                dk = 1
            elif lnew > 0.0:
                if lnew == np.inf or uniform(seed, step, uid_i, q, STREAM_DOCK) < 1.0 - math.exp(-lnew * dt):
                    dk = 1
        if brittle and has and dk == 1:
            rr = rt[0, t] * rt[0, t] + rt[1, t] * rt[1, t] + rt[2, t] * rt[2, t]
            rest = spacing * math.sqrt(slot_vecs[q, 0] ** 2 + slot_vecs[q, 1] ** 2 + slot_vecs[q, 2] ** 2)
            if math.sqrt(rr) > (1.0 + frac) * rest:
                if track and gain_fin:
                    # the stress criterion modifies λ_d (section 8.2.5): an overstretched slot loses its
                    # rate like an empty one and lets go when it reaches 0 (a sustained overload breaks
                    # it, a transient of less than λ_d/Δλ_d⁻ does not)
                    ldown = max(lq - loss * dt, 0.0) if loss_fin else 0.0
                    lam[i, q] = ldown
                    if ldown <= 0.0:
                        dk = 0
                else:  # an infinite gain restores any rate at once: the overstretched neighbour lets go now
                    dk = 0
                    if track:
                        lam[i, q] = 0.0
        docked_out[i, q] = dk
        if has and dk == 1:
            memb[t] = 1.0


@njit(cache=True, parallel=True)
def lattice_update(x, m, phase, obj, matid, uid, mats, nbr, nnbr, h, dim, spacing,
                   slot_vecs, tmat, table, order, amat, ainv, occ, docked, lam,
                   seed, step, dt, prime,
                   amat_out, ainv_out, occ_out, docked_out, gmat, fown, valid, fel, pmat, pmat_out):
    """Lattice assignment, docking, shape matching and neighbourhood forces for every solid particle.

    Inputs are in cell-sorted order; ``nbr`` rows ascending. The state of the previous step
    (``amat``, ``ainv``, occupant ids ``occ`` (N, Q) int32, -1 empty, ``docked`` (N, Q) uint8) is
    read at rows ``order`` (N,): particle ``i`` was row ``order[i]`` before the re-sort, so the
    state needs no re-sort of its own (the pass writes it in the new order: ``amat_out``,
    ``ainv_out``, ``occ_out``, ``docked_out``; an identity ``order`` may update ``occ`` and
    ``docked`` in place). The docking rates ``lam`` (N, Q) are updated in place. ``lam`` may have no columns, (N, 0), when every material docks with an
    infinite gain (the default): the rate of an assigned slot is then the maximum ``λ_d``
    whatever it was before, so the rates are never needed (the results are the same).
    Outputs per particle: new ``A`` and its stabilised inverse (the previous ones where the
    neighbourhood does not span the space), the goal matrix ``U S Vᵀ`` (8.29–8.30, into
    ``gmat`` unless it has no rows, (0, 3, 3): only freezing needs it), the particle's own
    share ``fown`` and ``valid`` (1 when the neighbourhood spans the space). ``prime`` (initial state) docks every assigned
    neighbour at once. ``fel`` (N, 3) receives the forces the neighbourhoods exert on their
    members: for particle ``j`` the sum over the neighbourhoods it is docked in of the
    direct + strain force and the exact torque correction ``w_j ω_i × (r_ij − c_i)``. The
    total elastic force on ``j`` is ``fown[j] + fel[j]``.

    Per particle ``i`` (small per-block buffers, columns by neighbour row): one vectorised loop
    over the neighbours rounds them to the lattice (8.21; in 3D the map ``T A⁻¹/d`` is formed once,
    :func:`unmesh.sph._slot_kernels._d3_round_k`) and gives their weights and the lattice offsets of
    their points; a short scalar loop resolves the slot conflicts, one over the slots docks; the
    members (docked winners) weigh ``W``, the other neighbours 0, in the vectorised sums ``M = Σ W l lᵀ``
    and ``B = Σ W r lᵀ`` (8.23) and in the member forces. The 3×3 algebra runs per group of
    :data:`LANES` particles: ``A = B M⁻¹``, its polar decomposition
    (:func:`unmesh.sph._polar_kernels.polar_lanes`; the SVD where a singular value is clamped, in 2D
    and for inverted lattices), the goal and strain matrices, and the ``ω`` of the torque
    correction. The forces on the members are added into the block's accumulator window, then
    summed per particle. The sums run in neighbour-row order (not slot order): results equal the
    numpy reference to round-off.
    """
    n = x.shape[0]
    nq = slot_vecs.shape[0]
    cap = nbr.shape[1]
    nblk = max(1, min(LATTICE_BLOCKS, n))
    h2 = h * h
    w_self = _w_zero(h, dim)
    c6 = w_self / (h2 * h2 * h2)  # W(r) = c6 (h² − r²)³
    # slot offsets in length units
    lv = np.empty((nq, 3))
    for q in range(nq):
        for p in range(3):
            lv[q, p] = slot_vecs[q, p] * spacing
    tm = tmat if dim == 3 else _EYE
    # D3 coordinates -> lattice offsets (length units): d T⁻¹ (3D)
    dti = np.empty((3, 3))
    _inv3(tm, dti)
    for p in range(3):
        for q in range(3):
            dti[p, q] *= spacing
    # accumulator windows: block b adds member forces into rows lo[b]..hi[b]
    lo = np.empty(nblk, np.int64)
    hi = np.empty(nblk, np.int64)
    for blk in range(nblk):
        lo_b = n
        hi_b = -1
        for i in range(blk * n // nblk, (blk + 1) * n // nblk):
            c = min(nnbr[i], cap)
            if c > 0:
                lo_b = min(lo_b, nbr[i, 0])
                hi_b = max(hi_b, nbr[i, c - 1])
        lo[blk] = lo_b
        hi[blk] = hi_b
    wmax = 1
    for blk in range(nblk):
        wmax = max(wmax, hi[blk] - lo[blk] + 1)
    win = np.empty((nblk, wmax, 3))
    others = 0
    for i in range(n):
        others += (phase[i] != SOLID) | (obj[i] != obj[0])
    onebody = others == 0
    for blk in prange(nblk):
        _lattice_block(blk * n // nblk, (blk + 1) * n // nblk, lo[blk], win[blk], x, m, phase, obj, matid, uid, mats,
                       nbr, nnbr, h, dim, spacing, slot_vecs, lv, dti, c6, w_self, tm, table, order, amat,
                       ainv, occ, docked, lam, seed, step, dt, prime, onebody, amat_out, ainv_out, occ_out, docked_out,
                       gmat, fown, valid, pmat, pmat_out)
    # the windows summed in block order (deterministic, whatever the thread count), in parallel over rows
    nchunk = (n + SUM_ROWS - 1) // SUM_ROWS
    for ch in prange(nchunk):
        j0 = ch * SUM_ROWS
        j1 = min(n, j0 + SUM_ROWS)
        for j in range(j0, j1):
            fel[j, 0] = 0.0
            fel[j, 1] = 0.0
            fel[j, 2] = 0.0
        for blk in range(nblk):
            for j in range(max(j0, lo[blk]), min(j1, hi[blk] + 1)):
                row = j - lo[blk]
                fel[j, 0] += win[blk, row, 0]
                fel[j, 1] += win[blk, row, 1]
                fel[j, 2] += win[blk, row, 2]
