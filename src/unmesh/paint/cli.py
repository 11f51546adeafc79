"""``unmesh paint``: paint on a surfel model, in the browser studio or by replaying a stroke file.

Examples::

    unmesh paint blob                                   # the studio in the browser; saves blob_painted.ply
    unmesh paint model.ply -o art.ply --port 8765 --no-browser
    unmesh paint blob --replay strokes.json -o painted.ply --render painted.png

MODEL is a surfel PLY (a PLY written by a paint session continues that session exactly) or a
built-in shape name (``blob``, ``sphere``, ...; sampled at diagonal / 150). ``--replay`` paints
a stroke file (format in ``docs/paint.md``) without a browser; the same file always gives the
same PLY. The output defaults to ``MODEL_painted.ply`` in the current folder.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["load_model", "register", "run"]


def register(sub: Any) -> None:
    p = sub.add_parser("paint", help="paint on a surfel model (browser studio, or --replay a stroke file)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL", help="surfel PLY, or a built-in shape name such as blob")
    p.add_argument("-o", "--output", metavar="OUT.ply", help="painted PLY (default MODEL_painted.ply here)")
    p.add_argument("--replay", metavar="STROKES.json", help="paint this stroke file without a browser")
    p.add_argument("--render", metavar="OUT.png", help="also render the painted model to an image")
    p.add_argument("--size", default="800x600", metavar="WxH", help="--render image size (default 800x600)")
    p.add_argument("--spacing", type=float, metavar="D", help="sample spacing of a built-in shape")
    p.add_argument("--port", type=int, default=0, metavar="N", help="studio port (default: a free port)")
    p.add_argument("--no-browser", action="store_true", help="do not open a browser for the studio")
    p.set_defaults(func=run)


def load_model(source: str, spacing: float | None = None) -> tuple[Any, str]:
    """A paint session for MODEL (PLY path or shape name) and the stem for default outputs."""
    import numpy as np

    from unmesh.errors import InputError
    from unmesh.paint import Session
    from unmesh.shapes import SHAPES, by_name

    path = Path(source)
    if source.lower() in SHAPES and not path.exists():
        shape = by_name(source)
        b = shape.bounds()
        diag = float(np.linalg.norm(b[1] - b[0]))
        if spacing is not None and not (np.isfinite(spacing) and spacing > 0):
            raise InputError(f"--spacing: expected a positive number, got {spacing}")
        return Session(shape.surfels(spacing or diag / 150.0)), source.lower()
    if not path.exists():
        raise InputError(f"MODEL: no such file or built-in shape {source!r}; shapes: {', '.join(sorted(SHAPES))}")
    if path.suffix.lower() != ".ply":
        raise InputError(f"MODEL: expected a surfel .ply file or a shape name, got {source!r}")
    return Session.load(path), path.stem


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from unmesh.errors import InputError
    from unmesh.paint.strokes import read_stroke_json

    session, stem = load_model(str(args.model), args.spacing)
    out = Path(args.output) if args.output else Path.cwd() / f"{stem}_painted.ply"
    if out.suffix.lower() != ".ply":
        raise InputError(f"--output: expected a .ply file, got {str(out)!r}")
    if args.render and Path(args.render).suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise InputError(f"--render: expected a .png or .jpg file, got {args.render!r}")
    from unmesh.render.cli import parse_size

    size = parse_size(args.size)
    if args.replay is None:
        from unmesh.paint.studio.server import run_studio

        run_studio(session, out, port=args.port, open_browser=not args.no_browser)
        return 0
    name = str(args.replay)
    data = read_stroke_json(name)
    session.options = dataclasses.replace(session.options, haptics=False)
    n = session.replay(data, name)
    session.save(out)
    print(f"replayed {n} strokes -> {len(session.cloud())} surfels; wrote {out}")
    if args.render:
        from unmesh.render import Camera, save_image

        pts = session.surface.tree.points
        cam = Camera.framing([pts.min(axis=0), pts.max(axis=0)], *size)
        save_image(args.render, session.render(cam, brush=False).color)
        print(f"wrote {args.render}")
    return 0
