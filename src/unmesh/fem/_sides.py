"""Snapped side classification of nodes against a cut plane (9.3.1, needle avoidance of 9.2).

Every node ``v`` gets a signed distance ``d_v`` to the plane and a class
``-1 / 0 / +1``. Class 0 means *on the plane*: the node is snapped onto the plane
(the cut surface is taken to pass through it; the node is not moved) when
``|d_v| <= snap · h_v``, with ``h_v`` the node's length scale
(:meth:`unmesh.fem.PolyMesh.node_scales`: initially the longest edge at the node,
interpolated to new nodes and kept by every cut). So an edge the plane crosses is
cut at least ``snap · h_v`` from its end nodes - no needle shorter than about
``snap`` of its edge (9.2) - and a snapped node lies at most ``snap · h_v`` off
the plane.

The class depends only on the node itself, never on the current edges, so it is
the same in every later cut by the same plane: a node snapped onto the blade plane
in one step of a progressive cut (9.3.2) is on it in the next step as well, and no
sliver is cut off between the two. Classes can be *forced* to 0 afterwards (where
one side of an element would be degenerate); the node's length scale then grows
so that its band covers the plane, which keeps that decision for later steps too
(when the cutter's cuts are done, see :meth:`unmesh.fem.cutting.Cutter.keep_snapped`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PlaneSides"]


class PlaneSides:
    """Lazy node classification against one plane for a :class:`unmesh.fem.cutting.Cutter`.

    Parameters
    ----------
    cutter : Cutter
        Provides the editor (``cutter.ed``), ``snap`` and the node length scales.
    origin, normal : (3,) float64
        The plane (``normal`` of unit length).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> from unmesh.fem.cutting import Cutter
    >>> import numpy as np
    >>> sides = PlaneSides(Cutter(hex_grid((2, 2, 2))), np.array([0, 0.505, 0.0]), np.array([0, 1.0, 0]))
    >>> sides(0), sides(3)[1]  # node 3 at y = 0.5 is within snap of the plane
    ((-0.505, -1), 0)
    """

    def __init__(self, cutter: Any, origin: np.ndarray, normal: np.ndarray, keep: bool = True) -> None:
        self.cutter = cutter
        #: whether :meth:`force` decisions are kept for later cuts (blade planes; not the
        #: planes through a cut polygon's edges, which only clip its in-plane faces)
        self.keep = keep
        self.ed = cutter.ed
        self.origin = np.asarray(origin, dtype=np.float64)
        self.normal = np.asarray(normal, dtype=np.float64)
        self.base_d = (cutter.mesh.points - self.origin) @ self.normal
        self._d: dict[int, float] = {}
        self._c: dict[int, int] = {}
        #: nodes forced onto the plane by :meth:`force`
        self.forced: set[int] = set()

    def distance(self, v: int) -> float:
        """Signed distance of node v to the plane (rest position)."""
        d = self._d.get(v)
        if d is None:
            ed = self.ed
            if v < ed.n_base_nodes and v not in ed._moved:
                d = float(self.base_d[v])
            else:
                d = float((ed.point(v) - self.origin) @ self.normal)
            self._d[v] = d
        return d

    def band(self, v: int) -> float:
        """Snapping distance of node v: ``snap`` times its local length scale."""
        return self.cutter.snap * self.cutter.length_scale(v)

    def __call__(self, v: int) -> tuple[float, int]:
        """(signed distance, class) of node v."""
        c = self._c.get(v)
        d = self.distance(v)
        if c is None:
            c = self._c[v] = 0 if abs(d) <= self.band(v) else (1 if d > 0 else -1)
        return d, c

    def cls(self, v: int) -> int:
        """Class of node v (-1, 0, +1)."""
        return self(v)[1]

    def force(self, v: int, keep: bool = True) -> bool:
        """Snap node v onto the plane (class 0); returns whether its class changed.

        Unless ``keep`` is false, the cutter keeps the decision for its later cuts and for the cuts of later steps
        (:meth:`unmesh.fem.cutting.Cutter.keep_snapped`: the node's length scale grows so
        that its band covers its distance to this plane).
        """
        before = self(v)[1]
        self._c[v] = 0
        if before != 0:
            self.forced.add(v)
            if self.keep and keep:
                self.cutter.keep_snapped(v, abs(self.distance(v)))
        return before != 0

    def on_plane(self, v: int) -> None:
        """Register a node created on the plane (distance and class 0)."""
        self._d[v] = 0.0
        self._c[v] = 0
