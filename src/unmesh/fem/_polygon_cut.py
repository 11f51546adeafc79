"""Progressive cuts by polygons (9.3.2): the part of :class:`unmesh.fem.cutting.Cutter` that
cuts along a convex planar polygon and separates the material along the cut faces by
duplicating their nodes (the pocket case included).

Example
-------
>>> from unmesh.fem import hex_grid
>>> from unmesh.fem.cutting import Cutter
>>> import numpy as np
>>> c = Cutter(hex_grid((2, 2, 2)))
>>> c.polygon(np.array([[-1, 0.5, -1], [2, 0.5, -1], [2, 0.5, 0.5], [-1, 0.5, 0.5]]))  # nodes duplicated
3
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from unmesh._validate import as_points
from unmesh.errors import InputError
from unmesh.fem import _cutgeom as G
from unmesh.fem._sides import PlaneSides


class CutMissWarning(UserWarning):
    """A cut did not intersect the mesh (nothing changed)."""


class PolygonCutter:
    """Mixin of :class:`unmesh.fem.cutting.Cutter`: :meth:`polygon` and the node duplication."""

    def polygon(self, polygon: Any) -> int:
        """Cut along a convex planar polygon (k,3); returns the number of duplicated nodes.

        1. Every element whose plane section overlaps the polygon and that has nodes on
           both sides of the plane is split (9.3.1; never refused, see :meth:`_prepare`).
        2. The *cut faces* are all faces lying in the plane (every node on it, up to
           snapping) between elements on opposite sides - created by the splits or
           already there - restricted to the polygon: faces crossing a polygon edge are
           split along it.
        3. Nodes of the cut faces are duplicated per part of their element star that the
           cut faces separate (:meth:`_separate`); nodes on the polygon's boundary stay
           shared, and cut faces without such a node get a node at their centroid first
           (the pocket case).

        Every path between the two sides inside the polygon crosses a cut face (an
        element has nodes on one side only, so a face between opposite sides has all its
        nodes on the plane), so a polygon covering the whole section separates the
        material, whatever was snapped.
        """
        try:
            return self._polygon(polygon)
        finally:
            self._keep_forced()

    def _polygon(self, polygon: Any) -> int:
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
        turns = [G.cross2(P2[(i + 1) % len(P2)] - P2[i], P2[(i + 2) % len(P2)] - P2[(i + 1) % len(P2)])
                 for i in range(len(P2))]
        if min(turns) < -1e-9 * size * size:
            raise InputError("polygon: expected a convex polygon (split non-convex cut shapes into convex ones)")
        ed = self.ed
        sides = PlaneSides(self, c, n)

        def to2(x: np.ndarray) -> np.ndarray:
            return np.array([(x - c) @ e1, (x - c) @ e2])

        eps = 1e-9 * size
        # 1. split the straddling elements whose plane section overlaps the polygon
        ed.reset_cache()
        near = self._near(sides.base_d, P)

        def overlaps(e: int) -> bool:
            sec = self._section(e, sides)
            return sec is not None and G.overlap(np.array([to2(x) for x in sec]), P2, eps)

        crossing = [e for e in near if self._straddles(ed.elem_nodes(e), sides) and overlaps(e)]
        for e in near:  # straddling without a section polygon: only collinear nodes cross the plane
            nodes = ed.elem_nodes(e)
            if self._straddles(nodes, sides) and self._section(e, sides) is None:
                crossing.append(e)
        split_children: set[int] = set()

        def outside(v: int) -> bool:
            return G.outside(to2(ed.point(v)), P2, sides.band(v))

        for e in self._prepare(crossing, sides, outside):
            r = self.split(e, sides)
            if r is not None:
                split_children.update(r)
        # 2. in-plane faces between opposite sides overlapping the polygon
        cand_elems = split_children | {e for e in near if e not in ed.dead_elems and self._has_zero(e, sides)}
        faces = set()
        for e in cand_elems:
            for f, _ in ed.elem(e):
                faces.add(f)
        side_of: dict[int, int] = {}

        def side(e: int) -> int:
            s = side_of.get(e)
            if s is None:
                s = side_of[e] = self._side(e, sides)
            return s

        T = []
        for f in sorted(faces):
            if f in ed.dead_faces:
                continue
            refs = ed.refs(f)
            if len(refs) != 2:
                continue
            cyc = ed.face(f)
            if any(sides.cls(v) != 0 for v in cyc):
                continue
            if {side(a) for a, _ in refs} != {-1, 1}:
                continue
            if G.overlap(np.array([to2(ed.point(v)) for v in cyc]), P2, eps):
                T.append(f)
        if not T:
            warnings.warn("cut polygon misses the mesh (no material on its plane inside the polygon); nothing cut",
                          CutMissWarning, stacklevel=3)
            return 0
        # 3. split the in-plane faces along the polygon edges (each line only where its segment crosses)
        line_sides = []
        for j in range(len(P)):
            a3, b3 = P[j], P[(j + 1) % len(P)]
            a2, b2 = P2[j], P2[(j + 1) % len(P)]
            m = np.cross(n, b3 - a3)
            m /= np.linalg.norm(m)
            if (c - a3) @ m > 0:
                m = -m
            ed.reset_cache()
            ls = PlaneSides(self, a3, m, keep=False)
            line_sides.append(ls)
            newT = []
            for f in T:
                cyc = ed.face(f)
                poly = np.array([to2(ed.point(v)) for v in cyc])
                if not G.segment_crosses(a2, b2, poly, eps):
                    newT.append(f)
                    continue
                cl = [ls.cls(v) for v in cyc]
                runs = G.sign_runs(cl)
                if len(runs) < 2:
                    newT.append(f)
                    continue
                while len(runs) > 2:  # a slightly non-convex face: snap the nodes of the shortest run
                    worst = min(runs, key=lambda r: max(abs(ls.distance(cyc[i])) for i in r))
                    for i in worst:
                        ls.force(cyc[i])
                        cl[i] = 0
                    runs = G.sign_runs(cl)
                for i in range(len(cyc)):
                    a, b = cyc[i], cyc[(i + 1) % len(cyc)]
                    if cl[i] * cl[(i + 1) % len(cyc)] < 0:
                        mnode = self._new_edge_node(a, b, ls)
                        sides.on_plane(mnode)  # lies in the cut plane
                cyc = ed.face(f)
                pn, pp = G.split_cycle(cyc, [ls.cls(v) for v in cyc])
                newT.extend(ed.split_face(f, pn, pp))
            T = newT
        # 4. the cut faces: pieces inside the polygon, decided with the same (snapped) side
        #    classification as the splits, so a piece is never left between two polygons
        inside = [f for f in T if all(max(ls.cls(v) for v in ed.face(f)) <= 0 for ls in line_sides)]
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
        tol = self.max_band
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

    def _separate(self, sigma: set[int]) -> int:
        """Duplicate the nodes of the cut faces ``sigma`` per separated part of their element star."""
        ed = self.ed
        plan = self._duplication_plan(sigma)
        pocket = [f for f in sigma if not any(v in plan for v in ed.face(f))]
        for f in pocket:
            cyc = ed.face(f)
            pts = ed.points_of(cyc)
            cen = pts.mean(axis=0)
            w = G.face_weights(pts, cen)
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
