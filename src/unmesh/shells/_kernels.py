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


@njit(cache=True, parallel=True)
def umbrella(x, pairs, pair_offsets, out_s, out_normal):
    """Umbrella vectors s_i = sum (x_a - x_i) x (x_b - x_i) and unit normals (zero if no pairs)."""
    n = x.shape[0]
    for i in prange(n):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for q in range(pair_offsets[i], pair_offsets[i + 1]):
            a = pairs[q, 0]
            b = pairs[q, 1]
            c0, c1, c2 = _cross(x[a, 0] - x[i, 0], x[a, 1] - x[i, 1], x[a, 2] - x[i, 2],
                                x[b, 0] - x[i, 0], x[b, 1] - x[i, 1], x[b, 2] - x[i, 2])
            s0 += c0
            s1 += c1
            s2 += c2
        out_s[i, 0] = s0
        out_s[i, 1] = s1
        out_s[i, 2] = s2
        nn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        if nn > 0.0:
            out_normal[i, 0] = s0 / nn
            out_normal[i, 1] = s1 / nn
            out_normal[i, 2] = s2 / nn
        else:
            out_normal[i, 0] = 0.0
            out_normal[i, 1] = 0.0
            out_normal[i, 2] = 0.0


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def fiber_pass(x, s, soft, fibers, fiber_offsets, rest_length, rest_angle, stretch_scale, bend_scale,
               ks, kb, weights, reference, node_offsets, out_length, out_angle, out_fgrad, out_gs, out_es, out_eb,
               out_node, work_tgrad, work_ngrad):
    """First pass (7.16): per centre node, fiber measures, node sums and per-fiber energy gradients.

    The angle of a fiber centred at i uses the raw umbrella vector s_i as its normal with
    regularisation soft[i]. out_fgrad (F, 3, 3) receives dE/d(x1, x, x2) of every fiber's share
    of its centre's energy, out_gs (N, 3) the gradient dE/ds_i, out_es / out_eb
    (N,) the membrane and bending energy of each node. Each angle is taken on the branch
    (theta + 2 pi k) nearest to ``reference`` (the previous step's angle), so a fiber that
    folds past 180 degrees keeps a continuous angle instead of jumping by 2 pi.
    node_offsets (N, 2) shift the node terms: (A_i - A_i^0 - dA_i) and (H_i - H_i^0 - dH_i);
    out_node (N, 4) receives A_i, A_i^0, H_i, H_i^0 (without offsets). work_tgrad (F, 3, 3) and
    work_ngrad (F, 3) hold dtheta/dx and dtheta/ds between the two loops.
    """
    n = x.shape[0]
    q4 = math.pi / 4.0
    two_pi = 2.0 * math.pi
    for i in prange(n):
        lo = fiber_offsets[i]
        hi = fiber_offsets[i + 1]
        out_gs[i, 0] = 0.0
        out_gs[i, 1] = 0.0
        out_gs[i, 2] = 0.0
        out_es[i] = 0.0
        out_eb[i] = 0.0
        m = hi - lo
        if m == 0:
            continue
        area = 0.0
        area0 = 0.0
        sig = 0.0
        bsum = 0.0
        h = 0.0
        h0 = 0.0
        n0 = s[i, 0]
        n1 = s[i, 1]
        n2 = s[i, 2]
        sf = soft[i]
        for k in range(lo, hi):
            j1 = fibers[k, 0]
            j2 = fibers[k, 2]
            ln = fiber_length(x, j1, i, j2, weights, out_fgrad[k], True)
            th = fiber_angle(x, j1, i, j2, n0, n1, n2, sf, work_tgrad[k], work_ngrad[k], True)
            th += two_pi * math.floor((reference[k] - th) / two_pi + 0.5)
            out_length[k] = ln
            out_angle[k] = th
            area += q4 * ln * ln
            area0 += q4 * rest_length[k] * rest_length[k]
            sig += stretch_scale[k]
            bsum += bend_scale[k]
            h += bend_scale[k] * th
            h0 += bend_scale[k] * rest_angle[k]
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
        da = area - area0 - node_offsets[i, 0]
        dh = h - h0 - node_offsets[i, 1]
        es = 0.0
        g0 = 0.0
        g1 = 0.0
        g2 = 0.0
        for k in range(lo, hi):
            ln = out_length[k]
            ak = q4 * ln * ln
            ak0 = q4 * rest_length[k] * rest_length[k]
            es += stretch_scale[k] * (ak - ak0) ** 2
            de_dl = ks * inv_m * (sig * da + stretch_scale[k] * (ak - ak0)) * (math.pi / 2.0) * ln
            de_dth = kb * area0 * bend_scale[k] * inv_m * dh
            for r in range(3):
                for c in range(3):
                    out_fgrad[k, r, c] = de_dl * out_fgrad[k, r, c] + de_dth * work_tgrad[k, r, c]
            g0 += de_dth * work_ngrad[k, 0]
            g1 += de_dth * work_ngrad[k, 1]
            g2 += de_dth * work_ngrad[k, 2]
        out_es[i] = 0.5 * ks * (sig * da * da + es * inv_m)
        out_eb[i] = 0.5 * kb * area0 * bsum * inv_m * dh * dh
        out_gs[i, 0] = g0
        out_gs[i, 1] = g1
        out_gs[i, 2] = g2


