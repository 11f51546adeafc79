"""Numba kernels of :class:`unmesh.spatial.TriangleBVH` (moved here from ``unmesh.shapes._kernels``).

- :func:`bvh_build`: median-split AABB tree over triangles, with the far-field data of
  the winding-number expansion.
- :func:`closest_on_triangle` / :func:`bvh_closest`: exact closest points with the
  triangle and barycentric coordinates.
- :func:`triangle_solid_angle` / :func:`bvh_winding`: generalized winding numbers
  (Jacobson et al. 2013; Barill et al. 2018: exact solid angles of nearby triangles,
  first-order dipole expansion of distant clusters).
- :func:`ray_triangle` (Moeller & Trumbore 1997), :func:`bvh_ray_first`,
  :func:`bvh_ray_count` / :func:`bvh_ray_fill`: ray hits.

Numpy references (brute force over all triangles) are in ``unmesh.spatial.bvh``:
``closest_point_reference``, ``winding_reference``, ``ray_hits_reference``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

LEAF_SIZE = 8


@njit(cache=True)
def bvh_build(vertices, faces, leaf_size):  # pragma: no cover - numba
    """Median-split AABB tree over triangles.

    Returns ``order`` (F,) (triangles of node n are ``order[start[n]:start[n]+count[n]]``),
    per-node ``lo, hi`` (M,3) boxes, ``left, right`` (M,) children (-1 for leaves),
    ``start, count`` (M,), and for the winding-number far field the node's area
    vector ``avec`` (M,3) (sum of half cross products), area-weighted centre
    ``ctr`` (M,3) and radius ``rad`` (M,) bounding the distance from ``ctr`` to
    every vertex of the node's triangles.
    """
    nf = faces.shape[0]
    tlo = np.empty((nf, 3))
    thi = np.empty((nf, 3))
    cen = np.empty((nf, 3))
    tvec = np.empty((nf, 3))
    tarea = np.empty(nf)
    for t in range(nf):
        a = vertices[faces[t, 0]]
        b = vertices[faces[t, 1]]
        c = vertices[faces[t, 2]]
        for k in range(3):
            tlo[t, k] = min(a[k], b[k], c[k])
            thi[t, k] = max(a[k], b[k], c[k])
            cen[t, k] = (a[k] + b[k] + c[k]) / 3.0
        e1 = b - a
        e2 = c - a
        tvec[t, 0] = 0.5 * (e1[1] * e2[2] - e1[2] * e2[1])
        tvec[t, 1] = 0.5 * (e1[2] * e2[0] - e1[0] * e2[2])
        tvec[t, 2] = 0.5 * (e1[0] * e2[1] - e1[1] * e2[0])
        tarea[t] = math.sqrt(tvec[t, 0] ** 2 + tvec[t, 1] ** 2 + tvec[t, 2] ** 2)
    cap = max(1, 2 * nf)
    lo = np.empty((cap, 3))
    hi = np.empty((cap, 3))
    left = -np.ones(cap, np.int64)
    right = -np.ones(cap, np.int64)
    start = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    order = np.arange(nf)
    nodes = 1
    start[0] = 0
    count[0] = nf
    stack = np.empty(128, np.int64)
    sp = 0
    stack[sp] = 0
    sp += 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s0 = start[node]
        n = count[node]
        for k in range(3):
            lo[node, k] = np.inf
            hi[node, k] = -np.inf
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for i in range(s0, s0 + n):
            t = order[i]
            for k in range(3):
                lo[node, k] = min(lo[node, k], tlo[t, k])
                hi[node, k] = max(hi[node, k], thi[t, k])
                clo[k] = min(clo[k], cen[t, k])
                chi[k] = max(chi[k], cen[t, k])
        if n <= leaf_size:
            continue
        axis = 0
        for k in range(1, 3):
            if chi[k] - clo[k] > chi[axis] - clo[axis]:
                axis = k
        keys = np.empty(n)
        for i in range(n):
            keys[i] = cen[order[s0 + i], axis]
        perm = np.argsort(keys, kind="mergesort")
        seg = order[s0:s0 + n].copy()
        for i in range(n):
            order[s0 + i] = seg[perm[i]]
        half = n // 2
        l_id = nodes
        r_id = nodes + 1
        nodes += 2
        left[node] = l_id
        right[node] = r_id
        start[l_id] = s0
        count[l_id] = half
        start[r_id] = s0 + half
        count[r_id] = n - half
        if sp + 2 > stack.shape[0]:
            bigger = np.empty(2 * stack.shape[0], np.int64)
            bigger[:sp] = stack[:sp]
            stack = bigger
        stack[sp] = l_id
        stack[sp + 1] = r_id
        sp += 2
    # Far-field data, children (higher ids) before parents.
    avec = np.zeros((nodes, 3))
    ctr = np.zeros((nodes, 3))
    rad = np.zeros(nodes)
    area = np.zeros(nodes)
    for node in range(nodes - 1, -1, -1):
        if left[node] < 0:
            s0 = start[node]
            n = count[node]
            tot = 0.0
            for i in range(s0, s0 + n):
                t = order[i]
                tot += tarea[t]
                for k in range(3):
                    avec[node, k] += tvec[t, k]
            for i in range(s0, s0 + n):
                t = order[i]
                w = tarea[t] / tot if tot > 0.0 else 1.0 / n
                for k in range(3):
                    ctr[node, k] += w * cen[t, k]
            area[node] = tot
            r = 0.0
            for i in range(s0, s0 + n):
                t = order[i]
                for j in range(3):
                    v = faces[t, j]
                    d = 0.0
                    for k in range(3):
                        d += (vertices[v, k] - ctr[node, k]) ** 2
                    r = max(r, math.sqrt(d))
            rad[node] = r
        else:
            lc = left[node]
            rc = right[node]
            tot = area[lc] + area[rc]
            area[node] = tot
            wl = area[lc] / tot if tot > 0.0 else 0.5
            for k in range(3):
                avec[node, k] = avec[lc, k] + avec[rc, k]
                ctr[node, k] = wl * ctr[lc, k] + (1.0 - wl) * ctr[rc, k]
            dl = 0.0
            dr = 0.0
            for k in range(3):
                dl += (ctr[lc, k] - ctr[node, k]) ** 2
                dr += (ctr[rc, k] - ctr[node, k]) ** 2
            rad[node] = max(math.sqrt(dl) + rad[lc], math.sqrt(dr) + rad[rc])
    return (order, lo[:nodes].copy(), hi[:nodes].copy(), left[:nodes].copy(), right[:nodes].copy(),
            start[:nodes].copy(), count[:nodes].copy(), avec, ctr, rad)


@njit(cache=True, inline="always")
def _dot(a0, a1, a2, b0, b1, b2):  # pragma: no cover - numba
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(cache=True)
def _push_nearer_last(stack, sp, lc, rc, left_nearer):
    """Push children ``lc`` and ``rc`` so that the nearer one is popped first; the new stack size."""
    if left_nearer:
        stack[sp] = rc
        stack[sp + 1] = lc
    else:
        stack[sp] = lc
        stack[sp + 1] = rc
    return sp + 2


@njit(cache=True, inline="always")
def _edge_point(p, e0, e1):  # pragma: no cover - numba
    """Closest point ``x = e0 + t (e1 - e0)`` on a segment: (x, t, squared distance)."""
    e = e1 - e0
    ee = _dot(e[0], e[1], e[2], e[0], e[1], e[2])
    t = 0.0
    if ee > 0.0:
        q = p - e0
        t = min(1.0, max(0.0, _dot(q[0], q[1], q[2], e[0], e[1], e[2]) / ee))
    x = e0 + t * e
    dx = p - x
    return x, t, _dot(dx[0], dx[1], dx[2], dx[0], dx[1], dx[2])


@njit(cache=True)
def closest_on_triangle(p, a, b, c):  # pragma: no cover - numba
    """Closest point (3,) on triangle abc to p and its barycentric coordinates (b0, b1, b2).

    Ericson, Real-Time Collision Detection 5.1.5; the point is ``b0 a + b1 b + b2 c``
    up to round-off (it is computed as in Ericson, the coordinates alongside).
    """
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = _dot(ab[0], ab[1], ab[2], ap[0], ap[1], ap[2])
    d2 = _dot(ac[0], ac[1], ac[2], ap[0], ap[1], ap[2])
    if d1 <= 0.0 and d2 <= 0.0:
        return a.copy(), 1.0, 0.0, 0.0
    bp = p - b
    d3 = _dot(ab[0], ab[1], ab[2], bp[0], bp[1], bp[2])
    d4 = _dot(ac[0], ac[1], ac[2], bp[0], bp[1], bp[2])
    if d3 >= 0.0 and d4 <= d3:
        return b.copy(), 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a + v * ab, 1.0 - v, v, 0.0
    cp = p - c
    d5 = _dot(ab[0], ab[1], ab[2], cp[0], cp[1], cp[2])
    d6 = _dot(ac[0], ac[1], ac[2], cp[0], cp[1], cp[2])
    if d6 >= 0.0 and d5 <= d6:
        return c.copy(), 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a + w * ac, 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b + w * (c - b), 0.0, 1.0 - w, w
    denom = va + vb + vc
    if denom == 0.0:  # degenerate triangle: fall back to the closest edge point
        x, t, bd = _edge_point(p, a, b)
        best = x
        w0, w1, w2 = 1.0 - t, t, 0.0
        x, t, dd = _edge_point(p, b, c)
        if dd < bd:
            bd = dd
            best = x
            w0, w1, w2 = 0.0, 1.0 - t, t
        x, t, dd = _edge_point(p, c, a)
        if dd < bd:
            best = x
            w0, w1, w2 = t, 0.0, 1.0 - t
        return best, w0, w1, w2
    v = vb / denom
    w = vc / denom
    return a + ab * v + ac * w, 1.0 - v - w, v, w


@njit(cache=True)
def _closest_one(qi, queries, vertices, faces, order, lo, hi, left, right, start, count,
                 dist, pts, face, bary):  # pragma: no cover - numba
    """Closest point of query ``qi`` into row ``qi`` of the outputs (body of :func:`bvh_closest`)."""
    p = queries[qi].copy()
    best = np.inf
    bface = -1
    bp = np.zeros(3)
    bw = np.full(3, np.nan)
    stack = np.empty(256, np.int64)
    sp = 1
    stack[0] = 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        d2 = 0.0
        for k in range(3):
            if p[k] < lo[node, k]:
                d2 += (lo[node, k] - p[k]) ** 2
            elif p[k] > hi[node, k]:
                d2 += (p[k] - hi[node, k]) ** 2
        if d2 >= best:
            continue
        if left[node] < 0:
            for i in range(start[node], start[node] + count[node]):
                t = order[i]
                x, w0, w1, w2 = closest_on_triangle(p, vertices[faces[t, 0]], vertices[faces[t, 1]], vertices[faces[t, 2]])
                dd = (x[0] - p[0]) ** 2 + (x[1] - p[1]) ** 2 + (x[2] - p[2]) ** 2
                if dd < best or (dd == best and t < bface):
                    best = dd
                    bface = t
                    bp[:] = x
                    bw[0] = w0
                    bw[1] = w1
                    bw[2] = w2
        else:
            # Push the farther child first so the nearer one is searched first.
            lc = left[node]
            rc = right[node]
            dl = 0.0
            dr = 0.0
            for k in range(3):
                c1 = 0.5 * (lo[lc, k] + hi[lc, k]) - p[k]
                c2 = 0.5 * (lo[rc, k] + hi[rc, k]) - p[k]
                dl += c1 * c1
                dr += c2 * c2
            sp = _push_nearer_last(stack, sp, lc, rc, dl <= dr)
    dist[qi] = math.sqrt(best)
    pts[qi] = bp
    face[qi] = bface
    bary[qi] = bw


@njit(cache=True, parallel=True)
def bvh_closest(queries, vertices, faces, order, lo, hi, left, right, start, count):  # pragma: no cover - numba
    """Closest point on the mesh: distances (Q,), points (Q,3), face index (Q,), barycentrics (Q,3).

    On exact ties the lowest face index among the visited leaves wins (boxes exactly as far as the
    best distance are pruned); with no triangles the distance is inf and the face -1.
    """
    # a thin prange loop over a serial body: array expressions in a parallel function are
    # parfors of their own, which multiplied its compile time (int64 index: one body signature)
    nq = queries.shape[0]
    dist = np.empty(nq)
    pts = np.empty((nq, 3))
    face = np.empty(nq, np.int64)
    bary = np.empty((nq, 3))
    for qi in prange(nq):
        _closest_one(np.int64(qi), queries, vertices, faces, order, lo, hi, left, right, start, count,
                     dist, pts, face, bary)
    return dist, pts, face, bary


@njit(cache=True)
def triangle_solid_angle(p, a, b, c):  # pragma: no cover - numba
    """Signed solid angle of triangle abc seen from p (Van Oosterom & Strackee 1983).

    Positive when p is behind the triangle (on the side opposite its CCW normal).
    """
    x = a - p
    y = b - p
    z = c - p
    lx = math.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2)
    ly = math.sqrt(y[0] ** 2 + y[1] ** 2 + y[2] ** 2)
    lz = math.sqrt(z[0] ** 2 + z[1] ** 2 + z[2] ** 2)
    det = (x[0] * (y[1] * z[2] - y[2] * z[1]) - x[1] * (y[0] * z[2] - y[2] * z[0])
           + x[2] * (y[0] * z[1] - y[1] * z[0]))
    den = (lx * ly * lz + _dot(x[0], x[1], x[2], y[0], y[1], y[2]) * lz
           + _dot(y[0], y[1], y[2], z[0], z[1], z[2]) * lx + _dot(z[0], z[1], z[2], x[0], x[1], x[2]) * ly)
    return 2.0 * math.atan2(det, den)


@njit(cache=True)
def _winding_one(qi, queries, vertices, faces, order, left, right, start, count, avec, ctr, rad, beta,
                 out):  # pragma: no cover - numba
    """Winding number of query ``qi`` into ``out[qi]`` (body of :func:`bvh_winding`)."""
    p = queries[qi].copy()
    total = 0.0
    stack = np.empty(256, np.int64)
    sp = 1
    stack[0] = 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        dx = ctr[node, 0] - p[0]
        dy = ctr[node, 1] - p[1]
        dz = ctr[node, 2] - p[2]
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        if r > beta * rad[node] and r > 0.0:
            total += (avec[node, 0] * dx + avec[node, 1] * dy + avec[node, 2] * dz) / (r * r * r)
        elif left[node] < 0:
            for i in range(start[node], start[node] + count[node]):
                t = order[i]
                total += triangle_solid_angle(p, vertices[faces[t, 0]], vertices[faces[t, 1]], vertices[faces[t, 2]])
        else:
            stack[sp] = left[node]
            stack[sp + 1] = right[node]
            sp += 2
    out[qi] = total / (4.0 * math.pi)


@njit(cache=True, parallel=True)
def bvh_winding(queries, vertices, faces, order, left, right, start, count, avec, ctr, rad, beta):  # pragma: no cover
    """Generalized winding numbers (Q,) (Jacobson et al. 2013).

    Nodes farther than ``beta * rad`` use the first-order (dipole) term of the
    expansion of Barill et al. 2018: with ``d = ctr - q``, ``4 pi w ~ A . d / |d|^3``
    (``A`` = the node's area vector); nearer triangles use exact solid angles.
    """
    nq = queries.shape[0]
    out = np.empty(nq)
    for qi in prange(nq):
        _winding_one(np.int64(qi), queries, vertices, faces, order, left, right, start, count, avec, ctr, rad, beta,
                     out)
    return out


# ---------------------------------------------------------------------------
# Rays
# ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def ray_triangle(o, d, a, b, c):  # pragma: no cover - numba
    """Moeller-Trumbore ray/triangle test: (hit, t, u, v), the hit at ``o + t d = (1-u-v) a + u b + v c``.

    Both sides count; a ray in the triangle's plane (zero determinant) misses; edges and
    vertices are inclusive (``u, v >= 0``, ``u + v <= 1``); only ``t >= 0`` hits.
    """
    e10 = b[0] - a[0]
    e11 = b[1] - a[1]
    e12 = b[2] - a[2]
    e20 = c[0] - a[0]
    e21 = c[1] - a[1]
    e22 = c[2] - a[2]
    p0 = d[1] * e22 - d[2] * e21
    p1 = d[2] * e20 - d[0] * e22
    p2 = d[0] * e21 - d[1] * e20
    det = e10 * p0 + e11 * p1 + e12 * p2
    if det == 0.0:
        return False, 0.0, 0.0, 0.0
    inv = 1.0 / det
    s0 = o[0] - a[0]
    s1 = o[1] - a[1]
    s2 = o[2] - a[2]
    u = (s0 * p0 + s1 * p1 + s2 * p2) * inv
    if u < 0.0 or u > 1.0:
        return False, 0.0, 0.0, 0.0
    q0 = s1 * e12 - s2 * e11
    q1 = s2 * e10 - s0 * e12
    q2 = s0 * e11 - s1 * e10
    v = (d[0] * q0 + d[1] * q1 + d[2] * q2) * inv
    if v < 0.0 or u + v > 1.0:
        return False, 0.0, 0.0, 0.0
    t = (e20 * q0 + e21 * q1 + e22 * q2) * inv
    if t < 0.0:
        return False, 0.0, 0.0, 0.0
    return True, t, u, v


@njit(cache=True, inline="always")
def _ray_box(o, d, lo, hi, node, tmax):  # pragma: no cover - numba
    """Entry parameter of the ray ``o + t d`` (t in [0, tmax]) into the node's box, -1 if it misses.

    The exit is widened by a relative 1e-10 so that round-off never drops a box a hit lies in.
    """
    t0 = 0.0
    t1 = tmax
    for k in range(3):
        if d[k] == 0.0:
            if o[k] < lo[node, k] or o[k] > hi[node, k]:
                return -1.0
        else:
            inv = 1.0 / d[k]
            ta = (lo[node, k] - o[k]) * inv
            tb = (hi[node, k] - o[k]) * inv
            if ta > tb:
                ta, tb = tb, ta
            if ta > t0:
                t0 = ta
            if tb < t1:
                t1 = tb
            if t0 > t1 + 1e-10 * abs(t1):
                return -1.0
    return t0


@njit(cache=True)
def _ray_first_one(r, origins, directions, vertices, faces, order, lo, hi, left, right, start, count,
                   tout, fout, bout):  # pragma: no cover - numba
    """Nearest hit of ray ``r`` into row ``r`` of the outputs (body of :func:`bvh_ray_first`)."""
    o = origins[r]
    d = directions[r]
    best = np.inf
    bface = -1
    bu = 0.0
    bv = 0.0
    stack = np.empty(256, np.int64)
    sp = 0
    if _ray_box(o, d, lo, hi, 0, best) >= 0.0:
        stack[0] = 0
        sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if _ray_box(o, d, lo, hi, node, best) < 0.0:
            continue
        if left[node] < 0:
            for i in range(start[node], start[node] + count[node]):
                t = order[i]
                hit, th, u, v = ray_triangle(o, d, vertices[faces[t, 0]], vertices[faces[t, 1]],
                                             vertices[faces[t, 2]])
                if hit and (th < best or (th == best and t < bface)):
                    best = th
                    bface = t
                    bu = u
                    bv = v
        else:
            lc = left[node]
            rc = right[node]
            tl = _ray_box(o, d, lo, hi, lc, best)
            tr = _ray_box(o, d, lo, hi, rc, best)
            # the nearer child goes on top of the stack
            if tl >= 0.0 and tr >= 0.0:
                sp = _push_nearer_last(stack, sp, lc, rc, tl <= tr)
            elif tl >= 0.0:
                stack[sp] = lc
                sp += 1
            elif tr >= 0.0:
                stack[sp] = rc
                sp += 1
    if bface >= 0:
        tout[r] = best
        fout[r] = bface
        bout[r, 0] = 1.0 - bu - bv
        bout[r, 1] = bu
        bout[r, 2] = bv
    else:
        tout[r] = np.inf
        fout[r] = -1
        bout[r, 0] = np.nan
        bout[r, 1] = np.nan
        bout[r, 2] = np.nan


@njit(cache=True, parallel=True)
def bvh_ray_first(origins, directions, vertices, faces, order, lo, hi, left, right, start, count):  # pragma: no cover
    """Nearest hit of every ray: t (R,) (inf if none), face (R,) (-1), barycentrics (R,3) (NaN).

    Ties in ``t`` go to the lowest face index.
    """
    nr = origins.shape[0]
    tout = np.empty(nr)  # every row written by the body (np.full here would be a parfor)
    fout = np.empty(nr, np.int64)
    bout = np.empty((nr, 3))
    for r in prange(nr):
        _ray_first_one(np.int64(r), origins, directions, vertices, faces, order, lo, hi, left, right, start, count,
                       tout, fout, bout)
    return tout, fout, bout


@njit(cache=True)
def _ray_all(o, d, vertices, faces, order, lo, hi, left, right, start, count, tb, fb, bb, pos):  # pragma: no cover
    """Visit every hit of one ray; write them from ``pos`` when ``tb`` is non-empty; returns the count."""
    n = 0
    write = tb.shape[0] > 0
    stack = np.empty(256, np.int64)
    sp = 1
    stack[0] = 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if _ray_box(o, d, lo, hi, node, np.inf) < 0.0:
            continue
        if left[node] < 0:
            for i in range(start[node], start[node] + count[node]):
                t = order[i]
                hit, th, u, v = ray_triangle(o, d, vertices[faces[t, 0]], vertices[faces[t, 1]], vertices[faces[t, 2]])
                if hit:
                    if write:
                        tb[pos + n] = th
                        fb[pos + n] = t
                        bb[pos + n, 0] = 1.0 - u - v
                        bb[pos + n, 1] = u
                        bb[pos + n, 2] = v
                    n += 1
        else:
            stack[sp] = left[node]
            stack[sp + 1] = right[node]
            sp += 2
    return n


@njit(cache=True, parallel=True)
def bvh_ray_count(origins, directions, vertices, faces, order, lo, hi, left, right, start, count):  # pragma: no cover
    """Number of hits (R,) of every ray (all ``t >= 0``)."""
    nr = origins.shape[0]
    out = np.empty(nr, np.int64)  # every entry written (np.zeros would be a parfor)
    empty_t = np.empty(0)
    empty_f = np.empty(0, np.int64)
    empty_b = np.empty((0, 3))
    for r in prange(nr):
        out[r] = _ray_all(origins[r], directions[r], vertices, faces, order, lo, hi, left, right, start, count,
                          empty_t, empty_f, empty_b, np.int64(0))  # not a literal 0: one _ray_all
    return out


@njit(cache=True, parallel=True)
def bvh_ray_fill(origins, directions, vertices, faces, order, lo, hi, left, right, start, count, offsets):  # pragma: no cover
    """Every hit, ray by ray in tree order: t (H,), face (H,), barycentrics (H,3) at ``offsets`` (R+1,)."""
    nr = origins.shape[0]
    nh = offsets[nr]
    tb = np.empty(nh)
    fb = np.empty(nh, np.int64)
    bb = np.empty((nh, 3))
    for r in prange(nr):
        if offsets[r + 1] > offsets[r]:
            _ray_all(origins[r], directions[r], vertices, faces, order, lo, hi, left, right, start, count,
                     tb, fb, bb, offsets[r])
    return tb, fb, bb
