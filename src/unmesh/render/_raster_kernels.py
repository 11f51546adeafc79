"""Numba kernels of the opaque rasterisers: triangles (z-buffer) and particle spheres.

Both are tiled like splatting (:mod:`unmesh.render._kernels`): a setup kernel computes
per-primitive camera-space data and pixel boxes, :func:`unmesh.render._kernels.bin_boxes`
buckets them, and a tile kernel (parallel over tiles, no write races) ray-casts each pixel
centre against the tile's primitives and writes the nearest hit into the G-buffer where it is
nearer than what the G-buffer already holds.

Triangles use the Moller-Trumbore ray-triangle test in camera space, so barycentrics are
perspective-correct and the ray parameter is the depth (``d_z = 1``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from unmesh.render._kernels import load_tile, sphere_box, tile_rect

__all__ = ["sphere_setup", "sphere_tiles", "texel_lod", "texture_level", "triangle_setup", "triangle_tiles"]


@njit(cache=True)
def _project_range(x, y, z, f, cx, cy, ortho, lo_c, hi_c, lo_r, hi_r):
    if ortho:
        col = cx + f * x
        row = cy - f * y
    else:
        col = cx + f * x / z
        row = cy - f * y / z
    return min(lo_c, col), max(hi_c, col), min(lo_r, row), max(hi_r, row)


@njit(cache=True, parallel=True)
def triangle_setup(vertices, faces, frame, eye, f, cx, cy, ortho, near, W, H, T, box):
    """Camera-space triangles ``T`` (F, 13): ``v0, e1 = v1 - v0, e2 = v2 - v0`` and the pixel box
    (also in ``box`` (F, 4) int32) of the part in front of the near plane (clipped polygon)."""
    nf = faces.shape[0]
    for i in prange(nf):
        cv = np.empty((3, 3))
        for k in range(3):
            v = faces[i, k]
            qx = vertices[v, 0] - eye[0]
            qy = vertices[v, 1] - eye[1]
            qz = vertices[v, 2] - eye[2]
            for j in range(3):
                cv[k, j] = frame[j, 0] * qx + frame[j, 1] * qy + frame[j, 2] * qz
        for j in range(3):
            T[i, j] = cv[0, j]
            T[i, 3 + j] = cv[1, j] - cv[0, j]
            T[i, 6 + j] = cv[2, j] - cv[0, j]
        lo_c = np.inf
        hi_c = -np.inf
        lo_r = np.inf
        hi_r = -np.inf
        nin = 0
        for k in range(3):
            if cv[k, 2] > near:
                nin += 1
                lo_c, hi_c, lo_r, hi_r = _project_range(cv[k, 0], cv[k, 1], cv[k, 2], f, cx, cy, ortho,
                                                        lo_c, hi_c, lo_r, hi_r)
        if nin < 3 and nin > 0:
            # points where the edges cross the near plane
            for k in range(3):
                k2 = (k + 1) % 3
                za = cv[k, 2] - near
                zb = cv[k2, 2] - near
                if (za > 0.0) != (zb > 0.0):
                    s = za / (za - zb)
                    x = cv[k, 0] + s * (cv[k2, 0] - cv[k, 0])
                    y = cv[k, 1] + s * (cv[k2, 1] - cv[k, 1])
                    lo_c, hi_c, lo_r, hi_r = _project_range(x, y, near, f, cx, cy, ortho, lo_c, hi_c, lo_r, hi_r)
        if nin == 0 or not (hi_c >= lo_c):
            box[i, 0] = 1
            box[i, 1] = 0
            box[i, 2] = 1
            box[i, 3] = 0
        else:
            pad = 1e-6
            box[i, 0] = max(math.ceil(max(lo_c, -2.0) - 0.5 - pad), 0)
            box[i, 1] = min(math.floor(min(hi_c, W + 2.0) - 0.5 + pad), W - 1)
            box[i, 2] = max(math.ceil(max(lo_r, -2.0) - 0.5 - pad), 0)
            box[i, 3] = min(math.floor(min(hi_r, H + 2.0) - 0.5 + pad), H - 1)
        for j in range(4):
            T[i, 9 + j] = box[i, j]


@njit(cache=True)
def _bilinear(img, u, v, out):
    """Bilinear texture lookup at ``(u, v)``, (0, 0) = bottom-left of the image (row 0 on top).

    Coordinates outside [0, 1] repeat (the integer part is dropped); within the texture the
    bilinear neighbours are clamped to the edge texels, so borders do not bleed into each other.
    """
    h = img.shape[0]
    w = img.shape[1]
    if u < 0.0 or u > 1.0:
        u -= math.floor(u)
    if v < 0.0 or v > 1.0:
        v -= math.floor(v)
    x = min(max(u * w - 0.5, 0.0), w - 1.0)
    y = min(max((1.0 - v) * h - 0.5, 0.0), h - 1.0)
    ix0 = min(int(x), w - 1)
    iy0 = min(int(y), h - 1)
    fx = x - ix0
    fy = y - iy0
    ix1 = min(ix0 + 1, w - 1)
    iy1 = min(iy0 + 1, h - 1)
    for k in range(3):
        a = img[iy0, ix0, k] * (1.0 - fx) + img[iy0, ix1, k] * fx
        b = img[iy1, ix0, k] * (1.0 - fx) + img[iy1, ix1, k] * fx
        out[k] = a * (1.0 - fy) + b * fy


@njit(cache=True, parallel=True)
def texture_level(prev, regions, s, out):
    """One filtered texture level (h, w, c) from the previous one: taps (1/8, 3/4, 1/8) spaced
    ``s`` texels along both axes (edges clamped), only where the tap's ``regions`` id (h, w)
    equals the centre's, weights renormalised (numpy reference:
    :func:`unmesh.render.raster.texture_level_reference`)."""
    h = prev.shape[0]
    w = prev.shape[1]
    nc = prev.shape[2]
    for i in prange(h):
        acc = np.empty(nc)
        for j in range(w):
            r0 = regions[i, j]
            wsum = 0.0
            for k in range(nc):
                acc[k] = 0.0
            for a in range(3):
                ii = min(max(i + (a - 1) * s, 0), h - 1)
                wy = 0.75 if a == 1 else 0.125
                for b in range(3):
                    jj = min(max(j + (b - 1) * s, 0), w - 1)
                    if regions[ii, jj] != r0:
                        continue
                    wt = wy * (0.75 if b == 1 else 0.125)
                    wsum += wt
                    for k in range(nc):
                        acc[k] += wt * prev[ii, jj, k]
            for k in range(nc):
                out[i, j, k] = acc[k] / wsum


@njit(cache=True)
def _level(flat, dims, k):
    """Level ``k`` (h, w, 3) of a texture stored as a flat (N, 3) buffer with ``dims`` (L, 3)
    rows (offset, h, w)."""
    o = dims[k, 0]
    return flat[o:o + dims[k, 1] * dims[k, 2]].reshape((dims[k, 1], dims[k, 2], 3))


@njit(cache=True)
def _lookup(flat, dims, u, v, lod, out, tmp):
    """Trilinear lookup in the levels of one texture (:func:`unmesh.render.raster.texture_levels`,
    flat buffer ``flat`` (N, 3), ``dims`` (L, 3): offset, height, width per level): bilinear at
    (u, v) in levels ``floor(lod)`` and ``floor(lod) + 1``, blended linearly; ``lod <= 0``
    (magnification) or a single level: bilinear in level 0."""
    nl = dims.shape[0]
    if nl == 1 or not (lod > 0.0):
        _bilinear(_level(flat, dims, 0), u, v, out)
        return
    if lod >= nl - 1.0:
        _bilinear(_level(flat, dims, nl - 1), u, v, out)
        return
    i0 = int(lod)
    fr = lod - i0
    _bilinear(_level(flat, dims, i0), u, v, out)
    _bilinear(_level(flat, dims, i0 + 1), u, v, tmp)
    for k in range(3):
        out[k] = out[k] * (1.0 - fr) + tmp[k] * fr


@njit(cache=True, inline="always")
def _ray(X, Y, ortho):
    """Origin ``(ox, oy, 0)`` and direction ``(dx, dy, 1)`` of the ray through image-plane point (X, Y)."""
    if ortho:
        return X, Y, 0.0, 0.0
    return 0.0, 0.0, X, Y


@njit(cache=True)
def _plane_bary(T, fi, X, Y, ortho):
    """Barycentrics (u, v) where the ray of the image-plane point (X, Y) meets the plane of
    triangle ``fi`` (no inside test); NaN when the ray is parallel to it or meets it behind
    the eye."""
    ox, oy, dx, dy = _ray(X, Y, ortho)
    e1x = T[fi, 3]
    e1y = T[fi, 4]
    e1z = T[fi, 5]
    e2x = T[fi, 6]
    e2y = T[fi, 7]
    e2z = T[fi, 8]
    pvx = dy * e2z - e2y
    pvy = e2x - dx * e2z
    pvz = dx * e2y - dy * e2x
    det = e1x * pvx + e1y * pvy + e1z * pvz
    if abs(det) < 1e-300:
        return np.nan, np.nan
    inv = 1.0 / det
    tvx = ox - T[fi, 0]
    tvy = oy - T[fi, 1]
    tvz = -T[fi, 2]
    u = (tvx * pvx + tvy * pvy + tvz * pvz) * inv
    qvx = tvy * e1z - tvz * e1y
    qvy = tvz * e1x - tvx * e1z
    qvz = tvx * e1y - tvy * e1x
    v = (dx * qvx + dy * qvy + qvz) * inv
    z = (e2x * qvx + e2y * qvy + e2z * qvz) * inv
    if not ortho and not (z > 0.0):
        return np.nan, np.nan
    return u, v


@njit(cache=True)
def texel_lod(T, fi, corner_uv, px, py, f, cx, cy, ortho, tw, th):
    """Level of detail ``log2(rho)`` of pixel (px, py) on triangle ``fi`` for a texture of
    tw x th texels: rho = the longer of the pixel's two edge vectors in texel units, from the
    texture coordinates where the rays of the pixel centre and of its right and lower
    neighbours meet the triangle's plane (the derivatives of a GPU's mip-map selection, by
    finite differences). ``inf`` when a neighbour's ray misses the plane (grazing)."""
    invf = 1.0 / f
    X = (px + 0.5 - cx) * invf
    Y = (cy - (py + 0.5)) * invf
    tuv = np.empty((3, 2))
    for k in range(3):
        xx = X + invf if k == 1 else X
        yy = Y - invf if k == 2 else Y
        u, v = _plane_bary(T, fi, xx, yy, ortho)
        if not (u == u):
            return np.inf
        w0 = 1.0 - u - v
        tuv[k, 0] = (w0 * corner_uv[fi, 0, 0] + u * corner_uv[fi, 1, 0] + v * corner_uv[fi, 2, 0]) * tw
        tuv[k, 1] = (w0 * corner_uv[fi, 0, 1] + u * corner_uv[fi, 1, 1] + v * corner_uv[fi, 2, 1]) * th
    ax = tuv[1, 0] - tuv[0, 0]
    ay = tuv[1, 1] - tuv[0, 1]
    bx = tuv[2, 0] - tuv[0, 0]
    by = tuv[2, 1] - tuv[0, 1]
    rho2 = max(ax * ax + ay * ay, bx * bx + by * by)
    if rho2 <= 0.0:
        return -np.inf
    return 0.5 * math.log2(rho2)


