"""Numba kernels of the texture patches (6.2.1): the texels a patch needs, and bilinear lookups.

A texel ``(row j, column i)`` of a patch is *needed* when the triangle meets the open square of
half-width one texel around its centre ``(i + 0.5, j + 0.5)``: exactly the texels a bilinear
lookup anywhere in the triangle reads (the "one pixel boundary" of 6.2.1). The test is the
separating-axis test of a triangle against an axis-aligned square (axes x, y and the three edge
normals). :func:`footprint_reference` is the numpy reference.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["bilinear", "bilinear_reference", "footprint_reference", "footprints"]


@njit(cache=True)
def _separated(px, py, cx, cy) -> bool:
    # axes x and y
    if max(px[0], px[1], px[2]) <= cx - 1.0 or min(px[0], px[1], px[2]) >= cx + 1.0:
        return True
    if max(py[0], py[1], py[2]) <= cy - 1.0 or min(py[0], py[1], py[2]) >= cy + 1.0:
        return True
    for e in range(3):
        ax = -(py[(e + 1) % 3] - py[e])
        ay = px[(e + 1) % 3] - px[e]
        t0 = ax * px[0] + ay * py[0]
        t1 = ax * px[1] + ay * py[1]
        t2 = ax * px[2] + ay * py[2]
        c = ax * cx + ay * cy
        rad = abs(ax) + abs(ay)
        if max(t0, t1, t2) <= c - rad or min(t0, t1, t2) >= c + rad:
            return True
    return False


@njit(cache=True, parallel=True)
def footprints(corners, widths, heights, offsets, out):
    """Needed-texel masks of many patches, row-major, concatenated.

    Parameters
    ----------
    corners : (P, 3, 2) float64
        Triangle corners in patch texel coordinates ``(column, row)``.
    widths, heights : (P,) int64
    offsets : (P + 1,) int64
        Start of patch p's ``heights[p] * widths[p]`` mask in ``out``.
    out : (offsets[-1],) bool
        Written.
    """
    for p in prange(len(widths)):
        px = corners[p, :, 0]
        py = corners[p, :, 1]
        w = widths[p]
        base = offsets[p]
        for j in range(heights[p]):
            for i in range(w):
                out[base + j * w + i] = not _separated(px, py, i + 0.5, j + 0.5)


def footprint_reference(corners: np.ndarray, width: int, height: int) -> np.ndarray:
    """Numpy reference of one patch's mask (height, width) bool."""
    j, i = np.mgrid[0:height, 0:width]
    cx = i + 0.5
    cy = j + 0.5
    px, py = corners[:, 0], corners[:, 1]
    sep = (px.max() <= cx - 1) | (px.min() >= cx + 1) | (py.max() <= cy - 1) | (py.min() >= cy + 1)
    for e in range(3):
        ax = -(py[(e + 1) % 3] - py[e])
        ay = px[(e + 1) % 3] - px[e]
        t = ax * px + ay * py
        c = ax * cx + ay * cy
        rad = abs(ax) + abs(ay)
        sep |= (t.max() <= c - rad) | (t.min() >= c + rad)
    return ~sep


@njit(cache=True, parallel=True)
def bilinear(image, cols, rows, out):
    """Bilinear samples of ``image`` (H, W, C) at continuous ``(cols, rows)`` (N,), texel centres
    at ``+0.5``, clamped at the borders; written to ``out`` (N, C)."""
    h = image.shape[0]
    w = image.shape[1]
    for q in prange(len(cols)):
        x = min(max(cols[q] - 0.5, 0.0), w - 1.0)
        y = min(max(rows[q] - 0.5, 0.0), h - 1.0)
        ix = min(int(x), w - 1)
        iy = min(int(y), h - 1)
        fx = x - ix
        fy = y - iy
        ix1 = min(ix + 1, w - 1)
        iy1 = min(iy + 1, h - 1)
        for c in range(image.shape[2]):
            a = image[iy, ix, c] * (1.0 - fx) + image[iy, ix1, c] * fx
            b = image[iy1, ix, c] * (1.0 - fx) + image[iy1, ix1, c] * fx
            out[q, c] = a * (1.0 - fy) + b * fy


