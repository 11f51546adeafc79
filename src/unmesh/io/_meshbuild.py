"""Building triangle meshes from file data: polygon fans, triangle strips, corner splitting.

All functions are vectorised over faces/corners and shared by the PLY, OBJ and OFF
readers.
"""

from __future__ import annotations

import os

import numpy as np

from unmesh.io._common import fail

__all__ = ["decode_strips", "fan_triangulate", "split_corners"]


def fan_triangulate(offsets: np.ndarray, values: np.ndarray, path: str | os.PathLike[str],
                    element: str, first_row: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate polygons given in CSR form by fans around their first corner.

    Parameters
    ----------
    offsets : ndarray (F+1,) int64
        Polygon ``i`` is ``values[offsets[i]:offsets[i+1]]``.
    values : ndarray (C,)
        Corner entries (vertex indices or corner ids).
    first_row : ndarray (F,) int64, optional
        Row numbers to report in errors (default ``arange(F)``).

    Returns
    -------
    triangles : ndarray (T, 3)
        Entries of ``values`` per triangle: (c0, c_i, c_{i+1}), i = 1..n-2.
    corner_index : ndarray (T, 3) int64
        Positions in ``values`` of those entries.

    Raises
    ------
    FormatError
        For polygons with fewer than 3 corners.

    Example
    -------
    >>> tri, _ = fan_triangulate(np.array([0, 4]), np.array([5, 6, 7, 8]), "q.ply", "face")
    >>> tri.tolist()
    [[5, 6, 7], [5, 7, 8]]
    """
    n = np.diff(offsets)
    bad = n < 3
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        row = i if first_row is None else int(first_row[i])
        raise fail(path, element, f"row {row}: a face needs at least 3 vertices, got {int(n[i])}")
    if len(n) and np.all(n == 3):
        idx = np.arange(len(values), dtype=np.int64).reshape(-1, 3)
        return values.reshape(-1, 3), idx
    ntri = n - 2
    start = np.repeat(offsets[:-1], ntri)
    tri_start = np.zeros(len(n) + 1, np.int64)
    np.cumsum(ntri, out=tri_start[1:])
    k = np.arange(int(tri_start[-1]), dtype=np.int64) - np.repeat(tri_start[:-1], ntri) + 1
    idx = np.stack([start, start + k, start + k + 1], axis=1)
    return values[idx], idx


def decode_strips(offsets: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Decode triangle strips (rows of a ``tristrips`` element, strips separated by -1).

    Triangle ``i`` of a strip ``s`` is ``(s[i], s[i+1], s[i+2])`` for even ``i`` and
    ``(s[i+1], s[i], s[i+2])`` for odd ``i`` (winding alternates along a strip).
    Degenerate triangles (two equal indices), used to join strips, are dropped.

    Returns
    -------
    triangles : ndarray (T, 3) int64
    row : ndarray (T,) int64
        The element row each triangle came from (for error messages).

    Example
    -------
    >>> decode_strips(np.array([0, 6]), np.array([0, 1, 2, 3, -1, 4]))[0].tolist()
    [[0, 1, 2], [2, 1, 3]]
    """
    v = np.asarray(values, dtype=np.int64)
    c = len(v)
    row_of = np.repeat(np.arange(len(offsets) - 1, dtype=np.int64), np.diff(offsets))
    if c < 3:
        return np.empty((0, 3), np.int64), np.empty(0, np.int64)
    # strip id: increments at each -1 and at each row start
    breaks = (v == -1).astype(np.int64)
    row_start = np.zeros(c, np.int64)
    row_start[offsets[:-1][offsets[:-1] < c]] = 1
    strip = np.cumsum(breaks + row_start)
    # position within strip (counting from the first index after a break)
    pos = np.arange(c, dtype=np.int64)
    begin = np.maximum.accumulate(np.where((breaks + row_start) > 0, pos + breaks, 0))
    i = pos[:-2]
    ok = (v[:-2] >= 0) & (v[1:-1] >= 0) & (v[2:] >= 0) & (strip[:-2] == strip[2:])
    i = i[ok]
    a, b, cc = v[i], v[i + 1], v[i + 2]
    odd = ((i - begin[i]) % 2) == 1
    tri = np.stack([np.where(odd, b, a), np.where(odd, a, b), cc], axis=1)
    keep = (a != b) & (b != cc) & (a != cc)
    return tri[keep], row_of[i[keep]]


def split_corners(vid: np.ndarray, keys: np.ndarray, nverts: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give every distinct (vertex, key) combination of the corners its own vertex.

    A vertex referenced with one key keeps its index; every further key of the same
    vertex becomes a new vertex appended after the original ``nverts``. Vertices that
    no corner references are kept.

    Parameters
    ----------
    vid : ndarray (C,) int64
        Vertex of each corner.
    keys : ndarray (C, m)
        Per-corner data that must be per-vertex (uv index, normal index, material, ...).
    nverts : int

    Returns
    -------
    corner_vertex : ndarray (C,) int64
        New vertex of each corner.
    source : ndarray (V',) int64
        Original vertex of each new vertex.
    vertex_key : ndarray (V', m)
        Key of each new vertex; rows of unreferenced vertices are ``-1`` (integer
        keys) or NaN (float keys).

    Example
    -------
    >>> cv, src, k = split_corners(np.array([0, 1, 0]), np.array([[5], [6], [7]]), 2)
    >>> cv.tolist(), src.tolist(), k[:, 0].tolist()
    ([0, 1, 2], [0, 1, 0], [5, 6, 7])
    """
    vid = np.asarray(vid, dtype=np.int64)
    keys = np.asarray(keys)
    if keys.ndim == 1:
        keys = keys[:, None]
    m = keys.shape[1]
    if keys.dtype.kind in "iu":
        keys = keys.astype(np.int64)
        lo = keys.min(axis=0) if len(keys) else np.zeros(m, np.int64)
        span = (keys.max(axis=0) - lo + 1) if len(keys) else np.ones(m, np.int64)
        total = float(nverts) * float(np.prod(span.astype(np.float64)))
        if total < 2.0**62:
            code = vid.copy()
            for j in range(m):
                code = code * int(span[j]) + (keys[:, j] - lo[j])
            uniq_code, inv = np.unique(code, return_inverse=True)
            uk = np.empty((len(uniq_code), m), np.int64)
            rest = uniq_code.copy()
            for j in range(m - 1, -1, -1):
                uk[:, j] = rest % int(span[j]) + lo[j]
                rest //= int(span[j])
            uv = rest
        else:
            uniq, inv = np.unique(np.column_stack([vid, keys]), axis=0, return_inverse=True)
            uv, uk = uniq[:, 0], uniq[:, 1:]
        fill = -1
    else:
        kf = keys.astype(np.float64) + 0.0  # -0.0 -> 0.0
        uniq, inv = np.unique(np.column_stack([vid.astype(np.float64), kf]), axis=0, return_inverse=True)
        uv, uk = uniq[:, 0].astype(np.int64), uniq[:, 1:]
        fill = np.nan
    inv = np.asarray(inv).reshape(-1)
    first = np.ones(len(uv), dtype=bool)
    first[1:] = uv[1:] != uv[:-1]
    new_id = np.empty(len(uv), np.int64)
    new_id[first] = uv[first]
    extra = ~first
    new_id[extra] = nverts + np.arange(int(extra.sum()), dtype=np.int64)
    source = np.concatenate([np.arange(nverts, dtype=np.int64), uv[extra]])
    vertex_key = np.full((len(source), m), fill, dtype=uk.dtype)
    vertex_key[new_id] = uk
    return new_id[inv], source, vertex_key
