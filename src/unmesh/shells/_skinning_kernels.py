"""Numba kernels for the local-frame surface skinning (thesis 7.4, eqs. 7.26-7.30).

Numpy reference: :func:`unmesh.shells.skinning.deform_reference`.

The local coordinates ``y^i`` (7.27) of every passive point are computed once when the
point is bound (:func:`local_coordinates`) and stored with it, as the thesis does; per
frame, :func:`deform` only builds the deformed frames (7.26) and blends (7.28-7.29). With
``N`` the (unit) plane normal and ``e1 = x_i - x_0``, ``L = |e1|``, the frame of (7.26) is
``e2 = N x e1 / L``, ``e3 = e2 x e1 / L = e1 (N.e1) / L^2 - N``, so a point with local
coordinates ``y`` maps to ``(y1 + y3 (N.e1)/L^2) e1 + (y2 / L) (N x e1) - y3 N``.
"""

from __future__ import annotations

import math

from numba import njit, prange

from unmesh.surfels._kernels import smallest_eigenvector

#: Doubles stored per frame: local coordinates of the offset p - x_0 and of the two tangent axes.
COORDS = 9


@njit(cache=True)
def plane_normal(x, normals, nodes):
    """Least-squares plane normal through x[nodes] (7.26), oriented along the sum of normals[nodes].

    Entries of ``nodes`` below 0 are skipped; with fewer than 3 nodes the normalised sum of
    their normals is returned.
    """
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


@njit(cache=True, parallel=True)
def local_coordinates(rest, bind, weights, plane, points, axes, out):
    """Local coordinates (7.27) of each point offset and tangent axis in its rest frames (7.26).

    out (S, K, 9): for frame i (node ``bind[s, i + 1]``), ``y`` of ``points[s] - rest[x_0]``,
    of ``axes[s, 0]`` and of ``axes[s, 1]``; zero for frames with weight 0.
    """
    for s in prange(bind.shape[0]):
        o = bind[s, 0]
        n0 = plane[s, 0]
        n1 = plane[s, 1]
        n2 = plane[s, 2]
        for i in range(weights.shape[1]):
            for c in range(9):
                out[s, i, c] = 0.0
            j = bind[s, i + 1]
            if weights[s, i] <= 0.0 or j < 0:
                continue
            e10 = rest[j, 0] - rest[o, 0]
            e11 = rest[j, 1] - rest[o, 1]
            e12 = rest[j, 2] - rest[o, 2]
            ln = math.sqrt(e10 * e10 + e11 * e11 + e12 * e12)
            if ln == 0.0:
                ln = 1e-300
            e20 = (n1 * e12 - n2 * e11) / ln
            e21 = (n2 * e10 - n0 * e12) / ln
            e22 = (n0 * e11 - n1 * e10) / ln
            e30 = (e21 * e12 - e22 * e11) / ln
            e31 = (e22 * e10 - e20 * e12) / ln
            e32 = (e20 * e11 - e21 * e10) / ln
            q1 = e10 * e10 + e11 * e11 + e12 * e12
            q2 = e20 * e20 + e21 * e21 + e22 * e22
            q3 = e30 * e30 + e31 * e31 + e32 * e32
            for v in range(3):
                if v == 0:
                    d0 = points[s, 0] - rest[o, 0]
                    d1 = points[s, 1] - rest[o, 1]
                    d2 = points[s, 2] - rest[o, 2]
                else:
                    d0 = axes[s, v - 1, 0]
                    d1 = axes[s, v - 1, 1]
                    d2 = axes[s, v - 1, 2]
                out[s, i, 3 * v] = (d0 * e10 + d1 * e11 + d2 * e12) / q1 if q1 > 0.0 else 0.0
                out[s, i, 3 * v + 1] = (d0 * e20 + d1 * e21 + d2 * e22) / q2 if q2 > 0.0 else 0.0
                out[s, i, 3 * v + 2] = (d0 * e30 + d1 * e31 + d2 * e32) / q3 if q3 > 0.0 else 0.0


