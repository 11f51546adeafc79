"""Command-line plumbing shared by ``unmesh sph``, ``unmesh shell`` and ``unmesh fem``.

Example
-------
A simulation package registers its command like this::

    def register(sub):
        p = sub.add_parser("sph", help="...", description="...")
        add_run_arguments(p)
        p.set_defaults(func=lambda args: run_scene_command(args, build_simulation))

where ``build_simulation(scene: Table) -> (Simulation, RunSettings)`` reads the
scene (and calls ``scene.finish()``).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from unmesh.scene import Table, load_scene, parse_override
from unmesh.sim.runner import RunResult, RunSettings, Simulation, run

__all__ = ["Builder", "add_run_arguments", "run_scene", "run_scene_command"]

#: Builds a simulation and its run settings from a scene's root table.
Builder = Callable[[Table], tuple[Simulation, RunSettings]]


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Add SCENE, -o/--output, --duration, --resume, --force, --set and --no-progress."""
    parser.add_argument("scene", help="scene file (TOML)")
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                        help="output directory (new or empty, unless --resume or --force)")
    parser.add_argument("--duration", type=float, metavar="SECONDS", help="simulated time (overrides the scene)")
    parser.add_argument("--resume", action="store_true", help="continue from OUTDIR/checkpoint.npz")
    parser.add_argument("--force", action="store_true",
                        help="start afresh in a non-empty OUTDIR: remove the files its previous run recorded in "
                             "OUTDIR/frames.json (never other files)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene value, e.g. --set simulation.dt=1e-4 (repeatable)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run_scene(scene_path: str | os.PathLike[str], outdir: str | os.PathLike[str], build: Builder, *,
              overrides: Mapping[str, Any] | None = None, duration: float | None = None, resume: bool = False,
              progress: bool = True, force: bool = False) -> RunResult:
    """Load a scene file, build its simulation and run it (the Python form of the CLI; see
    :func:`unmesh.sim.run` for ``resume`` and ``force``)."""
    scene = load_scene(scene_path, overrides)
    sim, settings = build(scene)
    if duration is not None:
        settings = settings.replace(duration=duration)
    return run(sim, Path(outdir), settings, resume=resume, progress=progress, force=force)


def run_scene_command(args: argparse.Namespace, build: Builder) -> int:
    """Run a simulation sub-command from parsed arguments; returns the exit status."""
    overrides = dict(parse_override(s) for s in args.set)
    result = run_scene(args.scene, args.output, build, overrides=overrides, duration=args.duration,
                       resume=args.resume, progress=not args.no_progress, force=getattr(args, "force", False))
    print(f"{Path(args.scene).name}: {result.status}, {result.frames} frames, {result.steps} steps, "
          f"{result.wall_seconds:.1f} s -> {result.outdir}")
    return 0