@njit(cache=True)
def _triangle_tile_loop(T, items, a, b, x0, y0, tw, th, f, cx, cy, ortho, near, lz, lf, lu, lv):
    """Nearest triangle per pixel of one tile (Moller-Trumbore in camera space).

    A pixel centre counts as inside when its barycentrics are >= -1e-12 (shared edges are
    covered by both triangles, never by neither); on equal depth the earlier face wins.
    """
    tol = 1e-12
    invf = 1.0 / f
    for k in range(a, b):
        fi = items[k]
        bx0 = max(int(T[fi, 9]), x0)
        bx1 = min(int(T[fi, 10]), x0 + tw - 1)
        by0 = max(int(T[fi, 11]), y0)
        by1 = min(int(T[fi, 12]), y0 + th - 1)
        v0x = T[fi, 0]
        v0y = T[fi, 1]
        v0z = T[fi, 2]
        e1x = T[fi, 3]
        e1y = T[fi, 4]
        e1z = T[fi, 5]
        e2x = T[fi, 6]
        e2y = T[fi, 7]
        e2z = T[fi, 8]
        for py in range(by0, by1 + 1):
            Y = (cy - (py + 0.5)) * invf
            row = (py - y0) * tw - x0
            for px in range(bx0, bx1 + 1):
                X = (px + 0.5 - cx) * invf
                ox, oy, dx, dy = _ray(X, Y, ortho)
                # pvec = d x e2, with d = (dx, dy, 1)
                pvx = dy * e2z - e2y
                pvy = e2x - dx * e2z
                pvz = dx * e2y - dy * e2x
                det = e1x * pvx + e1y * pvy + e1z * pvz
                if abs(det) < 1e-300:
                    continue
                inv = 1.0 / det
                tvx = ox - v0x
                tvy = oy - v0y
                tvz = -v0z
                u = (tvx * pvx + tvy * pvy + tvz * pvz) * inv
                if u < -tol or u > 1.0 + tol:
                    continue
                qvx = tvy * e1z - tvz * e1y
                qvy = tvz * e1x - tvx * e1z
                qvz = tvx * e1y - tvy * e1x
                v = (dx * qvx + dy * qvy + qvz) * inv
                if v < -tol or u + v > 1.0 + tol:
                    continue
                z = (e2x * qvx + e2y * qvy + e2z * qvz) * inv
                idx = row + px
                if z <= near or not (z < lz[idx]):
                    continue
                lz[idx] = z
                lf[idx] = fi
                lu[idx] = u
                lv[idx] = v


