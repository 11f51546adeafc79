"""Numba kernels of EWA surface splatting (thesis 3.2), tiled and parallel.

Pipeline (all camera conventions as in :mod:`unmesh.render._kernels`):

1. :func:`splat_setup` (parallel over surfels) writes per-surfel parameters ``P`` (N, NPARAM)
   and a pixel box (N, 4).
2. :func:`unmesh.render._kernels.bin_boxes` buckets surfels into screen tiles (front-facing
   surfels first); :func:`splat_setup_bin` fuses steps 1 and 2 into one pass. Each tile of
   step 3 copies its pairs' parameter rows into a tile-local array first (so its passes read
   them contiguously; :func:`gather_rows` is that copy for all pairs at once).
3. :func:`splat_tiles` (parallel over tiles; a tile owns its pixels, so there are no write
   races) runs the visibility pass (extended depth test, 3.2.1: the buffer keeps
   ``min(z_f + eps_s)``; fragments that may still pass are recorded) and the accumulation pass
   (``sum w``, ``sum w c``, ``sum w n``, ``sum w z`` of the recorded fragments with
   ``z_f <= zvis``) on tile-local buffers.
4. :func:`splat_resolve` normalises (third pass).

Every fragment is generated in one loop, :func:`_tile_pass`, which knows the surfel index ``s``
and the fragment's position: that is where per-fragment clipping (chapter 4, clipped splatting)
happens; today it evaluates per-surfel clip planes (:func:`_keep`). Partial updates (5.7) use
the same loop in its direct-accumulation mode, so their contributions are bit-identical.

Fragment model (perspective-correct ray-splat intersection with an approximate EWA prefilter,
after Botsch et al. 2004/2005 and Zwicker et al. 2001): the pixel ray meets the surfel plane at
local coordinates ``(u, v)`` in units of the semi-axes, ``rho3 = u^2 + v^2``; the screen-space
low-pass filter contributes ``rho2 = |pixel - projected centre|^2 / r_f^2`` (for surfels seen
edge-on an ellipse, ``r_f`` across their outline and up to one pixel along it, :func:`_filter_form`);
the fragment exists when ``rho = min(rho3, rho2) < 1`` and weighs ``w = exp(-kappa rho)`` (a
clipped Gaussian).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.render._kernels import load_tile, sphere_box, tile_rect

__all__ = ["NPARAM", "fill_tiles", "gather_rows", "splat_resolve", "splat_setup", "splat_setup_bin", "splat_tiles"]

#: Parameter layout of one (surfel, tile) pair (rows written in tile order):
#: 0 cz, 1-3 n (camera), 4 c.n, 5-7 b1 = a1/|a1|^2, 8-10 b2 = a2/|a2|^2, 11 c.b1, 12 c.b2
#: (``inf`` for degenerate ellipses, which then only reach pixels through the screen filter),
#: 13-14 projected centre (col, row), 15 radius, 16-18 colour, 19-22 pixel box x0, x1, y0, y1,
#: 23 depth range ``zr`` of the surfel's fragments (negative: seen edge-on, see :func:`_fragment`).
NPARAM = 24
#: ``log2(t)`` at index ``t`` for the powers of two up to 1024 (tile edges; 0 elsewhere).
TILE_SHIFTS = np.array([(t.bit_length() - 1) if t & (t - 1) == 0 else 0 for t in range(1025)], dtype=np.int64)
#: Surfels whose normal is more than ``atan(EDGE_ON_TAN)`` (76 degrees) from the view ray through
#: their centre are "edge-on": where their screen filter wins, fragments take the centre depth.
EDGE_ON_TAN = 4.0
#: Largest reach (pixels) of an edge-on surfel's screen filter along its projected major axis
#: (:func:`_filter_form`): the former one-pixel disc. With a filter radius of 0.71 across, a sheet
#: seen edge-on half a pixel off a row of pixel centres is then a closed line for samples up to
#: 1.42 pixels apart (a 0.71 disc: 1.0; tests/render/test_splat.py has 1.28).
EDGE_FILTER_REACH = 1.0


@njit(cache=True)
def _camera_point(frame, eye, p):
    qx = p[0] - eye[0]
    qy = p[1] - eye[1]
    qz = p[2] - eye[2]
    return (frame[0, 0] * qx + frame[0, 1] * qy + frame[0, 2] * qz,
            frame[1, 0] * qx + frame[1, 1] * qy + frame[1, 2] * qz,
            frame[2, 0] * qx + frame[2, 1] * qy + frame[2, 2] * qz)


@njit(cache=True)
def _camera_vector(frame, v):
    return (frame[0, 0] * v[0] + frame[0, 1] * v[1] + frame[0, 2] * v[2],
            frame[1, 0] * v[0] + frame[1, 1] * v[1] + frame[1, 2] * v[2],
            frame[2, 0] * v[0] + frame[2, 1] * v[1] + frame[2, 2] * v[2])


@njit(cache=True, inline="always")
def _splat_box(c0, c1, c2, r, a00, a01, a02, a10, a11, a12, f, cx, cy, ortho, near, W, H, rfilter, rfy):
    """Pixel box of a surfel (inclusive ranges; ``x0 > x1`` when invisible).

    The intersection of two conservative boxes: the bounding sphere's exact box and the box of
    the ellipse ``{c + u a1 + v a2 : u^2 + v^2 <= 1}`` under the projection linearised at the
    centre, widened by a bound ``err`` on the second-order remainder (skipped for splats larger
    than a quarter of their depth); then united with the box of the screen filter around the
    projected centre: half-widths ``rfilter`` along x and ``rfy`` along y (the disc's radius, or
    an edge-on surfel's filter ellipse, :func:`_filter_form`).
    """
    if c2 + r <= near:
        return 1, 0, 1, 0
    if ortho:
        x0, x1, y0, y1 = 0, W - 1, 0, H - 1  # the ellipse box below is exact in orthographic views
    else:
        x0, x1, y0, y1 = sphere_box(c0, c1, c2, r, f, cx, cy, ortho, near, W, H, 0.0)
    if ortho or c2 > near:
        if ortho:
            sx = cx + f * c0
            sy = cy - f * c1
            hx = f * math.sqrt(a00 * a00 + a10 * a10) + 1e-3
            hy = f * math.sqrt(a01 * a01 + a11 * a11) + 1e-3
        else:
            iz = 1.0 / c2
            sx = cx + f * c0 * iz
            sy = cy - f * c1 * iz
            q = r * iz
            if q < 0.25:
                j0 = c0 * iz
                j1 = c1 * iz
                ex = a00 - j0 * a02
                ey = a01 - j1 * a02
                fx = a10 - j0 * a12
                fy = a11 - j1 * a12
                err = 2.0 * f * (1.0 + abs(j0) + abs(j1)) * q * q / (1.0 - q) + 1e-3
                hx = f * iz * math.sqrt(ex * ex + fx * fx) + err
                hy = f * iz * math.sqrt(ey * ey + fy * fy) + err
            else:
                hx = 1e30
                hy = 1e30
        if x0 <= x1 and y0 <= y1 and hx < 1e29:
            x0 = max(x0, math.ceil(max(sx - hx, -2.0) - 0.5))
            x1 = min(x1, math.floor(min(sx + hx, W + 2.0) - 0.5))
            y0 = max(y0, math.ceil(max(sy - hy, -2.0) - 0.5))
            y1 = min(y1, math.floor(min(sy + hy, H + 2.0) - 0.5))
        if rfilter > 0.0 and abs(sx) < 1e9 and abs(sy) < 1e9:
            fx0 = max(math.ceil(max(sx - rfilter, -2.0) - 0.5), 0)
            fx1 = min(math.floor(min(sx + rfilter, W + 2.0) - 0.5), W - 1)
            fy0 = max(math.ceil(max(sy - rfy, -2.0) - 0.5), 0)
            fy1 = min(math.floor(min(sy + rfy, H + 2.0) - 0.5), H - 1)
            if fx0 <= fx1 and fy0 <= fy1:
                if x0 > x1 or y0 > y1:
                    return fx0, fx1, fy0, fy1
                return min(x0, fx0), max(x1, fx1), min(y0, fy0), max(y1, fy1)
    return x0, x1, y0, y1


@njit(cache=True, inline="always")
def _filter_form(c0, c1, c2, r, a00, a01, a02, a10, a11, a12, f, ortho, near, rfilter):
    """Screen filter of an edge-on surfel: ``rho2 = qxx ex^2 + 2 qxy ex ey + qyy ey^2`` for the
    offset ``(ex, ey)`` (pixels) of a pixel centre from the projected centre, and the half-widths
    ``hfx, hfy`` of its box.

    An ellipse with semi-axes ``rfilter`` across the surfel's projection (along its projected
    normal, i.e. across the outline it lies on) and ``min(sqrt(a^2 + rfilter^2),
    EDGE_FILTER_REACH)``, at least ``rfilter``, along its projected major semi-axis ``a`` (the
    reach of the EWA resampling ellipse ``J J^T + rfilter^2 I`` of Zwicker et al. 2001 along
    that axis, at most the former one-pixel disc). The thin ellipse of an edge-on surfel meets
    few pixel centres, so the filter draws the outline: it has to bridge neighbouring surfels
    along the outline, but should not reach further past it than any other splat's filter.
    ``J`` is the projection of the axes linearised at the centre; perspective splats larger
    than a quarter of their depth keep the disc (the linearisation does not hold there).
    """
    i2 = 1.0 / (rfilter * rfilter)
    if ortho:
        sc = f
        j0 = 0.0
        j1 = 0.0
    elif c2 > near and r < 0.25 * c2:
        sc = f / c2
        j0 = c0 / c2
        j1 = c1 / c2
    else:
        return i2, 0.0, i2, rfilter, rfilter
    # screen images (x right, y down) of the two axes, and their second moments J J^T
    p1x = sc * (a00 - j0 * a02)
    p1y = -sc * (a01 - j1 * a02)
    p2x = sc * (a10 - j0 * a12)
    p2y = -sc * (a11 - j1 * a12)
    sxx = p1x * p1x + p2x * p2x
    syy = p1y * p1y + p2y * p2y
    sxy = p1x * p1y + p2x * p2y
    hd = 0.5 * (sxx - syy)
    root = math.sqrt(hd * hd + sxy * sxy)
    lam = 0.5 * (sxx + syy) + root  # a^2
    if not (lam > 0.0) or not (lam < np.inf):
        return i2, 0.0, i2, rfilter, rfilter
    if hd >= 0.0:  # unit major direction (ux, uy), numerically stable branch
        ux = hd + root
        uy = sxy
    else:
        ux = sxy
        uy = root - hd
    ln = math.sqrt(ux * ux + uy * uy)
    if not (ln > 0.0):
        return i2, 0.0, i2, rfilter, rfilter
    ux /= ln
    uy /= ln
    along = max(rfilter, min(math.sqrt(lam + rfilter * rfilter), EDGE_FILTER_REACH))
    ia = 1.0 / (along * along)
    qxx = ia * ux * ux + i2 * uy * uy
    qyy = ia * uy * uy + i2 * ux * ux
    qxy = (ia - i2) * ux * uy
    hfx = math.sqrt(along * along * ux * ux + rfilter * rfilter * uy * uy)
    hfy = math.sqrt(along * along * uy * uy + rfilter * rfilter * ux * ux)
    return qxx, qxy, qyy, hfx, hfy


@njit(cache=True)
def _edge_form(Pt, k, f, cx, cy, ortho, near, inv_rf2):
    """``qxx, qxy, qyy`` of :func:`_filter_form` for the surfel of parameter row ``Pt[k]`` (valid
    ellipse): the axes are recovered from their dual basis (``a_i = sum_j (H^-1)_ij b_j`` with
    ``H`` the Gram matrix of ``b1, b2``) and the centre from its projection. Computed per
    (surfel, tile) pair of the few edge-on surfels, so that ``P`` needs no extra columns."""
    b1x, b1y, b1z = np.float64(Pt[k, 5]), np.float64(Pt[k, 6]), np.float64(Pt[k, 7])
    b2x, b2y, b2z = np.float64(Pt[k, 8]), np.float64(Pt[k, 9]), np.float64(Pt[k, 10])
    h11 = b1x * b1x + b1y * b1y + b1z * b1z
    h22 = b2x * b2x + b2y * b2y + b2z * b2z
    h12 = b1x * b2x + b1y * b2y + b1z * b2z
    det = h11 * h22 - h12 * h12
    if not (det > 0.0):
        return inv_rf2, 0.0, inv_rf2
    i11 = h22 / det
    i22 = h11 / det
    i12 = -h12 / det
    a00 = i11 * b1x + i12 * b2x
    a01 = i11 * b1y + i12 * b2y
    a02 = i11 * b1z + i12 * b2z
    a10 = i12 * b1x + i22 * b2x
    a11 = i12 * b1y + i22 * b2y
    a12 = i12 * b1z + i22 * b2z
    cz = np.float64(Pt[k, 0])
    sx = np.float64(Pt[k, 13])
    sy = np.float64(Pt[k, 14])
    if ortho:
        c0 = (sx - cx) / f
        c1 = (cy - sy) / f
    else:
        c0 = (sx - cx) * cz / f
        c1 = (cy - sy) * cz / f
    qxx, qxy, qyy, _, _ = _filter_form(c0, c1, cz, np.float64(Pt[k, 15]), a00, a01, a02, a10, a11, a12, f, ortho,
                                       near, 1.0 / math.sqrt(inv_rf2))
    return qxx, qxy, qyy


@njit(cache=True, inline="always")
def _setup_row(i, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H,
               rfilter, P, j):
    """The parameters of surfel ``i`` written to ``P[j]``; returns its pixel box ``x0, x1, y0, y1``
    (inclusive, ``x0 > x1`` or ``y0 > y1`` when invisible) and its group (0 facing the camera)."""
    c0, c1, c2 = _camera_point(frame, eye, pos[i])
    n0, n1, n2 = _camera_vector(frame, nrm[i])
    if elliptical:
        a00, a01, a02 = _camera_vector(frame, axes[i, 0])
        a10, a11, a12 = _camera_vector(frame, axes[i, 1])
    else:
        rad = radii[i]
        sg = 1.0 if n2 >= 0.0 else -1.0
        aa = -1.0 / (sg + n2)
        bb = n0 * n1 * aa
        a00 = (1.0 + sg * n0 * n0 * aa) * rad
        a01 = sg * bb * rad
        a02 = -sg * n0 * rad
        a10 = bb * rad
        a11 = (sg + n1 * n1 * aa) * rad
        a12 = -n1 * rad
    # dual basis b1, b2 of the (possibly non-orthogonal) axes: b_i . a_j = delta_ij in the
    # surfel plane, so (u, v) = ((p - c) . b1, (p - c) . b2) are the ellipse coordinates of
    # {c + u a1 + v a2 : u^2 + v^2 <= 1}; for orthogonal axes b_i = a_i / |a_i|^2 (eq. 3.13).
    if not elliptical:  # orthogonal axes of length rad: b_i = a_i / rad^2
        rad = radii[i]
        r = rad
        valid = rad * rad > 1e-300
        ir2 = 1.0 / (rad * rad) if valid else 0.0
        b10 = a00 * ir2
        b11 = a01 * ir2
        b12 = a02 * ir2
        b20 = a10 * ir2
        b21 = a11 * ir2
        b22 = a12 * ir2
    else:
        g00 = a00 * a00 + a01 * a01 + a02 * a02
        g11 = a10 * a10 + a11 * a11 + a12 * a12
        g01 = a00 * a10 + a01 * a11 + a02 * a12
        det = g00 * g11 - g01 * g01
        tr = g00 + g11
        valid = g00 > 1e-300 and g11 > 1e-300 and det > 1e-12 * tr * tr
        hd = 0.5 * (g00 - g11)
        r = math.sqrt(0.5 * tr + math.sqrt(hd * hd + g01 * g01))  # largest semi-axis
    if elliptical and valid:
        idet = 1.0 / det
        b10 = (g11 * a00 - g01 * a10) * idet
        b11 = (g11 * a01 - g01 * a11) * idet
        b12 = (g11 * a02 - g01 * a12) * idet
        b20 = (g00 * a10 - g01 * a00) * idet
        b21 = (g00 * a11 - g01 * a01) * idet
        b22 = (g00 * a12 - g01 * a02) * idet
    elif elliptical:
        b10 = b11 = b12 = b20 = b21 = b22 = 0.0
    P[j, 0] = c2
    P[j, 1] = n0
    P[j, 2] = n1
    P[j, 3] = n2
    P[j, 4] = c0 * n0 + c1 * n1 + c2 * n2
    P[j, 5] = b10
    P[j, 6] = b11
    P[j, 7] = b12
    P[j, 8] = b20
    P[j, 9] = b21
    P[j, 10] = b22
    P[j, 11] = c0 * b10 + c1 * b11 + c2 * b12 if valid else np.inf
    P[j, 12] = c0 * b20 + c1 * b21 + c2 * b22 if valid else np.inf
    if ortho:
        P[j, 13] = cx + f * c0
        P[j, 14] = cy - f * c1
    elif c2 > near:
        P[j, 13] = cx + f * c0 / c2
        P[j, 14] = cy - f * c1 / c2
    else:
        P[j, 13] = np.nan
        P[j, 14] = np.nan
    P[j, 15] = r
    # depth range of the fragments: the ellipse itself (r) plus the screen filter footprint
    # (rfilter pixels in world units at the centre depth) on the tilted plane
    if ortho:
        cos = abs(n2)
    else:
        cl = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        cos = abs(c0 * n0 + c1 * n1 + c2 * n2) / cl if cl > 0.0 else 1.0
    sin = math.sqrt(max(1.0 - cos * cos, 0.0))
    edge = sin > EDGE_ON_TAN * cos
    if ortho:
        fw = rfilter / f
    else:
        fw = rfilter * c2 / f if c2 > near else 0.0
    if edge:
        P[j, 23] = -(r + fw * EDGE_ON_TAN)
    else:
        P[j, 23] = r + fw * sin / cos
    for k in range(3):
        P[j, 16 + k] = colors[i, k]
    hfx = hfy = rfilter
    if edge and valid and rfilter > 0.0:
        hfx, hfy = _filter_form(c0, c1, c2, r, a00, a01, a02, a10, a11, a12, f, ortho, near, rfilter)[3:]
    x0, x1, y0, y1 = _splat_box(c0, c1, c2, r, a00, a01, a02, a10, a11, a12, f, cx, cy, ortho, near, W, H,
                                hfx, hfy)
    P[j, 19] = x0
    P[j, 20] = x1
    P[j, 21] = y0
    P[j, 22] = y1
    facing = n2 if ortho else c0 * n0 + c1 * n1 + c2 * n2
    return x0, x1, y0, y1, 0 if facing <= 0.0 else 1


@njit(cache=True, parallel=True)
def splat_setup(pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter,
                P, box, group):
    """Per-surfel parameters ``P`` (N, NPARAM), pixel boxes (N, 4) int32 and groups (N,) int8.

    ``pos``, ``nrm``, ``colors`` (N,3) world; ``radii`` (N,) the largest semi-axis; ``axes``
    (N,2,3) tangent axes used when ``elliptical`` (circular surfels get a tangent frame built from
    the camera-space normal, Duff et al. 2017); ``frame`` (3,3) world-to-camera rows;
    ``rfilter`` the screen filter radius (pixels).
    ``group`` is 0 for surfels facing the camera, 1 otherwise (binned after the front-facing
    ones so that early depth rejection works).
    """
    n = pos.shape[0]
    nchunks = 64
    step = (n + nchunks - 1) // nchunks
    for c in prange(nchunks):  # a thin parallel loop over a plain function (the set-up inlined there)
        _setup_range(c * step, min(n, (c + 1) * step), pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy,
                     ortho, near, W, H, rfilter, P, box, group)


@njit(cache=True)
def _setup_range(lo, hi, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter,
                 P, box, group):
    """Surfels ``lo:hi`` of :func:`splat_setup`."""
    for i in range(lo, hi):
        x0, x1, y0, y1, g = _setup_row(i, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho,
                                       near, W, H, rfilter, P, i)
        box[i, 0] = x0
        box[i, 1] = x1
        box[i, 2] = y0
        box[i, 3] = y1
        group[i] = g


@njit(cache=True, parallel=True)
def splat_setup_bin(pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter,
                    P, box, group, tile, ntx, nty, nchunks):
    """:func:`splat_setup` and the tile binning of its boxes in one parallel pass over the surfels.

    Writes ``P``, ``box``, ``group`` as :func:`splat_setup` and returns ``offsets, items, visits``:
    ``offsets`` (ntx*nty + 1,) int64 and ``items`` (pairs,) int32 exactly as
    :func:`unmesh.render._kernels.bin_boxes` with two groups and ``nchunks`` chunks (tile ``t``
    holds ``items[offsets[t]:offsets[t+1]]``, front-facing surfels first, then ascending), and
    ``visits`` the total number of pixels in the boxes (a work estimate). The per-tile counts are
    taken while each surfel's row is still in cache, so the surfels are read once before the fill.
    """
    n = pos.shape[0]
    ntiles = ntx * nty
    nslot = ntiles * 2
    counts = np.zeros((nchunks, nslot), dtype=np.int64)
    cvisits = np.zeros(nchunks, dtype=np.int64)
    step = (n + nchunks - 1) // nchunks
    for c in prange(nchunks):  # a thin parallel loop over a plain function (the set-up inlined there)
        lo = c * step
        cvisits[c] = _setup_count(lo, min(n, lo + step), pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx,
                                  cy, ortho, near, W, H, rfilter, P, box, group, tile, ntx, counts[c])
    offsets = np.zeros(ntiles + 1, dtype=np.int64)
    starts = np.zeros((nchunks, nslot), dtype=np.int64)
    total = 0
    for t in range(ntiles):
        offsets[t] = total
        for g in range(2):
            for c in range(nchunks):
                starts[c, t * 2 + g] = total
                total += counts[c, t * 2 + g]
    offsets[ntiles] = total
    items = np.empty(total, dtype=np.int32)
    for c in prange(nchunks):
        lo = c * step
        hi = min(n, lo + step)
        for i in range(lo, hi):
            if box[i, 0] > box[i, 1] or box[i, 2] > box[i, 3]:
                continue
            g = group[i]
            for ty in range(_tile_of(box[i, 2], tile), _tile_of(box[i, 3], tile) + 1):
                for tx in range(_tile_of(box[i, 0], tile), _tile_of(box[i, 1], tile) + 1):
                    q = (ty * ntx + tx) * 2 + g
                    items[starts[c, q]] = i
                    starts[c, q] += 1
    return offsets, items, cvisits.sum()


@njit(cache=True)
def _setup_count(lo, hi, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho, near, W, H, rfilter,
                 P, box, group, tile, ntx, counts):
    """Surfels ``lo:hi`` of :func:`splat_setup_bin`: set-up, ``counts[2 * tile + group] += 1``
    per tile met; returns the pixels of their boxes."""
    v = 0
    for i in range(lo, hi):
        x0, x1, y0, y1, g = _setup_row(i, pos, nrm, radii, axes, elliptical, colors, frame, eye, f, cx, cy, ortho,
                                       near, W, H, rfilter, P, i)
        box[i, 0] = x0
        box[i, 1] = x1
        box[i, 2] = y0
        box[i, 3] = y1
        group[i] = g
        if x0 > x1 or y0 > y1:
            continue
        v += np.int64(x1 - x0 + 1) * (y1 - y0 + 1)
        for ty in range(_tile_of(y0, tile), _tile_of(y1, tile) + 1):
            for tx in range(_tile_of(x0, tile), _tile_of(x1, tile) + 1):
                counts[(ty * ntx + tx) * 2 + g] += 1
    return v


@njit(cache=True, inline="always")
def _tile_of(x, tile):
    """``x // tile`` for a pixel index ``x >= 0``: a shift when ``tile`` is a power of two (an
    integer division costs tens of cycles; the default tile is 32)."""
    if tile & (tile - 1) == 0:
        return x >> TILE_SHIFTS[tile]
    return x // tile


@njit(cache=True, parallel=True)
def gather_rows(P, items, out):
    """``out[k] = P[items[k]]``: pair rows in tile order, so that tiles read them contiguously."""
    m = P.shape[1]
    for k in prange(items.shape[0]):
        s = items[k]
        for j in range(m):
            out[k, j] = P[s, j]


@njit(cache=True)
def _fragment(X, Y, pcx, pcy, ortho, inv_rf2, cz, nx, ny, nz, cn, b1x, b1y, b1z, b2x, b2y, b2z, cb1, cb2,
              sx, sy, zr, qxx, qxy, qyy):  # qxx, qxy, qyy: _edge_form of the surfel when edge-on
    """``(rho, z)`` of one surfel at the pixel whose ray has ``X, Y`` and centre ``(pcx, pcy)``.

    The surfel is given by its parameters (layout of ``P``). ``rho = min(rho3, rho2)``; ``z`` is
    the depth where the pixel ray meets the surfel plane, clamped to the surfel's depth range
    ``cz +- |zr|`` (ellipse plus screen-filter footprint), so fragments of neighbouring surfels of
    one surface agree in depth even when the screen filter wins (minification); for edge-on
    surfels (``zr < 0``) the centre depth is used where the screen filter wins, and their screen
    filter is the ellipse ``qxx, qxy, qyy`` (:func:`_filter_form`) instead of the disc.
    """
    ex = pcx - sx
    ey = pcy - sy
    ewa = not (zr > 0.0) and inv_rf2 < np.inf
    if ewa:
        rho2 = qxx * ex * ex + 2.0 * qxy * ex * ey + qyy * ey * ey
    else:
        rho2 = (ex * ex + ey * ey) * inv_rf2
    if not (rho2 >= 0.0):
        rho2 = np.inf
    if ortho:
        dn = nz
    else:
        dn = X * nx + Y * ny + nz
    z = cz
    rho3 = np.inf
    if abs(dn) > 1e-12:
        if ortho:
            t = (cn - X * nx - Y * ny) / dn
            qx = X
            qy = Y
        else:
            t = cn / dn
            qx = t * X
            qy = t * Y
        u = qx * b1x + qy * b1y + t * b1z - cb1
        v = qx * b2x + qy * b2y + t * b2z - cb2
        rho3 = u * u + v * v
        if not (rho3 >= 0.0):
            rho3 = np.inf
        if zr > 0.0 or rho3 <= rho2:
            za = abs(zr)
            if t == t:
                z = min(max(t, cz - za), cz + za)
    return min(rho3, rho2), z


@njit(cache=True)
def _tri_and(a, b):
    """Three-valued conjunction (4.10): -1 is unknown, ``b and unknown = b``."""
    if a < 0:
        return b
    if b < 0:
        return a
    return 1 if (a > 0 and b > 0) else 0


@njit(cache=True)
def _tri_or(a, b):
    """Three-valued disjunction (4.9): -1 is unknown, ``b or unknown = b``."""
    if a < 0:
        return b
    if b < 0:
        return a
    return 1 if (a > 0 or b > 0) else 0


#: Fragments closer than this (relative to the coordinates' magnitude) to a partner's plane are
#: on it: coplanar patches (4.5) then break the tie by leaf order, so that exactly one of two
#: coincident surfaces is drawn instead of none.
COPLANAR_EPS = 1e-6
#: Two partners of one patch lie on one plane when their normals differ by less than about this
#: angle (radians) and each centre is off the other's plane by less than this fraction of the
#: distance between the centres. Such a pair carries no more than either surfel alone, so the
#: second surfel of insidePatch (4.4) is the closest partner not on one plane with the first.
SAME_PLANE_TOL = 1e-3


@njit(cache=True)
def _clips(P, j, x0, x1, x2):
    """Whether partner row ``j`` (centre ``P[j, 0:3]``, normal ``P[j, 3:6]``) clips ``x`` (4.3)."""
    return (x0 - P[j, 0]) * P[j, 3] + (x1 - P[j, 1]) * P[j, 4] + (x2 - P[j, 2]) * P[j, 5] >= 0.0


@njit(cache=True, inline="always")
def _partner_dist2(partners, j, x0, x1, x2):  # pragma: no cover - numba
    """Squared distance from ``(x0, x1, x2)`` to the centre of clip partner ``j``."""
    dx = x0 - partners[j, 0]
    dy = x1 - partners[j, 1]
    dz = x2 - partners[j, 2]
    return dx * dx + dy * dy + dz * dz


@njit(cache=True)
def same_plane(P, a, b):
    """Whether partner rows ``a`` and ``b`` lie on one plane (:data:`SAME_PLANE_TOL`): parallel
    normals (``n_a.n_b >= 1 - tol^2/2``) and each centre on the other's plane
    (``((c_b - c_a).n)^2 <= tol^2 |c_b - c_a|^2`` for both normals)."""
    t2 = SAME_PLANE_TOL * SAME_PLANE_TOL
    if P[a, 3] * P[b, 3] + P[a, 4] * P[b, 4] + P[a, 5] * P[b, 5] < 1.0 - 0.5 * t2:
        return False
    dx = P[b, 0] - P[a, 0]
    dy = P[b, 1] - P[a, 1]
    dz = P[b, 2] - P[a, 2]
    dd = dx * dx + dy * dy + dz * dz
    ea = dx * P[a, 3] + dy * P[a, 4] + dz * P[a, 5]
    eb = dx * P[b, 3] + dy * P[b, 4] + dz * P[b, 5]
    return ea * ea <= t2 * dd and eb * eb <= t2 * dd


@njit(cache=True)
def _clips_fragment(P, j, x0, x1, x2, own):
    """:func:`_clips` for a fragment of leaf ``own``; on the plane (within :data:`COPLANAR_EPS`)
    the fragment counts as inside the partner's patch when ``own`` is the lower leaf."""
    d = (x0 - P[j, 0]) * P[j, 3] + (x1 - P[j, 1]) * P[j, 4] + (x2 - P[j, 2]) * P[j, 5]
    tol = COPLANAR_EPS * (1.0 + abs(x0) + abs(x1) + abs(x2))
    if abs(d) <= tol:
        return own > P[j, 6]
    return d >= 0.0


