"""Linear FEM on arbitrary convex polyhedra (thesis chapter 9).

Mean value shape functions (9.8–9.10) on convex polyhedral elements, heuristic
element integration (9.17–9.19) with a consistency correction, lumped masses
(9.21), stiffness warping with Horn's rotations and implicit Euler (9.20, 9.1.4),
element splitting and progressive cutting (9.3), sliver removal (9.2), VTU/PVD
output, scene files and the ``unmesh fem`` command (docs/fem_scene.md).

Modules: :mod:`~unmesh.fem.mesh` (PolyMesh), :mod:`~unmesh.fem.builders`,
:mod:`~unmesh.fem.mvc`, :mod:`~unmesh.fem.integration`, :mod:`~unmesh.fem.assembly`,
:mod:`~unmesh.fem.rotations`, :mod:`~unmesh.fem.dynamics`, :mod:`~unmesh.fem.solvers`,
:mod:`~unmesh.fem.editor`, :mod:`~unmesh.fem.cutting`, :mod:`~unmesh.fem.slivers`,
:mod:`~unmesh.fem.events`, :mod:`~unmesh.fem.vtk_io`, :mod:`~unmesh.fem.scene`,
:mod:`~unmesh.fem.simulation`.

Example
-------
>>> import numpy as np
>>> from unmesh.fem import hex_grid, solve_static, stiffness_matrix
>>> mesh = hex_grid((4, 1, 1), size=(4, 1, 1))
>>> stretch = np.c_[0.1 * mesh.points[:, 0], np.zeros((mesh.n_nodes, 2))]  # uniaxial, nu = 0
>>> f = (stiffness_matrix(mesh, 1.0, 0.0) @ stretch.ravel()).reshape(-1, 3)  # consistent end load
>>> u = solve_static(mesh, 1.0, 0.0, np.flatnonzero(mesh.points[:, 0] == 0), f)
>>> bool(np.allclose(u, stretch))
True
"""

from unmesh.fem.assembly import (
    constitutive_matrix,
    element_stiffness,
    lame_parameters,
    lumped_masses,
    solve_static,
    stiffness_matrix,
)
from unmesh.fem.builders import convex_polyhedron, hex_grid, polymesh_from_faces, tet_mesh, tetrahedralize, voronoi_foam
from unmesh.fem.cutting import PlaneCut, PolygonCut, apply_cuts, cut_by_plane, cut_by_polygon, split_element
from unmesh.fem.dynamics import Dynamics, Ground, Load, Prescribed
from unmesh.fem.integration import ElementIntegration, IntegrationRule, integrate_elements
from unmesh.fem.mesh import PolyMesh
from unmesh.fem.mvc import mean_value_coordinates
from unmesh.fem.rotations import horn_rotations
from unmesh.fem.scene import build_simulation
from unmesh.fem.slivers import find_slivers, remove_slivers

__all__ = [
    "Dynamics",
    "ElementIntegration",
    "Ground",
    "IntegrationRule",
    "Load",
    "PlaneCut",
    "PolyMesh",
    "PolygonCut",
    "Prescribed",
    "apply_cuts",
    "build_simulation",
    "constitutive_matrix",
    "convex_polyhedron",
    "cut_by_plane",
    "cut_by_polygon",
    "element_stiffness",
    "find_slivers",
    "hex_grid",
    "horn_rotations",
    "integrate_elements",
    "lame_parameters",
    "lumped_masses",
    "mean_value_coordinates",
    "polymesh_from_faces",
    "remove_slivers",
    "solve_static",
    "split_element",
    "stiffness_matrix",
    "tet_mesh",
    "tetrahedralize",
    "voronoi_foam",
]
