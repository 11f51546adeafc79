"""Scene files: TOML loading and validation shared by every simulation.

A scene is a TOML file. :func:`load_scene` parses it (optionally applying
overrides) and returns the root :class:`Table`, whose typed accessors validate each
value and raise :class:`unmesh.errors.SceneError` naming the file and the dotted
key. :meth:`Table.finish` rejects unknown keys with a suggestion, so typos never
pass silently. Paths inside a scene are relative to the scene file. Shape specs
(built-in shapes or mesh files) are described in :mod:`unmesh.scene.shapes`.

Example
-------
>>> import tempfile, pathlib
>>> f = pathlib.Path(tempfile.mkdtemp()) / "s.toml"
>>> _ = f.write_text("[simulation]\\ndt = 0.001\\nduration = 1.0\\n")
>>> scene = load_scene(f, overrides={"simulation.duration": 0.5})
>>> sim = scene.table("simulation")
>>> sim.number("dt", positive=True), sim.number("duration")
(0.001, 0.5)
>>> scene.finish()
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from unmesh.errors import SceneError
from unmesh.scene.table import REQUIRED, Table

__all__ = ["REQUIRED", "Table", "apply_override", "load_scene", "parse_override"]

_PART = re.compile(r"^([A-Za-z0-9_\-]+)(?:\[(\d+)\])?$")


def apply_override(data: dict[str, Any], dotted: str, value: Any, file: str = "scene") -> None:
    """Set ``data[a][b][i]...`` for a dotted key like ``"objects[0].velocity"`` (tables are created)."""
    parts = dotted.split(".")
    node: Any = data
    for depth, part in enumerate(parts):
        m = _PART.match(part)
        if not m:
            raise SceneError(f"{file}: override '{dotted}': '{part}' is not a valid key")
        name, index = m.group(1), m.group(2)
        last = depth == len(parts) - 1
        if index is None:
            if last:
                node[name] = value
                return
            node = node.setdefault(name, {})
            if not isinstance(node, dict):
                raise SceneError(f"{file}: override '{dotted}': '{name}' is not a table")
        else:
            seq = node.get(name)
            i = int(index)
            if not isinstance(seq, list) or i >= len(seq):
                raise SceneError(f"{file}: override '{dotted}': no element {i} in '{name}'")
            if last:
                seq[i] = value
                return
            node = seq[i]


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``KEY=VALUE`` where VALUE is a TOML value (bare words become strings).

    Example
    -------
    >>> parse_override("simulation.dt=1e-4")
    ('simulation.dt', 0.0001)
    """
    if "=" not in text:
        raise SceneError(f"--set {text!r}: expected KEY=VALUE")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key.strip(), value


def load_scene(path: str | os.PathLike[str], overrides: Mapping[str, Any] | None = None) -> Table:
    """Parse a TOML scene file and return its root :class:`Table`.

    Parameters
    ----------
    path : path-like
        The scene file.
    overrides : mapping of str to value, optional
        Dotted keys (``"simulation.duration"``, ``"objects[0].velocity"``) set
        after parsing, e.g. from ``--set`` or the gallery's quick mode.

    Raises
    ------
    unmesh.errors.SceneError
        Missing file, TOML syntax errors (with the line), bad overrides.
    """
    p = Path(path)
    if not p.is_file():
        raise SceneError(f"{p}: scene file not found")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{p.name}: invalid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise SceneError(f"{p.name}: not a UTF-8 text file") from None
    for key, value in (overrides or {}).items():
        apply_override(data, key, value, p.name)
    return Table(data, p.resolve())
