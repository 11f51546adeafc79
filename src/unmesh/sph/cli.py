"""``unmesh sph SCENE.toml -o OUTDIR [--duration SECONDS] [--resume | --force]``.

Runs a visco-elastic SPH scene (thesis chapter 8; format in ``docs/sph_scene.md``)
and writes ``OUTDIR/frames/frame_NNNNN.ply``, ``OUTDIR/boundary.ply``, ``OUTDIR/frames.json``
(the manifest of written files), ``OUTDIR/summary.json`` and ``OUTDIR/checkpoint.npz``.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from unmesh.scene import resolve_scene
    from unmesh.sim.cli import run_scene_command
    from unmesh.sph.scene import build_simulation

    args.scene = str(resolve_scene(args.scene, "sph"))  # a shipped scene by name: unmesh sph dam_break
    return run_scene_command(args, build_simulation)


def register(sub: Any) -> None:
    """Add the ``sph`` sub-command to the ``unmesh`` parser's sub-parsers.

    Example
    -------
    >>> import argparse
    >>> sub = argparse.ArgumentParser().add_subparsers()
    >>> register(sub)
    >>> sorted(sub.choices)
    ['sph']
    """
    from unmesh.sim.cli import add_run_arguments

    p = sub.add_parser(
        "sph", help="run a visco-elastic SPH scene (fluids, elastic solids, melting, freezing, fracture)",
        description="Weakly compressible SPH with connectivity-free elasticity (thesis chapter 8). Writes "
                    "frames/frame_NNNNN.ply (x y z vx vy vz density pressure temperature phase object), "
                    "boundary.ply, frames.json, summary.json and checkpoint.npz into OUTDIR. Scene format: "
                    "docs/sph_scene.md. SCENE may also name a shipped scene, e.g. 'unmesh sph dam_break -o out' "
                    "(list: 'unmesh scenes').")
    add_run_arguments(p)
    p.set_defaults(func=_run)
