"""Numba kernel of the brush's spring forces (thesis 5.1); reference
:func:`unmesh.paint.brush.spring_forces_reference` (the same operations in the same order;
tests compare bit for bit)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def spring_forces(x, h, springs, rest, stiffness, out):  # pragma: no cover - numba
    """``out`` (A + H, 3) = the spring forces (5.1) on the active masses ``x`` (A, 3) and the
    handle points ``h`` (H, 3): ``K_s (l - l_0) / l (x_j - x_i)`` on ``i``, its negative on
    ``j``, added spring by spring (all ``i`` ends first, then all ``j`` ends)."""
    na = x.shape[0]
    ns = springs.shape[0]
    f = np.empty((ns, 3))
    for s in range(ns):
        i = springs[s, 0]
        j = springs[s, 1]
        d2 = 0.0
        for c in range(3):
            a = x[i, c] if i < na else h[i - na, c]
            b = x[j, c] if j < na else h[j - na, c]
            f[s, c] = b - a
            d2 += f[s, c] * f[s, c]
        ln = max(np.sqrt(d2), 1e-300)
        coef = stiffness * (ln - rest[s]) / ln
        for c in range(3):
            f[s, c] = coef * f[s, c]
    out[:] = 0.0
    for s in range(ns):
        for c in range(3):
            out[springs[s, 0], c] += f[s, c]
    for s in range(ns):
        for c in range(3):
            out[springs[s, 1], c] += -f[s, c]
