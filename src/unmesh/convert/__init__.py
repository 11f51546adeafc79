"""Point cloud to textured triangle mesh (thesis chapter 6).

* :func:`reconstruct` — MLS implicit function on a narrow-band grid + marching cubes (6.1);
* :func:`simplify_to_error` / :func:`simplify_mesh` — topology-preserving QEM (6.1);
* :class:`ConvertOptions` — the two bounds and the output settings.
"""

from unmesh.convert.options import ConvertOptions
from unmesh.convert.reconstruct import reconstruct
from unmesh.convert.simplify import mesh_distance, simplify_mesh, simplify_to_error, topology

__all__ = ["ConvertOptions", "mesh_distance", "reconstruct", "simplify_mesh", "simplify_to_error", "topology"]
