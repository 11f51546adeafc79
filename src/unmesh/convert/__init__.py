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
Convert a painted or scanned cloud and write it for Blender or a game engine (the doctest
of :func:`to_textured_mesh` runs the pipeline on a sphere)::

    res = convert_cloud(cloud, ConvertOptions(mesh_error=0.005))
    write_textured("model.glb", res.textured)      # or model.obj (+ .mtl + .png pages)

    $ unmesh convert scan.ply -o scan.obj --report report.json
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
