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
offset) and writes the force on each member ``j`` into *j's* row, at the position
of ``i`` in j's neighbour list (``fpair[j, rev[i, t]]``, :func:`reverse_positions`):
every entry belongs to exactly one pair ``(i, j)``, so the parallel writes never
collide, and the force pass sums i's own row — no search and no recomputation
(measured: recomputing the forces from j's data in the force pass cost 3× more
than writing and reading the (N, cap, 3) array).

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

#: Flags of the helpers the fast-math lattice pass calls (numba passes a caller's ``fastmath``
#: and ``error_model`` on to callees that do not set them): they compile the same whoever calls
#: them first, e.g. the SVD stays bit-identical to the shared Jacobi solver.
PLAIN = {"cache": True, "fastmath": False, "error_model": "python"}

SOLID = 1
#: Clamp of singular values when inverting A for the next assignment.
SIG_LO = 0.2
SIG_HI = 5.0
SIGMA_FLOOR = 0.05
CHUNK = 64


@njit(**PLAIN)
def _w(r2, h, dim):
    if dim == 3:
        return poly6_3d(r2, h)
    return poly6_2d(r2, h)


@njit(**PLAIN)
def _w_zero(h, dim):
    """``W(0)`` of poly6 (C.1/C.4)."""
    return _w(0.0, h, dim)


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


@njit(**PLAIN)
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


@njit(**PLAIN)
def _rot2(c, s, a, b):
    """Plane rotation of the pair ``(a, b)``: ``(c a − s b, s a + c b)``."""
    return c * a - s * b, s * a + c * b


@njit(**PLAIN)
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


@njit(**PLAIN)
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


@njit(**PLAIN)
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


@njit(**PLAIN)
def _det3(m):
    """Determinant of a 3×3 matrix."""
    return (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
            + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))


# -- lattice look-up -------------------------------------------------------------------


#: D3 basis (columns): the FCC lattice of eq. (8.20) is the checkerboard lattice
#: D3 = {z in Z^3, sum even} up to a rotation and the scale sqrt(2) (all bases have 60 degree angles).
_D3 = np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
_SQ3 = math.sqrt(3.0)
_EYE = np.eye(3)


def d3_transform(bmat: np.ndarray) -> np.ndarray:
    """Linear map from lattice-frame coordinates (units of d) to D3 coordinates: ``T = D3 B⁻¹``."""
    return np.ascontiguousarray(_D3 @ np.linalg.inv(bmat))


@njit(**PLAIN)
def _round_away(v, r):
    """Round ``v`` to the integer next to ``r = round(v)`` on the other side."""
    return r + 1.0 if v > r else r - 1.0


@njit(**PLAIN)
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
def _d3_round(z0, z1, z2, half, size):
    """:func:`nearest_slot` (3D) for a point given in D3 coordinates ``z = T y``, in floating point.

    The Conway–Sloane rounding without branches and without integer conversions (so that the
    loop over a neighbourhood vectorises): the coordinate with the largest rounding error (the
    first of equal ones) moves one step the other way when the rounded sum is odd. Returns the
    flat index into the slot table (``(i0 · size + i1) · size + i2``, as a float; -1 outside the
    table of ``size³`` entries centred on ``half``) and the squared distance (units of d).
    """
    r0 = np.floor(z0 + 0.5)
    r1 = np.floor(z1 + 0.5)
    r2 = np.floor(z2 + 0.5)
    s = r0 + r1 + r2
    odd = s - 2.0 * np.floor(0.5 * s)  # 0 or 1, exactly
    e0 = z0 - r0
    e1 = z1 - r1
    e2 = z2 - r2
    d0 = abs(e0)
    d1 = abs(e1)
    d2 = abs(e2)
    m0 = odd * ((d0 >= d1) & (d0 >= d2))
    m1 = (odd - m0) * (d1 >= d2)
    m2 = odd - m0 - m1
    k0 = r0 + m0 * (2.0 * (e0 > 0.0) - 1.0)
    k1 = r1 + m1 * (2.0 * (e1 > 0.0) - 1.0)
    k2 = r2 + m2 * (2.0 * (e2 > 0.0) - 1.0)
    e0 = z0 - k0
    e1 = z1 - k1
    e2 = z2 - k2
    best = 0.5 * (e0 * e0 + e1 * e1 + e2 * e2)
    # back to lattice-basis integers: n = D3^-1 k, exact as the sum is even
    i0 = 0.5 * (k0 + k1 - k2) + half
    i1 = 0.5 * (k0 - k1 + k2) + half
    i2 = 0.5 * (k1 + k2 - k0) + half
    inside = (i0 >= 0.0) & (i1 >= 0.0) & (i2 >= 0.0) & (i0 < size) & (i1 < size) & (i2 < size)
    return ((i0 * size + i1) * size + i2 + 1.0) * inside - 1.0, best


