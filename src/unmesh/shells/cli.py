"""``unmesh shell SCENE.toml -o OUTDIR``: point-sampled thin shells (thesis chapter 7).

The scene format and the output files are documented in ``docs/shell_scene.md``.
"""

from __future__ import annotations

from typing import Any

__all__ = ["register"]

_DESCRIPTION = """\
Simulate a point-sampled thin shell (elastic, plastic, fracturing) described by a TOML
scene file. Writes OUTDIR/frames/frame_NNNNN.ply (the dense surfel cloud, renderable with
'unmesh render OUTDIR/frames'), OUTDIR/nodes/frame_NNNNN.ply (simulation nodes with
velocities), OUTDIR/fibers/frame_NNNNN.npz, OUTDIR/frames.json (the manifest of written
files) and OUTDIR/summary.json (energies, momentum,
fiber and crack counts, pieces, time per frame split into forces, fracture and surface).
Example scenes: examples/shells/*.toml; SCENE may also name a shipped scene, e.g.
'unmesh shell tearing_poster -o out' (list: 'unmesh scenes')."""


def _build(scene: Any) -> Any:
    from unmesh.shells.scene import build_simulation

    return build_simulation(scene)


def register(sub: Any) -> None:
    """Add the ``shell`` sub-command."""
    import argparse

    from unmesh.sim.cli import add_run_arguments, run_scene_command

    p = sub.add_parser("shell", help="simulate a point-sampled thin shell from a scene file",
                       description=_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_arguments(p)
    p.set_defaults(func=lambda args: run_scene_command(_shipped(args), _build))


def _shipped(args: Any) -> Any:
    """A shipped scene by name: ``unmesh shell tearing_poster``."""
    from unmesh.scene import resolve_scene

    args.scene = str(resolve_scene(args.scene, "shells"))
    return args
