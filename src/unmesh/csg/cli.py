"""``unmesh csg``: render a CSG scene of surfel patches with sharp edges (chapter 4).

Examples::

    unmesh csg scene.toml -o out.png --size 800x600
    unmesh csg icosahedron -o ico.png          # a shipped scene by name
    unmesh csg scene.toml -o out.png --classify classes.png
    unmesh csg scene.toml -o spin.mp4 --turntable 120
    unmesh csg carve.toml -o carve.mp4          # a scene with [animation]: dynamic CSG

The scene format is in ``docs/csg_scene.md``. The camera and output options are those of
``unmesh render`` (a default camera frames the patches); ``--buffers DIR`` writes the same
``depth.npy``, ``normal.npy``, ``coverage.npy`` and ``weight.npy``. ``--classify OUT.png``
also draws every surfel unclipped, coloured by its class (4.1.2, Fig. 4.4): surface blue, edge
grey, outside red.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from unmesh.render.cli import add_camera_arguments

__all__ = ["CLASS_COLORS", "register", "run"]

#: Colours of the surfel classes in ``--classify`` (Fig. 4.4): surface, edge, outside.
CLASS_COLORS = ((0.2, 0.35, 0.9), (0.6, 0.6, 0.6), (0.9, 0.15, 0.1))


def register(sub: Any) -> None:
    p = sub.add_parser("csg", help="render CSG combinations of surfel patches with sharp edges (chapter 4)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE.toml",
                   help="CSG scene file (docs/csg_scene.md) or a shipped one by name (unmesh scenes csg)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output image (.png ...), or .mp4/.gif with --turntable or an animated scene")
    add_camera_arguments(p, "the patches", "centre")
    p.add_argument("--shading", choices=("phong", "none"), default="phong", help="lighting (default phong)")
    p.add_argument("--background", default="1,1,1", metavar="R,G,B", help="background colour (0-1 or #rrggbb)")
    p.add_argument("--buffers", metavar="DIR", help="also write depth/normal/coverage/weight .npy files (stills)")
    p.add_argument("--turntable", type=int, metavar="N", help="render an orbit of N frames to OUT.mp4/.gif")
    p.add_argument("--fps", type=float, metavar="FPS", help="frames per second of videos (default: the scene's, or 30)")
    p.add_argument("--classify", metavar="OUT.png", help="also draw the surfels coloured by class")
    p.set_defaults(func=run, color_by=None, no_legend=True)


def classify_cloud(model: Any) -> Any:
    """All surfels of ``model`` (normals flipped at complemented leaves) coloured by class."""
    import numpy as np

    from unmesh.csg.frame import prepare

    frame = prepare(model)
    flip = frame.flat.invert[frame.flat.leaf_node[frame.leaf]].astype(bool)
    nrm = frame.cloud.normals.copy()
    nrm[flip] *= -1.0
    colors = np.asarray(CLASS_COLORS)[frame.classes]
    return frame.cloud.replace(normals=nrm, colors=colors)


def framing_cloud(model: Any) -> Any:
    """The drawn (surface and edge) surfels of ``model``, for the default camera."""
    from unmesh.csg.frame import prepare
    from unmesh.surfels import SurfelCloud

    a = prepare(model).arrays
    return SurfelCloud(a.positions, a.normals, radii=a.radii)


def run(args: argparse.Namespace) -> int:
    from unmesh.csg.scene import load
    from unmesh.errors import InputError
    from unmesh.render import render, turntable, write_video
    from unmesh.render.cli import _background, _camera, _note_rounding, _size
    from unmesh.render.image import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS

    size = _size(args.size)
    out = Path(args.output)
    ext = out.suffix.lower()
    from unmesh.scene import resolve_scene

    scene = load(resolve_scene(args.scene, "csg"))
    options: dict[str, Any] = {"shading": args.shading, "background": _background(args.background)}
    camera = _camera(args, framing_cloud(scene.model), size)
    if args.classify:
        cpath = Path(args.classify)
        if cpath.suffix.lower() not in IMAGE_EXTENSIONS:
            raise InputError(f"--classify: expected an image file ({', '.join(IMAGE_EXTENSIONS)}), got {cpath.name!r}")
        print(f"wrote {render(classify_cloud(scene.model), camera, **options).save(cpath)}")
    if args.turntable is not None or scene.frames > 1:
        if ext not in VIDEO_EXTENSIONS:
            raise InputError(f"-o: a turntable or an animated scene needs .mp4 or .gif, got {out.name!r}")
        if args.buffers:
            raise InputError("--buffers: only for still images")
        _note_rounding(ext, size)
        if args.turntable is not None:
            if args.eye is None and args.target is None:
                from unmesh.render import turntable_camera

                camera = turntable_camera(framing_cloud(scene.model), size[0], size[1], fov=args.fov or 40.0)
            path = turntable(scene.model, args.turntable, out, camera=camera, fps=args.fps or 30.0, **options)
        else:
            frames = (render(scene.at_frame(k), camera, **options).color for k in range(scene.frames))
            path = write_video(frames, out, fps=args.fps or scene.fps)
        print(f"wrote {path}")
        return 0
    if ext not in IMAGE_EXTENSIONS:
        raise InputError(f"-o: expected an image file ({', '.join(IMAGE_EXTENSIONS)}), got {out.name!r}")
    result = render(scene.model, camera, **options)
    print(f"wrote {result.save(out)}")
    if args.buffers:
        written = result.save_buffers(args.buffers)
        print(f"wrote {', '.join(str(p) for p in written.values())}")
    return 0
