"""Numba kernels of the full EWA splatting update by screen blocks (thesis 3.2, 3.2.1).

The tiled path (:mod:`unmesh.render._splat_kernels`) sets every surfel up in input order into
a parameter array, bins the pixel boxes into tiles, gathers the parameter rows into tile order
and splats each tile into tile-local buffers. A full update without clipping makes the same
fragments with less memory traffic:

1. :func:`block_count` (parallel over surfel chunks) counts the surfels of each screen block
   of ``2^shift`` rows by ``2^xshift`` columns (front-facing first) from a conservative pixel range of each
   surfel (:func:`_block_span`: a superset of the exact pixel box, cheap to compute);
2. :func:`block_setup` sets every surfel up once (:func:`~unmesh.render._splat_kernels._setup_row`,
   the tiled path's arithmetic) straight into its rows in block order, the pixel box of each
   copy clipped to its block (no parameter array in input order, no gather);
3. :func:`splat_blocks` (parallel over blocks; a block owns its pixels, so there are no write
   races) runs the tiled path's fragment loop and accumulation pass
   (:func:`~unmesh.render._splat_kernels._tile_pass`) for each block directly on the image
   buffers (no tile-local copies).

Within a pixel the fragments come in the tiled path's order (front-facing surfels first, then
ascending surfel index), so the sums are bit for bit those of
:func:`~unmesh.render._splat_kernels.splat_tiles`.
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

__all__ = ["block_count", "block_setup", "splat_blocks"]


@njit(cache=True, inline="always")
def _block_span(i, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift, xshift):
    """Block rows ``b0..b1`` and block columns ``t0..t1`` that may hold pixels of surfel ``i``
    (``b0 > b1``: none) and its group (0 facing the camera, as
    :func:`~unmesh.render._splat_kernels._setup_row`).

    A superset of the exact pixel box (:func:`~unmesh.render._splat_kernels._splat_box`):
    the bounding sphere of radius ``r`` (the radius; for elliptical surfels
    ``sqrt(|a1|^2 + |a2|^2)``, at least the largest semi-axis) united with the screen-filter
    disc, with a margin of 1e-3 pixels; the whole image when anything is not finite.
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
        return 0, (H - 1) >> shift, 0, (W - 1) >> xshift, gq
    if qc2 + rq <= near:
        return 1, 0, 1, 0, gq
    if ortho:  # the ellipse box's half extent is at most f r + 1e-3 pixels, the filter disc's rfilter
        ext = max(f * rq + 2e-3, rfilter + 1e-3)
        qsx = cx + f * qc0
        qsy = cy - f * qc1
        qx0 = max(math.ceil(qsx - ext - 0.5), 0)
        qx1 = min(math.floor(qsx + ext - 0.5), W - 1)
        qy0 = max(math.ceil(qsy - ext - 0.5), 0)
        qy1 = min(math.floor(qsy + ext - 0.5), H - 1)
    else:  # the projected centre is inside the sphere's box: padding it by rfilter covers the filter disc
        qx0, qx1, qy0, qy1 = sphere_box(qc0, qc1, qc2, rq, f, cx, cy, ortho, near, W, H, rfilter + 1e-3)
    if qx0 > qx1 or qy0 > qy1:
        return 1, 0, 1, 0, gq
    return qy0 >> shift, qy1 >> shift, qx0 >> xshift, qx1 >> xshift, gq


@njit(cache=True, parallel=True)
def block_count(pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift, xshift,
               nchunks):
    """Pass 1: ``offsets, starts, total`` of the (surfel, block) rows.

    Block ``t = by * ntx + bx`` (``ntx = ((W - 1) >> xshift) + 1``; pixel rows from ``by << shift``,
    columns from ``bx << xshift``, ``2^shift`` rows and ``2^xshift`` columns) holds rows ``offsets[t]:offsets[t+1]``:
    its front-facing surfels (group 0), then the others, each group in ascending surfel order;
    ``starts`` (nchunks, 2 * nblocks) int64 is where chunk ``c`` of the surfels writes its first
    row of each (block, group) slot (:func:`block_setup`).
    Arguments as :func:`~unmesh.render._splat_kernels.splat_setup`.
    """
    n = pos.shape[0]
    nblocks = (((H - 1) >> shift) + 1) * (((W - 1) >> xshift) + 1)
    nslot = 2 * nblocks
    counts = np.zeros((nchunks, nslot), dtype=np.int64)
    step = (n + nchunks - 1) // nchunks
    for c in prange(nchunks):  # a thin parallel loop over a plain function (see splat_tiles)
        _count_chunk(c * step, min(n, (c + 1) * step), pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy,
                     ortho, near, W, H, rfilter, shift, xshift, counts[c])
    offsets = np.zeros(nblocks + 1, dtype=np.int64)
    starts = np.zeros((nchunks, nslot), dtype=np.int64)
    total = 0
    for b in range(nblocks):
        offsets[b] = total
        for g in range(2):
            for c in range(nchunks):
                starts[c, 2 * b + g] = total
                total += counts[c, 2 * b + g]
    offsets[nblocks] = total
    return offsets, starts, total


