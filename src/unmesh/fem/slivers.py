"""Sliver detection and removal (9.2).

A *sliver* is an almost planar element: its thickness (extent of its nodes along
the smallest principal axis) divided by its diameter (extent along the largest)
is below a threshold. Removal follows the thesis: the element's nodes are
projected onto its least-squares *sliver plane* (coincident nodes are merged),
the faces above (outward normal along the plane normal) and below are overlaid
in the plane - crossing edges get a new node inserted into both edges, nodes
lying on an edge of the other side are inserted into it - and every region of
the overlay becomes a face connecting the element above to the element below.
Faces of the sliver that project to zero area (perpendicular sides) are dropped
from their other element. The sliver disappears; neighbours keep their shape
(only nodes of the sliver move, by less than its thickness) but gain nodes and
coplanar faces. Two tetrahedra separated by a tetrahedral sliver gain exactly one
node (the crossing of the two diagonals) and have five nodes each afterwards.

Example
-------
>>> from unmesh.fem import cut_by_plane, hex_grid
>>> m = cut_by_plane(hex_grid((1, 1, 2), size=(1, 1, 2)), (0, 0, 1.004), (0, 0, 1), snap=0.0)
>>> find_slivers(m, 0.05).tolist()
[1]
>>> remove_slivers(m, 0.05).n_elements
2
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import scalar
from unmesh.errors import InputError
from unmesh.fem.mesh import PolyMesh

__all__ = ["find_slivers", "flatness", "remove_slivers", "remove_slivers_in"]


def _frame(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    c = pts.mean(axis=0)
    _, v = np.linalg.eigh((pts - c).T @ (pts - c))
    proj = (pts - c) @ v
    ext = np.ptp(proj, axis=0)
    return c, v, float(ext[0]), float(ext[2])


def flatness(mesh: PolyMesh) -> np.ndarray:
    """Thickness / diameter of every element (E,) along its principal axes (0 = flat).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> flatness(hex_grid((1, 1, 1), size=(1, 1, 0.1))).round(3).tolist()
    [0.1]
    """
    off, nodes = mesh.element_nodes()
    p = mesh.points[nodes]
    n = np.diff(off)
    c = np.add.reduceat(p, off[:-1], axis=0) / n[:, None]
    d = p - np.repeat(c, n, axis=0)
    cov = np.add.reduceat(d[:, :, None] * d[:, None, :], off[:-1], axis=0)
    _, vecs = np.linalg.eigh(cov)
    e = np.repeat(np.arange(len(n)), n)
    proj = np.einsum("ij,ijk->ik", d, vecs[e])
    ext = np.maximum.reduceat(proj, off[:-1], axis=0) - np.minimum.reduceat(proj, off[:-1], axis=0)
    return ext[:, 0] / np.maximum(ext[:, 2], 1e-300)


def find_slivers(mesh: PolyMesh, threshold: float = 0.05) -> np.ndarray:
    """Indices of elements flatter than ``threshold`` (thickness / diameter).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> find_slivers(hex_grid((2, 1, 1))).tolist()
    []
    """
    thr = scalar(threshold, "threshold", minimum=0.0, maximum=1.0)
    return np.flatnonzero(flatness(mesh) < thr)


def _area2(pts2: np.ndarray) -> float:
    x, y = pts2[:, 0], pts2[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _seg_cross(p: np.ndarray, q: np.ndarray, r: np.ndarray, s: np.ndarray, eps: float) -> tuple[float, float] | None:
    """Parameters (t, u) of a proper crossing of segments pq and rs (interiors), else None."""
    d1 = q - p
    d2 = s - r
    den = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(den) <= eps * np.linalg.norm(d1) * np.linalg.norm(d2):
        return None
    w = r - p
    t = (w[0] * d2[1] - w[1] * d2[0]) / den
    u = (w[0] * d1[1] - w[1] * d1[0]) / den
    lt = eps / max(np.linalg.norm(d1), 1e-300)
    lu = eps / max(np.linalg.norm(d2), 1e-300)
    if lt < t < 1 - lt and lu < u < 1 - lu:
        return t, u
    return None


def _remove_one(ed: Any, S: int) -> bool:
    """Remove sliver element S from a MeshEditor (see module docstring); False if not possible."""
    nodes = ed.elem_nodes(S)
    pts = ed.points_of(nodes)
    c, axes, _thick, diam = _frame(pts)
    n = axes[:, 0]
    e1, e2 = axes[:, 2], np.cross(n, axes[:, 2])
    eps = 1e-9 * diam
    for v, x in zip(nodes, pts, strict=True):
        ed.move_node(v, x - ((x - c) @ n) * n)

    def p2(v: int) -> np.ndarray:
        x = ed.point(v) - c
        return np.array([x @ e1, x @ e2])

    # merge nodes that coincide after the projection
    for i, a in enumerate(nodes):
        for b in nodes[i + 1:]:
            if b in ed.elem_nodes(S) and a in ed.elem_nodes(S) and np.linalg.norm(p2(a) - p2(b)) <= 1e-6 * diam:
                ed.merge_nodes(a, b)
    up, down, side = [], [], []
    for f, s in ed.elem(S):
        cyc = ed.oriented(f, s)
        area = _area2(np.array([p2(v) for v in cyc]))
        (up if area > eps * diam else down if area < -eps * diam else side).append((f, s))
    if not up or not down:
        return False

    def edges(faces: list[tuple[int, int]]) -> set[tuple[int, int]]:
        out = set()
        for f, _ in faces:
            cyc = ed.face(f)
            for i, a in enumerate(cyc):
                b = cyc[(i + 1) % len(cyc)]
                out.add((min(a, b), max(a, b)))
        return out

    # crossings of up and down edges
    for _ in range(10000):
        found = False
        for a, b in edges(up):
            for r, s in edges(down):
                if len({a, b, r, s}) < 4:
                    continue
                hit = _seg_cross(p2(a), p2(b), p2(r), p2(s), eps)
                if hit is not None:
                    m = ed.split_edge(a, b, hit[0])
                    ed.insert_on_edge(r, s, m)
                    ed.reset_cache()
                    found = True
                    break
            if found:
                break
        if not found:
            break
    # nodes lying on an edge of the other side
    for mine, other in ((up, down), (down, up)):
        changed = True
        while changed:
            changed = False
            verts = {v for f, _ in mine for v in ed.face(f)}
            for a, b in edges(other):
                pa, pb = p2(a), p2(b)
                d = pb - pa
                ln2 = float(d @ d)
                for v in verts:
                    if v in (a, b):
                        continue
                    w = p2(v) - pa
                    t = float(w @ d) / ln2
                    if 0 < t < 1 and abs(w[0] * d[1] - w[1] * d[0]) / np.sqrt(ln2) <= 1e-6 * diam:
                        ed.insert_on_edge(a, b, v)
                        changed = True
                        break
                if changed:
                    break
    # overlay regions
    def other_ref(f: int) -> tuple[int, int] | None:
        r = [(e, s) for e, s in ed.refs(f) if e != S]
        return r[0] if r else None

    new_faces: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for fu, su in up:
        cu = ed.oriented(fu, su)
        pu = np.array([p2(v) for v in cu])
        for fd, sd in down:
            cd = ed.oriented(fd, sd)[::-1]
            pd = np.array([p2(v) for v in cd])
            cand = [v for v in dict.fromkeys(cu + cd) if _in_convex(p2(v), pu, eps) and _in_convex(p2(v), pd, eps)]
            if len(cand) < 3:
                continue
            q = np.array([p2(v) for v in cand])
            cen = q.mean(axis=0)
            order = np.argsort(np.arctan2(q[:, 1] - cen[1], q[:, 0] - cen[0]))
            region = [cand[i] for i in order]
            if _area2(q[order]) <= eps * diam:
                continue
            above, below = other_ref(fu), other_ref(fd)
            refs = []
            if below is not None:
                refs.append((below[0], 1))
            if above is not None:
                refs.append((above[0], -1))
            if not refs:
                continue
            g = ed.new_face(region, refs)
            for e, s in refs:
                new_faces.setdefault((e, {1: fd, -1: fu}[s]), []).append((g, s))
    # rewire neighbours and drop the sliver
    for f, _ in up + down + side:
        for e, _ in ed.refs(f):
            if e == S:
                continue
            faces = [(g, t) for g, t in ed.elem(e) if g != f]
            ed.set_elem(e, faces + new_faces.get((e, f), []))
        ed.kill_face(f)
    ed.dead_elems.add(S)
    return True


def _in_convex(p: np.ndarray, poly: np.ndarray, eps: float) -> bool:
    k = len(poly)
    for i in range(k):
        d = poly[(i + 1) % k] - poly[i]
        ln = np.linalg.norm(d)
        if ln == 0:
            continue
        if (d[0] * (p[1] - poly[i][1]) - d[1] * (p[0] - poly[i][0])) / ln < -eps * 10:
            return False
    return True


def remove_slivers_in(cutter: Any, threshold: float, elements: list[int] | None = None) -> int:
    """Remove slivers among the changed (or given) elements of a Cutter's editor; returns the count.

    Example
    -------
    >>> from unmesh.fem import cut_by_plane, hex_grid
    >>> m = cut_by_plane(hex_grid((1, 1, 2), size=(1, 1, 2)), (0, 0, 1.004), (0, 0, 1), snap=0.0)
    >>> remove_slivers(m, 0.05).n_elements
    2

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> from unmesh.fem.cutting import Cutter
    >>> remove_slivers_in(Cutter(hex_grid((1, 1, 1))), 0.05, [0])
    0
    """
    ed = cutter.ed
    cand = sorted(ed.changed) if elements is None else list(elements)
    removed = 0
    for e in cand:
        if e in ed.dead_elems:
            continue
        nodes = ed.elem_nodes(e)
        if len(nodes) < 4:
            continue
        _c, _ax, thick, diam = _frame(ed.points_of(nodes))
        if diam > 0 and thick / diam < threshold and _remove_one(ed, e):
            removed += 1
    return removed


def remove_slivers(mesh: PolyMesh, threshold: float = 0.05) -> PolyMesh:
    """Remove every element flatter than ``threshold`` by merging it into its neighbours (9.2).

    Parameters
    ----------
    mesh : PolyMesh
    threshold : float
        Thickness / diameter below which an element is a sliver.

    Returns
    -------
    PolyMesh
        Validated (closed, oriented, convex within the mesh tolerance plus the
        largest sliver flatness).
    """
    from unmesh.fem.cutting import Cutter

    thr = scalar(threshold, "threshold", minimum=0.0, maximum=0.5)
    slivers = find_slivers(mesh, thr)
    if len(slivers) == 0:
        return mesh
    cutter = Cutter(mesh, 0.0)
    count = remove_slivers_in(cutter, thr, slivers.tolist())
    if count == 0:
        raise InputError(f"slivers {slivers.tolist()}: could not be removed (isolated elements?)")
    return cutter.ed.commit(tolerance=max(mesh.tolerance, thr)).mesh
