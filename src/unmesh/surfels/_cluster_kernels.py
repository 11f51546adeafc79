"""Numba kernels of hierarchical clustering for surfel simplification (Pauly, Gross, Kobbelt 2002).

:func:`cluster_split`; reference ``unmesh.surfels.simplify.cluster_reference``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

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
        # not by_normal (False here), a run-time bool: the literal False compiled a second _cluster_stats
        _, axis, _, c, _ = _cluster_stats(points, normals, not by_normal, perm, s0, s1)
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
        lam0, _, _, _, spread0 = _cluster_stats(points, normals, use_normals, perm, np.int64(0), n)
        size = np.int64(0)  # int64, not literals: one signature of the heap helpers
        key = lam0 * n * (SPREAD_WEIGHT if spread0 else 1.0) if n > 1 else -1.0
        size = _heap_push(keys, ids, size, key, np.int64(0))
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