@njit(cache=True)
def _nearest_d3(z0, z1, z2, table):
    """Slot and squared distance of :func:`_d3_round` (the lattice pass's rounding), for tests."""
    size = table.shape[0]
    idx, best = _d3_round(z0, z1, z2, float(size // 2), float(size))
    if idx < 0.0:
        return -1, best
    k = int(idx)
    return table[k // (size * size), (k // size) % size, k % size], best


@njit(cache=True)
def nearest_slots(y, tmat, table, dim):
    """Vectorised :func:`nearest_slot` for tests: ``y`` (K, 3) -> (slots (K,), d2 (K,))."""
    n = y.shape[0]
    q = np.empty(n, np.int64)
    d2 = np.empty(n)
    for k in range(n):
        q[k], d2[k] = nearest_slot(y[k, 0], y[k, 1], y[k, 2], tmat, table, dim)
    return q, d2


# -- neighbour-list transpose ---------------------------------------------------------------


@njit(**PLAIN)
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


@njit(**PLAIN)
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


# -- polar decomposition -------------------------------------------------------------------


@njit(**PLAIN)
def polar_rotation(a, r):
    """Rotation ``R`` of the polar decomposition ``A = R S`` (3D) by Newton's iteration.

    ``R ← (R + R⁻ᵀ)/2`` from ``R = A`` converges quadratically to the orthogonal
    polar factor (Higham 1986); it is a rotation when ``det A > 0``. Stops when a
    step changes no entry by more than 1e-8 (the next iterate is then exact to
    rounding, the error squares) or after 40 steps. Writes ``r`` (3, 3) and returns
    True on convergence (False for ``det A ≤ 0`` or no convergence: use :func:`svd_rot`).

    Example
    -------
    >>> r = np.empty((3, 3))
    >>> polar_rotation(np.diag([2.0, 1.0, 0.5]), r), np.round(r, 12).tolist()[0]
    (True, [1.0, 0.0, 0.0])
    """
    r00, r01, r02 = a[0, 0], a[0, 1], a[0, 2]
    r10, r11, r12 = a[1, 0], a[1, 1], a[1, 2]
    r20, r21, r22 = a[2, 0], a[2, 1], a[2, 2]
    ok = False
    for _it in range(40):
        # cofactors: R⁻ᵀ = C / det R
        c00 = r11 * r22 - r12 * r21
        c01 = r12 * r20 - r10 * r22
        c02 = r10 * r21 - r11 * r20
        c10 = r02 * r21 - r01 * r22
        c11 = r00 * r22 - r02 * r20
        c12 = r01 * r20 - r00 * r21
        c20 = r01 * r12 - r02 * r11
        c21 = r02 * r10 - r00 * r12
        c22 = r00 * r11 - r01 * r10
        det = r00 * c00 + r01 * c01 + r02 * c02
        if not det > 0.0:
            break
        hinv = 0.5 / det
        n00 = 0.5 * r00 + hinv * c00
        n01 = 0.5 * r01 + hinv * c01
        n02 = 0.5 * r02 + hinv * c02
        n10 = 0.5 * r10 + hinv * c10
        n11 = 0.5 * r11 + hinv * c11
        n12 = 0.5 * r12 + hinv * c12
        n20 = 0.5 * r20 + hinv * c20
        n21 = 0.5 * r21 + hinv * c21
        n22 = 0.5 * r22 + hinv * c22
        diff = max(abs(n00 - r00), abs(n01 - r01), abs(n02 - r02), abs(n10 - r10), abs(n11 - r11),
                   abs(n12 - r12), abs(n20 - r20), abs(n21 - r21), abs(n22 - r22))
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = n00, n01, n02, n10, n11, n12, n20, n21, n22
        if diff <= 1e-8:
            ok = True
            break
    r[0, 0], r[0, 1], r[0, 2] = r00, r01, r02
    r[1, 0], r[1, 1], r[1, 2] = r10, r11, r12
    r[2, 0], r[2, 1], r[2, 2] = r20, r21, r22
    return ok


@njit(**PLAIN)
def polar_factors(a, dim, rot, sym, work):
    """``A = R S`` with the rotation ``R`` and symmetric ``S`` (3, 3) if no singular value is clamped.

    The lattice pass needs only functions of ``S`` that reduce to matrix algebra when
    every singular value lies inside the clamps (``SIG_LO < σ < SIG_HI``, which also
    keeps the goal floor ``SIGMA_FLOOR`` inactive): ``U diag(f(σ)) Vᵀ = R f(S)`` for
    ``f(σ) = sσ + (1 − s)`` and ``V diag(1/σ) Uᵀ = S⁻¹ Rᵀ``, ``Σσ = tr S``. Gershgorin's
    discs of ``S`` bound its eigenvalues, so the check is rigorous. Returns False (use the
    SVD, :func:`svd_rot`) in 2D, for ``det A ≤ 0``, when Newton's iteration does not
    converge or when a disc reaches a clamp. ``work`` is unused scratch (3, 3).

    Example
    -------
    >>> rot, sym = np.empty((3, 3)), np.empty((3, 3))
    >>> polar_factors(np.diag([1.1, 0.9, 1.0]), 3, rot, sym, np.empty((3, 3))), np.round(np.diag(sym), 12).tolist()
    (True, [1.1, 0.9, 1.0])
    """
    if dim != 3 or not polar_rotation(a, rot):
        return False
    for p in range(3):
        for q in range(3):
            work[p, q] = rot[0, p] * a[0, q] + rot[1, p] * a[1, q] + rot[2, p] * a[2, q]
    for p in range(3):
        for q in range(3):
            sym[p, q] = 0.5 * (work[p, q] + work[q, p])
    for p in range(3):
        rad = 0.0
        for q in range(3):
            if q != p:
                rad += abs(sym[p, q])
        if not (sym[p, p] - rad > SIG_LO * (1.0 + 1e-6) and sym[p, p] + rad < SIG_HI * (1.0 - 1e-6)):
            return False
    return True


# -- the update pass ---------------------------------------------------------------------


@njit(**PLAIN)
def _keep_previous(i, o, amat, ainv, amat_out, ainv_out):
    """Row ``i`` of the new lattice transformation and its inverse: the previous ones, rows ``o``
    (no shape matching)."""
    for p in range(3):
        for q in range(3):
            amat_out[i, p, q] = amat[o, p, q]
            ainv_out[i, p, q] = ainv[o, p, q]


#: Blocks of the lattice pass. Each block of particles owns a window of member-force
#: accumulators (the rows of its particles' neighbours), summed in block order: the result
#: does not depend on the number of threads.
LATTICE_BLOCKS = 16
#: Rows of the member-force sum per parallel task.
SUM_ROWS = 4096
#: Fast-math flags of the lattice pass (reassociation vectorises the sums over members;
#: no ``nnan``/``ninf``).
LATTICE_FASTMATH = {"nsz", "arcp", "contract", "reassoc"}


@njit(cache=True, fastmath=LATTICE_FASTMATH, error_model="numpy")
def _lattice_block(r0, r1, lo_b, win, x, m, phase, obj, matid, uid, mats, nbr, nnbr, h, dim, spacing, slot_vecs, lv,
                   c6, w_self, tm, tmat, table, order, amat, ainv, occ, docked, lam, seed, step, dt, prime, onebody,
                   amat_out, ainv_out, occ_out, docked_out, gmat, fown, valid):
    """The particles ``r0 .. r1 - 1`` of :func:`lattice_update` (one block, serial); member forces are
    added into ``win`` (W, 3), the accumulator rows ``lo_b, lo_b + 1, ...``. ``onebody``: every
    particle is solid and of one object (no neighbour needs the phase and object test)."""
    nq = slot_vecs.shape[0]
    cap = nbr.shape[1]
    h2 = h * h
    for k in range(win.shape[0]):
        win[k, 0] = 0.0
        win[k, 1] = 0.0
        win[k, 2] = 0.0
    # offsets r_ij of the neighbours, squared lattice distances, table indices, masses; ids
    rt = np.empty((6, cap))
    ut = np.empty(cap, np.int64)
    tsize = table.shape[0]
    thalf = float(tsize // 2)
    tflat = table.reshape(tsize * tsize * tsize)
    qt = np.empty(cap, np.int64)
    bestd = np.empty(nq + 1)
    bestj = np.empty(nq, np.int64)
    bestt = np.empty(nq + 1, np.int64)
    # the docked members of the current neighbourhood (slot order), as contiguous columns
    mj = np.empty(nq, np.int64)
    dflag = np.empty(nq, np.int64)
    mb = np.empty((11, nq))  # r (3), lattice offset l (3), W, m_j, force (3)
    a = np.empty((3, 3))
    u = np.empty((3, 3))
    v = np.empty((3, 3))
    sg = np.empty(3)
    rot = np.empty((3, 3))
    sym = np.empty((3, 3))
    g = np.empty((3, 3))
    b = np.empty((3, 3))
    mm = np.empty((3, 3))
    minv = np.empty((3, 3))
    work = np.empty((4, 3, 3))
    keep_goal = gmat.shape[0] > 0
    track = lam.shape[1] > 0
    for i in range(r0, r1):
        o = order[i]  # the particle's row in the state of the previous step
        valid[i] = 0
        cnt = min(nnbr[i], cap)
        fown[i, 0] = 0.0
        fown[i, 1] = 0.0
        fown[i, 2] = 0.0
        mt = matid[i]
        ke = mats[mt, M.KE]
        lmu = mats[mt, M.LMU]
        llam = mats[mt, M.LLAM]
        if phase[i] != SOLID or (ke <= 0.0 and lmu <= 0.0 and llam <= 0.0):
            for q in range(nq):
                occ_out[i, q] = -1
                docked_out[i, q] = 0
            _keep_previous(i, o, amat, ainv, amat_out, ainv_out)
            continue
        rho0 = mats[mt, M.RHO0]
        xi0 = x[i, 0]
        xi1 = x[i, 1]
        xi2 = x[i, 2]
        oi = obj[i]
        # world offset -> lattice frame in units of d (A^(t-1)^-1 / d), in 3D straight on to D3 coordinates
        p00 = (tm[0, 0] * ainv[o, 0, 0] + tm[0, 1] * ainv[o, 1, 0] + tm[0, 2] * ainv[o, 2, 0]) / spacing
        p01 = (tm[0, 0] * ainv[o, 0, 1] + tm[0, 1] * ainv[o, 1, 1] + tm[0, 2] * ainv[o, 2, 1]) / spacing
        p02 = (tm[0, 0] * ainv[o, 0, 2] + tm[0, 1] * ainv[o, 1, 2] + tm[0, 2] * ainv[o, 2, 2]) / spacing
        p10 = (tm[1, 0] * ainv[o, 0, 0] + tm[1, 1] * ainv[o, 1, 0] + tm[1, 2] * ainv[o, 2, 0]) / spacing
        p11 = (tm[1, 0] * ainv[o, 0, 1] + tm[1, 1] * ainv[o, 1, 1] + tm[1, 2] * ainv[o, 2, 1]) / spacing
        p12 = (tm[1, 0] * ainv[o, 0, 2] + tm[1, 1] * ainv[o, 1, 2] + tm[1, 2] * ainv[o, 2, 2]) / spacing
        p20 = (tm[2, 0] * ainv[o, 0, 0] + tm[2, 1] * ainv[o, 1, 0] + tm[2, 2] * ainv[o, 2, 0]) / spacing
        p21 = (tm[2, 0] * ainv[o, 0, 1] + tm[2, 1] * ainv[o, 1, 1] + tm[2, 2] * ainv[o, 2, 1]) / spacing
        p22 = (tm[2, 0] * ainv[o, 0, 2] + tm[2, 1] * ainv[o, 1, 2] + tm[2, 2] * ainv[o, 2, 2]) / spacing
        # 1. assignment (8.21) with conflict resolution: the closest candidate keeps a slot
        for q in range(nq + 1):
            bestd[q] = np.inf
            bestt[q] = -1
        # the neighbours' data in one pass (their loads overlap): offset, mass and id by row position
        for t in range(cnt):
            j = nbr[i, t]
            rt[0, t] = x[j, 0] - xi0
            rt[1, t] = x[j, 1] - xi1
            rt[2, t] = x[j, 2] - xi2
            rt[5, t] = m[j]
            ut[t] = uid[j]
        if onebody:
            for t in range(cnt):
                qt[t] = 1
        else:
            for t in range(cnt):
                j = nbr[i, t]
                qt[t] = np.int64((phase[j] == SOLID) & (obj[j] == oi))
        if dim == 3:
            # vectorised rounding (flat table index as a float), then the table look-ups
            for t in range(cnt):
                r0 = rt[0, t]
                r1 = rt[1, t]
                r2 = rt[2, t]
                idx, d2 = _d3_round(p00 * r0 + p01 * r1 + p02 * r2, p10 * r0 + p11 * r1 + p12 * r2,
                                    p20 * r0 + p21 * r1 + p22 * r2, thalf, tsize)
                rt[4, t] = idx
                rt[3, t] = d2
            for t in range(cnt):
                k = int(rt[4, t])
                q = tflat[max(k, 0)]
                qt[t] = q if (k >= 0) & (qt[t] != 0) else -1
        else:
            for t in range(cnt):
                r0 = rt[0, t]
                r1 = rt[1, t]
                q, d2 = nearest_slot(p00 * r0 + p01 * r1 + p02 * rt[2, t], p10 * r0 + p11 * r1 + p12 * rt[2, t], 0.0,
                                     tmat, table, dim)
                qt[t] = q if qt[t] != 0 else -1
                rt[3, t] = d2
        # branch-free: candidates outside the slot set go to the spare entry nq
        for t in range(cnt):
            q = qt[t]
            qq = q if q >= 0 else nq
            d2 = rt[3, t]
            better = d2 < bestd[qq]
            bestd[qq] = min(d2, bestd[qq])
            bestt[qq] = t if better else bestt[qq]
        for q in range(nq):
            t = bestt[q]
            bestj[q] = nbr[i, max(t, 0)] if t >= 0 else -1
        # 2. docking (section 8.2.5), 3. shape matching sums (8.23) over the docked members
        lmax = mats[mt, M.DOCK_MAX]
        gain = mats[mt, M.DOCK_GAIN]
        loss = mats[mt, M.DOCK_LOSS]
        frac = mats[mt, M.FRACTURE]
        s00 = 0.0
        s01 = 0.0
        s02 = 0.0
        s11 = 0.0
        s12 = 0.0
        s22 = 0.0
        b00 = 0.0
        b01 = 0.0
        b02 = 0.0
        b10 = 0.0
        b11 = 0.0
        b12 = 0.0
        b20 = 0.0
        b21 = 0.0
        b22 = 0.0
        gain_fin = gain < np.inf
        loss_fin = loss < np.inf
        brittle = frac < np.inf
        uid_i = uid[i]
        for q in range(nq):
            j = bestj[q]
            has = j >= 0
            newocc = ut[max(bestt[q], 0)] if has else -1
            dk = docked[o, q] if newocc == occ[o, q] else 0  # a new occupant starts undocked
            occ_out[i, q] = newocc
            if track:
                lq = lam[i, q]
                lup = min(lq + gain * dt, lmax) if gain_fin else lmax
                ldown = max(lq - loss * dt, 0.0) if loss_fin else 0.0
                lnew = lup if has else ldown
                if lnew != lq:  # a settled rate is not rewritten (no dirty cache lines)
                    lam[i, q] = lnew
            else:  # an infinite gain: the rate of an assigned slot is the maximum, whatever it was
                lnew = lmax
            if has and dk == 0:
                if prime:
                    dk = 1
                elif lnew > 0.0:
                    if lnew == np.inf or uniform(seed, step, uid_i, q, STREAM_DOCK) < 1.0 - math.exp(-lnew * dt):
                        dk = 1
            if brittle and has and dk == 1:
                t = bestt[q]
                rr = rt[0, t] * rt[0, t] + rt[1, t] * rt[1, t] + rt[2, t] * rt[2, t]
                rest = spacing * math.sqrt(slot_vecs[q, 0] ** 2 + slot_vecs[q, 1] ** 2 + slot_vecs[q, 2] ** 2)
                if math.sqrt(rr) > (1.0 + frac) * rest:
                    dk = 0
                    if track:
                        lam[i, q] = 0.0
            docked_out[i, q] = dk
            dflag[q] = has & (dk == 1)
        # the docked members, in slot order (branch-free: every slot is written, only members advance)
        count = 0
        for q in range(nq):
            t = max(bestt[q], 0)
            j = max(bestj[q], 0)
            r0 = rt[0, t]
            r1 = rt[1, t]
            r2 = rt[2, t]
            hw = max(h2 - (r0 * r0 + r1 * r1 + r2 * r2), 0.0)
            mj[count] = j
            mb[0, count] = r0
            mb[1, count] = r1
            mb[2, count] = r2
            mb[3, count] = lv[q, 0]
            mb[4, count] = lv[q, 1]
            mb[5, count] = lv[q, 2]
            mb[6, count] = c6 * hw * hw * hw
            mb[7, count] = rt[5, t]
            count += dflag[q]
        for k in range(count):
            w = mb[6, k]
            l0 = mb[3, k]
            l1 = mb[4, k]
            l2 = mb[5, k]
            wl0 = w * l0
            wl1 = w * l1
            wl2 = w * l2
            s00 += wl0 * l0
            s01 += wl0 * l1
            s02 += wl0 * l2
            s11 += wl1 * l1
            s12 += wl1 * l2
            s22 += wl2 * l2
            b00 += w * mb[0, k] * l0
            b01 += w * mb[0, k] * l1
            b02 += w * mb[0, k] * l2
            b10 += w * mb[1, k] * l0
            b11 += w * mb[1, k] * l1
            b12 += w * mb[1, k] * l2
            b20 += w * mb[2, k] * l0
            b21 += w * mb[2, k] * l1
            b22 += w * mb[2, k] * l2
        if dim == 2:
            s02 = s12 = 0.0
            b02 = b12 = b20 = b21 = 0.0
            s22 = 1.0
            b22 = 1.0
        mm[0, 0] = s00
        mm[0, 1] = s01
        mm[0, 2] = s02
        mm[1, 0] = s01
        mm[1, 1] = s11
        mm[1, 2] = s12
        mm[2, 0] = s02
        mm[2, 1] = s12
        mm[2, 2] = s22
        if count < dim:
            _keep_previous(i, o, amat, ainv, amat_out, ainv_out)
            continue
        tr = (s00 + s11 + (s22 if dim == 3 else 0.0)) / dim
        det = _inv3(mm, minv)
        if not det > 1e-6 * tr ** dim:
            _keep_previous(i, o, amat, ainv, amat_out, ainv_out)
            continue
        for p in range(3):
            bp0 = b00 if p == 0 else (b10 if p == 1 else b20)
            bp1 = b01 if p == 0 else (b11 if p == 1 else b21)
            bp2 = b02 if p == 0 else (b12 if p == 1 else b22)
            for q in range(3):
                a[p, q] = bp0 * minv[0, q] + bp1 * minv[1, q] + bp2 * minv[2, q]
        valid[i] = 1
        s = mats[mt, M.GOAL]
        if polar_factors(a, dim, rot, sym, mm):
            # every singular value inside the clamps: functions of S = Rᵀ A by matrix algebra
            trs = sym[0, 0] + sym[1, 1] + sym[2, 2] - 3.0
            for p in range(3):
                for q in range(3):
                    mm[p, q] = s * sym[p, q] + ((1.0 - s) if p == q else 0.0)
            norm = _det3(mm) ** (1.0 / 3.0)
            for p in range(3):
                for q in range(3):
                    g[p, q] = (rot[p, 0] * mm[0, q] + rot[p, 1] * mm[1, q] + rot[p, 2] * mm[2, q]) / norm
            _inv3(sym, mm)  # S⁻¹
            for p in range(3):
                for q in range(3):
                    amat_out[i, p, q] = a[p, q]
                    ainv_out[i, p, q] = mm[p, 0] * rot[q, 0] + mm[p, 1] * rot[q, 1] + mm[p, 2] * rot[q, 2]
        else:
            svd_rot(a, dim, u, sg, v, work)
            is0 = min(max(sg[0], SIG_LO), SIG_HI)
            is1 = min(max(sg[1], SIG_LO), SIG_HI)
            is2 = min(max(sg[2], SIG_LO), SIG_HI)
            for p in range(3):
                for q in range(3):
                    amat_out[i, p, q] = a[p, q]
                    ainv_out[i, p, q] = v[p, 0] * u[q, 0] / is0 + v[p, 1] * u[q, 1] / is1 + v[p, 2] * u[q, 2] / is2
            # 4. goal matrix (8.29-8.30)
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
            trs = (sg[0] - 1.0) + (sg[1] - 1.0)
            if dim == 3:
                trs += sg[2] - 1.0
            for p in range(3):
                for q in range(3):
                    g[p, q] = u[p, 0] * dg0 * v[q, 0] + u[p, 1] * dg1 * v[q, 1] + u[p, 2] * dg2 * v[q, 2]
                    rot[p, q] = u[p, 0] * v[q, 0] + u[p, 1] * v[q, 1] + u[p, 2] * v[q, 2]
        # 5. strain stress: b = V_i P M^-1, P = 2mu (A - R) + lam tr(R^T A - I) R
        for p in range(3):
            for q in range(3):
                mm[p, q] = 2.0 * lmu * (a[p, q] - rot[p, q]) + llam * trs * rot[p, q]
        if keep_goal:
            for p in range(3):
                for q in range(3):
                    gmat[i, p, q] = g[p, q]
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
        # 6. member forces (8.31 + strain), torque about x_i, weights for the correction
        g00, g01, g02 = g[0, 0], g[0, 1], g[0, 2]
        g10, g11, g12 = g[1, 0], g[1, 1], g[1, 2]
        g20, g21, g22 = g[2, 0], g[2, 1], g[2, 2]
        e00, e01, e02 = b[0, 0], b[0, 1], b[0, 2]
        e10, e11, e12 = b[1, 0], b[1, 1], b[1, 2]
        e20, e21, e22 = b[2, 0], b[2, 1], b[2, 2]
        chalf = 0.5 * ke * m[i] / rho0
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
        for k in range(count):
            r0 = mb[0, k]
            r1 = mb[1, k]
            r2 = mb[2, k]
            l0 = mb[3, k]
            l1 = mb[4, k]
            l2 = mb[5, k]
            w = mb[6, k]
            mk = mb[7, k]
            cw = chalf * mk * w
            f0 = cw * (g00 * l0 + g01 * l1 + g02 * l2 - r0) - w * (e00 * l0 + e01 * l1 + e02 * l2)
            f1 = cw * (g10 * l0 + g11 * l1 + g12 * l2 - r1) - w * (e10 * l0 + e11 * l1 + e12 * l2)
            f2 = cw * (g20 * l0 + g21 * l1 + g22 * l2 - r2) - w * (e20 * l0 + e21 * l1 + e22 * l2)
            mb[8, k] = f0
            mb[9, k] = f1
            mb[10, k] = f2
            fs0 += f0
            fs1 += f1
            fs2 += f2
            t0 += r1 * f2 - r2 * f1
            t1 += r2 * f0 - r0 * f2
            t2 += r0 * f1 - r1 * f0
            wk = mk * w
            wsum += wk
            c0 += wk * r0
            c1 += wk * r1
            c2 += wk * r2
            i00 += wk * (r1 * r1 + r2 * r2)
            i11 += wk * (r0 * r0 + r2 * r2)
            i22 += wk * (r0 * r0 + r1 * r1)
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
        # own share: -sum of member forces + correction at y = -c
        fown[i, 0] = -fs0 + wi * (om1 * (-c2) - om2 * (-c1))
        fown[i, 1] = -fs1 + wi * (om2 * (-c0) - om0 * (-c2))
        fown[i, 2] = -fs2 + wi * (om0 * (-c1) - om1 * (-c0))
        # the members' forces + torque correction at y = r - c, into the block's window
        for k in range(count):
            y0 = mb[0, k] - c0
            y1 = mb[1, k] - c1
            y2 = mb[2, k] - c2
            wk = mb[7, k] * mb[6, k]
            row = mj[k] - lo_b
            win[row, 0] += mb[8, k] + wk * (om1 * y2 - om2 * y1)
            win[row, 1] += mb[9, k] + wk * (om2 * y0 - om0 * y2)
            win[row, 2] += mb[10, k] + wk * (om0 * y1 - om1 * y0)


@njit(cache=True, parallel=True)
def lattice_update(x, m, phase, obj, matid, uid, mats, nbr, nnbr, h, dim, spacing,
                   slot_vecs, tmat, table, order, amat, ainv, occ, docked, lam,
                   seed, step, dt, prime,
                   amat_out, ainv_out, occ_out, docked_out, gmat, fown, valid, fel):
    """Lattice assignment, docking, shape matching and neighbourhood forces for every solid particle.

    Inputs are in cell-sorted order; ``nbr`` rows ascending. The state of the previous step
    (``amat``, ``ainv``, occupant ids ``occ`` (N, Q) int32, -1 empty, ``docked`` (N, Q) uint8) is
    read at rows ``order`` (N,): particle ``i`` was row ``order[i]`` before the re-sort, so the
    state needs no re-sort of its own (the pass writes it in the new order: ``amat_out``,
    ``ainv_out``, ``occ_out``, ``docked_out``; an identity ``order`` may update ``occ`` and
    ``docked`` in place). The docking rates ``lam`` (N, Q) are updated in place. ``lam`` may have no columns, (N, 0), when every material docks with an
    infinite gain (the default): the rate of an assigned slot is then the maximum ``λ_d``
    whatever it was before, so the rates are never needed (the results are the same).
    Outputs per particle: new ``A`` and its stabilised inverse (the previous ones where the
    neighbourhood does not span the space), the goal matrix ``U S Vᵀ`` (8.29–8.30, into
    ``gmat`` unless it has no rows, (0, 3, 3): only freezing needs it), the particle's own
    share ``fown`` and ``valid`` (1 when the neighbourhood spans the space). ``prime`` (initial state) docks every assigned
    neighbour at once. ``fel`` (N, 3) receives the forces the neighbourhoods exert on their
    members: for particle ``j`` the sum over the neighbourhoods it is docked in of the
    direct + strain force and the exact torque correction ``w_j ω_i × (r_ij − c_i)``. The
    total elastic force on ``j`` is ``fown[j] + fel[j]``.

    Per particle ``i`` (all in registers and small per-block buffers): one pass over the
    neighbours assigns slots (8.21) with the branch-free D3 rounding (in 3D the map
    ``T A⁻¹/d`` is formed once; the slot conflicts are resolved in a second, short pass); one
    pass over the slots docks and keeps the members, one over the members sums
    ``M = Σ w l lᵀ`` and ``B = Σ w r lᵀ`` (8.23, vectorised); ``A = B M⁻¹`` is
    split by the polar decomposition (:func:`polar_factors`; the SVD :func:`svd_rot` when
    a singular value is clamped, in 2D and for inverted lattices); the member forces and
    torque-correction sums run over contiguous member buffers (vectorised). The forces on
    the members are added into the block's accumulator window (race-free: one window per
    block), then summed per particle.
    """
    n = x.shape[0]
    nq = slot_vecs.shape[0]
    cap = nbr.shape[1]
    nblk = max(1, min(LATTICE_BLOCKS, n))
    h2 = h * h
    w_self = _w_zero(h, dim)
    c6 = w_self / (h2 * h2 * h2)  # W(r) = c6 (h² − r²)³
    # slot offsets in length units
    lv = np.empty((nq, 3))
    for q in range(nq):
        for p in range(3):
            lv[q, p] = slot_vecs[q, p] * spacing
    tm = tmat if dim == 3 else _EYE
    # accumulator windows: block b adds member forces into rows lo[b]..hi[b]
    lo = np.empty(nblk, np.int64)
    hi = np.empty(nblk, np.int64)
    for blk in range(nblk):
        lo_b = n
        hi_b = -1
        for i in range(blk * n // nblk, (blk + 1) * n // nblk):
            c = min(nnbr[i], cap)
            if c > 0:
                lo_b = min(lo_b, nbr[i, 0])
                hi_b = max(hi_b, nbr[i, c - 1])
        lo[blk] = lo_b
        hi[blk] = hi_b
    wmax = 1
    for blk in range(nblk):
        wmax = max(wmax, hi[blk] - lo[blk] + 1)
    win = np.empty((nblk, wmax, 3))
    others = 0
    for i in range(n):
        others += (phase[i] != SOLID) | (obj[i] != obj[0])
    onebody = others == 0
    for blk in prange(nblk):
        _lattice_block(blk * n // nblk, (blk + 1) * n // nblk, lo[blk], win[blk], x, m, phase, obj, matid, uid, mats,
                       nbr, nnbr, h, dim, spacing, slot_vecs, lv, c6, w_self, tm, tmat, table, order, amat,
                       ainv, occ, docked, lam, seed, step, dt, prime, onebody, amat_out, ainv_out, occ_out, docked_out,
                       gmat, fown, valid)
    # the windows summed in block order (deterministic, whatever the thread count), in parallel over rows
    nchunk = (n + SUM_ROWS - 1) // SUM_ROWS
    for ch in prange(nchunk):
        j0 = ch * SUM_ROWS
        j1 = min(n, j0 + SUM_ROWS)
        for j in range(j0, j1):
            fel[j, 0] = 0.0
            fel[j, 1] = 0.0
            fel[j, 2] = 0.0
        for blk in range(nblk):
            for j in range(max(j0, lo[blk]), min(j1, hi[blk] + 1)):
                row = j - lo[blk]
                fel[j, 0] += win[blk, row, 0]
                fel[j, 1] += win[blk, row, 1]
                fel[j, 2] += win[blk, row, 2]
