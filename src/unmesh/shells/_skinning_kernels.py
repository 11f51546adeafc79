"""Numba kernels for the local-frame surface skinning (thesis 7.4, eqs. 7.26-7.30).

Numpy reference: :func:`unmesh.shells.skinning.deform_reference`.
"""

from __future__ import annotations

import math

from numba import njit, prange


@njit(cache=True)
def smallest_eigenvector(c00, c01, c02, c11, c12, c22):
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (closed form)."""
    p1 = c01 * c01 + c02 * c02 + c12 * c12
    q = (c00 + c11 + c22) / 3.0
    p2 = (c00 - q) ** 2 + (c11 - q) ** 2 + (c22 - q) ** 2 + 2.0 * p1
    if p2 <= 0.0:
        return 0.0, 0.0, 1.0
    p = math.sqrt(p2 / 6.0)
    b00 = (c00 - q) / p
    b11 = (c11 - q) / p
    b22 = (c22 - q) / p
    b01 = c01 / p
    b02 = c02 / p
    b12 = c12 / p
    det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
    r = min(1.0, max(-1.0, det / 2.0))
    phi = math.acos(r) / 3.0
    lam = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    r00 = c00 - lam
    r11 = c11 - lam
    r22 = c22 - lam
    # cross products of the rows of (C - lam I); take the longest
    ax = c01 * c12 - c02 * r11
    ay = c02 * c01 - r00 * c12
    az = r00 * r11 - c01 * c01
    bx = c01 * r22 - c02 * c12
    by = c02 * c02 - r00 * r22
    bz = r00 * c12 - c01 * c02
    cx = r11 * r22 - c12 * c12
    cy = c12 * c02 - c01 * r22
    cz = c01 * c12 - r11 * c02
    na = ax * ax + ay * ay + az * az
    nb = bx * bx + by * by + bz * bz
    nc = cx * cx + cy * cy + cz * cz
    if na >= nb and na >= nc:
        s = math.sqrt(na)
        if s == 0.0:
            return 0.0, 0.0, 1.0
        return ax / s, ay / s, az / s
    if nb >= nc:
        s = math.sqrt(nb)
        return bx / s, by / s, bz / s
    s = math.sqrt(nc)
    return cx / s, cy / s, cz / s


@njit(cache=True)
def plane_normal(x, normals, nodes):
    """Least-squares plane normal through x[nodes] (7.26), oriented along the sum of normals[nodes]."""
    cnt = 0
    mx = 0.0
    my = 0.0
    mz = 0.0
    ox = 0.0
    oy = 0.0
    oz = 0.0
    for a in range(nodes.shape[0]):
        j = nodes[a]
        if j < 0:
            continue
        cnt += 1
        mx += x[j, 0]
        my += x[j, 1]
        mz += x[j, 2]
        ox += normals[j, 0]
        oy += normals[j, 1]
        oz += normals[j, 2]
    if cnt < 3:
        s = math.sqrt(ox * ox + oy * oy + oz * oz)
        if s == 0.0:
            return 0.0, 0.0, 1.0
        return ox / s, oy / s, oz / s
    mx /= cnt
    my /= cnt
    mz /= cnt
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for a in range(nodes.shape[0]):
        j = nodes[a]
        if j < 0:
            continue
        dx = x[j, 0] - mx
        dy = x[j, 1] - my
        dz = x[j, 2] - mz
        c00 += dx * dx
        c01 += dx * dy
        c02 += dx * dz
        c11 += dy * dy
        c12 += dy * dz
        c22 += dz * dz
    vx, vy, vz = smallest_eigenvector(c00, c01, c02, c11, c12, c22)
    if vx * ox + vy * oy + vz * oz < 0.0:
        return -vx, -vy, -vz
    return vx, vy, vz


@njit(cache=True, parallel=True)
def rest_plane_normals(x, normals, bind, out):
    """Rest plane normals (S, 3) of all bindings."""
    for s in prange(bind.shape[0]):
        a, b, c = plane_normal(x, normals, bind[s])
        out[s, 0] = a
        out[s, 1] = b
        out[s, 2] = c


@njit(cache=True)
def _frame(x, o, j, n0, n1, n2):
    """e1 = x_j - x_o, e2 = N x e1 / |e1|, e3 = e2 x e1 / |e1| (7.26) as 9 scalars."""
    e10 = x[j, 0] - x[o, 0]
    e11 = x[j, 1] - x[o, 1]
    e12 = x[j, 2] - x[o, 2]
    ln = math.sqrt(e10 * e10 + e11 * e11 + e12 * e12)
    if ln == 0.0:
        ln = 1e-300
    e20 = (n1 * e12 - n2 * e11) / ln
    e21 = (n2 * e10 - n0 * e12) / ln
    e22 = (n0 * e11 - n1 * e10) / ln
    e30 = (e21 * e12 - e22 * e11) / ln
    e31 = (e22 * e10 - e20 * e12) / ln
    e32 = (e20 * e11 - e21 * e10) / ln
    return e10, e11, e12, e20, e21, e22, e30, e31, e32


@njit(cache=True)
def _transfer(d0, d1, d2, f, g):
    """Local coordinates of d in rest frame f (7.27), mapped to world with frame g (7.28)."""
    out0 = 0.0
    out1 = 0.0
    out2 = 0.0
    for k in range(3):
        a0 = f[3 * k]
        a1 = f[3 * k + 1]
        a2 = f[3 * k + 2]
        nn = a0 * a0 + a1 * a1 + a2 * a2
        if nn > 0.0:
            y = (d0 * a0 + d1 * a1 + d2 * a2) / nn
            out0 += y * g[3 * k]
            out1 += y * g[3 * k + 1]
            out2 += y * g[3 * k + 2]
    return out0, out1, out2


@njit(cache=True, parallel=True)
def deform(rest, cur, cur_normals, bind, weights, plane_rest, points, axes, orient, out_points, out_axes,
           out_normals):
    """Skin S points and their tangent axes from rest to current node positions (7.26-7.30).

    bind (S, K+1): x0 first, then frame nodes (-1 = unused); weights (S, K) of the frames
    x_1..x_K (7.30). Points without any weighted frame are translated with x0.
    """
    for s in prange(bind.shape[0]):
        o = bind[s, 0]
        n0, n1, n2 = plane_rest[s, 0], plane_rest[s, 1], plane_rest[s, 2]
        m0, m1, m2 = plane_normal(cur, cur_normals, bind[s])
        d0 = points[s, 0] - rest[o, 0]
        d1 = points[s, 1] - rest[o, 1]
        d2 = points[s, 2] - rest[o, 2]
        wsum = 0.0
        p0 = p1 = p2 = 0.0
        a00 = a01 = a02 = a10 = a11 = a12 = 0.0
        for i in range(weights.shape[1]):
            w = weights[s, i]
            j = bind[s, i + 1]
            if w <= 0.0 or j < 0:
                continue
            f = _frame(rest, o, j, n0, n1, n2)
            g = _frame(cur, o, j, m0, m1, m2)
            q0, q1, q2 = _transfer(d0, d1, d2, f, g)
            p0 += w * q0
            p1 += w * q1
            p2 += w * q2
            q0, q1, q2 = _transfer(axes[s, 0, 0], axes[s, 0, 1], axes[s, 0, 2], f, g)
            a00 += w * q0
            a01 += w * q1
            a02 += w * q2
            q0, q1, q2 = _transfer(axes[s, 1, 0], axes[s, 1, 1], axes[s, 1, 2], f, g)
            a10 += w * q0
            a11 += w * q1
            a12 += w * q2
            wsum += w
        if wsum > 0.0:
            p0 /= wsum
            p1 /= wsum
            p2 /= wsum
            a00 /= wsum
            a01 /= wsum
            a02 /= wsum
            a10 /= wsum
            a11 /= wsum
            a12 /= wsum
        else:
            p0, p1, p2 = d0, d1, d2
            a00, a01, a02 = axes[s, 0, 0], axes[s, 0, 1], axes[s, 0, 2]
            a10, a11, a12 = axes[s, 1, 0], axes[s, 1, 1], axes[s, 1, 2]
        out_points[s, 0] = cur[o, 0] + p0
        out_points[s, 1] = cur[o, 1] + p1
        out_points[s, 2] = cur[o, 2] + p2
        out_axes[s, 0, 0] = a00
        out_axes[s, 0, 1] = a01
        out_axes[s, 0, 2] = a02
        out_axes[s, 1, 0] = a10
        out_axes[s, 1, 1] = a11
        out_axes[s, 1, 2] = a12
        c0 = a01 * a12 - a02 * a11
        c1 = a02 * a10 - a00 * a12
        c2 = a00 * a11 - a01 * a10
        cn = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        if cn > 0.0:
            out_normals[s, 0] = orient[s] * c0 / cn
            out_normals[s, 1] = orient[s] * c1 / cn
            out_normals[s, 2] = orient[s] * c2 / cn
        else:
            out_normals[s, 0] = m0
            out_normals[s, 1] = m1
            out_normals[s, 2] = m2
