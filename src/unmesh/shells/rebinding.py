"""Re-binding the skinned surface to cracks and crumbs (thesis 7.3.2 visibility, 7.4), once per frame.

:class:`Rebinding` holds the parts of :class:`~unmesh.shells.skinning.SkinnedSurface` that
run when the shell tears: binding points again with crack visibility and without the
crumbs (nodes cut off from every fiber), only the points whose binding can change, and
cutting the splat-cover pairs (module notes of :mod:`unmesh.shells.skinning`) that a crack
separates or that share no bound node any more. Every re-binding gives the binding of a
global one (``tests/shells/test_speed_paths.py``, ``tests/shells/test_fracture.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh.shells import _skinning_kernels as _sk
from unmesh.shells.topology import csr_entries, csr_from_groups

__all__ = ["Rebinding"]


def _cover_pairs(bind: np.ndarray, nbr: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(R, m) bool: surfel ``rows[r]`` and its rest neighbour ``nbr[rows[r], a]`` share a bound node
    (and are not the same surfel); :func:`unmesh.shells._skinning_kernels.shared_bound`."""
    out = np.empty((len(rows), nbr.shape[1]), dtype=np.bool_)
    _sk.shared_bound(bind, nbr, np.ascontiguousarray(rows, dtype=np.int64), out)
    return out


def _cover_pairs_reference(bind: np.ndarray, nbr: np.ndarray, rows: np.ndarray, chunk: int = 16384) -> np.ndarray:
    """Numpy reference of :func:`_cover_pairs`, in chunks of rows (an (R, m, K+1, K+1) comparison)."""
    out = np.zeros((len(rows), nbr.shape[1]), dtype=bool)
    for lo in range(0, len(rows), chunk):
        r = rows[lo:lo + chunk]
        mine = bind[r]                                   # (c, K+1)
        theirs = bind[nbr[r]]                            # (c, m, K+1)
        eq = (mine[:, None, :, None] == theirs[:, :, None, :]) & (mine[:, None, :, None] >= 0)
        out[lo:lo + chunk] = eq.any(axis=(2, 3)) & (nbr[r] != r[:, None])
    return out


class _Passive:
    """Arrays of a set of bound passive points (dense surfels or discontinuity surfels), growable."""

    FIELDS = ("points", "normals", "axes", "orient", "colors", "bind", "weights", "plane", "by_normals", "coords", "reach")

    def __init__(self, k: int) -> None:
        self.n = 0
        self.points = np.zeros((0, 3))
        self.normals = np.zeros((0, 3))  # rest surface normals (the facing test of the binding)
        self.axes = np.zeros((0, 2, 3))
        self.orient = np.zeros(0)
        self.colors = np.zeros((0, 3))
        self.bind = np.zeros((0, k + 1), dtype=np.int64)
        self.weights = np.zeros((0, k))
        self.plane = np.zeros((0, 3))
        self.by_normals = np.zeros(0, dtype=np.uint8)  # frames on the node normals (skinning.frame_normals)
        self.coords = np.zeros((0, k, _sk.COORDS))
        self.reach = np.zeros(0)     # distance to the farthest bound node

    def append(self, **arrays: np.ndarray) -> None:
        """Append rows (capacity doubles, so many small appends cost O(total))."""
        add = len(arrays["points"])
        need = self.n + add
        cap = len(self.points)
        if need > cap:
            new_cap = max(need, 2 * cap, 16)
            for name in self.FIELDS:
                old = getattr(self, name)
                grown = np.zeros((new_cap, *old.shape[1:]), dtype=old.dtype)
                grown[:self.n] = old[:self.n]
                setattr(self, name, grown)
        for name in self.FIELDS:
            getattr(self, name)[self.n:need] = arrays[name]
        self.n = need

    def view(self, name: str) -> np.ndarray:
        return getattr(self, name)[:self.n]


