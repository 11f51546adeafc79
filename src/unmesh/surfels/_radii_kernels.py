"""Numba kernel of the tangent-plane Voronoi covering radius of each surfel.

:func:`voronoi_radii`; reference ``unmesh.surfels.radii.voronoi_radii_reference``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

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
def voronoi_radii(points, normals, nbrs, clip, oriented, min_dot, reach):  # pragma: no cover - numba
    """Farthest vertex distance (N,) of each point's restricted Voronoi cell in its tangent plane.

    The cell of point i is the set of points p of its tangent plane that are
    closer (in 3-D) to x_i than to each valid neighbour x_j: the half-planes
    ``q'_j . (p - x_i) <= |x_j - x_i|^2 / 2`` (q'_j = tangential part of
    x_j - x_i), intersected with the regular ``CLIP_SIDES``-gon of inradius
    ``clip[i]``. Neighbours ``nbrs[i]`` (-1 = padding) count unless coincident or
    ``n_i . n_j <= min_dot`` (``|n_i . n_j|`` when not ``oriented``). Also returns
    whether the final cell touches the clip polygon (the cell is open there).

    ``reach`` (float; no default, so that every caller compiles the same signature): ``reach > 0``: a neighbour bounds the cell at its 3-D bisector but never beyond ``reach``
    times its own tangential offset (``c = min(|x_j - x_i|^2 / 2, reach |q'_j|^2)``): where the surface bends
    away faster than the spacing (a neighbour far below the tangent plane) the plain
    bisector lies far out in the plane, off the surface.
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
            if reach > 0.0:
                c = min(c, reach * (u * u + v * v))
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
