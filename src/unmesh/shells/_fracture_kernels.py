"""Numba kernels of the fracture criterion (thesis 7.24): the per-step scan and the candidate fibers.

:func:`fracture_scan` counts the fibers over a threshold and the degenerate fibers each step;
:func:`fiber_excess` lists the fibers over their threshold with the excess. Reference:
:func:`unmesh.shells.fracture.fracture_candidates` (the same arithmetic in numpy).
"""

from __future__ import annotations

import math

from numba import njit, prange

from unmesh.shells._fiber_kernels import degenerate


@njit(cache=True, parallel=True)
def fracture_scan(x, fibers, s, soft, lengths, angles, rest_length, rest_angle, gamma_s, gamma_b, ratio2):
    """Cheap per-step test: (fibers over a fracture threshold (7.24), degenerate fibers).

    ratio2 is the squared ratio below which an end tangent, projected as the tangent angle
    sees it (with the umbrella vectors ``s`` (N, 3) and regularisation ``soft`` (N,) of the
    centres), counts as vanished relative to the centre tangent (0 disables that test;
    :func:`unmesh.shells.fibers.degenerate`). Parallel over fibers (integer reductions).
    """
    over = 0
    bad = 0
    for k in prange(fibers.shape[0]):
        if lengths[k] > rest_length[k] * (1.0 + gamma_s[k]) or abs(angles[k] - rest_angle[k]) > gamma_b[k]:
            over += 1
        i = fibers[k, 1]
        if ratio2 > 0.0 and degenerate(x, fibers[k, 0], i, fibers[k, 2], s[i, 0], s[i, 1], s[i, 2], soft[i], ratio2):
            bad += 1
    return over, bad


@njit(cache=True, error_model="numpy")
def fiber_excess(lengths, angles, lorig, lplast, aorig, aplast, gamma_s, gamma_b, out_index, out_excess):
    """Fibers with ``max(strain / gamma_s, |dtheta| / gamma_b) > 1`` (7.24) and that excess, in fiber order.

    The arithmetic of :func:`unmesh.shells.fracture.fracture_candidates` (non-finite
    thresholds count 0, NaN 0, infinities the largest float); returns the count.
    """
    big = 1.7976931348623157e308
    m = 0
    for k in range(lengths.shape[0]):
        es = 0.0
        if math.isfinite(gamma_s[k]):
            es = (lengths[k] / (lorig[k] + lplast[k]) - 1.0) / gamma_s[k]
        eb = 0.0
        if math.isfinite(gamma_b[k]):
            eb = abs(angles[k] - (aorig[k] + aplast[k])) / gamma_b[k]
        es = 0.0 if math.isnan(es) else min(max(es, -big), big)
        eb = 0.0 if math.isnan(eb) else min(max(eb, -big), big)
        e = max(es, eb)
        if e > 1.0:
            out_index[m] = k
            out_excess[m] = e
            m += 1
    return m
