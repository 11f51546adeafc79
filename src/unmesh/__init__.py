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

import os as _os

# numba's OpenMP threading layer (libgomp) lets an idle worker spin 300,000 rounds after
# every parallel region before it sleeps. On cores shared with other busy processes the
# spinning worker takes the core the computation needs: with two CPU-bound processes beside
# it, a shell step of Fig. 7.5 took 16-89 ms per frame instead of ~4 ms. 30,000 rounds keep
# the speed on idle cores (see unmesh._threads). libgomp reads the variable when numba
# first loads it; a value the user set is kept.
_os.environ.setdefault("GOMP_SPINCOUNT", "30000")

from unmesh import errors
from unmesh._version import __version__
from unmesh.meshes import TriangleMesh
from unmesh.particles import Particles
from unmesh.surfels import SurfelCloud

__all__ = ["Particles", "SurfelCloud", "TriangleMesh", "__version__", "errors"]