class Rebinding:
    """Crack and crumb re-binding of :class:`~unmesh.shells.skinning.SkinnedSurface` (a mixin; see the module)."""

    def _reaches(self, bind: np.ndarray, pts: np.ndarray, cand_dist: np.ndarray | None = None) -> np.ndarray:
        """Distance from each point to its farthest bound node, (S,) (0 without nodes); a point bound
        to fewer than K + 1 nodes (``cand_dist`` (S, c): its candidates' distances) reaches to its
        farthest candidate: a node there that becomes visible or bindable joins its binding."""
        if not len(bind):
            return np.zeros(0)
        d = np.where(bind >= 0, np.linalg.norm(self.node_rest[np.maximum(bind, 0)] - pts[:, None], axis=2), 0)
        out = d.max(axis=1)
        if cand_dist is not None:
            short = bind[:, -1] < 0
            out[short] = np.maximum(out[short], np.where(np.isfinite(cand_dist[short]), cand_dist[short], 0).max(axis=1))
        return out

    def _candidates(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ``3 (K + 1)`` nearest nodes of dense surfels ``rows`` (distances, indices), each kd-tree
        query done once and kept (surfels near a tear are re-bound again as it grows)."""
        cand = int(min(3 * min(self.k + 1, len(self.node_rest)), len(self.node_rest)))
        if getattr(self, "_slot", None) is None:
            self._slot = np.full(self.dense.n, -1, dtype=np.int64)
            self._cand_n = 0                               # rows used of the growing buffers below
            self._cand_d = np.zeros((0, cand))
            self._cand_i = np.zeros((0, cand), dtype=np.int64)
        slot = self._slot[rows]
        miss = rows[slot < 0]
        if len(miss):
            d, i = self.tree.knn(self.dense.points[miss], cand)
            need = self._cand_n + len(miss)
            if need > len(self._cand_i):                   # capacity doubles: appends cost O(total)
                grow = max(need, 2 * len(self._cand_i))
                self._cand_d = np.concatenate([self._cand_d[:self._cand_n], np.zeros((grow - self._cand_n, cand))])
                self._cand_i = np.concatenate([self._cand_i[:self._cand_n],
                                               np.zeros((grow - self._cand_n, cand), dtype=np.int64)])
            self._cand_d[self._cand_n:need], self._cand_i[self._cand_n:need] = d, i
            self._slot[miss] = self._cand_n + np.arange(len(miss))
            self._cand_n = need
            slot = self._slot[rows]
        return self._cand_d[slot], self._cand_i[slot]

    def _rebind(self, part: _Passive, rows: np.ndarray, blocked: Any) -> None:
        pts = part.points[rows]
        axes = part.axes[rows]
        b, w, plane, by_normals, reach = self._bind(pts, part.normals[rows], blocked,
                                                    self._candidates(rows) if part is self.dense else None)
        part.bind[rows], part.weights[rows], part.plane[rows], part.by_normals[rows] = b, w, plane, by_normals
        part.coords[rows] = self._coords(b, w, plane, pts, axes)
        part.reach[rows] = reach
        self._reach = max(self._reach, float(reach.max()))

    def exclude_nodes(self, mask: np.ndarray, blocked: Any) -> int:
        """Bind no point to the nodes of ``mask`` (N,) bool from now on (crumbs: nodes a crack cut off
        from every fiber; they carry no material, and one that follows a node across a crack
        would stretch every splat bound to it across the opening).

        Only the points whose binding can change are bound again (with ``blocked``, the
        visibility test of all cracks): those bound to a newly excluded node, and those within
        their reach (:meth:`_reaches`) of a newly allowed one (it enters only bindings that
        reach it). Returns the number of points bound again.
        """
        mask = np.asarray(mask, dtype=bool)
        changed = np.flatnonzero(mask != self.excluded)
        if not len(changed):
            return 0
        gone = np.zeros(len(mask), dtype=bool)
        gone[changed[mask[changed]]] = True                 # excluded now: only bindings holding them
        back = changed[~mask[changed]]                       # allowed again: bindings that reach them
        self.excluded = mask.copy()
        c = self.node_rest[changed]
        rebound = np.zeros(0, dtype=np.int64)
        for part in (self.dense, self.disc):
            rows = self._near_owners(c, 0.0) if part is self.dense else np.arange(part.n)
            rows = rows[_sk.within_reach(part.points, rows, part.reach, 0.0, c)] if len(rows) else rows
            b = part.bind[rows]
            holds = (gone[np.maximum(b, 0)] & (b >= 0)).any(axis=1)
            if len(back):
                holds |= _sk.within_reach(part.points, rows, part.reach, 0.0, self.node_rest[back])
            rows = rows[holds]
            if len(rows):
                self._rebind(part, rows, blocked)
                rebound = rows if part is self.dense else rebound
        self._cut_cover_pairs(rebound)
        return len(rebound)

    def rebind_near(self, centers: np.ndarray, radius: float, blocked: Any, new_blocked: Any = None) -> int:
        """Bind again, with visibility, the points whose bound nodes the new crack discs hide.

        ``centers`` and ``radius`` (the largest radius) are those of the new discs; ``blocked``
        is the visibility test of all discs, ``new_blocked`` that of the new discs alone
        (default ``blocked``: all discs count as new). Only the surfels owned by nodes near the
        centres are examined (no pass over the whole cloud), and a point only when a centre is
        within its own reach (the distance to its farthest bound node) plus ``radius``:
        segments to its bound nodes are no longer, so farther discs cannot hide them. Of those,
        a point is bound again only when a new disc hides one of its bound nodes: discs only
        hide nodes, so a point that still sees all of them keeps its first ``K + 1`` visible
        candidates, i.e. its binding. Then the splat-cover pairs are cut
        (:meth:`_cut_cover_pairs`). Returns the number of points bound again.
        """
        if len(centers) == 0 or len(self) == 0:
            return 0
        c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        new_blocked = blocked if new_blocked is None else new_blocked
        count = 0
        rows = self._near_owners(c, radius)
        if len(rows):
            rows = np.sort(rows[_sk.within_reach(self.dense.points, rows, self.dense.reach, float(radius), c)])
            hidden = rows[self._hides_bound(self.dense, rows, new_blocked)]
            if len(hidden):
                self._rebind(self.dense, hidden, blocked)
                count += len(hidden)
            self._cut_cover_pairs(hidden, (rows, c, float(radius), new_blocked))
        if self.disc.n:
            rows = np.arange(self.disc.n)
            rows = rows[_sk.within_reach(self.disc.points, rows, self.disc.reach, float(radius), c)]
            rows = rows[self._hides_bound(self.disc, rows, new_blocked)]
            if len(rows):
                self._rebind(self.disc, rows, blocked)
                count += len(rows)
        return count

    def _near_owners(self, centers: np.ndarray, radius: float) -> np.ndarray:
        """Dense surfels that can be within their reach plus ``radius`` of a centre: those owned by
        nodes within ``2 (reach + radius)`` of one (the surfel-to-owner distance is within reach)."""
        _, near = self.tree.radius_neighbors(centers, 2.0 * (self._reach + radius))
        near = np.unique(near)
        return self._owned[csr_entries(self._owned_offsets, near)[0]]      # distinct surfels (each has one owner)

    def _hides_bound(self, part: _Passive, rows: np.ndarray, blocked: Any) -> np.ndarray:
        """(R,) bool: ``blocked`` hides one of the bound nodes of point ``rows[r]`` of ``part``."""
        b = part.bind[rows]
        r_, c_ = np.nonzero(b >= 0)
        out = np.zeros(len(rows), dtype=bool)
        if len(r_):
            hit = blocked(part.points[rows[r_]], self.node_rest[b[r_, c_]])
            out[r_[hit]] = True
        return out

    def _zero_reach(self) -> np.ndarray:
        if len(getattr(self, "_zeros", ())) != self.dense.n:
            self._zeros = np.zeros(self.dense.n)
        return self._zeros

    def _cut_cover_pairs(self, rebound: np.ndarray, new_discs: tuple[Any, ...] | None = None) -> None:
        """Drop the rest-neighbour pairs (module notes) that share no bound node any more (pairs with
        a re-bound end) or that a new disc separates: no splat grows across a crack. Pairs cut
        are never restored. ``new_discs`` = ``(near, centers, radius, new_blocked)``: only pairs
        among the points ``near`` the new discs' ``centers`` can cross one."""
        nbr, scale2 = self._cover_nbr, self._cover_scale2
        if len(rebound):
            if getattr(self, "_cover_rev", None) is None:     # who lists whom (the pairs never change)
                off, order = csr_from_groups(nbr.reshape(-1), self.dense.n)
                self._cover_rev = (off, order // nbr.shape[1])
            off, src = self._cover_rev
            rows = np.unique(np.concatenate([rebound, src[csr_entries(off, rebound)[0]]]))
            keep = _cover_pairs(self.dense.bind, nbr, rows) & (scale2[rows] > 0)
            scale2[rows] = np.where(keep, scale2[rows], 0.0)
        if new_discs is None:
            return
        near, centers, radius, new_blocked = new_discs
        if getattr(self, "_cover_len", None) is None:          # longest pair that counts
            pts = self.dense.points[:self.dense.n]
            live = scale2 > 0
            self._cover_len = float(np.linalg.norm(pts[nbr[live]] - np.repeat(pts, live.sum(axis=1), axis=0),
                                                   axis=1).max()) if live.any() else 0.0
        rows = near[_sk.within_reach(self.dense.points, near, self._zero_reach(), radius + self._cover_len, centers)]
        r_, c_ = np.nonzero(scale2[rows] > 0)
        if len(r_):
            pts = self.dense.points
            hit = new_blocked(pts[rows[r_]], pts[nbr[rows[r_], c_]])
            scale2[rows[r_[hit]], c_[hit]] = 0.0
