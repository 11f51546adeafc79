"""``unmesh render``: images, turntables and simulation videos of surfels, meshes and particles.

Examples::

    unmesh render bunny.ply -o bunny.png --size 800x600
    unmesh render bunny.ply -o bunny.png --eye 0,0.2,3 --target 0,0,0 --fov 30 --buffers buffers/
    unmesh render bunny.ply -o spin.mp4 --turntable 120
    unmesh render sph_out/ -o dam.mp4 --color-by density
    unmesh render cloud.ply -o mls.png --method raycast

A default camera frames the bounding box of the input (from the front-right-above; flat 2D data
is viewed head-on). ``--buffers DIR`` writes ``depth.npy`` (H,W float, camera z, inf = background),
``normal.npy`` (H,W,3 world normals, zeros in background), ``coverage.npy`` (H,W bool) and
``weight.npy`` (H,W accumulated splat weight). Still images are anti-aliased by 2 x 2
supersampling unless ``--aa`` says otherwise (the buffers are then block averages; ``--aa 1``
gives exact ones); videos and frame sequences use one sample per pixel.

A simulation output directory is read through its ``frames.json`` (the files the run wrote;
nothing is guessed from names, other files are ignored); its video plays at the simulation's
frame rate unless ``--fps`` is given. MP4 needs even image sizes: an odd ``--size`` is padded
by one pixel, and the command says so.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["add_camera_arguments", "register", "run"]


def register(sub: Any) -> None:
    p = sub.add_parser("render", help="render surfels, meshes and particles to images and videos",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", metavar="IN",
                   help="PLY/OBJ/OFF files (surfels, particles, meshes), or a simulation output directory")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output .png (still), .mp4/.gif (turntable or frame sequence) or a directory (PNG frames)")
    add_camera_arguments(p, "the bounding box", "bounding-box centre")
    p.add_argument("--method", choices=("splat", "raycast"), default="splat",
                   help="surfels by EWA splatting (default) or MLS ray casting")
    p.add_argument("--shading", choices=("phong", "none"), default="phong", help="lighting (default phong)")
    p.add_argument("--color-by", metavar="ATTR", help="colour by a per-element attribute through a colormap")
    p.add_argument("--colormap", default="viridis", metavar="NAME", help="colormap for --color-by (default viridis)")
    p.add_argument("--range", metavar="LO,HI", help="fixed value range for --color-by")
    p.add_argument("--no-legend", action="store_true", help="no colour bar with --color-by")
    p.add_argument("--background", default="1,1,1", metavar="R,G,B", help="background colour (0-1 or #rrggbb)")
    p.add_argument("--aa", type=int, default=None, metavar="K",
                   help="anti-aliasing: K x K samples per pixel (default 2 for a still image, 1 for videos and "
                        "frame sequences; buffers are then block averages)")
    p.add_argument("--buffers", metavar="DIR", help="also write depth/normal/coverage/weight .npy files (stills)")
    p.add_argument("--turntable", type=int, metavar="N", help="render an orbit of N frames to OUT.mp4/.gif")
    p.add_argument("--fps", type=float, metavar="FPS",
                   help="frames per second of videos (default: the simulation's frame rate for a simulation "
                        "output directory, else 30)")
    p.add_argument("--particle-radius", type=float, metavar="R", help="drawing radius of particles")
    p.add_argument("--particle-style", choices=("sphere", "disc"), default="sphere", help="particle glyphs")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="render a simulation's frames in parallel on a local Dask cluster of N processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="render a simulation's frames on an existing Dask cluster (tcp://host:8786)")
    p.set_defaults(func=run)



def add_camera_arguments(p: Any, framed: str, centre: str) -> None:
    """The camera options shared by ``unmesh render`` and the commands that render like it
    (``--size --eye --target --up --fov|--ortho``); ``framed``/``centre`` name the defaults."""
    p.add_argument("--size", default="800x600", metavar="WxH", help="image size in pixels (default 800x600)")
    p.add_argument("--eye", metavar="X,Y,Z", help=f"camera position (default: frames {framed})")
    p.add_argument("--target", metavar="X,Y,Z", help=f"point looked at (default: {centre})")
    p.add_argument("--up", default="0,1,0", metavar="X,Y,Z", help="up direction (default 0,1,0)")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--fov", type=float, metavar="DEG", help="vertical field of view in degrees (default 40)")
    view.add_argument("--ortho", type=float, metavar="HEIGHT", help="orthographic camera with this world height")

def _vector(text: str | None, name: str) -> Any:
    from unmesh.errors import InputError

    if text is None:
        return None
    parts = [s for s in text.replace(" ", "").split(",") if s]
    try:
        vals = [float(s) for s in parts]
    except ValueError:
        raise InputError(f"{name}: expected three numbers x,y,z, got {text!r}") from None
    if len(vals) != 3:
        raise InputError(f"{name}: expected three numbers x,y,z, got {text!r}")
    return vals


def parse_size(text: str) -> tuple[int, int]:
    """``"WIDTHxHEIGHT"`` (``--size``) as ``(width, height)``; InputError names ``--size``.

    Example
    -------
    >>> parse_size("800x600")
    (800, 600)
    """
    from unmesh.errors import InputError

    parts = text.lower().split("x")
    try:
        w, h = (int(s) for s in parts)
    except ValueError:
        raise InputError(f"--size: expected WIDTHxHEIGHT such as 800x600, got {text!r}") from None
    if w < 1 or h < 1 or w > 16384 or h > 16384:
        raise InputError(f"--size: expected sizes between 1 and 16384, got {text!r}")
    return w, h


_size = parse_size  # the name the csg command imports


def _background(text: str) -> Any:
    if text.startswith("#"):
        return text
    parts = text.split(",")
    return [float(s) for s in parts] if len(parts) == 3 else float(text)


def _camera(args: argparse.Namespace, objects: Any, size: tuple[int, int]) -> Any:
    import numpy as np

    from unmesh.render import Camera, scene_bounds, scene_points

    bounds = scene_bounds(objects)
    w, h = size
    eye = _vector(args.eye, "--eye")
    target = _vector(args.target, "--target")
    up = _vector(args.up, "--up")
    center = 0.5 * (bounds[0] + bounds[1]) if np.all(np.isfinite(bounds)) else np.zeros(3)
    if eye is None:
        margin = 1.35 if args.color_by and not args.no_legend else 1.08  # room for the colour bar
        cam = Camera.fit(scene_points(objects), w, h, fov=args.fov or 40.0, ortho=args.ortho is not None, up=up,
                         margin=margin)
        if target is not None:
            shift = np.asarray(target) - cam.target
            cam = cam.replace(eye=cam.eye + shift, target=cam.target + shift)
        if args.ortho is not None:
            cam = cam.replace(ortho=args.ortho)
        return cam
    return Camera(eye, center if target is None else target, up=up, width=w, height=h, fov=args.fov,
                  ortho=args.ortho)


def _note_rounding(ext: str, size: tuple[int, int]) -> None:
    """Say when an MP4's odd size will be padded to an even one (yuv420p needs even sizes)."""
    import sys

    w, h = size
    if ext == ".mp4" and (w % 2 or h % 2):
        print(f"note: MP4 needs an even width and height: {w}x{h} is padded to {w + w % 2}x{h + h % 2} "
              "(give an even --size to avoid it)", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from unmesh import io
    from unmesh.errors import InputError
    from unmesh.render import render, render_sequence, turntable
    from unmesh.render.image import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS

    size = parse_size(args.size)
    out = Path(args.output)
    ext = out.suffix.lower()
    color_range = None
    if args.range:
        try:
            lo, hi = (float(s) for s in args.range.split(","))
        except ValueError:
            raise InputError(f"--range: expected LO,HI, got {args.range!r}") from None
        color_range = (lo, hi)
    options: dict[str, Any] = {
        "method": args.method, "shading": args.shading, "background": _background(args.background),
        "color_by": args.color_by, "colormap": args.colormap, "color_range": color_range,
        "particle_radius": args.particle_radius, "particle_style": args.particle_style, "supersample": args.aa,
    }
    if args.no_legend:
        options["legend"] = False
    progress = not args.no_progress
    inputs = [Path(p) for p in args.inputs]
    for p in inputs:
        if not p.exists():
            raise InputError(f"input: no such file or directory: {p}")
    is_sequence = (len(inputs) == 1 and inputs[0].is_dir()) or (ext in VIDEO_EXTENSIONS and args.turntable is None) \
        or (ext == "" and args.turntable is None)
    if args.aa is None:  # stills anti-aliased by default; videos stay fast
        from unmesh.render.options import STILL_SUPERSAMPLE

        options["supersample"] = 1 if is_sequence or args.turntable is not None else STILL_SUPERSAMPLE
    if (args.workers is not None or args.scheduler is not None) and not is_sequence:
        raise InputError("--workers/--scheduler: only for frame sequences (a simulation directory to .mp4, .gif "
                         "or a folder)")
    if is_sequence:
        if args.buffers:
            raise InputError("--buffers: only for still images, not for frame sequences")
        if ext not in VIDEO_EXTENSIONS and ext != "":
            raise InputError(f"-o: a frame sequence needs .mp4, .gif or a directory, got {out.name!r}")
        if any(p.is_dir() for p in inputs) and len(inputs) > 1:
            raise InputError("input: give one simulation directory or a list of frame files")
        source: Any = inputs[0] if inputs[0].is_dir() else inputs
        camera = None
        if args.eye or args.target or args.fov or args.ortho:
            from unmesh.render.sequence import _frame_objects, find_frames

            groups, static = find_frames(source)
            camera = _camera(args, [_frame_objects(groups[0]), _frame_objects(groups[-1]), _frame_objects(static)],
                             size)
        color_by = options.pop("color_by")
        crange = options.pop("color_range")
        pr = options.pop("particle_radius")
        fps = args.fps
        note = ""
        if fps is None and ext in VIDEO_EXTENSIONS:
            from unmesh.render.sequence import sequence_fps

            sim_fps = sequence_fps(source)
            fps = sim_fps or 30.0
            note = f" at {fps:g} fps" + (" (the simulation's frame rate)" if sim_fps else "")
        if ext in VIDEO_EXTENSIONS:
            _note_rounding(ext, size)
        sequence = render_sequence
        if args.workers is not None or args.scheduler is not None:
            from functools import partial

            from unmesh.render.parallel import render_sequence_parallel

            sequence = partial(render_sequence_parallel, workers=args.workers, scheduler=args.scheduler)
        path = sequence(source, out, camera=camera, fps=fps, progress=progress, width=size[0],
                        height=size[1], color_by=color_by, color_range=crange, particle_radius=pr, **options)
        print(f"wrote {path}{note}")
        return 0
    objects = [io.load(p) for p in inputs]
    camera = _camera(args, objects, size)
    if args.turntable is not None:
        if ext not in VIDEO_EXTENSIONS:
            raise InputError(f"--turntable: expected -o OUT.mp4 or OUT.gif, got {out.name!r}")
        if args.buffers:
            raise InputError("--buffers: only for still images, not with --turntable")
        if args.eye is None and args.target is None:
            from unmesh.render import turntable_camera

            camera = turntable_camera(objects, size[0], size[1], fov=args.fov or 40.0)
        _note_rounding(ext, size)
        path = turntable(objects, args.turntable, out, camera=camera, fps=args.fps or 30.0, progress=progress,
                         **options)
        print(f"wrote {path}")
        return 0
    if ext not in IMAGE_EXTENSIONS:
        raise InputError(f"-o: expected an image file ({', '.join(IMAGE_EXTENSIONS)}), got {out.name!r}")
    result = render(objects, camera, progress=progress and args.method == "raycast", **options)
    path = result.save(out)
    print(f"wrote {path}")
    if args.buffers:
        written = result.save_buffers(args.buffers)
        print(f"wrote {', '.join(str(p) for p in written.values())}")
    return 0
