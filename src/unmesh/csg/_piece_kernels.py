"""Numba kernel of the pieces of a patch (4.1.2): connected components of its overlapping
surfels with the edge surfels removed. The reference is
:func:`unmesh.csg.frame.pieces_reference` (scipy's connected components); a test compares them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["piece_labels"]


@njit(cache=True)
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def piece_labels(n, pairs, edge):
    """Labels (n,) int64 of the connected components of the graph on ``n`` surfels with edges
    ``pairs`` (P, 2) int64, the surfels where ``edge`` (n,) bool removed (label -1); components
    numbered 0, 1, ... in the order of their lowest surfel. Returns ``(labels, count)``."""
    parent = np.arange(n)
    for q in range(pairs.shape[0]):
        a = pairs[q, 0]
        b = pairs[q, 1]
        if edge[a] or edge[b]:
            continue
        ra = _root(parent, a)
        rb = _root(parent, b)
        if ra != rb:
            if ra < rb:
                parent[rb] = ra
            else:
                parent[ra] = rb
    labels = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):
        if edge[i]:
            continue
        r = _root(parent, i)
        if labels[r] < 0:
            labels[r] = count
            count += 1
        labels[i] = labels[r]
    return labels, count
