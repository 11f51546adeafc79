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

import numpy as np
from numba import njit, prange

from unmesh._linalg_kernels import FASTMATH, smallest_eigenvector, smallest_eigenvector_sel
from unmesh.spatial._kernels import cell_key, dense_cell, dense_grid

#: Doubles stored per frame: local coordinates of the offset p - x_0 and of the two tangent axes.
COORDS = 9
#: A deformed frame whose edge ``e1`` is within 30° of ``N`` (``|cos| >= FRAME_FADE_TO``) spans almost
#: nothing across ``e1`` (7.26) and keeps only :data:`FRAME_FADE_FLOOR` of its weight; from 45°
#: (``FRAME_FADE_FROM``) to 30° its weight fades linearly (:func:`frame_fade`).
FRAME_FADE_FROM = 0.8660254037844387
FRAME_FADE_TO = 0.9659258262890683
#: The weight a degenerate frame keeps: when every frame of a point is degenerate their blend is
#: the unfaded one (the fade stays continuous).
FRAME_FADE_FLOOR = 1e-3


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


@njit(cache=True, inline="always")
def frame_fade(cos):
    """Weight factor of a deformed frame whose edge makes ``|cos| = |N . e1| / |e1|`` with ``N``:
    1 up to ``FRAME_FADE_FROM``, linear down to ``FRAME_FADE_FLOOR`` at ``FRAME_FADE_TO``."""
    if cos <= FRAME_FADE_FROM:
        return 1.0
    if cos >= FRAME_FADE_TO:
        return FRAME_FADE_FLOOR
    t = (FRAME_FADE_TO - cos) / (FRAME_FADE_TO - FRAME_FADE_FROM)
    return FRAME_FADE_FLOOR + (1.0 - FRAME_FADE_FLOOR) * t


@njit(cache=True, inline="always")
def _near(points, r, lim, centers, c):
    dx = points[r, 0] - centers[c, 0]
    dy = points[r, 1] - centers[c, 1]
    dz = points[r, 2] - centers[c, 2]
    return math.sqrt(dx * dx + dy * dy + dz * dz) <= lim


@njit(cache=True)
def within_reach(points, rows, reach, radius, centers):
    """(R,) bool: some centre lies within ``reach[r] + radius`` of ``points[r]`` (r in ``rows``), with
    distances ``sqrt(dx^2 + dy^2 + dz^2)`` as ``numpy.linalg.norm``.

    With many rows and centres the centres are binned in a uniform grid whose cells are at
    least the largest ``reach + radius``: a centre within reach of a point lies in the 27
    cells around the point's cell (the same answer, each point meeting only the centres
    near it)."""
    out = np.zeros(rows.shape[0], dtype=np.bool_)
    nc = centers.shape[0]
    if nc <= 8 or rows.shape[0] < 256:
        for t in range(rows.shape[0]):
            r = rows[t]
            lim = reach[r] + radius
            for c in range(nc):
                if _near(points, r, lim, centers, c):
                    out[t] = True
                    break
        return out
    h = 0.0
    for t in range(rows.shape[0]):
        h = max(h, reach[rows[t]] + radius)
    lo, _, inv, dims, start, order = dense_grid(centers, h * (1.0 + 1e-9) + 1e-300, 8 * nc + 64)
    for t in range(rows.shape[0]):
        r = rows[t]
        lim = reach[r] + radius
        c0, c1, c2 = dense_cell(points[r, 0], points[r, 1], points[r, 2], lo, inv)  # any value: ranges are clipped
        for j0 in range(max(c0 - 1, 0), min(c0 + 2, dims[0])):
            for j1 in range(max(c1 - 1, 0), min(c1 + 2, dims[1])):
                for j2 in range(max(c2 - 1, 0), min(c2 + 2, dims[2])):
                    g = cell_key(j0, j1, j2, dims)
                    for e in range(start[g], start[g + 1]):
                        if not out[t] and _near(points, r, lim, centers, order[e]):
                            out[t] = True
    return out


@njit(cache=True)
def shared_bound(bind, nbr, rows, out):
    """``out[t, a]`` (R, m) bool: surfel ``rows[t]`` and its rest neighbour ``nbr[rows[t], a]`` are
    bound to a common node (entries >= 0 of ``bind`` (S, K+1)) and are not the same surfel
    (:func:`unmesh.shells.skinning._cover_pairs`, its numpy reference)."""
    k = bind.shape[1]
    for t in range(rows.shape[0]):
        r = rows[t]
        for a in range(nbr.shape[1]):
            j = nbr[r, a]
            hit = False
            if j != r:
                for p in range(k):
                    b = bind[r, p]
                    if b >= 0:
                        for q in range(k):
                            if bind[j, q] == b:
                                hit = True
            out[t, a] = hit


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


