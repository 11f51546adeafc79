"""Cutting (9.3): splitting elements by planes and progressive cuts by polygons.

* Plane split (9.3.1): nodes are classified by their signed distance to the plane;
  a node closer than ``snap`` × the longest edge length counts as *on* the plane
  (snapping, so no edge shorter than that - no needle - is created). Every edge with endpoints strictly
  on opposite sides gets a new node, inserted into every face containing the
  edge (t-junctions in untouched neighbours are allowed), crossed faces are split
  along their chord, and the element is replaced by its two halves, closed by a
  cap face built from the open boundary loop (topology, not angles). Both halves
  are convex; volume is conserved exactly (shared faces are triangulated once).
* Polygon cut (9.3.2): the elements whose plane section overlaps the polygon are
  split by its plane; the in-plane faces overlapping the polygon are split along
  the polygon's edges (each edge line splits only the faces its segment crosses,
  so every piece is convex); the pieces inside the polygon form the cut. A node
  on the cut is duplicated for each part of its element star that the cut
  separates (connected components across faces that are not cut); cut faces
  without such a node get a node at their centroid first (the pocket case).
  Non-planar cut surfaces are sequences of polygons.

Cut geometry is given in rest (material) coordinates. Node states (displacement,
velocity) of new nodes are interpolated linearly along the split edges.

Example
-------
>>> from unmesh.fem import hex_grid
>>> m = cut_by_plane(hex_grid((2, 2, 2)), (0.5, 0.3, 0.5), (0.2, 1.0, 0.1))
>>> m.n_elements, round(m.volume(), 12)
(12, 1.0)
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, scalar
from unmesh.errors import InputError
from unmesh.fem.editor import EditResult, MeshEditor
from unmesh.fem.mesh import PolyMesh

__all__ = ["CutMissWarning", "Cutter", "PlaneCut", "PolygonCut", "apply_cuts", "cut_by_plane", "cut_by_polygon",
           "split_element"]


class CutMissWarning(UserWarning):
    """A cut did not intersect the mesh (nothing changed)."""


@dataclass(frozen=True)
class PlaneCut:
    """Split the crossed elements (all, or only ``elements``) by a plane (9.3.1).

    Example
    -------
    >>> PlaneCut((0, 0, 0), (0, 1, 0)).elements is None
    True
    """

    origin: tuple[float, float, float]
    normal: tuple[float, float, float]
    elements: tuple[int, ...] | None = None


@dataclass(frozen=True)
class PolygonCut:
    """Cut (and separate) the material along a planar convex polygon (9.3.2).

    Example
    -------
    >>> import numpy as np
    >>> PolygonCut(np.eye(3)).polygon.shape
    (3, 3)
    """

    polygon: np.ndarray


def _unit(v: Any, name: str) -> np.ndarray:
    n = as_array(v, name, (3,))
    ln = float(np.linalg.norm(n))
    if not ln > 0:
        raise InputError(f"{name}: expected a non-zero vector, got {n.tolist()}")
    return n / ln


def _open_loop(cycles: list[list[int]]) -> list[int]:
    """The single loop of half-edges without a reverse partner."""
    he = set()
    for c in cycles:
        for i, a in enumerate(c):
            he.add((a, c[(i + 1) % len(c)]))
    nxt: dict[int, int] = {}
    for a, b in he:
        if (b, a) not in he:
            if a in nxt:
                raise InputError("degenerate cut: the cut section is not a simple polygon (try a larger snap)")
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
        raise InputError("degenerate cut: the cut section is not a single polygon (try a larger snap)")
    return loop


def _split_cycle(cyc: list[int], cl: list[int]) -> tuple[list[int], list[int]]:
    """Split a convex face cycle whose nodes are classified -1/0/+1 (no adjacent -1/+1)."""
    n = len(cyc)
    starts = [i for i in range(n) if cl[i] > 0 and cl[i - 1] <= 0]
    if len(starts) != 1:
        raise InputError("degenerate cut: a face is crossed more than twice (non-convex face?)")
    i0 = starts[0]
    rot = cyc[i0:] + cyc[:i0]
    clr = cl[i0:] + cl[:i0]
    k = next(i for i in range(n) if clr[i] <= 0)
    if clr[k] != 0 or clr[-1] != 0:
        raise InputError("internal error: crossing edge left unsplit")
    pos = [rot[-1], *rot[:k], rot[k]]
    neg = rot[k:]
    return neg, pos


class Cutter:
    """Applies plane and polygon cuts to a :class:`MeshEditor` (commit once at the end).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> c = Cutter(hex_grid((2, 2, 2)))
    >>> c.plane((0.5, 0.3, 0.5), (0, 1, 0))
    4
    >>> c.commit().mesh.n_elements
    12
    """

    def __init__(self, mesh: PolyMesh, snap: float = 0.02) -> None:
        self.snap = scalar(snap, "snap", minimum=0.0, maximum=0.25)
        self.ed = MeshEditor(mesh)
        self.mesh = mesh
        #: global snapping distance: nodes this close to a cut plane count as on it, so no
        #: edge shorter than this is created (needles, 9.2). Scaled with the longest edge, it
        #: also covers the deviation of nodes snapped by the edge-relative rule, so a node once
        #: snapped onto a plane is on it again for the next (coplanar) cut polygon.
        self.snap_length = self.snap * mesh.max_edge_length()
        off, nodes = mesh.element_nodes()
        p = mesh.points[nodes]
        self._elo = np.minimum.reduceat(p, off[:-1], axis=0)
        self._ehi = np.maximum.reduceat(p, off[:-1], axis=0)
        self.touched = False

    # -- classification -----------------------------------------------------------------------
    def _classifier(self, origin: np.ndarray, normal: np.ndarray):
        """Node classification for one plane: (signed distance, -1/0/+1), consistent for the whole cut.

        A node is *on* the plane (0) if it is within ``snap_length`` of it, or if a
        crossing edge would get its new node within ``snap`` (relative to the edge) of
        it: so no needle and no sliver thinner than ``snap`` of its size is created.
        """
        base_d = (self.mesh.points - origin) @ normal
        ed = self.ed
        dist: dict[int, float] = {}
        cache: dict[int, tuple[float, int]] = {}
        sl = self.snap_length

        def d_of(v: int) -> float:
            d = dist.get(v)
            if d is None:
                d = float(base_d[v]) if v < ed.n_base_nodes and v not in ed._moved else float((ed.point(v) - origin) @ normal)
                dist[v] = d
            return d

        def classify(v: int) -> tuple[float, int]:
            hit = cache.get(v)
            if hit is not None:
                return hit
            d = d_of(v)
            c = 0 if abs(d) <= sl else (1 if d > 0 else -1)
            if c != 0 and self.snap > 0:
                for f in ed.faces_of_node(v):
                    cyc = ed.face(f)
                    i = cyc.index(v)
                    for w in (cyc[i - 1], cyc[(i + 1) % len(cyc)]):
                        dw = d_of(w)
                        if dw * d < 0 and abs(dw) > sl and abs(d) < self.snap * (abs(d) + abs(dw)):
                            c = 0
                            break
                    if c == 0:
                        break
            cache[v] = (d, c)
            return d, c

        def force_zero(v: int) -> None:
            cache[v] = (0.0, 0)
            dist[v] = 0.0

        return base_d, classify, force_zero

    def _new_edge_node(self, a: int, b: int, da: float, db: float, force_zero) -> int:
        t = da / (da - db)
        m = self.ed.split_edge(a, b, t)
        force_zero(m)
        return m

    # -- 9.3.1 element split ---------------------------------------------------------------------
    def split(self, e: int, classify, force_zero, normal: np.ndarray) -> tuple[int, int] | None:
        """Split element e by the plane of ``classify``; returns (negative, positive) halves."""
        ed = self.ed
        cls = {v: classify(v)[1] for v in ed.elem_nodes(e)}
        if not (any(c < 0 for c in cls.values()) and any(c > 0 for c in cls.values())):
            return None
        if any(all(cls[v] == 0 for v in ed.face(f)) for f, _ in ed.elem(e)):
            # a face lies in the plane (up to snapping): by convexity the element is on one side.
            # Known limitation: on curved progressive sweeps the previous step's plane can be
            # snapped into this one, and such elements then keep the two sides connected.
            return None
        sec = self._section(e, classify)
        pts = ed.points_of(list(cls))
        diam = float(np.linalg.norm(np.ptp(pts, axis=0)))
        if sec is None or _section_area(np.array(sec), normal) <= 1e-6 * diam * diam:
            return None  # the plane only grazes the element: splitting would leave a flat half
        vneg, vpos = self._half_volumes(e, classify, np.mean(sec, axis=0), normal)
        if min(vneg, vpos) <= 1e-6 * (vneg + vpos):
            return None  # one half would be (almost) flat
        edges = set()
        for f, _ in ed.elem(e):
            c = ed.face(f)
            for i, a in enumerate(c):
                b = c[(i + 1) % len(c)]
                if cls[a] * cls[b] < 0:
                    edges.add((min(a, b), max(a, b)))
        for a, b in sorted(edges):
            m = self._new_edge_node(a, b, classify(a)[0], classify(b)[0], force_zero)
            cls[m] = 0
        neg: list[tuple[int, int]] = []
        pos: list[tuple[int, int]] = []
        flat: list[tuple[int, int]] = []
        for f, s in list(ed.elem(e)):
            cyc = ed.face(f)
            cl = [cls[v] for v in cyc]
            if all(c == 0 for c in cl):
                flat.append((f, s))
            elif all(c <= 0 for c in cl):
                neg.append((f, s))
            elif all(c >= 0 for c in cl):
                pos.append((f, s))
            else:
                pn, pp = _split_cycle(cyc, cl)
                f1, f2 = ed.split_face(f, pn, pp)
                neg.append((f1, s))
                pos.append((f2, s))
        # faces (almost) in the cut plane go with the half whose faces share their edges
        while flat:
            def shared(side: list[tuple[int, int]], cyc: list[int]) -> int:
                edges = {frozenset((a, cyc[(i + 1) % len(cyc)])) for i, a in enumerate(cyc)}
                return sum(frozenset((a, c[(i + 1) % len(c)])) in edges
                           for g, _ in side for c in (ed.face(g),) for i, a in enumerate(c))

            scores = [(shared(neg, ed.face(f)), shared(pos, ed.face(f)), (f, s)) for f, s in flat]
            sn, sp_, fs = max(scores, key=lambda t: abs(t[0] - t[1]))
            if sn == sp_:
                p = ed.points_of(ed.oriented(*fs))
                nrm = np.cross(p - p.mean(axis=0), np.roll(p, -1, axis=0) - p.mean(axis=0)).sum(axis=0)
                (pos if nrm @ normal < 0 else neg).append(fs)
            else:
                (neg if sn > sp_ else pos).append(fs)
            flat.remove(fs)
        loop = _open_loop([ed.oriented(f, s) for f, s in neg])
        cap = [loop[0], *loop[:0:-1]]
        g = ed.new_face(cap, [])
        ed.set_elem(e, [*neg, (g, 1)])
        e2 = ed.new_elem([*pos, (g, -1)], parent=e)
        ed.set_refs(g, [(e, 1), (e2, -1)])
        for f, s in pos:
            ed.set_refs(f, [(e2 if (a == e and sa == s) else a, sa) for a, sa in ed.refs(f)])
        self.touched = True
        return e, e2

    def plane(self, origin: Any, normal: Any, elements: Any | None = None) -> int:
        """Split every element the plane crosses (or only ``elements``); returns the number split."""
        o = as_array(origin, "origin", (3,))
        n = _unit(normal, "normal")
        base_d, classify, force_zero = self._classifier(o, n)
        ed = self.ed
        ed.reset_cache()
        if elements is None:
            cand = self._candidates(base_d)
        else:
            cand = [int(e) for e in np.atleast_1d(np.asarray(elements, dtype=np.int64))]
            bad = [e for e in cand if not 0 <= e < ed.n_elems or e in ed.dead_elems]
            if bad:
                raise InputError(f"elements: no element {bad[0]} in the mesh")
        count = 0
        for e in cand:
            if self.split(e, classify, force_zero, n) is not None:
                count += 1
        return count

    def _candidates(self, base_d: np.ndarray) -> list[int]:
        """Elements with nodes on both sides of the plane (base elements via arrays, edited ones directly)."""
        ed = self.ed
        off, nodes = self.mesh.element_nodes()
        d = base_d[nodes]
        lo = np.minimum.reduceat(d, off[:-1])
        hi = np.maximum.reduceat(d, off[:-1])
        base = np.flatnonzero((lo < 0) & (hi > 0)).tolist()
        edited = {e for e in ed._elems if e not in ed.dead_elems}
        out = [e for e in base if e not in edited and e not in ed.dead_elems]
        return out + sorted(edited)

    # -- 9.3.2 polygon cut ---------------------------------------------------------------------------
    def polygon(self, polygon: Any) -> int:
        """Cut along a convex planar polygon (k,3); returns the number of duplicated nodes."""
        P = as_points(polygon, "polygon")
        if len(P) < 3:
            raise InputError(f"polygon: expected at least 3 vertices, got {len(P)}")
        c = P.mean(axis=0)
        nrm = np.zeros(3)
        for i in range(len(P)):
            nrm += np.cross(P[i] - c, P[(i + 1) % len(P)] - c)
        area2 = float(np.linalg.norm(nrm))
        size = float(np.ptp(P, axis=0).max())
        if not area2 > 1e-12 * size * size:
            raise InputError("polygon: degenerate cut polygon (zero area or collinear vertices)")
        n = nrm / area2
        if np.abs((P - c) @ n).max() > 1e-6 * size:
            raise InputError("polygon: the vertices are not coplanar (split it into planar polygons)")
        e1 = P[0] - c
        e1 -= n * (e1 @ n)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        P2 = np.c_[(P - c) @ e1, (P - c) @ e2]
        turns = [_cross2(P2[(i + 1) % len(P2)] - P2[i], P2[(i + 2) % len(P2)] - P2[(i + 1) % len(P2)])
                 for i in range(len(P2))]
        if min(turns) < -1e-9 * size * size:
            raise InputError("polygon: expected a convex polygon (split non-convex cut shapes into convex ones)")
        ed = self.ed
        base_d, classify, force_zero = self._classifier(c, n)

        def to2(x: np.ndarray) -> np.ndarray:
            return np.array([(x - c) @ e1, (x - c) @ e2])

        eps = 1e-9 * size
        # 1. split the crossed elements whose plane section overlaps the polygon
        ed.reset_cache()
        near = self._near(base_d, P)
        split_children: set[int] = set()
        for e in near:
            sec = self._section(e, classify)
            if sec is None or not _overlap(np.array([to2(x) for x in sec]), P2, eps):
                continue
            r = self.split(e, classify, force_zero, n)
            if r is not None:
                split_children.update(r)
        # 2. in-plane interior faces overlapping the polygon
        cand_elems = set(split_children) | {e for e in near if self._has_zero(e, classify)}
        faces = set()
        for e in cand_elems:
            for f, _ in ed.elem(e):
                faces.add(f)
        T = []
        for f in faces:
            if f in ed.dead_faces:
                continue
            cyc = ed.face(f)
            refs = ed.refs(f)
            if len(refs) != 2 or any(classify(v)[1] != 0 for v in cyc):
                continue
            sides = {self._side(a, classify) for a, _ in refs}
            if sides != {-1, 1}:
                continue
            if _overlap(np.array([to2(ed.point(v)) for v in cyc]), P2, eps):
                T.append(f)
        if not T:
            warnings.warn("cut polygon misses the mesh (no material on its plane inside the polygon); nothing cut",
                          CutMissWarning, stacklevel=3)
            return 0
        # 3. split the in-plane faces along the polygon edges (each line only where its segment crosses)
        side_cls = []
        for j in range(len(P)):
            a3, b3 = P[j], P[(j + 1) % len(P)]
            a2, b2 = P2[j], P2[(j + 1) % len(P)]
            m = np.cross(n, b3 - a3)
            m /= np.linalg.norm(m)
            if (c - a3) @ m > 0:
                m = -m
            ed.reset_cache()
            _, cls_j, zero_j = self._classifier(a3, m)
            side_cls.append(cls_j)
            newT = []
            for f in T:
                cyc = ed.face(f)
                poly = np.array([to2(ed.point(v)) for v in cyc])
                if not _segment_crosses(a2, b2, poly, eps):
                    newT.append(f)
                    continue
                cl = {v: cls_j(v)[1] for v in cyc}
                if not (any(x < 0 for x in cl.values()) and any(x > 0 for x in cl.values())):
                    newT.append(f)
                    continue
                for i in range(len(cyc)):
                    a, b = cyc[i], cyc[(i + 1) % len(cyc)]
                    if cl[a] * cl[b] < 0:
                        mnode = self._new_edge_node(a, b, cls_j(a)[0], cls_j(b)[0], zero_j)
                        force_zero(mnode)  # lies in the cut plane
                cyc = ed.face(f)
                pn, pp = _split_cycle(cyc, [cls_j(v)[1] for v in cyc])
                newT.extend(ed.split_face(f, pn, pp))
            T = newT
        # 4. the cut faces: pieces inside the polygon, decided with the same (snapped) side
        #    classification as the splits, so a piece is never left between two polygons
        inside = []
        for f in T:
            cyc = ed.face(f)
            if all(max(cl(v)[1] for v in cyc) <= 0 for cl in side_cls):
                inside.append(f)
        if not inside:
            warnings.warn("cut polygon covers no in-plane face of the mesh; nothing cut", CutMissWarning, stacklevel=3)
            return 0
        self.touched = True
        return self._separate(set(inside))

    def _near(self, base_d: np.ndarray, P: np.ndarray) -> list[int]:
        lo, hi = P.min(axis=0), P.max(axis=0)
        pad = 1e-9 * float(np.ptp(P, axis=0).max())
        off, nodes = self.mesh.element_nodes()
        d = base_d[nodes]
        dlo = np.minimum.reduceat(d, off[:-1])
        dhi = np.maximum.reduceat(d, off[:-1])
        tol = self.snap_length
        box = np.all(self._elo <= hi + pad, axis=1) & np.all(self._ehi >= lo - pad, axis=1)
        base = np.flatnonzero(box & (dlo <= tol) & (dhi >= -tol)).tolist()
        ed = self.ed
        edited = {e for e in ed._elems if e not in ed.dead_elems}
        out = [e for e in base if e not in edited and e not in ed.dead_elems]
        for e in sorted(edited):
            pts = ed.points_of(ed.elem_nodes(e))
            if np.all(pts.min(axis=0) <= hi + pad) and np.all(pts.max(axis=0) >= lo - pad):
                out.append(e)
        return out

    def _has_zero(self, e: int, classify) -> bool:
        return any(classify(v)[1] == 0 for v in self.ed.elem_nodes(e))

    def _side(self, e: int, classify) -> int:
        cs = {classify(v)[1] for v in self.ed.elem_nodes(e)}
        if 1 in cs and -1 not in cs:
            return 1
        if -1 in cs and 1 not in cs:
            return -1
        return 0

    def _half_volumes(self, e: int, classify, origin: np.ndarray, normal: np.ndarray) -> tuple[float, float]:
        """Volumes of the two halves the split would create (divergence theorem about a point on
        the plane, so the cap contributes nothing), computed before any edit."""
        ed = self.ed
        out = [0.0, 0.0]
        for f, s in ed.elem(e):
            cyc = ed.oriented(f, s)
            for k, sgn in enumerate((-1, 1)):
                poly = []
                for i, a in enumerate(cyc):
                    b = cyc[(i + 1) % len(cyc)]
                    da, ca = classify(a)
                    db, cb = classify(b)
                    if ca * sgn >= 0:
                        poly.append(ed.point(a))
                    if ca * cb < 0:
                        t = da / (da - db)
                        poly.append((1 - t) * ed.point(a) + t * ed.point(b))
                if len(poly) < 3:
                    continue
                q = np.array(poly) - origin
                area = 0.5 * np.cross(q, np.roll(q, -1, axis=0)).sum(axis=0)
                out[k] += float(area @ q.mean(axis=0)) / 3.0
        return out[0], out[1]

    def _section(self, e: int, classify) -> list[np.ndarray] | None:
        """Points of the element's section by the plane (zero nodes and edge crossings)."""
        ed = self.ed
        pts = []
        seen = set()
        for f, _ in ed.elem(e):
            c = ed.face(f)
            for i, a in enumerate(c):
                b = c[(i + 1) % len(c)]
                da, ca = classify(a)
                db, cb = classify(b)
                if ca == 0 and a not in seen:
                    seen.add(a)
                    pts.append(ed.point(a))
                if ca * cb < 0:
                    t = da / (da - db)
                    pts.append((1 - t) * ed.point(a) + t * ed.point(b))
        return pts if len(pts) >= 3 else None

    def _separate(self, sigma: set[int]) -> int:
        """Duplicate the nodes of the cut faces ``sigma`` per separated part of their element star."""
        ed = self.ed
        plan = self._duplication_plan(sigma)
        pocket = [f for f in sigma if not any(v in plan for v in ed.face(f))]
        for f in pocket:
            cyc = ed.face(f)
            pts = ed.points_of(cyc)
            cen = pts.mean(axis=0)
            w = _face_weights(pts, cen)
            cnode = ed.add_node(cen, ed.combine(cyc, list(w)))
            tris = [[cnode, cyc[i], cyc[(i + 1) % len(cyc)]] for i in range(len(cyc))]
            ids = ed.replace_face(f, tris)
            sigma.discard(f)
            sigma.update(ids)
        if pocket:
            plan = self._duplication_plan(sigma)
        # new nodes: one per extra component
        assign: dict[int, dict[int, int]] = {}
        for v, comps in plan.items():
            table = {}
            for k, comp in enumerate(comps):
                node = v if k == 0 else ed.add_node(ed.point(v), dict(ed.node_weights(v)))
                for e in comp:
                    table[e] = node
            assign[v] = table
        affected = set()
        for v in plan:
            affected.update(ed.faces_of_node(v))
        for f in affected:
            cyc = ed.face(f)
            refs = ed.refs(f)
            versions = [[assign[v].get(e, v) if v in assign else v for v in cyc] for e, _ in refs]
            if len(refs) == 2 and versions[0] != versions[1]:
                (ea, sa), (eb, sb) = refs
                ed.set_face(f, versions[0])
                ed.set_refs(f, [(ea, sa)])
                g = ed.new_face(versions[1], [(eb, sb)])
                faces = ed.elem(eb)
                k = faces.index((f, sb))
                ed.set_elem(eb, [*faces[:k], (g, sb), *faces[k + 1:]])
            elif refs and versions[0] != cyc:
                ed.set_face(f, versions[0])
        return sum(len(c) - 1 for c in plan.values())

    def _duplication_plan(self, sigma: set[int]) -> dict[int, list[list[int]]]:
        """For each node of the cut faces that the cut separates: the element groups (first keeps the node)."""
        ed = self.ed
        nodes = {v for f in sigma for v in ed.face(f)}
        plan = {}
        for v in sorted(nodes):
            elems = sorted(ed.elems_of_node(v))
            idx = {e: i for i, e in enumerate(elems)}
            cut = list(range(len(elems)))
            full = list(range(len(elems)))

            def find(p: list[int], i: int) -> int:
                while p[i] != i:
                    p[i] = p[p[i]]
                    i = p[i]
                return i

            for f in ed.faces_of_node(v):
                refs = ed.refs(f)
                if len(refs) != 2:
                    continue
                i, j = idx[refs[0][0]], idx[refs[1][0]]
                full[find(full, i)] = find(full, j)
                if f not in sigma:
                    cut[find(cut, i)] = find(cut, j)
            groups: dict[int, dict[int, list[int]]] = {}
            for e in elems:
                i = idx[e]
                groups.setdefault(find(full, i), {}).setdefault(find(cut, i), []).append(e)
            comps = []
            for parts in groups.values():
                if len(parts) > 1:
                    comps.extend(parts.values())
            if comps:
                plan[v] = comps
        return plan

    def commit(self, check: bool = True) -> EditResult:
        """The edited mesh and the state maps.

        Snapped nodes lie off the cut planes by up to ``snap_length`` or ``snap`` times
        an incident edge, so the result is checked for convexity within ``4·snap`` of
        the element size or ``2·snap`` times the longest edge (absolute).
        """
        tol = max(self.mesh.tolerance, 4.0 * self.snap)
        atol = max(self.mesh.abs_tolerance, 4.0 * self.snap_length, 2.0 * self.snap * self.mesh.max_edge_length())
        return self.ed.commit(tolerance=tol, abs_tolerance=atol, check=check)


