"""Numba kernel of sequential pairwise diffusion (thesis 5.15); reference
:func:`unmesh.paint.background.diffuse_pairs_reference`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def diffuse_pairs(pi, pj, coef, vw, area, wet, props, km):  # pragma: no cover - numba
    """Exchange paint between the pairs in order (Gauss-Seidel, as the thesis' background process).

    For pair (i, j): ``dV = 1/2 (V_i/A_i - V_j/A_j) min(A_i, A_j) c`` moves from i to j (or back
    when negative); the receiver's wet colour mixes by (5.11) (RGB or Kubelka-Munk) and its
    ``props`` columns by volume. ``vw``, ``wet``, ``props`` are updated in place.
    """
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        ai = area[i]
        aj = area[j]
        dv = 0.5 * (vw[i] / ai - vw[j] / aj) * min(ai, aj) * coef[p]
        if dv == 0.0:
            continue
        if dv > 0.0:
            s = i
            r = j
        else:
            s = j
            r = i
            dv = -dv
        vr = vw[r]
        tot = vr + dv
        for c in range(3):
            if km:
                a = min(max(wet[r, c], 1e-4), 1.0)
                b = min(max(wet[s, c], 1e-4), 1.0)
                ka = (1.0 - a) * (1.0 - a) / (2.0 * a)
                kb = (1.0 - b) * (1.0 - b) / (2.0 * b)
                k = (vr * ka + dv * kb) / tot
                wet[r, c] = min(max(1.0 + k - np.sqrt(k * k + 2.0 * k), 0.0), 1.0)
            else:
                wet[r, c] = (vr * wet[r, c] + dv * wet[s, c]) / tot
        for c in range(props.shape[1]):
            props[r, c] = (vr * props[r, c] + dv * props[s, c]) / tot
        vw[s] -= dv
        vw[r] = tot
