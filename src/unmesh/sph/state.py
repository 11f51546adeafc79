"""Particle state of an SPH simulation (thesis section 8.1, 8.2).

:class:`ParticleState` is the public snapshot of the simulated particles: what a
frame file holds and what :meth:`unmesh.sph.SPHSimulation.particles` returns.
The simulation itself keeps its working arrays sorted by grid cell for speed;
a snapshot is always in particle-id order (``ids`` ascending), so particle ``k``
of every frame is the same particle.

Phases: ``FLUID = 0``, ``SOLID = 1`` (eq. 8.34–8.36 switch between them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh._validate import as_array, as_points
from unmesh.errors import InputError
from unmesh.particles import Particles

__all__ = ["FLUID", "PLY_PROPERTIES", "SOLID", "ParticleState"]

#: Phase code of fluid particles (no elastic forces).
FLUID = 0
#: Phase code of solid particles (elastic lattice forces, section 8.2).
SOLID = 1

#: Per-vertex properties of frame files, in order (x y z come first).
PLY_PROPERTIES = ("vx", "vy", "vz", "density", "pressure", "temperature", "phase", "object")


@dataclass(frozen=True, eq=False, repr=False)
class ParticleState:
    """N simulated particles with their SPH attributes.

    Parameters
    ----------
    dim : int
        2 or 3. In 2D the z coordinates and velocities are zero.
    positions, velocities : array_like, shape (N, 3), float64
    masses, densities, pressures, temperatures : array_like, shape (N,), float64
    phases : array_like, shape (N,), int8
        ``FLUID`` (0) or ``SOLID`` (1).
    objects : array_like, shape (N,), int32
        Object id (index into the scene's objects).

    Example
    -------
    >>> s = ParticleState.empty(3, 2)
    >>> len(s), s.phase_counts()
    (2, {'fluid': 2, 'solid': 0})
    """

    dim: int
    positions: np.ndarray
    velocities: np.ndarray
    masses: np.ndarray
    densities: np.ndarray
    pressures: np.ndarray
    temperatures: np.ndarray
    phases: np.ndarray
    objects: np.ndarray

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise InputError(f"dim: expected 2 or 3, got {self.dim!r}")
        pos = as_points(self.positions, "positions")
        n = len(pos)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "velocities", as_points(self.velocities, "velocities", length=n))
        for name in ("masses", "densities", "pressures", "temperatures"):
            object.__setattr__(self, name, as_array(getattr(self, name), name, (None,), length=n))
        phases = as_array(self.phases, "phases", (None,), np.int8, finite=False, length=n)
        if np.any((phases != FLUID) & (phases != SOLID)):
            raise InputError("phases: expected 0 (fluid) or 1 (solid)")
        object.__setattr__(self, "phases", phases)
        object.__setattr__(self, "objects", as_array(self.objects, "objects", (None,), np.int32, finite=False, length=n))

    @classmethod
    def empty(cls, dim: int, n: int = 0) -> ParticleState:
        """``n`` fluid particles at the origin with unit mass and density (for tests)."""
        z = np.zeros((n, 3))
        return cls(dim, z, z.copy(), np.ones(n), np.ones(n), np.zeros(n), np.zeros(n), np.zeros(n, np.int8),
                   np.zeros(n, np.int32))

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def __repr__(self) -> str:
        return f"ParticleState(dim={self.dim}, {len(self)} particles, {self.phase_counts()})"

    def phase_counts(self) -> dict[str, int]:
        """``{"fluid": n0, "solid": n1}``."""
        solid = int(np.count_nonzero(self.phases == SOLID))
        return {"fluid": len(self) - solid, "solid": solid}

    def linear_momentum(self) -> np.ndarray:
        """Σ m v, shape (3,)."""
        return (self.masses[:, None] * self.velocities).sum(axis=0)

    def angular_momentum(self) -> np.ndarray:
        """Σ m x × v about the origin, shape (3,)."""
        return (self.masses[:, None] * np.cross(self.positions, self.velocities)).sum(axis=0)

    def kinetic_energy(self) -> float:
        """½ Σ m |v|²."""
        return float(0.5 * np.sum(self.masses * np.einsum("ij,ij->i", self.velocities, self.velocities)))

    def to_particles(self, radius: float | None = None) -> Particles:
        """As :class:`unmesh.particles.Particles` with the frame-file attributes.

        Attributes are ``vx vy vz density pressure temperature`` (float32 in files)
        and ``phase object`` (integers), the properties of ``frames/frame_NNNNN.ply``.
        """
        attrs = {
            "vx": self.velocities[:, 0], "vy": self.velocities[:, 1], "vz": self.velocities[:, 2],
            "density": self.densities, "pressure": self.pressures, "temperature": self.temperatures,
            "phase": self.phases.astype(np.uint8), "object": self.objects.astype(np.int32),
        }
        radii = None if radius is None else np.full(len(self), float(radius))
        return Particles(self.positions, radii, attrs)
