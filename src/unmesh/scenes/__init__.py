"""Example scene files shipped with unmesh (``examples/`` in the repository is a link here).

Example
-------
>>> path("sph/dam_break.toml").name
'dam_break.toml'
"""

from __future__ import annotations

from pathlib import Path

from unmesh.errors import InputError

__all__ = ["available", "path"]

_ROOT = Path(__file__).resolve().parent


def path(name: str) -> Path:
    """Path of a shipped scene, e.g. ``"sph/dam_break.toml"`` (need not exist yet for the doctest)."""
    p = (_ROOT / name).resolve()
    if _ROOT not in p.parents:
        raise InputError(f"name: expected a scene inside the package, got {name!r}")
    return p


def available() -> list[str]:
    """All shipped scene files, as names relative to the scenes directory."""
    return sorted(p.relative_to(_ROOT).as_posix() for p in _ROOT.glob("*/*.toml"))
