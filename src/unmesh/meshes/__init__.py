"""Triangle meshes (input to sampling, output of conversion and simulation surfaces) and marching cubes."""

from unmesh.meshes.marching import marching_cubes
from unmesh.meshes.triangles import TriangleMesh

__all__ = ["TriangleMesh", "marching_cubes"]
