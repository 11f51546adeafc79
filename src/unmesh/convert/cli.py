"""``unmesh convert``: a surfel cloud (or the vertices of a scan) to a textured triangle mesh (ch. 6).

Examples::

    unmesh convert scan.ply -o scan.obj                          # OBJ + MTL + PNG pages
    unmesh convert scan.ply -o scan.glb --faces 10000 --report report.json
    unmesh convert igea.ply -o igea.obj --mesh-error 0.005 --texture-error 0.01 --no-normal-map

IN is a surfel PLY (points without normals get estimated normals and radii) or a
triangle mesh file (PLY/OBJ/OFF), whose vertices become the points (with the mesh's
vertex normals and estimated radii). The mesh follows the geometry (--mesh-error, relative
to the bounding-box diagonal, or --faces); each triangle gets a texture patch whose
size follows the colour (and normal) detail (--texture-error); patches are packed into
power-of-two atlas pages (at most --page-size). The normal map is written as ``norm`` and
``map_Bump`` in the MTL (tangent space, OpenGL convention) and as the glTF normalTexture.
All output files (and the report) are written as one atomic set.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

__all__ = ["register", "run"]


def register(sub: Any) -> None:
    p = sub.add_parser("convert", help="convert surfels to a textured triangle mesh (OBJ/GLB)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", metavar="IN", help="surfel PLY, or a mesh file whose vertices are the points")
    p.add_argument("-o", "--output", required=True, metavar="OUT.obj|OUT.glb", help="output mesh")
    bound = p.add_mutually_exclusive_group()
    bound.add_argument("--faces", type=int, metavar="N", help="target triangle count")
    bound.add_argument("--mesh-error", type=float, metavar="E", default=None,
                       help="largest mesh-surfel distance relative to the bounding-box diagonal (default 0.005)")
    p.add_argument("--texture-error", type=float, default=None, metavar="T",
                   help="patch error threshold, mean RGB distance (default 0.02)")
    p.add_argument("--normal-map", action=argparse.BooleanOptionalAction, default=True,
                   help="bake a tangent-space normal map (default on)")
    p.add_argument("--page-size", type=int, default=2048, metavar="N", help="largest atlas page edge (power of two)")
    p.add_argument("--mipmaps", action="store_true", help="also assemble half and quarter resolution pages")
    p.add_argument("--depth-map", action="store_true",
                   help="also bake a depth (displacement) texture (OBJ: disp; not in .glb)")
    p.add_argument("--report", metavar="FILE.json", help="write a JSON report")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json

    from unmesh import io
    from unmesh.convert.export import write_textured
    from unmesh.convert.options import ConvertOptions
    from unmesh.convert.pipeline import cloud_from_mesh, convert_cloud
    from unmesh.errors import InputError
    from unmesh.meshes import TriangleMesh

    out = Path(args.output)
    if out.suffix.lower() not in (".obj", ".glb"):
        raise InputError(f"--output: expected a .obj or .glb file, got {os.fspath(out)!r}")
    src = Path(args.input)
    if not src.exists():
        raise InputError(f"IN: no such file {os.fspath(src)!r}")
    kw: dict[str, Any] = {"normal_map": args.normal_map, "page_size": args.page_size, "mipmaps": args.mipmaps,
                          "depth_map": args.depth_map,
                          "progress": not args.no_progress}
    if args.faces is not None:
        kw["faces"] = args.faces
    if args.mesh_error is not None:
        kw["mesh_error"] = args.mesh_error
    if args.texture_error is not None:
        kw["texture_error"] = args.texture_error
    opt = ConvertOptions(**kw)
    obj = io.load(src)
    cloud = cloud_from_mesh(obj) if isinstance(obj, TriangleMesh) else io.load_surfels(src)
    res = convert_cloud(cloud, opt)
    extra = []
    if args.report:
        res.report["input"] = os.fspath(src)
        res.report["output"] = os.fspath(out)
        public = {k: v for k, v in res.report.items() if not k.startswith("_")}  # per-triangle arrays stay in memory
        extra.append((Path(args.report), json.dumps(_clean(public), indent=1) + "\n"))
    files = write_textured(out, res.textured, extra)
    r = res.report
    print(f"{r['points']} points -> {r['patches']['triangles']} triangles, "
          f"{len(r['atlas']['pages'])} page(s) {r['atlas']['pages']} filled {100 * r['atlas']['fill_total']:.1f} %, "
          f"{r['timings']['total']:.1f} s; wrote {', '.join(f.name for f in files)}")
    return 0


def _clean(o: Any) -> Any:
    import math

    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_clean(v) for v in o]
    if hasattr(o, "tolist"):
        return _clean(o.tolist())
    return o
