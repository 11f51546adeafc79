"""Disc and plane (rectangle): open, one-sided surfaces.

For an open sheet there is no inside. unmesh uses the following convention:

- ``implicit(x)``: the magnitude is the exact Euclidean distance to the finite
  sheet; the sign is that of the side of the supporting plane (negative behind the
  sheet, i.e. opposite to its normal; points in the plane count as in front). The
  normal is the exact unit gradient: the sheet normal above and below the sheet,
  the direction away from (in front) or towards (behind) the rim beyond it.
- ``contains(x)``: ``implicit(x) < 0``, i.e. the open half-space behind the
  supporting plane. Used as a ground plane this is "below the floor".
- ``volume()`` raises InputError (an open sheet encloses no volume).
- ``mesh()`` is one-sided with faces counter-clockwise seen from the normal side.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError
from unmesh.shapes._meshing import cell_radii, grid_faces, polar_cells, polar_rings
from unmesh.shapes.base import FramedShape
from unmesh.shapes.revolved import _frame

__all__ = ["Disc", "Plane"]


def _sheet_implicit(p: np.ndarray, closest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    diff = p - closest
    dist = np.linalg.norm(diff, axis=1)
    sign = np.where(p[:, 2] < 0, -1.0, 1.0)
    n = np.zeros_like(p)
    ok = dist > 0
    n[ok] = sign[ok, None] * diff[ok] / dist[ok, None]
    n[~ok] = (0.0, 0.0, 1.0)
    return sign * dist, n


class _Sheet(FramedShape):
    closed = False

    @property
    def normal(self) -> np.ndarray:
        """Unit sheet normal (3,) in world coordinates."""
        return self.rotation[:, 2].copy()

    def volume(self) -> float:
        raise InputError(f"{type(self).__name__} is an open surface and encloses no volume")


class Disc(_Sheet):
    """A flat circular disc (open surface).

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre.
    radius : float
        Radius (> 0).
    normal : array_like, shape (3,), optional
        Front-side normal, default +y. Local frame: normal = local z.
    rotation : array_like, shape (3, 3), optional
        Local-to-world rotation instead of ``normal``.

    Notes
    -----
    See the module docstring for what ``implicit`` and ``contains`` mean for an
    open sheet.

    Example
    -------
    >>> d = Disc(radius=1.0)
    >>> v, n = d.implicit([[0.0, -0.5, 0.0], [2.0, 0.0, 0.0]])
    >>> v.tolist(), n[0].tolist()
    ([-0.5, 1.0], [0.0, 1.0, 0.0])
    """

    kind = "disc"

    def __init__(self, center: Any = (0.0, 0.0, 0.0), radius: float = 1.0, normal: Any = None,
                 rotation: Any = None) -> None:
        super().__init__(center, _frame(normal, rotation, "normal"))
        self.radius = positive_scalar(radius, "radius")

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "radius": self.radius, "normal": self.normal.tolist()}

    def size(self) -> float:
        return 2.0 * self.radius

    def area(self) -> float:
        return math.pi * self.radius**2

    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> Disc:
        return Disc(center, self.radius * factor, rotation=rotation)

    def _local_bounds_points(self) -> np.ndarray:
        raise NotImplementedError

    def bounds(self) -> np.ndarray:
        a = self.normal
        ext = self.radius * np.sqrt(np.maximum(0.0, 1.0 - a * a))
        return np.stack([self.center - ext, self.center + ext])

    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rho = np.hypot(p[:, 0], p[:, 1])
        scale = np.where(rho > self.radius, self.radius / np.where(rho > 0, rho, 1.0), 1.0)
        closest = np.stack([p[:, 0] * scale, p[:, 1] * scale, np.zeros(len(p))], 1)
        return _sheet_implicit(p, closest)

    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        return polar_rings(self.radius, spacing)

    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pc, lo, hi = polar_cells(self.radius, spacing)

        def disc(u: np.ndarray, v: np.ndarray) -> np.ndarray:
            return np.stack([u * np.cos(v), u * np.sin(v), np.zeros(len(u))], 1)

        return disc(pc[:, 0], pc[:, 1]), np.tile([0.0, 0.0, 1.0], (len(pc), 1)), cell_radii(disc, pc, lo, hi)


class Plane(_Sheet):
    """A flat rectangle (open surface), e.g. a floor.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre.
    size : array_like, shape (2,) or float
        Edge lengths along the two local tangent axes (local x and y). For the
        default normal +y these are world x and world z.
    normal : array_like, shape (3,), optional
        Front-side normal, default +y. Local frame: normal = local z.
    rotation : array_like, shape (3, 3), optional
        Local-to-world rotation instead of ``normal``.

    Notes
    -----
    See the module docstring for what ``implicit`` and ``contains`` mean for an
    open sheet.

    Example
    -------
    >>> p = Plane(size=(4.0, 2.0))
    >>> p.area(), p.contains([[0.0, -1.0, 0.0]]).tolist()
    (8.0, [True])
    """

    kind = "plane"

    def __init__(self, center: Any = (0.0, 0.0, 0.0), size: Any = (1.0, 1.0), normal: Any = None,
                 rotation: Any = None) -> None:
        super().__init__(center, _frame(normal, rotation, "normal"))
        s = np.asarray(size, dtype=np.float64) if np.ndim(size) else np.full(2, float(size))
        s = as_array(s, "size", (2,))
        if not np.all(s > 0):
            raise InputError(f"size: expected two positive edge lengths, got {s.tolist()}")
        self.size_uv = s
        self.size_uv.setflags(write=False)

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "size": self.size_uv.tolist(), "normal": self.normal.tolist()}

    def size(self) -> float:
        return float(self.size_uv.max())

    def area(self) -> float:
        return float(self.size_uv[0] * self.size_uv[1])

    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> Plane:
        return Plane(center, self.size_uv * factor, rotation=rotation)

    def _local_bounds_points(self) -> np.ndarray:
        a, b = 0.5 * self.size_uv
        return np.array([[-a, -b, 0.0], [a, -b, 0.0], [a, b, 0.0], [-a, b, 0.0]])

    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b = 0.5 * self.size_uv
        closest = np.stack([np.clip(p[:, 0], -a, a), np.clip(p[:, 1], -b, b), np.zeros(len(p))], 1)
        return _sheet_implicit(p, closest)

    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        nu = max(1, math.ceil(self.size_uv[0] / spacing))
        nv = max(1, math.ceil(self.size_uv[1] / spacing))
        u, v = np.meshgrid(np.linspace(-0.5, 0.5, nu + 1) * self.size_uv[0],
                           np.linspace(-0.5, 0.5, nv + 1) * self.size_uv[1], indexing="ij")
        verts = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], 1)
        return verts, grid_faces(nu, nv)

    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        nu = max(1, math.ceil(self.size_uv[0] / spacing))
        nv = max(1, math.ceil(self.size_uv[1] / spacing))
        du, dv = self.size_uv[0] / nu, self.size_uv[1] / nv
        u, v = np.meshgrid((np.arange(nu) + 0.5) * du - 0.5 * self.size_uv[0],
                           (np.arange(nv) + 0.5) * dv - 0.5 * self.size_uv[1], indexing="ij")
        pos = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], 1)
        radii = np.full(len(pos), 0.5 * math.hypot(du, dv) * (1.0 + 1e-9))
        return pos, np.tile([0.0, 0.0, 1.0], (len(pos), 1)), radii

