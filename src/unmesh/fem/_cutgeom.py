"""Geometric helpers of the cutter (:mod:`unmesh.fem.cutting`): face cycles split by a plane's
node classes, Newell normals, barycentric weights on a convex face and convex 2D polygon
predicates (separating-axis overlap, Cyrus-Beck clipping) in the plane of a cut polygon.

Example
-------
>>> sign_runs([1, 1, 0, -1, -1, 0])
[[0, 1], [3, 4]]
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh._validate import as_array
from unmesh.errors import InputError


def unit(v: Any, name: str) -> np.ndarray:
    n = as_array(v, name, (3,))
    ln = float(np.linalg.norm(n))
    if not ln > 0:
        raise InputError(f"{name}: expected a non-zero vector, got {n.tolist()}")
    return n / ln


def open_loop(cycles: list[list[int]]) -> list[int]:
    """The single loop of half-edges without a reverse partner."""
    he = set()
    for c in cycles:
        for i, a in enumerate(c):
            he.add((a, c[(i + 1) % len(c)]))
    nxt: dict[int, int] = {}
    for a, b in he:
        if (b, a) not in he:
            if a in nxt:
                raise InputError("degenerate cut: the cut section is not a simple polygon")
            nxt[a] = b
    if not nxt:
        raise InputError("degenerate cut: the element has no open boundary on the cut plane")
    start = next(iter(nxt))
    loop = [start]
    v = nxt[start]
    while v != start:
        loop.append(v)
        v = nxt.get(v, start)
        if len(loop) > len(nxt):
            break
    if len(loop) != len(nxt) or len(loop) < 3:
        raise InputError("degenerate cut: the cut section is not a single polygon")
    return loop


def sign_runs(cl: list[int]) -> list[list[int]]:
    """Cyclic runs of equal non-zero sign (zeros ignored): lists of positions."""
    nz = [i for i, c in enumerate(cl) if c != 0]
    if not nz:
        return []
    runs: list[list[int]] = [[nz[0]]]
    for i in nz[1:]:
        if cl[i] == cl[runs[-1][-1]]:
            runs[-1].append(i)
        else:
            runs.append([i])
    if len(runs) > 1 and cl[runs[0][0]] == cl[runs[-1][0]]:
        runs[0] = runs.pop() + runs[0]
    return runs


def split_cycle(cyc: list[int], cl: list[int]) -> tuple[list[int], list[int]]:
    """Split a face cycle classified -1/0/+1 into its (negative, positive) pieces.

    Requires one run of each sign (zeros ignored) and no edge joining -1 and +1
    (crossing edges are split first). The pieces share the chord between the zero
    nodes bounding the negative run; both keep the face's orientation.
    """
    n = len(cyc)
    if len(sign_runs(cl)) != 2:
        raise InputError("degenerate cut: a face is crossed more than twice (non-convex face?)")
    i0 = next(i for i in range(n) if cl[i] > 0)
    rot = cyc[i0:] + cyc[:i0]
    clr = cl[i0:] + cl[:i0]
    i1 = next(i for i in range(n) if clr[i] < 0)
    i2 = max(i for i in range(n) if clr[i] < 0)
    if clr[i1 - 1] != 0 or i2 + 1 >= n or clr[i2 + 1] != 0:
        raise InputError("internal error: crossing edge left unsplit")
    neg = rot[i1 - 1:i2 + 2]
    pos = rot[i2 + 1:] + rot[:i1]
    return neg, pos


def newell(p: np.ndarray) -> np.ndarray:
    """Area vector (Newell normal times area) of a polygon (k,3)."""
    c = p.mean(axis=0)
    return 0.5 * np.cross(p - c, np.roll(p, -1, axis=0) - c).sum(axis=0)


def face_weights(pts: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Weights of x on the (ear-clipped) triangulation of the convex polygon pts."""
    from unmesh.fem import _kernels as K

    k = len(pts)
    tris = K.triangulate_faces(pts, np.arange(k, dtype=np.int64), np.array([0, k], np.int64), 1e-9)
    best, bw = None, None
    for t in tris:
        a, b, cc = pts[t]
        nrm = np.cross(b - a, cc - a)
        nn = nrm @ nrm
        if nn <= 0:
            continue
        l1 = np.cross(x - a, cc - a) @ nrm / nn
        l2 = np.cross(b - a, x - a) @ nrm / nn
        lam = np.array([1 - l1 - l2, l1, l2])
        if best is None or lam.min() > bw.min():
            best, bw = t, lam
    w = np.zeros(k)
    if best is None:
        return np.full(k, 1.0 / k)
    w[best] = bw
    return w


def cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def proj(poly: list[list[float]], ax: float, ay: float) -> tuple[float, float]:
    lo = hi = poly[0][0] * ax + poly[0][1] * ay
    for x, y in poly[1:]:
        t = x * ax + y * ay
        lo = min(lo, t)
        hi = max(hi, t)
    return lo, hi


def overlap(A: np.ndarray, B: np.ndarray, eps: float) -> bool:
    """Do two convex 2D polygons overlap with positive area (separating axis test)?

    Scalar arithmetic on lists (small numpy arrays cost most of the cut, issue 5).
    """
    a = A.tolist() if isinstance(A, np.ndarray) else [list(p) for p in A]
    b = B.tolist() if isinstance(B, np.ndarray) else [list(p) for p in B]
    for poly in (a, b):
        k = len(poly)
        for i in range(k):
            dx = poly[(i + 1) % k][0] - poly[i][0]
            dy = poly[(i + 1) % k][1] - poly[i][1]
            ln = math.hypot(dx, dy)
            if ln == 0:
                continue
            ax, ay = -dy / ln, dx / ln
            a0, a1 = proj(a, ax, ay)
            b0, b1 = proj(b, ax, ay)
            if a1 <= b0 + eps or b1 <= a0 + eps:
                return False
    return True


def outside(p: np.ndarray, P: np.ndarray, margin: float) -> bool:
    """Does the 2D point p lie outside the convex polygon P by more than ``margin``?"""
    k = len(P)
    sgn = np.sign(sum(cross2(P[i], P[(i + 1) % k]) for i in range(k)))
    for i in range(k):
        d = P[(i + 1) % k] - P[i]
        if sgn * cross2(d, p - P[i]) / max(np.linalg.norm(d), 1e-300) < -margin:
            return True
    return False


def segment_crosses(a: np.ndarray, b: np.ndarray, poly: np.ndarray, eps: float) -> bool:
    """Does segment ab pass through the interior of convex polygon poly (Cyrus–Beck clip)?"""
    k = len(poly)
    sgn = np.sign(sum(cross2(poly[i], poly[(i + 1) % k]) for i in range(k)))
    t0, t1 = 0.0, 1.0
    d = b - a
    for i in range(k):
        e = poly[(i + 1) % k] - poly[i]
        ln = np.linalg.norm(e)
        if ln == 0:
            continue
        nin = sgn * np.array([-e[1], e[0]]) / ln  # inward normal
        num = (a - poly[i]) @ nin - eps
        den = d @ nin
        if abs(den) < 1e-300:
            if num < 0:
                return False
            continue
        t = -num / den
        if den > 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 >= t1:
            return False
    return (t1 - t0) * np.linalg.norm(d) > eps