def _face_weights(pts: np.ndarray, x: np.ndarray) -> np.ndarray:
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


def _section_area(pts: np.ndarray, normal: np.ndarray) -> float:
    """Area of the convex hull of points lying (about) in a plane with the given normal."""
    c = pts.mean(axis=0)
    e1 = pts[np.argmax(np.linalg.norm(pts - c, axis=1))] - c
    if not np.linalg.norm(e1) > 0:
        return 0.0
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    q = np.c_[(pts - c) @ e1, (pts - c) @ e2]
    ang = np.arctan2(q[:, 1], q[:, 0])
    q = q[np.argsort(ang)]
    return 0.5 * abs(float(np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1))))


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _proj(poly: np.ndarray, axis: np.ndarray) -> tuple[float, float]:
    p = poly @ axis
    return float(p.min()), float(p.max())


def _overlap(A: np.ndarray, B: np.ndarray, eps: float) -> bool:
    """Do two convex 2D polygons overlap with positive area (separating axis test)?"""
    for poly in (A, B):
        k = len(poly)
        for i in range(k):
            d = poly[(i + 1) % k] - poly[i]
            ax = np.array([-d[1], d[0]])
            ln = np.linalg.norm(ax)
            if ln == 0:
                continue
            ax /= ln
            a0, a1 = _proj(A, ax)
            b0, b1 = _proj(B, ax)
            if a1 <= b0 + eps or b1 <= a0 + eps:
                return False
    return True


