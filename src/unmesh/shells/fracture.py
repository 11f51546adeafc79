"""Fracture: crack planes, visibility-aware neighbourhoods and fiber rebuild (thesis 7.3.2).

A crack starts at a fiber whose stretch or bend exceeds its threshold (7.24)::

    l / l^0 - 1 > gamma_s      or      |theta - theta^0| > gamma_b

(the printed ``gamma_s < l/l^0`` is read as a strain, matching the thresholds of Appendix
F.1: 0.02 and 0.04). A small disc, the *crack plane*, is placed at the fiber's centre node;
its normal is the fiber's tangent there and its radius the mean node distance in that
neighbourhood (we average over the first ring, the 6 nearest nodes, so that the disc does
not grow with the neighbourhood size ``k``). Cracks live in rest (material) coordinates, so they move with the material.

The neighbourhoods of all nodes that could reach across the new disc are recomputed so
that only nodes *visible* from each other (the segment between them does not cross any
crack disc) are neighbours, and their fibers are created again from the original node
positions (7.4) -- this cuts every fiber crossing a crack and resamples the crack's edges
(Figure 7.7). Fibers that existed before keep their plastic state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh.shells import _fracture_kernels, _visibility_kernels
from unmesh.shells.energy import FiberState
from unmesh.shells.nodes import create_fibers, node_neighborhoods, umbrella_pairs, umbrella_softening
from unmesh.shells.topology import ShellTopology, csr_from_groups

__all__ = ["CrackSet", "fracture_candidates", "fracture_candidates_fast", "rebuild_near", "select_cracks"]

#: The crack radius is the mean distance to this many nearest neighbours (the first ring).
CRACK_RING = 6
#: Skip crack candidates right beside an existing crack face.
BESIDE_RULE = False
#: A new crack whose normal is within this cosine of a crack it lies near continues that crack's
#: plane (:func:`select_cracks`); 1 disables it.
CONTINUE_COS = 0.6
#: "Near": the node lies within this many radii of the existing crack's centre.
CONTINUE_REACH = 2.5

#: A node that sees fewer neighbours than this after a crack is detached (loses all fibers).
MIN_VISIBLE = 3

#: Assigns materials to new fibers: ``fn(fibers (F,3), rest (N,3)) -> dict of (F,) arrays``.
FiberMaterial = Callable[[np.ndarray, np.ndarray], dict[str, np.ndarray]]


@dataclass
class CrackSet:
    """All crack discs of a shell, in rest coordinates.

    Attributes
    ----------
    centers, normals : ndarray (C, 3)
    radii : ndarray (C,)
    nodes : ndarray (C,) int64
        Node at the centre of each crack.
    times : ndarray (C,)
        Simulated time at which each crack appeared.

    Example
    -------
    >>> cracks = CrackSet()
    >>> cracks.add([0.0, 0, 0], [1.0, 0, 0], 1.0, node=0, time=0.0)
    >>> cracks.blocked(np.array([[-0.5, 0, 0], [-0.5, 0, 0]]), np.array([[0.5, 0, 0], [-0.1, 2, 0]])).tolist()
    [True, False]
    """

    centers: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    radii: np.ndarray = field(default_factory=lambda: np.zeros(0))
    nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.radii)

    def add(self, center: object, normal: object, radius: float, node: int, time: float) -> None:
        """Append one crack disc (``normal`` is normalised)."""
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        self.centers = np.vstack([self.centers, np.asarray(center, dtype=np.float64)[None]])
        self.normals = np.vstack([self.normals, n[None]])
        self.radii = np.append(self.radii, float(radius))
        self.nodes = np.append(self.nodes, np.int64(node))
        self.times = np.append(self.times, float(time))

    def take(self, index: np.ndarray | slice) -> CrackSet:
        """The cracks ``index`` (indices or a slice) as a set of their own (e.g. the newest ones)."""
        return CrackSet(self.centers[index], self.normals[index], self.radii[index], self.nodes[index],
                        self.times[index])

    def blocked(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(M,) bool: True where segment ``p[m]``-``q[m]`` (rest coordinates) crosses a crack disc."""
        out = np.zeros(len(p), dtype=np.bool_)
        if len(self) and len(p):
            p = np.ascontiguousarray(p, dtype=np.float64)
            q = np.ascontiguousarray(q, dtype=np.float64)
            # only discs that reach the segments' bounding box can block one (the kernel's own test)
            near = _visibility_kernels.discs_near_segments(p, q, self.centers, self.radii)
            if len(near):
                # the grid pays for many discs, or for a few dozen discs and many segments
                grid = len(near) > 48 or (len(near) > 8 and len(p) >= 4096)
                kernel = _visibility_kernels.segments_blocked_grid if grid else _visibility_kernels.segments_blocked
                kernel(p, q, np.ascontiguousarray(self.centers[near]), np.ascontiguousarray(self.normals[near]),
                       np.ascontiguousarray(self.radii[near]), out)
        return out

    def as_dict(self) -> dict[str, np.ndarray]:
        """Arrays for checkpoints."""
        return {"centers": self.centers, "normals": self.normals, "radii": self.radii, "nodes": self.nodes,
                "times": self.times}


