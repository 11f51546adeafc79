"""Particles: points with optional radii and named attributes.

The noun that simulation frames are written and read as (SPH particles, shell
nodes) and that the renderer draws as shaded spheres coloured by an attribute.
Unlike surfels, particles carry no orientation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, first_index
from unmesh.errors import InputError

__all__ = ["Particles"]


@dataclass(frozen=True, eq=False, repr=False)
class Particles:
    """N particles.

    Parameters
    ----------
    positions : array_like, shape (N, 3)
    radii : array_like, shape (N,), optional
        Drawing radius per particle (> 0); ``None`` lets the renderer choose from
        the particle spacing.
    attributes : mapping of str to array_like, optional
        Per-particle arrays (first axis N), e.g. ``velocity`` (N,3), ``density`` (N,).

    Example
    -------
    >>> p = Particles([[0, 0, 0], [1, 0, 0]], attributes={"density": [1.0, 2.0]})
    >>> len(p), p.attributes["density"].dtype
    (2, dtype('float64'))
    """

    positions: np.ndarray
    radii: np.ndarray | None = None
    attributes: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        pos = as_points(self.positions, "positions")
        n = len(pos)
        radii = None
        if self.radii is not None:
            radii = as_array(self.radii, "radii", (None,), length=n)
            bad = ~(radii > 0)
            if bad.any():
                raise InputError(f"radii: expected positive values, got {radii[first_index(bad)]} at index {first_index(bad)}")
        attrs: dict[str, np.ndarray] = {}
        for key, value in dict(self.attributes).items():
            arr = np.ascontiguousarray(value)
            if arr.ndim == 0 or arr.shape[0] != n:
                raise InputError(f"attributes[{key!r}]: expected first axis of length {n}, got shape {arr.shape}")
            attrs[str(key)] = arr
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "radii", radii)
        object.__setattr__(self, "attributes", attrs)

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def __repr__(self) -> str:
        return f"Particles({len(self)} particles, attributes={sorted(self.attributes)})"

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2,3) ``[min, max]``; empty gives ``[inf, -inf]``."""
        if len(self) == 0:
            return np.array([[np.inf] * 3, [-np.inf] * 3])
        return np.stack([self.positions.min(axis=0), self.positions.max(axis=0)])

    def replace(self, **changes: Any) -> Particles:
        """A copy with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def subset(self, index: Any) -> Particles:
        """The particles selected by a boolean mask or index array."""
        idx = np.asarray(index)
        return Particles(self.positions[idx], None if self.radii is None else self.radii[idx],
                         {k: v[idx] for k, v in self.attributes.items()})
