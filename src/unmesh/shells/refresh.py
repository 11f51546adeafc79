"""Elastic forces after a local topology change (a crack, 7.3.2) from the forces of the last pass.

The elastic force is a sum over centre nodes of the contributions of their umbrella and
fibers (7.16). After a rebuild only the contributions of the centres that changed -- their
fibers, fiber states, umbrella pairs, regularisation or node-term offsets -- and of the
centres touching a node that moved since the last force pass (a collider pushed it, or it
is a crumb that followed its anchor) differ, so::

    F_new(x) = F_last - sum_{c in D} f_c(old arrays, x_last) + sum_{c in D} f_c(new arrays, x)

with both sums from force passes restricted to those centres ``D``
(:func:`unmesh.shells._force_kernels.force_chunks` with a mask). The fiber measures, normals and
node terms of the other centres are carried over. The result is that of a full force pass
up to round-off (``tests/shells/test_speed_paths.py``); :func:`refreshed_forces` returns
None when too much changed for this to pay.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._threads import threads_for
from unmesh.shells import _force_kernels, _rebuild_kernels
from unmesh.shells.energy import FiberState
from unmesh.shells.forces import FORCE_CHUNKS, ForceResult, arc_gram
from unmesh.shells.topology import ShellTopology

__all__ = ["refreshed_forces"]

#: Above this fraction of changed centres a full force pass is as cheap.
MAX_CHANGED = 0.25


def _masked_pass(x: np.ndarray, t: ShellTopology, st: FiberState, ks: float, kb: float, samples: int,
                 ref: np.ndarray, offsets: np.ndarray, only: np.ndarray) -> ForceResult:
    n, nf = t.n_nodes, len(t.fibers)
    out = ForceResult(np.empty((n, 3)), np.empty(n), np.empty(n), np.empty(nf), np.empty(nf), np.empty((n, 3)),
                      np.empty((n, 3)), np.empty((n, 4)))
    counts = np.diff(t.fiber_offsets)
    cap = int(counts.max()) if n else 0
    with threads_for(int(counts[only].sum()), key="refresh"):
        _force_kernels.force_chunks(FORCE_CHUNKS, np.ascontiguousarray(x, dtype=np.float64), t.pairs, t.pair_offsets[:-1],
                              np.diff(t.pair_offsets), t.soft, t.fibers, t.fiber_offsets[:-1], counts, st.length_orig,
                              st.length_plastic, st.angle_orig, st.angle_plastic, st.stretch_scale, st.bend_scale,
                              float(ks), float(kb), arc_gram(int(samples)), np.ascontiguousarray(ref, dtype=np.float64),
                              np.ascontiguousarray(offsets, dtype=np.float64), cap, np.empty((FORCE_CHUNKS, n, 3)),
                              out.forces, out.lengths, out.angles, out.umbrella, out.normals, out.node_terms,
                              out.stretch_energy, out.bend_energy, only, True)
    return out


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def refreshed_forces(x: np.ndarray, topology: ShellTopology, state: FiberState, offsets: np.ndarray,
                     reference: np.ndarray, origin: np.ndarray, old: dict[str, Any], ks: float, kb: float,
                     samples: int) -> ForceResult | None:
    """The :class:`~unmesh.shells.forces.ForceResult` of ``elastic_forces(x, topology, state, ks, kb, samples,
    reference, offsets)`` from the last pass before a topology change.

    Parameters
    ----------
    x : ndarray (N, 3)
        Current positions.
    topology, state, offsets, reference
        The new connectivity, fiber state, node-term offsets and angle references.
    origin : ndarray (F,) int64
        Index of every new fiber before the change (-1: new fiber).
    old : dict
        ``topology``, ``state``, ``offsets`` (copies of the arrays before the change),
        ``result`` (the last ForceResult), ``x`` (the positions it was evaluated at) and
        optionally ``touched``, the nodes whose fibers, pairs and regularisation were built
        again (all others unchanged; None or absent: compare everything).
    ks, kb, samples
        As for :func:`~unmesh.shells.forces.elastic_forces`.

    Returns
    -------
    ForceResult or None
        None when more than :data:`MAX_CHANGED` of the centres changed.
    """
    ot, ost, last = old["topology"], old["state"], old["result"]
    n = topology.n_nodes
    if len(origin) != len(topology.fibers) or len(last.angles) != len(ot.fibers) or len(old["x"]) != n:
        return None
    only = np.zeros(n, dtype=np.bool_)
    touched = old.get("touched")
    if touched is not None:     # only these nodes were built again, the other arrays are copies
        only[touched] = True
        moved = np.empty(n, dtype=np.bool_)
        if _rebuild_kernels.moved_rows(_f64(x), _f64(old["x"]), _f64(offsets), _f64(old["offsets"]), moved, only):
            _rebuild_kernels.touching(topology.fibers, topology.pairs, topology.pair_offsets, moved, only)
    else:
        moved = (x != old["x"]).any(axis=1)
        forces_of = ("length_orig", "length_plastic", "angle_orig", "angle_plastic", "stretch_scale", "bend_scale")
        _rebuild_kernels.changed_centres(ot.fiber_offsets, ot.fibers, ot.pair_offsets, ot.pairs, ot.soft,
                                         old["offsets"], *(getattr(ost, f) for f in forces_of), topology.fiber_offsets,
                                         topology.fibers, topology.pair_offsets, topology.pairs, topology.soft,
                                         np.ascontiguousarray(offsets, dtype=np.float64),
                                         *(getattr(state, f) for f in forces_of), moved, only)
    if only.sum() > MAX_CHANGED * n:
        return None
    if not only.any():
        keep = np.maximum(origin, 0)
        return ForceResult(last.forces.copy(), last.stretch_energy.copy(), last.bend_energy.copy(),
                           last.lengths[keep], last.angles[keep], last.normals.copy(), last.umbrella.copy(),
                           last.node_terms.copy())
    before = _masked_pass(old["x"], ot, ost, ks, kb, samples, last.angles, old["offsets"], only)
    new = _masked_pass(x, topology, state, ks, kb, samples, reference, offsets, only)
    # F_last - F_before + F_new; the listed centres' values from the new pass, the others' from the last
    _rebuild_kernels.refresh_merge(only, topology.fibers[:, 1], origin, last.lengths, last.angles, new.lengths,
                                   new.angles, last.forces, before.forces, new.forces, last.stretch_energy,
                                   new.stretch_energy, last.bend_energy, new.bend_energy, last.normals, new.normals,
                                   last.umbrella, new.umbrella, last.node_terms, new.node_terms)
    return new