@njit(cache=True, parallel=True)
def gather_forces(x, fgrad, fiber_inc_offsets, fiber_inc, gs, pairs, pair_offsets, pair_center,
                  pair_inc_offsets, pair_inc, out_force):
    """Second pass: F_p = -(sum of fiber gradient entries of p) - (umbrella-normal terms of p)."""
    n = x.shape[0]
    for p in prange(n):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for e in range(fiber_inc_offsets[p], fiber_inc_offsets[p + 1]):
            code = fiber_inc[e]
            k = code // 3
            r = code - 3 * k
            f0 -= fgrad[k, r, 0]
            f1 -= fgrad[k, r, 1]
            f2 -= fgrad[k, r, 2]
        # p as the centre of its own umbrella: dE/dx_p = -sum (e_b x g + g x e_a)
        g0 = gs[p, 0]
        g1 = gs[p, 1]
        g2 = gs[p, 2]
        if g0 != 0.0 or g1 != 0.0 or g2 != 0.0:
            for q in range(pair_offsets[p], pair_offsets[p + 1]):
                a = pairs[q, 0]
                b = pairs[q, 1]
                ba0, ba1, ba2 = _cross(x[b, 0] - x[p, 0], x[b, 1] - x[p, 1], x[b, 2] - x[p, 2], g0, g1, g2)
                ab0, ab1, ab2 = _cross(g0, g1, g2, x[a, 0] - x[p, 0], x[a, 1] - x[p, 1], x[a, 2] - x[p, 2])
                f0 += ba0 + ab0
                f1 += ba1 + ab1
                f2 += ba2 + ab2
        # p as a member (a or b) of other umbrellas
        for e in range(pair_inc_offsets[p], pair_inc_offsets[p + 1]):
            code = pair_inc[e]
            q = code // 2
            role = code - 2 * q
            i = pair_center[q]
            h0 = gs[i, 0]
            h1 = gs[i, 1]
            h2 = gs[i, 2]
            if role == 0:  # p = a: dE/dx_a = e_b x g
                b = pairs[q, 1]
                d0, d1, d2 = _cross(x[b, 0] - x[i, 0], x[b, 1] - x[i, 1], x[b, 2] - x[i, 2], h0, h1, h2)
            else:  # p = b: dE/dx_b = g x e_a
                a = pairs[q, 0]
                d0, d1, d2 = _cross(h0, h1, h2, x[a, 0] - x[i, 0], x[a, 1] - x[i, 1], x[a, 2] - x[i, 2])
            f0 -= d0
            f1 -= d1
            f2 -= d2
        out_force[p, 0] = f0
        out_force[p, 1] = f1
        out_force[p, 2] = f2


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


@njit(cache=True)
def fracture_scan(x, fibers, lengths, angles, rest_length, rest_angle, gamma_s, gamma_b, degenerate):
    """Cheap per-step test: (fibers over a fracture threshold (7.24), degenerate fibers).

    degenerate is the squared ratio below which an end tangent counts as vanished relative to
    the centre tangent (0 disables that test).
    """
    over = 0
    bad = 0
    for k in range(fibers.shape[0]):
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
