"""Triangle meshes (input to sampling, output of conversion and simulation surfaces)."""

from unmesh.meshes.triangles import TriangleMesh

__all__ = ["TriangleMesh"]
