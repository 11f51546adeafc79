"""Numba kernels for fiber geometry and elastic forces (thesis 7.2, Appendix B).

Numpy references: :mod:`unmesh.shells.fibers` (geometry) and
:func:`unmesh.shells.energy.elastic_forces_reference` (forces). Forces are computed in
two passes as in 7.2.2: the first pass (parallel over centre nodes, whose fibers are
contiguous) evaluates ``l~``, ``theta`` and their gradients for every fiber, the node sums
``A_i``, ``H_i`` and the per-fiber force triplets (7.16); the second pass (parallel over
nodes) gathers the triplets and the umbrella-normal terms through incidence lists, so no
two threads write the same entry.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: Regularisation of the tangent angle's cosine part (unmesh.shells.fibers.TANGENT_SOFTENING).
SOFT_X = 0.05

#: Fast-math flags: FMA contraction, reciprocal and reassociation; NaN/inf semantics kept.
FASTMATH = {"nsz", "arcp", "contract", "reassoc"}


def sample_weights(samples: int) -> np.ndarray:
    """Weights (2n, 3) of f1'(s_i) then f2'(s_i) on (x1, x, x2) at s_i = (i + 1/2)/n (B.4, B.6)."""
    s = (np.arange(samples) + 0.5) / samples
    w1 = np.stack([-1.25 + 0.75 * s**2, 1.5 - 1.5 * s**2, -0.25 + 0.75 * s**2], axis=1)
    w2 = np.stack([-0.5 + 1.5 * s - 0.75 * s**2, -3.0 * s + 1.5 * s**2, 0.5 + 1.5 * s - 0.75 * s**2], axis=1)
    return np.ascontiguousarray(np.concatenate([w1, w2]))


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, fastmath=FASTMATH)
def fiber_length(x, j1, i, j2, weights, grad, with_grad):
    """Arc length l~ (B.4) of fiber (j1, i, j2) with the speed weights of :func:`sample_weights`.

    When ``with_grad``, grad (3, 3) receives dl/d(x1, x, x2) (B.5, B.6).
    """
    ax, ay, az = x[j1, 0], x[j1, 1], x[j1, 2]
    bx, by, bz = x[i, 0], x[i, 1], x[i, 2]
    cx, cy, cz = x[j2, 0], x[j2, 1], x[j2, 2]
    total = 0.0
    g00 = g01 = g02 = g10 = g11 = g12 = g20 = g21 = g22 = 0.0
    for r in range(weights.shape[0]):
        w0 = weights[r, 0]
        w1 = weights[r, 1]
        w2 = weights[r, 2]
        v0 = w0 * ax + w1 * bx + w2 * cx
        v1 = w0 * ay + w1 * by + w2 * cy
        v2 = w0 * az + w1 * bz + w2 * cz
        sp = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        total += sp
        if with_grad and sp > 0.0:
            u0 = v0 / sp
            u1 = v1 / sp
            u2 = v2 / sp
            g00 += w0 * u0
            g01 += w0 * u1
            g02 += w0 * u2
            g10 += w1 * u0
            g11 += w1 * u1
            g12 += w1 * u2
            g20 += w2 * u0
            g21 += w2 * u1
            g22 += w2 * u2
    inv = 2.0 / weights.shape[0]
    if with_grad:
        grad[0, 0] = g00 * inv
        grad[0, 1] = g01 * inv
        grad[0, 2] = g02 * inv
        grad[1, 0] = g10 * inv
        grad[1, 1] = g11 * inv
        grad[1, 2] = g12 * inv
        grad[2, 0] = g20 * inv
        grad[2, 1] = g21 * inv
        grad[2, 2] = g22 * inv
    return total * inv


@njit(cache=True, fastmath=FASTMATH)
def fiber_angle(x, j1, i, j2, n0, n1, n2, soft, grad, gnormal, with_grad):
    """Tangent angle theta = atan2(a.(t0 x t1), t0.t1 - (t0.a)(t1.a) + SOFT_X |tc|^2), a = u / sqrt(|u|^2 + soft^2 |tc|^2).

    When ``with_grad``, grad (3, 3) receives dtheta/d(x1, x, x2) and gnormal (3,) dtheta/dN;
    see :func:`unmesh.shells.fibers.bending_angle_gradient` for the derivation.
    """
    a1x, a1y, a1z = x[j1, 0], x[j1, 1], x[j1, 2]
    bx, by, bz = x[i, 0], x[i, 1], x[i, 2]
    a2x, a2y, a2z = x[j2, 0], x[j2, 1], x[j2, 2]
    t00 = -1.25 * a1x + 1.5 * bx - 0.25 * a2x
    t01 = -1.25 * a1y + 1.5 * by - 0.25 * a2y
    t02 = -1.25 * a1z + 1.5 * bz - 0.25 * a2z
    t10 = 0.25 * a1x - 1.5 * bx + 1.25 * a2x
    t11 = 0.25 * a1y - 1.5 * by + 1.25 * a2y
    t12 = 0.25 * a1z - 1.5 * bz + 1.25 * a2z
    tc0 = 0.5 * (a2x - a1x)
    tc1 = 0.5 * (a2y - a1y)
    tc2 = 0.5 * (a2z - a1z)
    u0, u1, u2 = _cross(n0, n1, n2, tc0, tc1, tc2)
    c2 = soft * soft * (tc0 * tc0 + tc1 * tc1 + tc2 * tc2)
    rho = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2 + c2)
    if rho > 0.0:
        a0, a1, a2 = u0 / rho, u1 / rho, u2 / rho
    else:
        a0, a1, a2 = 0.0, 0.0, 0.0
    c0, c1, c2 = _cross(t00, t01, t02, t10, t11, t12)
    ta0 = t00 * a0 + t01 * a1 + t02 * a2
    ta1 = t10 * a0 + t11 * a1 + t12 * a2
    X = t00 * t10 + t01 * t11 + t02 * t12 - ta0 * ta1 + SOFT_X * (tc0 * tc0 + tc1 * tc1 + tc2 * tc2)
    Y = a0 * c0 + a1 * c1 + a2 * c2
    theta = math.atan2(Y, X)
    if not with_grad:
        return theta
    D = X * X + Y * Y
    if D <= 0.0:
        for r in range(3):
            gnormal[r] = 0.0
            for c in range(3):
                grad[r, c] = 0.0
        return theta
    gx = -Y / D
    gy = X / D
    # dtheta/dt0 = gy (t1 x a) + gx (t1 - (t1.a) a), dtheta/dt1 = gy (a x t0) + gx (t0 - (t0.a) a)
    p0, p1, p2 = _cross(t10, t11, t12, a0, a1, a2)
    q0, q1, q2 = _cross(a0, a1, a2, t00, t01, t02)
    g00 = gy * p0 + gx * (t10 - ta1 * a0)
    g01 = gy * p1 + gx * (t11 - ta1 * a1)
    g02 = gy * p2 + gx * (t12 - ta1 * a2)
    g10 = gy * q0 + gx * (t00 - ta0 * a0)
    g11 = gy * q1 + gx * (t01 - ta0 * a1)
    g12 = gy * q2 + gx * (t02 - ta0 * a2)
    # through a = u/|u|, u = N x tc: dtheta/da = gy (t0 x t1) - gx ((t1.a) t0 + (t0.a) t1)
    ga0 = gy * c0 - gx * (ta1 * t00 + ta0 * t10)
    ga1 = gy * c1 - gx * (ta1 * t01 + ta0 * t11)
    ga2 = gy * c2 - gx * (ta1 * t02 + ta0 * t12)
    if rho > 0.0:
        ug = (u0 * ga0 + u1 * ga1 + u2 * ga2) / (rho * rho * rho)
        gu0, gu1, gu2 = ga0 / rho - u0 * ug, ga1 / rho - u1 * ug, ga2 / rho - u2 * ug
    else:
        ug = 0.0
        gu0, gu1, gu2 = 0.0, 0.0, 0.0
    gn0, gn1, gn2 = _cross(tc0, tc1, tc2, gu0, gu1, gu2)
    gt0, gt1, gt2 = _cross(gu0, gu1, gu2, n0, n1, n2)
    ss = soft * soft * ug - 2.0 * SOFT_X * gx
    gt0 -= ss * tc0
    gt1 -= ss * tc1
    gt2 -= ss * tc2
    gnormal[0] = gn0
    gnormal[1] = gn1
    gnormal[2] = gn2
    grad[0, 0] = -1.25 * g00 + 0.25 * g10 - 0.5 * gt0
    grad[0, 1] = -1.25 * g01 + 0.25 * g11 - 0.5 * gt1
    grad[0, 2] = -1.25 * g02 + 0.25 * g12 - 0.5 * gt2
    grad[1, 0] = 1.5 * (g00 - g10)
    grad[1, 1] = 1.5 * (g01 - g11)
    grad[1, 2] = 1.5 * (g02 - g12)
    grad[2, 0] = -0.25 * g00 + 1.25 * g10 + 0.5 * gt0
    grad[2, 1] = -0.25 * g01 + 1.25 * g11 + 0.5 * gt1
    grad[2, 2] = -0.25 * g02 + 1.25 * g12 + 0.5 * gt2
    return theta


@njit(cache=True, parallel=True)
def fiber_measures(x, fibers, normals, soft, weights, out_len, out_theta):
    """l~ and theta of all fibers, N and soft per fiber (rest-state measures; same arithmetic as the forces)."""
    g = np.empty((3, 3))
    gn = np.empty(3)
    for k in prange(fibers.shape[0]):
        out_len[k] = fiber_length(x, fibers[k, 0], fibers[k, 1], fibers[k, 2], weights, g, False)
        out_theta[k] = fiber_angle(x, fibers[k, 0], fibers[k, 1], fibers[k, 2], normals[k, 0], normals[k, 1],
                                   normals[k, 2], soft[k], g, gn, False)


@njit(cache=True)
def fiber_length_batch(x, fibers, weights, out_len, out_grad):
    """Arc lengths (F,) and gradients (F, 3, 3) of all fibers (reference check helper)."""
    g = np.empty((3, 3))
    for k in range(fibers.shape[0]):
        out_len[k] = fiber_length(x, fibers[k, 0], fibers[k, 1], fibers[k, 2], weights, g, True)
        out_grad[k] = g


@njit(cache=True)
def fiber_angle_batch(x, fibers, normals, soft, out_theta, out_grad, out_gnormal):
    """Angles (F,), gradients (F, 3, 3) and normal gradients (F, 3) of all fibers, N and soft per fiber."""
    g = np.empty((3, 3))
    gn = np.empty(3)
    for k in range(fibers.shape[0]):
        out_theta[k] = fiber_angle(x, fibers[k, 0], fibers[k, 1], fibers[k, 2], normals[k, 0], normals[k, 1],
                                   normals[k, 2], soft[k], g, gn, True)
        out_grad[k] = g
        out_gnormal[k] = gn


@njit(cache=True, inline="always")
def umbrella_at(i, x, pairs, q0, q1, out_s, out_normal):
    """Umbrella vector ``s_i = sum (x_a - x_i) x (x_b - x_i)`` over ``pairs[q0:q1]`` and its unit
    normal (zero without pairs) into row ``i`` of ``out_s`` / ``out_normal`` (7.10)."""
    xi0 = x[i, 0]
    xi1 = x[i, 1]
    xi2 = x[i, 2]
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for q in range(q0, q1):
        a = pairs[q, 0]
        b = pairs[q, 1]
        c0, c1, c2 = _cross(x[a, 0] - xi0, x[a, 1] - xi1, x[a, 2] - xi2, x[b, 0] - xi0, x[b, 1] - xi1, x[b, 2] - xi2)
        s0 += c0
        s1 += c1
        s2 += c2
    out_s[i, 0] = s0
    out_s[i, 1] = s1
    out_s[i, 2] = s2
    sn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if sn > 0.0:
        out_normal[i, 0] = s0 / sn
        out_normal[i, 1] = s1 / sn
        out_normal[i, 2] = s2 / sn
    else:
        out_normal[i, 0] = 0.0
        out_normal[i, 1] = 0.0
        out_normal[i, 2] = 0.0


@njit(cache=True, parallel=True)
def umbrella(x, pairs, pair_offsets, out_s, out_normal):
    """Umbrella vectors s_i = sum (x_a - x_i) x (x_b - x_i) and unit normals (zero if no pairs)."""
    for i in prange(x.shape[0]):
        umbrella_at(i, x, pairs, pair_offsets[i], pair_offsets[i + 1], out_s, out_normal)


@njit(cache=True, fastmath=FASTMATH)
def node_forces(i, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast, sscale,
                bscale, ks, kb, weights, ref, offs, buf, scr, out_len, out_ang, out_s, out_normal, out_node):
    """Energy and force contributions of node ``i``'s umbrella and fibers (7.5-7.17).

    One pass per centre node: the umbrella vector ``s_i`` (normal of the tangent angles),
    every fiber's ``l~`` and ``theta`` with gradients (kept in ``scr`` (cap, 7, 3)), the node
    sums, then ``dE/dx`` of every node touched by the fibers and the umbrella scattered into
    ``buf`` (N, 3) (``buf -= dE/dx``). Energies (per node ``i``, ``m`` fibers ``k``)::

        E_s = K_s/2 [ mean(sigma) da^2 + (1/m) sum_k sigma_k (A_k - A_k^0)^2 ]      (7.7)
        E_b = K_b/2 A_i^0 mean(beta) dh^2                                          (7.11)
        da  = A_i - A_i^0 - offs[i, 0],   dh = H_i - H_i^0 - offs[i, 1]
        H_i = sum_k beta_k theta_k / sum_k beta_k                                  (7.9)

    (the printed forms; see :mod:`unmesh.shells.energy`). Each ``theta`` is taken on the
    branch nearest ``ref[k]``.

    Returns
    -------
    (es, eb, folds)
        Membrane and bending energy of the node, and the number of its fibers whose angle
        moved by more than pi/2 from ``ref``.
    """
    xi0 = x[i, 0]
    xi1 = x[i, 1]
    xi2 = x[i, 2]
    p0 = pstart[i]
    umbrella_at(i, x, pairs, p0, p0 + pcount[i], out_s, out_normal)
    s0 = out_s[i, 0]
    s1 = out_s[i, 1]
    s2 = out_s[i, 2]
    m = fcount[i]
    if m == 0:
        out_node[i, 0] = 0.0
        out_node[i, 1] = 0.0
        out_node[i, 2] = 0.0
        out_node[i, 3] = 0.0
        return 0.0, 0.0, 0
    f0 = fstart[i]
    sf = soft[i]
    q4 = math.pi / 4.0
    two_pi = 2.0 * math.pi
    area = 0.0
    area0 = 0.0
    sig = 0.0
    bsum = 0.0
    h = 0.0
    h0 = 0.0
    folds = 0
    for q in range(m):
        k = f0 + q
        j1 = fibers[k, 0]
        j2 = fibers[k, 2]
        g = scr[q]
        ln = fiber_length(x, j1, i, j2, weights, g[0:3], True)
        th = fiber_angle(x, j1, i, j2, s0, s1, s2, sf, g[3:6], g[6], True)
        r = ref[k]
        th += two_pi * math.floor((r - th) / two_pi + 0.5)
        if abs(th - r) > 0.5 * math.pi:
            folds += 1
        out_len[k] = ln
        out_ang[k] = th
        l0 = lorig[k] + lplast[k]
        area += q4 * ln * ln
        area0 += q4 * l0 * l0
        sig += sscale[k]
        bk = bscale[k]
        bsum += bk
        h += bk * th
        h0 += bk * (aorig[k] + aplast[k])
    inv_m = 1.0 / m
    area *= inv_m
    area0 *= inv_m
    sig *= inv_m
    if bsum > 0.0:
        h /= bsum
        h0 /= bsum
    out_node[i, 0] = area
    out_node[i, 1] = area0
    out_node[i, 2] = h
    out_node[i, 3] = h0
    da = area - area0 - offs[i, 0]
    dh = h - h0 - offs[i, 1]
    esum = 0.0
    gs0 = 0.0
    gs1 = 0.0
    gs2 = 0.0
    half_pi = 0.5 * math.pi
    for q in range(m):
        k = f0 + q
        g = scr[q]
        ln = out_len[k]
        l0 = lorig[k] + lplast[k]
        ak0 = q4 * l0 * l0
        dak = q4 * ln * ln - ak0
        esum += sscale[k] * dak * dak
        de_dl = ks * inv_m * (sig * da + sscale[k] * dak) * half_pi * ln
        de_dth = kb * area0 * dh * bscale[k] * inv_m
        j1 = fibers[k, 0]
        j2 = fibers[k, 2]
        for c in range(3):
            buf[j1, c] -= de_dl * g[0, c] + de_dth * g[3, c]
            buf[i, c] -= de_dl * g[1, c] + de_dth * g[4, c]
            buf[j2, c] -= de_dl * g[2, c] + de_dth * g[5, c]
        gs0 += de_dth * g[6, 0]
        gs1 += de_dth * g[6, 1]
        gs2 += de_dth * g[6, 2]
    es = 0.5 * ks * (sig * da * da + esum * inv_m)
    eb = 0.5 * kb * area0 * bsum * inv_m * dh * dh
    if gs0 != 0.0 or gs1 != 0.0 or gs2 != 0.0:
        # through the umbrella vector s_i = sum e_a x e_b: dE/dx_a = e_b x g, dE/dx_b = g x e_a
        for q in range(p0, p0 + pcount[i]):
            a = pairs[q, 0]
            b = pairs[q, 1]
            ga0, ga1, ga2 = _cross(x[b, 0] - xi0, x[b, 1] - xi1, x[b, 2] - xi2, gs0, gs1, gs2)
            gb0, gb1, gb2 = _cross(gs0, gs1, gs2, x[a, 0] - xi0, x[a, 1] - xi1, x[a, 2] - xi2)
            buf[a, 0] -= ga0
            buf[a, 1] -= ga1
            buf[a, 2] -= ga2
            buf[b, 0] -= gb0
            buf[b, 1] -= gb1
            buf[b, 2] -= gb2
            buf[i, 0] += ga0 + gb0
            buf[i, 1] += ga1 + gb1
            buf[i, 2] += ga2 + gb2
    return es, eb, folds


@njit(cache=True, parallel=True)
def force_chunks(chunks, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast,
                 sscale, bscale, ks, kb, weights, ref, offs, cap, buf, out_force, out_len, out_ang, out_s,
                 out_normal, out_node, out_es, out_eb):
    """Elastic forces of all nodes (7.16): ``chunks`` contiguous node ranges in parallel.

    Every chunk scatters into its own buffer ``buf[c]`` (chunks, N, 3) -- no write races --
    and the buffers are summed into ``out_force`` (N, 3). ``cap`` is the largest fiber count
    of a node (scratch size).
    """
    n = x.shape[0]
    for c in prange(chunks):
        lo = c * n // chunks
        hi = (c + 1) * n // chunks
        b = buf[c]
        b[:, :] = 0.0
        scr = np.empty((max(cap, 1), 7, 3))
        for i in range(lo, hi):
            es, eb, _ = node_forces(i, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast,
                                    aorig, aplast, sscale, bscale, ks, kb, weights, ref, offs, b, scr, out_len,
                                    out_ang, out_s, out_normal, out_node)
            out_es[i] = es
            out_eb[i] = eb
    for i in prange(n):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for c in range(chunks):
            f0 += buf[c, i, 0]
            f1 += buf[c, i, 1]
            f2 += buf[c, i, 2]
        out_force[i, 0] = f0
        out_force[i, 1] = f1
        out_force[i, 2] = f2


@njit(cache=True, parallel=True)
def segments_blocked(p, q, centers, normals, radii, out):
    """out[m] = True when segment p[m]-q[m] crosses one of the crack discs (7.3.2).

    A disc (c, n, r) separates the closed half-space n.(x - c) >= 0 from the open one
    n.(x - c) < 0; a segment with ends on different sides is blocked when it meets the
    disc's plane within distance r of c. A node on the plane belongs to the + side.
    """
    m = p.shape[0]
    nc = centers.shape[0]
    for k in prange(m):
        hit = False
        mx = 0.5 * (p[k, 0] + q[k, 0])
        my = 0.5 * (p[k, 1] + q[k, 1])
        mz = 0.5 * (p[k, 2] + q[k, 2])
        half = 0.5 * math.sqrt((q[k, 0] - p[k, 0]) ** 2 + (q[k, 1] - p[k, 1]) ** 2 + (q[k, 2] - p[k, 2]) ** 2)
        for c in range(nc):
            dx = mx - centers[c, 0]
            dy = my - centers[c, 1]
            dz = mz - centers[c, 2]
            reach = half + radii[c]
            if dx * dx + dy * dy + dz * dz > reach * reach:
                continue
            dp = (normals[c, 0] * (p[k, 0] - centers[c, 0]) + normals[c, 1] * (p[k, 1] - centers[c, 1])
                  + normals[c, 2] * (p[k, 2] - centers[c, 2]))
            dq = (normals[c, 0] * (q[k, 0] - centers[c, 0]) + normals[c, 1] * (q[k, 1] - centers[c, 1])
                  + normals[c, 2] * (q[k, 2] - centers[c, 2]))
            if (dp >= 0.0) == (dq >= 0.0):
                continue
            t = dp / (dp - dq)
            ix = p[k, 0] + t * (q[k, 0] - p[k, 0]) - centers[c, 0]
            iy = p[k, 1] + t * (q[k, 1] - p[k, 1]) - centers[c, 1]
            iz = p[k, 2] + t * (q[k, 2] - p[k, 2]) - centers[c, 2]
            if ix * ix + iy * iy + iz * iz <= radii[c] * radii[c]:
                hit = True
                break
        out[k] = hit


@njit(cache=True, parallel=True)
def fracture_scan(x, fibers, lengths, angles, rest_length, rest_angle, gamma_s, gamma_b, degenerate):
    """Cheap per-step test: (fibers over a fracture threshold (7.24), degenerate fibers).

    degenerate is the squared ratio below which an end tangent counts as vanished relative to
    the centre tangent (0 disables that test). Parallel over fibers (integer reductions).
    """
    over = 0
    bad = 0
    for k in prange(fibers.shape[0]):
        if lengths[k] > rest_length[k] * (1.0 + gamma_s[k]) or abs(angles[k] - rest_angle[k]) > gamma_b[k]:
            over += 1
        if degenerate > 0.0:
            a = fibers[k, 0]
            i = fibers[k, 1]
            b = fibers[k, 2]
            s0 = 0.0
            s1 = 0.0
            sc = 0.0
            for c in range(3):
                t0 = -1.25 * x[a, c] + 1.5 * x[i, c] - 0.25 * x[b, c]
                t1 = 0.25 * x[a, c] - 1.5 * x[i, c] + 1.25 * x[b, c]
                tc = 0.5 * (x[b, c] - x[a, c])
                s0 += t0 * t0
                s1 += t1 * t1
                sc += tc * tc
            if min(s0, s1) < degenerate * sc:
                bad += 1
    return over, bad


@njit(cache=True)
def group_order(groups, count, out_offsets, out_order):
    """Stable counting sort of entries by key: CSR offsets (count + 1,) and entry order (M,).

    Same result as ``np.argsort(groups, kind="stable")`` with ``bincount`` offsets, in O(M).
    """
    out_offsets[:] = 0
    for e in range(groups.shape[0]):
        out_offsets[groups[e] + 1] += 1
    for g in range(count):
        out_offsets[g + 1] += out_offsets[g]
    fill = out_offsets[:-1].copy()
    for e in range(groups.shape[0]):
        g = groups[e]
        out_order[fill[g]] = e
        fill[g] += 1


@njit(cache=True)
def node_terms_rows(rows, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast,
                    sscale, bscale, weights, ref, cap, out_node):
    """``A_i, A_i^0, H_i, H_i^0`` (7.6, 7.9) of the listed nodes only, into ``out_node[r]`` (R, 4).

    Runs :func:`node_forces` (same arithmetic as :func:`force_chunks`) on each listed node
    with scratch outputs; the forces are discarded.
    """
    n = x.shape[0]
    nf = fibers.shape[0]
    buf = np.zeros((n, 3))
    scr = np.empty((max(cap, 1), 7, 3))
    ln = np.empty(nf)
    ang = np.empty(nf)
    s = np.empty((n, 3))
    nrm = np.empty((n, 3))
    node = np.zeros((n, 4))
    offs = np.zeros((n, 2))
    for r in range(rows.shape[0]):
        i = rows[r]
        node_forces(i, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast, sscale,
                    bscale, 1.0, 1.0, weights, ref, offs, buf, scr, ln, ang, s, nrm, node)
        for c in range(4):
            out_node[r, c] = node[i, c]
