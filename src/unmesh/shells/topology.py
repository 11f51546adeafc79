"""Connectivity of a point-sampled shell: node neighbourhoods, umbrella pairs and fibers.

The shell keeps *persistent but not consistent* connectivity (thesis 7.2): each simulation
node ``i`` has a neighbourhood ``N_i`` of nearby nodes, and fibers ``(j, i, j')`` through
``i`` (7.4). Two derived structures make the force kernels race-free:

* fibers are sorted by their centre node, with CSR offsets, so a node's fibers are
  contiguous (first force pass, 7.16);
* an incidence list per node of ``(fiber, role)`` entries (role 0, 1, 2 for ``x1``, ``x``,
  ``x2``) lets the second pass gather forces per node in parallel.

The surface normal ``N_i`` at a node (needed by the tangent angle, 7.10) is the *umbrella
normal* ``s_i / |s_i|`` with ``s_i = sum (x_a - x_i) x (x_b - x_i)`` over consecutive
neighbour pairs ``(a, b)`` in counter-clockwise order around the rest normal (pairs
spanning a gap of more than 0.9 pi, i.e. open boundary sides, are left out). It is a
smooth function of the node positions, so its gradient enters the forces and the forces
stay the exact gradient of the energy. The raw vector ``s_i`` is what the tangent angle
uses, with the per-node regularisation ``soft_i = 0.1 |s_i^0|`` (rest length of ``s_i``; see
:func:`unmesh.shells.fibers.bending_angle_gradient`): a node whose umbrella collapses or
folds under extreme deformation then has bounded forces.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from unmesh._csr import csr_entries
from unmesh._validate import as_array, as_indices
from unmesh.errors import InputError

__all__ = ["UMBRELLA_SOFTENING", "ShellTopology", "csr_entries", "csr_from_groups"]

#: soft_i = UMBRELLA_SOFTENING * |s_i| at rest (regularisation of the tangent-angle axis).
UMBRELLA_SOFTENING = 0.1


def csr_from_groups(groups: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Stable grouping of entries by integer key.

    Parameters
    ----------
    groups : ndarray, shape (M,) int64
        Key of each entry, in [0, count).
    count : int
        Number of groups.

    Returns
    -------
    offsets : ndarray, shape (count + 1,) int64
    order : ndarray, shape (M,) int64
        Entry indices sorted by key (stable); entries of group g are
        ``order[offsets[g]:offsets[g + 1]]``. A counting sort (numba, O(M)); equal to
        :func:`csr_from_groups_reference`.

    Example
    -------
    >>> csr_from_groups(np.array([1, 0, 1]), 3)
    (array([0, 1, 3, 3]), array([1, 0, 2]))
    """
    from unmesh._csr_kernels import counting_sort_csr

    order, offsets = counting_sort_csr(np.ascontiguousarray(groups, dtype=np.int64), int(count))
    return offsets, order


