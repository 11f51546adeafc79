"""The row kernels of painting (visible colour of rows, surfel gather and scatter for the view's
full updates) against their numpy references."""

from __future__ import annotations

import numpy as np

from unmesh.paint._paint_kernels import gather_surfels, scatter_surfels, visible_colors_rows
from unmesh.paint.surface import visible_colors


def test_visible_colors_rows_equals_the_numpy_reference():
    rng = np.random.default_rng(5)
    n = 500
    wet, dry, base = rng.random((n, 3)), rng.random((n, 3)), rng.random((n, 3))
    vw, vd = rng.random(n) * rng.integers(0, 2, n), rng.random(n) * 2
    rho, area = rng.random(n) * 3, rng.random(n) + 0.1
    idx = rng.permutation(n)[:300]
    out = np.empty((len(idx), 3))
    visible_colors_rows(idx, wet, dry, vw, rho, area, vd, base, out)
    ref = visible_colors(wet[idx], dry[idx], vw[idx], rho[idx], area[idx], vd[idx], base[idx])
    np.testing.assert_array_equal(out, ref)


def test_gather_and_scatter_surfels_equal_fancy_indexing():
    rng = np.random.default_rng(6)
    n = 400
    pos, nrm, rad, col = rng.random((n, 3)), rng.random((n, 3)), rng.random(n), rng.random((n, 3))
    idx = rng.permutation(n)[:250].astype(np.int64)
    p, q, r = np.empty((250, 3)), np.empty((250, 3)), np.empty(250)
    gather_surfels(idx, pos, nrm, rad, p, q, r)
    np.testing.assert_array_equal(p, pos[idx])
    np.testing.assert_array_equal(q, nrm[idx])
    np.testing.assert_array_equal(r, rad[idx])
    to = [np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3))]
    scatter_surfels(idx, p, q, r, col[idx], *to)
    ref = [np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3))]
    for dst, src in zip(ref, (pos, nrm, rad, col), strict=True):
        dst[idx] = src[idx]
    for a, b in zip(to, ref, strict=True):
        np.testing.assert_array_equal(a, b)
