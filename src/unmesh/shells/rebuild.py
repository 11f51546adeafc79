"""Local fiber rebuild after a crack (thesis 7.3.2) at the cost of the affected nodes.

:func:`rebuild_near` gives what :func:`unmesh.shells.fracture.rebuild_near` (the plain
reference) gives -- the same topology, fiber state and origins, entry for entry
(``tests/shells/test_speed_paths.py``) -- but touches the whole shell only to copy its
arrays once: the neighbourhoods, umbrella pairs and fibers of the affected nodes are made
as in the reference, their rest and current measures are taken from the new umbrella pairs
of those nodes alone, and the new rows are spliced into the node-ordered arrays
(:mod:`unmesh.shells._rebuild_kernels`), which are then already sorted.

When the crack leaves a node that had neighbours with fewer than
:data:`~unmesh.shells.fracture.MIN_VISIBLE` visible ones, the reference detaches it from
the whole shell: it leaves every neighbour list, umbrella pair and fiber. Those are the
lists, pairs and fibers of the nodes around it (found in one pass over the arrays); their
rows are spliced too, stripped of the detached nodes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh.shells import _fiber_kernels, _rebuild_kernels
from unmesh.shells.energy import _FIELDS, FiberState
from unmesh.shells.forces import arc_gram
from unmesh.shells.fracture import MIN_VISIBLE, CrackSet, FiberMaterial, fracture_candidates
from unmesh.shells.fracture import rebuild_near as rebuild_near_reference
from unmesh.shells.nodes import create_fibers, node_neighborhoods, umbrella_pairs
from unmesh.shells.topology import UMBRELLA_SOFTENING, ShellTopology
from unmesh.shells.topology import csr_entries as _entries

__all__ = ["rebuild_local", "rebuild_near"]


def _row_offsets(keys: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """CSR offsets over ``rows`` (sorted) of entries with (sorted) row ``keys``."""
    return np.searchsorted(keys, np.concatenate([rows, [np.iinfo(np.int64).max]]), side="left").astype(np.int64)


def _splice(old_offsets: np.ndarray, row_of: np.ndarray, new_offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of the spliced CSR and its source runs (:func:`~unmesh.shells._rebuild_kernels.splice_runs`)."""
    out = np.empty(len(old_offsets), dtype=np.int64)
    runs = _rebuild_kernels.splice_runs(old_offsets, row_of, new_offsets, out)
    return out, runs


