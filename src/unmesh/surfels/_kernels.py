"""Numba kernels of surfel sampling and estimation.

Each kernel has a plain numpy/Python reference that the tests compare against:

- :func:`ldc_count` / :func:`ldc_fill` (LDC ray-bundle sampling):
  ``unmesh.surfels.sampling.ldc_reference``.
- :func:`voronoi_radii` (tangent-plane Voronoi covering radius):
  ``unmesh.surfels.radii.voronoi_radii_reference``.
- :func:`neighbour_covariances`: ``unmesh.surfels.normals.covariance_reference``.
- :func:`smallest_eigenvectors`: ``numpy.linalg.eigh``.
- :func:`kruskal_forest`: ``scipy.sparse.csgraph.minimum_spanning_tree``.
- :func:`propagate_orientation`: ``unmesh.surfels.normals.propagate_reference``.
- :func:`cluster_split`: ``unmesh.surfels.simplify.cluster_reference``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh._csr_kernels import counting_sort_csr

# ---------------------------------------------------------------------------
# LDC sampling: rasterise every triangle into the ray lattice of one axis
# ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _less(au, av, bu, bv):  # pragma: no cover - numba
    """Lexicographic order of 2-D points (u first, then v)."""
    return au < bu or (au == bu and av < bv)


@njit(cache=True, inline="always")
def _edge(au, av, bu, bv, pu, pv):  # pragma: no cover - numba
    """Edge function of directed edge a->b at p, computed in a canonical vertex order.

    Returns ``(value, tie)``: ``value > 0`` left of a->b; bitwise ``-value`` for
    b->a. ``tie`` says whether a point exactly on the edge belongs to this side.
    """
    if _less(au, av, bu, bv):
        return (bu - au) * (pv - av) - (bv - av) * (pu - au), True
    return -((au - bu) * (pv - bv) - (av - bv) * (pu - bu)), False


@njit(cache=True, inline="always")
def _inside(e, tie):  # pragma: no cover - numba
    return e > 0.0 or (e == 0.0 and tie)


@njit(cache=True)
def _raster(vertices, faces, t, axis, inv_d, d, count_only, out_pos, out_face, out_bary, base):  # pragma: no cover
    """Hits of the rays along ``axis`` at lattice positions ``(i + 1/2) d`` with triangle ``t``."""
    ua = (axis + 1) % 3
    va = (axis + 2) % 3
    f0 = faces[t, 0]
    f1 = faces[t, 1]
    f2 = faces[t, 2]
    au = vertices[f0, ua]
    av = vertices[f0, va]
    bu = vertices[f1, ua]
    bv = vertices[f1, va]
    cu = vertices[f2, ua]
    cv = vertices[f2, va]
    area2 = (bu - au) * (cv - av) - (bv - av) * (cu - au)
    if area2 == 0.0 or not math.isfinite(area2):
        return 0
    i1 = f1
    i2 = f2
    if area2 < 0.0:  # make the projected triangle counter-clockwise
        bu, cu = cu, bu
        bv, cv = cv, bv
        i1, i2 = f2, f1
        area2 = -area2
    umin = min(au, bu, cu)
    umax = max(au, bu, cu)
    vmin = min(av, bv, cv)
    vmax = max(av, bv, cv)
    i_lo = math.ceil(umin * inv_d - 0.5) - 1
    i_hi = math.floor(umax * inv_d - 0.5) + 1
    j_lo = math.ceil(vmin * inv_d - 0.5) - 1
    j_hi = math.floor(vmax * inv_d - 0.5) + 1
    n = 0
    for i in range(i_lo, i_hi + 1):
        pu = (i + 0.5) * d
        if pu < umin or pu > umax:
            continue
        # Scanline: the v-range of the triangle on the line u = pu (slivers cost only their area);
        # widened by a cell on each side, the exact edge tests below decide.
        slo = vmax
        shi = vmin
        for e in range(3):
            if e == 0:
                eu0, ev0, eu1, ev1 = au, av, bu, bv
            elif e == 1:
                eu0, ev0, eu1, ev1 = bu, bv, cu, cv
            else:
                eu0, ev0, eu1, ev1 = cu, cv, au, av
            if min(eu0, eu1) <= pu <= max(eu0, eu1):
                if eu1 != eu0:
                    vv = ev0 + (pu - eu0) * (ev1 - ev0) / (eu1 - eu0)
                    slo = min(slo, vv)
                    shi = max(shi, vv)
                else:
                    slo = min(slo, ev0, ev1)
                    shi = max(shi, ev0, ev1)
        if slo > shi:
            continue
        jl = max(j_lo, math.ceil(slo * inv_d - 0.5) - 1)
        jh = min(j_hi, math.floor(shi * inv_d - 0.5) + 1)
        for j in range(jl, jh + 1):
            pv = (j + 0.5) * d
            if pv < vmin or pv > vmax:
                continue
            e0, t0 = _edge(bu, bv, cu, cv, pu, pv)  # opposite a
            if not _inside(e0, t0):
                continue
            e1, t1 = _edge(cu, cv, au, av, pu, pv)  # opposite b
            if not _inside(e1, t1):
                continue
            e2, t2 = _edge(au, av, bu, bv, pu, pv)  # opposite c
            if not _inside(e2, t2):
                continue
            if not count_only:
                s = e0 + e1 + e2
                if s <= 0.0:
                    s = area2
                b0 = e0 / s
                b1 = e1 / s
                b2 = e2 / s
                k = base + n
                w = b0 * vertices[f0, axis] + b1 * vertices[i1, axis] + b2 * vertices[i2, axis]
                out_pos[k, axis] = w
                out_pos[k, ua] = pu
                out_pos[k, va] = pv
                out_face[k] = t
                # Barycentrics in the face's own vertex order.
                out_bary[k, 0] = b0
                if i1 == f1:
                    out_bary[k, 1] = b1
                    out_bary[k, 2] = b2
                else:
                    out_bary[k, 1] = b2
                    out_bary[k, 2] = b1
            n += 1
    return n


@njit(cache=True, parallel=True)
def ldc_count(vertices, faces, f0, f1, axis, d):  # pragma: no cover - numba
    """Number of ray hits (f1-f0,) of each triangle in ``faces[f0:f1]`` for one ray bundle."""
    counts = np.zeros(f1 - f0, np.int64)
    dummy_p = np.empty((0, 3))
    dummy_f = np.empty(0, np.int64)
    dummy_b = np.empty((0, 3))
    inv_d = 1.0 / d
    for t in prange(f0, f1):
        counts[t - f0] = _raster(vertices, faces, t, axis, inv_d, d, True, dummy_p, dummy_f, dummy_b, 0)
    return counts


@njit(cache=True, parallel=True)
def ldc_fill(vertices, faces, f0, f1, axis, d, offsets):  # pragma: no cover - numba
    """Hit positions (H,3), faces (H,) and barycentrics (H,3); ``offsets`` from :func:`ldc_count`."""
    total = offsets[-1]
    pos = np.empty((total, 3))
    face = np.empty(total, np.int64)
    bary = np.empty((total, 3))
    inv_d = 1.0 / d
    for t in prange(f0, f1):
        _raster(vertices, faces, t, axis, inv_d, d, False, pos, face, bary, offsets[t - f0])
    return pos, face, bary


# ---------------------------------------------------------------------------
# Tangent-plane Voronoi radii
# ---------------------------------------------------------------------------

CLIP_SIDES = 16


@njit(cache=True)
def _clip(px, py, n, ax, ay, c, qx, qy):  # pragma: no cover - numba
    """Clip convex polygon (px, py)[:n] by the half-plane ax*x + ay*y <= c; result in (qx, qy)."""
    m = 0
    for s in range(n):
        e = (s + 1) % n
        fs = ax * px[s] + ay * py[s] - c
        fe = ax * px[e] + ay * py[e] - c
        if fs <= 0.0:
            qx[m] = px[s]
            qy[m] = py[s]
            m += 1
        if (fs < 0.0 < fe) or (fe < 0.0 < fs):
            t = fs / (fs - fe)
            qx[m] = px[s] + t * (px[e] - px[s])
            qy[m] = py[s] + t * (py[e] - py[s])
            m += 1
    return m


@njit(cache=True, parallel=True)
def voronoi_radii(points, normals, nbrs, clip, oriented, min_dot):  # pragma: no cover - numba
    """Farthest vertex distance (N,) of each point's restricted Voronoi cell in its tangent plane.

    The cell of point i is the set of points p of its tangent plane that are
    closer (in 3-D) to x_i than to each valid neighbour x_j: the half-planes
    ``q'_j . (p - x_i) <= |x_j - x_i|^2 / 2`` (q'_j = tangential part of
    x_j - x_i), intersected with the regular ``CLIP_SIDES``-gon of inradius
    ``clip[i]``. Neighbours ``nbrs[i]`` (-1 = padding) count unless coincident or
    ``n_i . n_j <= min_dot`` (``|n_i . n_j|`` when not ``oriented``). Also returns
    whether the final cell touches the clip polygon (the cell is open there).
    """
    n = points.shape[0]
    kk = nbrs.shape[1]
    out = np.empty(n)
    opened = np.zeros(n, np.bool_)
    cap = CLIP_SIDES + kk + 4
    for i in prange(n):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        # tangent frame (same construction as unmesh.surfels.cloud.tangent_frame)
        anx, any_, anz = abs(nx), abs(ny), abs(nz)
        hx, hy, hz = 0.0, 0.0, 0.0
        if anx <= any_ and anx <= anz:
            hx = 1.0
        elif any_ <= anz:
            hy = 1.0
        else:
            hz = 1.0
        t1x = hy * nz - hz * ny
        t1y = hz * nx - hx * nz
        t1z = hx * ny - hy * nx
        ln = math.sqrt(t1x * t1x + t1y * t1y + t1z * t1z)
        t1x /= ln
        t1y /= ln
        t1z /= ln
        t2x = ny * t1z - nz * t1y
        t2y = nz * t1x - nx * t1z
        t2z = nx * t1y - ny * t1x
        px = np.empty(cap)
        py = np.empty(cap)
        qx = np.empty(cap)
        qy = np.empty(cap)
        rho = clip[i]
        rv = rho / math.cos(math.pi / CLIP_SIDES)
        for s in range(CLIP_SIDES):
            ang = 2.0 * math.pi * (s + 0.5) / CLIP_SIDES
            px[s] = rv * math.cos(ang)
            py[s] = rv * math.sin(ang)
        m = CLIP_SIDES
        for a in range(kk):
            j = nbrs[i, a]
            if j < 0 or j == i:
                continue
            dx = points[j, 0] - points[i, 0]
            dy = points[j, 1] - points[i, 1]
            dz = points[j, 2] - points[i, 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dist <= 1e-12 * rho:
                continue
            dn = nx * normals[j, 0] + ny * normals[j, 1] + nz * normals[j, 2]
            if not oriented:
                dn = abs(dn)
            if dn <= min_dot:
                continue
            u = dx * t1x + dy * t1y + dz * t1z
            v = dx * t2x + dy * t2y + dz * t2z
            if u * u + v * v <= 1e-24 * dist * dist:
                continue  # straight above or below: no constraint in this plane
            c = 0.5 * dist * dist
            m = _clip(px, py, m, u, v, c, qx, qy)
            px, qx = qx, px
            py, qy = qy, py
            if m == 0:
                break
        best = 0.0
        touch = False
        for s in range(m):
            r2 = px[s] * px[s] + py[s] * py[s]
            if r2 > best:
                best = r2
            # on the clip polygon boundary?
            for e in range(CLIP_SIDES):
                ang = 2.0 * math.pi * e / CLIP_SIDES
                if px[s] * math.cos(ang) + py[s] * math.sin(ang) >= rho * (1.0 - 1e-9):
                    touch = True
        out[i] = math.sqrt(best)
        opened[i] = touch
    return out, opened


# ---------------------------------------------------------------------------
# Normals: neighbourhood covariance and MST orientation propagation
# ---------------------------------------------------------------------------


@njit(cache=True, parallel=True)
def neighbour_covariances(points, nbrs):  # pragma: no cover - numba
    """Covariance (N,3,3) of each point's neighbours ``nbrs`` (N,K) (-1 = padding) about their mean."""
    n = points.shape[0]
    kk = nbrs.shape[1]
    cov = np.zeros((n, 3, 3))
    for i in prange(n):
        mx = 0.0
        my = 0.0
        mz = 0.0
        cnt = 0
        for a in range(kk):
            j = nbrs[i, a]
            if j < 0:
                continue
            mx += points[j, 0]
            my += points[j, 1]
            mz += points[j, 2]
            cnt += 1
        if cnt == 0:
            continue
        mx /= cnt
        my /= cnt
        mz /= cnt
        for a in range(kk):
            j = nbrs[i, a]
            if j < 0:
                continue
            d0 = points[j, 0] - mx
            d1 = points[j, 1] - my
            d2 = points[j, 2] - mz
            cov[i, 0, 0] += d0 * d0
            cov[i, 0, 1] += d0 * d1
            cov[i, 0, 2] += d0 * d2
            cov[i, 1, 1] += d1 * d1
            cov[i, 1, 2] += d1 * d2
            cov[i, 2, 2] += d2 * d2
        for r in range(3):
            for c in range(r, 3):
                cov[i, r, c] /= cnt
                cov[i, c, r] = cov[i, r, c]
    return cov