@njit(cache=True, parallel=True)
def triangle_tiles(T, items, offsets, order, tile, W, H, f, cx, cy, ortho, near, corner_normals, corner_colors,
                   corner_uv, texture, texture_dims, has_texture, normal_map, normal_dims, has_normal_map,
                   corner_tangents, corner_bitangents,
                   depth, albedo, normal, covered, weight):
    """Z-buffer the binned triangles and write their G-buffer entries.

    ``corner_*`` arrays are (F, 3, k) per face corner: world normals, colours, uv (when
    ``has_texture`` or ``has_normal_map``), tangent and bitangent (for the normal map).
    ``texture`` and ``normal_map`` are the filtered levels of an image (row 0 at the top;
    :func:`unmesh.render.raster.texture_levels`) in one flat (N, 3) buffer each, with
    ``texture_dims``/``normal_dims`` (L, 3) int64 rows (offset, height, width); they are looked
    up trilinearly at the pixel's texel footprint (:func:`texel_lod`); one level = bilinear. The G-buffer arrays
    (``depth`` etc.) are updated where a triangle is nearer than their current depth.
    """
    ntx = (W + tile - 1) // tile
    for kk in prange(order.shape[0]):
        t = order[kk]
        a = offsets[t]
        b = offsets[t + 1]
        if a == b:
            continue
        x0, y0, tw, th = tile_rect(t, ntx, tile, W, H)
        m = tw * th
        lz = load_tile(depth, x0, y0, tw, th)
        lf = np.full(m, -1, dtype=np.int64)
        lu = np.zeros(m)
        lv = np.zeros(m)
        _triangle_tile_loop(T, items, a, b, x0, y0, tw, th, f, cx, cy, ortho, near, lz, lf, lu, lv)
        col = np.empty(3)
        tex = np.empty(3)
        tmp = np.empty(3)
        tg = np.empty(3)
        bt = np.empty(3)
        for i in range(th):
            for j in range(tw):
                q = i * tw + j
                fi = lf[q]
                if fi < 0:
                    continue
                gy = y0 + i
                gx = x0 + j
                u = lu[q]
                v = lv[q]
                w0 = 1.0 - u - v
                nx = w0 * corner_normals[fi, 0, 0] + u * corner_normals[fi, 1, 0] + v * corner_normals[fi, 2, 0]
                ny = w0 * corner_normals[fi, 0, 1] + u * corner_normals[fi, 1, 1] + v * corner_normals[fi, 2, 1]
                nz = w0 * corner_normals[fi, 0, 2] + u * corner_normals[fi, 1, 2] + v * corner_normals[fi, 2, 2]
                ln = math.sqrt(nx * nx + ny * ny + nz * nz)
                if ln > 0.0:
                    nx /= ln
                    ny /= ln
                    nz /= ln
                for c in range(3):
                    col[c] = w0 * corner_colors[fi, 0, c] + u * corner_colors[fi, 1, c] + v * corner_colors[fi, 2, c]
                if has_texture or has_normal_map:
                    tu = w0 * corner_uv[fi, 0, 0] + u * corner_uv[fi, 1, 0] + v * corner_uv[fi, 2, 0]
                    tv = w0 * corner_uv[fi, 0, 1] + u * corner_uv[fi, 1, 1] + v * corner_uv[fi, 2, 1]
                    lod_t = 0.0
                    if has_texture and texture_dims.shape[0] > 1:
                        lod_t = texel_lod(T, fi, corner_uv, gx, gy, f, cx, cy, ortho, texture_dims[0, 2],
                                          texture_dims[0, 1])
                    if has_texture:
                        _lookup(texture, texture_dims, tu, tv, lod_t, tex, tmp)
                        for c in range(3):
                            col[c] *= tex[c]
                    if has_normal_map:
                        lod_n = 0.0
                        if normal_dims.shape[0] > 1:
                            same = normal_dims[0, 1] == texture_dims[0, 1] and normal_dims[0, 2] == texture_dims[0, 2]
                            if has_texture and texture_dims.shape[0] > 1 and same:
                                lod_n = lod_t
                            else:
                                lod_n = texel_lod(T, fi, corner_uv, gx, gy, f, cx, cy, ortho, normal_dims[0, 2],
                                                  normal_dims[0, 1])
                        _lookup(normal_map, normal_dims, tu, tv, lod_n, tex, tmp)
                        sx = 2.0 * tex[0] - 1.0
                        sy = 2.0 * tex[1] - 1.0
                        sz = 2.0 * tex[2] - 1.0
                        for c in range(3):
                            tg[c] = w0 * corner_tangents[fi, 0, c] + u * corner_tangents[fi, 1, c] + v * corner_tangents[fi, 2, c]
                            bt[c] = w0 * corner_bitangents[fi, 0, c] + u * corner_bitangents[fi, 1, c] + v * corner_bitangents[fi, 2, c]
                        # Gram-Schmidt: make the frame orthonormal around the interpolated normal
                        d = tg[0] * nx + tg[1] * ny + tg[2] * nz
                        tg[0] -= d * nx
                        tg[1] -= d * ny
                        tg[2] -= d * nz
                        lt = math.sqrt(tg[0] ** 2 + tg[1] ** 2 + tg[2] ** 2)
                        if lt > 0.0:
                            for c in range(3):
                                tg[c] /= lt
                            d = bt[0] * nx + bt[1] * ny + bt[2] * nz
                            d2 = bt[0] * tg[0] + bt[1] * tg[1] + bt[2] * tg[2]
                            for c in range(3):
                                bt[c] -= d * (nx if c == 0 else (ny if c == 1 else nz)) + d2 * tg[c]
                            lb = math.sqrt(bt[0] ** 2 + bt[1] ** 2 + bt[2] ** 2)
                            if lb > 0.0:
                                for c in range(3):
                                    bt[c] /= lb
                                mx = sx * tg[0] + sy * bt[0] + sz * nx
                                my = sx * tg[1] + sy * bt[1] + sz * ny
                                mz = sx * tg[2] + sy * bt[2] + sz * nz
                                lm = math.sqrt(mx * mx + my * my + mz * mz)
                                if lm > 0.0:
                                    nx = mx / lm
                                    ny = my / lm
                                    nz = mz / lm
                depth[gy, gx] = lz[q]
                normal[gy, gx, 0] = nx
                normal[gy, gx, 1] = ny
                normal[gy, gx, 2] = nz
                for c in range(3):
                    albedo[gy, gx, c] = min(max(col[c], 0.0), 1.0)
                covered[gy, gx] = True
                weight[gy, gx] = 1.0


