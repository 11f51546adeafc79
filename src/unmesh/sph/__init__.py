"""Weakly compressible SPH with connectivity-free elasticity (thesis chapter 8).

Fluids, elastic solids, and the transitions between them, without any stored
connectivity: solids are SPH particles whose neighbourhoods are fitted to a closest
packing every step (implicit rest state, section 8.2), so plasticity, fracture,
melting and freezing come out of the same particle model.

Modules
-------
:mod:`~unmesh.sph.simulation`
    :class:`SPHSimulation` (the :class:`unmesh.sim.Simulation` the runner drives),
    :class:`SPHConfig`, :class:`SPHObject`.
:mod:`~unmesh.sph.materials`
    :class:`Material`: Appendix F.2 parameters (``K, Γ, ρ0, ζ, μ, ξ, K_e, s``), Young's
    modulus and Poisson ratio, docking rates, conduction, melting and freezing rates.
:mod:`~unmesh.sph.fluid`
    Numpy references of density (8.4), pressure (8.15-8.16), pressure and viscous
    accelerations (8.17-8.18), XSPH (8.19).
:mod:`~unmesh.sph.elastic`
    Numpy references of lattice assignment (8.21), shape matching (8.23-8.24), goal
    positions (8.29-8.31), the least-squares strain and linear stress (8.2.2) and the
    exact momentum-conserving torque correction (replacing 8.32-8.33).
:mod:`~unmesh.sph.sampling`
    Hexagonal / cubic closest packing (8.20), lattice slots, nearest lattice point.
:mod:`~unmesh.sph.boundary`
    Boundary particles (Akinci et al. 2012) and analytic planes and boxes.
:mod:`~unmesh.sph.phase`
    Melting (8.35) and freezing (8.36) as Poisson processes (8.34), heat sources.
:mod:`~unmesh.sph.collisions`
    Penalty collisions between objects (8.37).
:mod:`~unmesh.sph.surface`
    Marching-cubes fluid surfaces and skinned solid surfaces (8.38).
:mod:`~unmesh.sph.scene`, :mod:`~unmesh.sph.cli`
    TOML scenes (``docs/sph_scene.md``) and ``unmesh sph SCENE.toml -o OUTDIR``.

The numba kernels (``_kernels``, ``_elastic_kernels`` with ``_polar_kernels`` and ``_slot_kernels``,
``_phase_kernels``) work on
particles sorted by grid cell and write only their own rows; each has a numpy
reference that the tests compare against.

Example
-------
>>> from unmesh.sph import Material, SPHConfig, SPHObject, SPHSimulation, box_planes
>>> from unmesh.sph.sampling import closest_packing
>>> water = SPHObject("water", closest_packing([0, 0, 0], [0.2, 0.4, 0], 0.02, 2), "water")
>>> sim = SPHSimulation(SPHConfig(dim=2, spacing=0.02, dt=1e-3, cfl=0.3), {"water": Material("water", stiffness=1000.0)},
...                     [water], planes=box_planes([0, 0, 0], [1, 1, 0], 2, open_top=True))
>>> while sim.time < 0.05:
...     _ = sim.step()
>>> state = sim.particles()
>>> len(state), bool(state.velocities[:, 0].max() > 0)   # the column starts to collapse
(190, True)
"""

from unmesh.sph.boundary import BoundaryParticles, Plane, box_planes, sample_boundary, wall_tables
from unmesh.sph.materials import Material
from unmesh.sph.phase import HeatSource
from unmesh.sph.scene import build_simulation
from unmesh.sph.simulation import SPHConfig, SPHObject, SPHSimulation
from unmesh.sph.state import FLUID, SOLID, ParticleState

__all__ = [
    "FLUID",
    "SOLID",
    "BoundaryParticles",
    "HeatSource",
    "Material",
    "ParticleState",
    "Plane",
    "SPHConfig",
    "SPHObject",
    "SPHSimulation",
    "box_planes",
    "build_simulation",
    "sample_boundary",
    "wall_tables",
]
