"""``unmesh scenes``: list the scene files shipped with unmesh, one line each.

Each line is ``KIND/NAME`` and the first sentence of the file's leading comment. Run
a shipped scene by its name, without a path: ``unmesh sph dam_break -o out``,
``unmesh shell tearing_poster -o out``, ``unmesh fem blob_slicing -o out``.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["register", "run"]

#: Scene kind -> the sub-command that runs it.
COMMANDS = {"sph": "sph", "shells": "shell", "fem": "fem", "csg": "csg", "batch": "batch"}


def register(sub: Any) -> None:
    """Add the ``scenes`` sub-command.

    Example
    -------
    >>> import argparse
    >>> sub = argparse.ArgumentParser().add_subparsers()
    >>> register(sub)
    >>> sorted(sub.choices)
    ['scenes']
    """
    p = sub.add_parser("scenes", help="list the shipped example scenes (run them by name)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("kind", nargs="?", choices=sorted(COMMANDS), help="only the scenes of this simulation")
    p.add_argument("--paths", action="store_true", help="print the scene files' paths too")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print one line per shipped scene; returns 0."""
    from unmesh import scenes
    from unmesh.scene import describe_scene, shipped_scenes

    names = shipped_scenes(args.kind)
    width = max((len(n) for n in names), default=0)
    for name in names:
        path = scenes.path(f"{name}.toml")
        line = f"{name:<{width}}  {describe_scene(path)}"
        if args.paths:
            line += f"  [{path}]"
        print(line)
    runnable = [n for n in names if n.split("/", 1)[0] != "batch"]  # sweeps are run by path
    if runnable:
        kind, stem = runnable[0].split("/", 1)
        print(f"\nrun one with: unmesh {COMMANDS[kind]} {stem} -o OUTDIR")
    return 0
