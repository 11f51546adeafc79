"""Cylinder and torus: closed solids of revolution about their local z axis."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh._validate import positive_scalar
from unmesh.errors import InputError
from unmesh.shapes._meshing import cell_radii, grid_faces, polar_cells, polar_rings, weld
from unmesh.shapes.base import FramedShape, rotation_from_axis

__all__ = ["Cylinder", "Torus"]


def _frame(axis: Any, rotation: Any, name: str = "axis") -> Any:
    if rotation is not None and axis is not None:
        raise InputError(f"{name}: give {name} or rotation, not both")
    if rotation is not None:
        return rotation
    return rotation_from_axis((0.0, 1.0, 0.0) if axis is None else axis, name)


def _radial(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from the z axis (N,) and unit radial direction (N,3) (x on the axis)."""
    rho = np.hypot(p[:, 0], p[:, 1])
    e = np.zeros_like(p)
    ok = rho > 0
    e[ok, 0] = p[ok, 0] / rho[ok]
    e[ok, 1] = p[ok, 1] / rho[ok]
    e[~ok, 0] = 1.0
    return rho, e


class Cylinder(FramedShape):
    """A closed cylinder (side and two flat caps).

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre (midpoint of the axis segment).
    radius : float
        Radius (> 0).
    height : float
        Full length along the axis (> 0).
    axis : array_like, shape (3,), optional
        Axis direction, default +y. Local frame: the axis is local z.
    rotation : array_like, shape (3, 3), optional
        Local-to-world rotation instead of ``axis``.

    Notes
    -----
    ``implicit`` is the exact signed distance of the capped cylinder, with
    ``q = (rho - r, |z| - h/2)``: ``|max(q, 0)| + min(max(q), 0)``. Surfels are
    sampled separately on the side and on each cap (cell-centred grids with exact
    normals), keeping the rim edges sharp.

    Example
    -------
    >>> c = Cylinder(radius=1.0, height=2.0)
    >>> round(c.volume(), 6), c.axis.tolist()
    (6.283185, [0.0, 1.0, 0.0])
    """

    kind = "cylinder"
    smooth = False

    def __init__(self, center: Any = (0.0, 0.0, 0.0), radius: float = 0.5, height: float = 1.0,
                 axis: Any = None, rotation: Any = None) -> None:
        super().__init__(center, _frame(axis, rotation))
        self.radius = positive_scalar(radius, "radius")
        self.height = positive_scalar(height, "height")

    @property
    def axis(self) -> np.ndarray:
        """Unit axis direction (3,) in world coordinates."""
        return self.rotation[:, 2].copy()

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "radius": self.radius, "height": self.height, "axis": self.axis.tolist()}

    def size(self) -> float:
        return max(2.0 * self.radius, self.height)

    def area(self) -> float:
        return 2.0 * math.pi * self.radius * self.height + 2.0 * math.pi * self.radius**2

    def volume(self) -> float:
        return math.pi * self.radius**2 * self.height

    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> Cylinder:
        return Cylinder(center, self.radius * factor, self.height * factor, rotation=rotation)

    def _local_bounds_points(self) -> np.ndarray:
        t = np.linspace(0, 2 * np.pi, 721)
        ring = np.stack([self.radius * np.cos(t), self.radius * np.sin(t), np.zeros_like(t)], 1)
        h = 0.5 * self.height
        return np.concatenate([ring + np.array([0.0, 0.0, h]), ring - np.array([0.0, 0.0, h])])

    def bounds(self) -> np.ndarray:
        # Exact: the cap circles' extent along world axis k is r * sqrt(1 - a_k^2).
        a = self.axis
        ext = self.radius * np.sqrt(np.maximum(0.0, 1.0 - a * a)) + 0.5 * self.height * np.abs(a)
        return np.stack([self.center - ext, self.center + ext])

    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rho, er = _radial(p)
        h = 0.5 * self.height
        qr = rho - self.radius
        qz = np.abs(p[:, 2]) - h
        sz = np.where(p[:, 2] < 0, -1.0, 1.0)
        o_r, o_z = np.maximum(qr, 0.0), np.maximum(qz, 0.0)
        dout = np.hypot(o_r, o_z)
        values = dout + np.minimum(np.maximum(qr, qz), 0.0)
        gr = np.where(dout > 0, o_r / np.where(dout > 0, dout, 1.0), (qr >= qz).astype(float))
        gz = np.where(dout > 0, o_z / np.where(dout > 0, dout, 1.0), (qr < qz).astype(float))
        n = er * gr[:, None]
        n[:, 2] = sz * gz
        return values, n

    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        r, h = self.radius, 0.5 * self.height
        cap_v, cap_f = polar_rings(r, spacing)
        n_around = max(8, math.ceil(2 * math.pi * r / spacing))
        n_h = max(1, math.ceil(self.height / spacing))
        th = 2 * np.pi * np.arange(n_around) / n_around
        frac = 1.0  # polar_rings' outer ring uses radius * (m / m) == radius * 1.0: same floats, welded
        z = np.linspace(-h, h, n_h + 1)
        ang, zz = np.meshgrid(th, z, indexing="ij")
        side = np.stack([r * frac * np.cos(ang).ravel(), r * frac * np.sin(ang).ravel(), zz.ravel()], 1)
        side_f = grid_faces(n_around, n_h, wrap_u=True)
        top = cap_v + np.array([0.0, 0.0, h])
        bottom = cap_v + np.array([0.0, 0.0, -h])
        verts = np.concatenate([side, top, bottom])
        faces = np.concatenate([side_f, cap_f + len(side), cap_f[:, ::-1] + len(side) + len(top)])
        return weld(verts, faces)

    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r, h = self.radius, 0.5 * self.height
        n_around = max(3, math.ceil(2 * math.pi * r / spacing))
        n_h = max(1, math.ceil(self.height / spacing))
        dth, dz = 2 * math.pi / n_around, self.height / n_h
        i, j = np.meshgrid(np.arange(n_around), np.arange(n_h), indexing="ij")
        lo = np.stack([i.ravel() * dth, -h + j.ravel() * dz], 1)
        hi = lo + np.array([dth, dz])
        mid = 0.5 * (lo + hi)

        def side(u: np.ndarray, v: np.ndarray) -> np.ndarray:
            return np.stack([r * np.cos(u), r * np.sin(u), v], 1)

        pos = [side(mid[:, 0], mid[:, 1])]
        nrm = [np.stack([np.cos(mid[:, 0]), np.sin(mid[:, 0]), np.zeros(len(mid))], 1)]
        rad = [cell_radii(side, mid, lo, hi)]
        pc, plo, phi = polar_cells(r, spacing)
        for sign in (1.0, -1.0):

            def cap(u: np.ndarray, v: np.ndarray, s: float = sign) -> np.ndarray:
                return np.stack([u * np.cos(v), u * np.sin(v), np.full(len(u), s * h)], 1)

            pos.append(cap(pc[:, 0], pc[:, 1]))
            nrm.append(np.tile([0.0, 0.0, sign], (len(pc), 1)))
            rad.append(cell_radii(cap, pc, plo, phi))
        return np.concatenate(pos), np.concatenate(nrm), np.concatenate(rad)