def _inside(p: np.ndarray, P: np.ndarray, eps: float) -> bool:
    k = len(P)
    sgn = np.sign(sum(_cross2(P[i], P[(i + 1) % k]) for i in range(k)))
    for i in range(k):
        d = P[(i + 1) % k] - P[i]
        if sgn * _cross2(d, p - P[i]) / max(np.linalg.norm(d), 1e-300) <= eps:
            return False
    return True


def _segment_crosses(a: np.ndarray, b: np.ndarray, poly: np.ndarray, eps: float) -> bool:
    """Does segment ab pass through the interior of convex polygon poly (Cyrus–Beck clip)?"""
    k = len(poly)
    sgn = np.sign(sum(_cross2(poly[i], poly[(i + 1) % k]) for i in range(k)))
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


def apply_cuts(mesh: PolyMesh, cuts: list[PlaneCut | PolygonCut], *, snap: float = 0.02,
               check: bool = True) -> EditResult:
    """Apply several cuts in order and commit once (one re-integration per step).

    Parameters
    ----------
    mesh : PolyMesh
    cuts : list of PlaneCut or PolygonCut
        In rest coordinates.
    snap : float
        Snapping distance as a fraction of the longest edge length.
    check : bool
        Validate the result (closed, oriented, convex within ``4·snap``).

    Returns
    -------
    EditResult
        New mesh, node-state weights (new × old), element parents, changed flags.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> import numpy as np
    >>> quad = np.array([[-1, 0.5, -1], [2, 0.5, -1], [2, 0.5, 0.5], [-1, 0.5, 0.5]])
    >>> r = apply_cuts(hex_grid((2, 2, 2)), [PolygonCut(quad)])
    >>> r.mesh.n_nodes > 27
    True
    """
    cutter = Cutter(mesh, snap)
    for cut in cuts:
        if isinstance(cut, PlaneCut):
            cutter.plane(cut.origin, cut.normal, cut.elements)
        elif isinstance(cut, PolygonCut):
            cutter.polygon(cut.polygon)
        elif hasattr(cut, "apply"):
            cut.apply(cutter)
        else:
            raise InputError(f"cuts: expected PlaneCut or PolygonCut, got {type(cut).__name__}")
    return cutter.commit(check)


