"""Sweep files: parse, expand into tasks, and give every task a readable, stable id.

A sweep file (TOML, documented in ``docs/batch.md``) names a command, a base scene or input
files, and the parameters to vary::

    command = "sph"
    scene = "dam_break.toml"          # relative to the sweep file
    duration = 0.5
    [sweep]                            # cartesian product, first key slowest
    "materials.water.viscosity" = [0.0, 0.01, 0.05]
    "simulation.spacing" = [0.02, 0.015]

``[[runs]]`` tables list explicit parameter sets instead (an optional ``id`` names the run);
with both, every run is combined with every point of ``[sweep]``. For scene commands (``sph``,
``shell``, ``fem``) the keys are the dotted keys of ``--set``; for commands on input files
(``sample``, ``render``, ``convert``: ``inputs = ["scans/*.ply"]``) they are the command's
options without the dashes (``spacing = [0.01, 0.005]`` runs ``--spacing 0.01`` ...).

Task ids look like ``viscosity=0.01_spacing=0.02-30bd46ed``: the last part of each key with
its value, keys in alphabetical order of their full names (the input file's stem first), then 8 hex digits of a hash of the task's full
parameters and input. An id depends on its own task only (not on the other tasks or the
order of the keys), so it survives editing the sweep and ``--resume`` finds the tasks again.

Example
-------
>>> task_id({"materials.water.viscosity": 0.01, "simulation.spacing": 0.02})
'viscosity=0.01_spacing=0.02-30bd46ed'
"""

from __future__ import annotations

import difflib
import glob
import hashlib
import itertools
import json
import math
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from unmesh.errors import SceneError

__all__ = ["SWEEP_KEYS", "Sweep", "Task", "expand", "load_sweep", "task_id"]

#: Top-level keys of a sweep file.
SWEEP_KEYS = ("command", "scene", "inputs", "duration", "options", "output", "sweep", "runs")
#: Longest readable part of an id (before the hash).
_READABLE_MAX = 80
_SAFE = re.compile(r"[^A-Za-z0-9.,+\-]")
_ID_OK = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+,=\-]{0,119}$")


@dataclass(frozen=True)
class Task:
    """One run of a sweep.

    Attributes
    ----------
    id : str
        Readable, stable, file-name-safe id (the task's folder under OUTDIR).
    parameters : tuple of (str, value)
        The task's parameters in the sweep file's order (see :attr:`params`).
    input : str or None
        The input file (absolute path) or built-in name of commands on inputs.
    """

    id: str
    parameters: tuple[tuple[str, Any], ...] = ()
    input: str | None = None

    @property
    def params(self) -> dict[str, Any]:
        """The parameters as a dict."""
        return dict(self.parameters)


@dataclass(frozen=True)
class Sweep:
    """A parsed sweep file (see the module docstring).

    Attributes
    ----------
    path : Path
        The sweep file (absolute).
    command : str
        Sub-command run by every task.
    scene : Path or None
        Base scene of scene commands (absolute).
    duration : float or None
        Simulated time of scene commands (``--duration``).
    options : tuple of str
        Extra command-line options passed to every task.
    output : str or None
        Output file name of commands on inputs (``{stem}`` is the input's stem).
    tasks : tuple of Task
    """

    path: Path
    command: str
    scene: Path | None
    duration: float | None
    options: tuple[str, ...]
    output: str | None
    tasks: tuple[Task, ...] = field(default=())

    def task(self, task_id: str) -> Task:
        """The task with this id."""
        for t in self.tasks:
            if t.id == task_id:
                return t
        raise KeyError(task_id)


def _value_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if isinstance(value, list | tuple):
        return ",".join(_value_text(v) for v in value)
    if isinstance(value, dict):
        return ",".join(f"{k}:{_value_text(v)}" for k, v in value.items())
    return str(value)


def _canonical(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in sorted(value.items())}
    if isinstance(value, list | tuple):
        return [_canonical(v) for v in value]
    return value


