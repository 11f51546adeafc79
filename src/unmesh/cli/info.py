"""``unmesh info FILE``: counts, bounds and attributes of a surfel or mesh file."""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["register", "run"]


def register(sub: Any) -> None:
    p = sub.add_parser("info", help="describe a surfel cloud or mesh file", description=__doc__)
    p.add_argument("file", help="PLY, OBJ or OFF file")
    p.set_defaults(func=run)


def describe(obj: Any) -> list[str]:
    """Lines describing a SurfelCloud or TriangleMesh."""
    import numpy as np

    from unmesh.meshes import TriangleMesh
    from unmesh.surfels import SurfelCloud

    lines: list[str] = []
    if isinstance(obj, SurfelCloud):
        lines.append(f"type: surfel cloud ({'elliptical' if obj.is_elliptical else 'circular'})")
        lines.append(f"surfels: {len(obj)}")
        if len(obj):
            r = np.asarray(obj.radii)
            lines.append(f"radius: min {r.min():.6g}  mean {r.mean():.6g}  max {r.max():.6g}")
    elif isinstance(obj, TriangleMesh):
        lines.append("type: triangle mesh")
        lines.append(f"vertices: {len(obj.vertices)}")
        lines.append(f"faces: {len(obj.faces)}")
        lines.append(f"boundary edges: {len(obj.boundary_edges())}")
        lines.append(f"area: {obj.area():.6g}")
        extras = [n for n in ("uv", "vertex_normals", "vertex_colors", "texture", "normal_map") if getattr(obj, n) is not None]
        if extras:
            lines.append("per-vertex data: " + ", ".join(extras))
    b = obj.bounds()
    if np.all(np.isfinite(b)):
        lines.append("bounds: min " + " ".join(f"{x:.6g}" for x in b[0]) + "  max " + " ".join(f"{x:.6g}" for x in b[1]))
    attrs = getattr(obj, "attributes", {})
    if attrs:
        lines.append("attributes: " + ", ".join(f"{k} {v.dtype}{list(v.shape[1:]) or ''}" for k, v in sorted(attrs.items())))
    return lines


def run(args: argparse.Namespace) -> int:
    from unmesh import io

    obj = io.load(args.file)
    print(f"file: {args.file}")
    for line in describe(obj):
        print(line)
    return 0
