"""Numba kernels of the full EWA splatting update by row bands (thesis 3.2, 3.2.1).

The tiled path (:mod:`unmesh.render._splat_kernels`) sets every surfel up in input order,
bins the pixel boxes into tiles, gathers the parameter rows into tile order and splats each
tile into tile-local buffers. For a full update without clipping the same fragments are made
with less memory traffic:

1. :func:`band_count` (parallel over surfel chunks) counts the surfels of each band of
   ``band`` image rows (front-facing first), from a conservative row range of each surfel
   (:func:`_band_span`: a superset of the exact pixel box, cheap to compute);
2. :func:`band_setup` sets every surfel up once (:func:`~unmesh.render._splat_kernels._setup_row`,
   the tiled path's arithmetic) straight into its rows in band order, the pixel box of each
   copy clipped to its band;
3. :func:`splat_bands` (parallel over bands; a band owns its rows, so there are no write
   races) runs the tiled path's fragment loop and accumulation pass
   (:func:`~unmesh.render._splat_kernels._tile_pass`) over each band directly on the image
   buffers.

Within a pixel the fragments come in the tiled path's order (front-facing surfels first, then
ascending surfel index), so the sums are bit for bit those of :func:`splat_tiles`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.render._kernels import sphere_box
from unmesh.render._splat_kernels import (
    WORK_COLUMNS,
    _accumulate_records,
    _camera_point,
    _camera_vector,
    _setup_row,
    _tile_pass,
)

__all__ = ["band_count", "band_setup", "splat_bands"]


@njit(cache=True, inline="always")
def _band_span(i, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift):
    """Bands ``b0..b1`` that may hold pixels of surfel ``i`` (``b0 > b1``: none) and its group
    (0 facing the camera, as :func:`~unmesh.render._splat_kernels._setup_row`).

    A superset of the rows of the exact pixel box (:func:`~unmesh.render._splat_kernels._splat_box`):
    the bounding sphere of radius ``r`` (the radius; for elliptical surfels
    ``sqrt(|a1|^2 + |a2|^2)``, at least the largest semi-axis) widened by a pixel, united
    with the screen-filter disc; the whole image when anything is not finite.
    """
    qc0, qc1, qc2 = _camera_point(frame, eye, pos[i])
    qn0, qn1, qn2 = _camera_vector(frame, nrm[i])
    qfacing = qn2 if ortho else qc0 * qn0 + qc1 * qn1 + qc2 * qn2
    gq = 0 if qfacing <= 0.0 else 1
    if elliptical:
        rq = 0.0
        for qa in range(2):
            for qd in range(3):
                rq += axes[i, qa, qd] * axes[i, qa, qd]
        rq = math.sqrt(rq) * (1.0 + 1e-9)
    else:
        rq = radii[i] * (1.0 + 1e-9)
    if not (abs(rq) < 1e30 and abs(qc0) < 1e30 and abs(qc1) < 1e30 and abs(qc2) < 1e30):
        return 0, (H - 1) >> shift, gq
    # the projected centre is inside the sphere's box, so padding it by the filter radius
    # covers the screen-filter disc
    qx0, qx1, qy0, qy1 = sphere_box(qc0, qc1, qc2, rq, f, cx, cy, ortho, near, W, H, rfilter + 1.0)
    if qx0 > qx1 or qy0 > qy1:
        return 1, 0, gq
    return qy0 >> shift, qy1 >> shift, gq


@njit(cache=True, parallel=True)
def band_count(pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift,
               nchunks):
    """Pass 1: ``offsets, starts, total`` of the (surfel, band) rows.

    Band ``b`` (image rows ``b << shift`` to ``((b + 1) << shift) - 1``) holds rows
    ``offsets[b]:offsets[b+1]``: its front-facing surfels (group 0), then the others, each
    group in ascending surfel order; ``starts`` (nchunks, 2 * nbands) int64 is where chunk
    ``c`` of the surfels writes its first row of each (band, group) slot (:func:`band_setup`).
    Arguments as :func:`~unmesh.render._splat_kernels.splat_setup`.
    """
    n = pos.shape[0]
    nbands = ((H - 1) >> shift) + 1
    nslot = 2 * nbands
    counts = np.zeros((nchunks, nslot), dtype=np.int64)
    step = (n + nchunks - 1) // nchunks
    for c in prange(nchunks):  # a thin parallel loop over a plain function (see splat_tiles)
        _count_chunk(c * step, min(n, (c + 1) * step), pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy,
                     ortho, near, W, H, rfilter, shift, counts[c])
    offsets = np.zeros(nbands + 1, dtype=np.int64)
    starts = np.zeros((nchunks, nslot), dtype=np.int64)
    total = 0
    for b in range(nbands):
        offsets[b] = total
        for g in range(2):
            for c in range(nchunks):
                starts[c, 2 * b + g] = total
                total += counts[c, 2 * b + g]
    offsets[nbands] = total
    return offsets, starts, total


@njit(cache=True, parallel=True)
def band_setup(pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift,
               starts, P, items):
    """Pass 2: the parameter rows ``P`` (total, NPARAM) and surfel indices ``items`` (total,)
    int32 in band order (``starts`` from :func:`band_count`, not changed); each band's copy of
    a row has its pixel box (columns 21, 22) clipped to the band's rows. Returns
    ``frag_offsets`` (nbands + 1,) int64: band ``b`` has at most
    ``frag_offsets[b+1] - frag_offsets[b]`` pixels in its rows' boxes."""
    n = pos.shape[0]
    nchunks = starts.shape[0]
    nbands = starts.shape[1] // 2
    step = (n + nchunks - 1) // nchunks
    area = np.zeros((nchunks, nbands), dtype=np.int64)
    for c in prange(nchunks):
        _setup_chunk(c * step, min(n, (c + 1) * step), pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx,
                     cy, ortho, near, W, H, rfilter, shift, starts[c].copy(), P, items, area[c])
    frag_offsets = np.zeros(nbands + 1, dtype=np.int64)
    for b in range(nbands):
        frag_offsets[b + 1] = frag_offsets[b] + area[:, b].sum()
    return frag_offsets


