"""Counter-based random numbers for the stochastic parts of the SPH model.

Melting, freezing (eqs. 8.34–8.36) and docking (section 8.2.5) draw one uniform
number per particle (and lattice slot) and time step. A counter-based generator
(SplitMix64 finaliser of ``(seed, step, particle id, slot, stream)``) makes each
draw a pure function of its indices: runs are reproducible for a given scene seed,
independent of thread count and particle order, and a resumed run draws exactly
the numbers the uninterrupted run would have drawn (the state is the step counter).

Example
-------
>>> u = uniform_np(7, 3, np.arange(4), 0, STREAM_MELT)
>>> u.shape, bool(np.all((u >= 0) & (u < 1)))
((4,), True)
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["STREAM_DOCK", "STREAM_FREEZE", "STREAM_MELT", "uniform", "uniform_np"]

STREAM_MELT = 1
STREAM_FREEZE = 2
STREAM_DOCK = 3

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_G = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True, fastmath=False, error_model="python")
def _mix(z):
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, fastmath=False, error_model="python")
def uniform(seed, step, pid, slot, stream):
    """Uniform number in [0, 1) for the given integer counters (numba scalar)."""
    z = _mix(np.uint64(seed) * _G + np.uint64(stream))
    z = _mix(z ^ (np.uint64(step) * _G))
    z = _mix(z ^ (np.uint64(pid) * _G + np.uint64(0x632BE59BD9B4E019)))
    z = _mix(z ^ (np.uint64(slot) * _G + np.uint64(0x8CB92BA72F3D8DD7)))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


def uniform_np(seed: int, step: int, pid: np.ndarray, slot: int | np.ndarray, stream: int) -> np.ndarray:
    """Numpy reference of :func:`uniform` for arrays of particle ids (and slots).

    Example
    -------
    >>> float(uniform_np(1, 2, np.array([3]), 4, 5)[0]) == uniform(1, 2, 3, 4, 5)
    True
    """

    def mix(z: np.ndarray) -> np.ndarray:
        z = (z ^ (z >> np.uint64(30))) * _M1
        z = (z ^ (z >> np.uint64(27))) * _M2
        return z ^ (z >> np.uint64(31))

    with np.errstate(over="ignore"):
        p = np.asarray(pid, dtype=np.int64).astype(np.uint64)
        s = np.broadcast_to(np.asarray(slot, dtype=np.int64).astype(np.uint64), p.shape)
        z = mix(np.full(p.shape, np.uint64(seed) * _G + np.uint64(stream), dtype=np.uint64))
        z = mix(z ^ (np.uint64(step) * _G))
        z = mix(z ^ (p * _G + np.uint64(0x632BE59BD9B4E019)))
        z = mix(z ^ (s * _G + np.uint64(0x8CB92BA72F3D8DD7)))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)