@njit(cache=True, parallel=True)
def block_setup(pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift, xshift,
               starts, P, items):
    """Pass 2: the parameter rows ``P`` (total, NPARAM) and surfel indices ``items`` (total,)
    int32 in block order (``starts`` from :func:`block_count`, not changed); each block's copy
    of a row has its pixel box (columns 19-22) clipped to the block. Returns ``frag_offsets``
    (nblocks + 1,) int64: block ``t`` has at most ``frag_offsets[t+1] - frag_offsets[t]``
    pixels in its rows' boxes."""
    n = pos.shape[0]
    nchunks = starts.shape[0]
    nblocks = starts.shape[1] // 2
    step = (n + nchunks - 1) // nchunks
    area = np.zeros((nchunks, nblocks), dtype=np.int64)
    for c in prange(nchunks):
        _setup_chunk(c * step, min(n, (c + 1) * step), pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx,
                     cy, ortho, near, W, H, rfilter, shift, xshift, starts[c].copy(), P, items, area[c])
    frag_offsets = np.zeros(nblocks + 1, dtype=np.int64)
    for b in range(nblocks):
        frag_offsets[b + 1] = frag_offsets[b] + area[:, b].sum()
    return frag_offsets


@njit(cache=True)
def _count_chunk(lo, hi, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, shift, xshift,
                 counts):
    """Surfels ``lo:hi`` of :func:`block_count`: ``counts[2 * block + group] += 1`` per block met."""
    ntx = ((W - 1) >> xshift) + 1
    for i in range(lo, hi):
        b0, b1, t0, t1, g = _block_span(i, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W,
                                       H, rfilter, shift, xshift)
        for b in range(b0, b1 + 1):
            for t in range(t0, t1 + 1):
                counts[2 * (b * ntx + t) + g] += 1


@njit(cache=True)
def _setup_chunk(lo, hi, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter,
                 shift, xshift, slot, P, items, area):
    """Surfels ``lo:hi`` of :func:`block_setup`; ``slot`` the chunk's next row per (block, group)
    slot, ``area`` (nblocks,) gets the pixels of the clipped boxes."""
    ntx = ((W - 1) >> xshift) + 1
    for i in range(lo, hi):
        b0, b1, t0, t1, g = _block_span(i, pos, nrm, radii, axes, elliptical, frame, eye, f, cx, cy, ortho, near, W,
                                       H, rfilter, shift, xshift)
        if b0 > b1 or t0 > t1:
            continue
        j = -1
        for b in range(b0, b1 + 1):
            for t in range(t0, t1 + 1):
                q = 2 * (b * ntx + t) + g
                k = slot[q]
                slot[q] += 1
                if j < 0:
                    j = k
                    x0, x1, y0, y1, _g = _setup_row(i, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx,
                                                    cy, ortho, near, W, H, rfilter, P, j)
                else:
                    for m in range(P.shape[1]):
                        P[k, m] = P[j, m]
                items[k] = i
                left = max(x0, t << xshift)
                right = min(x1, ((t + 1) << xshift) - 1)
                top = max(y0, b << shift)
                bottom = min(y1, ((b + 1) << shift) - 1)
                P[k, 19] = left
                P[k, 20] = right
                P[k, 21] = top
                P[k, 22] = bottom
                if right >= left and bottom >= top:
                    area[b * ntx + t] += (right - left + 1) * (bottom - top + 1)


@njit(cache=True, parallel=True)
def splat_blocks(P, items, offsets, order, W, H, f, cx, cy, ortho, near, rfilter, kappa, eps_factor, eye, frame,
                zvis, acc_w, acc_c, acc_n, acc_z, count, frag_offsets, frag_q, frag_k, frag_rho, frag_z):
    """Visibility and accumulation passes of a full update, in parallel over the blocks.

    ``P``, ``items``, ``offsets``, ``frag_offsets`` from :func:`block_count` / :func:`block_setup`;
    ``order`` a permutation of the blocks. The image buffers are flat views: ``zvis``,
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
        _splat_block(offsets[b], offsets[b + 1], P, items, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa,
                    eps_factor, eye, frame, zvis, acc_w, acc_c, acc_n, acc_z, count, frag_q[fa:fb], frag_k[fa:fb],
                    frag_rho[fa:fb], frag_z[fa:fb])


@njit(cache=True)
def _splat_block(a, e, P, items, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa, eps_factor, eye, frame, zvis,
                acc_w, acc_c, acc_n, acc_z, count, frag_q, frag_k, frag_rho, frag_z):
    """Rows ``a:e`` (one block) of :func:`splat_blocks`: the tiled path's fragment loop over the
    whole image (the rows' boxes are already clipped to the block), recording, then
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
