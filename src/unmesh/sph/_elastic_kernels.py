"""Numba kernels of the elastic lattice forces (thesis section 8.2).

Numpy references: :mod:`unmesh.sph.elastic` (per-neighbourhood math) and
:mod:`unmesh.sph.sampling` (nearest lattice point). Arrays are in the
simulation's cell-sorted order; lattice slots are identified across steps by the
*particle id* (``uid``) of their occupant, so re-sorting needs no remapping.

Pass ``lattice_update`` (one per solid particle ``i``, writes only row ``i``):
assignment (8.21) with conflict resolution, docking (section 8.2.5), shape
matching (8.23–8.24), goal matrix (8.29–8.30), strain stress (8.2.2), the forces
the neighbourhood exerts on its members and the exact torque correction. It
keeps the per-neighbourhood data (goal matrix, ``V P M⁻¹``, ``ω``, centroid
offset) and writes the slot of each member ``j`` into *j's* row, at the position
of ``i`` in j's neighbour list (``slott[j, rev[i, t]]``, :func:`reverse_positions`):
every entry belongs to exactly one pair ``(i, j)``, so the parallel writes never
collide. The force pass then recomputes the force of neighbourhood ``j`` on ``i``
from j's data and the slot (:func:`member_force`, the same arithmetic as here, so
the result is bit-identical) while walking i's own row — no search, and no
(N, cap, 3) pair-force array streamed through memory.

Speed notes: one pass over the neighbours assigns slots (in 3D the map
``T A⁻¹/d`` to D3 coordinates is formed once per particle, so each neighbour costs
one 3×3 product and one rounding); one pass over the slots docks, records the
members and accumulates the shape-matching sums in scalars; the members' offsets and
weights are kept for the force pass over them; the 3×3 eigenproblem of the SVD runs
in registers (:func:`jacobi3`, bit-identical to the shared
:func:`unmesh._linalg_kernels.jacobi_eigh`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh._linalg_kernels import jacobi_eigh
from unmesh.kernels._kernels import poly6_2d, poly6_3d
from unmesh.sph import materials as M
from unmesh.sph._rng import STREAM_DOCK, uniform

SOLID = 1
#: Clamp of singular values when inverting A for the next assignment.
SIG_LO = 0.2
SIG_HI = 5.0
SIGMA_FLOOR = 0.05
CHUNK = 64


@njit(cache=True, inline="always")
def _w(r2, h, dim):
    if dim == 3:
        return poly6_3d(r2, h)
    return poly6_2d(r2, h)


# -- small dense linear algebra --------------------------------------------------------


@njit(cache=True)
def sym_eig3(a, vec, val, b):
    """Eigen-decomposition of the symmetric 3×3 ``a`` by cyclic Jacobi (descending).

    Writes eigenvectors (columns of ``vec``, ``det = +1``) and eigenvalues ``val``;
    ``b`` (3, 3) is scratch.
    """
    for p in range(3):
        for q in range(3):
            b[p, q] = a[p, q]
    jacobi_eigh(b, vec)
    for k in range(3):
        val[k] = b[k, k]
    _sort_desc(vec, val)


@njit(cache=True, inline="always")
def _sort_desc(vec, val):
    """Sort eigenvalues descending (columns of ``vec`` along) and make ``det vec = +1``."""
    for i in range(2):
        best = i
        for j in range(i + 1, 3):
            if val[j] > val[best]:
                best = j
        if best != i:
            tmp = val[i]
            val[i] = val[best]
            val[best] = tmp
            for k in range(3):
                tmp = vec[k, i]
                vec[k, i] = vec[k, best]
                vec[k, best] = tmp
    det = (vec[0, 0] * (vec[1, 1] * vec[2, 2] - vec[1, 2] * vec[2, 1])
           - vec[0, 1] * (vec[1, 0] * vec[2, 2] - vec[1, 2] * vec[2, 0])
           + vec[0, 2] * (vec[1, 0] * vec[2, 1] - vec[1, 1] * vec[2, 0]))
    if det < 0.0:
        for k in range(3):
            vec[k, 2] = -vec[k, 2]


@njit(cache=True)
def _orthonormal_to(u, col, ref):
    """Unit vector orthogonal to column ``ref`` of ``u`` written into column ``col``."""
    ax = 0
    if abs(u[1, ref]) < abs(u[ax, ref]):
        ax = 1
    if abs(u[2, ref]) < abs(u[ax, ref]):
        ax = 2
    d = u[ax, ref]
    n2 = 0.0
    for k in range(3):
        u[k, col] = (1.0 if k == ax else 0.0) - d * u[k, ref]
        n2 += u[k, col] * u[k, col]
    n = math.sqrt(n2)
    for k in range(3):
        u[k, col] /= n


@njit(cache=True, inline="always")
def _rot2(c, s, a, b):
    """Plane rotation of the pair ``(a, b)``: ``(c a − s b, s a + c b)``."""
    return c * a - s * b, s * a + c * b


@njit(cache=True, inline="always")
def _angle(bpp, bqq, apq):
    """Cosine and sine of the Jacobi rotation that annihilates ``apq`` (as :func:`jacobi_eigh`)."""
    theta = (bqq - bpp) / (2.0 * apq)
    t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
    if theta < 0.0:
        t = -t
    c = 1.0 / math.sqrt(t * t + 1.0)
    return c, t * c


@njit(cache=True)
def jacobi3(b00, b01, b02, b10, b11, b12, b20, b21, b22):
    """Cyclic Jacobi eigen-decomposition of a symmetric 3×3 matrix held in scalars.

    The same rotations, in the same order and with the same floating-point
    operations as :func:`unmesh._linalg_kernels.jacobi_eigh` (at most 30 sweeps, stop
    when the off-diagonal mass is below ``1e-32`` of the diagonal's), unrolled so the
    matrix stays in registers: the results are bit-identical.

    Returns
    -------
    tuple of 12 floats
        Eigenvalues ``l0, l1, l2`` (unsorted) and the eigenvector matrix ``V`` row by row
        (column ``k`` is the eigenvector of ``l_k``).

    Example
    -------
    >>> jacobi3(2.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 1.0)[:3]
    (2.0, 3.0, 1.0)
    """
    v00 = 1.0
    v01 = 0.0
    v02 = 0.0
    v10 = 0.0
    v11 = 1.0
    v12 = 0.0
    v20 = 0.0
    v21 = 0.0
    v22 = 1.0
    for _sweep in range(30):
        diag = b00 * b00 + b11 * b11 + b22 * b22
        off = b01 * b01 + b02 * b02 + b12 * b12
        if off <= 1e-32 * diag or off == 0.0:
            break
        if b01 != 0.0:  # (p, q) = (0, 1)
            c, s = _angle(b00, b11, b01)
            b00, b01 = _rot2(c, s, b00, b01)
            b10, b11 = _rot2(c, s, b10, b11)
            b20, b21 = _rot2(c, s, b20, b21)
            b00, b10 = _rot2(c, s, b00, b10)
            b01, b11 = _rot2(c, s, b01, b11)
            b02, b12 = _rot2(c, s, b02, b12)
            v00, v01 = _rot2(c, s, v00, v01)
            v10, v11 = _rot2(c, s, v10, v11)
            v20, v21 = _rot2(c, s, v20, v21)
        if b02 != 0.0:  # (0, 2)
            c, s = _angle(b00, b22, b02)
            b00, b02 = _rot2(c, s, b00, b02)
            b10, b12 = _rot2(c, s, b10, b12)
            b20, b22 = _rot2(c, s, b20, b22)
            b00, b20 = _rot2(c, s, b00, b20)
            b01, b21 = _rot2(c, s, b01, b21)
            b02, b22 = _rot2(c, s, b02, b22)
            v00, v02 = _rot2(c, s, v00, v02)
            v10, v12 = _rot2(c, s, v10, v12)
            v20, v22 = _rot2(c, s, v20, v22)
        if b12 != 0.0:  # (1, 2)
            c, s = _angle(b11, b22, b12)
            b01, b02 = _rot2(c, s, b01, b02)
            b11, b12 = _rot2(c, s, b11, b12)
            b21, b22 = _rot2(c, s, b21, b22)
            b10, b20 = _rot2(c, s, b10, b20)
            b11, b21 = _rot2(c, s, b11, b21)
            b12, b22 = _rot2(c, s, b12, b22)
            v01, v02 = _rot2(c, s, v01, v02)
            v11, v12 = _rot2(c, s, v11, v12)
            v21, v22 = _rot2(c, s, v21, v22)
    return b00, b11, b22, v00, v01, v02, v10, v11, v12, v20, v21, v22


@njit(cache=True)
def svd_rot(a, dim, u, s, v, work):
    """``A = U diag(s) Vᵀ`` with ``det U = det V = +1`` (last ``s`` signed), eq. (8.24).

    2D decomposes the upper 2×2 block (closed form via the polar angle); the z
    row/column of ``U``, ``V`` is the identity and ``s[2] = 1``. 3D diagonalises
    ``AᵀA`` by Jacobi rotations. ``work`` (4, 3, 3) is scratch.
    """
    if dim == 2:
        theta = math.atan2(a[1, 0] - a[0, 1], a[0, 0] + a[1, 1])
        c = math.cos(theta)
        sn = math.sin(theta)
        # symmetric S = R^T A
        p = c * a[0, 0] + sn * a[1, 0]
        q = c * a[0, 1] + sn * a[1, 1]
        r = -sn * a[0, 1] + c * a[1, 1]
        phi = 0.5 * math.atan2(2.0 * q, p - r)
        cp = math.cos(phi)
        sp = math.sin(phi)
        mean = 0.5 * (p + r)
        rad = math.sqrt(0.25 * (p - r) * (p - r) + q * q)
        s[0] = mean + rad
        s[1] = mean - rad
        s[2] = 1.0
        for i in range(3):
            for j in range(3):
                u[i, j] = 0.0
                v[i, j] = 0.0
        v[0, 0] = cp
        v[1, 0] = sp
        v[0, 1] = -sp
        v[1, 1] = cp
        v[2, 2] = 1.0
        # U = R V
        u[0, 0] = c * cp - sn * sp
        u[1, 0] = sn * cp + c * sp
        u[0, 1] = -c * sp - sn * cp
        u[1, 1] = -sn * sp + c * cp
        u[2, 2] = 1.0
        return
    ata = work[0]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += a[k, i] * a[k, j]
            ata[i, j] = acc
    lam = work[1, 0]
    (lam[0], lam[1], lam[2], v[0, 0], v[0, 1], v[0, 2], v[1, 0], v[1, 1], v[1, 2], v[2, 0], v[2, 1],
     v[2, 2]) = jacobi3(ata[0, 0], ata[0, 1], ata[0, 2], ata[1, 0], ata[1, 1], ata[1, 2], ata[2, 0], ata[2, 1],
                        ata[2, 2])
    _sort_desc(v, lam)
    av = work[3]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += a[i, k] * v[k, j]
            av[i, j] = acc
    n0 = math.sqrt(av[0, 0] ** 2 + av[1, 0] ** 2 + av[2, 0] ** 2)
    if n0 > 1e-300:
        for k in range(3):
            u[k, 0] = av[k, 0] / n0
    else:
        for k in range(3):
            u[k, 0] = v[k, 0]
    d = u[0, 0] * av[0, 1] + u[1, 0] * av[1, 1] + u[2, 0] * av[2, 1]
    t0 = av[0, 1] - d * u[0, 0]
    t1 = av[1, 1] - d * u[1, 0]
    t2 = av[2, 1] - d * u[2, 0]
    n1 = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if n1 > 1e-12 * max(n0, 1e-300):
        u[0, 1] = t0 / n1
        u[1, 1] = t1 / n1
        u[2, 1] = t2 / n1
    else:
        _orthonormal_to(u, 1, 0)
    u[0, 2] = u[1, 0] * u[2, 1] - u[2, 0] * u[1, 1]
    u[1, 2] = u[2, 0] * u[0, 1] - u[0, 0] * u[2, 1]
    u[2, 2] = u[0, 0] * u[1, 1] - u[1, 0] * u[0, 1]
    for j in range(3):
        s[j] = u[0, j] * av[0, j] + u[1, j] * av[1, j] + u[2, j] * av[2, j]


@njit(cache=True, inline="always")
def _inv3(m, out):
    """Inverse of a 3×3 matrix; returns the determinant (0 leaves ``out`` unchanged)."""
    c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
    c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
    c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
    det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
    if det == 0.0:
        return 0.0
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[1, 0] = c01 * inv
    out[2, 0] = c02 * inv
    out[0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) * inv
    out[1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) * inv
    out[2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) * inv
    out[0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) * inv
    out[1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) * inv
    out[2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) * inv
    return det


# -- lattice look-up -------------------------------------------------------------------


#: D3 basis (columns): the FCC lattice of eq. (8.20) is the checkerboard lattice
#: D3 = {z in Z^3, sum even} up to a rotation and the scale sqrt(2) (all bases have 60 degree angles).
_D3 = np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
_SQ3 = math.sqrt(3.0)
_EYE = np.eye(3)


def d3_transform(bmat: np.ndarray) -> np.ndarray:
    """Linear map from lattice-frame coordinates (units of d) to D3 coordinates: ``T = D3 B⁻¹``."""
    return np.ascontiguousarray(_D3 @ np.linalg.inv(bmat))


@njit(cache=True, inline="always")
def _round_away(v, r):
    """Round ``v`` to the integer next to ``r = round(v)`` on the other side."""
    return r + 1.0 if v > r else r - 1.0


@njit(cache=True, inline="always")
def nearest_slot(y0, y1, y2, tmat, table, dim):
    """Slot of the lattice point nearest to ``y`` (lattice frame, units of d) and the squared distance.

    The minimisation of eq. (8.21) in closed form: 2D splits the hexagonal
    lattice into two rectangular lattices and keeps the nearer rounding; 3D maps
    ``y`` to D3 coordinates (``tmat``, :func:`d3_transform`) and applies the
    Conway–Sloane rounding for D_n (round every coordinate; if the sum is odd,
    re-round the coordinate with the largest error the other way). Returns slot -1
    when the nearest point is the origin or outside the slot set (``table``).
    """
    if dim == 2:
        a0 = math.floor(y0 + 0.5)
        a1 = math.floor(y1 / _SQ3 + 0.5) * _SQ3
        e0 = y0 - a0
        e1 = y1 - a1
        b0 = math.floor(y0 - 0.5 + 0.5) + 0.5
        b1 = math.floor((y1 - 0.5 * _SQ3) / _SQ3 + 0.5) * _SQ3 + 0.5 * _SQ3
        f0 = y0 - b0
        f1 = y1 - b1
        da = e0 * e0 + e1 * e1
        db = f0 * f0 + f1 * f1
        if db < da:
            a0 = b0
            a1 = b1
            da = db
        n1 = a1 / (0.5 * _SQ3)
        n0 = a0 - 0.5 * n1
        i0 = math.floor(n0 + 0.5)
        i1 = math.floor(n1 + 0.5)
        i2 = 0
        best = da
    else:
        z0 = tmat[0, 0] * y0 + tmat[0, 1] * y1 + tmat[0, 2] * y2
        z1 = tmat[1, 0] * y0 + tmat[1, 1] * y1 + tmat[1, 2] * y2
        z2 = tmat[2, 0] * y0 + tmat[2, 1] * y1 + tmat[2, 2] * y2
        r0 = math.floor(z0 + 0.5)
        r1 = math.floor(z1 + 0.5)
        r2 = math.floor(z2 + 0.5)
        if (int(r0) + int(r1) + int(r2)) & 1:
            d0 = abs(z0 - r0)
            d1 = abs(z1 - r1)
            d2 = abs(z2 - r2)
            if d0 >= d1 and d0 >= d2:
                r0 = _round_away(z0, r0)
            elif d1 >= d2:
                r1 = _round_away(z1, r1)
            else:
                r2 = _round_away(z2, r2)
        best = 0.5 * ((z0 - r0) ** 2 + (z1 - r1) ** 2 + (z2 - r2) ** 2)
        # back to lattice-basis integers: n = D3^-1 z = ½ (z0+z1−z2, z0−z1+z2, −z0+z1+z2), exact as the sum is even
        k0 = int(r0)
        k1 = int(r1)
        k2 = int(r2)
        i0 = (k0 + k1 - k2) >> 1
        i1 = (k0 - k1 + k2) >> 1
        i2 = (k1 + k2 - k0) >> 1
    half = table.shape[0] // 2
    i0 += half
    i1 += half
    i2 += half
    if i0 < 0 or i1 < 0 or i2 < 0 or i0 >= table.shape[0] or i1 >= table.shape[0] or i2 >= table.shape[0]:
        return -1, best
    return table[i0, i1, i2], best


@njit(cache=True, inline="always")
def _nearest_d3(z0, z1, z2, table):
    """:func:`nearest_slot` (3D) for a point given in D3 coordinates ``z = T y``."""
    r0 = math.floor(z0 + 0.5)
    r1 = math.floor(z1 + 0.5)
    r2 = math.floor(z2 + 0.5)
    if (int(r0) + int(r1) + int(r2)) & 1:
        d0 = abs(z0 - r0)
        d1 = abs(z1 - r1)
        d2 = abs(z2 - r2)
        if d0 >= d1 and d0 >= d2:
            r0 = _round_away(z0, r0)
        elif d1 >= d2:
            r1 = _round_away(z1, r1)
        else:
            r2 = _round_away(z2, r2)
    best = 0.5 * ((z0 - r0) ** 2 + (z1 - r1) ** 2 + (z2 - r2) ** 2)
    k0 = int(r0)
    k1 = int(r1)
    k2 = int(r2)
    half = table.shape[0] // 2
    i0 = ((k0 + k1 - k2) >> 1) + half
    i1 = ((k0 - k1 + k2) >> 1) + half
    i2 = ((k1 + k2 - k0) >> 1) + half
    if i0 < 0 or i1 < 0 or i2 < 0 or i0 >= table.shape[0] or i1 >= table.shape[0] or i2 >= table.shape[0]:
        return -1, best
    return table[i0, i1, i2], best


@njit(cache=True)
def nearest_slots(y, tmat, table, dim):
    """Vectorised :func:`nearest_slot` for tests: ``y`` (K, 3) -> (slots (K,), d2 (K,))."""
    n = y.shape[0]
    q = np.empty(n, np.int64)
    d2 = np.empty(n)
    for k in range(n):
        q[k], d2[k] = nearest_slot(y[k, 0], y[k, 1], y[k, 2], tmat, table, dim)
    return q, d2


# -- per-member force (shared by the update pass and the gather) ------------------------


@njit(cache=True, inline="always")
def _member_force(r0, r1, r2, w, l0, l1, l2, coef, g, b):
    """Direct + strain force of a neighbourhood on one member (without torque correction).

    ``coef = ½ K_e m_i m_j / ρ0``; ``g`` the goal matrix, ``b = V_i P M⁻¹``.
    """
    gl0 = g[0, 0] * l0 + g[0, 1] * l1 + g[0, 2] * l2
    gl1 = g[1, 0] * l0 + g[1, 1] * l1 + g[1, 2] * l2
    gl2 = g[2, 0] * l0 + g[2, 1] * l1 + g[2, 2] * l2
    bl0 = b[0, 0] * l0 + b[0, 1] * l1 + b[0, 2] * l2
    bl1 = b[1, 0] * l0 + b[1, 1] * l1 + b[1, 2] * l2
    bl2 = b[2, 0] * l0 + b[2, 1] * l1 + b[2, 2] * l2
    cw = coef * w
    return cw * (gl0 - r0) - w * bl0, cw * (gl1 - r1) - w * bl1, cw * (gl2 - r2) - w * bl2


@njit(cache=True, inline="always")
def _position(row, count, value):
    """Index of ``value`` in the ascending ``row[:count]`` (-1 if absent); branch-free search."""
    if count == 0:
        return -1
    base = 0
    n = count
    while n > 1:
        half = n >> 1
        probe = base + half
        base = probe if row[probe] <= value else base
        n -= half
    return base if row[base] == value else -1


@njit(cache=True, inline="always")
def _lower_bound(row, count, value):
    """Number of entries of the ascending ``row[:count]`` that are below ``value``."""
    lo = 0
    hi = count
    while lo < hi:
        mid = (lo + hi) >> 1
        if row[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, parallel=True)
def reverse_positions(nbr, nnbr, nblocks, rev):
    """Position of ``i`` in the neighbour list of each of its neighbours.

    ``rev[i, t] = u`` with ``nbr[j, u] == i`` for ``j = nbr[i, t]`` (-1 when ``i``
    is missing from j's list, which a symmetric neighbour relation never gives).
    Rows must be ascending (as the density pass and ``radius_neighbors`` produce
    them). The rows are split into ``nblocks`` contiguous blocks processed in
    parallel; within a block, the entries of row ``j`` that belong to the block's
    rows come in ascending order, so one cursor per ``j`` (started by a binary
    search) finds every position in O(1): O(N·k) in all.

    Returns the number of missing entries.
    """
    n = nbr.shape[0]
    cap = nbr.shape[1]
    nb = max(1, min(nblocks, n))
    missing = 0
    for blk in prange(nb):
        r0 = blk * n // nb
        r1 = (blk + 1) * n // nb
        lo = n
        hi = -1
        for i in range(r0, r1):
            c = min(nnbr[i], cap)
            if c > 0:
                lo = min(lo, nbr[i, 0])
                hi = max(hi, nbr[i, c - 1])
        if hi < lo:
            continue
        cur = np.full(hi - lo + 1, -1, np.int64)
        for i in range(r0, r1):
            c = min(nnbr[i], cap)
            for t in range(c):
                j = nbr[i, t]
                cj = min(nnbr[j], cap)
                k = cur[j - lo]
                if k < 0:
                    k = _lower_bound(nbr[j], cj, r0)
                if k < cj and nbr[j, k] == i:
                    rev[i, t] = k
                    cur[j - lo] = k + 1
                else:
                    u = _position(nbr[j], cj, i)
                    rev[i, t] = u
                    if u < 0:
                        missing += 1
                    else:
                        cur[j - lo] = u + 1
    return missing


@njit(cache=True, inline="always")
def member_force(j, i, q, x, m, matid, mats, h, dim, spacing, slot_vecs, gmat, bstr, omega, cen):
    """Force of the neighbourhood of ``i`` on its member ``j`` docked at slot ``q``.

    Direct force (8.29–8.31) + strain force (8.2.2) + the exact torque correction
    ``w_j ω_i × (r_ij − c_i)``, from the per-neighbourhood outputs of
    :func:`lattice_update` (``gmat``, ``bstr``, ``omega``, ``cen`` = centroid offset
    ``c_i``). The arithmetic is that of :func:`lattice_update`'s member loop.
    """
    r0 = x[j, 0] - x[i, 0]
    r1 = x[j, 1] - x[i, 1]
    r2 = x[j, 2] - x[i, 2]
    w = _w(r0 * r0 + r1 * r1 + r2 * r2, h, dim)
    mt = matid[i]
    coef = 0.5 * mats[mt, M.KE] * m[i] * m[j] / mats[mt, M.RHO0]
    f0, f1, f2 = _member_force(r0, r1, r2, w, slot_vecs[q, 0] * spacing, slot_vecs[q, 1] * spacing,
                               slot_vecs[q, 2] * spacing, coef, gmat[i], bstr[i])
    wk = m[j] * w
    y0 = r0 - cen[i, 0]
    y1 = r1 - cen[i, 1]
    y2 = r2 - cen[i, 2]
    om0 = omega[i, 0]
    om1 = omega[i, 1]
    om2 = omega[i, 2]
    return f0 + wk * (om1 * y2 - om2 * y1), f1 + wk * (om2 * y0 - om0 * y2), f2 + wk * (om0 * y1 - om1 * y0)


@njit(cache=True, inline="always")
def gather_member_force(i, x, m, matid, mats, nbr, nnbr, h, dim, spacing, slot_vecs, gmat, bstr, omega, cen,
                        slott, out):
    """Add the elastic forces that the neighbourhoods of ``i``'s neighbours exert on ``i`` to ``out``.

    :func:`lattice_update` stores in ``slott[i, t]`` the slot of ``i`` in the
    lattice of ``j = nbr[i, t]`` (-1 when ``i`` is not docked there or j's
    neighbourhood gives no forces); the forces are summed in neighbour order.
    """
    for t in range(min(nnbr[i], nbr.shape[1])):
        q = slott[i, t]
        if q >= 0:
            f0, f1, f2 = member_force(i, nbr[i, t], q, x, m, matid, mats, h, dim, spacing, slot_vecs, gmat, bstr,
                                      omega, cen)
            out[0] += f0
            out[1] += f1
            out[2] += f2


# -- the update pass ---------------------------------------------------------------------


@njit(cache=True, inline="always")
def _clear_slots(i, nbr, nnbr, rev, slott):
    """Mark ``i``'s neighbours as non-members of its lattice in their rows (no forces from ``i``)."""
    for t in range(min(nnbr[i], nbr.shape[1])):
        ut = rev[i, t]
        if ut >= 0:
            slott[nbr[i, t], ut] = -1


@njit(cache=True, parallel=True)
def lattice_update(x, m, phase, obj, matid, uid, mats, nbr, nnbr, h, dim, spacing,
                   slot_vecs, tmat, table, amat, ainv, occ, docked, lam,
                   seed, step, dt, prime, rev,
                   amat_out, ainv_out, gmat, bstr, omega, cen, fown, valid, mslot, slott):
    """Lattice assignment, docking, shape matching and neighbourhood forces for every solid particle.

    Inputs are in cell-sorted order. ``occ`` (N, Q) int64 holds occupant ids (-1
    empty), ``docked`` (N, Q) uint8 and ``lam`` (N, Q) docking rates are updated in
    place. Outputs per particle: new ``A`` and its stabilised inverse, goal matrix
    ``U S Vᵀ``, ``V_i P M⁻¹``, torque-correction ``ω`` and centroid, the particle's
    own share ``fown`` and ``valid`` (1 when the neighbourhood spans the space).
    ``prime`` (initial state) docks every assigned neighbour at once. ``mslot``
    (N, cap) int16 receives, aligned with ``nbr``, the slot of each docked neighbour
    (-1 otherwise). ``rev`` (N, cap) are the :func:`reverse_positions` of ``nbr``;
    ``slott`` (N, cap) int16 receives the transpose of ``mslot``: in
    ``slott[j, rev[i, t]]`` the slot of ``j = nbr[i, t]`` in i's lattice, -1 when
    ``j`` is not a member or i's neighbourhood gives no forces. ``cen`` is the
    offset ``c_i`` of the weighted centroid from ``x_i``. The forces on the members
    follow from these outputs (:func:`member_force`, :func:`gather_member_force`).
    """
    n = x.shape[0]
    nq = slot_vecs.shape[0]
    cap = nbr.shape[1]
    nchunk = (n + CHUNK - 1) // CHUNK
    w_self = _w(0.0, h, dim)
    for ch in prange(nchunk):
        bestd = np.empty(nq)
        bestj = np.empty(nq, np.int64)
        bestt = np.empty(nq, np.int64)
        # the docked members of the current neighbourhood, in slot order
        mq = np.empty(nq, np.int64)
        mj = np.empty(nq, np.int64)
        mr = np.empty((nq, 3))
        mw = np.empty(nq)
        minv = np.empty((3, 3))
        a = np.empty((3, 3))
        u = np.empty((3, 3))
        v = np.empty((3, 3))
        sg = np.empty(3)
        g = np.empty((3, 3))
        b = np.empty((3, 3))
        mm = np.empty((3, 3))
        work = np.empty((4, 3, 3))
        for i in range(ch * CHUNK, min(n, (ch + 1) * CHUNK)):
            valid[i] = 0
            cnt = min(nnbr[i], cap)
            for t in range(cnt):
                mslot[i, t] = -1
            for p in range(3):
                fown[i, p] = 0.0
                omega[i, p] = 0.0
                cen[i, p] = 0.0
                for q in range(3):
                    amat_out[i, p, q] = amat[i, p, q]
                    ainv_out[i, p, q] = ainv[i, p, q]
                    gmat[i, p, q] = 0.0
                    bstr[i, p, q] = 0.0
            mt = matid[i]
            ke = mats[mt, M.KE]
            lmu = mats[mt, M.LMU]
            llam = mats[mt, M.LLAM]
            if phase[i] != SOLID or (ke <= 0.0 and lmu <= 0.0 and llam <= 0.0):
                for q in range(nq):
                    occ[i, q] = -1
                    docked[i, q] = 0
                _clear_slots(i, nbr, nnbr, rev, slott)
                continue
            rho0 = mats[mt, M.RHO0]
            xi0 = x[i, 0]
            xi1 = x[i, 1]
            xi2 = x[i, 2]
            oi = obj[i]
            # world offset -> lattice frame in units of d (A^(t-1)^-1 / d), in 3D straight on to D3 coordinates
            tm = tmat if dim == 3 else _EYE
            p00 = (tm[0, 0] * ainv[i, 0, 0] + tm[0, 1] * ainv[i, 1, 0] + tm[0, 2] * ainv[i, 2, 0]) / spacing
            p01 = (tm[0, 0] * ainv[i, 0, 1] + tm[0, 1] * ainv[i, 1, 1] + tm[0, 2] * ainv[i, 2, 1]) / spacing
            p02 = (tm[0, 0] * ainv[i, 0, 2] + tm[0, 1] * ainv[i, 1, 2] + tm[0, 2] * ainv[i, 2, 2]) / spacing
            p10 = (tm[1, 0] * ainv[i, 0, 0] + tm[1, 1] * ainv[i, 1, 0] + tm[1, 2] * ainv[i, 2, 0]) / spacing
            p11 = (tm[1, 0] * ainv[i, 0, 1] + tm[1, 1] * ainv[i, 1, 1] + tm[1, 2] * ainv[i, 2, 1]) / spacing
            p12 = (tm[1, 0] * ainv[i, 0, 2] + tm[1, 1] * ainv[i, 1, 2] + tm[1, 2] * ainv[i, 2, 2]) / spacing
            p20 = (tm[2, 0] * ainv[i, 0, 0] + tm[2, 1] * ainv[i, 1, 0] + tm[2, 2] * ainv[i, 2, 0]) / spacing
            p21 = (tm[2, 0] * ainv[i, 0, 1] + tm[2, 1] * ainv[i, 1, 1] + tm[2, 2] * ainv[i, 2, 1]) / spacing
            p22 = (tm[2, 0] * ainv[i, 0, 2] + tm[2, 1] * ainv[i, 1, 2] + tm[2, 2] * ainv[i, 2, 2]) / spacing
            # 1. assignment (8.21) with conflict resolution: the closest candidate keeps a slot
            for q in range(nq):
                bestd[q] = 1e300
                bestj[q] = -1
            for t in range(cnt):
                j = nbr[i, t]
                if phase[j] != SOLID or obj[j] != oi:
                    continue
                r0 = x[j, 0] - xi0
                r1 = x[j, 1] - xi1
                r2 = x[j, 2] - xi2
                y0 = p00 * r0 + p01 * r1 + p02 * r2
                y1 = p10 * r0 + p11 * r1 + p12 * r2
                if dim == 3:
                    q, d2 = _nearest_d3(y0, y1, p20 * r0 + p21 * r1 + p22 * r2, table)
                else:
                    q, d2 = nearest_slot(y0, y1, 0.0, tmat, table, dim)
                if q >= 0 and d2 < bestd[q]:
                    bestd[q] = d2
                    bestj[q] = j
                    bestt[q] = t
            # 2. docking (section 8.2.5), 3. shape matching sums (8.23) over the docked members
            lmax = mats[mt, M.DOCK_MAX]
            gain = mats[mt, M.DOCK_GAIN]
            loss = mats[mt, M.DOCK_LOSS]
            frac = mats[mt, M.FRACTURE]
            m00 = 0.0
            m01 = 0.0
            m02 = 0.0
            m10 = 0.0
            m11 = 0.0
            m12 = 0.0
            m20 = 0.0
            m21 = 0.0
            m22 = 0.0
            b00 = 0.0
            b01 = 0.0
            b02 = 0.0
            b10 = 0.0
            b11 = 0.0
            b12 = 0.0
            b20 = 0.0
            b21 = 0.0
            b22 = 0.0
            count = 0
            for q in range(nq):
                j = bestj[q]
                newocc = uid[j] if j >= 0 else -1
                if newocc != occ[i, q]:
                    occ[i, q] = newocc
                    docked[i, q] = 0
                lq = lam[i, q]
                if j >= 0:
                    lnew = min(lq + gain * dt, lmax) if gain < np.inf else lmax
                else:
                    lnew = max(lq - loss * dt, 0.0) if loss < np.inf else 0.0
                if lnew != lq:  # a settled rate is not rewritten (no dirty cache lines)
                    lam[i, q] = lnew
                if j < 0:
                    continue
                r0 = x[j, 0] - xi0
                r1 = x[j, 1] - xi1
                r2 = x[j, 2] - xi2
                if prime:
                    docked[i, q] = 1
                if docked[i, q] == 0 and lam[i, q] > 0.0:
                    uu = uniform(seed, step, uid[i], q, STREAM_DOCK)
                    if lam[i, q] == np.inf or uu < 1.0 - math.exp(-lam[i, q] * dt):
                        docked[i, q] = 1
                if docked[i, q] == 1 and frac < np.inf:
                    rest = spacing * math.sqrt(slot_vecs[q, 0] ** 2 + slot_vecs[q, 1] ** 2 + slot_vecs[q, 2] ** 2)
                    if math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) > (1.0 + frac) * rest:
                        docked[i, q] = 0
                        lam[i, q] = 0.0
                if docked[i, q] == 0:
                    continue
                mslot[i, bestt[q]] = q
                w = _w(r0 * r0 + r1 * r1 + r2 * r2, h, dim)
                l0 = slot_vecs[q, 0] * spacing
                l1 = slot_vecs[q, 1] * spacing
                l2 = slot_vecs[q, 2] * spacing
                wl0 = w * l0
                wl1 = w * l1
                wl2 = w * l2
                wr0 = w * r0
                wr1 = w * r1
                wr2 = w * r2
                m00 += wl0 * l0
                m01 += wl0 * l1
                m02 += wl0 * l2
                m10 += wl1 * l0
                m11 += wl1 * l1
                m12 += wl1 * l2
                m20 += wl2 * l0
                m21 += wl2 * l1
                m22 += wl2 * l2
                b00 += wr0 * l0
                b01 += wr0 * l1
                b02 += wr0 * l2
                b10 += wr1 * l0
                b11 += wr1 * l1
                b12 += wr1 * l2
                b20 += wr2 * l0
                b21 += wr2 * l1
                b22 += wr2 * l2
                mq[count] = q
                mj[count] = j
                mr[count, 0] = r0
                mr[count, 1] = r1
                mr[count, 2] = r2
                mw[count] = w
                count += 1
            if dim == 2:
                m02 = m12 = m20 = m21 = 0.0
                b02 = b12 = b20 = b21 = 0.0
                m22 = 1.0
                b22 = 1.0
            mm[0, 0] = m00
            mm[0, 1] = m01
            mm[0, 2] = m02
            mm[1, 0] = m10
            mm[1, 1] = m11
            mm[1, 2] = m12
            mm[2, 0] = m20
            mm[2, 1] = m21
            mm[2, 2] = m22
            if count < dim:
                _clear_slots(i, nbr, nnbr, rev, slott)
                continue
            tr = (m00 + m11 + (m22 if dim == 3 else 0.0)) / dim
            det = _inv3(mm, minv)
            if not det > 1e-6 * tr ** dim:
                _clear_slots(i, nbr, nnbr, rev, slott)
                continue
            for p in range(3):
                bp0 = b00 if p == 0 else (b10 if p == 1 else b20)
                bp1 = b01 if p == 0 else (b11 if p == 1 else b21)
                bp2 = b02 if p == 0 else (b12 if p == 1 else b22)
                for q in range(3):
                    a[p, q] = bp0 * minv[0, q] + bp1 * minv[1, q] + bp2 * minv[2, q]
            svd_rot(a, dim, u, sg, v, work)
            valid[i] = 1
            is0 = min(max(sg[0], SIG_LO), SIG_HI)
            is1 = min(max(sg[1], SIG_LO), SIG_HI)
            is2 = min(max(sg[2], SIG_LO), SIG_HI)
            for p in range(3):
                for q in range(3):
                    amat_out[i, p, q] = a[p, q]
                    ainv_out[i, p, q] = v[p, 0] * u[q, 0] / is0 + v[p, 1] * u[q, 1] / is1 + v[p, 2] * u[q, 2] / is2
            # 4. goal matrix (8.29-8.30)
            s = mats[mt, M.GOAL]
            dg0 = s * max(sg[0], SIGMA_FLOOR) + (1.0 - s)
            dg1 = s * max(sg[1], SIGMA_FLOOR) + (1.0 - s)
            if dim == 3:
                dg2 = s * max(sg[2], SIGMA_FLOOR) + (1.0 - s)
                norm = (dg0 * dg1 * dg2) ** (1.0 / 3.0)
                dg2 /= norm
            else:
                dg2 = 1.0
                norm = (dg0 * dg1) ** 0.5
            dg0 /= norm
            dg1 /= norm
            # 5. strain stress: b = V_i P M^-1, P = 2mu (A - R) + lam tr(R^T A - I) R
            trs = (sg[0] - 1.0) + (sg[1] - 1.0)
            if dim == 3:
                trs += sg[2] - 1.0
            for p in range(3):
                for q in range(3):
                    g[p, q] = u[p, 0] * dg0 * v[q, 0] + u[p, 1] * dg1 * v[q, 1] + u[p, 2] * dg2 * v[q, 2]
                    gmat[i, p, q] = g[p, q]
                    rpq = u[p, 0] * v[q, 0] + u[p, 1] * v[q, 1] + u[p, 2] * v[q, 2]
                    mm[p, q] = 2.0 * lmu * (a[p, q] - rpq) + llam * trs * rpq
            if dim == 2:
                for p in range(3):
                    mm[2, p] = 0.0
                    mm[p, 2] = 0.0
            vol = m[i] / rho0
            for p in range(3):
                for q in range(3):
                    b[p, q] = vol * (mm[p, 0] * minv[0, q] + mm[p, 1] * minv[1, q] + mm[p, 2] * minv[2, q])
                    if dim == 2 and (p == 2 or q == 2):
                        b[p, q] = 0.0
                    bstr[i, p, q] = b[p, q]
            # 6. member forces, torque about x_i, weights for the correction
            fs0 = 0.0
            fs1 = 0.0
            fs2 = 0.0
            t0 = 0.0
            t1 = 0.0
            t2 = 0.0
            wi = m[i] * w_self
            wsum = wi
            c0 = 0.0
            c1 = 0.0
            c2 = 0.0
            i00 = 0.0
            i01 = 0.0
            i02 = 0.0
            i11 = 0.0
            i12 = 0.0
            i22 = 0.0
            chalf = 0.5 * ke * m[i]
            for k in range(count):
                q = mq[k]
                j = mj[k]
                r0 = mr[k, 0]
                r1 = mr[k, 1]
                r2 = mr[k, 2]
                w = mw[k]
                coef = chalf * m[j] / rho0
                f0, f1, f2 = _member_force(r0, r1, r2, w, slot_vecs[q, 0] * spacing, slot_vecs[q, 1] * spacing,
                                           slot_vecs[q, 2] * spacing, coef, g, b)
                fs0 += f0
                fs1 += f1
                fs2 += f2
                t0 += r1 * f2 - r2 * f1
                t1 += r2 * f0 - r0 * f2
                t2 += r0 * f1 - r1 * f0
                wk = m[j] * w
                wsum += wk
                c0 += wk * r0
                c1 += wk * r1
                c2 += wk * r2
                rr = r0 * r0 + r1 * r1 + r2 * r2
                i00 += wk * (rr - r0 * r0)
                i11 += wk * (rr - r1 * r1)
                i22 += wk * rr - wk * r2 * r2
                i01 -= wk * r0 * r1
                i02 -= wk * r0 * r2
                i12 -= wk * r1 * r2
            c0 /= wsum
            c1 /= wsum
            c2 /= wsum
            # parallel-axis shift to the centroid
            cc = c0 * c0 + c1 * c1 + c2 * c2
            i00 -= wsum * (cc - c0 * c0)
            i11 -= wsum * (cc - c1 * c1)
            i22 -= wsum * (cc - c2 * c2)
            i01 += wsum * c0 * c1
            i02 += wsum * c0 * c2
            i12 += wsum * c1 * c2
            if dim == 2:
                om0 = 0.0
                om1 = 0.0
                om2 = -t2 / i22 if i22 > 0.0 else 0.0
            else:
                mm[0, 0] = i00
                mm[1, 1] = i11
                mm[2, 2] = i22
                mm[0, 1] = i01
                mm[1, 0] = i01
                mm[0, 2] = i02
                mm[2, 0] = i02
                mm[1, 2] = i12
                mm[2, 1] = i12
                if _inv3(mm, minv) != 0.0:
                    om0 = -(minv[0, 0] * t0 + minv[0, 1] * t1 + minv[0, 2] * t2)
                    om1 = -(minv[1, 0] * t0 + minv[1, 1] * t1 + minv[1, 2] * t2)
                    om2 = -(minv[2, 0] * t0 + minv[2, 1] * t1 + minv[2, 2] * t2)
                else:
                    om0 = 0.0
                    om1 = 0.0
                    om2 = 0.0
            omega[i, 0] = om0
            omega[i, 1] = om1
            omega[i, 2] = om2
            cen[i, 0] = c0
            cen[i, 1] = c1
            cen[i, 2] = c2
            # own share: -sum of member forces + correction at y = -c
            fown[i, 0] = -fs0 + wi * (om1 * (-c2) - om2 * (-c1))
            fown[i, 1] = -fs1 + wi * (om2 * (-c0) - om0 * (-c2))
            fown[i, 2] = -fs2 + wi * (om0 * (-c1) - om1 * (-c0))
            # members' slots into the members' rows (the force pass recomputes the forces, member_force)
            for t in range(cnt):
                ut = rev[i, t]
                if ut >= 0:
                    slott[nbr[i, t], ut] = mslot[i, t]
