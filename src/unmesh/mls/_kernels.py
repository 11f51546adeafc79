"""Numba kernels of the MLS surface (thesis section 3.1).

All kernels work on the samples sorted by cell of an :class:`unmesh.spatial.CellGrid`
whose cell edge is the largest kernel support ``cutoff·max σ_i``, so the 27-cell
stencil of a point holds every sample whose kernel reaches it. Arrays:

``gp`` (N,3) positions, ``gn`` (N,3) unit normals, ``gs`` (N,) kernel widths σ_i,
``grho`` (N,) disc radii for ray starts, all in grid order; ``origin``, ``inv_cell``,
``cell``, ``dims``, ``cell_keys``, ``cell_start`` from the grid.

Options (integers so that they can be passed to numba):
``kernel`` 0 = clipped Gaussian (3.11), 1 = Wendland C² (3.12) with support
``cutoff·σ_i``; ``normal_mode`` 0 = Hermite normal (3.8), 1 = covariance normal
(3.5); ``degree`` 1 = plane only (3.7), 2 = plus a quadratic height field (3.3, 3.4).

The local fit at a point x (:func:`local_fit`) writes into ``res``:
``res[0:3]`` foot point p, ``res[3:6]`` unit normal n, ``res[6:9]`` weighted mean
q (3.6), ``res[9]`` weight sum, ``res[10]`` mean σ of the neighbours, ``res[11]``
neighbour count. ``p − x`` is parallel to ``n``.

The plain numpy reference implementation is ``tests/mls/reference.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.kernels._kernels import clipped_gaussian_w, wendland_c2_w
from unmesh.spatial._kernels import find_cell, point_cell, stencil_ranges

#: Status codes of :func:`project_kernel`.
CONVERGED, NOT_CONVERGED, NO_NEIGHBORS, LOST = 0, 1, 2, 3

_BLOCK = 64  # queries per parallel work item (work arrays are allocated per item)
_CAP = 1024  # neighbour buffer of a local fit


@njit(cache=True)
def _weight(d2, s, cutoff, kernel):
    if kernel == 0:
        return clipped_gaussian_w(d2, s, cutoff)
    return wendland_c2_w(math.sqrt(d2), cutoff * s)


@njit(cache=True)
def tangent_frame(nx, ny, nz):
    """Orthonormal tangents t1, t2 with t1 × t2 = n (Duff et al. 2017, branchless)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@njit(cache=True)
