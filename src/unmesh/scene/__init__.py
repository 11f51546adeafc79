"""Scene files: TOML loading and validation shared by every simulation.

A scene is a TOML file. :func:`load_scene` parses it (optionally applying
overrides) and returns the root :class:`Table`, whose typed accessors validate each
value and raise :class:`unmesh.errors.SceneError` naming the file and the dotted
key. :meth:`Table.finish` rejects unknown keys with a suggestion, so typos never
pass silently. Paths inside a scene are relative to the scene file. Shape specs
(built-in shapes or mesh files) are described in :mod:`unmesh.scene.shapes`.

Shared by every simulation (sph, shells, fem), so that they read and report alike:

- :meth:`Table.guard` / :meth:`Table.call`: the one conversion of an
  :class:`~unmesh.errors.InputError` or :class:`~unmesh.errors.FormatError` raised
  while building from a key into a SceneError naming the file and key;
- ``Table.number(key, infinite=True)`` with :func:`parse_infinite`: the one reading
  of "no limit" values (TOML ``inf``, ``"inf"``, ``"off"``, ``"none"``);
- :meth:`Table.check_budget`: sizes a scene implies against the memory budget
  (``UNMESH_MEMORY_BUDGET``, :mod:`unmesh.io.budget`), refused with the estimate;
- :func:`resolve_scene` / :func:`shipped_scenes` / :func:`describe_scene`: shipped
  scenes by name (``unmesh sph dam_break``) and ``unmesh scenes``.

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
from unmesh.scene.table import INFINITY_WORDS, REQUIRED, Table, parse_infinite

__all__ = ["INFINITY_WORDS", "REQUIRED", "Table", "apply_override", "describe_scene", "load_scene",
           "parse_infinite", "parse_override", "resolve_scene", "shipped_scenes"]

#: Largest scene file read (scenes are a few KB; anything bigger is not a scene).
_MAX_SCENE_BYTES = 16 * 2**20

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
    try:
        found = p.is_file()
    except (OSError, ValueError):  # e.g. a name longer than the OS allows
        found = False
    if not found:
        raise SceneError(f"{os.fspath(p)[:300]}: scene file not found (shipped scenes: 'unmesh scenes')")
    size = p.stat().st_size
    if size > _MAX_SCENE_BYTES:
        raise SceneError(f"{p.name}: {size} bytes is too large for a scene file (at most {_MAX_SCENE_BYTES})")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{p.name}: invalid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise SceneError(f"{p.name}: not a UTF-8 text file") from None
    for key, value in (overrides or {}).items():
        apply_override(data, key, value, p.name)
    return Table(data, p.resolve())


def shipped_scenes(kind: str | None = None) -> list[str]:
    """Names ``"sph/dam_break"`` ... of the scenes shipped in :mod:`unmesh.scenes` (one kind or all).

    Example
    -------
    >>> "sph/dam_break" in shipped_scenes("sph")
    True
    """
    from unmesh import scenes

    names = [n[:-len(".toml")] for n in scenes.available()]
    return [n for n in names if kind is None or n.split("/", 1)[0] == kind]


def resolve_scene(name: str | os.PathLike[str], kind: str) -> Path:
    """The scene file ``name`` names: an existing path, or a shipped scene of ``kind`` by name.

    ``unmesh sph dam_break`` runs the shipped ``sph/dam_break.toml``; a path that
    exists always wins, and any other name is returned unchanged (so that
    :func:`load_scene` reports it as not found).

    Example
    -------
    >>> resolve_scene("dam_break", "sph").name
    'dam_break.toml'
    """
    p = Path(name)
    try:
        if p.exists():
            return p
    except (OSError, ValueError):
        return p
    text = os.fspath(name)
    stem = text[:-len(".toml")] if text.endswith(".toml") else text
    if "/" in stem.replace("\\", "/"):
        if stem.split("/", 1)[0] != kind:
            return p
        stem = stem.split("/", 1)[1]
    if f"{kind}/{stem}" in shipped_scenes(kind):
        from unmesh import scenes

        return scenes.path(f"{kind}/{stem}.toml")
    return p


def describe_scene(path: str | os.PathLike[str], limit: int = 100) -> str:
    """First sentence of a scene file's leading ``#`` comment (at most ``limit`` characters).

    Example
    -------
    >>> from unmesh import scenes
    >>> describe_scene(scenes.path("sph/dice.toml"))
    'Fig. 8.8: stiff elastic dice thrown into a box collide and tumble.'
    """
    words: list[str] = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if not line.startswith("#"):
            break
        text = line.lstrip("#").strip()
        if text.lower().startswith(("run:", "format:")):
            break
        words.append(text)
    text = " ".join(w for w in words if w)
    m = re.search(r"(?<=[a-z0-9)\]])(?<!Fig)(?<!Figs)(?<!eq)(?<!e\.g)(?<!i\.e)(?<!approx)\.(\s+[A-Z(]|$)", text)
    if m:
        text = text[:m.start() + 1]
    return text if len(text) <= limit else text[:limit - 3].rstrip() + "..."