def task_id(parameters: Mapping[str, Any], input: str | None = None, name: str | None = None) -> str:
    """The id of a task: readable parameter values and a hash of everything that defines the task.

    Parameters
    ----------
    parameters : mapping of str to value
        Dotted keys (``"materials.water.viscosity"``) or option names and their values.
    input : str, optional
        The input (file name as written in the sweep, or a built-in name); its stem comes first.
    name : str, optional
        An explicit run name (``id`` of a ``[[runs]]`` table): replaces the readable parameters.

    Returns
    -------
    str
        ``[stem_]key=value_..._key=value-hhhhhhhh`` (at most about 90 characters, file-name safe).

    Example
    -------
    >>> task_id({"spacing": 0.01}, input="scans/bunny.ply")
    'bunny_spacing=0.01-916150cf'
    """
    canon = json.dumps({"input": input, "parameters": _canonical(dict(parameters)), "name": name},
                       sort_keys=True, separators=(",", ":"), allow_nan=False)
    digest = hashlib.sha256(canon.encode("utf-8")).hexdigest()[:8]
    parts = []
    if input is not None:
        parts.append(_SAFE.sub("-", Path(input).stem))
    if name is not None:
        parts.append(_SAFE.sub("-", name))
    else:
        for key, value in sorted(parameters.items(), key=lambda kv: str(kv[0])):
            short = re.sub(r"\[\d+\]$", "", str(key).split(".")[-1])
            parts.append(f"{_SAFE.sub('-', short)}={_SAFE.sub('-', _value_text(value))}")
    readable = "_".join(p for p in parts if p)[:_READABLE_MAX].strip("_-.") or "run"
    return f"{readable}-{digest}"


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Dotted keys of nested tables (``a.b = 1`` in TOML is ``{"a": {"b": 1}}``)."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, f"{dotted}."))
        else:
            out[dotted] = value
    return out


def _glob_inputs(where: str, base: Path, entries: Sequence[Any], accepts_names: bool) -> list[str]:
    files: list[str] = []
    for entry in entries:
        if not isinstance(entry, str) or not entry:
            raise SceneError(f"{where}: 'inputs': expected file names or glob patterns, got {entry!r}")
        pattern = entry if os.path.isabs(entry) else os.fspath(base / entry)
        if glob.has_magic(entry):
            found = sorted(p for p in glob.glob(pattern, recursive=True) if os.path.isfile(p))
            if not found:
                raise SceneError(f"{where}: 'inputs': pattern {entry!r} matches no file (relative to {base})")
            files.extend(found)
        elif os.path.isfile(pattern):
            files.append(pattern)
        elif accepts_names:
            files.append(entry)
        else:
            raise SceneError(f"{where}: 'inputs': no such file {entry!r} (relative to {base})")
    unique = list(dict.fromkeys(os.path.abspath(f) if os.path.isfile(f) else f for f in files))
    return unique


def expand(sweep: Mapping[str, Any], runs: Sequence[Mapping[str, Any]] | None = None,
           where: str = "sweep") -> list[tuple[str | None, dict[str, Any]]]:
    """The parameter sets of ``[sweep]`` (cartesian product) combined with ``[[runs]]``.

    Returns
    -------
    list of (run name or None, parameters)
        In order: runs, then the product with the first key varying slowest.

    Example
    -------
    >>> [p for _, p in expand({"a": [1, 2], "b": ["x"]})]
    [{'a': 1, 'b': 'x'}, {'a': 2, 'b': 'x'}]
    """
    axes = _flatten(sweep)
    for key, values in axes.items():
        if not isinstance(values, list) or not values:
            raise SceneError(f"{where}: [sweep] '{key}': expected a non-empty list of values, got {values!r}")
        seen = [json.dumps(_canonical(v), sort_keys=True) for v in values]
        if len(set(seen)) != len(seen):
            raise SceneError(f"{where}: [sweep] '{key}': values repeat in {values!r}")
    points = [dict(zip(axes, combo, strict=True)) for combo in itertools.product(*axes.values())]
    run_sets: list[tuple[str | None, dict[str, Any]]] = []
    for k, run in enumerate(runs if runs else [{}]):
        if not isinstance(run, dict):
            raise SceneError(f"{where}: [[runs]] {k}: expected a table, got {run!r}")
        run = dict(run)
        name = run.pop("id", None)
        if name is not None and (not isinstance(name, str) or not _ID_OK.match(name)):
            raise SceneError(f"{where}: [[runs]] {k} 'id': expected letters, digits and . _ + , = - "
                             f"(at most 120), got {name!r}")
        params = _flatten(run)
        clash = sorted(set(params) & set(axes))
        if clash:
            raise SceneError(f"{where}: [[runs]] {k}: '{clash[0]}' is also swept in [sweep]")
        run_sets.append((name, params))
    return [(name, {**params, **point}) for name, params in run_sets for point in points]