@njit(cache=True, parallel=True, fastmath={"nsz", "arcp", "contract", "reassoc"})
def deform(rest, cur, cur_normals, bind, weights, coords, points, axes, orient, out_points, out_normals, out_radii):
    """Skin S points and their tangent axes from rest to current node positions (7.26-7.30).

    bind (S, K+1): x_0 first, then frame nodes (-1 = unused); weights (S, K) of the frames
    (7.30); coords (S, K, 9) from :func:`local_coordinates`. Writes positions, unit normals
    (``orient`` times the normalised cross product of the deformed axes) and radii (the
    longer deformed axis). Points without any weighted frame are translated with x_0.
    """
    for s in prange(bind.shape[0]):
        o = bind[s, 0]
        m0, m1, m2 = plane_normal(cur, cur_normals, bind[s])
        xo0 = cur[o, 0]
        xo1 = cur[o, 1]
        xo2 = cur[o, 2]
        wsum = 0.0
        p0 = p1 = p2 = 0.0
        a00 = a01 = a02 = a10 = a11 = a12 = 0.0
        y3p = 0.0
        y3a = 0.0
        y3b = 0.0
        for i in range(weights.shape[1]):
            w = weights[s, i]
            j = bind[s, i + 1]
            if w <= 0.0 or j < 0:
                continue
            e0 = cur[j, 0] - xo0
            e1 = cur[j, 1] - xo1
            e2 = cur[j, 2] - xo2
            l2 = e0 * e0 + e1 * e1 + e2 * e2
            if l2 == 0.0:
                l2 = 1e-300
            inv_l = 1.0 / math.sqrt(l2)
            ne = (m0 * e0 + m1 * e1 + m2 * e2) / l2
            c0 = (m1 * e2 - m2 * e1) * inv_l
            c1 = (m2 * e0 - m0 * e2) * inv_l
            c2 = (m0 * e1 - m1 * e0) * inv_l
            y = coords[s, i]
            u = w * (y[0] + y[2] * ne)
            t = w * y[1]
            p0 += u * e0 + t * c0
            p1 += u * e1 + t * c1
            p2 += u * e2 + t * c2
            y3p += w * y[2]
            u = w * (y[3] + y[5] * ne)
            t = w * y[4]
            a00 += u * e0 + t * c0
            a01 += u * e1 + t * c1
            a02 += u * e2 + t * c2
            y3a += w * y[5]
            u = w * (y[6] + y[8] * ne)
            t = w * y[7]
            a10 += u * e0 + t * c0
            a11 += u * e1 + t * c1
            a12 += u * e2 + t * c2
            y3b += w * y[8]
            wsum += w
        if wsum > 0.0:
            inv = 1.0 / wsum
            p0 = (p0 - y3p * m0) * inv
            p1 = (p1 - y3p * m1) * inv
            p2 = (p2 - y3p * m2) * inv
            a00 = (a00 - y3a * m0) * inv
            a01 = (a01 - y3a * m1) * inv
            a02 = (a02 - y3a * m2) * inv
            a10 = (a10 - y3b * m0) * inv
            a11 = (a11 - y3b * m1) * inv
            a12 = (a12 - y3b * m2) * inv
        else:
            p0 = points[s, 0] - rest[o, 0]
            p1 = points[s, 1] - rest[o, 1]
            p2 = points[s, 2] - rest[o, 2]
            a00, a01, a02 = axes[s, 0, 0], axes[s, 0, 1], axes[s, 0, 2]
            a10, a11, a12 = axes[s, 1, 0], axes[s, 1, 1], axes[s, 1, 2]
        out_points[s, 0] = xo0 + p0
        out_points[s, 1] = xo1 + p1
        out_points[s, 2] = xo2 + p2
        r0 = a00 * a00 + a01 * a01 + a02 * a02
        r1 = a10 * a10 + a11 * a11 + a12 * a12
        out_radii[s] = math.sqrt(max(r0, r1))
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
