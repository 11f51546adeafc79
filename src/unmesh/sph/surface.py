"""Surfaces of SPH results (thesis section 8.2.7).

Fluids
    Marching cubes (:func:`unmesh.meshes.marching_cubes`) of the SPH density field
    ``ρ(x) = Σ_j m_j W(x − x_j)`` (poly6, eq. 8.4) sampled on a grid, at half the rest
    density; vertices are at the level of the grid's trilinear interpolant (float64).
Solids
    A surface mesh (or surfel cloud) skinned to the particles (eq. 8.38): each
    vertex ``s`` stores its rest offsets ``s⁰_i = s − x⁰_i`` to the nearby particles
    of its object; per frame every particle predicts ``s_i = x_i + F_i s⁰_i`` with
    its lattice deformation ``F_i = A_i A_i⁰⁻¹`` (eq. 8.23) and the predictions are
    averaged with the SPH weights ``W(‖s⁰_i‖) V_i`` (normalised, so vertices near
    the surface, whose kernel sums are incomplete, stay in place). Particles that
    melted no longer carry the skin; vertices left without support are dropped.

Example
-------
>>> import numpy as np
>>> from unmesh.sph.sampling import closest_packing
>>> x = closest_packing([-0.2, -0.2, -0.2], [0.2, 0.2, 0.2], 0.04, 3)
>>> mesh = fluid_surface(x, np.full(len(x), 5.4e-5), rest_density=1.0, h=0.08)
>>> bool(np.all(np.abs(mesh.vertices) < 0.3))
True
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from unmesh._validate import as_array, as_points, positive_scalar
from unmesh.kernels._kernels import poly6_3d
from unmesh.meshes import TriangleMesh, marching_cubes

__all__ = ["Skin", "density_grid", "fluid_surface", "write_surfaces"]


@njit(cache=True)
def _splat(x, m, h, lower, step, shape, out):
    """Add ``m_j W(node − x_j)`` of every particle to the grid nodes (serial)."""
    reach = int(np.ceil(h / step))
    for j in range(x.shape[0]):
        c0 = int((x[j, 0] - lower[0]) / step)
        c1 = int((x[j, 1] - lower[1]) / step)
        c2 = int((x[j, 2] - lower[2]) / step)
        for a in range(max(c0 - reach, 0), min(c0 + reach + 1, shape[0])):
            d0 = lower[0] + a * step - x[j, 0]
            for b in range(max(c1 - reach, 0), min(c1 + reach + 1, shape[1])):
                d1 = lower[1] + b * step - x[j, 1]
                for c in range(max(c2 - reach, 0), min(c2 + reach + 1, shape[2])):
                    d2 = lower[2] + c * step - x[j, 2]
                    r2 = d0 * d0 + d1 * d1 + d2 * d2
                    if r2 < h * h:
                        out[a, b, c] += m[j] * poly6_3d(r2, h)


def density_grid(positions: Any, masses: Any, h: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """SPH density (8.4) sampled on a regular grid covering the particles plus ``h``.

    Returns
    -------
    grid : ndarray (nx, ny, nz)
    lower : ndarray (3,)
        Position of node (0, 0, 0); node ``(a, b, c)`` is at ``lower + step·(a, b, c)``.

    Example
    -------
    >>> g, lo = density_grid([[0.0, 0, 0]], [1.0], 1.0, 0.5)
    >>> g.shape, round(float(g.max()), 4)
    ((5, 5, 5), 1.5667)
    """
    x = as_points(positions)
    m = as_array(masses, "masses", (None,), length=len(x))
    hh = positive_scalar(h, "h")
    st = positive_scalar(step, "step")
    lower = x.min(axis=0) - hh
    upper = x.max(axis=0) + hh
    shape = np.floor((upper - lower) / st).astype(np.int64) + 1
    grid = np.zeros(tuple(shape))
    _splat(x, m, hh, lower, st, shape, grid)
    return grid, lower


def fluid_surface(positions: Any, masses: Any, rest_density: float, h: float, step: float | None = None,
                  level: float = 0.5) -> TriangleMesh:
    """Marching-cubes iso-surface ``ρ = level·ρ0`` of the particles' density field (3D).

    Parameters
    ----------
    positions : array_like (N, 3)
    masses : array_like (N,)
    rest_density : float
    h : float
        Kernel support.
    step : float, optional
        Grid spacing (default ``h/4``, i.e. half the particle spacing for ``h = 2d``).
    level : float
        Iso-level as a fraction of the rest density.

    Returns
    -------
    TriangleMesh
        Empty (no faces) when there are no particles or the density nowhere exceeds the level.

    Example
    -------
    >>> from unmesh.sph.sampling import closest_packing
    >>> x = closest_packing([0, 0, 0], [0.2, 0.2, 0.2], 0.02, 3)
    >>> len(fluid_surface(x, np.full(len(x), 0.02**3 / np.sqrt(2)), 1.0, 0.04).faces) > 0
    True
    """
    x = as_points(positions)
    if len(x) == 0:
        return TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    st = h / 4.0 if step is None else positive_scalar(step, "step")
    grid, lower = density_grid(x, masses, h, st)
    # zero padding closes the surface where the grid ends (the density is 0 there)
    return marching_cubes(np.pad(grid, 1), lower - st, st, level * rest_density, inside="above")


@dataclass(frozen=True, eq=False)
class Skin:
    """A surface mesh bound to the particles of one object (eq. 8.38).

    Parameters
    ----------
    mesh : TriangleMesh
        Rest-state surface.
    vertex : ndarray (P,) int64
        Vertex of each binding.
    particle : ndarray (P,) int64
        Particle id of each binding.
    offset : ndarray (P, 3)
        Rest offset ``s⁰`` expressed in the particle's lattice frame (``A⁰⁻¹ (s − x⁰)``).
    weight : ndarray (P,)
        ``W(‖s − x⁰‖) V``.

    Example
    -------
    >>> from unmesh.shapes import Box
    >>> from unmesh.sph.sampling import sample_shape
    >>> box = Box(size=(0.2, 0.2, 0.2))
    >>> x = sample_shape(box, 0.05, 3)
    >>> skin = Skin.bind(box.mesh(0.05), x, np.arange(len(x)), np.ones(len(x)),
    ...                  np.repeat(np.eye(3)[None], len(x), 0), 0.1)
    >>> moved = skin.deform(x + 1.0, np.repeat(np.eye(3)[None], len(x), 0), np.ones(len(x)))
    >>> bool(np.allclose(moved.vertices, box.mesh(0.05).vertices + 1.0))
    True
    """

    mesh: TriangleMesh
    vertex: np.ndarray
    particle: np.ndarray
    offset: np.ndarray
    weight: np.ndarray

    @classmethod
    def bind(cls, mesh: TriangleMesh, positions: np.ndarray, ids: np.ndarray, volumes: np.ndarray,
             a_rest: np.ndarray, h: float) -> Skin:
        """Bind every vertex to the particles within ``h`` (or its nearest particle).

        ``positions`` (K, 3), ``ids`` (K,), ``volumes`` (K,) and ``a_rest`` (K, 3, 3)
        describe the object's particles at rest; ``ids`` index the id-ordered arrays
        passed to :meth:`deform`.
        """
        from unmesh.kernels import poly6
        from unmesh.spatial import knn, radius_neighbors

        verts = mesh.vertices
        off, ind = radius_neighbors(positions, h, queries=verts)
        counts = np.diff(off)
        vtx = np.repeat(np.arange(len(verts)), counts)
        part = ind.copy()
        lonely = np.flatnonzero(counts == 0)
        if len(lonely):
            _, nn = knn(positions, 1, queries=verts[lonely])
            vtx = np.concatenate([vtx, lonely])
            part = np.concatenate([part, nn[:, 0]])
        rel = verts[vtx] - positions[part]
        w = np.asarray(poly6(np.linalg.norm(rel, axis=1), h, 3)) * volumes[part]
        w = np.where(w > 0, w, 1e-12 * volumes[part])  # nearest-particle fallback keeps a tiny weight
        local = np.einsum("kba,kb->ka", a_rest[part], rel)  # A0^-1 rel with A0 a rotation
        return cls(mesh, vtx, ids[part], local, w)

    def deform(self, positions: np.ndarray, amat: np.ndarray, active: np.ndarray) -> TriangleMesh:
        """The skinned mesh for current particle positions/lattice transforms (id-indexed arrays)."""
        pred = positions[self.particle] + np.einsum("kab,kb->ka", amat[self.particle], self.offset)
        w = self.weight * active[self.particle]
        nv = len(self.mesh.vertices)
        wsum = np.bincount(self.vertex, weights=w, minlength=nv)
        acc = np.stack([np.bincount(self.vertex, weights=w * pred[:, k], minlength=nv) for k in range(3)], axis=1)
        ok = wsum > 0
        verts = self.mesh.vertices.copy()
        verts[ok] = acc[ok] / wsum[ok, None]
        faces = self.mesh.faces[np.all(ok[self.mesh.faces], axis=1)]
        keep = np.zeros(nv, bool)
        keep[faces.ravel()] = True
        remap = np.cumsum(keep) - 1
        return TriangleMesh(verts[keep], remap[faces])


def write_surfaces(sim: Any, outdir: Path, frame: int) -> None:
    """Deprecated: use :meth:`unmesh.sph.SPHSimulation.write_surfaces` (``sim.write_surfaces(outdir, frame)``).

    Kept so that old imports keep working; this module no longer knows the simulation
    (``sph.simulation`` imports ``sph.surface``, never the other way round).
    """
    warnings.warn("unmesh.sph.surface.write_surfaces(sim, outdir, frame) is deprecated; "
                  "use sim.write_surfaces(outdir, frame)", DeprecationWarning, stacklevel=2)
    sim.write_surfaces(outdir, frame)