@njit(cache=True)
def keep_tree(s, x0, x1, x2, clip_offsets, partners, tree, leaf, work):
    """Algorithm 4.2 for a fragment of surfel ``s`` at world ``x``: whether it is on the surface.

    ``partners[clip_offsets[s]:clip_offsets[s+1]]`` are the clipping partners of ``s`` (4.2.1),
    rows ``(cx, cy, cz, nx, ny, nz, node)`` with ``node`` the leaf of the partner's patch;
    ``tree`` (K, 4) int32 rows ``(op, parent, first, invert)`` in post order (op 0 intersection,
    1 union, 2 leaf; the sub-tree of node k is ``first[k] .. k``; ``invert`` complements a leaf,
    4.3); ``leaf[s]`` is the leaf node of ``s``. ``work`` (K, 5) float64 scratch.

    insidePatch (Algorithm 4.4) uses the partner ``s1`` of the patch closest to ``x`` and the
    closest ``s2`` of the others not on one plane with ``s1`` (:func:`same_plane`; two surfels
    of one plane say no more than one, and would reduce 4.4 to that plane's half-space); a
    fragment on a partner's plane (coplanar patches, 4.5) is inside the lower leaf's patch.
    No partner gives unknown, no ``s2`` the closest-surfel test (4.3), both the concave/convex
    rule (4.4); first partners in row order win ties; insideTree
    (Algorithm 4.3) combines them with the three-valued logic (4.9, 4.10), evaluated for every
    node in post order; then the walk from ``leaf[s]`` to the root applies (4.5)/(4.6).
    """
    K = tree.shape[0]
    for k in range(K):
        work[k, 0] = np.inf
        work[k, 1] = np.inf
        work[k, 2] = -1.0
        work[k, 3] = -1.0
    for j in range(clip_offsets[s], clip_offsets[s + 1]):  # s1 of every leaf
        node = int(partners[j, 6])
        d = _partner_dist2(partners, j, x0, x1, x2)
        if d < work[node, 0]:
            work[node, 0] = d
            work[node, 2] = j
    for j in range(clip_offsets[s], clip_offsets[s + 1]):  # s2: the closest not on s1's plane
        node = int(partners[j, 6])
        i1 = int(work[node, 2])
        if j == i1 or same_plane(partners, i1, j):
            continue
        d = _partner_dist2(partners, j, x0, x1, x2)
        if d < work[node, 1]:
            work[node, 1] = d
            work[node, 3] = j
    for k in range(K):
        op = tree[k, 0]
        if op == 2:
            i1 = int(work[k, 2])
            if i1 < 0:
                val = -1
            else:
                i2 = int(work[k, 3])
                own = leaf[s]
                c1 = _clips_fragment(partners, i1, x0, x1, x2, own)
                if i2 < 0:
                    inside = not c1
                else:
                    c2 = _clips_fragment(partners, i2, x0, x1, x2, own)
                    concave = (_clips(partners, i1, partners[i2, 0], partners[i2, 1], partners[i2, 2])
                               and _clips(partners, i2, partners[i1, 0], partners[i1, 1], partners[i1, 2]))
                    if concave:
                        inside = (not c1) or (not c2)
                    else:
                        inside = (not c1) and (not c2)
                if tree[k, 3] != 0:
                    inside = not inside
                val = 1 if inside else 0
        else:
            right = k - 1
            left = tree[right, 2] - 1
            a = int(work[left, 4])
            b = int(work[right, 4])
            val = _tri_and(a, b) if op == 0 else _tri_or(a, b)
        work[k, 4] = val
    node = leaf[s]
    while tree[node, 1] >= 0:
        p = tree[node, 1]
        right = p - 1
        sib = tree[right, 2] - 1 if node == right else right
        inside = int(work[sib, 4])
        if inside >= 0:
            on = inside > 0 if tree[p, 0] == 0 else inside == 0
            if not on:
                return False
        node = p
    return True


