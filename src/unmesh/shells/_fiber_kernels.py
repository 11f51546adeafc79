"""Numba kernels for the fiber geometry: arc length and tangent angle with gradients (thesis 7.2.1, App. B).

Numpy reference: :mod:`unmesh.shells.fibers` (``arc_length_gradient``,
``bending_angle_gradient``); ``tests/shells/test_energy.py`` compares the two.

Both measures are written in the two edge vectors of the fiber ``(x1, x, x2)``,
``d1 = x1 - x`` and ``d2 = x2 - x``: every spline derivative is a weighted sum of the three
nodes with weights that sum to zero (B.3), so ``f'(s) = alpha(s) d1 + gamma(s) d2``.

* Arc length (B.4): the speed at sample ``r`` is ``|f'(s_r)| = sqrt(alpha_r^2 D11 +
  2 alpha_r gamma_r D12 + gamma_r^2 D22)`` with the Gram entries ``Dab = da . db``, so a
  sample costs three multiply-adds and a square root instead of a 3-vector, and the
  gradient (B.5, B.6) is ``dl/dd1 = S11 d1 + S12 d2``, ``dl/dd2 = S12 d1 + S22 d2`` with
  ``Sab = (1/n) sum_r alpha_a alpha_b / |f'(s_r)|``; ``dl/dx = -(dl/dd1 + dl/dd2)``.
* Tangent angle (7.10): ``t0 = -5/4 d1 - 1/4 d2``, ``t1 = 1/4 d1 + 5/4 d2``,
  ``tc = (d2 - d1)/2``; the angle and its gradient are those of
  :func:`unmesh.shells.fibers.bending_angle_gradient`; ``dtheta/dx = -(dtheta/dx1 +
  dtheta/dx2)`` (translation invariance).

:func:`fiber_measures` (rest state) and the force kernels use the same functions, so the
rest state has zero energy and force up to round-off.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh._linalg_kernels import FASTMATH, atan2

#: Regularisation of the tangent angle's cosine part (unmesh.shells.fibers.TANGENT_SOFTENING).
SOFT_X = 0.05



def sample_weights(samples: int) -> np.ndarray:
    """Weights (2n, 3) of f1'(s_i) then f2'(s_i) on (x1, x, x2) at s_i = (i + 1/2)/n (B.4, B.6)."""
    s = (np.arange(samples) + 0.5) / samples
    w1 = np.stack([-1.25 + 0.75 * s**2, 1.5 - 1.5 * s**2, -0.25 + 0.75 * s**2], axis=1)
    w2 = np.stack([-0.5 + 1.5 * s - 0.75 * s**2, -3.0 * s + 1.5 * s**2, 0.5 + 1.5 * s - 0.75 * s**2], axis=1)
    return np.ascontiguousarray(np.concatenate([w1, w2]))


def gram_weights(weights: np.ndarray) -> np.ndarray:
    """Table (2n, 6) of the Gram form of the speed samples: ``alpha^2, 2 alpha gamma, gamma^2`` and
    ``alpha^2/n, alpha gamma/n, gamma^2/n`` per sample, from :func:`sample_weights` (columns x1, x2)."""
    w = np.asarray(weights, dtype=np.float64)
    a, g = w[:, 0], w[:, 2]
    inv_n = 2.0 / len(w)
    return np.ascontiguousarray(np.stack([a * a, 2.0 * a * g, g * g, a * a * inv_n, a * g * inv_n, g * g * inv_n],
                                         axis=1))


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, fastmath=FASTMATH, inline="always")
def arc(d10, d11, d12, d20, d21, d22, gram):
    """Arc length l~ (B.4) of the fiber with edge vectors d1, d2 and its gradient coefficients.

    Returns ``(l, S11, S12, S22)``: ``dl/dx1 = S11 d1 + S12 d2``, ``dl/dx2 = S12 d1 + S22 d2``.
    """
    q11 = d10 * d10 + d11 * d11 + d12 * d12
    q12 = d10 * d20 + d11 * d21 + d12 * d22
    q22 = d20 * d20 + d21 * d21 + d22 * d22
    total = 0.0
    s11 = 0.0
    s12 = 0.0
    s22 = 0.0
    for r in range(gram.shape[0]):
        q = gram[r, 0] * q11 + gram[r, 1] * q12 + gram[r, 2] * q22
        if q > 0.0:
            sp = math.sqrt(q)
            inv = 1.0 / sp
            total += sp
            s11 += gram[r, 3] * inv
            s12 += gram[r, 4] * inv
            s22 += gram[r, 5] * inv
    return total * (2.0 / gram.shape[0]), s11, s12, s22


@njit(cache=True, fastmath=FASTMATH, inline="always")
def angle(d10, d11, d12, d20, d21, d22, n0, n1, n2, soft, with_grad):
    """Tangent angle theta = atan2(a.(t0 x t1), t0.t1 - (t0.a)(t1.a) + SOFT_X |tc|^2), a = u / sqrt(|u|^2 + soft^2 |tc|^2), u = N x tc.

    Returns ``(theta, gA0, gA1, gA2, gC0, gC1, gC2, gN0, gN1, gN2)``: dtheta/dx1, dtheta/dx2 and
    dtheta/dN (zeros unless ``with_grad``); see :func:`unmesh.shells.fibers.bending_angle_gradient`.
    """
    t00 = -1.25 * d10 - 0.25 * d20
    t01 = -1.25 * d11 - 0.25 * d21
    t02 = -1.25 * d12 - 0.25 * d22
    t10 = 0.25 * d10 + 1.25 * d20
    t11 = 0.25 * d11 + 1.25 * d21
    t12 = 0.25 * d12 + 1.25 * d22
    tc0 = 0.5 * (d20 - d10)
    tc1 = 0.5 * (d21 - d11)
    tc2 = 0.5 * (d22 - d12)
    u0, u1, u2 = _cross(n0, n1, n2, tc0, tc1, tc2)
    tt = tc0 * tc0 + tc1 * tc1 + tc2 * tc2
    ss = soft * soft
    rho = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2 + ss * tt)
    ir = 1.0 / rho if rho > 0.0 else 0.0
    a0 = u0 * ir
    a1 = u1 * ir
    a2 = u2 * ir
    c0, c1, c2 = _cross(t00, t01, t02, t10, t11, t12)
    ta0 = t00 * a0 + t01 * a1 + t02 * a2
    ta1 = t10 * a0 + t11 * a1 + t12 * a2
    X = t00 * t10 + t01 * t11 + t02 * t12 - ta0 * ta1 + SOFT_X * tt
    Y = a0 * c0 + a1 * c1 + a2 * c2
    theta = atan2(Y, X)
    D = X * X + Y * Y
    if not with_grad or not D > 0.0:
        return theta, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    iD = 1.0 / D
    gx = -Y * iD
    gy = X * iD
    # dtheta/dt0 = gy (t1 x a) + gx (t1 - (t1.a) a), dtheta/dt1 = gy (a x t0) + gx (t0 - (t0.a) a)
    p0, p1, p2 = _cross(t10, t11, t12, a0, a1, a2)
    q0, q1, q2 = _cross(a0, a1, a2, t00, t01, t02)
    g00 = gy * p0 + gx * (t10 - ta1 * a0)
    g01 = gy * p1 + gx * (t11 - ta1 * a1)
    g02 = gy * p2 + gx * (t12 - ta1 * a2)
    g10 = gy * q0 + gx * (t00 - ta0 * a0)
    g11 = gy * q1 + gx * (t01 - ta0 * a1)
    g12 = gy * q2 + gx * (t02 - ta0 * a2)
    # through a = u/rho, u = N x tc: dtheta/da = gy (t0 x t1) - gx ((t1.a) t0 + (t0.a) t1)
    ga0 = gy * c0 - gx * (ta1 * t00 + ta0 * t10)
    ga1 = gy * c1 - gx * (ta1 * t01 + ta0 * t11)
    ga2 = gy * c2 - gx * (ta1 * t02 + ta0 * t12)
    ug = (u0 * ga0 + u1 * ga1 + u2 * ga2) * (ir * ir * ir)
    gu0 = ga0 * ir - u0 * ug
    gu1 = ga1 * ir - u1 * ug
    gu2 = ga2 * ir - u2 * ug
    gn0, gn1, gn2 = _cross(tc0, tc1, tc2, gu0, gu1, gu2)
    gt0, gt1, gt2 = _cross(gu0, gu1, gu2, n0, n1, n2)
    sx = ss * ug - 2.0 * SOFT_X * gx
    gt0 -= sx * tc0
    gt1 -= sx * tc1
    gt2 -= sx * tc2
    return (theta,
            -1.25 * g00 + 0.25 * g10 - 0.5 * gt0, -1.25 * g01 + 0.25 * g11 - 0.5 * gt1,
            -1.25 * g02 + 0.25 * g12 - 0.5 * gt2,
            -0.25 * g00 + 1.25 * g10 + 0.5 * gt0, -0.25 * g01 + 1.25 * g11 + 0.5 * gt1,
            -0.25 * g02 + 1.25 * g12 + 0.5 * gt2,
            gn0, gn1, gn2)


@njit(cache=True, inline="always")
def _tangents(d10, d11, d12, d20, d21, d22):
    """End and centre tangents ``t0 = -5/4 d1 - 1/4 d2``, ``t1 = 1/4 d1 + 5/4 d2``, ``tc = (d2 - d1)/2`` (B.3)."""
    return (-1.25 * d10 - 0.25 * d20, -1.25 * d11 - 0.25 * d21, -1.25 * d12 - 0.25 * d22,
            0.25 * d10 + 1.25 * d20, 0.25 * d11 + 1.25 * d21, 0.25 * d12 + 1.25 * d22,
            0.5 * (d20 - d10), 0.5 * (d21 - d11), 0.5 * (d22 - d12))


@njit(cache=True, inline="always")
def degenerate_edges(d10, d11, d12, d20, d21, d22, n0, n1, n2, soft, ratio2):
    """True when the fiber with edge vectors ``d1 = x1 - x``, ``d2 = x2 - x`` is degenerate: an end
    tangent projected onto the fiber's normal plane (as :func:`angle` sees it) is shorter than
    ``sqrt(ratio2) |tc|``, with the centre's umbrella vector ``N`` and regularisation ``soft``
    (:func:`unmesh.shells.fibers.degenerate`). The projection keeps ``t.tc``, so end tangents
    with ``(t.tc)^2 >= ratio2 |tc|^4`` pass at once (nearly every fiber); only the others are
    projected."""
    t00, t01, t02, t10, t11, t12, tc0, tc1, tc2 = _tangents(d10, d11, d12, d20, d21, d22)
    tt = tc0 * tc0 + tc1 * tc1 + tc2 * tc2
    c0 = t00 * tc0 + t01 * tc1 + t02 * tc2
    c1 = t10 * tc0 + t11 * tc1 + t12 * tc2
    lim = ratio2 * tt * tt
    if c0 * c0 >= lim and c1 * c1 >= lim:
        return False
    u0, u1, u2 = _cross(n0, n1, n2, tc0, tc1, tc2)
    rho = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2 + soft * soft * tt)
    ir = 1.0 / rho if rho > 0.0 else 1.0
    a0 = u0 * ir
    a1 = u1 * ir
    a2 = u2 * ir
    w = 2.0 - (a0 * a0 + a1 * a1 + a2 * a2)
    ta0 = t00 * a0 + t01 * a1 + t02 * a2
    ta1 = t10 * a0 + t11 * a1 + t12 * a2
    q0 = t00 * t00 + t01 * t01 + t02 * t02 - ta0 * ta0 * w
    q1 = t10 * t10 + t11 * t11 + t12 * t12 - ta1 * ta1 * w
    return min(q0, q1) < ratio2 * tt


@njit(cache=True, inline="always")
def degenerate(x, j1, i, j2, n0, n1, n2, soft, ratio2):
    """:func:`degenerate_edges` of fiber ``(j1, i, j2)`` at positions ``x``."""
    return degenerate_edges(x[j1, 0] - x[i, 0], x[j1, 1] - x[i, 1], x[j1, 2] - x[i, 2], x[j2, 0] - x[i, 0],
                            x[j2, 1] - x[i, 1], x[j2, 2] - x[i, 2], n0, n1, n2, soft, ratio2)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def fiber_measure(x, j1, i, j2, n0, n1, n2, soft, gram):
    """``(l~, theta)`` of fiber (j1, i, j2) with normal N and regularisation ``soft`` (no gradients)."""
    d10 = x[j1, 0] - x[i, 0]
    d11 = x[j1, 1] - x[i, 1]
    d12 = x[j1, 2] - x[i, 2]
    d20 = x[j2, 0] - x[i, 0]
    d21 = x[j2, 1] - x[i, 1]
    d22 = x[j2, 2] - x[i, 2]
    ln = arc(d10, d11, d12, d20, d21, d22, gram)[0]
    th = angle(d10, d11, d12, d20, d21, d22, n0, n1, n2, soft, False)[0]
    return ln, th


@njit(cache=True, parallel=True)
def fiber_measures(x, fibers, normals, soft, gram, out_len, out_theta):
    """l~ and theta of all fibers, N and soft per fiber (rest-state measures; same arithmetic as the forces)."""
    for k in prange(fibers.shape[0]):
        out_len[k], out_theta[k] = fiber_measure(x, fibers[k, 0], fibers[k, 1], fibers[k, 2], normals[k, 0],
                                                 normals[k, 1], normals[k, 2], soft[k], gram)


@njit(cache=True)
def fiber_length_batch(x, fibers, weights, out_len, out_grad):
    """Arc lengths (F,) and gradients (F, 3, 3) of all fibers (reference check helper; weights of
    :func:`sample_weights`)."""
    n2 = weights.shape[0]
    gram = np.empty((n2, 6))
    for r in range(n2):
        a = weights[r, 0]
        g = weights[r, 2]
        gram[r, 0] = a * a
        gram[r, 1] = 2.0 * a * g
        gram[r, 2] = g * g
        gram[r, 3] = a * a * (2.0 / n2)
        gram[r, 4] = a * g * (2.0 / n2)
        gram[r, 5] = g * g * (2.0 / n2)
    for k in range(fibers.shape[0]):
        j1, i, j2 = fibers[k, 0], fibers[k, 1], fibers[k, 2]
        d1 = x[j1] - x[i]
        d2 = x[j2] - x[i]
        ln, s11, s12, s22 = arc(d1[0], d1[1], d1[2], d2[0], d2[1], d2[2], gram)
        out_len[k] = ln
        for c in range(3):
            ga = s11 * d1[c] + s12 * d2[c]
            gc = s12 * d1[c] + s22 * d2[c]
            out_grad[k, 0, c] = ga
            out_grad[k, 1, c] = -(ga + gc)
            out_grad[k, 2, c] = gc


@njit(cache=True)
def fiber_angle_batch(x, fibers, normals, soft, out_theta, out_grad, out_gnormal):
    """Angles (F,), gradients (F, 3, 3) and normal gradients (F, 3) of all fibers, N and soft per fiber."""
    for k in range(fibers.shape[0]):
        j1, i, j2 = fibers[k, 0], fibers[k, 1], fibers[k, 2]
        d1 = x[j1] - x[i]
        d2 = x[j2] - x[i]
        r = angle(d1[0], d1[1], d1[2], d2[0], d2[1], d2[2], normals[k, 0], normals[k, 1], normals[k, 2], soft[k],
                  True)
        out_theta[k] = r[0]
        for c in range(3):
            out_grad[k, 0, c] = r[1 + c]
            out_grad[k, 2, c] = r[4 + c]
            out_grad[k, 1, c] = -(r[1 + c] + r[4 + c])
            out_gnormal[k, c] = r[7 + c]


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
