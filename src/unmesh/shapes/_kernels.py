"""Numba kernels of the procedural shapes.

- :func:`blob_eval`: the blob's smooth-union implicit function and unit gradient
  (numpy reference: ``unmesh.shapes.blob._blob_unit``).
- A bounding volume hierarchy over triangles (:func:`bvh_build`) with exact
  closest-point queries (:func:`bvh_closest`) and fast generalized winding numbers
  (:func:`bvh_winding`; Barill et al. 2018: exact solid angles of nearby
  triangles, first-order dipole expansion of distant clusters). Numpy references:
  ``closest_point_reference`` and ``winding_reference`` in ``unmesh.shapes.mesh_shape``.
- :func:`greedy_poisson`: maximal Poisson-disk selection from candidate neighbour
  lists (Python reference in ``unmesh.shapes._sampling``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# ---------------------------------------------------------------------------
# Blob
# ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _ellipsoid(points, a, centers, semi, rots, amin, k):  # pragma: no cover - numba
    """g_k = amin_k (|u| - 1) with u = Q_k^T (x - c_k) / semi_k; returns (g, |u|, u0, u1, u2)."""
    d0 = points[a, 0] - centers[k, 0]
    d1 = points[a, 1] - centers[k, 1]
    d2 = points[a, 2] - centers[k, 2]
    u0 = (rots[k, 0, 0] * d0 + rots[k, 1, 0] * d1 + rots[k, 2, 0] * d2) / semi[k, 0]
    u1 = (rots[k, 0, 1] * d0 + rots[k, 1, 1] * d1 + rots[k, 2, 1] * d2) / semi[k, 1]
    u2 = (rots[k, 0, 2] * d0 + rots[k, 1, 2] * d1 + rots[k, 2, 2] * d2) / semi[k, 2]
    nu = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    return amin[k] * (nu - 1.0), nu, u0, u1, u2


@njit(cache=True, parallel=True)
def blob_eval(points, centers, semi, rots, amin, blend):  # pragma: no cover - numba
    """Smooth union ``-k log sum exp(-g_i / k)`` of ellipsoid functions; values (N,), unit gradients (N,3)."""
    n = points.shape[0]
    kk = centers.shape[0]
    values = np.empty(n)
    normals = np.empty((n, 3))
    for a in prange(n):
        m = np.inf
        for k in range(kk):
            g, _, _, _, _ = _ellipsoid(points, a, centers, semi, rots, amin, k)
            if g < m:
                m = g
        ssum = 0.0
        gx = 0.0
        gy = 0.0
        gz = 0.0
        for k in range(kk):
            g, nu, u0, u1, u2 = _ellipsoid(points, a, centers, semi, rots, amin, k)
            w = math.exp(-(g - m) / blend)
            ssum += w
            safe = nu if nu > 0.0 else 1.0
            l0 = amin[k] * u0 / semi[k, 0] / safe
            l1 = amin[k] * u1 / semi[k, 1] / safe
            l2 = amin[k] * u2 / semi[k, 2] / safe
            gx += w * (rots[k, 0, 0] * l0 + rots[k, 0, 1] * l1 + rots[k, 0, 2] * l2)
            gy += w * (rots[k, 1, 0] * l0 + rots[k, 1, 1] * l1 + rots[k, 1, 2] * l2)
            gz += w * (rots[k, 2, 0] * l0 + rots[k, 2, 1] * l1 + rots[k, 2, 2] * l2)
        values[a] = m - blend * math.log(ssum)
        norm = math.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 0.0:
            normals[a, 0] = gx / norm
            normals[a, 1] = gy / norm
            normals[a, 2] = gz / norm
        else:
            normals[a, 0] = 0.0
            normals[a, 1] = 1.0
            normals[a, 2] = 0.0
    return values, normals


# ---------------------------------------------------------------------------
# Triangle BVH
# ---------------------------------------------------------------------------

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
def closest_on_triangle(p, a, b, c):  # pragma: no cover - numba
    """Closest point (3,) on triangle abc to p (Ericson, Real-Time Collision Detection 5.1.5)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = _dot(ab[0], ab[1], ab[2], ap[0], ap[1], ap[2])
    d2 = _dot(ac[0], ac[1], ac[2], ap[0], ap[1], ap[2])
    if d1 <= 0.0 and d2 <= 0.0:
        return a.copy()
    bp = p - b
    d3 = _dot(ab[0], ab[1], ab[2], bp[0], bp[1], bp[2])
    d4 = _dot(ac[0], ac[1], ac[2], bp[0], bp[1], bp[2])
    if d3 >= 0.0 and d4 <= d3:
        return b.copy()
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a + v * ab
    cp = p - c
    d5 = _dot(ab[0], ab[1], ab[2], cp[0], cp[1], cp[2])
    d6 = _dot(ac[0], ac[1], ac[2], cp[0], cp[1], cp[2])
    if d6 >= 0.0 and d5 <= d6:
        return c.copy()
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a + w * ac
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b + w * (c - b)
    denom = va + vb + vc
    if denom == 0.0:  # degenerate triangle: fall back to the closest edge point
        best = a.copy()
        bd = np.inf
        for e0, e1 in ((a, b), (b, c), (c, a)):
            e = e1 - e0
            ee = _dot(e[0], e[1], e[2], e[0], e[1], e[2])
            t = 0.0
            if ee > 0.0:
                q = p - e0
                t = min(1.0, max(0.0, _dot(q[0], q[1], q[2], e[0], e[1], e[2]) / ee))
            x = e0 + t * e
            dx = p - x
            dd = _dot(dx[0], dx[1], dx[2], dx[0], dx[1], dx[2])
            if dd < bd:
                bd = dd
                best = x
        return best
    v = vb / denom
    w = vc / denom
    return a + ab * v + ac * w