#: Columns of the per-tile ``work`` array of the clip tree (rows ``0..K-1`` per tree node, rows
#: ``K, K+1`` the two fragment-cache slots, rows ``K+2+r`` the partner lists): see
#: :func:`keep_tree_cached`.
WORK_COLUMNS = 8


@njit(cache=True)
def max_rows(clip_offsets):
    """The largest number of partners of a surfel (CSR ``clip_offsets``)."""
    rmax = 0
    for s in range(clip_offsets.shape[0] - 1):
        rmax = max(rmax, clip_offsets[s + 1] - clip_offsets[s])
    return rmax


@njit(cache=True)
def clip_work(tree_rows, rmax):
    """Fresh per-tile scratch of :func:`keep_tree_cached`: (K + 2 + rmax, 8) float64 with
    ``rmax`` the largest number of partners of a surfel (:func:`max_rows`), the cache rows
    marked empty."""
    work = np.empty((tree_rows + 2 + rmax, WORK_COLUMNS))
    for c in range(WORK_COLUMNS):
        work[tree_rows, c] = -1.0
        work[tree_rows + 1, c] = -1.0
    return work


@njit(cache=True)
def _plane_margin(P, j, x0, x1, x2):
    """How far ``x`` may move before :func:`_clips_fragment` of row ``j`` may change (0 within
    the coplanar band)."""
    d = (x0 - P[j, 0]) * P[j, 3] + (x1 - P[j, 1]) * P[j, 4] + (x2 - P[j, 2]) * P[j, 5]
    tol = COPLANAR_EPS * (1.0 + abs(x0) + abs(x1) + abs(x2))
    return max(abs(d) - tol, 0.0) / (1.0 + 4.0 * COPLANAR_EPS) * (1.0 - 1e-9)


