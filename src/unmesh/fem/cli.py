"""The ``unmesh fem`` command: run an FEM scene file (format: docs/fem_scene.md).

Usage::

    unmesh fem SCENE.toml -o OUTDIR [--duration SECONDS] [--resume | --force] [--set KEY=VALUE] [--no-progress]

Writes ``OUTDIR/frames/mesh_NNNNN.vtu`` + ``OUTDIR/mesh.pvd`` (ParaView), ``OUTDIR/frames/surface_NNNNN.ply``
(renderer), ``OUTDIR/frames.json`` (the manifest of written files) and ``OUTDIR/summary.json``.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["register"]


def _build(scene: Any) -> Any:
    from unmesh.fem.scene import build_simulation

    return build_simulation(scene)


def _run(args: argparse.Namespace) -> int:
    from unmesh.scene import resolve_scene
    from unmesh.sim.cli import run_scene_command

    args.scene = str(resolve_scene(args.scene, "fem"))  # a shipped scene by name: unmesh fem blob_slicing
    return run_scene_command(args, _build)


def register(sub: Any) -> None:
    """Add the ``fem`` sub-command.

    Example
    -------
    >>> import argparse
    >>> sub = argparse.ArgumentParser().add_subparsers()
    >>> register(sub)
    """
    from unmesh.sim.cli import add_run_arguments

    p = sub.add_parser("fem", help="linear FEM on convex polyhedra with cutting (chapter 9)",
                       description="Run a finite element scene: polyhedral meshes with mean value shape functions, "
                                   "stiffness warping, implicit Euler, scripted cuts. Writes frames/mesh_NNNNN.vtu + "
                                   "mesh.pvd (ParaView), frames/surface_NNNNN.ply, frames.json and summary.json "
                                   "into OUTDIR (docs/fem_scene.md). SCENE may also name a shipped scene, e.g. "
                                   "'unmesh fem blob_slicing -o out' (list: 'unmesh scenes').")
    add_run_arguments(p)
    p.set_defaults(func=_run)
