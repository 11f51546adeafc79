"""Point-sampled thin shells with fibers, plasticity, fracture and surface animation (thesis ch. 7).

A dense surfel cloud is simulated as a thin shell without a mesh: simulation nodes are
chosen by clustering (7.2), each node gets a neighbourhood and *fibers* -- natural cubic
splines through three nodes (7.2.1, Appendix B) -- which measure stretch (arc length) and
bending (the tangent angle theta). Membrane and bending energies (7.5-7.11) give forces
(7.12-7.17), integrated with velocity Verlet (7.18); plasticity, fracture with crack
planes and visibility, weakening and anisotropy (7.3) act per fiber; the dense surface
follows the nodes by local-frame skinning (7.4).

Modules
-------
- :mod:`~unmesh.shells.fibers`: spline, arc length, tangent angle and their gradients.
- :mod:`~unmesh.shells.nodes`, :mod:`~unmesh.shells.topology`: nodes, neighbourhoods, fibers.
- :mod:`~unmesh.shells.energy` (numpy reference), :mod:`~unmesh.shells.forces` (numba).
- :mod:`~unmesh.shells.plasticity`, :mod:`~unmesh.shells.fracture`, :mod:`~unmesh.shells.material`.
- :mod:`~unmesh.shells.dynamics`: colliders, gravity, pressure, pulling forces, handles.
- :mod:`~unmesh.shells.skinning`: surface animation and discontinuity surfels.
- :mod:`~unmesh.shells.simulation`: :class:`ShellSimulation` for :func:`unmesh.sim.run`.
- :mod:`~unmesh.shells.scene`: TOML scenes (``unmesh shell``; see ``docs/shell_scene.md``).

Example
-------
>>> from unmesh.shells import FiberState, elastic_forces, grid_sheet
>>> x, topo = grid_sheet(6, 6, spacing=0.1)
>>> rest = FiberState.at_rest(x, topo)
>>> f = elastic_forces(x * 1.02, topo, rest, ks=100.0, kb=10.0)
>>> bool(abs(f.forces.sum(axis=0)).max() < 1e-9)
True
"""

from unmesh.shells.dynamics import Gravity, Handle, PlaneCollider, Pressure, Pull, SphereCollider
from unmesh.shells.energy import FiberState, elastic_energy, elastic_forces_reference, umbrella_normals
from unmesh.shells.fibers import (
    arc_length,
    arc_length_gradient,
    bending_angle,
    bending_angle_gradient,
    evaluate,
    spline_coefficients,
    tangents,
    thesis_bending_angle,
)
from unmesh.shells.forces import ForceResult, elastic_forces
from unmesh.shells.fracture import CrackSet
from unmesh.shells.material import Anisotropy, MaterialRegion, ShellMaterial
from unmesh.shells.nodes import build_topology, create_fibers, grid_sheet, node_neighborhoods, select_nodes
from unmesh.shells.plasticity import Plasticity
from unmesh.shells.scene import build_shell_simulation, build_simulation
from unmesh.shells.simulation import ShellSimulation, stable_time_step
from unmesh.shells.skinning import SkinnedSurface
from unmesh.shells.topology import ShellTopology

__all__ = [
    "Anisotropy",
    "CrackSet",
    "FiberState",
    "ForceResult",
    "Gravity",
    "Handle",
    "MaterialRegion",
    "PlaneCollider",
    "Plasticity",
    "Pressure",
    "Pull",
    "ShellMaterial",
    "ShellSimulation",
    "ShellTopology",
    "SkinnedSurface",
    "SphereCollider",
    "arc_length",
    "arc_length_gradient",
    "bending_angle",
    "bending_angle_gradient",
    "build_shell_simulation",
    "build_simulation",
    "build_topology",
    "create_fibers",
    "elastic_energy",
    "elastic_forces",
    "elastic_forces_reference",
    "evaluate",
    "grid_sheet",
    "node_neighborhoods",
    "select_nodes",
    "spline_coefficients",
    "stable_time_step",
    "tangents",
    "thesis_bending_angle",
    "umbrella_normals",
]