@njit(cache=True)
def smallest_eigenvector(a00, a01, a02, a11, a12, a22):  # pragma: no cover - numba
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (upper triangle).

    Closed-form eigenvalues (trigonometric solution of the characteristic cubic) of the
    matrix scaled to unit max-norm, then the eigenvector as the largest cross product of two
    rows of ``A - l I``. Where that eigenspace is more than one-dimensional any unit vector in
    it is returned; the zero matrix gives ``(0, 0, 1)``. Shared by normal estimation, MLS
    (3.5) and shell skinning (7.26). Reference: ``numpy.linalg.eigh``.
    """
    s = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    if s == 0.0:
        return 0.0, 0.0, 1.0
    a00 /= s
    a01 /= s
    a02 /= s
    a11 /= s
    a12 /= s
    a22 /= s
    m = (a00 + a11 + a22) / 3.0
    k00 = a00 - m
    k11 = a11 - m
    k22 = a22 - m
    p = (k00 * k00 + k11 * k11 + k22 * k22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0
    q = 0.5 * (k00 * (k11 * k22 - a12 * a12) - a01 * (a01 * k22 - a12 * a02) + a02 * (a01 * a12 - k11 * a02))
    sp = math.sqrt(max(p, 0.0))
    phi = math.atan2(math.sqrt(max(p * p * p - q * q, 0.0)), q) / 3.0
    lam = m + 2.0 * sp * math.cos(phi + 2.0 * math.pi / 3.0)
    r0x, r0y, r0z = a00 - lam, a01, a02
    r1x, r1y, r1z = a01, a11 - lam, a12
    r2x, r2y, r2z = a02, a12, a22 - lam
    c0x = r0y * r1z - r0z * r1y
    c0y = r0z * r1x - r0x * r1z
    c0z = r0x * r1y - r0y * r1x
    c1x = r0y * r2z - r0z * r2y
    c1y = r0z * r2x - r0x * r2z
    c1z = r0x * r2y - r0y * r2x
    c2x = r1y * r2z - r1z * r2y
    c2y = r1z * r2x - r1x * r2z
    c2z = r1x * r2y - r1y * r2x
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    l0 = r0x * r0x + r0y * r0y + r0z * r0z
    l1 = r1x * r1x + r1y * r1y + r1z * r1z
    l2 = r2x * r2x + r2y * r2y + r2z * r2z
    lmax = max(l0, l1, l2)
    # |cross| <= 1e-6 |row|^2: the rows are parallel (a repeated smallest eigenvalue).
    tiny = 1e-12 * lmax * lmax + 1e-300
    if n0 >= n1 and n0 >= n2 and n0 > tiny:
        vx, vy, vz, nn = c0x, c0y, c0z, n0
    elif n1 >= n2 and n1 > tiny:
        vx, vy, vz, nn = c1x, c1y, c1z, n1
    elif n2 > tiny:
        vx, vy, vz, nn = c2x, c2y, c2z, n2
    else:
        # rank <= 1: any vector orthogonal to the largest row of A - l I
        if l0 >= l1 and l0 >= l2:
            bx, by, bz, bl = r0x, r0y, r0z, l0
        elif l1 >= l2:
            bx, by, bz, bl = r1x, r1y, r1z, l1
        else:
            bx, by, bz, bl = r2x, r2y, r2z, l2
        if bl <= 1e-30:
            return 0.0, 0.0, 1.0
        if abs(bx) <= abs(by) and abs(bx) <= abs(bz):
            vx, vy, vz = 0.0, -bz, by
        elif abs(by) <= abs(bz):
            vx, vy, vz = bz, 0.0, -bx
        else:
            vx, vy, vz = -by, bx, 0.0
        nn = vx * vx + vy * vy + vz * vz
    inv = 1.0 / math.sqrt(nn)
    return vx * inv, vy * inv, vz * inv


@njit(cache=True, parallel=True)
def smallest_eigenvectors(cov):  # pragma: no cover - numba
    """Unit eigenvector (N,3) of the smallest eigenvalue of each symmetric 3x3 matrix (N,3,3)
    (:func:`smallest_eigenvector` per matrix). Reference: ``numpy.linalg.eigh``.
    """
    n = cov.shape[0]
    out = np.empty((n, 3))
    for i in prange(n):
        c = cov[i]
        vx, vy, vz = smallest_eigenvector(c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2])
        out[i, 0] = vx
        out[i, 1] = vy
        out[i, 2] = vz
    return out


@njit(cache=True)
def propagate_orientation(points, normals, order, parent, min_dot):  # pragma: no cover - numba
    """Flip normals in tree order so each agrees with its parent; in place.

    Where ``|n_i . n_p| >= min_dot`` the child agrees when ``n_i . n_p > 0``. Across
    sharp edges (normals nearly perpendicular) the dot product says nothing; there
    the child agrees when each point lies on the same side of the other's tangent
    plane, ``(n_p . d) (n_i . -d) > 0`` with ``d = x_i - x_p`` (below each other's
    plane at a convex edge, above at a concave one); this test also holds on
    smooth surfaces, where both offsets are ``-kappa |d|^2 / 2``.
    """
    for a in range(order.shape[0]):
        i = order[a]
        p = parent[i]
        if p < 0:
            continue
        dot = normals[i, 0] * normals[p, 0] + normals[i, 1] * normals[p, 1] + normals[i, 2] * normals[p, 2]
        agree = dot >= 0.0
        if abs(dot) < min_dot:
            d0 = points[i, 0] - points[p, 0]
            d1 = points[i, 1] - points[p, 1]
            d2 = points[i, 2] - points[p, 2]
            hp = normals[p, 0] * d0 + normals[p, 1] * d1 + normals[p, 2] * d2
            hi = -(normals[i, 0] * d0 + normals[i, 1] * d1 + normals[i, 2] * d2)
            prod = hp * hi
            if prod != 0.0:
                agree = prod > 0.0
        if not agree:
            normals[i, 0] = -normals[i, 0]
            normals[i, 1] = -normals[i, 1]
            normals[i, 2] = -normals[i, 2]
    return normals


@njit(cache=True)
def _find(parent, i):  # pragma: no cover - numba
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def kruskal_forest(n, a, b, order):  # pragma: no cover - numba
    """Minimum spanning forest (Kruskal) of the graph with edges ``(a[e], b[e])`` visited in
    ``order`` (ascending weight). Returns the forest's edges ``(ta, tb)``. Reference:
    ``scipy.sparse.csgraph.minimum_spanning_tree`` (same total weight)."""
    parent = np.arange(n)
    size = np.ones(n, np.int64)
    ta = np.empty(max(n - 1, 0), np.int64)
    tb = np.empty(max(n - 1, 0), np.int64)
    m = 0
    for e in order:
        ra = _find(parent, a[e])
        rb = _find(parent, b[e])
        if ra == rb:
            continue
        if size[ra] < size[rb]:
            ra, rb = rb, ra
        parent[rb] = ra
        size[ra] += size[rb]
        ta[m] = a[e]
        tb[m] = b[e]
        m += 1
        if m == n - 1:
            break
    return ta[:m].copy(), tb[:m].copy()


@njit(cache=True)
def forest_bfs(n, ta, tb, seeds):  # pragma: no cover - numba
    """Breadth-first order (N,) and parents (N,) (-1 at roots) of a forest.

    Each tree is entered at its vertex listed first in ``seeds`` (a permutation of
    all vertices, preferred roots first). Also returns the component label (N,).
    """
    m = ta.shape[0]
    ends = np.empty(2 * m, np.int64)     # edge e as the entries 2e (at ta[e]) and 2e + 1 (at tb[e])
    other = np.empty(2 * m, np.int64)
    for e in range(m):
        ends[2 * e] = ta[e]
        ends[2 * e + 1] = tb[e]
        other[2 * e] = tb[e]
        other[2 * e + 1] = ta[e]
    slot, deg = counting_sort_csr(ends, n)
    adj = other[slot]
    order = np.empty(n, np.int64)
    parent = -np.ones(n, np.int64)
    comp = -np.ones(n, np.int64)
    head = 0
    tail = 0
    c = 0
    for s in seeds:
        if comp[s] >= 0:
            continue
        comp[s] = c
        order[tail] = s
        tail += 1
        while head < tail:
            i = order[head]
            head += 1
            for q in range(deg[i], deg[i + 1]):
                j = adj[q]
                if comp[j] < 0:
                    comp[j] = c
                    parent[j] = i
                    order[tail] = j
                    tail += 1
        c += 1
    return order, parent, comp


# ---------------------------------------------------------------------------
# Hierarchical clustering (Pauly, Gross, Kobbelt 2002)
# ---------------------------------------------------------------------------


#: Priority factor of clusters whose normals spread over more than 90 degrees (target mode).
SPREAD_WEIGHT = 4.0
#: A split by normal direction must leave at least this fraction of the points on each side.
MIN_NORMAL_SHARE = 0.1


@njit(cache=True)
def _cluster_stats(points, normals, use_normals, perm, s0, s1):  # pragma: no cover - numba
    """Statistics of the cluster ``perm[s0:s1]``.

    Returns the largest covariance eigenvalue, the split direction, the surface
    variation ``l0 / (l0 + l1 + l2)``, the centroid and whether the normal cone is
    wider than 90 degrees (``spread``). The split direction is the largest
    eigenvector of the position covariance, or for a spread cluster the largest
    eigenvector of the normals' second moment ``sum n n^T`` (the split then goes by
    the sign of ``n . axis``, which separates the two sides of a thin part).
    Directions have a canonical sign (largest component positive).
    """
    n = s1 - s0
    c = np.zeros(3)
    for a in range(s0, s1):
        for k in range(3):
            c[k] += points[perm[a], k]
    c /= n
    cov = np.zeros((3, 3))
    for a in range(s0, s1):
        d = points[perm[a]] - c
        for r in range(3):
            for q in range(3):
                cov[r, q] += d[r] * d[q]
    cov /= n
    w, v = np.linalg.eigh(cov)
    tot = w[0] + w[1] + w[2]
    var = w[0] / tot if tot > 0.0 else 0.0
    axis = v[:, 2].copy()
    spread = False
    if use_normals:
        m = np.zeros(3)
        for a in range(s0, s1):
            m += normals[perm[a]]
        lm = math.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
        if lm <= 0.0:
            spread = True
        else:
            m /= lm
            for a in range(s0, s1):
                j = perm[a]
                if normals[j, 0] * m[0] + normals[j, 1] * m[1] + normals[j, 2] * m[2] < 0.0:
                    spread = True
                    break
        if spread:
            nn = np.zeros((3, 3))
            for a in range(s0, s1):
                j = perm[a]
                for r in range(3):
                    for q in range(3):
                        nn[r, q] += normals[j, r] * normals[j, q]
            _, vn = np.linalg.eigh(nn)
            axis = vn[:, 2].copy()
    big = 0
    for k in range(1, 3):
        if abs(axis[k]) > abs(axis[big]):
            big = k
    if axis[big] < 0.0:  # canonical sign: the split does not depend on the eigen-solver's sign choice
        axis = -axis
    return max(w[2], 0.0), axis, var, c, spread


@njit(cache=True)
def _side(points, normals, j, c, axis, by_normal):  # pragma: no cover - numba
    if by_normal:
        return normals[j, 0] * axis[0] + normals[j, 1] * axis[1] + normals[j, 2] * axis[2] <= 0.0
    return (points[j, 0] - c[0]) * axis[0] + (points[j, 1] - c[1]) * axis[1] + (points[j, 2] - c[2]) * axis[2] <= 0.0


@njit(cache=True)
def _split(points, normals, perm, s0, s1, axis, c, by_normal, tmp):  # pragma: no cover - numba
    """Stable partition of ``perm[s0:s1]`` by :func:`_side`; returns the cut index.

    A split by normal that leaves less than ``MIN_NORMAL_SHARE`` of the points on
    one side is replaced by the position split (plane through ``c`` normal to the
    largest covariance eigenvector, recomputed here).
    """
    n = s1 - s0
    left = 0
    for a in range(s0, s1):
        if _side(points, normals, perm[a], c, axis, by_normal):
            left += 1
    if by_normal and min(left, n - left) < MIN_NORMAL_SHARE * n:
        _, axis, _, c, _ = _cluster_stats(points, normals, False, perm, s0, s1)
        by_normal = False
    left = 0
    for a in range(s0, s1):
        j = perm[a]
        if _side(points, normals, j, c, axis, by_normal):
            tmp[left] = j
            left += 1
    right = left
    for a in range(s0, s1):
        j = perm[a]
        if not _side(points, normals, j, c, axis, by_normal):
            tmp[right] = j
            right += 1
    if left == 0 or left == n:
        # Degenerate (coincident points): split by projection order at the median.
        proj = np.empty(n)
        for a in range(n):
            j = perm[s0 + a]
            proj[a] = points[j, 0] * axis[0] + points[j, 1] * axis[1] + points[j, 2] * axis[2]
        o = np.argsort(proj, kind="mergesort")
        for a in range(n):
            tmp[a] = perm[s0 + o[a]]
        left = n // 2
    for a in range(n):
        perm[s0 + a] = tmp[a]
    return s0 + left


@njit(cache=True)
def _heap_push(keys, ids, size, key, ident):  # pragma: no cover - numba
    i = size
    keys[i] = key
    ids[i] = ident
    while i > 0:
        p = (i - 1) // 2
        # max-heap on key; ties: smaller id first
        if keys[p] > keys[i] or (keys[p] == keys[i] and ids[p] < ids[i]):
            break
        keys[p], keys[i] = keys[i], keys[p]
        ids[p], ids[i] = ids[i], ids[p]
        i = p
    return size + 1


@njit(cache=True)
def _heap_pop(keys, ids, size):  # pragma: no cover - numba
    top = ids[0]
    size -= 1
    keys[0] = keys[size]
    ids[0] = ids[size]
    i = 0
    while True:
        lft = 2 * i + 1
        rgt = lft + 1
        best = i
        if lft < size and (keys[lft] > keys[best] or (keys[lft] == keys[best] and ids[lft] < ids[best])):
            best = lft
        if rgt < size and (keys[rgt] > keys[best] or (keys[rgt] == keys[best] and ids[rgt] < ids[best])):
            best = rgt
        if best == i:
            break
        keys[best], keys[i] = keys[i], keys[best]
        ids[best], ids[i] = ids[i], ids[best]
        i = best
    return top, size


@njit(cache=True)
def cluster_split(points, normals, use_normals, target, max_size, max_variation):  # pragma: no cover - numba
    """Recursive covariance splitting; returns ``perm`` (N,) and cluster ranges ``starts``, ``ends`` (K,).

    With ``target > 0`` the cluster with the highest priority (largest covariance
    eigenvalue times the point count, i.e. the scatter along the principal axis,
    times ``SPREAD_WEIGHT`` when the normal cone is wider than 90 degrees; ties by
    creation order) is split until there are ``target`` clusters. Otherwise every
    cluster with more than ``max_size`` points, surface variation above
    ``max_variation`` or (with normals) a normal cone wider than 90 degrees is
    split (``max_size <= 0`` / ``max_variation < 0`` disable a criterion).
    """
    n = points.shape[0]
    perm = np.arange(n)
    tmp = np.empty(n, np.int64)
    starts = np.empty(max(n, 1), np.int64)
    ends = np.empty(max(n, 1), np.int64)
    starts[0] = 0
    ends[0] = n
    count = 1
    if target > 0:
        keys = np.empty(max(n, 1))
        ids = np.empty(max(n, 1), np.int64)
        lam0, _, _, _, spread0 = _cluster_stats(points, normals, use_normals, perm, 0, n)
        size = 0
        key = lam0 * n * (SPREAD_WEIGHT if spread0 else 1.0) if n > 1 else -1.0
        size = _heap_push(keys, ids, size, key, 0)
        while count < target and size > 0:
            cid, size = _heap_pop(keys, ids, size)
            s0 = starts[cid]
            s1 = ends[cid]
            _, axis, _, c, spread = _cluster_stats(points, normals, use_normals, perm, s0, s1)
            cut = _split(points, normals, perm, s0, s1, axis, c, spread, tmp)
            ends[cid] = cut
            starts[count] = cut
            ends[count] = s1
            new = count
            count += 1
            for k in (cid, new):
                a0 = starts[k]
                a1 = ends[k]
                if a1 - a0 > 1:
                    lam, _, _, _, spread = _cluster_stats(points, normals, use_normals, perm, a0, a1)
                    key = lam * (a1 - a0) * (SPREAD_WEIGHT if spread else 1.0)
                else:
                    key = -1.0
                size = _heap_push(keys, ids, size, key, k)
    else:
        stack = np.empty(max(n, 1), np.int64)
        sp = 1
        stack[0] = 0
        while sp > 0:
            sp -= 1
            cid = stack[sp]
            s0 = starts[cid]
            s1 = ends[cid]
            if s1 - s0 < 2:
                continue
            _, axis, var, c, spread = _cluster_stats(points, normals, use_normals, perm, s0, s1)
            need = (max_size > 0 and s1 - s0 > max_size) or (max_variation >= 0.0 and var > max_variation) or spread
            if not need:
                continue
            cut = _split(points, normals, perm, s0, s1, axis, c, spread, tmp)
            ends[cid] = cut
            starts[count] = cut
            ends[count] = s1
            stack[sp] = cid
            stack[sp + 1] = count
            sp += 2
            count += 1
    return perm, starts[:count].copy(), ends[:count].copy()
