"""Point cloud to textured triangle mesh (thesis chapter 6).

* :func:`to_textured_mesh` / :func:`convert_cloud` — the whole pipeline, with a report;
* :func:`reconstruct` — MLS implicit function on a narrow-band grid + marching cubes (6.1);
* :func:`simplify_to_error` / :func:`simplify_mesh` — topology-preserving QEM (6.1);
* :func:`render_patches` — adaptive per-triangle patches by EWA splatting (6.2.1);
* :func:`pack` — Algorithm 6.1 into power-of-two pages (6.3);
* :class:`TexturedMesh` — the result, drawable by :func:`unmesh.render.render`;
* :func:`write_textured` — OBJ + MTL + PNG or .glb, atomically as a set;
* :class:`ConvertOptions` — the two bounds and the output settings.

Example
-------
>>> import numpy as np
>>> from unmesh.surfels import SurfelCloud
>>> rng = np.random.default_rng(1)
>>> n = rng.normal(size=(3000, 3)); n /= np.linalg.norm(n, axis=1, keepdims=True)
>>> res = convert_cloud(SurfelCloud(n, n, radii=np.full(3000, 0.06)), ConvertOptions(faces=300))
>>> res.report["patches"]["triangles"] <= 300, res.report["reconstruction"]["boundary_edges"]
(True, 0)
"""

from unmesh.convert.export import write_glb, write_textured, write_textured_obj
from unmesh.convert.options import ConvertOptions
from unmesh.convert.packing import pack
from unmesh.convert.patches import render_patches
from unmesh.convert.pipeline import Conversion, cloud_from_mesh, convert_cloud, to_textured_mesh
from unmesh.convert.reconstruct import reconstruct
from unmesh.convert.simplify import mesh_distance, simplify_mesh, simplify_to_error, topology
from unmesh.convert.textured import TexturedMesh

__all__ = [
    "Conversion",
    "ConvertOptions",
    "TexturedMesh",
    "cloud_from_mesh",
    "convert_cloud",
    "mesh_distance",
    "pack",
    "reconstruct",
    "render_patches",
    "simplify_mesh",
    "simplify_to_error",
    "to_textured_mesh",
    "topology",
    "write_glb",
    "write_textured",
    "write_textured_obj",
]
