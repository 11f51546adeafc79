"""Numba kernel of one whole time step of the thin shell (thesis 7.2.2 eq. 7.18, 7.3.1, 7.24).

:func:`shell_step` does in one call what :meth:`unmesh.shells.ShellSimulation.step_plain`
does with numpy and several kernel calls: the velocity-Verlet step of (7.18) with the
elastic forces of :func:`unmesh.shells._force_kernels.node_forces`, gravity, mass-proportional
damping, pressure and given extra forces, the kinematic (pinned and handle) nodes, plane
and sphere colliders, the crumbs that follow their anchors, plasticity (7.19-7.23, 7.25)
and the per-step fracture test (7.24). The plain path is its reference
(``tests/shells/test_step_kernel.py``).

All work is split into fixed node or fiber ranges (``chunks``), so the result does not
depend on the number of threads.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.shells._block_kernels import BLK, ROWS
from unmesh.shells._fiber_kernels import FASTMATH
from unmesh.shells._force_kernels import SCRATCH, _clear_rows, chunk_forces, sum_chunks, touched_range

#: Collider kinds in ``col_type``; ``col_data`` rows are (point, normal, restitution, friction)
#: for planes and (center, radius, -, -, restitution, friction) for spheres.
PLANE = 0
SPHERE = 1


@njit(cache=True, inline="always")
def _kinematic(j, h, rest, hdisp, hvel, x, v):
    """Set node ``j`` to its kinematic state: at rest (``h < 0``) or moved by handle ``h``."""
    if h < 0:
        for c in range(3):
            x[j, c] = rest[j, c]
            v[j, c] = 0.0
    else:
        for c in range(3):
            x[j, c] = rest[j, c] + hdisp[h, c]
            v[j, c] = hvel[h, c]


@njit(cache=True, inline="always")
def _friction(i, n0, n1, n2, e, mu, v):
    """Reflect the inward normal velocity of node ``i`` (restitution ``e``), Coulomb friction ``mu``
    on the tangential part (:func:`unmesh.shells.dynamics._friction`)."""
    vn = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
    t0 = v[i, 0] - vn * n0
    t1 = v[i, 1] - vn * n1
    t2 = v[i, 2] - vn * n2
    inward = vn < 0.0
    dvn = -(1.0 + e) * vn if inward else 0.0
    tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    keep = max(0.0, 1.0 - mu * dvn / max(tn, 1e-300)) if tn > 0.0 else 1.0
    new_vn = -e * vn if inward else vn
    v[i, 0] = t0 * keep + new_vn * n0
    v[i, 1] = t1 * keep + new_vn * n1
    v[i, 2] = t2 * keep + new_vn * n2


@njit(cache=True)
def _collide(i, col_type, col_data, x, v):
    """Resolve node ``i`` against every collider in order (PlaneCollider / SphereCollider.resolve)."""
    for c in range(col_type.shape[0]):
        p0 = col_data[c, 0]
        p1 = col_data[c, 1]
        p2 = col_data[c, 2]
        if col_type[c] == PLANE:
            n0 = col_data[c, 3]
            n1 = col_data[c, 4]
            n2 = col_data[c, 5]
            dist = (x[i, 0] - p0) * n0 + (x[i, 1] - p1) * n1 + (x[i, 2] - p2) * n2
            if dist < 0.0:
                x[i, 0] -= dist * n0
                x[i, 1] -= dist * n1
                x[i, 2] -= dist * n2
                _friction(i, n0, n1, n2, col_data[c, 6], col_data[c, 7], v)
        else:
            rad = col_data[c, 3]
            r0 = x[i, 0] - p0
            r1 = x[i, 1] - p1
            r2 = x[i, 2] - p2
            dist = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if dist < rad:
                if dist == 0.0:
                    n0, n1, n2 = 0.0, 1.0, 0.0
                else:
                    inv = 1.0 / max(dist, 1e-300)
                    n0, n1, n2 = r0 * inv, r1 * inv, r2 * inv
                x[i, 0] = p0 + rad * n0
                x[i, 1] = p1 + rad * n1
                x[i, 2] = p2 + rad * n2
                _friction(i, n0, n1, n2, col_data[c, 6], col_data[c, 7], v)


#: The node loops must run one after the other: no fusion of the parallel loops.
@njit(cache=True, parallel={"fusion": False}, fastmath=FASTMATH, error_model="numpy")
def shell_step(chunks, dt, x, v, acc, rest, mass, area, kin_handle, hdisp, hvel,
               pairs, pstart, pcount, soft, fibers, fstart, fcount, cap,
               lorig, lplast, aorig, aplast, sscale, bscale, gamma_s, gamma_b,
               ks, kb, gram, ref, offs, gravity, damping, pressure, fan0, extra,
               col_type, col_data, crumbs, anchors, plastic, degenerate, scan,
               buf, out_force, out_len, out_ang, out_s, out_normal, out_node, out_es, out_eb, out_x):
    """One velocity-Verlet step of (7.18) with plasticity and the fracture test, in place.

    Parameters (N nodes, F fibers; arrays float64 unless noted)
    ----------------------------------------------------------
    chunks : int
        Number of fixed node / fiber ranges (and of force buffers ``buf`` (chunks, N, 3)).
    x, v, acc : (N, 3)
        Positions, velocities and the accelerations of the previous step; updated.
    rest, mass, area : (N, 3), (N,), (N,)
    kin_handle : (N,) int64
        -2 free node, -1 pinned at rest, h >= 0 moved by handle ``h``: ``x = rest + hdisp[h]``,
        ``v = hvel[h]`` (H, 3), evaluated at the new time.
    pairs .. cap
        Topology (as for :func:`unmesh.shells._force_kernels.force_chunks`).
    lorig .. gamma_b : (F,)
        Fiber state; ``lplast``, ``aplast`` and ``gamma_b`` are updated by plasticity.
    ks, kb, gram, ref, offs
        As for :func:`unmesh.shells._force_kernels.node_forces`.
    gravity : (3,)
    damping : float
        ``D`` of the force ``-D m v``.
    pressure : float
        Pressure ``p(t)``; the force is ``p a_i r_i N_i`` with ``r_i = |s_i| / fan0_i`` (1 where
        not finite). 0 disables it.
    extra : (N, 3) or (0, 3)
        Further external forces (pulls), if given.
    col_type, col_data : (C,) int64, (C, 8)
        Colliders, resolved in order.
    crumbs, anchors : (K,) int64
        Nodes that follow their anchor rigidly.
    plastic : (6,)
        ``creep_stretch, creep_bend, yield_stretch, yield_bend, weakening`` and a flag word
        (1: stretch creep active, 2: bend creep active).
    degenerate : float
        Squared end/centre tangent ratio below which a fiber counts as degenerate (0: no test);
        the end tangents projected onto the fiber's normal plane, tested in the force pass at
        the positions ``out_x`` with ``out_s`` and ``soft`` (:func:`unmesh.shells.fibers.degenerate`).
    scan : bool
        Count fibers over a fracture threshold and degenerate ones.
    buf, out_* :
        Scratch and outputs of the force pass (forces, l~, theta, s_i, N_i, node terms, energies,
        and the positions ``out_x`` (N, 3) they were evaluated at).

    Returns
    -------
    (over, bad, folds)
        Fibers over a fracture threshold (7.24) (0 unless ``scan``) and degenerate fibers (0
        unless ``degenerate``), and fibers whose angle moved by more than pi/2 since ``ref``.
    """
    n = x.shape[0]
    nf = fibers.shape[0]
    half = 0.5 * dt
    # first half kick and drift; kinematic nodes at the new time
    for c in prange(chunks):
        for i in range(c * n // chunks, (c + 1) * n // chunks):
            for d in range(3):
                v[i, d] += half * acc[i, d]
                x[i, d] += dt * v[i, d]
            if kin_handle[i] > -2:
                _kinematic(i, kin_handle[i], rest, hdisp, hvel, x, v)
            for d in range(3):
                out_x[i, d] = x[i, d]
    # elastic forces: every node range scatters into its own buffer (and counts degenerate fibers)
    folds = 0
    bad = 0
    span = np.empty((chunks, 2), dtype=np.int64)  # plain loops (an array expression would be a parfor)
    # the arguments of force_chunks' call of chunk_forces (a writable empty mask, a run-time flag), so
    # that one compiled chunk_forces serves both kernels (a constant True or a global array would be a
    # second signature and a second compile of the force pass)
    nomask = np.empty(0, dtype=np.bool_)
    scatter = chunks > 0
    for c in prange(chunks):
        b = buf[c]
        lo, hi = touched_range(c * n // chunks, (c + 1) * n // chunks, pairs, pstart, pcount, fibers, fstart, fcount,
                               nomask)
        span[c, 0] = lo
        span[c, 1] = hi
        _clear_rows(b, lo, hi)
        blk = np.empty(ROWS * BLK)
        scr = np.empty((max(cap, 1), SCRATCH))
        fo, bd = chunk_forces(c * n // chunks, (c + 1) * n // chunks, x, pairs, pstart, pcount, soft, fibers, fstart,
                              fcount, lorig, lplast, aorig, aplast, sscale, bscale, ks, kb, gram, ref, offs, b, blk,
                              scr, out_len, out_ang, out_s, out_normal, out_node, out_es, out_eb, nomask, scatter,
                              degenerate)
        folds += fo
        bad += bd
    # accelerations, second half kick, kinematic nodes, colliders
    has_extra = extra.shape[0] == n
    g0 = gravity[0]
    g1 = gravity[1]
    g2 = gravity[2]
    for c in prange(chunks):
        for i in range(c * n // chunks, (c + 1) * n // chunks):
            f0, f1, f2 = sum_chunks(i, chunks, buf, span)
            out_force[i, 0] = f0
            out_force[i, 1] = f1
            out_force[i, 2] = f2
            m = mass[i]
            md = -damping * m
            e0 = m * g0 + md * v[i, 0]
            e1 = m * g1 + md * v[i, 1]
            e2 = m * g2 + md * v[i, 2]
            if pressure != 0.0:
                sn = math.sqrt(out_s[i, 0] ** 2 + out_s[i, 1] ** 2 + out_s[i, 2] ** 2)
                r = sn / fan0[i] if fan0[i] != 0.0 else math.inf
                if not math.isfinite(r):
                    r = 1.0
                pa = pressure * (area[i] * r)
                e0 += pa * out_normal[i, 0]
                e1 += pa * out_normal[i, 1]
                e2 += pa * out_normal[i, 2]
            if has_extra:
                e0 += extra[i, 0]
                e1 += extra[i, 1]
                e2 += extra[i, 2]
            h = kin_handle[i]
            if h > -2:
                acc[i, 0] = 0.0
                acc[i, 1] = 0.0
                acc[i, 2] = 0.0
                _kinematic(i, h, rest, hdisp, hvel, x, v)
            else:
                acc[i, 0] = (f0 + e0) / m
                acc[i, 1] = (f1 + e1) / m
                acc[i, 2] = (f2 + e2) / m
                for d in range(3):
                    v[i, d] += half * acc[i, d]
            if col_type.shape[0] > 0:  # an ordinary call (inlined, it is compiled again with the parallel loop)
                _collide(i, col_type, col_data, x, v)
    for k in range(crumbs.shape[0]):
        j = crumbs[k]
        a = anchors[k]
        for d in range(3):
            x[j, d] = x[a, d] + (rest[j, d] - rest[a, d])
            v[j, d] = v[a, d]
    # plasticity (7.20-7.23, 7.25), then the fracture test (7.24) on the updated rest state
    cs, cb, ys, yb, weak = plastic[0], plastic[1], plastic[2], plastic[3], plastic[4]
    flags = int(plastic[5])
    over = 0
    if flags == 0 and not scan:
        return over, bad, folds
    for c in prange(chunks):
        for k in range(c * nf // chunks, (c + 1) * nf // chunks):
            ln = out_len[k]
            th = out_ang[k]
            if flags & 1:
                l0 = lorig[k] + lplast[k]
                dl = ln - l0
                if abs(dl) > ys * l0:
                    lplast[k] += cs * dl * dt
            if flags & 2:
                dth = th - (aorig[k] + aplast[k])
                if abs(dth) > yb:
                    step = cb * dth * dt
                    aplast[k] += step
                    if weak > 0.0:
                        gamma_b[k] *= max(0.0, 1.0 - weak * abs(step))
            if scan:
                if ln > (lorig[k] + lplast[k]) * (1.0 + gamma_s[k]) or abs(th - (aorig[k] + aplast[k])) > gamma_b[k]:
                    over += 1
    return over, bad, folds


@njit(cache=True)
def check_stats(x, v, mass, angles, prev, es, eb):
    """``(finite, kinetic energy, max |v|^2, jumps, elastic energy)`` of a state for ShellSimulation.check.

    ``finite``: no NaN or infinity in ``x`` and ``v``; ``jumps``: fibers whose angle differs
    from ``prev`` by more than pi/2 (0 when ``prev`` is empty); the elastic energy is the sum
    of the node energies ``es`` and ``eb`` (N,).
    """
    elastic = 0.0
    for i in range(es.shape[0]):
        elastic += es[i]
    for i in range(eb.shape[0]):
        elastic += eb[i]
    finite = True
    ke = 0.0
    vmax = 0.0
    for i in range(x.shape[0]):
        s = 0.0
        for d in range(3):
            if not (math.isfinite(x[i, d]) and math.isfinite(v[i, d])):
                finite = False
            s += v[i, d] * v[i, d]
        ke += mass[i] * s
        vmax = max(vmax, s)
    jumps = 0
    if prev.shape[0] == angles.shape[0]:
        half_pi = 0.5 * math.pi
        for k in range(angles.shape[0]):
            if abs(angles[k] - prev[k]) > half_pi:
                jumps += 1
    return finite, 0.5 * ke, vmax, jumps, elastic