def fracture_candidates(state: FiberState, lengths: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fibers over a fracture threshold (7.24), most overloaded first.

    Parameters
    ----------
    state : FiberState
    lengths, angles : ndarray (F,)
        Current ``l~`` and ``theta``.

    Returns
    -------
    index : ndarray (K,) int64
    excess : ndarray (K,)
        ``max(strain / gamma_s, |dtheta| / gamma_b)`` (> 1).

    Example
    -------
    >>> s = FiberState.uniform([1.0, 1.0, 1.0], [0.0] * 3, fracture_stretch=0.1)
    >>> fracture_candidates(s, np.array([1.05, 1.2, 1.3]), np.zeros(3))
    (array([2, 1]), array([3., 2.]))
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        strain = lengths / state.rest_length() - 1.0
        es = np.where(np.isfinite(state.fracture_stretch), strain / state.fracture_stretch, 0.0)
        eb = np.where(np.isfinite(state.fracture_bend), np.abs(angles - state.rest_angle()) / state.fracture_bend, 0.0)
    excess = np.maximum(np.nan_to_num(es, nan=0.0), np.nan_to_num(eb, nan=0.0))
    idx = np.flatnonzero(excess > 1.0)
    order = idx[np.argsort(-excess[idx], kind="stable")]
    return order.astype(np.int64), excess[order]


def fracture_candidates_fast(state: FiberState, lengths: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fracture_candidates` in one kernel pass (same result; used after every over-threshold step).

    Example
    -------
    >>> s = FiberState.uniform([1.0, 1.0, 1.0], [0.0] * 3, fracture_stretch=0.1)
    >>> fracture_candidates_fast(s, np.array([1.05, 1.2, 1.3]), np.zeros(3))
    (array([2, 1]), array([3., 2.]))
    """
    idx = np.empty(len(lengths), dtype=np.int64)
    exc = np.empty(len(lengths))
    m = _fracture_kernels.fiber_excess(np.ascontiguousarray(lengths, dtype=np.float64), np.ascontiguousarray(angles, dtype=np.float64),
                              state.length_orig, state.length_plastic, state.angle_orig, state.angle_plastic,
                              state.fracture_stretch, state.fracture_bend, idx, exc)
    order = np.argsort(-exc[:m], kind="stable")
    return idx[:m][order], exc[:m][order]


def select_cracks(candidates: np.ndarray, topology: ShellTopology, rest: np.ndarray, rest_normals: np.ndarray,
                  cracks: CrackSet, max_new: int = 8) -> list[tuple[int, np.ndarray, np.ndarray, float]]:
    """Choose crack discs for the most overloaded fibers, at least two disc radii apart.

    Returns
    -------
    list of (node, center, normal, radius)
        The crack normal is the fiber's rest tangent at its centre, made perpendicular to
        the rest surface normal; a candidate is skipped when an existing crack at the same
        node has almost the same normal, or when its node lies beside the face of an
        existing crack (between a quarter and two radii from its plane, within its disc;
        ``BESIDE_RULE``, off). A disc near a nearly parallel crack continues that crack's
        plane when it still cuts the fiber (:func:`_continue_crack`); it is skipped when that
        disc exists already.
    """
    out: list[tuple[int, np.ndarray, np.ndarray, float]] = []
    f = topology.fibers
    for k in candidates:
        if len(out) >= max_new:
            break
        j1, i, j2 = f[k]
        t = rest[j2] - rest[j1]
        nrm = rest_normals[i]
        t = t - (t @ nrm) * nrm
        tl = np.linalg.norm(t)
        if not tl > 0:
            continue
        t /= tl
        nb = topology.neighborhood(int(i))[:CRACK_RING]  # nearest first
        radius = float(np.linalg.norm(rest[nb] - rest[i], axis=1).mean()) if len(nb) else float(
            np.linalg.norm(rest[j2] - rest[j1]) / 2)
        if len(cracks):
            same = (cracks.nodes == i) & (np.abs(cracks.normals @ t) > 0.9)
            # a node right beside an existing crack face (not ahead of its edge) starts no new
            # crack: two parallel discs one node apart would cut out a sliver of loose nodes
            d = rest[i] - cracks.centers
            off = np.abs(np.einsum("ij,ij->i", d, cracks.normals))
            lateral = np.linalg.norm(d - off[:, None] * cracks.normals, axis=1)
            beside = (off > 0.25 * cracks.radii) & (off < 2.0 * cracks.radii) & (lateral < 0.75 * cracks.radii)
            if same.any() or (BESIDE_RULE and beside.any()):
                continue
        center = rest[i].copy()
        if len(cracks) and CONTINUE_COS < 1.0:
            c2, t2 = _continue_crack(center, t, cracks)
            # the continued disc must cut the overloaded fiber (else the thesis' disc at its node)
            if c2 is not center and CrackSet(c2[None], t2[None], np.array([radius]), np.array([i]),
                                             np.zeros(1)).blocked(rest[[j1, i]], rest[[i, j2]]).any():
                if _duplicate(c2, t2, radius, cracks):
                    continue
                center, t = c2, t2
        if any(np.linalg.norm(center - c) < 2 * max(radius, r) for _, c, _, r in out):
            continue
        out.append((int(i), center, t, radius))
    return out


def _duplicate(center: np.ndarray, normal: np.ndarray, radius: float, cracks: CrackSet) -> bool:
    """True when an existing disc has (almost) this centre and plane."""
    close = np.linalg.norm(cracks.centers - center, axis=1) < 0.25 * radius
    return bool((close & (np.abs(cracks.normals @ normal) > 0.9)).any())


def _continue_crack(center: np.ndarray, normal: np.ndarray, cracks: CrackSet) -> tuple[np.ndarray, np.ndarray]:
    """Centre and normal of a new crack disc that continues the nearest existing crack it extends.

    A crack is a surface; its discs sit at nodes, so where the tip steps from one row of
    nodes to the next, a new disc parallel to the last one but one node beside it leaves the
    nodes between the two planes connected to both sides (a sliver bridging the tear, and
    the halves never separate). A new disc whose node lies within ``CONTINUE_REACH`` radii of
    an existing crack with a normal within ``arccos(CONTINUE_COS)`` of its own is therefore
    moved into that crack's plane (the node's projection onto it) and takes its normal.

    Example
    -------
    >>> c = CrackSet()
    >>> c.add([0.0, 0, 0], [1.0, 0, 0], 1.0, node=0, time=0.0)
    >>> p, n = _continue_crack(np.array([0.3, -1.1, 0]), np.array([0.8, 0.6, 0]), c)
    >>> p.tolist(), n.tolist()
    ([0.0, -1.1, 0.0], [1.0, 0.0, 0.0])
    """
    d = center - cracks.centers
    dist = np.linalg.norm(d, axis=1)
    cos = cracks.normals @ normal
    near = (dist < CONTINUE_REACH * cracks.radii) & (np.abs(cos) > CONTINUE_COS)
    if not near.any():
        return center, normal
    k = int(np.flatnonzero(near)[np.argmin(dist[near])])
    n = cracks.normals[k] * np.sign(cos[k])
    return center - (d[k] @ n) * n, n.copy()


def _replace_rows(offsets: np.ndarray, values: np.ndarray, rows: np.ndarray, new_offsets: np.ndarray,
                  new_values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR with the listed rows replaced by new contents (rows given in ascending order)."""
    n = len(offsets) - 1
    counts = np.diff(offsets).copy()
    counts[rows] = np.diff(new_offsets)
    out_off = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=out_off[1:])
    out = np.empty(out_off[-1], dtype=values.dtype)
    keep = np.ones(n, dtype=bool)
    keep[rows] = False
    old_rows = np.repeat(np.arange(n), np.diff(offsets))
    mask = keep[old_rows]
    pos_old = out_off[old_rows[mask]] + (np.arange(len(values))[mask] - offsets[old_rows[mask]])
    out[pos_old] = values[mask]
    new_rows = np.repeat(rows, np.diff(new_offsets))
    pos_new = out_off[new_rows] + (np.arange(len(new_values)) - new_offsets[np.repeat(np.arange(len(rows)),
                                                                                     np.diff(new_offsets))])
    out[pos_new] = new_values
    return out_off, out


def rebuild_near(rest: np.ndarray, rest_normals: np.ndarray, topology: ShellTopology, state: FiberState,
                 cracks: CrackSet, affected: np.ndarray, neighbors: int, min_angle: float,
                 fiber_material: FiberMaterial, current: np.ndarray | None = None,
                 samples: int = 4, tree: Any = None) -> tuple[ShellTopology, FiberState, np.ndarray]:
    """Recompute neighbourhoods, umbrella pairs and fibers of the ``affected`` nodes with visibility.

    Parameters
    ----------
    rest, rest_normals : ndarray (N, 3)
        Original node positions and normals (fibers are initialised there, 7.3.2).
    topology, state : ShellTopology, FiberState
        Current connectivity and fiber state.
    cracks : CrackSet
        All cracks, including the new ones.
    affected : ndarray (A,) int64
        Nodes whose neighbourhoods may cross a new crack.
    neighbors, min_angle : int, float
        As for :func:`unmesh.shells.nodes.build_topology`.
    fiber_material : callable
        Material of new fibers (stiffness scales and fracture thresholds).
    current : ndarray (N, 3), optional
        Current node positions. New fibers (not present before) that would already be
        over their fracture threshold here are not created: they would join material that
        has torn apart around the edge of a crack disc, and break again at once. The other
        new fibers keep the original shape as ``l_orig``, ``theta_orig`` but start unloaded:
        their current deviation from it is stored as plastic part (7.19). (The thesis
        starts them from the original positions, i.e. loaded; in a stretched sheet every
        rebuild then adds elastic energy, and in our tests tears shattered.)
    samples : int
        Arc-length samples (B.4).
    tree : unmesh.spatial.KDTree, optional
        Tree over ``rest`` to reuse for the neighbour queries (same result).

    Returns
    -------
    (ShellTopology, FiberState, ndarray)
        Fibers sorted by centre; fibers present before keep their plastic state and
        thresholds, rest angles of the affected centres are measured again. The array
        (F,) int64 gives each fiber's index before the rebuild, -1 for new fibers.
    """
    rows = np.unique(np.asarray(affected, dtype=np.int64))
    noff, nbr = node_neighborhoods(rest, neighbors, cracks.blocked, nodes=rows, tree=tree)
    off, idx = _replace_rows(topology.neighbor_offsets, topology.neighbors, rows, noff, nbr)
    # umbrella pairs of the affected nodes (computed on all nodes' CSR, kept for the rows)
    new_pairs, new_centers = umbrella_pairs(rest, rest_normals, noff, nbr, nodes=rows)
    is_aff = np.zeros(topology.n_nodes, dtype=bool)
    is_aff[rows] = True
    keep_pairs = ~is_aff[topology.pair_center]
    pairs = np.concatenate([topology.pairs[keep_pairs], new_pairs])
    centers = np.concatenate([topology.pair_center[keep_pairs], new_centers])
    # fibers: drop those centred at affected nodes, create them again
    old = topology.fibers
    keep = ~is_aff[old[:, 1]]
    new = create_fibers(rest, noff, nbr, min_angle, nodes=rows)
    aff_old = np.flatnonzero(~keep)
    key_old = {tuple(r): int(k) for k, r in zip(aff_old, old[aff_old].tolist(), strict=True)}
    reuse = np.array([key_old.get(tuple(r), -1) for r in new.tolist()], dtype=np.int64)
    kept_state = state.take(keep)
    fresh = FiberState.uniform(np.ones(len(new)), np.zeros(len(new)))
    if len(new):
        mat = fiber_material(new, rest)
        fresh = FiberState(np.ones(len(new)), np.zeros(len(new)), np.zeros(len(new)), np.zeros(len(new)),
                           mat["stretch_scale"], mat["bend_scale"], mat["fracture_stretch"], mat["fracture_bend"])
        have = reuse >= 0
        if have.any():
            fresh_old = state.take(reuse[have])
            for name, arr in fresh_old.as_dict().items():
                getattr(fresh, name)[have] = arr
    fibers = np.concatenate([old[keep], new])
    merged = FiberState.concatenate([kept_state, fresh])
    # nodes left with fewer than MIN_VISIBLE neighbours hang on by a fiber end or two: such
    # near-detached crumbs give very stiff local modes, so they are detached completely
    counts = np.diff(off)
    loose = counts < MIN_VISIBLE
    if loose.any():
        attached = ~loose[fibers].any(axis=1)
        fibers, merged = fibers[attached], merged.take(attached)
        fresh_flag = np.concatenate([np.zeros(int(keep.sum()), bool), np.ones(len(new), bool)])[attached]
    else:
        fresh_flag = np.concatenate([np.zeros(int(keep.sum()), bool), np.ones(len(new), bool)])
    reuse_full = np.concatenate([np.zeros(int(keep.sum()), np.int64), reuse])
    origin = np.concatenate([np.flatnonzero(keep), reuse]).astype(np.int64)
    if loose.any():
        reuse_full = reuse_full[attached]
        origin = origin[attached]
    _, order = csr_from_groups(fibers[:, 1], topology.n_nodes)   # stable: as argsort(kind="stable")
    fibers, merged, origin = fibers[order], merged.take(order), origin[order]
    if loose.any():
        # a detached node is nobody's neighbour any more (its motion must not steer the
        # umbrella normals of the nodes around it)
        rows_of = np.repeat(np.arange(topology.n_nodes), np.diff(off))
        ok = ~loose[idx] & ~loose[rows_of]
        off = np.zeros_like(off)
        np.cumsum(np.bincount(rows_of[ok], minlength=topology.n_nodes), out=off[1:])
        idx = idx[ok]
        good = ~loose[pairs].any(axis=1) & ~loose[centers]
        pairs, centers = pairs[good], centers[good]
    soft = topology.soft.copy()
    redo_soft = np.zeros(topology.n_nodes, bool)
    redo_soft[rows] = True
    redo_soft |= loose
    sel = redo_soft[centers]
    fresh_soft = umbrella_softening(rest, pairs[sel], centers[sel])
    soft[redo_soft] = fresh_soft[redo_soft]
    topo = ShellTopology.build(topology.n_nodes, off, idx, pairs, centers, fibers, soft, validate=False)
    # rest measures of the fibers at affected centres (new fibers, and new umbrella normals)
    redo = np.flatnonzero(is_aff[topo.fibers[:, 1]])
    merged.length_orig[redo], merged.angle_orig[redo] = FiberState.measure(rest, topo, samples, redo)
    if current is not None and len(new):
        fresh_mask = (fresh_flag & (reuse_full < 0))[order]
        fr = np.flatnonzero(fresh_mask)
        now_l, now_a = FiberState.measure(current, topo, samples, fr)
        sub = merged.take(fr)
        torn, _ = fracture_candidates(sub, now_l, now_a)
        drop = np.zeros(len(fibers), bool)
        drop[fr[torn]] = True
        # new fibers start unloaded: the original shape stays in l_orig / theta_orig, the
        # current deviation from it becomes their plastic part (7.19)
        ok = ~drop[fr]
        merged.length_plastic[fr[ok]] = now_l[ok] - merged.length_orig[fr[ok]]
        merged.angle_plastic[fr[ok]] = now_a[ok] - merged.angle_orig[fr[ok]]
        if drop.any():
            fibers, merged, origin = fibers[~drop], merged.take(~drop), origin[~drop]
            topo = ShellTopology.build(topology.n_nodes, off, idx, pairs, centers, fibers, soft, validate=False)
    return topo, merged, origin