@njit(cache=True)
def _leaf_value(k, s, x0, x1, x2, partners, tree, leaf, work, base):
    """insidePatch (4.3/4.4) of leaf node ``k`` for the fragment of surfel ``s`` at ``x``, from
    the partner list of ``k`` (linked in ``work``): ``(value, margin)`` with value -1 unknown,
    and ``margin`` the distance ``x`` may move without changing the value (no plane of the
    leaf's partners changing side when they all agree on ``x``, otherwise also ``s1`` and ``s2``
    of :func:`keep_tree` staying what they are: the two closest staying the two closest when
    they are off each other's plane, else ``s1`` staying the closest and ``s2`` the closest of
    the partners off its plane)."""
    d1 = np.inf
    d2 = np.inf
    d3 = np.inf
    i1 = -1
    i2 = -1
    own = leaf[s]
    tol = COPLANAR_EPS * (1.0 + abs(x0) + abs(x1) + abs(x2))
    rows = 0
    clipping = 0
    gap = np.inf
    j = int(work[k, 1])
    while j >= 0:  # the same scan order and ties as keep_tree
        dx = x0 - partners[j, 0]
        dy = x1 - partners[j, 1]
        dz = x2 - partners[j, 2]
        d = dx * dx + dy * dy + dz * dz
        e = dx * partners[j, 3] + dy * partners[j, 4] + dz * partners[j, 5]  # _clips_fragment
        if (own > partners[j, 6]) if abs(e) <= tol else (e >= 0.0):
            clipping += 1
        rows += 1
        gap = min(gap, abs(e) - tol)
        if d < d1:
            d3 = d2
            d2 = d1
            i2 = i1
            d1 = d
            i1 = j
        elif d < d2:
            d3 = d2
            d2 = d
            i2 = j
        elif d < d3:
            d3 = d
        j = int(work[base + j, 0])
    if i1 < 0:
        return -1, np.inf
    if clipping == 0 or clipping == rows:
        # every partner clips x, or none does: the value whichever two are closest (4.3/4.4),
        # while no plane changes side (the _plane_margin of the nearest plane)
        inside = clipping == 0
        if tree[k, 3] != 0:
            inside = not inside
        return (1 if inside else 0), max(gap, 0.0) / (1.0 + 4.0 * COPLANAR_EPS) * (1.0 - 1e-9)
    c1 = _clips_fragment(partners, i1, x0, x1, x2, own)
    margin = _plane_margin(partners, i1, x0, x1, x2)
    if i2 >= 0 and same_plane(partners, i1, i2):
        # s2 is the closest partner not on s1's plane (keep_tree): while s1 stays the closest
        # (half the gap to the second closest) the partners off its plane stay the same, and
        # s2 stays their closest (half the gap to the next of them)
        margin = min(margin, 0.5 * (math.sqrt(d2) - math.sqrt(d1)) * (1.0 - 1e-9))
        e1 = np.inf
        e2 = np.inf
        i2 = -1
        j = int(work[k, 1])
        while j >= 0:  # the same scan order and ties as keep_tree
            if j != i1 and not same_plane(partners, i1, j):
                d = _partner_dist2(partners, j, x0, x1, x2)
                if d < e1:
                    e2 = e1
                    e1 = d
                    i2 = j
                elif d < e2:
                    e2 = d
            j = int(work[base + j, 0])
        if i2 >= 0 and e2 < np.inf:
            margin = min(margin, 0.5 * (math.sqrt(e2) - math.sqrt(e1)) * (1.0 - 1e-9))
        d3 = np.inf  # the gap bound above replaces that of the two closest
    if i2 < 0:
        inside = not c1
    else:
        c2 = _clips_fragment(partners, i2, x0, x1, x2, own)
        margin = min(margin, _plane_margin(partners, i2, x0, x1, x2))
        if d3 < np.inf:  # the two closest (s1 and s2, off each other's plane) stay the two closest
            margin = min(margin, 0.5 * (math.sqrt(d3) - math.sqrt(d2)) * (1.0 - 1e-9))
        concave = (_clips(partners, i1, partners[i2, 0], partners[i2, 1], partners[i2, 2])
                   and _clips(partners, i2, partners[i1, 0], partners[i1, 1], partners[i1, 2]))
        if concave:
            inside = (not c1) or (not c2)
        else:
            inside = (not c1) and (not c2)
    if tree[k, 3] != 0:
        inside = not inside
    return (1 if inside else 0), margin


