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

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, scalar
from unmesh.errors import InputError
from unmesh.fem._sides import PlaneSides
from unmesh.fem.editor import EditResult, MeshEditor
from unmesh.fem.mesh import PolyMesh

__all__ = ["CutMissWarning", "Cutter", "PlaneCut", "PolygonCut", "apply_cuts", "cut_by_plane", "cut_by_polygon",
           "split_element"]

#: Cut elements are convex within ``CONVEXITY_FACTOR * snap`` of their diameter (checked on commit).
CONVEXITY_FACTOR = 4.0



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


def _sign_runs(cl: list[int]) -> list[list[int]]:
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


def _split_cycle(cyc: list[int], cl: list[int]) -> tuple[list[int], list[int]]:
    """Split a face cycle classified -1/0/+1 into its (negative, positive) pieces.

    Requires one run of each sign (zeros ignored) and no edge joining -1 and +1
    (crossing edges are split first). The pieces share the chord between the zero
    nodes bounding the negative run; both keep the face's orientation.
    """
    n = len(cyc)
    if len(_sign_runs(cl)) != 2:
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


def _newell(p: np.ndarray) -> np.ndarray:
    """Area vector (Newell normal times area) of a polygon (k,3)."""
    c = p.mean(axis=0)
    return 0.5 * np.cross(p - c, np.roll(p, -1, axis=0) - c).sum(axis=0)