@njit(cache=True)
def _count_chunk(lo, hi, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift,
                 counts):
    """Surfels ``lo:hi`` of :func:`band_count`: ``counts[2 * band + group] += 1`` per band met."""
    for i in range(lo, hi):
        b0, b1, g = _band_span(i, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H,
                               rfilter, shift)
        for b in range(b0, b1 + 1):
            counts[2 * b + g] += 1


@njit(cache=True)
def _setup_chunk(lo, hi, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter,
                 shift, slot, P, items, area):
    """Surfels ``lo:hi`` of :func:`band_setup`; ``slot`` the chunk's next row per (band, group)
    slot, ``area`` (nbands,) gets the pixels of the clipped boxes."""
    for i in range(lo, hi):
        b0, b1, g = _band_span(i, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H,
                               rfilter, shift)
        if b0 > b1:
            continue
        j = slot[2 * b0 + g]
        slot[2 * b0 + g] += 1
        x0, x1, y0, y1, _g = _setup_row(i, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy,
                                        ortho, near, W, H, rfilter, P, j)
        items[j] = i
        wide = x1 - x0 + 1
        for b in range(b0 + 1, b1 + 1):
            k = slot[2 * b + g]
            slot[2 * b + g] += 1
            for m in range(P.shape[1]):
                P[k, m] = P[j, m]
            items[k] = i
            top = max(y0, b << shift)
            bottom = min(y1, ((b + 1) << shift) - 1)
            P[k, 21] = top
            P[k, 22] = bottom
            if wide > 0 and bottom >= top:
                area[b] += wide * (bottom - top + 1)
        top = max(y0, b0 << shift)
        bottom = min(y1, ((b0 + 1) << shift) - 1)
        P[j, 21] = top
        P[j, 22] = bottom
        if wide > 0 and bottom >= top:
            area[b0] += wide * (bottom - top + 1)


@njit(cache=True, parallel=True)
def splat_bands(P, items, offsets, order, W, H, f, cx, cy, ortho, near, rfilter, kappa, eps_factor, eye, frame,
                zvis, acc_w, acc_c, acc_n, acc_z, count, frag_offsets, frag_q, frag_k, frag_rho, frag_z):
    """Visibility and accumulation passes of a full update, in parallel over the bands.

    ``P``, ``items``, ``offsets``, ``frag_offsets`` from :func:`band_count` / :func:`band_setup`;
    ``order`` a permutation of the bands. The image buffers are flat views: ``zvis``,
    ``acc_w``, ``acc_z`` (H*W,) float64, ``acc_c``, ``acc_n`` (H*W, 3) float64, ``count``
    (H*W,) int32; the sums must be zero (a cleared renderer) and ``zvis`` holds the opaque
    depth. ``frag_*`` (frag_offsets[-1],) work arrays (int32, int64, float64, float64).
    """
    invf = 1.0 / f
    inv_rf2 = 1.0 / (rfilter * rfilter) if rfilter > 0.0 else np.inf
    for kk in prange(order.shape[0]):
        b = order[kk]
        fa = frag_offsets[b]
        fb = frag_offsets[b + 1]
        _splat_band(offsets[b], offsets[b + 1], P, items, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa,
                    eps_factor, eye, frame, zvis, acc_w, acc_c, acc_n, acc_z, count, frag_q[fa:fb], frag_k[fa:fb],
                    frag_rho[fa:fb], frag_z[fa:fb])


@njit(cache=True)
def _splat_band(a, e, P, items, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa, eps_factor, eye, frame, zvis,
                acc_w, acc_c, acc_n, acc_z, count, frag_q, frag_k, frag_rho, frag_z):
    """Rows ``a:e`` (one band) of :func:`splat_bands`: the tiled path's fragment loop over the
    whole image (the rows' boxes are already clipped to the band), recording, then
    accumulating."""
    if a == e:
        return
    no_off = np.zeros(1, dtype=np.int64)
    no_planes = np.zeros((0, 4))
    no_mode = np.zeros(1, dtype=np.int8)
    work = np.empty((1, WORK_COLUMNS))
    nrec = _tile_pass(0, P, items, a, e, 0, 0, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa, eps_factor, 1.0,
                      False, eye, frame, no_off, no_planes, no_mode, None, None, work, zvis, acc_w, acc_c, acc_n,
                      acc_z, count, frag_q, frag_k, frag_rho, frag_z)
    _accumulate_records(nrec, P, kappa, 1.0, zvis, acc_w, acc_c, acc_n, acc_z, count, frag_q, frag_k, frag_rho,
                        frag_z)
