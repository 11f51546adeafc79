"""Numba kernel of the brush's collision queries (thesis 5.4.1): exact k-nearest originals from
a candidate ball; reference :meth:`unmesh.spatial.KDTree.knn` (tests compare)."""

from __future__ import annotations

import numpy as np
from numba import njit

from unmesh.paint._buffer_kernels import _insert


@njit(cache=True)
def ball_knn(points, ids, queries, k, centre, radius, dist, idx, ok):  # pragma: no cover - numba
    """The ``k`` nearest of the candidate ``points`` (P, 3) (global ids ``ids``, ascending) of
    each query, sorted by (distance, id), distances ``sqrt`` of the squared differences summed
    in axis order (a candidate is skipped without its square root once its squared distance
    exceeds the k-th's by more than round-off, as in the paint buffer's grid search). The candidates are all points within ``radius`` of ``centre``; ``ok[q]`` says
    the answer is provably the global one (the k-th distance plus the query's distance from the
    centre stays below ``radius``, so every point outside is strictly farther)."""
    bd = np.empty(k)
    bi = np.empty(k, np.int64)
    for q in range(queries.shape[0]):
        m = 0
        lim = np.inf  # squared distances above this are certainly farther than the k-th
        for a in range(points.shape[0]):
            d = points[a, 0] - queries[q, 0]
            s = d * d
            d = points[a, 1] - queries[q, 1]
            s = s + d * d
            d = points[a, 2] - queries[q, 2]
            s = s + d * d
            if s > lim:
                continue
            m = _insert(bd, bi, m, k, np.sqrt(s), ids[a])
            if m == k:
                lim = bd[k - 1] * bd[k - 1] * (1.0 + 1e-12)
        e = 0.0
        for c in range(3):
            e += (queries[q, c] - centre[c]) ** 2
        ok[q] = m == k and bd[k - 1] + np.sqrt(e) < radius * (1.0 - 1e-9)
        for t in range(m):
            dist[q, t] = bd[t]
            idx[q, t] = bi[t]

