"""The surge front of a dam break: the figure Martin & Moyce (1952) measured.

Used by the SPH frame records (``surge_front`` in ``summary.json``, hence
``final.surge_front`` in a batch's ``batch.csv``), the validation test and the
benchmark, so they all measure the same thing.
"""

from __future__ import annotations

from typing import Any

from unmesh._validate import as_points
from unmesh.spatial import knn

__all__ = ["surge_front"]


def surge_front(positions: Any, spacing: float, axis: int = 0) -> float:
    """Largest coordinate along ``axis`` of a particle that is not an isolated droplet.

    A particle counts when another lies within 1.5 ``spacing`` (the front of the water
    body, not a spray particle ahead of it). For the dam break along +x, ``Z = front / a``
    against ``T = t √(2g/a)`` is Martin & Moyce's surge-front curve.

    Parameters
    ----------
    positions : (N, 3) float array
    spacing : float
        Initial particle spacing d.
    axis : int
        0, 1 or 2.

    Returns
    -------
    float
        Finite (frame records must be): when no particle has a neighbour that close, the
        largest coordinate of all; 0 for no particles.

    Example
    -------
    >>> import numpy as np
    >>> x = np.array([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [5.0, 0, 0]])
    >>> surge_front(x, 0.1)
    0.2
    """
    pts = as_points(positions, "positions")
    if len(pts) < 2:
        return float(pts[:, axis].max()) if len(pts) else 0.0
    dist, _ = knn(pts, 2)
    attached = dist[:, 1] < 1.5 * float(spacing)
    return float(pts[attached if attached.any() else slice(None), axis].max())
