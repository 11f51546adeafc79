"""Scripted cuts over time: planes, polygons, random element splits, moving blades.

Each event yields, for a time step ``[t0, t1)``, the cut operations due in it;
the simulation applies all of them with one :class:`unmesh.fem.cutting.Cutter`
and re-integrates the changed elements once (9.3.1: deferred to the end of the
step). Geometry is in rest (material) coordinates.

Example
-------
>>> import numpy as np
>>> blade = BladeEvent(0.0, 1.0, np.array([[[0, 1, 0], [0, 1, 1]], [[0, 0, 0], [0, 0, 1]]], float))
>>> len(blade.operations(0.0, 0.1))  # the quad swept in the first tenth
1
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.fem.cutting import Cutter, PlaneCut, PolygonCut

__all__ = ["BladeEvent", "CutEvent", "PlaneEvent", "PolygonEvent", "RandomSplits", "RandomSplitsEvent"]


class CutEvent:
    """Base class: ``operations(t0, t1)`` returns the cuts due in ``[t0, t1)``.

    Example
    -------
    >>> issubclass(PlaneEvent, CutEvent)
    True
    """

    def operations(self, t0: float, t1: float) -> list[Any]:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class PlaneEvent(CutEvent):
    """Split every element a plane crosses at ``time`` (9.3.1; nothing separates).

    Example
    -------
    >>> len(PlaneEvent(0.5, (0, 0, 0), (0, 1, 0)).operations(0.49, 0.51))
    1
    """

    time: float
    origin: tuple[float, float, float]
    normal: tuple[float, float, float]

    def operations(self, t0: float, t1: float) -> list[Any]:
        return [PlaneCut(tuple(self.origin), tuple(self.normal))] if t0 <= self.time < t1 else []


@dataclass(frozen=True)
class PolygonEvent(CutEvent):
    """Cut along a convex planar polygon at ``time`` (9.3.2; the material separates inside it).

    Example
    -------
    >>> import numpy as np
    >>> PolygonEvent(1.0, np.eye(3)).operations(0.0, 0.5)
    []
    """

    time: float
    polygon: np.ndarray

    def operations(self, t0: float, t1: float) -> list[Any]:
        return [PolygonCut(self.polygon)] if t0 <= self.time < t1 else []


@dataclass(frozen=True)
class RandomSplits:
    """Split ``count`` randomly chosen elements (volume-weighted) by random planes through them.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> from unmesh.fem.cutting import Cutter
    >>> c = Cutter(hex_grid((1, 1, 1))); RandomSplits(3, seed=1).apply(c)
    >>> c.commit().mesh.n_elements
    4
    """

    count: int
    seed: int = 0

    def apply(self, cutter: Cutter) -> None:
        rng = np.random.default_rng(self.seed)
        ed = cutter.ed
        for _ in range(self.count):
            alive = [e for e in range(ed.n_elems) if e not in ed.dead_elems]
            vols = []
            cents = []
            for e in alive:
                pts = ed.points_of(ed.elem_nodes(e))
                cents.append(pts.mean(axis=0))
                vols.append(np.prod(np.ptp(pts, axis=0)))
            p = np.asarray(vols) / np.sum(vols)
            for _try in range(20):
                k = int(rng.choice(len(alive), p=p))
                e = alive[k]
                pts = ed.points_of(ed.elem_nodes(e))
                origin = cents[k] + 0.15 * (pts[rng.integers(len(pts))] - cents[k]) * rng.random()
                if cutter.plane(origin, rng.normal(size=3), [e]):
                    break


@dataclass(frozen=True)
class RandomSplitsEvent(CutEvent):
    """At ``time``, split random elements by random planes (Fig. 9.4).

    Example
    -------
    >>> len(RandomSplitsEvent(0.0, 30).operations(0.0, 0.01))
    1
    """

    time: float
    count: int
    seed: int = 0

    def operations(self, t0: float, t1: float) -> list[Any]:
        return [RandomSplits(self.count, self.seed)] if t0 <= self.time < t1 else []


@dataclass(frozen=True)
class BladeEvent(CutEvent):
    """A straight blade (segment) moved from ``start`` to ``stop`` along a path, cutting progressively.

    Parameters
    ----------
    start, stop : float
        Time interval of the sweep.
    path : (k, 2, 3) floats
        Blade endpoints at k ≥ 2 key positions, spread evenly over the interval
        (linear in between). Every step cuts the surface swept since the last
        step (a quad, or two triangles when it is not planar) (9.3.2).

    Example
    -------
    >>> import numpy as np
    >>> b = BladeEvent(0.0, 1.0, np.array([[[0, 1, 0], [0, 1, 1]], [[0, 0, 0], [0, 0, 1]]], float))
    >>> b.blade(0.5).tolist()
    [[0.0, 0.5, 0.0], [0.0, 0.5, 1.0]]
    """

    start: float
    stop: float
    path: np.ndarray

    def __post_init__(self) -> None:
        p = np.asarray(self.path, dtype=np.float64)
        if p.ndim != 3 or p.shape[1:] != (2, 3) or p.shape[0] < 2:
            raise InputError(f"blade path: expected shape (k >= 2, 2, 3), got {p.shape}")
        if not self.stop > self.start:
            raise InputError(f"blade: expected stop > start, got {self.start}, {self.stop}")
        object.__setattr__(self, "path", p)

    def blade(self, t: float) -> np.ndarray:
        """Blade endpoints (2,3) at time t."""
        s = np.clip((t - self.start) / (self.stop - self.start), 0.0, 1.0) * (len(self.path) - 1)
        i = min(int(s), len(self.path) - 2)
        f = s - i
        return (1 - f) * self.path[i] + f * self.path[i + 1]

    def operations(self, t0: float, t1: float) -> list[Any]:
        if t1 <= self.start or t0 >= self.stop:
            return []
        a0, b0 = self.blade(t0)
        a1, b1 = self.blade(t1)
        quad = np.array([a0, b0, b1, a1])
        c = quad.mean(axis=0)
        n = np.cross(b0 - a0, a1 - a0)
        size = max(np.linalg.norm(b0 - a0), np.linalg.norm(a1 - a0), 1e-300)
        if np.linalg.norm(a1 - a0) < 1e-12 * size and np.linalg.norm(b1 - b0) < 1e-12 * size:
            return []
        nn = np.linalg.norm(n)
        if nn > 0 and np.abs((quad - c) @ (n / nn)).max() <= 1e-9 * size:
            return [PolygonCut(quad)]
        ops = []
        for tri in (np.array([a0, b0, b1]), np.array([a0, b1, a1])):
            if np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0])) > 1e-12 * size * size:
                ops.append(PolygonCut(tri))
        return ops