#: Surfels per block of the vectorised :func:`deform` (one row of its scratch).
SBLK = 64
#: Scratch rows: node count (0), sum of node normals (1-3), covariance (4-9), plane normal (10-12).
SROWS = 13
_CNT, _NSUM, _COV, _M = 0, 1, 4, 10


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _deform_block(s0, nb, cur, cur_normals, bind, weights, coords, points, axes, orient, by_normals, rest, blk,
                  out_points, out_normals, out_radii):
    """:func:`deform` of the surfels ``s0 .. s0 + nb`` (nb <= SBLK): node sums per surfel (one pass,
    offsets from x_0), the plane normals of the whole block (vectorised), then frames and
    blending per surfel."""
    B = SBLK
    kk = bind.shape[1]
    for t in range(nb):                               # node count, covariance and normal sum of the bound nodes
        s = s0 + t
        o = bind[s, 0]
        xo0 = cur[o, 0]
        xo1 = cur[o, 1]
        xo2 = cur[o, 2]
        cnt = 1.0
        ox = cur_normals[o, 0]
        oy = cur_normals[o, 1]
        oz = cur_normals[o, 2]
        s10 = s11 = s12 = 0.0
        c00 = c01 = c02 = c11 = c12 = c22 = 0.0
        for a in range(1, kk):                        # sums of d = x_j - x_0 and of d d^T (x_0 itself: d = 0)
            j = bind[s, a]
            if j >= 0:
                d0 = cur[j, 0] - xo0
                d1 = cur[j, 1] - xo1
                d2 = cur[j, 2] - xo2
                cnt += 1.0
                ox += cur_normals[j, 0]
                oy += cur_normals[j, 1]
                oz += cur_normals[j, 2]
                s10 += d0
                s11 += d1
                s12 += d2
                c00 += d0 * d0
                c01 += d0 * d1
                c02 += d0 * d2
                c11 += d1 * d1
                c12 += d1 * d2
                c22 += d2 * d2
        ic = 1.0 / cnt
        blk[_CNT * B + t] = cnt
        blk[(_NSUM + 0) * B + t] = ox
        blk[(_NSUM + 1) * B + t] = oy
        blk[(_NSUM + 2) * B + t] = oz
        blk[(_COV + 0) * B + t] = c00 - s10 * s10 * ic
        blk[(_COV + 1) * B + t] = c01 - s10 * s11 * ic
        blk[(_COV + 2) * B + t] = c02 - s10 * s12 * ic
        blk[(_COV + 3) * B + t] = c11 - s11 * s11 * ic
        blk[(_COV + 4) * B + t] = c12 - s11 * s12 * ic
        blk[(_COV + 5) * B + t] = c22 - s12 * s12 * ic
    for t in range(nb):                               # the least-squares plane normals (7.26)
        vx, vy, vz = smallest_eigenvector_sel(blk[(_COV + 0) * B + t], blk[(_COV + 1) * B + t],
                                              blk[(_COV + 2) * B + t], blk[(_COV + 3) * B + t],
                                              blk[(_COV + 4) * B + t], blk[(_COV + 5) * B + t])
        ox = blk[(_NSUM + 0) * B + t]
        oy = blk[(_NSUM + 1) * B + t]
        oz = blk[(_NSUM + 2) * B + t]
        flip = vx * ox + vy * oy + vz * oz < 0.0
        vx = -vx if flip else vx
        vy = -vy if flip else vy
        vz = -vz if flip else vz
        # fewer than 3 nodes, or no reliable plane at rest (``by_normals``): the normalised sum
        # of their normals
        few = blk[_CNT * B + t] < 3.0 or by_normals[s0 + t] != 0
        on = math.sqrt(ox * ox + oy * oy + oz * oz)
        ion0 = 1.0 / on
        ion = ion0 if on > 0.0 else 0.0
        blk[(_M + 0) * B + t] = (ox * ion if on > 0.0 else 0.0) if few else vx
        blk[(_M + 1) * B + t] = (oy * ion if on > 0.0 else 0.0) if few else vy
        blk[(_M + 2) * B + t] = (oz * ion if on > 0.0 else 1.0) if few else vz
    for t in range(nb):                               # frames (7.26) and blending (7.28, 7.29)
        s = s0 + t
        o = bind[s, 0]
        m0 = blk[(_M + 0) * B + t]
        m1 = blk[(_M + 1) * B + t]
        m2 = blk[(_M + 2) * B + t]
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
            l20 = e0 * e0 + e1 * e1 + e2 * e2
            l2 = l20 if l20 > 0.0 else 1e-300
            inv_l = 1.0 / math.sqrt(l2)
            ne = (m0 * e0 + m1 * e1 + m2 * e2) * (inv_l * inv_l)
            w *= frame_fade(abs(ne) * math.sqrt(l2))       # a frame turned onto N fades (FRAME_FADE_*)
            c0 = (m1 * e2 - m2 * e1) * inv_l
            c1 = (m2 * e0 - m0 * e2) * inv_l
            c2 = (m0 * e1 - m1 * e0) * inv_l
            u = w * (coords[s, i, 0] + coords[s, i, 2] * ne)
            v = w * coords[s, i, 1]
            p0 += u * e0 + v * c0
            p1 += u * e1 + v * c1
            p2 += u * e2 + v * c2
            y3p += w * coords[s, i, 2]
            u = w * (coords[s, i, 3] + coords[s, i, 5] * ne)
            v = w * coords[s, i, 4]
            a00 += u * e0 + v * c0
            a01 += u * e1 + v * c1
            a02 += u * e2 + v * c2
            y3a += w * coords[s, i, 5]
            u = w * (coords[s, i, 6] + coords[s, i, 8] * ne)
            v = w * coords[s, i, 7]
            a10 += u * e0 + v * c0
            a11 += u * e1 + v * c1
            a12 += u * e2 + v * c2
            y3b += w * coords[s, i, 8]
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
        else:                                         # no weighted frame: translated with x_0
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
        rad = math.sqrt(max(r0, r1))
        out_radii[s] = rad if rad > 0.0 else 1e-9
        c0 = a01 * a12 - a02 * a11
        c1 = a02 * a10 - a00 * a12
        c2 = a00 * a11 - a01 * a10
        cn = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        if cn > 0.0:
            f = orient[s] / cn
            out_normals[s, 0] = c0 * f
            out_normals[s, 1] = c1 * f
            out_normals[s, 2] = c2 * f
        elif abs(m0) + abs(m1) + abs(m2) > 0.0:
            out_normals[s, 0] = m0
            out_normals[s, 1] = m1
            out_normals[s, 2] = m2
        else:
            out_normals[s, 0] = 0.0
            out_normals[s, 1] = 0.0
            out_normals[s, 2] = 1.0


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def deform(rest, cur, cur_normals, bind, weights, coords, points, axes, orient, by_normals, out_points, out_normals,
           out_radii):
    """Skin S points and their tangent axes from rest to current node positions (7.26-7.30).

    bind (S, K+1): x_0 first, then frame nodes (-1 = unused); weights (S, K) of the frames
    (7.30); coords (S, K, 9) from :func:`local_coordinates`. Writes positions, unit normals
    (``orient`` times the normalised cross product of the deformed axes; the plane normal
    where that vanishes, (0, 0, 1) where both do) and radii (the longer deformed axis,
    1e-9 where zero). Each frame's weight is scaled by :func:`frame_fade` of its deformed
    edge (beyond the thesis: a frame whose edge turned onto ``N`` amplifies node motion).
    Points without any weighted frame are translated with x_0. Points with
    ``by_normals[s] != 0`` (S,) uint8 use the normalised sum of their nodes' normals as ``N``
    instead of the least-squares plane normal (see :func:`unmesh.shells.skinning.frame_normals`). The
    surfels are done in blocks of :data:`SBLK`; the plane normal is that of :func:`plane_normal`
    (its covariance from sums of the node offsets from x_0, up to round-off).
    """
    n = bind.shape[0]
    nblocks = (n + SBLK - 1) // SBLK
    for c in prange((nblocks + 7) // 8):
        blk = np.empty(SROWS * SBLK)
        for bb in range(8 * c, min(8 * c + 8, nblocks)):
            s0 = bb * SBLK
            _deform_block(s0, min(SBLK, n - s0), cur, cur_normals, bind, weights, coords, points, axes, orient,
                          by_normals, rest, blk, out_points, out_normals, out_radii)


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def cover_radii(points, nbr, scale2, cap, radii):
    """Enlarge deformed splat radii so that no gap opens towards rest neighbours (in place).

    ``radii[s] = max(radii[s], max_j sqrt(scale2[s, a]) |p_s - p_j|)`` over the rest neighbours
    ``j = nbr[s, a]`` with ``scale2[s, a] = (rest radius / rest distance)^2`` (0 for pairs that
    do not count: torn apart by a crack, or sharing no bound node) whose term is at most
    ``cap radii[s]`` (farther ones count as torn apart). Numpy reference:
    :func:`unmesh.shells.skinning.cover_radii_reference`.
    """
    n, m = nbr.shape
    for s in prange(n):
        r = radii[s]
        best = r * r
        lim = cap * cap * best
        for a in range(m):
            j = nbr[s, a]
            dx = points[j, 0] - points[s, 0]
            dy = points[j, 1] - points[s, 1]
            dz = points[j, 2] - points[s, 2]
            need = scale2[s, a] * (dx * dx + dy * dy + dz * dz)
            if need > best and need <= lim:
                best = need
        radii[s] = math.sqrt(best)