@njit(cache=True)
def _subtree_value(lo, hi, s, x0, x1, x2, partners, tree, leaf, work, base, margin):
    """insideTree (Algorithm 4.3) of the sub-tree ``lo..hi`` (post order, root ``hi``) with
    short-circuits: a left operand that decides its node (false under an intersection, true
    under a union, 4.9/4.10) skips the right one. Returns ``(value, margin)``."""
    k = lo
    while k <= hi:
        op = tree[k, 0]
        if op == 2:
            v, m = _leaf_value(k, s, x0, x1, x2, partners, tree, leaf, work, base)
            margin = min(margin, m)
        else:
            right = k - 1
            left = tree[right, 2] - 1
            a = int(work[left, 0])
            b = int(work[right, 0])
            v = _tri_and(a, b) if op == 0 else _tri_or(a, b)
        work[k, 0] = v
        while k < hi:
            p = tree[k, 1]
            if k == p - 1 or v < 0 or (tree[p, 0] == 0) == (v > 0):
                break
            work[p, 0] = v  # k is p's left operand and decides it
            k = p
        k += 1
    return int(work[hi, 0]), margin


@njit(cache=True, inline="always")
def _cache_hit(work, row, s, x0, x1, x2):
    """Whether cache slot ``row`` holds a result of surfel ``s`` valid at ``x``."""
    if work[row, 0] != s:
        return False
    dx = x0 - work[row, 1]
    dy = x1 - work[row, 2]
    dz = x2 - work[row, 3]
    return dx * dx + dy * dy + dz * dz < work[row, 4]


@njit(cache=True)
def _keep_single(s, x0, x1, x2, partners, tree, leaf, work):
    """:func:`keep_tree` for a surfel ``s`` with at most one partner per leaf (half-spaces, the
    faces of Fig. 4.10): insidePatch of a leaf is the side of its one plane (4.3, no search for
    the closest partners). The walk of :func:`keep_tree_cached` without its short-circuits inside
    a sibling's sub-tree (the siblings of folded trees are mostly single leaves); returns
    ``(keep, margin)`` with the margin of the planes tested. ``work[k, 1]`` holds the partner
    row of leaf node ``k`` (-1: none, unknown); insideTree values go to column 0."""
    own = leaf[s]
    tol = COPLANAR_EPS * (1.0 + abs(x0) + abs(x1) + abs(x2))
    margin = np.inf
    node = own
    while tree[node, 1] >= 0:
        p = tree[node, 1]
        right = p - 1
        sib = tree[right, 2] - 1 if node == right else right
        for k in range(tree[sib, 2], sib + 1):  # insideTree of the sibling's sub-tree, post order
            op = tree[k, 0]
            if op == 2:
                j = int(work[k, 1])
                if j < 0:
                    v = -1
                else:  # _clips_fragment and _plane_margin of row j
                    d = ((x0 - partners[j, 0]) * partners[j, 3] + (x1 - partners[j, 1]) * partners[j, 4]
                         + (x2 - partners[j, 2]) * partners[j, 5])
                    if abs(d) <= tol:
                        inside = not (own > partners[j, 6])
                    else:
                        inside = not (d >= 0.0)
                    if tree[k, 3] != 0:
                        inside = not inside
                    v = 1 if inside else 0
                    margin = min(margin, max(abs(d) - tol, 0.0) / (1.0 + 4.0 * COPLANAR_EPS) * (1.0 - 1e-9))
            else:
                r = k - 1
                a = int(work[tree[r, 2] - 1, 0])
                b = int(work[r, 0])
                v = _tri_and(a, b) if op == 0 else _tri_or(a, b)
            work[k, 0] = v
        v = int(work[sib, 0])
        if v >= 0 and not (v > 0 if tree[p, 0] == 0 else v == 0):
            return False, margin
        node = p
    return True, margin



@njit(cache=True)
def keep_tree_cached(s, x0, x1, x2, clip_offsets, partners, tree, leaf, work):
    """:func:`keep_tree` with the traversal short-circuited and its result reused between
    neighbouring fragments (4.2.3: "past results of the traversal are cached and reused").

    Only the sub-trees Algorithm 4.2 needs are evaluated, lazily (a sibling that puts the
    fragment off the surface ends the walk; a deciding left operand skips the right one). With
    the result, the distance ``margin`` that ``x`` may move without changing any value used is
    kept (the distance to the nearest plane tested, and for every leaf evaluated whose
    partners disagree on the fragment the gaps that keep its ``s1``/``s2`` in place, see
    :func:`_leaf_value`: when all of a leaf's partners clip it, or none does, the value is the
    same whichever two are chosen, and only their planes bound the margin); a later fragment of the same surfel
    within ``margin`` of a cached one gets the cached result, exactly the one a new traversal
    would give. Two slots: the last result and the one before (the start of the previous
    pixel row, typically).

    ``work`` from :func:`clip_work`: column 0 of node rows holds insideTree values, column 1
    the first partner of each leaf node; rows ``K`` and ``K+1`` are the cache slots
    ``(s, x, margin^2, result)`` and ``work[K, 6]`` the surfel whose partner lists rows
    ``K + 2 + r`` link per leaf, in order.
    """
    K = tree.shape[0]
    base = K + 2 - clip_offsets[s]
    if work[K, 6] != s:  # partner lists of the leaves, each in ascending row order
        for k in range(K):
            work[k, 1] = -1.0
        single = 1.0
        for j in range(clip_offsets[s + 1] - 1, clip_offsets[s] - 1, -1):
            node = int(partners[j, 6])
            if work[node, 1] >= 0.0:
                single = 0.0
            work[base + j, 0] = work[node, 1]
            work[node, 1] = j
        work[K, 6] = s
        work[K, 7] = single
    elif _cache_hit(work, K, s, x0, x1, x2):
        return work[K, 5] > 0.0
    elif _cache_hit(work, K + 1, s, x0, x1, x2):
        return work[K + 1, 5] > 0.0
    if work[K, 7] > 0.0:
        keep, margin = _keep_single(s, x0, x1, x2, partners, tree, leaf, work)
    else:
        margin = np.inf
        keep = True
        node = leaf[s]
        while tree[node, 1] >= 0:
            p = tree[node, 1]
            right = p - 1
            sib = tree[right, 2] - 1 if node == right else right
            v, margin = _subtree_value(tree[sib, 2], sib, s, x0, x1, x2, partners, tree, leaf, work, base, margin)
            if v >= 0 and not (v > 0 if tree[p, 0] == 0 else v == 0):
                keep = False
                break
            node = p
    for c in range(6):  # the last result moves to the second slot
        work[K + 1, c] = work[K, c]
    work[K, 0] = s
    work[K, 1] = x0
    work[K, 2] = x1
    work[K, 3] = x2
    work[K, 4] = margin * margin
    work[K, 5] = 1.0 if keep else 0.0
    return keep


@njit(cache=True, inline="always")
def _keep(s, X, Y, z, ortho, eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree, clip_leaf, work):
    """Per-fragment clip test of surfel ``s`` at depth ``z`` (chapter 4).

    With ``clip_tree`` None: surfel ``s`` owns planes
    ``clip_planes[clip_offsets[s]:clip_offsets[s+1]]`` (rows ``(nx, ny, nz, d)`` in world
    space); plane ``j`` keeps points with ``n.x + d <= 0``. ``clip_mode[s] == 0`` keeps a
    fragment kept by *all* planes (convex corner), ``1`` by *any* plane (concave corner).
    Otherwise ``clip_planes`` are clipping partners and the CSG tree decides
    (:func:`keep_tree`, Algorithm 4.2).
    """
    a = clip_offsets[s]
    b = clip_offsets[s + 1]
    if a == b:
        return True
    if ortho:
        px = X
        py = Y
    else:
        px = X * z
        py = Y * z
    wx = eye[0] + px * frame[0, 0] + py * frame[1, 0] + z * frame[2, 0]
    wy = eye[1] + px * frame[0, 1] + py * frame[1, 1] + z * frame[2, 1]
    wz = eye[2] + px * frame[0, 2] + py * frame[1, 2] + z * frame[2, 2]
    if clip_tree is not None:  # None (plain splatting) prunes this branch at compile time
        # the cache hits of keep_tree_cached here, in the fragment loop: a call per fragment
        # costs more than the look-up itself
        K = clip_tree.shape[0]
        if work[K, 6] == s:
            for row in range(K, K + 2):
                if _cache_hit(work, row, s, wx, wy, wz):
                    return work[row, 5] > 0.0
        return keep_tree_cached(s, wx, wy, wz, clip_offsets, clip_planes, clip_tree, clip_leaf, work)
    anymode = clip_mode[s] != 0
    for j in range(a, b):
        side = clip_planes[j, 0] * wx + clip_planes[j, 1] * wy + clip_planes[j, 2] * wz + clip_planes[j, 3]
        if anymode and side <= 0.0:
            return True
        if not anymode and side > 0.0:
            return False
    return not anymode


#: Half-width of a partner plane's band along a pixel row (:func:`_row_bands`), relative to
#: the coordinates' magnitude: twice :data:`COPLANAR_EPS`, so outside the band every fragment is
#: off the plane's coplanar band (4.5) on one side, whatever the rounding of its world position.
ROW_BAND_TOL = 2.0 * COPLANAR_EPS
#: Margin (pixels) added to each end of a band, for the rounding of its ends.
ROW_BAND_MARGIN = 0.01
#: Rows of a surfel's span within a tile at most this many pixels wide evaluate the clip tree
#: per fragment (its cache is cheaper there than the bands of every plane).
ROW_MIN_WIDTH = 16
#: Surfels with more partners than this take the per-fragment path (the one-partner-per-leaf
#: check of :func:`_rows_begin` is quadratic in the partners).
ROW_MAX_PARTNERS = 64


