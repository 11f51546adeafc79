"""Elastic forces of a fiber-sampled shell with numba kernels (thesis 7.2.2, eqs. 7.12-7.17).

Same energy and forces as :func:`unmesh.shells.energy.elastic_forces_reference`, computed
in the two passes of 7.2.2 (see :mod:`unmesh.shells._force_kernels`). The result also carries
the current fiber lengths and angles and the node normals, which plasticity (7.19-7.23),
fracture (7.24) and the pressure force reuse without recomputing them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh._threads import threads_for
from unmesh.shells import _force_kernels
from unmesh.shells.arcs import arc_gram, arc_weights  # re-exported: callers import them from here
from unmesh.shells.energy import FiberState
from unmesh.shells.fibers import ARC_SAMPLES
from unmesh.shells.topology import ShellTopology

__all__ = ["ForceResult", "arc_gram", "arc_weights", "elastic_forces", "node_terms"]

#: Fixed number of node ranges of the force pass, each with its own force buffer: the
#: summation order, and so the result bit for bit, does not depend on the number of threads.
FORCE_CHUNKS = 8


@dataclass(frozen=True, eq=False)
class ForceResult:
    """Output of :func:`elastic_forces`.

    Attributes
    ----------
    forces : ndarray (N, 3)
        ``-grad (E_s + E_b)``.
    stretch_energy, bend_energy : ndarray (N,)
        Per-node membrane (7.7) and bending (7.11) energy.
    lengths, angles : ndarray (F,)
        Current ``l~`` and ``theta`` of every fiber.
    normals : ndarray (N, 3)
        Current umbrella normals (zero where a node has no umbrella pairs).
    umbrella : ndarray (N, 3)
        Umbrella vectors ``s_i`` (twice the vector area of each node's fan).
    node_terms : ndarray (N, 4)
        ``A_i, A_i^0, H_i, H_i^0`` of every node (7.6, 7.9; zeros without fibers).
    """

    forces: np.ndarray
    stretch_energy: np.ndarray
    bend_energy: np.ndarray
    lengths: np.ndarray
    angles: np.ndarray
    normals: np.ndarray
    umbrella: np.ndarray
    node_terms: np.ndarray

    @property
    def energy(self) -> float:
        """Total elastic energy."""
        return float(self.stretch_energy.sum() + self.bend_energy.sum())


def elastic_forces(x: np.ndarray, topology: ShellTopology, state: FiberState, ks: float, kb: float,
                   samples: int = ARC_SAMPLES, reference: np.ndarray | None = None,
                   node_offsets: np.ndarray | None = None) -> ForceResult:
    """Elastic forces on all nodes (7.16, two passes), energies and fiber measures.

    Parameters
    ----------
    x : ndarray (N, 3) float64, C-contiguous
        Node positions (not validated: this is the inner loop of the simulation).
    topology : ShellTopology
    state : FiberState
        Rest state aligned with ``topology.fibers``.
    ks, kb : float
        ``K_s``, ``K_b``.
    samples : int
        Arc-length samples per segment.
    reference : ndarray (F,), optional
        Angles of the previous step: each ``theta`` is taken on the branch ``theta + 2 pi k``
        nearest to it (continuity through folds); default the rest angles.
    node_offsets : ndarray (N, 2), optional
        Offsets ``(dA_i, dH_i)`` of the node terms, ``A_i - A_i^0 - dA_i`` and
        ``H_i - H_i^0 - dH_i`` (kept by fracture so that rebuilding a node's fibers does not
        change its node terms; default zero).

    Returns
    -------
    ForceResult

    Example
    -------
    >>> from unmesh.shells.nodes import grid_sheet
    >>> x, topo = grid_sheet(5, 5)
    >>> state = FiberState.at_rest(x, topo)
    >>> r = elastic_forces(x * 1.01, topo, state, 100.0, 1.0)
    >>> bool(np.abs(r.forces.sum(axis=0)).max() < 1e-9), r.energy > 0
    (True, True)
    """
    with threads_for(len(topology.fibers)):
        return _elastic_forces(x, topology, state, ks, kb, samples, reference, node_offsets)


_NO_MASK = np.zeros(0, dtype=np.bool_)


def _elastic_forces(x: np.ndarray, topology: ShellTopology, state: FiberState, ks: float, kb: float, samples: int,
                    reference: np.ndarray | None, node_offsets: np.ndarray | None,
                    only: np.ndarray = _NO_MASK, scatter: bool = True) -> ForceResult:
    n = topology.n_nodes
    nf = len(topology.fibers)
    chunks = FORCE_CHUNKS
    s = np.empty((n, 3))
    normals = np.empty((n, 3))
    lengths = np.empty(nf)
    angles = np.empty(nf)
    es = np.empty(n)
    eb = np.empty(n)
    node = np.empty((n, 4))
    forces = np.empty((n, 3))
    offsets = np.zeros((n, 2)) if node_offsets is None else np.ascontiguousarray(node_offsets, dtype=np.float64)
    counts = np.diff(topology.fiber_offsets)
    cap = int(counts.max()) if n else 0
    ref = state.rest_angle() if reference is None else np.ascontiguousarray(reference, dtype=np.float64)
    buf = np.empty((chunks, n, 3)) if scatter else np.empty((chunks, 0, 3))
    _force_kernels.force_chunks(chunks, np.ascontiguousarray(x, dtype=np.float64), topology.pairs,
                          topology.pair_offsets[:-1], np.diff(topology.pair_offsets), topology.soft, topology.fibers,
                          topology.fiber_offsets[:-1], counts, state.length_orig, state.length_plastic,
                          state.angle_orig, state.angle_plastic, state.stretch_scale, state.bend_scale, float(ks),
                          float(kb), arc_gram(int(samples)), ref, offsets, cap, buf, forces, lengths, angles, s,
                          normals, node, es, eb, only, scatter)
    return ForceResult(forces, es, eb, lengths, angles, normals, s, node)


def node_terms(x: np.ndarray, topology: ShellTopology, state: FiberState, rows: np.ndarray,
               samples: int = ARC_SAMPLES, reference: np.ndarray | None = None) -> np.ndarray:
    """Node terms ``A_i, A_i^0, H_i, H_i^0`` (7.6, 7.9) of the nodes ``rows`` only.

    Equal, bit for bit, to ``elastic_forces(x, topology, state, ..., reference).node_terms[rows]``
    (the same kernel on the same blocks of nodes), at the cost of the blocks holding the
    listed nodes only: fracture uses it to keep the node terms of rebuilt nodes continuous.

    Parameters
    ----------
    x : ndarray (N, 3) float64
    topology : ShellTopology
    state : FiberState
    rows : ndarray (R,) int64
        Node indices.
    samples : int
        Arc-length samples per segment.
    reference : ndarray (F,), optional
        Angle branch reference, as for :func:`elastic_forces`.

    Returns
    -------
    ndarray (R, 4)

    Example
    -------
    >>> from unmesh.shells.nodes import grid_sheet
    >>> x, topo = grid_sheet(5, 5)
    >>> state = FiberState.at_rest(x, topo)
    >>> full = elastic_forces(x * 1.01, topo, state, 1.0, 1.0).node_terms
    >>> bool(np.array_equal(node_terms(x * 1.01, topo, state, np.array([3, 7])), full[[3, 7]]))
    True
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    if not len(rows):
        return np.zeros((0, 4))
    only = np.zeros(topology.n_nodes, dtype=np.bool_)
    only[rows] = True
    with threads_for(int(np.diff(topology.fiber_offsets)[rows].sum())):     # a few blocks: one thread
        res = _elastic_forces(x, topology, state, 1.0, 1.0, samples, reference, None, only, scatter=False)
    return res.node_terms[rows]