def cut_by_plane(mesh: PolyMesh, origin: Any, normal: Any, *, snap: float = 0.02) -> PolyMesh:
    """Split every element the plane crosses (9.3.1); nothing is separated.

    Parameters
    ----------
    mesh : PolyMesh
    origin, normal : (3,) floats
        The plane (rest coordinates).
    snap : float
        Nodes closer to the plane than ``snap`` × the longest edge length count as on it.

    Returns
    -------
    PolyMesh
        Same volume; every element convex within ``4·snap`` (relative).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> cut_by_plane(hex_grid((1, 1, 1)), (0.5, 0.5, 0.5), (1, 1, 1)).n_elements
    2
    """
    cutter = Cutter(mesh, snap)
    count = cutter.plane(origin, normal)
    if count == 0:
        warnings.warn("cut plane misses the mesh (no element crosses it); nothing cut", CutMissWarning, stacklevel=2)
    return cutter.commit().mesh


def split_element(mesh: PolyMesh, element: int, origin: Any, normal: Any, *, snap: float = 0.02) -> PolyMesh:
    """Split one element by a plane (9.3.1); neighbours get t-junction nodes, not splits.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> split_element(hex_grid((2, 1, 1), size=(2, 1, 1)), 0, (0.5, 0.3, 0.5), (0, 1, 0)).n_elements
    3
    """
    cutter = Cutter(mesh, snap)
    count = cutter.plane(origin, normal, [int(element)])
    if count == 0:
        warnings.warn(f"cut plane misses element {element}; nothing cut", CutMissWarning, stacklevel=2)
    return cutter.commit().mesh


def cut_by_polygon(mesh: PolyMesh, polygon: Any, *, snap: float = 0.02) -> PolyMesh:
    """Progressive cut by a planar convex polygon (9.3.2): split, tessellate, duplicate nodes.

    Parameters
    ----------
    mesh : PolyMesh
    polygon : (k, 3) floats
        Convex planar cut shape (rest coordinates).
    snap : float

    Returns
    -------
    PolyMesh
        The material is separated inside the polygon and stays connected outside.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> import numpy as np
    >>> half = np.array([[-1, 0.5, -1], [2, 0.5, -1], [2, 0.5, 0.5], [-1, 0.5, 0.5]])
    >>> cut = cut_by_polygon(hex_grid((2, 2, 2)), half)
    >>> cut.n_nodes - 27  # nodes duplicated along the opened half of the middle plane
    3
    """
    cutter = Cutter(mesh, snap)
    cutter.polygon(polygon)
    return cutter.commit().mesh