@njit(cache=True)
def _rows_begin(s, bx0, bx1, by0, by1, zmin, zmax, cn, ortho, near, invf, cx, cy, eye, frame, clip_offsets, partners,
                clip_mode, tree, work):
    """Set-up of the row-interval path of the clip tree for surfel ``s`` (box ``bx0..bx1``,
    ``by0..by1``, fragment depths ``zmin..zmax``): returns ``(applies, tmin)``.

    Along one pixel row, the fragments on the surfel's plane lie on a line, and each partner
    plane's side (4.3, :func:`_clips_fragment`) changes at most once on it. When every leaf has
    at most one partner (:func:`_keep_single`), a leaf's value is that side, so the row splits
    into intervals of constant leaf values between the planes' crossings, and the tree
    (Algorithms 4.2/4.3) needs one evaluation per interval. The path applies with a clip tree
    (``clip_mode[0] == 0``; 1 evaluates every fragment, the reference of the tests), one partner
    per leaf and, in perspective, a surfel plane off the eye (``cn = c.n != 0``, camera space)
    and on-plane fragments in front of it (``tmin``: their smallest depth). Per partner row ``j`` it writes to ``work[K + 2 + r]`` (``r = j -
    clip_offsets[s]``) columns 3-7: ``(e - c).n``, ``F0.n``, ``F1.n``, ``F2.n`` (``F`` the rows
    of ``frame``, ``e`` the eye) and the band half-width ``delta``, which bounds
    ``COPLANAR_EPS (1 + |x|_1)`` plus the rounding of the distance for every fragment ``x`` in
    the box (:data:`ROW_BAND_TOL`).
    """
    if tree is None:
        return False, 0.0
    if clip_mode[0] != 0:
        return False, 0.0
    a = clip_offsets[s]
    b = clip_offsets[s + 1]
    if b - a > ROW_MAX_PARTNERS:
        return False, 0.0
    for j in range(a + 1, b):  # one partner per leaf (the rows of a leaf are mostly adjacent)
        for i in range(j - 1, a - 1, -1):
            if partners[i, 6] == partners[j, 6]:
                return False, 0.0
    tmin = 1.0
    if not ortho:
        tmin = max(zmin, near)
        if not (tmin > 0.0) or not (abs(cn) > 0.0):
            return False, 0.0
    xm = max(abs((bx0 + 0.5 - cx) * invf), abs((bx1 + 0.5 - cx) * invf))
    ym = max(abs((cy - by0 - 0.5) * invf), abs((cy - by1 - 0.5) * invf))
    zm = max(abs(zmin), abs(zmax))
    pm = xm + ym + zm if ortho else zm * (xm + ym + 1.0)  # bounds |camera-space x|_1
    mw = abs(eye[0]) + abs(eye[1]) + abs(eye[2]) + 3.0 * pm  # bounds |world x|_1
    if not (mw < np.inf):
        return False, 0.0
    base = tree.shape[0] + 2 - a
    for j in range(a, b):
        r = base + j
        n0 = partners[j, 3]
        n1 = partners[j, 4]
        n2 = partners[j, 5]
        work[r, 3] = (eye[0] - partners[j, 0]) * n0 + (eye[1] - partners[j, 1]) * n1 + (eye[2] - partners[j, 2]) * n2
        work[r, 4] = frame[0, 0] * n0 + frame[0, 1] * n1 + frame[0, 2] * n2
        work[r, 5] = frame[1, 0] * n0 + frame[1, 1] * n1 + frame[1, 2] * n2
        work[r, 6] = frame[2, 0] * n0 + frame[2, 1] * n1 + frame[2, 2] * n2
        work[r, 7] = ROW_BAND_TOL * (1.0 + mw + abs(partners[j, 0]) + abs(partners[j, 1]) + abs(partners[j, 2]))
    return True, tmin


@njit(cache=True)
def _row_bands(s, first, last, ortho, Y, t0, tX, dn0, nx, cn, tmin, f, cx, clip_offsets, tree, work):
    """The band of each partner plane in the pixel row ``first..last`` (:func:`_rows_begin`):
    pixels ``lo..hi`` (``lo = hi + 1`` when no pixel is in it, clamped to ``first - 2 .. last +
    2``) around the plane's crossing, a superset of the on-plane fragments within ``delta`` of
    the plane. Pixels before the band are on one side of the plane, pixels after it on the
    other. The bands that reach into the row are written to ``work[K + 2 + i]`` columns 1, 2
    for ``i < nband``; returns ``nband``.

    On the row, an on-plane fragment at ray coordinate ``X`` is at depth ``t = t0 + tX X``
    (orthographic, world ``x = e + X F0 + Y F1 + t F2``) or ``t = cn / (nx X + dn0)``
    (perspective, ``x = e + t (X F0 + Y F1 + F2)``), so its distance to the plane is affine in
    ``X`` (orthographic) or ``t g(X)`` with ``g`` affine (perspective, ``t >= tmin > 0``).
    """
    K = tree.shape[0]
    base = K + 2 - clip_offsets[s]
    lmin = first - 2.0
    lmax = last + 2.0
    nband = 0
    for j in range(clip_offsets[s], clip_offsets[s + 1]):
        r = base + j
        e = work[r, 3]
        fa = work[r, 4]
        fb = work[r, 5]
        fc = work[r, 6]
        dl = work[r, 7]
        if ortho:
            c0 = e + Y * fb + t0 * fc
            c1 = fa + tX * fc
        else:  # g(X) = d / t = e (nx X + dn0) / cn + X F0.n + Y F1.n + F2.n
            c0 = e * dn0 / cn + Y * fb + fc
            c1 = e * nx / cn + fa
            dl = dl / tmin
        lo = lmin  # the whole row unless shown otherwise
        hi = lmax
        if c1 != 0.0:
            pa = (-dl - c0) / c1 * f + cx - 0.5
            pb = (dl - c0) / c1 * f + cx - 0.5
            if pa > pb:
                pa, pb = pb, pa
            if pa <= pb:
                lo = math.ceil(min(max(pa - ROW_BAND_MARGIN, lmin), lmax))
                hi = math.floor(min(max(pb + ROW_BAND_MARGIN, lmin), lmax))
        elif abs(c0) >= dl:  # parallel to the row and off the band: no band
            continue
        if hi < first or lo > last:  # the whole row on one side
            continue
        work[K + 2 + nband, 1] = lo
        work[K + 2 + nband, 2] = hi
        nband += 1
    return nband


@njit(cache=True)
def _row_event(px, s, nband, clip_offsets, tree, work):
    """Whether pixel ``px`` of the row is in one of the ``nband`` bands of :func:`_row_bands`,
    and the next pixel where that, or the side of a plane, changes."""
    K = tree.shape[0]
    inband = False
    nxt = np.inf
    for i in range(nband):
        lo = work[K + 2 + i, 1]
        hi = work[K + 2 + i, 2]
        if lo > px:
            nxt = min(nxt, lo)
        elif hi >= px:
            inband = True
            nxt = min(nxt, hi + 1.0)
    return inband, nxt


@njit(cache=True, inline="always")
def _accumulate(q, k, w, z, Pt, lw, lc, ln, ld, lcount):
    """Add one fragment of pair ``k`` with weight ``w`` and depth ``z`` to tile pixel ``q``."""
    lw[q] += w
    lc[q, 0] += w * Pt[k, 16]
    lc[q, 1] += w * Pt[k, 17]
    lc[q, 2] += w * Pt[k, 18]
    ln[q, 0] += w * Pt[k, 1]
    ln[q, 1] += w * Pt[k, 2]
    ln[q, 2] += w * Pt[k, 3]
    ld[q] += w * z
    lcount[q] += 1


#: Margin (pixels) of the per-row pixel spans of :func:`_row_span` beyond their analytic ends:
#: the spans only skip pixels that cannot hold a fragment, every pixel inside is still tested.
SPAN_MARGIN = 0.01
#: Box rows at most this many pixels wide (within the tile) are visited whole instead of
#: through :func:`_row_span`: the span costs more than testing the few pixels it would skip (the
#: fragments and their order are the same either way). See docs/performance.md, stop 34.
SPAN_MIN_WIDTH = 8


@njit(cache=True, inline="always")
def _interval(lo, hi, bx0, bx1):
    """Pixel indices ``[ceil(lo), floor(hi)]`` clamped to ``[bx0, bx1]`` (empty: first > last)."""
    lo = max(lo, bx0 - 1.0)
    hi = min(hi, bx1 + 1.0)
    if not (lo <= hi):
        return bx1 + 1, bx0 - 1
    return max(math.ceil(lo), bx0), min(math.floor(hi), bx1)


@njit(cache=True, inline="always")
def _row_span(qa, iqa, qb, qc, f, cx, lo, hi, bx0, bx1):
    """The pixels of one row that may hold a fragment: a superset of ``rho < 1``.

    ``qa X^2 + 2 qb X + qc < 0`` (``iqa = 1 / qa``) is the row's part of the ellipse
    ``rho3 < 1`` in the ray coordinate ``X`` (``qa <= 0`` or NaN: the whole box row; ``qc``
    inf: none); ``[lo, hi]`` (pixel columns) covers the screen-filter disc in this row. Returns
    the hull ``(first, last)`` of both within ``[bx0, bx1]``, widened by :data:`SPAN_MARGIN`;
    ``first > last`` when empty.
    """
    if qc < np.inf:
        if qa > 0.0 and abs(qb) < np.inf and qc > -np.inf:
            disc = qb * qb - qa * qc
            if disc >= -1e-9 * (qb * qb + abs(qa * qc)):
                sq = math.sqrt(max(disc, 0.0))
                lo = min(lo, (-qb - sq) * iqa * f + cx - 0.5 - SPAN_MARGIN)
                hi = max(hi, (-qb + sq) * iqa * f + cx - 0.5 + SPAN_MARGIN)
        else:
            return bx0, bx1
    return _interval(lo, hi, bx0, bx1)