@njit(cache=True, parallel=True)
def sphere_setup(centers, radii, frame, eye, f, cx, cy, ortho, near, W, H, rfilter, S, box):
    """Camera-space spheres ``S`` (N, 8): centre (3), radius, projected centre (col, row) and
    ``r^2``, ``|c|^2 - r^2``; pixel boxes (N, 4) int32 widened by the screen filter radius."""
    n = centers.shape[0]
    for i in prange(n):
        qx = centers[i, 0] - eye[0]
        qy = centers[i, 1] - eye[1]
        qz = centers[i, 2] - eye[2]
        c0 = frame[0, 0] * qx + frame[0, 1] * qy + frame[0, 2] * qz
        c1 = frame[1, 0] * qx + frame[1, 1] * qy + frame[1, 2] * qz
        c2 = frame[2, 0] * qx + frame[2, 1] * qy + frame[2, 2] * qz
        r = radii[i]
        S[i, 0] = c0
        S[i, 1] = c1
        S[i, 2] = c2
        S[i, 3] = r
        if ortho:
            S[i, 4] = cx + f * c0
            S[i, 5] = cy - f * c1
        elif c2 > near:
            S[i, 4] = cx + f * c0 / c2
            S[i, 5] = cy - f * c1 / c2
        else:
            S[i, 4] = np.nan
            S[i, 5] = np.nan
        S[i, 6] = r * r
        S[i, 7] = c0 * c0 + c1 * c1 + c2 * c2 - r * r
        x0, x1, y0, y1 = sphere_box(c0, c1, c2, r, f, cx, cy, ortho, near, W, H, rfilter)
        box[i, 0] = x0
        box[i, 1] = x1
        box[i, 2] = y0
        box[i, 3] = y1


