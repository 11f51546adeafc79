"""Compressed sparse rows (offsets (R+1,) int64 into an entry array): helpers shared by the packages."""

from __future__ import annotations

import numpy as np

__all__ = ["csr_entries"]


def csr_entries(offsets: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of the entries of the listed CSR rows (in row order) and the row of each.

    Example
    -------
    >>> csr_entries(np.array([0, 2, 3, 5]), np.array([2, 0]))
    (array([3, 4, 0, 1]), array([2, 2, 0, 0]))
    """
    counts = offsets[rows + 1] - offsets[rows]
    pos = np.repeat(offsets[rows] - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))
    return pos.astype(np.int64), np.repeat(rows, counts)