@njit(cache=True)
def _tile_pass(mode, Pt, items, a, b, x0, y0, tw, th, invf, cx, cy, ortho, near, inv_rf2, kappa, eps_factor,
               sign, has_clip, eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree, clip_leaf, work, lz, lw, lc, ln, ld,
               lcount, frag_q, frag_k, frag_rho, frag_z):
    """The fragment loop of one tile: the one place every splat fragment is generated.

    ``mode 0`` (visibility pass of a full update): every fragment not already behind ``lz``
    is recorded in ``frag_*`` and lowers ``lz`` to ``z + eps`` (``eps = eps_factor * r``,
    3.2.1); returns the number recorded. The accumulation pass (:func:`_accumulate_records`)
    then keeps the recorded fragments with ``z <= lz``; since ``lz`` only decreases, these are
    exactly the fragments of all surfels that pass the final extended depth test.
    ``mode 1`` (partial updates, fixed ``lz``): fragments with ``z <= lz`` are accumulated
    directly with weight ``sign * w``; returns 0.

    A surfel that cannot reach ``lz`` anywhere in its box (``cz - |zr| > lz``) is skipped
    before any fragment work; in each box row only the span that may hold fragments
    (:func:`_row_span`) is visited (the whole row when the box is at most
    :data:`SPAN_MIN_WIDTH` pixels wide within the tile). The fragment model is that of
    :func:`_fragment`, evaluated with the per-row constants taken out (the ray-plane
    intersection, ``u`` and ``v`` are affine in the pixel column ``X`` in orthographic views).
    Chapter 4's clipped splatting
    tests each fragment here (:func:`_keep`, surfel ``items[k]``); with a clip tree of one
    partner per leaf, once per interval of a row between the partner planes' crossings
    (:func:`_rows_begin`).
    """
    nrec = 0
    f = 1.0 / invf
    # the screen filter disc: rows with ey^2 < rf2x, columns within rfl of the centre
    rf2x = (1.0 + 1e-9) / inv_rf2 if inv_rf2 < np.inf else 0.0
    rfl = math.sqrt(rf2x)
    for k in range(a, b):
        bx0 = max(int(Pt[k, 19]), x0)
        bx1 = min(int(Pt[k, 20]), x0 + tw - 1)
        by0 = max(int(Pt[k, 21]), y0)
        by1 = min(int(Pt[k, 22]), y0 + th - 1)
        cz = np.float64(Pt[k, 0])
        zr = np.float64(Pt[k, 23])
        eps = eps_factor * Pt[k, 15]
        za = abs(zr)
        zmin = cz - za
        zmax = cz + za
        reach = False
        for py in range(by0, by1 + 1):
            row = (py - y0) * tw - x0
            for px in range(bx0, bx1 + 1):
                if zmin <= lz[row + px]:
                    reach = True
                    break
            if reach:
                break
        if not reach:
            continue
        nx = np.float64(Pt[k, 1])
        ny = np.float64(Pt[k, 2])
        nz = np.float64(Pt[k, 3])
        cn = np.float64(Pt[k, 4])
        b1x = np.float64(Pt[k, 5])
        b1y = np.float64(Pt[k, 6])
        b1z = np.float64(Pt[k, 7])
        b2x = np.float64(Pt[k, 8])
        b2y = np.float64(Pt[k, 9])
        b2z = np.float64(Pt[k, 10])
        cb1 = np.float64(Pt[k, 11])
        cb2 = np.float64(Pt[k, 12])
        sx = np.float64(Pt[k, 13])
        sy = np.float64(Pt[k, 14])
        edge = not (zr > 0.0)
        # edge-on surfels: the screen filter is an ellipse (_filter_form), rows scanned whole
        ewa = edge and inv_rf2 < np.inf
        qxx = qyy = inv_rf2
        qxy2 = 0.0
        if ewa and abs(np.float64(Pt[k, 11])) < np.inf and abs(np.float64(Pt[k, 12])) < np.inf:
            qxx, qxy, qyy = _edge_form(Pt, k, f, cx, cy, ortho, near, inv_rf2)
            qxy2 = 2.0 * qxy
        s = items[k]
        clip = has_clip and clip_offsets[s + 1] > clip_offsets[s]
        planar = abs(nz) > 1e-12  # orthographic: the rays meet the surfel plane
        finite = abs(cb1) < np.inf and abs(cb2) < np.inf
        # orthographic: t = t0 + tX X, u = u0 + uX X, v = v0 + vX X along a row
        inz = 1.0 / nz if planar else 0.0
        tX = -nx * inz
        tY = -ny * inz
        tA = cn * inz
        uX = b1x + tX * b1z
        vX = b2x + tX * b2z
        # perspective: u = (UX X + U0) / dn, dn = nx X + dn0 (rows of the span's quadratic)
        UX = cn * b1x - cb1 * nx
        VX = cn * b2x - cb2 * nx
        qa = uX * uX + vX * vX if ortho else UX * UX + VX * VX - nx * nx
        iqa = 1.0 / qa if qa > 0.0 else 0.0
        flo = sx - rfl - 0.5 - SPAN_MARGIN
        fhi = sx + rfl - 0.5 + SPAN_MARGIN
        rows = False  # the clip tree's row intervals (_rows_begin)
        tmin = 1.0
        if clip_tree is not None:
            if clip and bx1 - bx0 >= ROW_MIN_WIDTH:
                rows, tmin = _rows_begin(s, bx0, bx1, by0, by1, zmin, zmax, cn, ortho, near, invf, cx, cy, eye, frame,
                                         clip_offsets, clip_planes, clip_mode, clip_tree, work)
        for py in range(by0, by1 + 1):
            pcy = py + 0.5
            Y = (cy - pcy) * invf
            ey = pcy - sy
            ey2 = ey * ey
            qb = 0.0
            qc = np.inf
            if ortho:
                t0 = tA + tY * Y
                u0 = Y * b1y + t0 * b1z - cb1
                v0 = Y * b2y + t0 * b2z - cb2
                if planar and finite:
                    qb = uX * u0 + vX * v0
                    qc = u0 * u0 + v0 * v0 - 1.0
            else:
                dn0 = Y * ny + nz
                e10 = Y * b1y + b1z
                e20 = Y * b2y + b2z
                if finite:
                    U0 = cn * e10 - cb1 * dn0
                    V0 = cn * e20 - cb2 * dn0
                    qb = UX * U0 + VX * V0 - nx * dn0
                    qc = U0 * U0 + V0 * V0 - dn0 * dn0
            if bx1 - bx0 < SPAN_MIN_WIDTH or ewa:  # narrow boxes: testing every pixel is cheaper
                first, last = bx0, bx1
            elif ey2 < rf2x:
                first, last = _row_span(qa, iqa, qb, qc, f, cx, flo, fhi, bx0, bx1)
            else:
                first, last = _row_span(qa, iqa, qb, qc, f, cx, np.inf, -np.inf, bx0, bx1)
            row = (py - y0) * tw - x0
            inrow = rows and last - first >= ROW_MIN_WIDTH  # the clip tree's intervals in this row
            nxt = -np.inf  # next band event
            inband = True
            kept = -1  # the current interval's result (-1: not evaluated)
            nband = 0
            if clip_tree is not None:
                if inrow:
                    nband = _row_bands(s, first, last, ortho, Y, tA + tY * Y, tX, Y * ny + nz, nx, cn, tmin, f, cx,
                                       clip_offsets, clip_tree, work)
            for px in range(first, last + 1):
                pcx = px + 0.5
                X = (pcx - cx) * invf
                ex = pcx - sx
                if ewa:
                    rho2 = qxx * ex * ex + qxy2 * ex * ey + qyy * ey2
                else:
                    rho2 = (ex * ex + ey2) * inv_rf2
                if not (rho2 >= 0.0):
                    rho2 = np.inf
                z = cz
                rho3 = np.inf
                t = np.nan
                hit = False
                if ortho:
                    if planar:
                        hit = True
                        t = t0 + tX * X
                        u = u0 + uX * X
                        v = v0 + vX * X
                        rho3 = u * u + v * v
                else:
                    dn = X * nx + dn0
                    if abs(dn) > 1e-12:
                        hit = True
                        t = cn / dn
                        u = t * (X * b1x + e10) - cb1
                        v = t * (X * b2x + e20) - cb2
                        rho3 = u * u + v * v
                if not (rho3 >= 0.0):
                    rho3 = np.inf
                if hit and (not edge or rho3 <= rho2) and t == t:
                    z = min(max(t, zmin), zmax)
                rho = min(rho3, rho2)
                if rho >= 1.0 or z <= near:
                    continue
                q = row + px
                if z > lz[q]:
                    continue
                if clip:
                    if inrow:
                        # one tree evaluation per interval of constant leaf values (_rows_begin):
                        # the fragments on the row's line outside every plane's band share it
                        if clip_tree is not None:
                            if px >= nxt:
                                inband, nxt = _row_event(px, s, nband, clip_offsets, clip_tree, work)
                                kept = -1
                        line = not inband and hit and z == t
                        if line and kept >= 0:
                            keep = kept > 0
                        else:
                            keep = _keep(s, X, Y, z, ortho, eye, frame, clip_offsets, clip_planes, clip_mode,
                                         clip_tree, clip_leaf, work)
                            if line:
                                kept = 1 if keep else 0
                        if not keep:
                            continue
                    elif not _keep(s, X, Y, z, ortho, eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree,
                                   clip_leaf, work):
                        continue
                if mode == 0:
                    frag_q[nrec] = q
                    frag_k[nrec] = k
                    frag_rho[nrec] = rho
                    frag_z[nrec] = z
                    nrec += 1
                    if z + eps < lz[q]:
                        lz[q] = z + eps
                else:
                    _accumulate(q, k, sign * math.exp(-kappa * rho), z, Pt, lw, lc, ln, ld, lcount)
    return nrec


@njit(cache=True)
def _accumulate_records(nrec, Pt, kappa, sign, lz, lw, lc, ln, ld, lcount, frag_q, frag_k, frag_rho, frag_z):
    """Accumulation pass of a full update over the fragments recorded by :func:`_tile_pass`:
    those with ``z <= lz`` add ``sign * exp(-kappa rho)`` times colour, normal and depth."""
    for i in range(nrec):
        q = frag_q[i]
        z = frag_z[i]
        if z <= lz[q]:
            _accumulate(q, frag_k[i], sign * math.exp(-kappa * frag_rho[i]), z, Pt, lw, lc, ln, ld, lcount)