def bilinear_reference(image: np.ndarray, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Numpy reference of :func:`bilinear`."""
    h, w = image.shape[:2]
    x = np.clip(cols - 0.5, 0, w - 1.0)
    y = np.clip(rows - 0.5, 0, h - 1.0)
    ix = np.minimum(x.astype(np.int64), w - 1)
    iy = np.minimum(y.astype(np.int64), h - 1)
    fx = (x - ix)[:, None]
    fy = (y - iy)[:, None]
    ix1 = np.minimum(ix + 1, w - 1)
    iy1 = np.minimum(iy + 1, h - 1)
    a = image[iy, ix] * (1 - fx) + image[iy, ix1] * fx
    b = image[iy1, ix] * (1 - fx) + image[iy1, ix1] * fx
    return a * (1 - fy) + b * fy


@njit(cache=True)
def _pairs_pass(faces, vf_off, vf_idx, fs_off, fs_idx, normals, fnormal, counts, pt, ps, fill):
    nf = faces.shape[0]
    mark = np.full(nf, -1, np.int64)
    for t in range(nf):
        k = counts[t] if fill else 0
        base = k
        n = 0
        for c in range(3):
            v = faces[t, c]
            for a in range(vf_off[v], vf_off[v + 1]):
                f = vf_idx[a]
                if mark[f] == t:
                    continue
                mark[f] = t
                for b in range(fs_off[f], fs_off[f + 1]):
                    s = fs_idx[b]
                    if normals[s, 0] * fnormal[t, 0] + normals[s, 1] * fnormal[t, 1] + normals[s, 2] * fnormal[t, 2] > 0.0:
                        if fill:
                            pt[base + n] = t
                            ps[base + n] = s
                        n += 1
        if not fill:
            counts[t] = n


def candidate_pairs(faces, nv, nearest, normals, fnormal):
    """(triangle, surfel) pairs: surfels whose nearest triangle shares a vertex with the triangle
    and whose normal faces the triangle's side; sorted by triangle, then by adjacent face.

    Parameters
    ----------
    faces : (F, 3) int64
    nv : int
        Number of vertices.
    nearest : (N,) int64
        Nearest triangle of every surfel.
    normals : (N, 3) float64
    fnormal : (F, 3) float64

    Returns
    -------
    pt, ps : (P,) int64
    """
    nf = len(faces)
    order = np.argsort(faces.ravel(), kind="stable")
    vf_idx = (order // 3).astype(np.int64)
    vf_off = np.zeros(nv + 1, np.int64)
    np.cumsum(np.bincount(faces.ravel(), minlength=nv), out=vf_off[1:])
    fs_idx = np.argsort(nearest, kind="stable").astype(np.int64)
    fs_off = np.zeros(nf + 1, np.int64)
    np.cumsum(np.bincount(nearest, minlength=nf), out=fs_off[1:])
    counts = np.zeros(nf, np.int64)
    dummy = np.zeros(0, np.int64)
    _pairs_pass(faces, vf_off, vf_idx, fs_off, fs_idx, normals, fnormal, counts, dummy, dummy, False)
    starts = np.zeros(nf, np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    total = int(counts.sum())
    pt = np.empty(total, np.int64)
    ps = np.empty(total, np.int64)
    _pairs_pass(faces, vf_off, vf_idx, fs_off, fs_idx, normals, fnormal, starts, pt, ps, True)
    return pt, ps


def candidate_pairs_reference(faces, nv, nearest, normals, fnormal):
    """Numpy/python reference of :func:`candidate_pairs` (as sorted (t, s) pair sets)."""
    out = []
    for t in range(len(faces)):
        adj = np.flatnonzero(np.isin(faces, faces[t]).any(axis=1))
        s = np.flatnonzero(np.isin(nearest, adj))
        s = s[normals[s] @ fnormal[t] > 0]
        out += [(t, int(j)) for j in s]
    return sorted(out)


@njit(cache=True, parallel=True)
def pair_frames(pt, ps, origin, rotation, positions, normals, loc, lnrm):
    """Local coordinates ``R_t (x_s - o_t)`` and normals ``R_t n_s`` of every pair, into loc, lnrm (P, 3)."""
    for p in prange(len(pt)):
        t = pt[p]
        s = ps[p]
        for i in range(3):
            a = 0.0
            b = 0.0
            for j in range(3):
                a += rotation[t, i, j] * (positions[s, j] - origin[t, j])
                b += rotation[t, i, j] * normals[s, j]
            loc[p, i] = a
            lnrm[p, i] = b
