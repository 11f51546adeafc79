"""The one CSR (compressed sparse row) builder: a stable counting sort of keys.

:func:`counting_sort_csr` groups entries by an integer key in O(M + K): it serves the cell
grids of :mod:`unmesh.spatial`, the node -> face and node -> element incidences of FEM, the
fiber/node groupings and the disc grid of shells and the tree adjacency of normal
orientation. :func:`csr_rows` gives the row of every entry of a CSR layout (to map sorted
entries back to the rows they came from). Reference: ``numpy.argsort(keys, kind="stable")``
with ``numpy.searchsorted`` offsets (``tests/test_csr_kernels.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["counting_sort_csr", "csr_rows"]


@njit(cache=True)
def counting_sort_csr(keys, nkeys):  # pragma: no cover - numba
    """Stable counting sort of ``keys`` (M,) int64 with values in ``[0, nkeys)``.

    Returns ``(order, offsets)``: ``order`` (M,) int64 lists the entries by ascending key
    (entries of one key ascending, as ``np.argsort(keys, kind="stable")``) and ``offsets``
    (nkeys + 1,) int64 is the CSR start of each key: the entries of key ``g`` are
    ``order[offsets[g]:offsets[g + 1]]``.

    Example
    -------
    >>> import numpy as np
    >>> order, offsets = counting_sort_csr(np.array([1, 0, 1]), 3)
    >>> order.tolist(), offsets.tolist()
    ([1, 0, 2], [0, 1, 3, 3])
    """
    m = keys.shape[0]
    offsets = np.zeros(nkeys + 1, np.int64)
    for e in range(m):
        offsets[keys[e] + 1] += 1
    for g in range(nkeys):
        offsets[g + 1] += offsets[g]
    fill = offsets[:-1].copy()
    order = np.empty(m, np.int64)
    for e in range(m):
        g = keys[e]
        order[fill[g]] = e
        fill[g] += 1
    return order, offsets


@njit(cache=True, parallel=True)
def csr_rows(offsets):  # pragma: no cover - numba
    """Row of every entry (offsets[-1],) int64 of the CSR layout ``offsets`` (R + 1,).

    Example
    -------
    >>> import numpy as np
    >>> csr_rows(np.array([0, 2, 2, 3])).tolist()
    [0, 0, 2]
    """
    rows = np.empty(offsets[-1], np.int64)
    for r in prange(offsets.shape[0] - 1):
        for k in range(offsets[r], offsets[r + 1]):
            rows[k] = r
    return rows