def load_sweep(path: str | os.PathLike[str], commands: Mapping[str, Any] | None = None) -> Sweep:
    """Read a sweep file and expand it into tasks.

    Parameters
    ----------
    path : path-like
        The sweep file (TOML); ``scene`` and ``inputs`` are relative to it.
    commands : mapping, optional
        The command table (default :data:`unmesh.batch.tasks.COMMANDS`); a command must be in it
        and available (its module installed).

    Raises
    ------
    unmesh.errors.SceneError
        Missing file, bad TOML, unknown keys or commands, bad values, repeated tasks.
    """
    from unmesh.batch.tasks import COMMANDS, command

    p = Path(path).resolve()
    where = p.name
    if not p.is_file():
        raise SceneError(f"{p}: sweep file not found")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{where}: invalid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise SceneError(f"{where}: not a UTF-8 text file") from None
    for key in data:
        if key not in SWEEP_KEYS:
            close = difflib.get_close_matches(key, SWEEP_KEYS, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else f"; expected one of {', '.join(SWEEP_KEYS)}"
            raise SceneError(f"{where}: unknown key '{key}'{hint}")
    name = data.get("command")
    if not isinstance(name, str):
        raise SceneError(f"{where}: 'command': expected a command name such as \"sph\", got {name!r}")
    cmd = command(name, where=where, commands=COMMANDS if commands is None else commands)
    base = p.parent
    duration = data.get("duration")
    if duration is not None:
        if isinstance(duration, bool) or not isinstance(duration, int | float) or not duration > 0:
            raise SceneError(f"{where}: 'duration': expected a positive number of seconds, got {duration!r}")
        duration = float(duration)
    options = data.get("options", [])
    if not isinstance(options, list) or not all(isinstance(o, str) for o in options):
        raise SceneError(f"{where}: 'options': expected a list of strings such as [\"--size\", \"400x300\"], "
                         f"got {options!r}")
    if options and cmd.builder is not None:
        raise SceneError(f"{where}: 'options': command '{name}' runs its scene in-process; give its settings as "
                         "[sweep] or [[runs]] keys (the keys of --set) and 'duration'")
    output = data.get("output")
    if output is not None and (not isinstance(output, str) or not output or "/" in output or "\\" in output):
        raise SceneError(f"{where}: 'output': expected a file name such as \"{{stem}}.ply\", got {output!r}")
    sweep_table = data.get("sweep", {})
    if not isinstance(sweep_table, dict):
        raise SceneError(f"{where}: 'sweep': expected a table [sweep], got {sweep_table!r}")
    runs = data.get("runs")
    if runs is not None and not isinstance(runs, list):
        raise SceneError(f"{where}: 'runs': expected tables [[runs]], got {runs!r}")
    sets = expand(sweep_table, runs, where)
    scene: Path | None = None
    inputs: list[str | None] = [None]
    if cmd.kind == "scene":
        if "inputs" in data:
            raise SceneError(f"{where}: 'inputs': command '{name}' runs a scene; give 'scene' instead")
        raw = data.get("scene")
        if not isinstance(raw, str) or not raw:
            raise SceneError(f"{where}: 'scene': expected the base scene file of command '{name}', got {raw!r}")
        scene = (base / raw).resolve()
        if not scene.is_file():
            raise SceneError(f"{where}: 'scene': no such file {raw!r} (relative to {base})")
    else:
        if "scene" in data:
            raise SceneError(f"{where}: 'scene': command '{name}' runs on input files; give 'inputs' instead")
        if duration is not None:
            raise SceneError(f"{where}: 'duration': only for simulation commands, not '{name}'")
        raw_inputs = data.get("inputs")
        if isinstance(raw_inputs, str):
            raw_inputs = [raw_inputs]
        if not isinstance(raw_inputs, list) or not raw_inputs:
            raise SceneError(f"{where}: 'inputs': expected a file, glob pattern or list of them for command "
                             f"'{name}', got {raw_inputs!r}")
        inputs = list(_glob_inputs(where, base, raw_inputs, cmd.accepts_names))
    tasks: list[Task] = []
    seen: dict[str, int] = {}
    for inp in inputs:
        shown = None if inp is None else (os.path.relpath(inp, base) if os.path.isabs(inp) else inp)
        for run_name, params in sets:
            tid = task_id(params, shown, run_name if run_name is not None and not sweep_table else None)
            if run_name is not None and not sweep_table and inp is None:
                tid = run_name
            if tid in seen:
                raise SceneError(f"{where}: tasks {seen[tid]} and {len(tasks)} are the same ({tid}); "
                                 "each parameter set may appear once")
            seen[tid] = len(tasks)
            tasks.append(Task(tid, tuple(params.items()), inp))
    return Sweep(p, name, scene, duration, tuple(options), output, tuple(tasks))