@njit(cache=True, parallel=True)
def sphere_tiles(S, box, items, offsets, order, tile, W, H, f, cx, cy, ortho, near, rfilter, disc, colors, frame,
                 depth, albedo, normal, covered, weight):
    """Ray-cast the binned spheres (``disc``: camera-facing flat discs) into the G-buffer.

    A pixel sees sphere ``i`` where its ray hits it in front of ``near``; where the ray misses
    but the pixel centre lies within ``rfilter`` pixels of the projected centre the sphere is
    still drawn (depth ``z_c - r``, normal towards the viewer), so particles smaller than a pixel
    never vanish. Nearest hit wins (earlier particle on ties). Normals are written in world space.
    """
    ntx = (W + tile - 1) // tile
    invf = 1.0 / f
    rf2 = rfilter * rfilter
    for kk in prange(order.shape[0]):
        t = order[kk]
        a = offsets[t]
        b = offsets[t + 1]
        if a == b:
            continue
        x0, y0, tw, th = tile_rect(t, ntx, tile, W, H)
        m = tw * th
        lz = load_tile(depth, x0, y0, tw, th)
        lid = np.full(m, -1, dtype=np.int64)
        ln = np.zeros((m, 3))
        for k in range(a, b):
            s = items[k]
            c0 = S[s, 0]
            c1 = S[s, 1]
            c2 = S[s, 2]
            r = S[s, 3]
            sx = S[s, 4]
            sy = S[s, 5]
            r2 = S[s, 6]
            cc = S[s, 7]
            bx0 = max(box[s, 0], x0)
            bx1 = min(box[s, 1], x0 + tw - 1)
            by0 = max(box[s, 2], y0)
            by1 = min(box[s, 3], y0 + th - 1)
            for py in range(by0, by1 + 1):
                pcy = py + 0.5
                Y = (cy - pcy) * invf
                row = (py - y0) * tw - x0
                for px in range(bx0, bx1 + 1):
                    pcx = px + 0.5
                    X = (pcx - cx) * invf
                    z = np.inf
                    nx = 0.0
                    ny = 0.0
                    nz = -1.0
                    if disc:
                        if ortho:
                            ex = X - c0
                            ey = Y - c1
                        else:
                            ex = X * c2 - c0
                            ey = Y * c2 - c1
                        if ex * ex + ey * ey <= r2:
                            z = c2
                    elif ortho:
                        ex = X - c0
                        ey = Y - c1
                        h2 = r2 - ex * ex - ey * ey
                        if h2 >= 0.0:
                            hz = math.sqrt(h2)
                            z = c2 - hz
                            nx = ex / r
                            ny = ey / r
                            nz = -hz / r
                    else:
                        dd = X * X + Y * Y + 1.0
                        dc = X * c0 + Y * c1 + c2
                        disc2 = dc * dc - dd * cc
                        if disc2 >= 0.0:
                            tt = (dc - math.sqrt(disc2)) / dd
                            z = tt
                            nx = (tt * X - c0) / r
                            ny = (tt * Y - c1) / r
                            nz = (tt - c2) / r
                    if not (z > near and z < np.inf):
                        z = np.inf
                        if rf2 > 0.0:
                            ex = pcx - sx
                            ey = pcy - sy
                            if ex * ex + ey * ey <= rf2 and c2 - r > near:
                                z = c2 - r
                                nx = 0.0
                                ny = 0.0
                                nz = -1.0
                    idx = row + px
                    if z < lz[idx]:
                        lz[idx] = z
                        lid[idx] = s
                        ln[idx, 0] = nx
                        ln[idx, 1] = ny
                        ln[idx, 2] = nz
        for i in range(th):
            for j in range(tw):
                q = i * tw + j
                s = lid[q]
                if s < 0:
                    continue
                gy = y0 + i
                gx = x0 + j
                depth[gy, gx] = lz[q]
                for c in range(3):
                    normal[gy, gx, c] = frame[0, c] * ln[q, 0] + frame[1, c] * ln[q, 1] + frame[2, c] * ln[q, 2]
                    albedo[gy, gx, c] = colors[s, c]
                covered[gy, gx] = True
                weight[gy, gx] = 1.0
