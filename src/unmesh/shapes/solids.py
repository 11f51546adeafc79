"""Sphere and box: closed shapes with exact signed distance functions."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError
from unmesh.shapes._meshing import grid_faces, weld
from unmesh.shapes.base import FramedShape

__all__ = ["Box", "Sphere"]

#: For face k of a box (outward +e_k), the in-face axes (i, j) with e_i x e_j = e_k.
_FACE_AXES = ((1, 2), (2, 0), (0, 1))


def _cube_faces(n: tuple[int, int, int], coords: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices/faces of the six grid faces of the cube with per-axis coordinate arrays.

    ``coords[k]`` are the n[k]+1 vertex coordinates along axis k, from -1 to 1
    (any monotone map); face k at +-1 uses ``coords[i]`` x ``coords[j]``.
    """
    verts, faces = [], []
    offset = 0
    for k in range(3):
        i, j = _FACE_AXES[k]
        ui, vj = np.meshgrid(coords[i], coords[j], indexing="ij")
        for sign in (1.0, -1.0):
            v = np.empty((ui.size, 3))
            v[:, i] = ui.ravel()
            v[:, j] = vj.ravel()
            v[:, k] = sign
            f = grid_faces(n[i], n[j])
            if sign < 0:
                f = f[:, ::-1]
            verts.append(v)
            faces.append(f + offset)
            offset += len(v)
    return weld(np.concatenate(verts), np.concatenate(faces))


class Sphere(FramedShape):
    """A sphere.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre.
    radius : float
        Radius (> 0).
    rotation : array_like, shape (3, 3), optional
        Orientation of the mesh and samples (the sphere itself is invariant).

    Notes
    -----
    ``implicit`` is the exact signed distance ``|x - c| - r`` with normal
    ``(x - c) / |x - c|``. The mesh is an equal-angle cube sphere; surfels use a
    spherical Fibonacci lattice with tangent-plane Voronoi radii.

    Example
    -------
    >>> s = Sphere(radius=2.0)
    >>> round(s.volume(), 6)
    33.510322
    """

    kind = "sphere"

    def __init__(self, center: Any = (0.0, 0.0, 0.0), radius: float = 1.0, rotation: Any = None) -> None:
        super().__init__(center, rotation)
        self.radius = positive_scalar(radius, "radius")

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "radius": self.radius}

    def size(self) -> float:
        return 2.0 * self.radius

    def area(self) -> float:
        return 4.0 * math.pi * self.radius**2

    def volume(self) -> float:
        return 4.0 / 3.0 * math.pi * self.radius**3

    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> Sphere:
        return Sphere(center, self.radius * factor, rotation)

    def _local_bounds_points(self) -> np.ndarray:
        return np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]) * self.radius

    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.linalg.norm(p, axis=1)
        n = np.zeros_like(p)
        ok = d > 0
        n[ok] = p[ok] / d[ok, None]
        n[~ok] = (0.0, 0.0, 1.0)
        return d - self.radius, n

    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        n = max(2, math.ceil(0.5 * math.pi * self.radius / spacing))
        t = np.tan(0.25 * math.pi * np.linspace(-1.0, 1.0, n + 1))
        t[0], t[-1] = -1.0, 1.0
        v, f = _cube_faces((n, n, n), [t, t, t])
        v = v / np.linalg.norm(v, axis=1, keepdims=True) * self.radius
        return v, f

    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, None]:
        # Hexagonal density: each sample owns an area sqrt(3)/2 * spacing^2.
        count = max(12, math.ceil(4.0 * math.pi * self.radius**2 / (math.sqrt(3.0) / 2.0 * spacing**2)))
        k = np.arange(count) + 0.5
        z = 1.0 - 2.0 * k / count
        phi = math.pi * (3.0 - math.sqrt(5.0)) * np.arange(count)
        rho = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        n = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], 1)
        return n * self.radius, n, None