def _take(runs: np.ndarray, old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """The spliced array: old entries and new ones as the ``runs`` of :func:`_splice` say."""
    total = int(runs[-1, 0] + runs[-1, 2]) if len(runs) else 0
    out = np.empty((total, *old.shape[1:]), dtype=old.dtype)
    if old.ndim == 1:
        _rebuild_kernels.gather_runs(runs, old, np.ascontiguousarray(new, dtype=old.dtype), out)
    else:
        _rebuild_kernels.gather_runs2(runs, old, np.ascontiguousarray(new, dtype=old.dtype).reshape(-1, old.shape[1]),
                                      out)
    return out


def _measure(x: np.ndarray, fibers: np.ndarray, pairs: np.ndarray, pair_offsets: np.ndarray, rows: np.ndarray,
             soft: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """``FiberState.measure`` of ``fibers`` (centred at ``rows``) with the rows' umbrella pairs only."""
    n = len(x)
    s, nrm = np.zeros((n, 3)), np.zeros((n, 3))
    full = np.zeros(n + 1, dtype=np.int64)              # pair offsets of all nodes (other rows empty)
    counts = np.zeros(n, dtype=np.int64)
    counts[rows] = np.diff(pair_offsets)
    np.cumsum(counts, out=full[1:])
    _fiber_kernels.umbrella(np.ascontiguousarray(x), np.ascontiguousarray(pairs), full, s, nrm)
    f = np.ascontiguousarray(fibers)
    length, angle = np.empty(len(f)), np.empty(len(f))
    _fiber_kernels.fiber_measures(np.ascontiguousarray(x), f, np.ascontiguousarray(s[f[:, 1]]),
                            np.ascontiguousarray(soft[f[:, 1]]), arc_gram(samples), length, angle)
    return length, angle


def _crossed(rest: np.ndarray, topology: ShellTopology, rows: np.ndarray, cracks: CrackSet, new: int) -> np.ndarray:
    """(R,) bool: a segment from the node to one of its neighbours crosses one of the last ``new`` cracks."""
    pos, src = _entries(topology.neighbor_offsets, rows)
    hit = cracks.take(slice(-new, None)).blocked(rest[src], rest[topology.neighbors[pos]])
    out = np.zeros(len(rows), dtype=bool)
    out[np.searchsorted(rows, src[hit])] = True
    return out


def _softening_rows(rest: np.ndarray, pairs: np.ndarray, centers: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``umbrella_softening(rest, pairs, centers)[rows]`` for centres among the (sorted) ``rows``."""
    s = np.zeros((len(rows), 3))
    np.add.at(s, np.searchsorted(rows, centers), np.cross(rest[pairs[:, 0]] - rest[centers],
                                                          rest[pairs[:, 1]] - rest[centers]))
    return UMBRELLA_SOFTENING * np.linalg.norm(s, axis=1)


def _stripped(topology: ShellTopology, loose: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """The present neighbours, umbrella pairs and fibers of ``rows`` without the ``loose`` nodes
    (a loose row keeps none): neighbour offsets and indices, pairs, their centres, fibers and
    the fibers' indices."""
    pos, of = _entries(topology.neighbor_offsets, rows)
    nb = topology.neighbors[pos]
    ok = ~loose[nb] & ~loose[of]
    noff, nbr = _row_offsets(of[ok], rows), nb[ok]
    pos, of = _entries(topology.pair_offsets, rows)
    ok = ~loose[topology.pairs[pos]].any(axis=1) & ~loose[of]
    pairs, centers = topology.pairs[pos[ok]], of[ok]
    pos, _ = _entries(topology.fiber_offsets, rows)
    pos = pos[~loose[topology.fibers[pos]].any(axis=1)]
    return noff, nbr, pairs, centers, topology.fibers[pos], pos


def _traces(topology: ShellTopology, gone: np.ndarray) -> np.ndarray:
    """(N,) bool: the ``gone`` nodes and the nodes whose neighbour list, umbrella pairs or fibers hold one."""
    out = gone.copy()
    _rebuild_kernels.touching(topology.fibers, topology.pairs, topology.pair_offsets, gone, out)
    _, of = _entries(topology.neighbor_offsets, np.arange(topology.n_nodes))
    out[of[gone[topology.neighbors]]] = True
    return out


def _union_order(union: np.ndarray, keys_a: np.ndarray, keys_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR offsets over the sorted ``union`` of two row sets, and the order that groups the entries
    ``concatenate([a, b])`` of rows ``keys_a`` (grouped in row order) and ``keys_b`` (likewise) by row."""
    keys = np.concatenate([keys_a, keys_b])
    order = np.argsort(keys, kind="stable")
    return _row_offsets(keys[order], union), order


def _keys(f: np.ndarray, n: int) -> np.ndarray:
    return (f[:, 0] * n + f[:, 1]) * n + f[:, 2]


def rebuild_near(rest: np.ndarray, rest_normals: np.ndarray, topology: ShellTopology, state: FiberState,
                 cracks: CrackSet, affected: np.ndarray, neighbors: int, min_angle: float,
                 fiber_material: FiberMaterial, current: np.ndarray | None = None,
                 samples: int = 4, tree: Any = None, new_cracks: int | None = None,
                 ) -> tuple[ShellTopology, FiberState, np.ndarray]:
    """:func:`unmesh.shells.fracture.rebuild_near` (same arguments and result) in time of the affected nodes.

    With ``new_cracks`` (the number of cracks at the end of ``cracks`` that are new), only
    the affected nodes one of whose neighbour segments crosses a new crack disc are built
    again: the neighbourhood of any other node is the same with or without the new discs
    (its first visible candidates stay visible, hidden ones stay hidden), and so are its
    umbrella pairs, fibers and their rest measures.

    Example
    -------
    >>> from unmesh.shells.nodes import grid_sheet
    >>> x, topo = grid_sheet(6, 6)
    >>> cracks = CrackSet()
    >>> cracks.add([2.5, 2.5, 0], [1.0, 0, 0], 1.5, 14, 0.0)
    >>> mat = lambda f, r: {"stretch_scale": np.ones(len(f)), "bend_scale": np.ones(len(f)),
    ...                     "fracture_stretch": np.full(len(f), np.inf), "fracture_bend": np.full(len(f), np.inf)}
    >>> st = FiberState.at_rest(x, topo)
    >>> args = (x, np.tile([0, 0, 1.0], (36, 1)), topo, st, cracks, np.arange(8, 28), 12, 60.0, mat, x)
    >>> t1, s1, o1 = rebuild_near(*args)
    >>> t2, s2, o2 = rebuild_near_reference(*args)
    >>> bool(np.array_equal(t1.fibers, t2.fibers) and np.array_equal(s1.length_orig, s2.length_orig))
    True
    """
    return rebuild_local(rest, rest_normals, topology, state, cracks, affected, neighbors, min_angle, fiber_material,
                         current, samples, tree, new_cracks)[:3]


def _neighbourhoods(rest: np.ndarray, topology: ShellTopology, cracks: CrackSet, rows: np.ndarray, neighbors: int,
                    tree: Any, new_cracks: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Visible neighbourhoods of the ``rows`` (CSR over the rows): searched again, or, for a row
    with a full list none of whose segments crosses one of the ``new_cracks`` last discs, its
    present list (see :func:`rebuild_local`)."""
    if new_cracks is None or not len(cracks) >= new_cracks > 0:
        return node_neighborhoods(rest, neighbors, cracks.blocked, nodes=rows, tree=tree)
    full = np.diff(topology.neighbor_offsets)[rows] >= min(neighbors, topology.n_nodes - 1)
    search = _crossed(rest, topology, rows, cracks, new_cracks) | ~full
    if search.all():
        return node_neighborhoods(rest, neighbors, cracks.blocked, nodes=rows, tree=tree)
    # the present lists of the others and the new lists of the searched ones, in row order
    soff, snbr = node_neighborhoods(rest, neighbors, cracks.blocked, nodes=rows[search], tree=tree)
    pos, of = _entries(topology.neighbor_offsets, rows)
    local = np.full(len(rows), -1, dtype=np.int64)
    local[search] = np.arange(int(search.sum()))
    noff, src = _splice(_row_offsets(of, rows), local, soff)
    return noff, _take(src, topology.neighbors[pos], snbr)


def rebuild_local(rest: np.ndarray, rest_normals: np.ndarray, topology: ShellTopology, state: FiberState,
                  cracks: CrackSet, affected: np.ndarray, neighbors: int, min_angle: float,
                  fiber_material: FiberMaterial, current: np.ndarray | None = None, samples: int = 4,
                  tree: Any = None, new_cracks: int | None = None,
                  ) -> tuple[ShellTopology, FiberState, np.ndarray, np.ndarray | None]:
    """:func:`rebuild_near`, and the nodes built again (None when the reference rebuild ran: then
    anything may have changed). The arrays of all other nodes are copies of the old ones.

    With ``new_cracks`` (the number of cracks at the end of ``cracks`` that are new), an
    affected node none of whose neighbour segments crosses a new disc keeps its present
    neighbourhood when that is full (``neighbors`` nodes): it is then the search's result as
    it was, none of it taken away since (a detached node leaves the lists it is in), and the
    new discs hide none of its first visible candidates. Only the others are searched again.
    (Its fibers are still made again: fibers dropped before may come back, as in the reference.)
    """
    n = topology.n_nodes
    rows = np.unique(np.asarray(affected, dtype=np.int64))
    if current is None or len(rows) == 0 or n >= 2**21:
        return (*rebuild_near_reference(rest, rest_normals, topology, state, cracks, affected, neighbors, min_angle,
                                        fiber_material, current, samples, tree), None)
    noff, nbr = _neighbourhoods(rest, topology, cracks, rows, neighbors, tree, new_cracks)
    old_counts = np.diff(topology.neighbor_offsets)
    counts = old_counts.copy()
    counts[rows] = np.diff(noff)
    loose = counts < MIN_VISIBLE
    # nodes detached now leave the lists, pairs and fibers of the nodes around them, too
    extra = np.zeros(0, dtype=np.int64)
    if (loose & (old_counts > 0)).any():
        around = _traces(topology, loose & (old_counts > 0))
        around[rows] = False
        extra = np.flatnonzero(around)
    # pairs and fibers of the affected nodes, from their unfiltered neighbourhoods (as the reference)
    pairs, centers = umbrella_pairs(rest, rest_normals, noff, nbr, nodes=rows)
    new = create_fibers(rest, noff, nbr, min_angle, nodes=rows)
    # reuse the state of fibers that existed before (the last of equal old fibers, as a dict would)
    aff_old, _ = _entries(topology.fiber_offsets, rows)
    old_keys = _keys(topology.fibers[aff_old], n)
    order = np.argsort(old_keys, kind="stable")
    sk = old_keys[order]
    new_keys = _keys(new, n)
    at = np.searchsorted(sk, new_keys, side="right") - 1
    hit = (at >= 0) & (sk[np.maximum(at, 0)] == new_keys) if len(sk) else np.zeros(len(new), bool)
    reuse = np.where(hit, aff_old[order][np.maximum(at, 0)] if len(sk) else -1, -1).astype(np.int64)
    if loose.any():                                # detached nodes: no fibers, pairs or neighbours
        good = ~loose[pairs].any(axis=1) & ~loose[centers]
        pairs, centers = pairs[good], centers[good]
        att = ~loose[new].any(axis=1) if len(new) else np.zeros(0, bool)
        new, reuse = new[att], reuse[att]
        entry_row = np.repeat(rows, np.diff(noff))
        ok = ~loose[nbr] & ~loose[entry_row]
        nbr = nbr[ok]
        noff = _row_offsets(entry_row[ok], rows)
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    centers = np.ascontiguousarray(centers, dtype=np.int64)
    poff_rows = _row_offsets(centers, rows)
    soft = topology.soft.copy()
    redo = np.zeros(n, dtype=bool)
    redo[rows] = True
    redo[extra] = True
    redo |= loose
    soft[loose] = 0.0                              # no pairs
    soft[rows] = _softening_rows(rest, pairs, centers, rows)
    # states of the new fibers: the old state where a fiber existed, else the material's
    f = len(new)
    st = {name: np.zeros(f) for name in _FIELDS}
    st["length_orig"][:] = 1.0
    if f:
        have = reuse >= 0
        fresh = np.flatnonzero(~have)
        if len(fresh):                             # per-fiber values: only the fresh fibers need them
            mat = fiber_material(new[fresh], rest)
            for name in ("stretch_scale", "bend_scale", "fracture_stretch", "fracture_bend"):
                st[name][fresh] = mat[name]
        for name in _FIELDS:
            st[name][have] = getattr(state, name)[reuse[have]]
        # rest measures with the new umbrella normals; fresh fibers start unloaded (or torn)
        st["length_orig"][:], st["angle_orig"][:] = _measure(rest, new, pairs, poff_rows, rows, soft, samples)
        fr = np.flatnonzero(~have)
        if len(fr):
            now_l, now_a = _measure(current, new[fr], pairs, poff_rows, rows, soft, samples)
            sub = FiberState._checked(st[name][fr] for name in _FIELDS)
            torn, _ = fracture_candidates(sub, now_l, now_a)
            ok = np.ones(len(fr), bool)
            ok[torn] = False
            st["length_plastic"][fr[ok]] = now_l[ok] - st["length_orig"][fr[ok]]
            st["angle_plastic"][fr[ok]] = now_a[ok] - st["angle_orig"][fr[ok]]
            if not ok.all():
                keep = np.ones(f, bool)
                keep[fr[~ok]] = False
                new, reuse = new[keep], reuse[keep]
                st = {name: arr[keep] for name, arr in st.items()}
    fiber_off = _row_offsets(new[:, 1], rows)
    if len(extra):
        # the rows around detached nodes: their present entries without the loose nodes
        xoff, xnbr, xpairs, xcenters, xfib, xpos = _stripped(topology, loose, extra)
        union = np.union1d(rows, extra)
        noff, o = _union_order(union, np.repeat(rows, np.diff(noff)), np.repeat(extra, np.diff(xoff)))
        nbr = np.concatenate([nbr, xnbr])[o]
        poff_rows, o = _union_order(union, centers, xcenters)
        pairs, centers = np.concatenate([pairs, xpairs])[o], np.concatenate([centers, xcenters])[o]
        fiber_off, o = _union_order(union, new[:, 1], xfib[:, 1])
        new, reuse = np.concatenate([new, xfib])[o], np.concatenate([reuse, xpos])[o]
        st = {name: np.concatenate([arr, getattr(state, name)[xpos]])[o] for name, arr in st.items()}
        rows = union
    # splice the rows into the node-ordered arrays
    row_of = np.full(n, -1, dtype=np.int64)
    row_of[rows] = np.arange(len(rows))
    off, src = _splice(topology.neighbor_offsets, row_of, noff)
    idx = _take(src, topology.neighbors, nbr)
    poff, src = _splice(topology.pair_offsets, row_of, poff_rows)
    out_pairs = _take(src, topology.pairs, pairs)
    out_centers = _take(src, topology.pair_center, centers)
    foff, src = _splice(topology.fiber_offsets, row_of, fiber_off)
    fibers = _take(src, topology.fibers, new)
    merged = FiberState._checked(_take(src, getattr(state, name), st[name]) for name in _FIELDS)
    origin = _take(src, np.arange(len(topology.fibers), dtype=np.int64), reuse)
    # spliced in node order: already grouped, with the offsets of the splice
    topo = ShellTopology(n, off, idx, out_pairs, poff, out_centers, fibers, foff, soft)
    return topo, merged, origin, np.flatnonzero(redo)