class Torus(FramedShape):
    """A ring torus around its axis.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre.
    major : float
        Distance from the centre to the tube centre circle (> minor).
    minor : float
        Tube radius (> 0).
    axis : array_like, shape (3,), optional
        Symmetry axis, default +y (the torus lies flat). Local frame: axis = local z.
    rotation : array_like, shape (3, 3), optional
        Local-to-world rotation instead of ``axis``.

    Notes
    -----
    ``implicit`` is the exact signed distance ``|(rho - R, z)| - r``. Area
    ``4 pi^2 R r``, volume ``2 pi^2 R r^2``.

    Example
    -------
    >>> t = Torus(major=1.0, minor=0.25)
    >>> round(t.area(), 6)
    9.869604
    """

    kind = "torus"

    def __init__(self, center: Any = (0.0, 0.0, 0.0), major: float = 1.0, minor: float = 0.35,
                 axis: Any = None, rotation: Any = None) -> None:
        super().__init__(center, _frame(axis, rotation))
        self.major = positive_scalar(major, "major")
        self.minor = positive_scalar(minor, "minor")
        if not self.minor < self.major:
            raise InputError(f"minor: expected a tube radius smaller than major={self.major} (a ring torus), got {self.minor}")

    @property
    def axis(self) -> np.ndarray:
        """Unit symmetry axis (3,) in world coordinates."""
        return self.rotation[:, 2].copy()

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "major": self.major, "minor": self.minor, "axis": self.axis.tolist()}

    def size(self) -> float:
        return 2.0 * (self.major + self.minor)

    def area(self) -> float:
        return 4.0 * math.pi**2 * self.major * self.minor

    def volume(self) -> float:
        return 2.0 * math.pi**2 * self.major * self.minor**2

    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> Torus:
        return Torus(center, self.major * factor, self.minor * factor, rotation=rotation)

    def _local_bounds_points(self) -> np.ndarray:
        raise NotImplementedError  # bounds() is exact below

    def bounds(self) -> np.ndarray:
        a = self.axis
        # Support function of (circle of radius R) + (ball of radius r) along world axis k.
        ext = self.major * np.sqrt(np.maximum(0.0, 1.0 - a * a)) + self.minor
        return np.stack([self.center - ext, self.center + ext])

    def _param(self, phi: np.ndarray, theta: np.ndarray) -> np.ndarray:
        w = self.major + self.minor * np.cos(theta)
        return np.stack([w * np.cos(phi), w * np.sin(phi), self.minor * np.sin(theta)], 1)

    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rho, er = _radial(p)
        qr = rho - self.major
        qz = p[:, 2]
        d = np.hypot(qr, qz)
        ok = d > 0
        gr = np.where(ok, qr / np.where(ok, d, 1.0), 1.0)
        gz = np.where(ok, qz / np.where(ok, d, 1.0), 0.0)
        n = er * gr[:, None]
        n[:, 2] = gz
        return d - self.minor, n

    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        nu = max(8, math.ceil(2 * math.pi * (self.major + self.minor) / spacing))
        nv = max(6, math.ceil(2 * math.pi * self.minor / spacing))
        phi, theta = np.meshgrid(2 * np.pi * np.arange(nu) / nu, 2 * np.pi * np.arange(nv) / nv, indexing="ij")
        verts = self._param(phi.ravel(), theta.ravel())
        return verts, grid_faces(nu, nv, wrap_u=True, wrap_v=True)

    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        R, r = self.major, self.minor
        nv = max(3, math.ceil(2 * math.pi * r / spacing))
        dth = 2 * math.pi / nv
        centers, lo, hi = [], [], []
        for j in range(nv):
            t0 = j * dth
            # Ring length at the widest point of the cell decides the count.
            w = R + r * max(math.cos(t0), math.cos(t0 + dth), 1.0 if t0 <= 0 <= t0 + dth else -1.0)
            nu = max(3, math.ceil(2 * math.pi * w / spacing))
            dph = 2 * math.pi / nu
            ph0 = dph * (np.arange(nu) + 0.5 * (j % 2))
            lo.append(np.stack([ph0, np.full(nu, t0)], 1))
            hi.append(np.stack([ph0 + dph, np.full(nu, t0 + dth)], 1))
        lo_a, hi_a = np.concatenate(lo), np.concatenate(hi)
        centers = 0.5 * (lo_a + hi_a)
        pos = self._param(centers[:, 0], centers[:, 1])
        c_ph, c_th = centers[:, 0], centers[:, 1]
        nrm = np.stack([np.cos(c_th) * np.cos(c_ph), np.cos(c_th) * np.sin(c_ph), np.sin(c_th)], 1)
        return pos, nrm, cell_radii(self._param, centers, lo_a, hi_a)
