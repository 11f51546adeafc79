"""Numba kernels of normal estimation: neighbourhood covariance and MST orientation propagation.

- :func:`neighbour_covariances`: ``unmesh.surfels.normals.covariance_reference``; the smallest
  eigenvectors of the covariances are :func:`unmesh._linalg_kernels.smallest_eigenvectors`
  (``numpy.linalg.eigh``).
- :func:`kruskal_forest`: ``scipy.sparse.csgraph.minimum_spanning_tree``.
- :func:`propagate_orientation`: ``unmesh.surfels.normals.propagate_reference``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh._csr_kernels import counting_sort_csr


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
