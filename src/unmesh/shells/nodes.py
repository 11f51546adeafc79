"""Simulation nodes, their neighbourhoods and fiber creation (thesis 7.2, 7.2.1).

* :func:`select_nodes` picks simulation nodes among the surfels of a dense cloud with the
  clustering simplification of Pauly et al. 2002 (:mod:`unmesh.surfels`), "yielding a good
  sampling with simulation nodes that adequately represents the surface geometry".
* :func:`node_neighborhoods` gives each node its ``k`` nearest nodes (kd-tree,
  :mod:`unmesh.spatial`), optionally only those *visible* across crack planes (7.3.2).
* :func:`umbrella_pairs` orders each neighbourhood around the rest normal; consecutive
  pairs define the umbrella normal (:mod:`unmesh.shells.topology`).
* :func:`create_fibers` creates one fiber ``(j, i, j')`` per neighbour ``j`` with ``j'`` the
  most opposite neighbour (7.4), drops duplicates and fibers bent by more than
  ``180 - min_angle`` degrees at the centre (at open boundaries no opposite node exists)
  and badly shaped splines: with the centre at t = 1/2, very unequal arms make the end
  tangents swing away from the chord, and their angle (7.10) becomes ill-conditioned;
  fibers whose rest end tangents deviate more than ``max_end_angle`` from the chord are
  dropped (the "pathological cases" 7.2.1 says to avoid; about 4 % of the fibers of a
  clustered sampling, never all fibers of a node in our tests).
* :func:`build_topology` does all of it; :func:`grid_sheet` makes a small flat sheet for
  tests and examples.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points
from unmesh.errors import InputError
from unmesh.shells.fibers import tangents
from unmesh.shells.topology import UMBRELLA_SOFTENING, ShellTopology

__all__ = [
    "DEFAULT_MIN_ANGLE",
    "DEFAULT_NEIGHBORS",
    "NodeCandidates",
    "build_topology",
    "create_fibers",
    "grid_sheet",
    "hide_blocked",
    "node_neighborhoods",
    "select_nodes",
    "umbrella_pairs",
    "umbrella_softening",
]

#: Default neighbourhood size ``|N_i|``.
DEFAULT_NEIGHBORS = 12
#: Default smallest angle (degrees) between the two arms of a fiber at its centre.
DEFAULT_MIN_ANGLE = 120.0
#: Default largest angle (degrees) between a fiber's end tangent and its chord ``x2 - x1``.
DEFAULT_MAX_END_ANGLE = 45.0
#: Shortest fiber arm relative to the longer one (at 1/5 an end tangent of the spline vanishes).
MIN_ARM_RATIO = 1.0 / 3.0
#: Shortest end tangent of a new fiber relative to its centre tangent (for collinear nodes
#: this needs arms within a factor 2 of each other).
MIN_END_TANGENT = 0.5
#: Umbrella pairs spanning a larger angular gap are left out (open boundary sides).
MAX_UMBRELLA_GAP = 0.9 * np.pi

#: A visibility test ``blocked(p, q) -> (M,) bool`` for segments between rest positions.
Blocker = Callable[[np.ndarray, np.ndarray], np.ndarray]


def select_nodes(cloud: Any, count: int) -> np.ndarray:
    """Indices of about ``count`` surfels chosen as simulation nodes (7.2).

    Uses the hierarchical clustering of :mod:`unmesh.surfels` (Pauly et al. 2002) in its
    ``target`` mode (clusters of similar extent, never straddling both sides of a thin
    part) and takes, for each cluster, the surfel closest to its centroid, so nodes lie
    exactly on the surface and carry the input normals.

    Parameters
    ----------
    cloud : SurfelCloud
        Dense input surface.
    count : int
        Number of nodes.

    Returns
    -------
    ndarray (M,) int64
        Sorted surfel indices.

    Raises
    ------
    InputError
        If ``count`` is below 4 or not below the number of surfels.
    """
    from unmesh.surfels import cluster, representatives

    n = len(cloud)
    if int(count) != count or count < 4:
        raise InputError(f"nodes: expected an integer of at least 4, got {count!r}")
    if count >= n:
        raise InputError(f"nodes: expected fewer nodes than surfels ({n}), got {count}")
    labels = cluster(cloud.positions, cloud.normals, target=int(count))
    return np.unique(representatives(cloud.positions, labels)).astype(np.int64)


def _padded(offsets: np.ndarray, indices: np.ndarray) -> np.ndarray:
    counts = np.diff(offsets)
    k = int(counts.max()) if len(counts) else 0
    out = np.full((len(counts), max(k, 1)), -1, dtype=np.int64)
    rows = np.repeat(np.arange(len(counts)), counts)
    cols = np.arange(len(indices)) - offsets[rows]
    out[rows, cols] = indices
    return out


class NodeCandidates:
    """The nearest nodes of rest nodes, each node's list taken from a kd-tree once and kept.

    The rest positions never change, so a node's candidate list does not either; the crack
    events of a tearing shell search the neighbourhoods of the same nodes again and again.
    Pass it as ``tree`` to :func:`node_neighborhoods` (the same result as the tree itself).

    Parameters
    ----------
    rest : ndarray (N, 3)
        Rest positions of all nodes.
    tree : unmesh.spatial.KDTree
        A tree over ``rest``.

    Example
    -------
    >>> from unmesh.spatial import KDTree
    >>> x = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
    >>> NodeCandidates(x, KDTree(x)).nearest(np.array([2]), 2).tolist()
    [[2, 1]]
    """

    def __init__(self, rest: np.ndarray, tree: Any) -> None:
        self.rest = rest
        self.tree = tree
        self._idx = np.zeros((len(rest), 0), dtype=np.int64)
        self._known = np.zeros(len(rest), dtype=bool)

    def nearest(self, nodes: np.ndarray, k: int) -> np.ndarray:
        """(Q, k) int64: the ``k`` nearest nodes of each of ``nodes`` by (distance, index), itself included."""
        if self._idx.shape[1] != k:
            self._idx = np.full((len(self.rest), k), -1, dtype=np.int64)
            self._known[:] = False
        miss = np.unique(nodes[~self._known[nodes]])
        if len(miss):
            self._idx[miss] = self.tree.knn(self.rest[miss], k)[1]
            self._known[miss] = True
        return self._idx[nodes]


def hide_blocked(keep: np.ndarray, a: np.ndarray, b: np.ndarray, idx: np.ndarray, blocked: Blocker,
                 want: int) -> None:
    """Clear in ``keep`` the candidates a crack hides, as far as the first ``want`` visible ones need.

    ``keep`` (R, c) bool marks the valid candidates ``idx[r, j]`` (rows of ``b``) of query
    ``a[r]``, nearest first; ``blocked(p, q)`` is the visibility test (7.3.2). The nearest
    ``want + want // 2 + 2`` columns are tested for every row, the others only for rows with
    fewer than ``want`` visible among them: a row's first ``want`` visible candidates (and
    whether it sees any) are those of testing every candidate, and later columns of the
    other rows stay set (callers keep the first ``want`` set entries).
    """
    rows = np.arange(keep.shape[0])
    head = min(keep.shape[1], want + want // 2 + 2)
    for lo, hi in ((0, head), (head, keep.shape[1])):
        if lo >= hi or not len(rows):
            break
        r_, c_ = np.nonzero(keep[rows, lo:hi])
        if len(r_):
            r_, c_ = rows[r_], c_ + lo
            hit = blocked(a[r_], b[idx[r_, c_]])
            keep[r_[hit], c_[hit]] = False
        rows = rows[keep[rows, :hi].sum(axis=1) < want]


def node_neighborhoods(rest: Any, k: int = DEFAULT_NEIGHBORS, blocked: Blocker | None = None,
                       nodes: Any = None, candidates: int | None = None,
                       tree: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest other nodes of each node, in rest positions, nearest first.

    Parameters
    ----------
    rest : array_like (N, 3)
        Rest positions of all nodes.
    k : int
        Neighbourhood size.
    blocked : callable, optional
        ``blocked(p, q)`` -> (M,) bool, True where the segment p-q crosses a crack plane;
        such neighbours are skipped (visibility criterion of 7.3.2) and farther visible
        nodes are taken instead (up to ``candidates`` are examined).
    nodes : array_like (Q,) int, optional
        Only compute the neighbourhoods of these nodes (default all).
    candidates : int, optional
        Nearest nodes examined when ``blocked`` is given (default ``3 k``).
    tree : unmesh.spatial.KDTree or NodeCandidates, optional
        A tree over ``rest`` to reuse, or the kept candidate lists of :class:`NodeCandidates`
        (the same result as without).

    Returns
    -------
    offsets : ndarray (Q + 1,) int64
    indices : ndarray int64
        CSR neighbour lists sorted by distance.

    Example
    -------
    >>> off, nbr = node_neighborhoods([[0, 0, 0], [1, 0, 0], [3, 0, 0], [7, 0, 0]], k=2)
    >>> nbr.tolist()
    [1, 2, 0, 2, 1, 0, 2, 1]
    """
    from unmesh.spatial import knn

    x = as_points(rest, "rest")
    if int(k) != k or k < 2:
        raise InputError(f"neighbors: expected an integer of at least 2, got {k!r}")
    q = np.arange(len(x)) if nodes is None else as_array(nodes, "nodes", (None,), np.int64)
    want = int(min(k, len(x) - 1))
    cand = want if blocked is None else int(min(candidates or 3 * want, len(x) - 1))
    if len(q) == 0 or want < 1:
        return np.zeros(len(q) + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if isinstance(tree, NodeCandidates):
        idx = tree.nearest(q, cand + 1)
    else:
        _, idx = knn(x, cand + 1, queries=x[q]) if tree is None else tree.knn(x[q], cand + 1)
    idx = idx[:, : cand + 1]
    keep = (idx != q[:, None]) & (idx >= 0)
    if blocked is not None:
        hide_blocked(keep, x[q], x, idx, blocked, want)
    rank = np.cumsum(keep, axis=1)
    keep &= rank <= want
    counts = keep.sum(axis=1)
    offsets = np.zeros(len(q) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets, np.ascontiguousarray(idx[keep], dtype=np.int64)


def umbrella_pairs(rest: Any, normals: Any, offsets: Any, indices: Any,
                   max_gap: float = MAX_UMBRELLA_GAP, nodes: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Consecutive neighbour pairs around each node, counter-clockwise about its normal.

    Parameters
    ----------
    rest : array_like (N, 3)
        Rest positions.
    normals : array_like (N, 3)
        Rest normals (orientation of the shell).
    offsets, indices : array_like
        CSR neighbourhoods of all N nodes (or of ``nodes``).
    max_gap : float
        Pairs spanning a larger angle (radians) are dropped.
    nodes : array_like (Q,) int, optional
        Centre nodes the CSR rows belong to (default all).

    Returns
    -------
    pairs : ndarray (P, 2) int64
        ``(a, b)`` with ``(x_a - x_i) x (x_b - x_i)`` along the normal of ``i``.
    centers : ndarray (P,) int64

    Example
    -------
    >>> x = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]]
    >>> n = np.tile([0.0, 0, 1], (5, 1))
    >>> p, c = umbrella_pairs(x, n, [0, 4, 4, 4, 4, 4], [1, 2, 3, 4])
    >>> p.tolist()
    [[1, 2], [2, 3], [3, 4], [4, 1]]
    """
    xa = as_points(rest, "rest")
    q = np.arange(len(xa)) if nodes is None else as_array(nodes, "nodes", (None,), np.int64)
    nrm = as_points(normals, "normals", length=len(xa))[q]
    off = as_array(offsets, "offsets", (len(q) + 1,), np.int64)
    nbr = as_array(indices, "indices", (None,), np.int64)
    if len(q) == 0:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    pad = _padded(off, nbr)
    valid = pad >= 0
    e = xa[np.where(valid, pad, 0)] - xa[q][:, None, :]
    t1 = np.cross(nrm, np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0, 0]], [[0.0, 1, 0]]))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    ang = np.arctan2(np.einsum("nkc,nc->nk", e, t2), np.einsum("nkc,nc->nk", e, t1))
    ang = np.where(valid, ang, np.inf)
    order = np.argsort(ang, axis=1, kind="stable")
    sp = np.take_along_axis(pad, order, axis=1)
    sa = np.take_along_axis(ang, order, axis=1)
    cnt = valid.sum(axis=1)
    nxt = (np.arange(pad.shape[1])[None, :] + 1) % np.maximum(cnt, 1)[:, None]
    b = np.take_along_axis(sp, nxt, axis=1)
    with np.errstate(invalid="ignore"):
        gap = np.take_along_axis(sa, nxt, axis=1) - sa
    gap = np.where(gap < 0, gap + 2 * np.pi, gap)
    ok = (np.arange(pad.shape[1])[None, :] < cnt[:, None]) & (cnt[:, None] >= 2) & (gap > 1e-9) & (gap < max_gap)
    centers = np.broadcast_to(q[:, None], ok.shape)[ok]
    return np.stack([sp[ok], b[ok]], axis=1).astype(np.int64), centers.astype(np.int64)


def _fiber_partners_reference(x: np.ndarray, q: np.ndarray, off: np.ndarray, nbr: np.ndarray,
                              cos_limit: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Numpy reference of :func:`unmesh.shells._rebuild_kernels.fiber_partners`: centres, lo, hi."""
    pad = _padded(off, nbr)
    valid = pad >= 0
    e = np.where(valid[:, :, None], x[np.where(valid, pad, 0)] - x[q][:, None, :], 0.0)  # (Q, K, 3)
    # score[n, j, j'] = (x_j' - x_j).(x_j - x_i) = e_j'.e_j - |e_j|^2
    dots = np.einsum("nac,nbc->nab", e, e)
    score = dots - np.einsum("naa->na", dots)[:, :, None]
    score = np.where(valid[:, None, :], score, np.inf)
    jp = np.argmin(score, axis=2)
    partner = np.take_along_axis(pad, jp, axis=1)
    norm = np.linalg.norm(e, axis=2)
    cos = np.take_along_axis(dots, jp[:, :, None], axis=2)[:, :, 0] / np.maximum(
        norm * np.take_along_axis(norm, jp, axis=1), 1e-300)
    ok = valid & (partner >= 0) & (partner != pad) & (cos <= cos_limit)
    centers = np.broadcast_to(q[:, None], pad.shape)[ok]
    return centers, np.minimum(pad[ok], partner[ok]), np.maximum(pad[ok], partner[ok])


def create_fibers(rest: Any, offsets: Any, indices: Any, min_angle: float = DEFAULT_MIN_ANGLE,
                  nodes: Any = None, max_end_angle: float = DEFAULT_MAX_END_ANGLE, reference: bool = False) -> np.ndarray:
    """Fibers by the most-opposite-neighbour heuristic (7.4), duplicates removed.

    For node ``i`` and each neighbour ``j``, ``j' = argmin_{j' in N_i} (x_j' - x_j).(x_j - x_i)``;
    the fiber ``(j, i, j')`` is kept when the angle between ``x_j - x_i`` and ``x_j' - x_i``
    is at least ``min_angle`` degrees, both end tangents of the spline lie within
    ``max_end_angle`` degrees of the chord ``x_j' - x_j`` and are at least half as long as
    the centre tangent, and the shorter arm is at least a third of the longer one. Fibers are stored as
    ``(min(j, j'), i, max(j, j'))``.

    Parameters
    ----------
    rest : array_like (N, 3)
        Rest positions (fibers are created on the undeformed shape, 7.3.2).
    offsets, indices : array_like
        CSR neighbourhoods of the nodes listed in ``nodes`` (default: all N, in order).
    min_angle : float
        Smallest accepted angle at the centre, degrees.
    nodes : array_like (Q,) int, optional
        Centre nodes the neighbourhoods belong to.
    max_end_angle : float
        Largest angle between an end tangent and the chord, degrees.
    reference : bool
        Find the partners with numpy instead of the kernel
        (:func:`unmesh.shells._rebuild_kernels.fiber_partners`; the same fibers).

    Returns
    -------
    ndarray (F, 3) int64
        Unique fibers sorted by centre.

    Example
    -------
    >>> x = [[0, 0, 0], [1, 0, 0], [-1, 0.1, 0], [0, 1, 0]]
    >>> create_fibers(x, [0, 3], [1, 2, 3], nodes=[0]).tolist()
    [[1, 0, 2]]
    """
    x = as_points(rest, "rest")
    q = np.arange(len(x)) if nodes is None else as_array(nodes, "nodes", (None,), np.int64)
    off = as_array(offsets, "offsets", (len(q) + 1,), np.int64)
    nbr = as_array(indices, "indices", (None,), np.int64)
    if len(nbr) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    cos_limit = float(np.cos(np.radians(min_angle)) + 1e-12)
    if reference:
        centers, lo, hi = _fiber_partners_reference(x, q, off, nbr, cos_limit)
    else:
        from unmesh.shells import _rebuild_kernels

        cand = np.empty((len(nbr), 3), dtype=np.int64)
        m = _rebuild_kernels.fiber_partners(x, q, off, nbr, cos_limit, cand)
        centers, lo, hi = cand[:m, 0], cand[:m, 1], cand[:m, 2]
    n = len(x)
    if n < 2**21:   # unique rows (centre, lo, hi) in lexicographic order, as int64 keys
        key = np.unique((centers * n + lo) * n + hi)
        fib = np.stack([key // n % n, key // (n * n), key % n], axis=1)
    else:
        fib = np.unique(np.stack([centers, lo, hi], axis=1), axis=0)[:, [1, 0, 2]]
    if len(fib):
        t0, t1, tc = tangents(x[fib[:, 0]], x[fib[:, 1]], x[fib[:, 2]])
        lim = np.cos(np.radians(max_end_angle))
        nc = np.linalg.norm(tc, axis=1)
        n0, n1 = np.linalg.norm(t0, axis=1), np.linalg.norm(t1, axis=1)
        ok0 = (np.einsum("ij,ij->i", t0, tc) >= lim * n0 * nc) & (n0 > MIN_END_TANGENT * nc)
        ok1 = (np.einsum("ij,ij->i", t1, tc) >= lim * n1 * nc) & (n1 > MIN_END_TANGENT * nc)
        arm0 = np.linalg.norm(x[fib[:, 0]] - x[fib[:, 1]], axis=1)
        arm1 = np.linalg.norm(x[fib[:, 2]] - x[fib[:, 1]], axis=1)
        even = np.minimum(arm0, arm1) >= MIN_ARM_RATIO * np.maximum(arm0, arm1)
        fib = fib[ok0 & ok1 & even]
    return np.ascontiguousarray(fib, dtype=np.int64)


def build_topology(rest: Any, normals: Any, neighbors: int = DEFAULT_NEIGHBORS,
                   min_angle: float = DEFAULT_MIN_ANGLE, blocked: Blocker | None = None) -> ShellTopology:
    """Neighbourhoods, umbrella pairs and fibers for nodes at rest positions ``rest``.

    Parameters
    ----------
    rest : array_like (N, 3)
    normals : array_like (N, 3)
        Rest normals (from the input surfels).
    neighbors : int
        Neighbourhood size ``k``.
    min_angle : float
        See :func:`create_fibers`.
    blocked : callable, optional
        Crack visibility test, see :func:`node_neighborhoods`.

    Returns
    -------
    ShellTopology

    Example
    -------
    >>> x, topo = grid_sheet(3, 3)
    >>> topo.fiber_counts().tolist()
    [0, 3, 0, 3, 4, 3, 0, 3, 0]
    """
    x = as_points(rest, "rest")
    off, nbr = node_neighborhoods(x, neighbors, blocked)
    pairs, centers = umbrella_pairs(x, normals, off, nbr)
    fib = create_fibers(x, off, nbr, min_angle)
    return ShellTopology.build(len(x), off, nbr, pairs, centers, fib, umbrella_softening(x, pairs, centers))


def umbrella_softening(rest: np.ndarray, pairs: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """Per-node regularisation ``0.1 |s_i|`` of the umbrella vectors at rest, (N,).

    Example
    -------
    >>> umbrella_softening(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[1, 2]]), np.array([0]))
    array([0.1, 0. , 0. ])
    """
    s = np.zeros_like(rest)
    np.add.at(s, centers, np.cross(rest[pairs[:, 0]] - rest[centers], rest[pairs[:, 1]] - rest[centers]))
    return UMBRELLA_SOFTENING * np.linalg.norm(s, axis=1)


def grid_sheet(nx: int, ny: int, spacing: float = 1.0, jitter: float = 0.0, seed: int = 0,
               neighbors: int = DEFAULT_NEIGHBORS) -> tuple[np.ndarray, ShellTopology]:
    """A flat ``nx`` x ``ny`` sheet of nodes in the plane z = 0 (normal +z) with its topology.

    Parameters
    ----------
    nx, ny : int
        Nodes along x and y.
    spacing : float
        Grid spacing.
    jitter : float
        Random in-plane displacement, as a fraction of the spacing.
    seed : int
        Random seed for the jitter.
    neighbors : int
        Neighbourhood size.

    Returns
    -------
    x : ndarray (nx * ny, 3)
    topology : ShellTopology

    Example
    -------
    >>> x, topo = grid_sheet(4, 3)
    >>> x.shape, len(topo.fibers) > 0
    ((12, 3), True)
    """
    gx, gy = np.meshgrid(np.arange(nx) * spacing, np.arange(ny) * spacing, indexing="ij")
    x = np.stack([gx.ravel(), gy.ravel(), np.zeros(nx * ny)], axis=1)
    if jitter:
        rng = np.random.default_rng(seed)
        x[:, :2] += rng.uniform(-jitter, jitter, size=(len(x), 2)) * spacing
    normals = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    return x, build_topology(x, normals, neighbors)