class Box(FramedShape):
    """A box (cuboid).

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre.
    size : array_like, shape (3,) or float
        Full edge lengths along the local x, y, z axes (> 0).
    rotation : array_like, shape (3, 3), optional
        Local-to-world rotation (default: axis aligned).

    Notes
    -----
    ``implicit`` is the exact signed distance
    ``|max(q, 0)| + min(max_k q_k, 0)`` with ``q = |p| - size/2``; its gradient is
    exact except on the (measure-zero) medial surface. Surfels are sampled per face
    on a cell-centred grid with the exact face normal, so the sharp edges stay sharp;
    each radius is the half diagonal of its cell.

    Example
    -------
    >>> Box(size=(1, 2, 3)).volume()
    6.0
    """

    kind = "box"
    smooth = False

    def __init__(self, center: Any = (0.0, 0.0, 0.0), size: Any = (1.0, 1.0, 1.0), rotation: Any = None) -> None:
        super().__init__(center, rotation)
        s = np.asarray(size, dtype=np.float64) if np.ndim(size) else np.full(3, float(size))
        s = as_array(s, "size", (3,))
        if not np.all(s > 0):
            raise InputError(f"size: expected three positive edge lengths, got {s.tolist()}")
        self.size_xyz = s
        self.size_xyz.setflags(write=False)

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "size": self.size_xyz.tolist()}

    @property
    def half(self) -> np.ndarray:
        """Half edge lengths (3,)."""
        return 0.5 * self.size_xyz

    def size(self) -> float:
        return float(self.size_xyz.max())

    def area(self) -> float:
        a, b, c = self.size_xyz
        return float(2.0 * (a * b + b * c + c * a))

    def volume(self) -> float:
        return float(np.prod(self.size_xyz))

    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> Box:
        return Box(center, self.size_xyz * factor, rotation)

    def _local_bounds_points(self) -> np.ndarray:
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
        return signs * self.half

    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h = self.half
        sgn = np.where(p < 0, -1.0, 1.0)
        q = np.abs(p) - h
        outside = np.maximum(q, 0.0)
        dout = np.linalg.norm(outside, axis=1)
        qmax = q.max(axis=1)
        values = dout + np.minimum(qmax, 0.0)
        n = np.zeros_like(p)
        out = dout > 0
        n[out] = sgn[out] * outside[out] / dout[out, None]
        k = np.argmax(q[~out], axis=1)
        rows = np.flatnonzero(~out)
        n[rows, k] = sgn[rows, k]
        return values, n

    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        n = tuple(max(1, math.ceil(s / spacing)) for s in self.size_xyz)
        coords = [np.linspace(-1.0, 1.0, k + 1) for k in n]
        v, f = _cube_faces(n, coords)  # type: ignore[arg-type]
        return v * self.half, f

    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h = self.half
        pos, nrm, rad = [], [], []
        for k in range(3):
            i, j = _FACE_AXES[k]
            ni = max(1, math.ceil(self.size_xyz[i] / spacing))
            nj = max(1, math.ceil(self.size_xyz[j] / spacing))
            ci = (np.arange(ni) + 0.5) / ni * 2.0 - 1.0
            cj = (np.arange(nj) + 0.5) / nj * 2.0 - 1.0
            ui, vj = np.meshgrid(ci * h[i], cj * h[j], indexing="ij")
            r = 0.5 * math.hypot(self.size_xyz[i] / ni, self.size_xyz[j] / nj) * (1.0 + 1e-9)
            for sign in (1.0, -1.0):
                p = np.empty((ui.size, 3))
                p[:, i] = ui.ravel()
                p[:, j] = vj.ravel()
                p[:, k] = sign * h[k]
                nn = np.zeros_like(p)
                nn[:, k] = sign
                pos.append(p)
                nrm.append(nn)
                rad.append(np.full(len(p), r))
        return np.concatenate(pos), np.concatenate(nrm), np.concatenate(rad)