@njit(cache=True, parallel=True)
def splat_tiles(P, items, offsets, order, tile, W, H, f, cx, cy, ortho, near, rfilter, kappa, eps_factor, has_clip,
                eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree, clip_leaf, visibility, sign, zvis, acc_w, acc_c, acc_n, acc_z,
                count, dirty):
    """Visibility (optional) and accumulation passes over all tiles, in parallel.

    ``P`` (N, NPARAM) per-surfel parameters (:func:`splat_setup`) and ``items`` (pairs,) surfel
    indices in tile order with ``offsets`` from :func:`unmesh.render._kernels.bin_boxes` (each
    tile gathers its pairs' rows of ``P`` into a tile-local array); ``order`` the tile permutation
    (every tile once when ``visibility``). ``zvis`` (H,W) is the visibility buffer: updated when
    ``visibility`` is true (full update), otherwise only read (partial updates, 5.7). ``acc_n``
    sums camera-space normals. Partial updates add ``sign`` (+1 splat, -1 unsplat) times the
    contributions to the accumulators (H,W) / (H,W,3) float64 and ``count`` (H,W) int32; pixels
    whose count returns to zero are reset to exact zeros. A full update (``visibility``,
    ``sign`` +1) *overwrites* them instead, so they need not be cleared before: each tile with
    pairs writes all its pixels (exact zeros where no fragment), and a tile without pairs is
    zeroed only if ``dirty`` says it may hold values. ``dirty`` (ntiles,) uint8 is 1 for the
    tiles of the accumulators that may be nonzero: read and updated here (a tile that received
    fragments becomes 1; a full update sets the others to 0).
    """
    ntx = (W + tile - 1) // tile
    invf = 1.0 / f
    inv_rf2 = 1.0 / (rfilter * rfilter) if rfilter > 0.0 else np.inf
    rmax = 0 if clip_tree is None else max_rows(clip_offsets)
    # a thin parallel loop over a plain function: the tile body is typed and optimised once, not
    # as part of the parfor (its array allocations would each become a parfor of their own)
    for kk in prange(order.shape[0]):
        _splat_tile(order[kk], P, items, offsets, tile, ntx, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa,
                    eps_factor, has_clip, eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree, clip_leaf, rmax,
                    visibility, sign, zvis, acc_w, acc_c, acc_n, acc_z, count, dirty)


@njit(cache=True, inline="always")
def _zero_pixel(count, acc_w, acc_z, acc_c, acc_n, i, j):  # pragma: no cover - numba
    """Reset the sums of pixel ``(i, j)`` (no fragment left there)."""
    count[i, j] = 0
    acc_w[i, j] = 0.0
    acc_z[i, j] = 0.0
    for k3 in range(3):
        acc_c[i, j, k3] = 0.0
        acc_n[i, j, k3] = 0.0


@njit(cache=True)
def _splat_tile(t, P, items, offsets, tile, ntx, W, H, invf, cx, cy, ortho, near, inv_rf2, kappa, eps_factor, has_clip,
                eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree, clip_leaf, rmax, visibility, sign, zvis,
                acc_w, acc_c, acc_n, acc_z, count, dirty):
    """One tile of :func:`splat_tiles` (tile ``t``; it owns its pixels)."""
    a = offsets[t]
    b = offsets[t + 1]
    if a == b:
        if visibility and dirty[t] != 0:  # a full update leaves no stale values in empty tiles
            x0, y0, tw, th = tile_rect(t, ntx, tile, W, H)
            for i in range(y0, y0 + th):
                for j in range(x0, x0 + tw):
                    _zero_pixel(count, acc_w, acc_z, acc_c, acc_n, i, j)
            dirty[t] = 0
        return
    x0, y0, tw, th = tile_rect(t, ntx, tile, W, H)
    m = tw * th
    # the tile's pair rows, gathered here into a tile-local (cache-resident) array
    npair = b - a
    ncol = P.shape[1]
    Pt = np.empty((npair, ncol), dtype=P.dtype)
    for k in range(npair):
        s = items[a + k]
        for j in range(ncol):
            Pt[k, j] = P[s, j]
    its = items[a:b]
    lz = load_tile(zvis, x0, y0, tw, th)
    lw = np.zeros(m)
    lc = np.zeros((m, 3))
    ln = np.zeros((m, 3))
    ld = np.zeros(m)
    lcount = np.zeros(m, dtype=np.int32)
    if clip_tree is None:
        work = np.empty((1, WORK_COLUMNS))
    else:
        work = clip_work(clip_tree.shape[0], rmax)
    # one call site of _tile_pass with a run-time mode: one compiled body, not one per literal mode
    cap = 0
    mode = 1
    if visibility:
        mode = 0
        for k in range(npair):
            w_ = min(int(Pt[k, 20]), x0 + tw - 1) - max(int(Pt[k, 19]), x0) + 1
            h_ = min(int(Pt[k, 22]), y0 + th - 1) - max(int(Pt[k, 21]), y0) + 1
            if w_ > 0 and h_ > 0:
                cap += w_ * h_
    frag_q = np.empty(cap, dtype=np.int32)
    frag_k = np.empty(cap, dtype=np.int64)
    frag_rho = np.empty(cap)
    frag_z = np.empty(cap)
    nrec = _tile_pass(mode, Pt, its, 0, npair, x0, y0, tw, th, invf, cx, cy, ortho, near, inv_rf2, kappa,
                      eps_factor, sign, has_clip, eye, frame, clip_offsets, clip_planes, clip_mode, clip_tree,
                      clip_leaf, work, lz, lw, lc, ln, ld, lcount, frag_q, frag_k, frag_rho, frag_z)
    if visibility:
        for i in range(th):
            for j in range(tw):
                zvis[y0 + i, x0 + j] = lz[i * tw + j]
        _accumulate_records(nrec, Pt, kappa, sign, lz, lw, lc, ln, ld, lcount, frag_q, frag_k, frag_rho, frag_z)
        # full update: overwrite the tile (the tile-local sums start from zero, so these are the
        # values that clearing and adding would give, bit for bit)
        touched = 0
        for i in range(th):
            for j in range(tw):
                q = i * tw + j
                gy = y0 + i
                gx = x0 + j
                count[gy, gx] = lcount[q]
                acc_w[gy, gx] = lw[q]
                acc_z[gy, gx] = ld[q]
                for k3 in range(3):
                    acc_c[gy, gx, k3] = lc[q, k3]
                    acc_n[gy, gx, k3] = ln[q, k3]
                if lcount[q] != 0:
                    touched = 1
        dirty[t] = touched
        return
    for i in range(th):
        for j in range(tw):
            q = i * tw + j
            if lcount[q] == 0:
                continue
            gy = y0 + i
            gx = x0 + j
            c = count[gy, gx] + (lcount[q] if sign > 0 else -lcount[q])
            count[gy, gx] = c
            dirty[t] = 1
            if c <= 0:
                _zero_pixel(count, acc_w, acc_z, acc_c, acc_n, gy, gx)
                continue
            acc_w[gy, gx] += lw[q]
            acc_z[gy, gx] += ld[q]
            for k3 in range(3):
                acc_c[gy, gx, k3] += lc[q, k3]
                acc_n[gy, gx, k3] += ln[q, k3]


@njit(cache=True, parallel=True)
def splat_resolve(acc_w, acc_c, acc_n, acc_z, count, frame, albedo, normal, depth, covered, weight):
    """Normalisation pass: where splats contributed, overwrite the G-buffer with
    ``sum w c / sum w``, the normalised ``sum w n`` rotated to world space (``-forward`` if it
    vanishes), ``sum w z / sum w`` and the accumulated weight."""
    H, W = acc_w.shape
    for py in prange(H):
        for px in range(W):
            w = acc_w[py, px]
            if count[py, px] <= 0 or not (w > 0.0):
                continue
            for k in range(3):
                albedo[py, px, k] = min(max(acc_c[py, px, k] / w, 0.0), 1.0)
            nx = acc_n[py, px, 0]
            ny = acc_n[py, px, 1]
            nz = acc_n[py, px, 2]
            ln = math.sqrt(nx * nx + ny * ny + nz * nz)
            if ln > 1e-12 * abs(w):
                nx /= ln
                ny /= ln
                nz /= ln
            else:
                nx = 0.0
                ny = 0.0
                nz = -1.0
            for k in range(3):
                normal[py, px, k] = frame[0, k] * nx + frame[1, k] * ny + frame[2, k] * nz
            depth[py, px] = acc_z[py, px] / w
            covered[py, px] = True
            weight[py, px] = w


@njit(cache=True, parallel=True)
def fill_tiles(Pt, offsets, order, tile, W, H, out):
    """Benchmark baseline: visit the pixels :func:`splat_tiles` may evaluate (every pair's box
    within each tile, reading the same pair rows), twice, with a trivial depth-test-like write
    and no EWA arithmetic. ``out`` (H,W) receives the pass-2 visit counts."""
    ntx = (W + tile - 1) // tile
    for kk in prange(order.shape[0]):
        t = order[kk]
        a = offsets[t]
        b = offsets[t + 1]
        if a == b:
            continue
        x0, y0, tw, th = tile_rect(t, ntx, tile, W, H)
        lz = np.full(tw * th, np.inf)
        lw = np.zeros(tw * th)
        for mode in range(2):
            for k in range(a, b):
                bx0 = max(int(Pt[k, 19]), x0)
                bx1 = min(int(Pt[k, 20]), x0 + tw - 1)
                by0 = max(int(Pt[k, 21]), y0)
                by1 = min(int(Pt[k, 22]), y0 + th - 1)
                zz = Pt[k, 0]
                for py in range(by0, by1 + 1):
                    row = (py - y0) * tw - x0
                    for px in range(bx0, bx1 + 1):
                        if mode == 0:
                            lz[row + px] = min(lz[row + px], zz)
                        elif zz <= lz[row + px]:
                            lw[row + px] += 1.0
        for i in range(th):
            for j in range(tw):
                out[y0 + i, x0 + j] = lw[i * tw + j]
