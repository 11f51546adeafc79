"""Numba kernel of sequential pairwise diffusion (thesis 5.15); reference
:func:`unmesh.paint.background.diffuse_pairs_reference`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


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


@njit(cache=True, parallel=True)
def visible_colors_rows(idx, wet, dry, vw, rho, area, vd, base, out):  # pragma: no cover - numba
    """``out[k]`` = visible colour (5.8) of row ``idx[k]``: the gather and
    :func:`unmesh.paint.surface.visible_colors` (its reference, same operations) in one pass."""
    for k in prange(idx.shape[0]):
        i = idx[k]
        alpha = min(rho[i] * vw[i] / area[i], 1.0)
        beta = min(rho[i] * vd[i] / area[i], 1.0)
        for c in range(3):
            d = beta * dry[i, c] + (1.0 - beta) * base[i, c]
            out[k, c] = min(max(alpha * wet[i, c] + (1.0 - alpha) * d, 0.0), 1.0)


@njit(cache=True, parallel=True)
def gather_surfels(idx, pos, nrm, rad, out_pos, out_nrm, out_rad):  # pragma: no cover - numba
    """``out_pos[k] = pos[idx[k]]`` (and normals, radii) in one parallel pass."""
    for k in prange(idx.shape[0]):
        i = idx[k]
        for c in range(3):
            out_pos[k, c] = pos[i, c]
            out_nrm[k, c] = nrm[i, c]
        out_rad[k] = rad[i]


@njit(cache=True, parallel=True)
def scatter_surfels(idx, pos, nrm, rad, col, to_pos, to_nrm, to_rad, to_col):  # pragma: no cover - numba
    """``to_pos[idx[k]] = pos[k]`` (and normals, radii, colours) in one parallel pass; ``idx`` unique."""
    for k in prange(idx.shape[0]):
        i = idx[k]
        for c in range(3):
            to_pos[i, c] = pos[k, c]
            to_nrm[i, c] = nrm[k, c]
            to_col[i, c] = col[k, c]
        to_rad[i] = rad[k]
