"""Arc-length speed tables of the numba fiber kernels (thesis Appendix B.4-B.6).

The force kernels (:mod:`unmesh.shells.forces`) and the rest-state measurement
(:meth:`unmesh.shells.energy.FiberState.at_rest`) share these tables, so they live
below both. The numpy reference (:mod:`unmesh.shells.fibers`) forms its own weights.
"""

from __future__ import annotations

import functools

import numpy as np

from unmesh.shells._fiber_kernels import gram_weights, sample_weights
from unmesh.shells.fibers import _samples

__all__ = ["arc_gram", "arc_weights"]


@functools.lru_cache(maxsize=16)
def arc_weights(samples: int) -> np.ndarray:
    """Speed-sample weights (2n, 3) used by the kernels for ``samples`` = n per segment (B.4-B.6).

    Example
    -------
    >>> arc_weights(1)
    array([[-1.0625,  1.125 , -0.0625],
           [ 0.0625, -1.125 ,  1.0625]])
    """
    w = sample_weights(_samples(samples))
    w.setflags(write=False)
    return w


@functools.lru_cache(maxsize=16)
def arc_gram(samples: int) -> np.ndarray:
    """Gram-form speed table (2n, 6) of :func:`arc_weights` used by the kernels (B.4-B.6).

    Columns ``alpha^2, 2 alpha gamma, gamma^2, alpha^2/n, alpha gamma/n, gamma^2/n``, where ``alpha``, ``gamma`` are the weights of ``x1``, ``x2`` (see
    :mod:`unmesh.shells._fiber_kernels`).

    Example
    -------
    >>> arc_gram(1)[:, :3]
    array([[1.12890625, 0.1328125 , 0.00390625],
           [0.00390625, 0.1328125 , 1.12890625]])
    """
    g = gram_weights(arc_weights(samples))
    g.setflags(write=False)
    return g
