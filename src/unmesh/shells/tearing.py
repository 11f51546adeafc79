"""Fracture events of the thin shell (thesis 7.3.2): cracks, local rebuilds, crumbs, surface re-binding.

:class:`Tearing` holds the parts of :class:`~unmesh.shells.simulation.ShellSimulation` that
run when a fiber goes over its fracture threshold (7.24) after a step: degenerate fibers
are dropped, crack discs placed (:func:`~unmesh.shells.fracture.select_cracks`), the
neighbourhoods, umbrella pairs and fibers near them rebuilt
(:func:`~unmesh.shells.rebuild.rebuild_local`), node terms kept continuous, nodes cut off
from every fiber made to follow a neighbour, and the accelerations brought up to date
(:mod:`unmesh.shells.refresh`); the dense surface is re-bound once per rendered frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._threads import threads_for
from unmesh.shells import _fracture_kernels, _rebuild_kernels, _visibility_kernels
from unmesh.shells.fibers import degenerate as degenerate_fibers
from unmesh.shells.forces import node_terms
from unmesh.shells.fracture import fracture_candidates_fast as fracture_candidates
from unmesh.shells.fracture import select_cracks
from unmesh.shells.nodes import NodeCandidates
from unmesh.shells.rebuild import rebuild_local
from unmesh.shells.topology import ShellTopology

__all__ = ["DEGENERATE_RATIO", "Tearing", "warm_up"]

#: With fracture, a fiber whose end tangent falls below this fraction of its centre tangent is torn.
DEGENERATE_RATIO = 0.3


def warm_up() -> None:
    """Load the compiled kernels of a crack event now (from numba's cache) rather than at the first crack."""
    from unmesh.shells import _fracture_kernels, _skinning_kernels

    i1, i2, f1, b1 = np.zeros(1, np.int64), np.zeros((0, 2), np.int64), np.zeros(0), np.zeros(0, np.bool_)
    p3 = np.zeros((0, 3))
    runs = _rebuild_kernels.splice_runs(np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(1, np.int64), i1.copy())
    for arr in (np.zeros(0, np.int64), f1):
        _rebuild_kernels.gather_runs(runs, arr, arr, arr.copy())
    for arr in (i2, np.zeros((0, 3), np.int64)):
        _rebuild_kernels.gather_runs2(runs, arr, arr, arr.copy())
    b0, x1, n1 = np.zeros(0, np.bool_), np.zeros((0, 3)), np.zeros((0, 4))
    _rebuild_kernels.moved_rows(x1, x1, np.zeros((0, 2)), np.zeros((0, 2)), b0, b0.copy())
    _rebuild_kernels.refresh_merge(b0, np.zeros(0, np.int64), np.zeros(0, np.int64), f1, f1, f1.copy(), f1.copy(), x1,
                                   x1, x1.copy(), f1, f1.copy(), f1, f1.copy(), x1, x1.copy(), x1, x1.copy(), n1,
                                   n1.copy())
    _rebuild_kernels.mark_on_fiber(np.zeros((0, 3), np.int64), b0.copy())
    _rebuild_kernels.carry(np.zeros(0, np.int64), f1, f1, f1.copy())
    _fracture_kernels.fiber_excess(f1, f1, f1, f1, f1, f1, f1, f1, np.zeros(0, np.int64), f1.copy())
    _visibility_kernels.discs_near_segments(p3, p3, np.zeros((1, 3)), np.ones(1))
    for kernel in (_visibility_kernels.segments_blocked, _visibility_kernels.segments_blocked_grid):
        kernel(p3, p3, np.zeros((1, 3)), np.ones((1, 3)), np.ones(1), b1.copy())
    _skinning_kernels.within_reach(p3, np.zeros(0, np.int64), f1, 1.0, np.zeros((1, 3)))


class Tearing:
    """Fracture handling of :class:`~unmesh.shells.simulation.ShellSimulation` (a mixin; see the module)."""

    def _drop_degenerate(self) -> bool:
        """Remove fibers whose tangent angle degenerated (:func:`unmesh.shells.fibers.degenerate`).

        A centre node can slide along its fiber, or sideways within the surface, without
        changing the arc length much; near a crack, where it has lost its other fibers, it
        may slide until an end tangent -- as the angle (7.10) sees it, projected onto the
        fiber's normal plane -- vanishes: the angle jumps by pi and its gradient is unbounded
        there. Fibers whose projected end tangent falls below 0.3 of the centre tangent
        count as torn (7.3.2: the crack has cut the material they measured). Tested where the
        angle was evaluated: at the positions of the last force pass (the step's kernel counts
        them there).
        """
        f = self.topology.fibers
        x = self._x_force
        c = f[:, 1]
        bad = degenerate_fibers(x[f[:, 0]], x[c], x[f[:, 2]], self._last.umbrella[c], self.topology.soft[c], DEGENERATE_RATIO)
        if not bad.any():
            return False
        keep = ~bad
        self._keep_fibers(keep)
        return True

    def _keep_fibers(self, keep: np.ndarray) -> None:
        """Keep the fibers where ``keep`` (F,) bool: topology, fiber state and bending angles;
        nodes left without fibers become crumbs."""
        self._carry_angles(self._last.angles, np.flatnonzero(keep))
        t = self.topology
        self.topology = ShellTopology.build(t.n_nodes, t.neighbor_offsets, t.neighbors, t.pairs, t.pair_center,
                                           t.fibers[keep], t.soft, validate=False)
        self.fibers = self.fibers.take(keep)
        self._anchor_crumbs(None)

    def _drop_slivers(self) -> bool:
        """Detach pieces of fewer than ``neighbors`` nodes from their fibers (they become crumbs).

        Crack discs sit at nodes; where the tip steps between two rows of nodes, two nearly
        parallel discs one node apart can cut out a short strip of nodes that still hold each
        other by fibers along the strip. Such a sliver is an artifact of the disc placement,
        not a piece of material (it is narrower than one neighbourhood): like a single node
        cut off from every fiber (:meth:`_anchor_crumbs`) it follows a node of a piece it still
        sees. Pieces holding fixed or kinematic nodes are kept.
        """
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        f = self.topology.fibers
        n = len(self.rest)
        if not len(f):
            return False
        rows, cols = np.concatenate([f[:, 0], f[:, 1]]), np.concatenate([f[:, 1], f[:, 2]])
        _, labels = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False)
        on_fiber = np.zeros(n, bool)
        on_fiber[f.ravel()] = True
        sizes = np.bincount(labels[on_fiber], minlength=labels.max() + 1)
        small = (sizes > 0) & (sizes < self.neighbors)
        small[np.unique(labels[self.fixed])] = False
        if not small.any():
            return False
        keep = ~small[labels[f[:, 1]]]
        self._keep_fibers(keep)
        return True

    def _fracture(self) -> None:
        st = self.fibers
        with threads_for(len(st), key="fracture_scan"):
            over, bad = _fracture_kernels.fracture_scan(self._x_force, self.topology.fibers, self._last.umbrella, self.topology.soft,
                                               self._last.lengths, self._last.angles,
                                               st.rest_length(), st.rest_angle(), st.fracture_stretch,
                                               st.fracture_bend, DEGENERATE_RATIO**2)
        if over == 0 and bad == 0:
            return
        self._fracture_events(bad > 0)

    def _fracture_events(self, degenerate: bool) -> None:
        """Drop degenerate fibers, place cracks at overloaded fibers and rebuild around them (7.3.2).

        On one thread: the kernels of an event work on a few hundred nodes, and on a machine
        shared with other busy processes every parallel region of two threads can wait for a
        time slice (a rebuild on the tearing poster took 63 ms instead of 12).
        """
        with threads_for(0, key="events"):
            self._crack_event(degenerate)

    def _crack_event(self, degenerate: bool) -> None:
        cand, _ = fracture_candidates(self.fibers, self._last.lengths, self._last.angles)
        if degenerate and self._drop_degenerate():
            before = self._last.node_terms
            had = np.ones(self.topology.n_nodes, bool)
            self._keep_node_terms(before, had, np.unique(self.topology.fibers[:, 1]))
            self.acc = self._accelerations()
            cand, _ = fracture_candidates(self.fibers, self._last.lengths, self._last.angles)
        if len(cand) == 0:
            return
        chosen = select_cracks(cand, self.topology, self.rest, self.rest_normals, self.cracks, self.max_cracks)
        if not chosen:
            return
        for node, center, normal, radius in chosen:
            self.cracks.add(center, normal, radius, node, self.time)
        if self.first_crack is None:
            self.first_crack = self.time
        centers = np.stack([c for _, c, _, _ in chosen])
        rmax = max(r for _, _, _, r in chosen)
        _, near = self._rest_tree().radius_neighbors(centers, self._reach + rmax)
        before = self._last.node_terms
        had = np.diff(self.topology.fiber_offsets) > 0
        angles = self._last.angles
        last = {"topology": self.topology, "state": self.fibers, "offsets": self.node_offsets.copy(),
                "result": self._last, "x": getattr(self, "_x_force", None)}
        self.topology, self.fibers, origin, last["touched"] = rebuild_local(
            self.rest, self.rest_normals, self.topology, self.fibers, self.cracks, np.unique(near), self.neighbors,
            self.min_angle, self.material.fiber_material, self.x, self.material.arc_samples, tree=self._node_candidates(),
            new_cracks=len(chosen))
        self._carry_angles(angles, origin)
        rebuilt = np.unique(near)
        self._keep_node_terms(before, had, rebuilt)
        self._anchor_crumbs(None)   # all nodes: a rebuild can strip nodes outside `near` too
        self._reach = max(self._reach, self._neighbor_reach(rebuilt))
        # the dense surface is re-bound once per rendered frame (_update_surface), not per event
        self._pending_cracks.extend(len(self.cracks) - len(chosen) + np.arange(len(chosen)))
        self.acc = self._accelerations_after(last, origin)
        if self._drop_slivers():
            before = self._last.node_terms
            had = np.ones(self.topology.n_nodes, bool)
            self._keep_node_terms(before, had, np.unique(self.topology.fibers[:, 1]))
            self.acc = self._accelerations()

    def _accelerations_after(self, last: dict[str, Any], origin: np.ndarray) -> np.ndarray:
        """:meth:`_accelerations` after a rebuild, from the last force pass and the changed centres
        (:func:`unmesh.shells.refresh.refreshed_forces`); a full pass when that does not apply."""
        from unmesh.shells.refresh import refreshed_forces

        if last["x"] is None or last["result"] is not self._last or not self.fused:
            return self._accelerations()
        m = self.material
        ref = self._reference_angles()
        res = refreshed_forces(self.x, self.topology, self.fibers, self.node_offsets, ref, origin, last, m.ks, m.kb,
                               m.arc_samples)
        if res is None:
            self._resume_angles = ref
            return self._accelerations()
        self._x_force = self.x.copy()
        return self._acc_of(res)

    def _node_candidates(self) -> NodeCandidates:
        """Nearest-node lists of the rest nodes for the neighbourhood searches of the crack events (kept)."""
        if getattr(self, "_candidates", None) is None:
            self._candidates = NodeCandidates(self.rest, self._rest_tree())
        return self._candidates

    def _rest_tree(self) -> Any:
        """KD-tree over the rest node positions (built once; the rest positions never change)."""
        if getattr(self, "_tree", None) is None:
            from unmesh.spatial import KDTree

            self._tree = KDTree(self.rest)
        return self._tree

    def _update_surface(self) -> None:
        """Bind the dense surface to the cracks that appeared and the crumbs that changed since the
        last rendered frame.

        Re-binding (7.3.2 visibility) is local: a surfel farther than the skinning reach plus
        a crack's radius from the crack centre sees all its bound nodes, so its binding is
        the same with or without that crack; likewise a crumb (which the surface does not
        follow: :meth:`SkinnedSurface.exclude_nodes`) changes only bindings that reach it.
        Doing it once per frame for all the frame's cracks and crumbs (with the state at the
        end of the frame) therefore gives the binding a global re-bind gives
        (``tests/shells/test_speed_paths.py``), as :meth:`load_state_dict` does; the
        skinning is used only for the output surface.
        """
        crumbs = self.anchor >= 0
        if not self._pending_cracks and np.array_equal(crumbs, self.surface.excluded):
            return
        with threads_for(0, key="rebind"):     # small parallel regions: one thread (see _fracture_events)
            self._rebind_surface(crumbs)

    def _rebind_surface(self, crumbs: np.ndarray) -> None:
        c = self.cracks
        self.surface.exclude_nodes(crumbs, c.blocked)
        new = np.asarray(self._pending_cracks, dtype=np.int64)
        self._pending_cracks = []
        if not len(new):
            return
        self.surface.rebind_near(c.centers[new], float(c.radii[new].max()), c.blocked, c.take(new).blocked)
        self.surface.add_discontinuities(c.centers[new], c.normals[new], c.radii[new], self.rest_normals[c.nodes[new]],
                                         c.blocked)

    def _anchor_crumbs(self, rows: np.ndarray | None) -> None:
        """Let nodes that the cracks cut off from every fiber follow a neighbouring piece.

        ``rows`` are the nodes to look at (with the crumbs that exist; None: all nodes).

        Such a crumb (a sliver between two nearly parallel crack discs) has no elastic
        forces; left free it would drift off as a separate piece of one node. It follows,
        rigidly translated, the nearest node that lies on a fiber and that it still sees
        (7.3.2 visibility), else the nearest node on a fiber. Fixed nodes are never crumbs.
        """
        self._crumb_cache = None
        on_fiber = np.empty(len(self.rest), dtype=np.bool_)
        _rebuild_kernels.mark_on_fiber(self.topology.fibers, on_fiber)
        self.anchor[on_fiber] = -1                     # a rebuild gave it fibers again
        lost = np.flatnonzero(self.anchor >= 0)
        self.anchor[lost[~on_fiber[self.anchor[lost]]]] = -1   # its anchor lost its fibers: choose again
        rows = np.arange(len(self.rest)) if rows is None else np.union1d(rows, lost)
        crumbs = rows[~on_fiber[rows] & (self.anchor[rows] < 0) & ~self.fixed[rows]]
        if not len(crumbs):
            return
        pool = int(on_fiber.sum())
        if not pool:
            return
        k = int(min(12, pool))
        cand = self._nearest_on_fiber(crumbs, on_fiber, k)          # (C, k) by distance
        src = np.repeat(crumbs, k)
        hidden = self.cracks.blocked(self.rest[src], self.rest[cand.ravel()]).reshape(cand.shape)
        # the nearest visible one; a crumb walled in by cracks on all sides (an island of one
        # node, an artifact of overlapping crack discs) follows its nearest node
        first = np.where((~hidden).any(axis=1), np.argmax(~hidden, axis=1), 0)
        self.anchor[crumbs] = cand[np.arange(len(crumbs)), first]

    def _nearest_on_fiber(self, nodes: np.ndarray, on_fiber: np.ndarray, k: int) -> np.ndarray:
        """(Q, k) int64: the ``k`` nearest nodes on a fiber of each of ``nodes`` (rest positions), sorted
        by (distance, index) -- what a kd-tree over the nodes on fibers gives -- from the tree over
        all nodes, asked for more candidates until ``k`` of them are on fibers."""
        tree, n = self._rest_tree(), len(self.rest)
        out = np.empty((len(nodes), k), dtype=np.int64)
        todo = np.arange(len(nodes))
        m = min(2 * k, n)
        while len(todo):
            _, idx = tree.knn(self.rest[nodes[todo]], m)
            ok = (idx >= 0) & on_fiber[np.maximum(idx, 0)]
            done = (ok.sum(axis=1) >= k) | (m == n)          # with all nodes asked, a pool of >= k
            sel = ok[done] & (np.cumsum(ok[done], axis=1) <= k)
            out[todo[done]] = idx[done][sel].reshape(-1, k)
            todo = todo[~done]
            m = min(2 * m, n)
        return out

    def _follow(self) -> None:
        """Move the crumbs with their anchors (see :meth:`_anchor_crumbs`)."""
        c, a = self._crumbs
        if len(c):
            self.x[c] = self.x[a] + (self.rest[c] - self.rest[a])
            self.v[c] = self.v[a]

    @property
    def _crumbs(self) -> tuple[np.ndarray, np.ndarray]:
        """Crumb nodes and their anchors (cached; :meth:`_anchor_crumbs` and restores refresh it)."""
        cached = getattr(self, "_crumb_cache", None)
        if cached is None or cached[0] is not self.anchor:
            c = np.flatnonzero(self.anchor >= 0)
            cached = self._crumb_cache = (self.anchor, c, np.ascontiguousarray(self.anchor[c]))
        return cached[1], cached[2]

    def pieces(self) -> tuple[int, np.ndarray]:
        """Connected pieces of the fiber graph, crumbs counted with the piece they follow.

        Returns
        -------
        count : int
        labels : ndarray (N,) int64
        """
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        f = self.topology.fibers
        c = np.flatnonzero(self.anchor >= 0)
        rows = np.concatenate([f[:, 0], f[:, 1], c])
        cols = np.concatenate([f[:, 1], f[:, 2], self.anchor[c]])
        n = len(self.rest)
        count, labels = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)),
                                             directed=False)
        return int(count), labels.astype(np.int64)

    def _carry_angles(self, angles: np.ndarray, origin: np.ndarray) -> None:
        """Keep the continuous angle branch of surviving fibers across a topology change."""
        if len(self.fibers) != len(origin):  # origin refers to the fibers after _drop_degenerate's take
            self._resume_angles = angles[origin].copy()
            return
        rest = self.fibers.rest_angle()
        if len(angles):
            out = np.empty(len(origin))
            _rebuild_kernels.carry(np.ascontiguousarray(origin, dtype=np.int64), np.ascontiguousarray(angles,
                                   dtype=np.float64), rest, out)
            rest = out
        self._resume_angles = rest

    def _keep_node_terms(self, before: np.ndarray, had: np.ndarray, rows: np.ndarray) -> None:
        """Offsets that keep each rebuilt node's area and curvature terms continuous.

        Removing the fibers that cross a crack changes the *means* (7.6, 7.9) over a node's
        fibers abruptly (e.g. only the compressed fibers across the tension remain), which
        would inject elastic energy at every crack. The offsets ``(dA_i, dH_i)`` make
        ``A_i - A_i^0 - dA_i`` and ``H_i - H_i^0 - dH_i`` the same just after the rebuild as
        just before; the per-fiber terms are untouched.
        """
        m = self.material
        ref = getattr(self, "_resume_angles", None)
        ref = ref if ref is not None and len(ref) == len(self.topology.fibers) else None
        has = np.diff(self.topology.fiber_offsets) > 0
        r = rows[had[rows] & has[rows]]
        after = node_terms(self.x, self.topology, self.fibers, r, m.arc_samples, ref)   # rows r only
        old_da = before[r, 0] - before[r, 1] - self.node_offsets[r, 0]
        old_dh = before[r, 2] - before[r, 3] - self.node_offsets[r, 1]
        self.node_offsets[r, 0] = after[:, 0] - after[:, 1] - old_da
        self.node_offsets[r, 1] = after[:, 2] - after[:, 3] - old_dh
        gone = rows[~has[rows]]
        self.node_offsets[gone] = 0.0
