"""unmesh: modeling and animation with relaxed connectivity.

Point-sampled surfaces (surfels, MLS, EWA splatting), CSG, painting, conversion to
meshes, point-sampled thin shells, visco-elastic SPH and FEM on convex polyhedra,
after M. Wicke, *Modeling and Animation with Relaxed Connectivity Requirements*,
ETH Zurich 2007.

Example
-------
>>> import unmesh
>>> cloud = unmesh.SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.1])
>>> len(cloud)
1
"""

from unmesh import errors
from unmesh._version import __version__
from unmesh.meshes import TriangleMesh
from unmesh.particles import Particles
from unmesh.surfels import SurfelCloud

__all__ = ["Particles", "SurfelCloud", "TriangleMesh", "__version__", "errors"]
