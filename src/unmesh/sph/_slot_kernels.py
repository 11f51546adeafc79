"""Nearest lattice point of the lattice assignment (thesis eq. 8.21) in closed form.

Numpy reference: :func:`unmesh.sph.sampling.nearest_lattice_point` (and
:func:`unmesh.sph.elastic.assign_slots`), which the tests compare against. A point ``y`` in the
lattice frame (units of the spacing d) goes to the lattice point nearest to it; the slot table
(:func:`unmesh.sph.sampling.lattice_slots`) maps that point to its slot, -1 if it is none.

Example
-------
>>> import numpy as np
>>> from unmesh.sph.sampling import lattice_basis, lattice_slots
>>> vecs, _, table = lattice_slots(3, 2.0)
>>> q, d2 = nearest_slots(1.02 * vecs[:1], d3_transform(lattice_basis(3)), table, 3)
>>> int(q[0]), round(float(d2[0]), 6)
(0, 0.0004)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from unmesh.sph._kernels import PLAIN

#: D3 basis (columns): the FCC lattice of eq. (8.20) is the checkerboard lattice
#: D3 = {z in Z^3, sum even} up to a rotation and the scale sqrt(2) (all bases have 60 degree angles).
_D3 = np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
_SQ3 = math.sqrt(3.0)


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
def _d3_round_k(z0, z1, z2, half, size):
    """:func:`nearest_slot` (3D) for a point given in D3 coordinates ``z = T y``, in floating point.

    The Conway–Sloane rounding without branches and without integer conversions (so that the
    loop over a neighbourhood vectorises; the choices are selects): the coordinate with the largest
    rounding error (the first of equal ones) moves one step the other way when the rounded sum is
    odd. Returns the flat index into the slot table (``(i0 · size + i1) · size + i2``, as a float;
    -1 outside the table of ``size³`` entries centred on ``half``), the squared distance (units of
    d) and the D3 coordinates ``k`` of the nearest point (integer-valued floats; its lattice-frame
    offset is ``T⁻¹ k``).
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
    m0 = odd if (d0 >= d1) & (d0 >= d2) else 0.0
    m1 = odd - m0 if d1 >= d2 else 0.0
    m2 = odd - m0 - m1
    k0 = r0 + (m0 if e0 > 0.0 else -m0)
    k1 = r1 + (m1 if e1 > 0.0 else -m1)
    k2 = r2 + (m2 if e2 > 0.0 else -m2)
    e0 = z0 - k0
    e1 = z1 - k1
    e2 = z2 - k2
    best = 0.5 * (e0 * e0 + e1 * e1 + e2 * e2)
    # back to lattice-basis integers: n = D3^-1 k, exact as the sum is even
    i0 = 0.5 * (k0 + k1 - k2) + half
    i1 = 0.5 * (k0 - k1 + k2) + half
    i2 = 0.5 * (k1 + k2 - k0) + half
    inside = (i0 >= 0.0) & (i1 >= 0.0) & (i2 >= 0.0) & (i0 < size) & (i1 < size) & (i2 < size)
    return (i0 * size + i1) * size + i2 if inside else -1.0, best, k0, k1, k2


@njit(cache=True)
def _nearest_d3(z0, z1, z2, table):
    """Slot and squared distance of :func:`_d3_round_k` (the lattice pass's rounding), for tests."""
    size = table.shape[0]
    idx, best, _k0, _k1, _k2 = _d3_round_k(z0, z1, z2, float(size // 2), float(size))
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