def csr_from_groups_reference(groups: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Numpy reference of :func:`csr_from_groups` (stable ``argsort`` and ``bincount``).

    Example
    -------
    >>> csr_from_groups_reference(np.array([1, 0, 1]), 3)
    (array([0, 1, 3, 3]), array([1, 0, 2]))
    """
    order = np.argsort(groups, kind="stable").astype(np.int64)
    offsets = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(np.bincount(groups, minlength=count), out=offsets[1:])
    return offsets, order


def _grouped(keys: np.ndarray, rows: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR offsets by ``keys`` and ``rows``, ``keys`` in stable key order (no reordering when sorted)."""
    if len(keys) < 2 or bool((keys[1:] >= keys[:-1]).all()):
        offsets = np.zeros(count + 1, dtype=np.int64)
        np.cumsum(np.bincount(keys, minlength=count), out=offsets[1:])
        return offsets, np.ascontiguousarray(rows), np.ascontiguousarray(keys)
    offsets, order = csr_from_groups(keys, count)
    return offsets, np.ascontiguousarray(rows[order]), np.ascontiguousarray(keys[order])


@dataclass(frozen=True, eq=False)
class ShellTopology:
    """Neighbourhoods, umbrella pairs and fibers of ``n_nodes`` simulation nodes.

    Build it with :meth:`build`; the fields below are derived and validated there.

    Attributes
    ----------
    n_nodes : int
    neighbor_offsets : ndarray (N + 1,) int64
        CSR offsets of the node neighbourhoods ``N_i``.
    neighbors : ndarray (M,) int64
        Neighbour indices (excluding the node itself).
    pairs : ndarray (P, 2) int64
        Umbrella pairs ``(a, b)``, grouped by centre node.
    pair_offsets : ndarray (N + 1,) int64
        CSR offsets of the pairs of each node.
    pair_center : ndarray (P,) int64
        Centre node of each pair.
    pair_incidence_offsets, pair_incidence : ndarray
        CSR per node of ``2 * pair + role`` for every pair in which the node is ``a``
        (role 0) or ``b`` (role 1).
    fibers : ndarray (F, 3) int64
        Fibers ``(j, i, j')`` sorted by centre ``i``.
    fiber_offsets : ndarray (N + 1,) int64
        CSR offsets of the fibers of each centre node.
    fiber_incidence_offsets, fiber_incidence : ndarray
        CSR per node of ``3 * fiber + role`` for every fiber through the node.
    soft : ndarray (N,) float64
        Regularisation of each node's tangent-angle axis (0 = none).

    Example
    -------
    >>> topo = ShellTopology.build(3, [0, 2, 4, 6], [1, 2, 0, 2, 0, 1], [[1, 2]], [0], [[1, 0, 2]])
    >>> topo.fibers, topo.fiber_offsets
    (array([[1, 0, 2]]), array([0, 1, 1, 1]))
    """

    n_nodes: int
    neighbor_offsets: np.ndarray
    neighbors: np.ndarray
    pairs: np.ndarray
    pair_offsets: np.ndarray
    pair_center: np.ndarray
    fibers: np.ndarray
    fiber_offsets: np.ndarray
    soft: np.ndarray

    # the incidence lists are built on first use (the force kernels do not need them)
    @functools.cached_property
    def _pair_incidence(self) -> tuple[np.ndarray, np.ndarray]:
        return csr_from_groups(self.pairs.reshape(-1), self.n_nodes)  # entry e = 2 * pair + role

    @functools.cached_property
    def _fiber_incidence(self) -> tuple[np.ndarray, np.ndarray]:
        return csr_from_groups(self.fibers.reshape(-1), self.n_nodes)  # entry e = 3 * fiber + role

    @property
    def pair_incidence_offsets(self) -> np.ndarray:
        """CSR offsets (N + 1,) of :attr:`pair_incidence`."""
        return self._pair_incidence[0]

    @property
    def pair_incidence(self) -> np.ndarray:
        """``2 * pair + role`` for every pair in which a node is ``a`` (0) or ``b`` (1), by node."""
        return self._pair_incidence[1]

    @property
    def fiber_incidence_offsets(self) -> np.ndarray:
        """CSR offsets (N + 1,) of :attr:`fiber_incidence`."""
        return self._fiber_incidence[0]

    @property
    def fiber_incidence(self) -> np.ndarray:
        """``3 * fiber + role`` for every fiber through a node, by node."""
        return self._fiber_incidence[1]

    @classmethod
    def build(cls, n_nodes: int, neighbor_offsets: object, neighbors: object, pairs: object, pair_center: object,
              fibers: object, soft: object = None, validate: bool = True) -> ShellTopology:
        """Validate the primary arrays, sort fibers and pairs by centre and derive incidence lists.

        Parameters
        ----------
        n_nodes : int
        neighbor_offsets : array_like (N + 1,) int
        neighbors : array_like (M,) int
        pairs : array_like (P, 2) int
            Umbrella pairs; ``pair_center`` gives the centre node of each.
        pair_center : array_like (P,) int
        fibers : array_like (F, 3) int
            ``(j, i, j')`` with the centre in the middle column.
        soft : array_like (N,), optional
            Per-node regularisation (default 0).
        validate : bool
            ``False`` skips the checks, for arrays derived from a valid topology (the fracture
            rebuild); the result is the same.

        Returns
        -------
        ShellTopology
        """
        n = int(n_nodes)
        if not validate:
            def ints(a: object, shape: tuple[int, ...]) -> np.ndarray:
                return np.ascontiguousarray(a, dtype=np.int64).reshape(shape)

            fib = ints(fibers, (-1, 3))
            return cls._derive(n, ints(neighbor_offsets, (n + 1,)), ints(neighbors, (-1,)), ints(pairs, (-1, 2)),
                               ints(pair_center, (-1,)), fib,
                               np.zeros(n) if soft is None else np.ascontiguousarray(soft, dtype=np.float64))
        noff = as_indices(neighbor_offsets, "neighbor_offsets", (n + 1,))
        nbr = as_indices(neighbors, "neighbors", (None,), upper=n)
        if noff[0] != 0 or noff[-1] != len(nbr) or np.any(np.diff(noff) < 0):
            raise InputError("neighbor_offsets: expected non-decreasing CSR offsets from 0 to len(neighbors)")
        pr = as_indices(pairs, "pairs", (None, 2), upper=n)
        pc = as_indices(pair_center, "pair_center", (None,), upper=n, length=len(pr))
        fib = as_indices(fibers, "fibers", (None, 3), upper=n)
        if len(fib) and np.any((fib[:, 0] == fib[:, 1]) | (fib[:, 2] == fib[:, 1]) | (fib[:, 0] == fib[:, 2])):
            raise InputError("fibers: expected three distinct nodes per fiber")
        sf = np.zeros(n) if soft is None else as_array(soft, "soft", (n,))
        if np.any(sf < 0):
            raise InputError("soft: expected values >= 0")
        return cls._derive(n, noff, nbr, pr, pc, fib, sf)

    @classmethod
    def _derive(cls, n: int, noff: np.ndarray, nbr: np.ndarray, pr: np.ndarray, pc: np.ndarray, fib: np.ndarray,
                sf: np.ndarray) -> ShellTopology:
        """Sort pairs and fibers by centre (arrays already checked).

        Already sorted arrays (a fracture rebuild splices them in order) are kept as they
        are: the stable sort would not move anything.
        """
        poff, pr, pc = _grouped(pc, pr, n)
        foff, fib, _ = _grouped(np.ascontiguousarray(fib[:, 1]), fib, n)
        return cls(n, noff, nbr, pr, poff, pc, fib, foff, sf)

    def fiber_counts(self) -> np.ndarray:
        """Number of fibers ``m_i`` centred at each node, (N,) int64."""
        return np.diff(self.fiber_offsets)

    def neighborhood(self, i: int) -> np.ndarray:
        """Neighbour indices of node ``i``."""
        return self.neighbors[self.neighbor_offsets[i]:self.neighbor_offsets[i + 1]]

    def components(self) -> tuple[int, np.ndarray]:
        """Connected pieces of the fiber graph (nodes joined when they share a fiber).

        Returns
        -------
        count : int
            Number of pieces; a node on no fiber is a piece of its own.
        labels : ndarray (N,) int64
            Piece of each node.
        """
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        f = self.fibers
        rows = np.concatenate([f[:, 0], f[:, 1]])
        cols = np.concatenate([f[:, 1], f[:, 2]])
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(self.n_nodes, self.n_nodes))
        count, labels = connected_components(graph, directed=False)
        return int(count), labels.astype(np.int64)
