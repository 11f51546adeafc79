"""Numba kernels of the node-coupling pattern of the global matrix (rebuilt after every cut).

The numpy reference is :meth:`unmesh.fem.assembly.BlockPattern.build` with ``fast=False``
(compared in ``tests/fem/test_fem_assembly.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh._csr_kernels import counting_sort_csr, csr_rows

#: Fixed number of row ranges of the pattern build, each with its own marker arrays (the
#: result does not depend on the number of threads: every row is built alone).
PATTERN_CHUNKS = 16


@njit(cache=True)
def node_incidence(node_off, nodes, n_nodes):
    """Node -> (element, local index) incidence: ``(inc_off (n+1,), inc_e, inc_a)``, elements ascending.

    Node i is local node ``inc_a[t]`` of element ``inc_e[t]`` for ``t`` in
    ``inc_off[i]:inc_off[i+1]`` (:func:`unmesh._csr_kernels.counting_sort_csr` of the element node lists).
    """
    order, inc_off = counting_sort_csr(nodes, n_nodes)
    inc_e = csr_rows(node_off)[order]
    inc_a = order - node_off[inc_e]
    return inc_off, inc_e, inc_a


@njit(cache=True, parallel=True)
def _row_lengths(node_off, nodes, inc_off, inc_e, n_nodes):
    counts = np.zeros(n_nodes, np.int64)
    for ch in prange(PATTERN_CHUNKS):
        mark = np.full(n_nodes, -1, np.int64)
        for i in range(ch * n_nodes // PATTERN_CHUNKS, (ch + 1) * n_nodes // PATTERN_CHUNKS):
            c = 0
            for t in range(inc_off[i], inc_off[i + 1]):
                e = inc_e[t]
                for k in range(node_off[e], node_off[e + 1]):
                    j = nodes[k]
                    if mark[j] != i:
                        mark[j] = i
                        c += 1
            counts[i] = c
    return counts


@njit(cache=True, parallel=True)
def _fill_rows(node_off, nodes, inc_off, inc_e, inc_a, bstart, indptr, indices, block_map, diag, n_nodes):
    for ch in prange(PATTERN_CHUNKS):
        mark = np.full(n_nodes, -1, np.int64)
        pos = np.empty(n_nodes, np.int64)
        for i in range(ch * n_nodes // PATTERN_CHUNKS, (ch + 1) * n_nodes // PATTERN_CHUNKS):
            p0 = indptr[i]
            p = p0
            for t in range(inc_off[i], inc_off[i + 1]):
                e = inc_e[t]
                for k in range(node_off[e], node_off[e + 1]):
                    j = nodes[k]
                    if mark[j] != i:
                        mark[j] = i
                        # insertion into the sorted row (a few dozen entries)
                        q = p
                        while q > p0 and indices[q - 1] > j:
                            indices[q] = indices[q - 1]
                            q -= 1
                        indices[q] = j
                        p += 1
            for q in range(p0, p):
                pos[indices[q]] = q
                if indices[q] == i:
                    diag[i] = q
            for t in range(inc_off[i], inc_off[i + 1]):
                e = inc_e[t]
                a = inc_a[t]
                m = node_off[e + 1] - node_off[e]
                for b in range(m):
                    block_map[bstart[e] + a * m + b] = pos[nodes[node_off[e] + b]]


@njit(cache=True)
def block_pattern(node_off, nodes, n_nodes):
    """Node-coupling pattern of the element node lists and the node incidence.

    Returns ``(indptr, indices, block_map, diag, inc_off, inc_e, inc_a)``: row i lists, sorted,
    every node sharing an element with node i; ``block_map[k]`` is the global block of
    element block k (element order, ``a·n_e + b`` within an element), ``diag[i]`` the
    position of block (i, i) (-1 for a node of no element); the incidence is
    :func:`node_incidence`. O(Σ_e n_e²) with marker arrays (no global sort); the rows are
    built in parallel (each alone, so the result does not depend on the thread count).
    """
    ne = node_off.shape[0] - 1
    inc_off, inc_e, inc_a = node_incidence(node_off, nodes, n_nodes)
    bstart = np.empty(ne + 1, np.int64)
    bstart[0] = 0
    for e in range(ne):
        m = node_off[e + 1] - node_off[e]
        bstart[e + 1] = bstart[e] + m * m
    counts = _row_lengths(node_off, nodes, inc_off, inc_e, n_nodes)
    indptr = np.zeros(n_nodes + 1, np.int64)
    for i in range(n_nodes):
        indptr[i + 1] = indptr[i] + counts[i]
    indices = np.empty(indptr[n_nodes], np.int64)
    block_map = np.empty(bstart[ne], np.int64)
    diag = np.full(n_nodes, -1, np.int64)
    _fill_rows(node_off, nodes, inc_off, inc_e, inc_a, bstart, indptr, indices, block_map, diag, n_nodes)
    return indptr, indices, block_map, diag, inc_off, inc_e, inc_a
