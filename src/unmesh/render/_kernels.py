"""Numba kernels shared by the renderers: screen bounds, tile binning, deferred shading.

All kernels take arrays and scalars only. Camera parameters are the scalars of
:meth:`unmesh.render.camera.Camera.kernel_params`: ``f`` (pixels per unit), ``cx = W/2``,
``cy = H/2``, ``ortho`` (0/1) and ``near``. The ray through the centre of pixel ``(py, px)``
in camera space is ``o + t d`` with ``X = (px + 0.5 - cx)/f``, ``Y = -(py + 0.5 - cy)/f`` and

* perspective: ``o = 0``, ``d = (X, Y, 1)``;
* orthographic: ``o = (X, Y, 0)``, ``d = (0, 0, 1)``;

so ``d_z = 1`` and the ray parameter ``t`` of a hit *is* its depth. Plain numpy references are in
:mod:`unmesh.render._reference`.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit, prange

from unmesh._threads import SERIAL_BELOW, serial_if_small

__all__ = ["SERIAL_BELOW", "bin_boxes", "box_visits", "clear_background", "facing_rows", "load_tile", "serial_if_small", "shade_pixels", "sphere_box",
           "tile_order", "tile_rect"]

# The thread policy (one thread below SERIAL_BELOW work items: launching a parallel region costs
# more than it saves for small partial updates) is unmesh._threads'; re-exported for the renderers.


def box_visits(box: np.ndarray) -> int:
    """Total number of pixels in the (N, 4) inclusive pixel boxes (a work estimate)."""
    w = np.clip(box[:, 1].astype(np.int64) - box[:, 0] + 1, 0, None)
    h = np.clip(box[:, 3].astype(np.int64) - box[:, 2] + 1, 0, None)
    return int(np.sum(w * h))


@njit(cache=True)
def sphere_box(x, y, z, r, f, cx, cy, ortho, near, W, H, pad):
    """Pixel index range ``(x0, x1, y0, y1)`` (inclusive) of pixel centres that may see a sphere.

    The sphere has camera-space centre ``(x, y, z)`` and radius ``r``; ``pad`` (pixels) widens
    the range. Returns ``x0 > x1`` when nothing can be visible. Exact tangent-cone bounds in
    perspective, the whole screen when the sphere reaches the eye plane.
    """
    if z + r <= near:
        return 1, 0, 1, 0
    if ortho:
        cmin = cx + f * (x - r) - pad
        cmax = cx + f * (x + r) + pad
        rmin = cy - f * (y + r) - pad
        rmax = cy - f * (y - r) + pad
    elif z - r <= near or z * z - r * r <= 1e-12 * z * z:
        cmin = -1e30
        cmax = 1e30
        rmin = -1e30
        rmax = 1e30
    else:
        den = z * z - r * r
        sx = r * math.sqrt(max(x * x + den, 0.0))
        sy = r * math.sqrt(max(y * y + den, 0.0))
        cmin = cx + f * (x * z - sx) / den - pad
        cmax = cx + f * (x * z + sx) / den + pad
        rmin = cy - f * (y * z + sy) / den - pad
        rmax = cy - f * (y * z - sy) / den + pad
    x0 = max(math.ceil(max(cmin, -2.0) - 0.5), 0)
    x1 = min(math.floor(min(cmax, W + 2.0) - 0.5), W - 1)
    y0 = max(math.ceil(max(rmin, -2.0) - 0.5), 0)
    y1 = min(math.floor(min(rmax, H + 2.0) - 0.5), H - 1)
    return x0, x1, y0, y1


@njit(cache=True, parallel=True)
def bin_boxes(box, group, ngroups, tile, ntx, nty, nchunks):
    """Bucket primitives into screen tiles by their pixel boxes.

    Parameters
    ----------
    box : (N, 4) int32
        ``x0, x1, y0, y1`` inclusive pixel ranges; ``x0 > x1`` or ``y0 > y1`` means culled.
    group : (N,) int8
        Group of each primitive in ``[0, ngroups)``; within a tile, group 0 comes first (e.g.
        front-facing surfels before back-facing ones, so early depth rejection works).
    tile : int
        Tile edge in pixels.
    ntx, nty : int
        Tiles per row and column.
    nchunks : int
        Number of primitive chunks counted and filled in parallel.

    Returns
    -------
    offsets : (ntx*nty + 1,) int64
        Tile ``t`` holds ``items[offsets[t]:offsets[t+1]]``.
    items : (P,) int32
        Primitive indices; within a tile sorted by group, then ascending (deterministic).
    """
    n = box.shape[0]
    ntiles = ntx * nty
    nslot = ntiles * ngroups
    counts = np.zeros((nchunks, nslot), dtype=np.int64)
    step = (n + nchunks - 1) // nchunks
    for c in prange(nchunks):
        lo = c * step
        hi = min(n, lo + step)
        for i in range(lo, hi):
            if box[i, 0] > box[i, 1] or box[i, 2] > box[i, 3]:
                continue
            g = group[i]
            for ty in range(box[i, 2] // tile, box[i, 3] // tile + 1):
                for tx in range(box[i, 0] // tile, box[i, 1] // tile + 1):
                    counts[c, (ty * ntx + tx) * ngroups + g] += 1
    offsets = np.zeros(ntiles + 1, dtype=np.int64)
    starts = np.zeros((nchunks, nslot), dtype=np.int64)
    total = 0
    for t in range(ntiles):
        offsets[t] = total
        for g in range(ngroups):
            for c in range(nchunks):
                starts[c, t * ngroups + g] = total
                total += counts[c, t * ngroups + g]
    offsets[ntiles] = total
    items = np.empty(total, dtype=np.int32)
    for c in prange(nchunks):
        lo = c * step
        hi = min(n, lo + step)
        for i in range(lo, hi):
            if box[i, 0] > box[i, 1] or box[i, 2] > box[i, 3]:
                continue
            g = group[i]
            for ty in range(box[i, 2] // tile, box[i, 3] // tile + 1):
                for tx in range(box[i, 0] // tile, box[i, 1] // tile + 1):
                    q = (ty * ntx + tx) * ngroups + g
                    items[starts[c, q]] = i
                    starts[c, q] += 1
    return offsets, items


@njit(cache=True, inline="always")
def tile_rect(t, ntx, tile, W, H):
    """Pixel rectangle ``(x0, y0, tw, th)`` of tile ``t`` in a row-major grid of ``ntx`` tiles per row."""
    tyi = t // ntx
    txi = t - tyi * ntx
    x0 = txi * tile
    y0 = tyi * tile
    return x0, y0, min(tile, W - x0), min(tile, H - y0)


@njit(cache=True, inline="always")
def load_tile(image, x0, y0, tw, th):
    """Copy of the (th, tw) block of a 2-D ``image`` at ``(y0, x0)``, flattened row by row."""
    out = np.empty(tw * th)
    for i in range(th):
        for j in range(tw):
            out[i * tw + j] = image[y0 + i, x0 + j]
    return out


def tile_order(ntiles: int) -> np.ndarray:
    """A fixed pseudo-random permutation of tile indices (int64) that balances the static
    split of ``prange`` between threads (dense and empty tiles are mixed in every chunk).

    A copy of a cached permutation: a new random generator per call costs about 0.1 ms, which
    small partial updates (5.7) would pay on every splat and unsplat."""
    return _tile_order(int(ntiles)).copy()


@functools.lru_cache(maxsize=16)
def _tile_order(ntiles: int) -> np.ndarray:
    return np.random.default_rng(20070101).permutation(ntiles).astype(np.int64)


@njit(cache=True)
def facing_rows(rows, pos, nrm, eye, forward, ortho):
    """The entries ``i`` of ``rows`` (M,) int64, in order, whose normal ``nrm[i]`` faces the
    camera: ``n . (eye - pos[i]) > 0``, or ``n . -forward > 0`` when ``ortho`` (``pos``, ``nrm``
    (N, 3) float64; :meth:`unmesh.render.Camera.facing` without gathering the rows first)."""
    out = np.empty(rows.shape[0], dtype=np.int64)
    m = 0
    for k in range(rows.shape[0]):
        i = rows[k]
        if ortho:
            d = nrm[i, 0] * -forward[0] + nrm[i, 1] * -forward[1] + nrm[i, 2] * -forward[2]
        else:
            d = nrm[i, 0] * (eye[0] - pos[i, 0]) + nrm[i, 1] * (eye[1] - pos[i, 1]) + nrm[i, 2] * (eye[2] - pos[i, 2])
        if d > 0.0:
            out[m] = i
            m += 1
    return out[:m]


@njit(cache=True, parallel=True)
def clear_background(covered, depth, normal, weight):
    """Where ``covered`` (H,W) bool is false: ``depth`` (H,W) = inf, ``normal`` (H,W,3) = 0,
    ``weight`` (H,W) = 0, in place (one pass; the G-buffer's background convention)."""
    H, W = covered.shape
    for py in prange(H):
        for px in range(W):
            if not covered[py, px]:
                depth[py, px] = np.inf
                normal[py, px, 0] = 0.0
                normal[py, px, 1] = 0.0
                normal[py, px, 2] = 0.0
                weight[py, px] = 0.0


@njit(cache=True, inline="always")
def _int_power(x, n):
    """``x ** n`` for an integer ``n >= 0`` by repeated squaring (equal to ``pow`` up to round-off)."""
    result = 1.0
    while n > 0:
        if n & 1:
            result *= x
        x *= x
        n >>= 1
    return result


@njit(cache=True, parallel=True)
def shade_pixels(albedo, normal, depth, covered, f, cx, cy, ortho, frame, light_dirs, light_cols,
                 ambient, specular, shininess, background, out):
    """Deferred Blinn-Phong shading of a G-buffer (two-sided: normals facing away are flipped).

    ``albedo``, ``normal`` (world, unit) (H,W,3); ``depth`` (H,W); ``covered`` (H,W) bool;
    ``frame`` (3,3) world-to-camera rows; ``light_dirs`` (L,3) unit world directions *towards*
    the lights, ``light_cols`` (L,3) their colours times intensity. Writes ``out`` (H,W,3):
    ``albedo (ambient + sum_l c_l max(0, n.l)) + specular sum_l c_l max(0, n.h)^shininess``,
    clipped to [0, 1]; ``background`` where not covered.
    """
    H, W = depth.shape
    nl = light_dirs.shape[0]
    # integral exponents (the default 40) by repeated squaring: pow() was the costliest step
    ishin = int(shininess) if shininess == math.floor(shininess) and 0.0 <= shininess <= 1024.0 else -1
    for py in prange(H):
        Y = -(py + 0.5 - cy) / f
        for px in range(W):
            if not covered[py, px]:
                for k in range(3):
                    out[py, px, k] = background[k]
                continue
            X = (px + 0.5 - cx) / f
            # unit view vector (towards the eye) in world space
            if ortho:
                vx = -frame[2, 0]
                vy = -frame[2, 1]
                vz = -frame[2, 2]
            else:
                dx = X * frame[0, 0] + Y * frame[1, 0] + frame[2, 0]
                dy = X * frame[0, 1] + Y * frame[1, 1] + frame[2, 1]
                dz = X * frame[0, 2] + Y * frame[1, 2] + frame[2, 2]
                dl = math.sqrt(dx * dx + dy * dy + dz * dz)
                vx = -dx / dl
                vy = -dy / dl
                vz = -dz / dl
            nx = normal[py, px, 0]
            ny = normal[py, px, 1]
            nz = normal[py, px, 2]
            if nx * vx + ny * vy + nz * vz < 0.0:
                nx = -nx
                ny = -ny
                nz = -nz
            dr = ambient
            dg = ambient
            db = ambient
            sr = 0.0
            sg = 0.0
            sb = 0.0
            for j in range(nl):
                lx = light_dirs[j, 0]
                ly = light_dirs[j, 1]
                lz = light_dirs[j, 2]
                ndl = nx * lx + ny * ly + nz * lz
                if ndl <= 0.0:
                    continue
                dr += light_cols[j, 0] * ndl
                dg += light_cols[j, 1] * ndl
                db += light_cols[j, 2] * ndl
                if specular > 0.0:
                    hx = lx + vx
                    hy = ly + vy
                    hz = lz + vz
                    hl = math.sqrt(hx * hx + hy * hy + hz * hz)
                    if hl > 0.0:
                        ndh = (nx * hx + ny * hy + nz * hz) / hl
                        if ndh > 0.0:
                            sp = _int_power(ndh, ishin) if ishin >= 0 else ndh**shininess
                            sr += light_cols[j, 0] * sp
                            sg += light_cols[j, 1] * sp
                            sb += light_cols[j, 2] * sp
            out[py, px, 0] = min(max(albedo[py, px, 0] * dr + specular * sr, 0.0), 1.0)
            out[py, px, 1] = min(max(albedo[py, px, 1] * dg + specular * sg, 0.0), 1.0)
            out[py, px, 2] = min(max(albedo[py, px, 2] * db + specular * sb, 0.0), 1.0)
