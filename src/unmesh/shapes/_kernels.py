"""Numba kernels of the procedural shapes.

- :func:`blob_eval`: the blob's smooth-union implicit function and unit gradient
  (numpy reference: ``unmesh.shapes.blob._blob_unit``).
- The triangle BVH of mesh shapes lives in ``unmesh.spatial._bvh_kernels``
  (:class:`unmesh.spatial.TriangleBVH`).
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
