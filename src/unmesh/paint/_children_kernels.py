"""Numba kernels of the father -> children lists of a paintable surface (thesis 5.3): doubly
linked lists in row arrays (``head``/``tail`` per original, ``nxt``/``prv``/``linked`` per row),
each list in ascending row order. The plain reference is the dict of lists these replaced
(``tests/paint/test_children.py`` keeps it and compares)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _append(r, f, head, tail, nxt, prv, linked):  # pragma: no cover - numba
    """Append row ``r`` to the end of father ``f``'s list."""
    t = tail[f]
    prv[r] = t
    nxt[r] = -1
    if t >= 0:
        nxt[t] = r
    else:
        head[f] = r
    tail[f] = r
    linked[r] = True


@njit(cache=True)
def link_rows(rows, father, head, tail, nxt, prv, linked):  # pragma: no cover - numba
    """Append each of ``rows`` (ascending, larger than every linked row of its father) to the
    end of its father's list."""
    for r in rows:
        _append(r, father[r], head, tail, nxt, prv, linked)


@njit(cache=True)
def unlink_rows(rows, father, head, tail, nxt, prv, linked):  # pragma: no cover - numba
    """Remove each linked row of ``rows`` from its father's list (others are left alone)."""
    for r in rows:
        if not linked[r]:
            continue
        f = father[r]
        p = prv[r]
        q = nxt[r]
        if p >= 0:
            nxt[p] = q
        else:
            head[f] = q
        if q >= 0:
            prv[q] = p
        else:
            tail[f] = p
        linked[r] = False


@njit(cache=True)
def relink_all(n, father, alive, head, tail, nxt, prv, linked):  # pragma: no cover - numba
    """Rebuild every list from the arrays: rows ``< n`` that are alive and not their own father."""
    head[:] = -1
    tail[:] = -1
    linked[:] = False
    for r in range(n):
        if alive[r] and father[r] != r:
            _append(r, father[r], head, tail, nxt, prv, linked)


@njit(cache=True)
def gather_children(fathers, head, nxt):  # pragma: no cover - numba
    """The linked children of ``fathers``, father by father, each list in order, (K,) int64."""
    m = 0
    for f in fathers:
        c = head[f]
        while c >= 0:
            m += 1
            c = nxt[c]
    out = np.empty(m, np.int64)
    m = 0
    for f in fathers:
        c = head[f]
        while c >= 0:
            out[m] = c
            m += 1
            c = nxt[c]
    return out