def smallest_eigenvector(a00, a01, a02, a11, a12, a22):
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix."""
    scale = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    if scale <= 0.0:
        return 0.0, 0.0, 1.0
    a00 /= scale
    a01 /= scale
    a02 /= scale
    a11 /= scale
    a12 /= scale
    a22 /= scale
    # closed-form eigenvalues (trigonometric method)
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    qm = (a00 + a11 + a22) / 3.0
    p2 = (a00 - qm) ** 2 + (a11 - qm) ** 2 + (a22 - qm) ** 2 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    if p < 1e-300:
        return 0.0, 0.0, 1.0
    b00 = (a00 - qm) / p
    b11 = (a11 - qm) / p
    b22 = (a22 - qm) / p
    b01 = a01 / p
    b02 = a02 / p
    b12 = a12 / p
    detb = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
    r = min(1.0, max(-1.0, detb / 2.0))
    phi = math.acos(r) / 3.0
    lam = qm + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)  # smallest
    # eigenvector: the largest cross product of two rows of (A - lam I)
    r0x, r0y, r0z = a00 - lam, a01, a02
    r1x, r1y, r1z = a01, a11 - lam, a12
    r2x, r2y, r2z = a02, a12, a22 - lam
    c0x, c0y, c0z = r0y * r1z - r0z * r1y, r0z * r1x - r0x * r1z, r0x * r1y - r0y * r1x
    c1x, c1y, c1z = r0y * r2z - r0z * r2y, r0z * r2x - r0x * r2z, r0x * r2y - r0y * r2x
    c2x, c2y, c2z = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    if n0 >= n1 and n0 >= n2:
        vx, vy, vz, nn = c0x, c0y, c0z, n0
    elif n1 >= n2:
        vx, vy, vz, nn = c1x, c1y, c1z, n1
    else:
        vx, vy, vz, nn = c2x, c2y, c2z, n2
    if nn < 1e-300:
        return 0.0, 0.0, 1.0
    inv = 1.0 / math.sqrt(nn)
    return vx * inv, vy * inv, vz * inv


@njit(cache=True)
def solve_spd(A, b, n):
    """Solve A x = b (n×n symmetric positive definite, upper triangle used) in place.

    Cholesky; returns False when a pivot is below 1e-12 of the largest diagonal
    entry (rank-deficient fit). ``b`` receives the solution.
    """
    dmax = 0.0
    for i in range(n):
        dmax = max(dmax, A[i, i])
    if dmax <= 0.0:
        return False
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[k, j] * A[k, j]
        if s <= 1e-12 * dmax:
            return False
        d = math.sqrt(s)
        A[j, j] = d
        for i in range(j + 1, n):
            t = A[j, i]
            for k in range(j):
                t -= A[k, j] * A[k, i]
            A[j, i] = t / d
    # forward: U^T y = b
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= A[k, i] * b[k]
        b[i] = t / A[i, i]
    # backward: U x = y
    for i in range(n - 1, -1, -1):
        t = b[i]
        for k in range(i + 1, n):
            t -= A[i, k] * b[k]
        b[i] = t / A[i, i]
    return True


@njit(cache=True, inline="always")
def _add_quad(A, rhs, gp, a, w, ox, oy, oz, nx, ny, nz, t1, t2, isl):
    """Add sample a with weight w to the normal equations of the quadratic height field."""
    rx = gp[a, 0] - ox
    ry = gp[a, 1] - oy
    rz = gp[a, 2] - oz
    u = (t1[0] * rx + t1[1] * ry + t1[2] * rz) * isl
    v = (t2[0] * rx + t2[1] * ry + t2[2] * rz) * isl
    z = nx * rx + ny * ry + nz * rz
    phi = (1.0, u, v, u * u, u * v, v * v)
    for r in range(6):
        wr = w * phi[r]
        rhs[r] += wr * z
        for c in range(r, 6):
            A[r, c] += wr * phi[c]


@njit(cache=True)
def local_fit(x, gp, gn, gs, cutoff, kernel, normal_mode, degree,
              origin, inv_cell, dims, cell_keys, cell_start, ranges, A, rhs, res, nbr, wbuf):
    """MLS fit at point ``x`` (3,): plane (3.5, 3.6, 3.8) and optional quadratic (3.3, 3.4).

    ``nbr`` (int64) and ``wbuf`` (float64) are work buffers of equal length for the
    neighbours and their weights; when they overflow the quadratic pass scans the
    stencil again. Returns False when no sample's kernel reaches ``x`` (or the
    normals cancel); otherwise fills ``res`` (see the module docstring).
    """
    cap = nbr.shape[0]
    x0, x1, x2 = x[0], x[1], x[2]
    i, j, k = point_cell(x, origin, inv_cell, dims)
    ns = stencil_ranges(i, j, k, 1, dims, cell_keys, cell_start, ranges)
    wsum = 0.0
    mx = my = mz = 0.0
    hx = hy = hz = 0.0
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    ssum = 0.0
    cnt = 0
    for s in range(ns):
        for a in range(ranges[s, 0], ranges[s, 1]):
            dx = gp[a, 0] - x0
            dy = gp[a, 1] - x1
            dz = gp[a, 2] - x2
            d2 = dx * dx + dy * dy + dz * dz
            sa = gs[a]
            w = _weight(d2, sa, cutoff, kernel)
            if w <= 0.0:
                continue
            if cnt < cap:
                nbr[cnt] = a
                wbuf[cnt] = w
            cnt += 1
            wsum += w
            mx += w * dx
            my += w * dy
            mz += w * dz
            hx += w * gn[a, 0]
            hy += w * gn[a, 1]
            hz += w * gn[a, 2]
            ssum += w * sa
            if normal_mode == 1:
                c00 += w * dx * dx
                c01 += w * dx * dy
                c02 += w * dx * dz
                c11 += w * dy * dy
                c12 += w * dy * dz
                c22 += w * dz * dz
    if cnt == 0 or not wsum > 0.0:
        return False
    inv = 1.0 / wsum
    mx *= inv  # q - x
    my *= inv
    mz *= inv
    hx *= inv
    hy *= inv
    hz *= inv
    sl = ssum * inv
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if normal_mode == 1:
        vx, vy, vz = smallest_eigenvector(c00 * inv - mx * mx, c01 * inv - mx * my, c02 * inv - mx * mz,
                                          c11 * inv - my * my, c12 * inv - my * mz, c22 * inv - mz * mz)
        if vx * hx + vy * hy + vz * hz < 0.0:
            vx, vy, vz = -vx, -vy, -vz
        nx, ny, nz = vx, vy, vz
    else:
        if hn < 1e-9:
            return False
        nx, ny, nz = hx / hn, hy / hn, hz / hn
    # projection of x onto the plane through q with normal N: o = x + (N.(q - x)) N
    dn = nx * mx + ny * my + nz * mz
    ox, oy, oz = x0 + dn * nx, x1 + dn * ny, x2 + dn * nz
    fa = 0.0
    fb = 0.0
    fc = 0.0
    if degree == 2 and cnt >= 6:
        t1, t2 = tangent_frame(nx, ny, nz)
        for r in range(6):
            rhs[r] = 0.0
            for c in range(6):
                A[r, c] = 0.0
        isl = 1.0 / sl
        if cnt <= cap:
            for m in range(cnt):
                _add_quad(A, rhs, gp, nbr[m], wbuf[m], ox, oy, oz, nx, ny, nz, t1, t2, isl)
        else:
            for s in range(ns):
                for a in range(ranges[s, 0], ranges[s, 1]):
                    dx = gp[a, 0] - x0
                    dy = gp[a, 1] - x1
                    dz = gp[a, 2] - x2
                    w = _weight(dx * dx + dy * dy + dz * dz, gs[a], cutoff, kernel)
                    if w > 0.0:
                        _add_quad(A, rhs, gp, a, w, ox, oy, oz, nx, ny, nz, t1, t2, isl)
        if solve_spd(A, rhs, 6):
            fa = rhs[0]
            fb = rhs[1] * isl
            fc = rhs[2] * isl
            # normal of the height field at the origin: N - f_u t1 - f_v t2
            px = nx - fb * t1[0] - fc * t2[0]
            py = ny - fb * t1[1] - fc * t2[1]
            pz = nz - fb * t1[2] - fc * t2[2]
            pn = 1.0 / math.sqrt(px * px + py * py + pz * pz)
            nx2, ny2, nz2 = px * pn, py * pn, pz * pn
        else:
            nx2, ny2, nz2 = nx, ny, nz
    else:
        nx2, ny2, nz2 = nx, ny, nz
    res[0] = ox + fa * nx
    res[1] = oy + fa * ny
    res[2] = oz + fa * nz
    res[3] = nx2
    res[4] = ny2
    res[5] = nz2
    res[6] = x0 + mx
    res[7] = x1 + my
    res[8] = x2 + mz
    res[9] = wsum
    res[10] = sl
    res[11] = cnt
    return True


@njit(cache=True, parallel=True)
def project_kernel(queries, gp, gn, gs, cutoff, kernel, normal_mode, degree,
                   origin, inv_cell, dims, cell_keys, cell_start, max_iter, tol,
                   out_p, out_n, status):
    """Iterated orthogonal projection of every query onto the MLS surface.

    Iteration: fit at y_k (foot p_k, normal n_k), then
    ``y_{k+1} = x − (n_k·(x − p_k)) n_k``; at the fixed point ``x − y ∥ n(y)`` and y
    lies on its own local fit (constraint 3.2 of Levin's definition).
    Stops when ``|y_{k+1} − y_k| <= tol·σ_local``. Writes NaN for queries that no
    kernel reaches.
    """
    nq = queries.shape[0]
    nblk = (nq + _BLOCK - 1) // _BLOCK
    for blk in prange(nblk):
        ranges = np.empty((9, 2), np.int64)
        A = np.empty((6, 6))
        rhs = np.empty(6)
        res = np.empty(12)
        nbr = np.empty(_CAP, np.int64)
        wbuf = np.empty(_CAP)
        y = np.empty(3)
        for qi in range(blk * _BLOCK, min(nq, (blk + 1) * _BLOCK)):
            x0, x1, x2 = queries[qi, 0], queries[qi, 1], queries[qi, 2]
            y[0] = x0
            y[1] = x1
            y[2] = x2
            st = NOT_CONVERGED
            nx = ny = nz = math.nan
            for it in range(max_iter):
                ok = local_fit(y, gp, gn, gs, cutoff, kernel, normal_mode, degree,
                               origin, inv_cell, dims, cell_keys, cell_start, ranges, A, rhs, res, nbr, wbuf)
                if not ok:
                    st = NO_NEIGHBORS if it == 0 else LOST
                    break
                nx, ny, nz = res[3], res[4], res[5]
                dist = nx * (x0 - res[0]) + ny * (x1 - res[1]) + nz * (x2 - res[2])
                y0, y1, y2 = x0 - dist * nx, x1 - dist * ny, x2 - dist * nz
                step = math.sqrt((y0 - y[0]) ** 2 + (y1 - y[1]) ** 2 + (y2 - y[2]) ** 2)
                y[0] = y0
                y[1] = y1
                y[2] = y2
                if step <= tol * res[10]:
                    st = CONVERGED
                    break
            status[qi] = st
            if st == NO_NEIGHBORS or st == LOST:
                for t in range(3):
                    out_p[qi, t] = math.nan
                    out_n[qi, t] = math.nan
            else:
                out_p[qi, 0] = y[0]
                out_p[qi, 1] = y[1]
                out_p[qi, 2] = y[2]
                out_n[qi, 0] = nx
                out_n[qi, 1] = ny
                out_n[qi, 2] = nz


@njit(cache=True, parallel=True)
def fit_kernel(queries, gp, gn, gs, cutoff, kernel, normal_mode, degree,
               origin, inv_cell, dims, cell_keys, cell_start, out):
    """One local fit per query (no iteration): ``out[i] = res`` (12 values), NaN if none."""
    nq = queries.shape[0]
    nblk = (nq + _BLOCK - 1) // _BLOCK
    for blk in prange(nblk):
        ranges = np.empty((9, 2), np.int64)
        A = np.empty((6, 6))
        rhs = np.empty(6)
        res = np.empty(12)
        nbr = np.empty(_CAP, np.int64)
        wbuf = np.empty(_CAP)
        for qi in range(blk * _BLOCK, min(nq, (blk + 1) * _BLOCK)):
            ok = local_fit(queries[qi], gp, gn, gs, cutoff, kernel, normal_mode, degree,
                           origin, inv_cell, dims, cell_keys, cell_start, ranges, A, rhs, res, nbr, wbuf)
            for t in range(12):
                out[qi, t] = res[t] if ok else math.nan


# -- ray casting (Algorithm 3.1) ----------------------------------------------------------


@njit(cache=True)
def _scan_cell(ii, jj, kk, dims, keys, start, items, skip, use_skip, gp, gn, grho, o, d, tlo, thi, best):
    """Ray–disc tests against the discs listed in ray-grid cell (ii, jj, kk).

    Keeps the nearest hit with ``tlo <= t <= thi`` in ``best`` (``best[0]`` = t,
    ``best[1]`` = sample index as float).
    """
    if ii < 0 or jj < 0 or kk < 0 or ii >= dims[0] or jj >= dims[1] or kk >= dims[2]:
        return
    if use_skip and skip[ii, jj, kk] != 0:
        return
    c = find_cell((ii * dims[1] + jj) * dims[2] + kk, keys)
    if c < 0:
        return
    for m in range(start[c], start[c + 1]):
        a = items[m]
        den = gn[a, 0] * d[0] + gn[a, 1] * d[1] + gn[a, 2] * d[2]
        if den == 0.0:
            continue
        cx = gp[a, 0] - o[0]
        cy = gp[a, 1] - o[1]
        cz = gp[a, 2] - o[2]
        t = (gn[a, 0] * cx + gn[a, 1] * cy + gn[a, 2] * cz) / den
        if t < tlo or t > thi or t >= best[0]:
            continue
        ex = t * d[0] - cx
        ey = t * d[1] - cy
        ez = t * d[2] - cz
        if ex * ex + ey * ey + ez * ez <= grho[a] * grho[a]:
            best[0] = t
            best[1] = a


@njit(cache=True)
def first_disc(o, d, tlo, thi, gp, gn, grho, origin, cell, dims, keys, start, items, skip, use_skip, best):
    """Nearest ray–disc hit with ``tlo <= t <= thi`` by a 3D-DDA walk through the ray grid.

    Every sample is listed in each ray-grid cell its disc's bounding sphere
    overlaps, so the disc hits inside a cell are all found by scanning that cell's
    list, and a hit is final once it lies before the exit of the current cell.
    Empty space is skipped with ``skip`` (when ``use_skip``): the Chebyshev distance
    in cells from each cell to the nearest non-empty one; from a cell at distance
    D >= 3 the ray jumps ``D − 2`` cells. Returns True and ``best = (t, sample)``
    when found.
    """
    best[0] = math.inf
    best[1] = -1.0
    c = np.empty(3, np.int64)
    tmaxs = np.empty(3)
    tdel = np.empty(3)
    step = np.empty(3, np.int64)
    dmax = max(abs(d[0]), abs(d[1]), abs(d[2]))
    # clip to the grid box
    tcur = tlo
    for ax in range(3):
        lo = origin[ax]
        hi = origin[ax] + dims[ax] * cell
        if d[ax] == 0.0:
            if o[ax] < lo or o[ax] > hi:
                return False
        else:
            ta = (lo - o[ax]) / d[ax]
            tb = (hi - o[ax]) / d[ax]
            if ta > tb:
                ta, tb = tb, ta
            tcur = max(tcur, ta)
            thi = min(thi, tb)
    if not tcur <= thi:
        return False
    while True:
        # (re)start the walk at tcur
        for ax in range(3):
            p = o[ax] + tcur * d[ax]
            ci = math.floor((p - origin[ax]) / cell)
            c[ax] = min(max(ci, 0), dims[ax] - 1)
            if d[ax] > 0.0:
                step[ax] = 1
                tdel[ax] = cell / d[ax]
                tmaxs[ax] = tcur + (origin[ax] + (c[ax] + 1) * cell - p) / d[ax]
            elif d[ax] < 0.0:
                step[ax] = -1
                tdel[ax] = -cell / d[ax]
                tmaxs[ax] = tcur + (origin[ax] + c[ax] * cell - p) / d[ax]
            else:
                step[ax] = 0
                tdel[ax] = math.inf
                tmaxs[ax] = math.inf
        _scan_cell(c[0], c[1], c[2], dims, keys, start, items, skip, use_skip, gp, gn, grho, o, d, tlo, thi, best)
        jumped = False
        while True:
            ax = 0
            if tmaxs[1] < tmaxs[ax]:
                ax = 1
            if tmaxs[2] < tmaxs[ax]:
                ax = 2
            texit = tmaxs[ax]
            if best[0] <= texit:
                return True
            if texit > thi:
                return best[0] <= thi
            if use_skip:
                dist = skip[c[0], c[1], c[2]]
                if dist >= 3:
                    tj = min(texit + (dist - 2) * cell / dmax, best[0])
                    if tj > thi:
                        return best[0] <= thi
                    if tj > tcur:
                        tcur = tj
                        jumped = True
                        break
            c[ax] += step[ax]
            tmaxs[ax] += tdel[ax]
            if c[ax] < 0 or c[ax] >= dims[ax]:
                return best[0] <= thi
            _scan_cell(c[0], c[1], c[2], dims, keys, start, items, skip, use_skip, gp, gn, grho, o, d,
                       tlo, thi, best)
        if not jumped:
            return best[0] <= thi


@njit(cache=True)
def ray_iterate(o, d, t0, gp, gn, gs, cutoff, kernel, normal_mode, degree,
                origin, inv_cell, dims, cell_keys, cell_start, max_iter, tol, reach_len,
                ranges, A, rhs, res, nbr, wbuf, x):
    """Algorithm 3.1 from ``x_0 = o + t0 d``: intersect the ray with the local fit plane until converged.

    The plane at ``x_{k-1}`` passes through the foot point p with normal n; its
    intersection with the ray is ``t_k = t_{k-1} + n·(p − x_{k-1}) / (n·d)``. Returns
    ``(converged, t)``; fails when no kernel reaches an iterate, the ray is nearly
    parallel to the plane, or the iterate drifts more than ``reach_len`` from the start.
    """
    dn = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    t = t0
    for _ in range(max_iter):
        for ax in range(3):
            x[ax] = o[ax] + t * d[ax]
        if not local_fit(x, gp, gn, gs, cutoff, kernel, normal_mode, degree,
                         origin, inv_cell, dims, cell_keys, cell_start, ranges, A, rhs, res, nbr, wbuf):
            return False, t
        nd = res[3] * d[0] + res[4] * d[1] + res[5] * d[2]
        if abs(nd) < 1e-3 * dn:
            return False, t
        tn = t + (res[3] * (res[0] - x[0]) + res[4] * (res[1] - x[1]) + res[5] * (res[2] - x[2])) / nd
        if abs(tn - t0) * dn > reach_len:
            return False, tn
        if abs(tn - t) * dn <= tol * res[10]:
            return True, tn
        t = tn
    return False, t


@njit(cache=True, parallel=True)
def intersect_kernel(origins, dirs, tmax, gp, gn, gs, grho, cutoff, kernel, normal_mode, degree,
                     origin, inv_cell, dims, cell_keys, cell_start,
                     rorigin, rcell, rdims, rkeys, rstart, ritems, skip, use_skip,
                     max_iter, tol, eps2, max_attempts, out_t, out_hit, out_n):
    """First intersection with t > 0 of every ray with the MLS surface (Algorithm 3.1).

    For each ray: find the nearest surfel-disc hit (:func:`first_disc`, which culls
    the ray against the ray grid's box) in ``[−ρ_max/|d|, tmax]`` as the start point; run
    :func:`ray_iterate`; accept when it converges to ``t > 0`` with
    ``‖q(x) − x‖ < eps2·σ`` (line 6 of Algorithm 3.1). Otherwise continue behind the
    failed start (by the disc radius), at most ``max_attempts`` times.
    """
    nr = origins.shape[0]
    support = 1.0 / inv_cell
    rho_max = 0.0
    for a in range(grho.shape[0]):
        rho_max = max(rho_max, grho[a])
    nblk = (nr + _BLOCK - 1) // _BLOCK
    for blk in prange(nblk):
        ranges = np.empty((9, 2), np.int64)
        A = np.empty((6, 6))
        rhs = np.empty(6)
        res = np.empty(12)
        nbr = np.empty(_CAP, np.int64)
        wbuf = np.empty(_CAP)
        x = np.empty(3)
        best = np.empty(2)
        o = np.empty(3)
        d = np.empty(3)
        for ri in range(blk * _BLOCK, min(nr, (blk + 1) * _BLOCK)):
            out_t[ri] = math.inf
            out_hit[ri] = False
            for ax in range(3):
                out_n[ri, ax] = math.nan
                o[ax] = origins[ri, ax]
                d[ax] = dirs[ri, ax]
            dn = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            # a disc may be hit slightly behind the origin with the surface in front of it
            t0 = -rho_max / dn
            t1 = tmax[ri]
            tlo = t0
            for _ in range(max_attempts):
                if not first_disc(o, d, tlo, t1, gp, gn, grho, rorigin, rcell, rdims, rkeys, rstart, ritems,
                                  skip, use_skip, best):
                    break
                th = best[0]
                j = int(best[1])
                ok, tc = ray_iterate(o, d, th, gp, gn, gs, cutoff, kernel, normal_mode, degree,
                                     origin, inv_cell, dims, cell_keys, cell_start, max_iter, tol, support,
                                     ranges, A, rhs, res, nbr, wbuf, x)
                if ok and tc > 0.0:
                    if tc > tmax[ri]:
                        break
                    # line 6 of Algorithm 3.1, with the fit of the last iterate (within tol·σ of x)
                    e = 0.0
                    for ax in range(3):
                        e += (res[6 + ax] - (o[ax] + tc * d[ax])) ** 2
                    if math.sqrt(e) < eps2 * res[10]:
                        out_t[ri] = tc
                        out_hit[ri] = True
                        out_n[ri, 0] = res[3]
                        out_n[ri, 1] = res[4]
                        out_n[ri, 2] = res[5]
                        break
                tlo = th + grho[j] / dn
                if tlo > t1:
                    break