class Cutter:
    """Applies plane and polygon cuts to a :class:`MeshEditor` (commit once at the end).

    Parameters
    ----------
    mesh : PolyMesh
    snap : float
        Snapping fraction (see :mod:`unmesh.fem._sides`): a node within ``snap`` times
        its length scale (:meth:`PolyMesh.node_scales`, initially its longest edge) of
        a cut plane is taken to lie on it.

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
        #: widest snapping band of any node (a pre-filter for candidate elements)
        self.max_band = self.snap * float(mesh.node_scales().max(initial=0.0))
        off, nodes = mesh.element_nodes()
        p = mesh.points[nodes]
        self._elo = np.minimum.reduceat(p, off[:-1], axis=0) if len(off) > 1 else np.zeros((0, 3))
        self._ehi = np.maximum.reduceat(p, off[:-1], axis=0) if len(off) > 1 else np.zeros((0, 3))
        self.touched = False
        #: nodes snapped onto a plane because a split would have left a degenerate half
        self.forced = 0
        #: straddling elements whose split would have been degenerate (their thin side was snapped)
        self.degenerate = 0
        #: forced snapping decisions of the current cut to keep (node -> distance), see :meth:`keep_snapped`
        self._kept: dict[int, float] = {}

    # -- nodes ---------------------------------------------------------------------------------
    def length_scale(self, v: int) -> float:
        """Snapping length scale of node v (:meth:`PolyMesh.node_scales`, carried over by cuts)."""
        return self.ed.node_scale(v)

    def keep_snapped(self, v: int, distance: float) -> None:
        """Keep the decision to snap node v onto a plane it lies ``distance`` off (called by
        :meth:`PlaneSides.force`): once the current cut is done, v's length scale grows so that
        its band covers ``distance`` (:attr:`MeshEditor.scale_override`, carried over by the
        commit into :meth:`PolyMesh.node_scales`).

        So a node forced onto the blade plane in one step of a progressive cut (9.3.2) is on
        it in the next steps as well (as a node within its own band is, :mod:`._sides`):
        otherwise the next step finds the element it kept on one side straddling the
        plane again and cuts off the sliver between that element's face through the node,
        which the previous step left as (part of) the cut surface, and the plane; the
        sliver's cap then runs through the snapped nodes of that face, which lie off the
        plane by up to their band, at a grazing angle: in the plane they lie far inside
        the section, so the cap is not convex (the blob slicing scene, issue 5).

        Kept are the decisions for thin sides (:meth:`_thin_side`: within twice the band of
        a node of the element), degenerate halves and slightly non-convex faces, not those of
        the fallback for an element whose halves do not close (:meth:`_unsplittable_side`):
        it may snap nodes from farther away, and a band grown to that distance would snap
        them onto unrelated later planes too. Nor are the snaps onto the planes through a
        cut polygon's edges kept (``PlaneSides(keep=False)``), which only clip its faces.
        """
        self._kept[v] = max(self._kept.get(v, 0.0), distance)

    def _keep_forced(self) -> None:
        """Grow the length scales of the nodes forced by the cut just done (:meth:`keep_snapped`)."""
        if self.snap > 0:
            for v, d in self._kept.items():
                # a hair wider than the distance, so the next plane (same plane, another
                # origin on it: other rounding) still finds the node within its band
                h = d / self.snap * (1.0 + 1e-9)
                if h > self.ed.node_scale(v):
                    self.ed.scale_override[v] = h
                    self.max_band = max(self.max_band, self.snap * h)
        self._kept.clear()

    def _new_edge_node(self, a: int, b: int, sides: PlaneSides) -> int:
        da, db = sides.distance(a), sides.distance(b)
        t = da / (da - db)
        m = self.ed.split_edge(a, b, t)
        sides.on_plane(m)
        return m

    # -- 9.3.1 element split ---------------------------------------------------------------------
    def _prepare(self, elems: list[int], sides: PlaneSides,
                 outside: Callable[[int], bool] | None = None) -> list[int]:
        """Make every element of ``elems`` that straddles the plane splittable; return those.

        Snapping decisions are global per node, so a split is never refused: where a face
        would be crossed more than twice (a slightly non-planar face) the nodes of the
        shortest sign runs are snapped onto the plane, and where one half would be
        degenerate (less than 1e-6 of the volume) its nodes are snapped onto the plane,
        so the element lies on one side. ``outside(v)`` tells whether node v lies outside
        the cut polygon (beyond its snapping band; ``None`` for a plane cut), see
        :meth:`_unsplittable_side`.
        """
        ed = self.ed
        out: list[int] = []
        for _sweep in range(20):
            changed = False
            out = []
            for e in elems:
                if e in ed.dead_elems:
                    continue
                nodes = ed.elem_nodes(e)
                if not self._straddles(nodes, sides):
                    continue
                for f, _ in ed.elem(e):
                    cyc = ed.face(f)
                    cl = [sides.cls(v) for v in cyc]
                    runs = _sign_runs(cl)
                    while len(runs) > 2:
                        worst = min(runs, key=lambda r: max(abs(sides.distance(cyc[i])) for i in r))
                        for i in worst:
                            changed |= sides.force(cyc[i])
                            cl[i] = 0
                        self.forced += len(worst)
                        runs = _sign_runs(cl)
                if not self._straddles(nodes, sides):
                    continue
                thin = self._thin_side(nodes, sides)
                keep = True  # the decision holds for later steps, except the fallback's (see keep_snapped)
                if thin == 0:
                    vneg, vpos = self._half_volumes(e, sides)
                    if min(vneg, vpos) <= 1e-6 * (vneg + vpos):
                        thin = -1 if vneg < vpos else 1
                        if vneg < 0 or vpos < 0:  # no valid split
                            thin = self._unsplittable_side(e, nodes, sides, outside)
                            keep = False
                        self.degenerate += 1
                if thin != 0:
                    for v in nodes:
                        if sides.cls(v) == thin:
                            changed |= sides.force(v, keep)
                            self.forced += 1
                    continue
                out.append(e)
            if not changed:
                return out
        return out

    def _unsplittable_side(self, e: int, nodes: list[int], sides: PlaneSides,
                           outside: Callable[[int], bool] | None) -> int:
        """The side (-1/+1) to snap onto the plane for a straddling element whose halves
        do not close.

        The halves fail to close when a face of the element that lies in the plane
        (every node snapped onto it) does not bound the half :meth:`_flat_side` gives it
        to: the face is only snapped, and in truth tilted against the plane - typically
        a face of an earlier cut next to the bend line of a curved blade, where the
        previous blade plane meets the current one within the snapping band.

        For a polygon cut (``outside`` given): if the in-plane faces all say that the
        element is on side ``s`` (a convex element lies behind its faces) and every
        node on the other side lies outside the polygon, those nodes are snapped. They
        lie beyond the bend, where this plane does not cut, so snapping them changes
        how the element is subdivided there but not what the cut separates.
        Otherwise (and always for a plane cut) the side closer to the plane is snapped.
        Doing that in the case above snaps a node from the far side of the cut surface
        onto the plane: the element then bridges the cut, a hinge that keeps the two
        pieces together (issue 5, the curved blade sweep through the blob).
        """
        if outside is not None:
            ed = self.ed
            behind = {self._flat_side(cyc, sides) for f, s in ed.elem(e) for cyc in (ed.oriented(f, s),)
                      if all(sides.cls(v) == 0 for v in cyc)}
            if len(behind) == 1:
                s = behind.pop()
                if all(outside(v) for v in nodes if sides.cls(v) == -s):
                    return -s
        reach = {s_: max((abs(sides.distance(v)) for v in nodes if sides.cls(v) == s_), default=0.0)
                 for s_ in (-1, 1)}
        return -1 if reach[-1] <= reach[1] else 1

    @staticmethod
    def _thin_side(nodes: list[int], sides: PlaneSides) -> int:
        """A side (-1/+1) whose nodes lie within twice the height of the nodes snapped onto the
        plane on that side (the half would be a folded sliver under its non-planar cap), else 0.

        Only nodes within their own snapping band count as snapped here (not nodes forced
        onto the plane), so forced distances stay below twice the band and cannot cascade.
        """
        top = {-1: 0.0, 1: 0.0}
        cap = {-1: 0.0, 1: 0.0}
        for v in nodes:
            d, c = sides(v)
            if c != 0:
                top[c] = max(top[c], abs(d))
            elif d != 0.0 and abs(d) <= sides.band(v) and v not in sides.forced:
                s = 1 if d > 0 else -1
                cap[s] = max(cap[s], abs(d))
        for s in (-1, 1):
            if 0.0 < top[s] <= 2.0 * cap[s]:
                return s
        return 0

    @staticmethod
    def _straddles(nodes: list[int], sides: PlaneSides) -> bool:
        cs = {sides.cls(v) for v in nodes}
        return 1 in cs and -1 in cs

    def split(self, e: int, sides: PlaneSides) -> tuple[int, int] | None:
        """Split element e by the plane of ``sides``; returns its (negative, positive) halves.

        Call :meth:`_prepare` first (it guarantees non-degenerate halves). Faces
        lying in the plane (all nodes on it) go with the half they bound: the one
        on the side their outward normal points away from.
        """
        ed = self.ed
        normal = sides.normal
        cls = {v: sides.cls(v) for v in ed.elem_nodes(e)}
        if not (any(c < 0 for c in cls.values()) and any(c > 0 for c in cls.values())):
            return None
        edges = set()
        for f, _ in ed.elem(e):
            c = ed.face(f)
            for i, a in enumerate(c):
                b = c[(i + 1) % len(c)]
                if cls[a] * cls[b] < 0:
                    edges.add((min(a, b), max(a, b)))
        for a, b in sorted(edges):
            cls[self._new_edge_node(a, b, sides)] = 0
        neg: list[tuple[int, int]] = []
        pos: list[tuple[int, int]] = []
        flat: list[tuple[int, int]] = []
        for f, s in list(ed.elem(e)):
            cyc = ed.face(f)
            cl = [cls[v] for v in cyc]
            has_n = any(c < 0 for c in cl)
            has_p = any(c > 0 for c in cl)
            if has_n and has_p:
                pn, pp = _split_cycle(cyc, cl)
                f1, f2 = ed.split_face(f, pn, pp)
                neg.append((f1, s))
                pos.append((f2, s))
            elif has_n:
                neg.append((f, s))
            elif has_p:
                pos.append((f, s))
            else:
                flat.append((f, s))
        loop = None
        for attempt in ("geometry", "adjacency"):
            n_side, p_side = list(neg), list(pos)
            for fs in (flat if attempt == "geometry" else []):
                (p_side if self._flat_side(ed.oriented(*fs), sides) > 0 else n_side).append(fs)
            if attempt == "adjacency":
                self._assign_by_adjacency(flat, n_side, p_side, normal)
            try:
                loop = _open_loop([ed.oriented(f, s) for f, s in n_side])
            except InputError:
                if not flat or attempt == "adjacency":
                    raise
                continue
            break
        assert loop is not None
        if len(n_side) < 3 or len(p_side) < 3:
            raise InputError("degenerate cut: a half of a split element has fewer than three faces")
        cap = [loop[0], *loop[:0:-1]]
        g = ed.new_face(cap, [])
        ed.set_elem(e, [*n_side, (g, 1)])
        e2 = ed.new_elem([*p_side, (g, -1)], parent=e)
        ed.set_refs(g, [(e, 1), (e2, -1)])
        for f, s in p_side:
            ed.set_refs(f, [(e2 if (a == e and sa == s) else a, sa) for a, sa in ed.refs(f)])
        self.touched = True
        return e, e2

    def _flat_side(self, cyc: list[int], sides: PlaneSides) -> int:
        """Half (+1/-1) that an element face lying in the plane (every node snapped onto it) bounds.

        ``cyc`` is oriented outward for the element. A convex element lies behind each of
        its faces, so a face in the plane bounds the half its outward normal points away
        from. This holds also for a face that is slightly tilted against the plane (its
        nodes snapped from one side): deciding by the side its nodes lie on instead would
        give such a face to the half that is in front of it, and that half's cap would
        then overlap it (an edge used by four faces of one element).
        """
        area = _newell(self.ed.points_of(cyc))
        return 1 if area @ sides.normal < 0 else -1

    def _assign_by_adjacency(self, flat: list[tuple[int, int]], neg: list[tuple[int, int]],
                             pos: list[tuple[int, int]], normal: np.ndarray) -> None:
        """Give each in-plane face to the half whose faces share more of its edges."""
        ed = self.ed
        todo = list(flat)

        def shared(side: list[tuple[int, int]], cyc: list[int]) -> int:
            edges = {frozenset((a, cyc[(i + 1) % len(cyc)])) for i, a in enumerate(cyc)}
            return sum(frozenset((a, c[(i + 1) % len(c)])) in edges
                       for g, _ in side for c in (ed.face(g),) for i, a in enumerate(c))

        while todo:
            scores = [(shared(neg, ed.face(f)), shared(pos, ed.face(f)), (f, s)) for f, s in todo]
            sn, sp_, fs = max(scores, key=lambda t: abs(t[0] - t[1]))
            if sn == sp_:
                area = _newell(ed.points_of(ed.oriented(*fs)))
                (pos if area @ normal < 0 else neg).append(fs)
            else:
                (neg if sn > sp_ else pos).append(fs)
            todo.remove(fs)

    def plane(self, origin: Any, normal: Any, elements: Any | None = None) -> int:
        """Split every element the plane crosses (or only ``elements``); returns the number split."""
        try:
            return self._plane(origin, normal, elements)
        finally:
            self._keep_forced()

    def _plane(self, origin: Any, normal: Any, elements: Any | None) -> int:
        o = as_array(origin, "origin", (3,))
        n = _unit(normal, "normal")
        sides = PlaneSides(self, o, n)
        ed = self.ed
        ed.reset_cache()
        if elements is None:
            cand = self._candidates(sides.base_d)
        else:
            cand = [int(e) for e in np.atleast_1d(np.asarray(elements, dtype=np.int64))]
            bad = [e for e in cand if not 0 <= e < ed.n_elems or e in ed.dead_elems]
            if bad:
                raise InputError(f"elements: no element {bad[0]} in the mesh")
        count = 0
        for e in self._prepare(cand, sides):
            if self.split(e, sides) is not None:
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
        turns = [_cross2(P2[(i + 1) % len(P2)] - P2[i], P2[(i + 2) % len(P2)] - P2[(i + 1) % len(P2)])
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
            return sec is not None and _overlap(np.array([to2(x) for x in sec]), P2, eps)

        crossing = [e for e in near if self._straddles(ed.elem_nodes(e), sides) and overlaps(e)]
        for e in near:  # straddling without a section polygon: only collinear nodes cross the plane
            nodes = ed.elem_nodes(e)
            if self._straddles(nodes, sides) and self._section(e, sides) is None:
                crossing.append(e)
        split_children: set[int] = set()

        def outside(v: int) -> bool:
            return _outside(to2(ed.point(v)), P2, sides.band(v))

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
            if _overlap(np.array([to2(ed.point(v)) for v in cyc]), P2, eps):
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
                if not _segment_crosses(a2, b2, poly, eps):
                    newT.append(f)
                    continue
                cl = [ls.cls(v) for v in cyc]
                runs = _sign_runs(cl)
                if len(runs) < 2:
                    newT.append(f)
                    continue
                while len(runs) > 2:  # a slightly non-convex face: snap the nodes of the shortest run
                    worst = min(runs, key=lambda r: max(abs(ls.distance(cyc[i])) for i in r))
                    for i in worst:
                        ls.force(cyc[i])
                        cl[i] = 0
                    runs = _sign_runs(cl)
                for i in range(len(cyc)):
                    a, b = cyc[i], cyc[(i + 1) % len(cyc)]
                    if cl[i] * cl[(i + 1) % len(cyc)] < 0:
                        mnode = self._new_edge_node(a, b, ls)
                        sides.on_plane(mnode)  # lies in the cut plane
                cyc = ed.face(f)
                pn, pp = _split_cycle(cyc, [ls.cls(v) for v in cyc])
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

    def _has_zero(self, e: int, sides: PlaneSides) -> bool:
        return any(sides.cls(v) == 0 for v in self.ed.elem_nodes(e))

    def _side(self, e: int, sides: PlaneSides) -> int:
        """+1 / -1 for an element on one side of the plane (0 if it straddles it); an element
        lying in the plane (every node snapped onto it) takes the side of its centroid."""
        nodes = self.ed.elem_nodes(e)
        cs = {sides.cls(v) for v in nodes}
        if 1 in cs:
            return 0 if -1 in cs else 1
        if -1 in cs:
            return -1
        d = float((self.ed.points_of(nodes).mean(axis=0) - sides.origin) @ sides.normal)
        return 1 if d >= 0 else -1

    def _half_volumes(self, e: int, sides: PlaneSides) -> tuple[float, float]:
        """Volumes of the two halves the split would create, computed before any edit.

        The halves are built virtually exactly as :meth:`split` builds them (crossing
        points, face pieces, in-plane faces by orientation, the cap through the snapped
        nodes), so a half left flat by snapped nodes shows up as (almost) zero volume.
        A configuration the split could not close gives ``(-1, -1)`` (:meth:`_prepare` then
        snaps the element to one side, :meth:`_unsplittable_side`).
        """
        ed = self.ed
        pts: dict[Any, np.ndarray] = {}

        def point(k: Any) -> np.ndarray:
            x = pts.get(k)
            if x is None:
                if isinstance(k, tuple):
                    a, b = k
                    da, db = sides.distance(a), sides.distance(b)
                    t = da / (da - db)
                    x = (1 - t) * ed.point(a) + t * ed.point(b)
                else:
                    x = ed.point(k)
                pts[k] = x
            return x

        neg: list[list[Any]] = []
        pos: list[list[Any]] = []
        for f, s in ed.elem(e):
            cyc = ed.oriented(f, s)
            keys: list[Any] = []
            cl: list[int] = []
            for i, a in enumerate(cyc):
                b = cyc[(i + 1) % len(cyc)]
                ca, cb = sides.cls(a), sides.cls(b)
                keys.append(a)
                cl.append(ca)
                if ca * cb < 0:
                    keys.append((min(a, b), max(a, b)))
                    cl.append(0)
            has_n = any(c < 0 for c in cl)
            has_p = any(c > 0 for c in cl)
            if has_n and has_p:
                try:
                    pn, pp = _split_cycle(keys, cl)
                except InputError:
                    return -1.0, -1.0
                neg.append(pn)
                pos.append(pp)
            elif has_n:
                neg.append(keys)
            elif has_p:
                pos.append(keys)
            else:
                (pos if self._flat_side(cyc, sides) > 0 else neg).append(keys)
        try:
            loop = _open_loop(neg)
        except InputError:
            return -1.0, -1.0
        ox, oy, oz = point(loop[0]).tolist()
        flat: dict[Any, tuple[float, float, float]] = {}

        def volume(polys: list[list[Any]]) -> float:
            # scalar arithmetic: np.cross on 3-vectors cost most of the cut (issue 5)
            v = 0.0
            for poly in polys:
                q = []
                for k in poly:
                    t = flat.get(k)
                    if t is None:
                        x, y, z = point(k).tolist()
                        t = flat[k] = (x - ox, y - oy, z - oz)
                    q.append(t)
                ax, ay, az = q[0]
                for i in range(1, len(q) - 1):
                    bx, by, bz = q[i]
                    cx, cy, cz = q[i + 1]
                    v += ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
            return v / 6.0

        cap = [loop[0], *loop[:0:-1]]
        return volume([*neg, cap]), volume([*pos, loop])

    def _section(self, e: int, sides: PlaneSides) -> list[np.ndarray] | None:
        """Points of the element's section by the plane (zero nodes and edge crossings)."""
        ed = self.ed
        pts = []
        seen = set()
        for f, _ in ed.elem(e):
            c = ed.face(f)
            for i, a in enumerate(c):
                b = c[(i + 1) % len(c)]
                da, ca = sides(a)
                db, cb = sides(b)
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

        Snapped nodes lie off the cut planes by at most ``snap`` times their longest
        edge, so the result is checked for convexity within :data:`CONVEXITY_FACTOR`
        ``· snap`` of each element's diameter (no absolute allowance).
        """
        tol = max(self.mesh.tolerance, CONVEXITY_FACTOR * self.snap)
        return self.ed.commit(tolerance=tol, abs_tolerance=0.0, check=check)


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


def _proj(poly: list[list[float]], ax: float, ay: float) -> tuple[float, float]:
    lo = hi = poly[0][0] * ax + poly[0][1] * ay
    for x, y in poly[1:]:
        t = x * ax + y * ay
        lo = min(lo, t)
        hi = max(hi, t)
    return lo, hi


def _overlap(A: np.ndarray, B: np.ndarray, eps: float) -> bool:
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
            a0, a1 = _proj(a, ax, ay)
            b0, b1 = _proj(b, ax, ay)
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


def _outside(p: np.ndarray, P: np.ndarray, margin: float) -> bool:
    """Does the 2D point p lie outside the convex polygon P by more than ``margin``?"""
    k = len(P)
    sgn = np.sign(sum(_cross2(P[i], P[(i + 1) % k]) for i in range(k)))
    for i in range(k):
        d = P[(i + 1) % k] - P[i]
        if sgn * _cross2(d, p - P[i]) / max(np.linalg.norm(d), 1e-300) < -margin:
            return True
    return False


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