@njit(cache=True, parallel=True)
def bvh_closest(queries, vertices, faces, order, lo, hi, left, right, start, count):  # pragma: no cover - numba
    """Closest point on the mesh: distances (Q,), points (Q,3), face index (Q,)."""
    nq = queries.shape[0]
    dist = np.empty(nq)
    pts = np.empty((nq, 3))
    face = np.empty(nq, np.int64)
    for qi in prange(nq):
        p = queries[qi].copy()
        best = np.inf
        bface = -1
        bp = np.zeros(3)
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
                    x = closest_on_triangle(p, vertices[faces[t, 0]], vertices[faces[t, 1]], vertices[faces[t, 2]])
                    dd = (x[0] - p[0]) ** 2 + (x[1] - p[1]) ** 2 + (x[2] - p[2]) ** 2
                    if dd < best or (dd == best and t < bface):
                        best = dd
                        bface = t
                        bp[:] = x
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
                if dl <= dr:
                    stack[sp] = rc
                    stack[sp + 1] = lc
                else:
                    stack[sp] = lc
                    stack[sp + 1] = rc
                sp += 2
        dist[qi] = math.sqrt(best)
        pts[qi] = bp
        face[qi] = bface
    return dist, pts, face


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
    return out


# ---------------------------------------------------------------------------
# Poisson-disk selection
# ---------------------------------------------------------------------------


@njit(cache=True)
def greedy_poisson(order, offsets, indices):  # pragma: no cover - numba
    """Visit candidates in ``order``; keep one unless a kept candidate is its neighbour.

    ``offsets/indices`` is the CSR list of candidates within the disk radius.
    Returns a boolean keep mask (N,): kept points are pairwise farther apart than
    the radius, and every candidate is within the radius of a kept one (maximal).
    """
    n = offsets.shape[0] - 1
    keep = np.zeros(n, np.bool_)
    blocked = np.zeros(n, np.bool_)
    for a in range(order.shape[0]):
        i = order[a]
        if blocked[i]:
            continue
        keep[i] = True
        for s in range(offsets[i], offsets[i + 1]):
            blocked[indices[s]] = True
    return keep
