"""The commands a batch can run, and running one task inside a worker.

:data:`COMMANDS` maps a command name to a :class:`Command`: its kind (``"scene"``: a scene
file with ``--set`` parameters, or ``"inputs"``: one task per input file with option
parameters), the module that must be installed for it, and the function that runs a task.
A task runs the command in-process through the capability's own public function (the scene
commands through :func:`unmesh.sim.cli.run_scene`, the others through the capability's
``cli.register`` parser), so its files are those of the same command run alone.
:func:`register_command` adds commands; ``csg`` and ``convert`` are listed and become
available once their packages exist.

Example
-------
>>> sorted(COMMANDS)[:3]
['convert', 'csg', 'fem']
>>> COMMANDS["sph"].kind
'scene'
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import json
import math
import os
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from unmesh.errors import InputError, SceneError, SimulationError, UnmeshError

__all__ = ["COMMANDS", "Command", "TaskFailed", "command", "register_command", "run_task", "task_spec"]


@dataclass(frozen=True)
class Command:
    """A sub-command that batch tasks can run.

    Attributes
    ----------
    name : str
        The sub-command (``"sph"``).
    kind : str
        ``"scene"`` (one scene, parameters are ``--set`` keys) or ``"inputs"`` (one task per
        input file, parameters are options without the dashes).
    module : str
        Module that must be importable for the command to be available.
    runner : str
        ``"module:function"`` called in the worker as ``function(spec, resume) -> figures``.
    builder : str or None
        ``"module:function"`` building a simulation from a scene (scene commands run in-process).
    output : str or None
        Default output file name of input commands (``{stem}`` is the input's stem).
    accepts_names : bool
        Inputs may be names (built-in shapes) instead of files.
    """

    name: str
    kind: str
    module: str
    runner: str
    builder: str | None = None
    output: str | None = None
    accepts_names: bool = False

    def __post_init__(self) -> None:
        if self.kind not in ("scene", "inputs"):
            raise InputError(f"Command.kind: expected 'scene' or 'inputs', got {self.kind!r}")

    def available(self) -> bool:
        """Whether the command's module is installed."""
        try:
            return importlib.util.find_spec(self.module) is not None
        except ModuleNotFoundError:
            return False


_SCENE = "unmesh.batch.tasks:run_scene_task"
_ARGV = "unmesh.batch.tasks:run_argv_task"

#: Commands known to ``unmesh batch`` (extend with :func:`register_command`).
COMMANDS: dict[str, Command] = {}


def register_command(cmd: Command) -> None:
    """Add (or replace) a command in :data:`COMMANDS`."""
    if not isinstance(cmd, Command):
        raise InputError(f"cmd: expected a unmesh.batch.Command, got {type(cmd).__name__}")
    COMMANDS[cmd.name] = cmd


for _cmd in (
    Command("sph", "scene", "unmesh.sph.scene", _SCENE, builder="unmesh.sph.scene:build_simulation"),
    Command("shell", "scene", "unmesh.shells.scene", _SCENE, builder="unmesh.shells.scene:build_simulation"),
    Command("fem", "scene", "unmesh.fem.scene", _SCENE, builder="unmesh.fem.scene:build_simulation"),
    Command("csg", "scene", "unmesh.csg.cli", _ARGV),
    Command("render", "inputs", "unmesh.render.cli", _ARGV, output="{stem}.png"),
    Command("sample", "inputs", "unmesh.surfels.sampling", "unmesh.batch.tasks:run_sample_task",
            output="{stem}.ply", accepts_names=True),
    Command("convert", "inputs", "unmesh.convert.cli", _ARGV, output="{stem}.ply"),
):
    register_command(_cmd)


def command(name: str, where: str = "sweep", commands: Mapping[str, Command] | None = None) -> Command:
    """The available command ``name``, or a :class:`SceneError` naming the known ones."""
    table = COMMANDS if commands is None else commands
    cmd = table.get(name)
    if cmd is None:
        raise SceneError(f"{where}: 'command': unknown command {name!r}; expected one of {', '.join(sorted(table))}")
    if not cmd.available():
        ready = ", ".join(sorted(n for n, c in table.items() if c.available()))
        raise SceneError(f"{where}: 'command': {name!r} is not available in this version of unmesh "
                         f"(module {cmd.module} is missing); available: {ready}")
    return cmd


class TaskFailed(UnmeshError):
    """A task's error, as one line, with the worker that ran it (picklable across processes)."""

    def __init__(self, message: str, worker: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.worker = worker

    def __reduce__(self) -> tuple[Any, ...]:
        return (TaskFailed, (self.message, self.worker))


def one_line(exc: BaseException) -> str:
    """``"Type: first line of the message"`` of an exception."""
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    if isinstance(exc, TaskFailed):
        return msg
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def _resolve(dotted: str) -> Callable[..., Any]:
    module, _, name = dotted.partition(":")
    return getattr(importlib.import_module(module), name)


def task_spec(sweep: Any, task: Any, outdir: str | os.PathLike[str], *, resume: bool = False,
              numba_threads: int | None = None, commands: Mapping[str, Command] | None = None) -> dict[str, Any]:
    """The plain-data description of one task that :func:`run_task` runs in a worker."""
    cmd = (COMMANDS if commands is None else commands)[sweep.command]
    root = Path(outdir).resolve()
    output = None
    if cmd.kind == "inputs":
        template = sweep.output or cmd.output or "{stem}.out"
        stem = Path(task.input).stem if task.input is not None else "output"
        output = template.replace("{stem}", stem)
    return {
        "id": task.id, "command": cmd.name, "kind": cmd.kind, "module": cmd.module, "runner": cmd.runner,
        "builder": cmd.builder, "scene": None if sweep.scene is None else os.fspath(sweep.scene),
        "input": task.input, "parameters": task.params, "duration": sweep.duration,
        "options": list(sweep.options), "outdir": os.fspath(root / task.id), "output": output,
        "log": os.fspath(root / "logs" / f"{task.id}.log"), "resume": bool(resume), "numba_threads": numba_threads,
    }


def run_task(spec: Mapping[str, Any]) -> dict[str, Any]:
    """Run one task (in a Dask worker); returns ``{"wall_seconds", "worker", "output", "figures"}``.

    The task's folder is emptied first, unless ``spec["resume"]`` is set and the folder holds a
    simulation checkpoint (the simulation then continues with its own ``--resume``). The
    command's printed output goes to ``OUTDIR/logs/<id>.log``.

    Raises
    ------
    TaskFailed
        The command failed; the message is its one-line error.
    """
    from unmesh.distributed import limit_numba_threads, worker_name

    worker = worker_name()
    outdir = Path(spec["outdir"])
    resume = bool(spec.get("resume")) and (outdir / "checkpoint.npz").is_file()
    start = time.perf_counter()
    try:
        limit_numba_threads(spec.get("numba_threads"))
        if not resume and outdir.exists():
            shutil.rmtree(outdir)
        outdir.mkdir(parents=True, exist_ok=True)
        log = Path(spec["log"])
        log.parent.mkdir(parents=True, exist_ok=True)
        runner = _resolve(spec["runner"])
        with open(log, "a", encoding="utf-8") as fh, contextlib.redirect_stdout(fh), contextlib.redirect_stderr(fh):
            print(f"task {spec['id']} on {worker}{' (resumed)' if resume else ''}", flush=True)
            figures = runner(spec, resume) or {}
    except Exception as exc:
        raise TaskFailed(one_line(exc), worker) from None
    out = outdir / spec["output"] if spec.get("output") else outdir
    return {"wall_seconds": time.perf_counter() - start, "worker": worker, "output": os.fspath(out),
            "figures": figures, "resumed": resume}


def run_scene_task(spec: Mapping[str, Any], resume: bool) -> dict[str, Any]:
    """A scene command in-process: :func:`unmesh.sim.cli.run_scene` with the task's ``--set`` values."""
    if spec.get("builder") is None:
        return run_argv_task(spec, resume)
    from unmesh.sim.cli import run_scene

    build = _resolve(spec["builder"])
    result = run_scene(spec["scene"], spec["outdir"], build, overrides=dict(spec["parameters"]),
                       duration=spec.get("duration"), resume=resume, progress=False)
    if result.status != "completed":
        raise SimulationError(f"run ended with status {result.status}: {result.summary.get('message', '')}")
    return {"frames": result.frames, "steps": result.steps}


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("nan" if value != value else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise InputError(f"parameter: expected a TOML value, got {value!r}")


def _option_args(parameters: Mapping[str, Any]) -> list[str]:
    argv: list[str] = []
    for key, value in parameters.items():
        flag = f"--{key}"
        if value is True:
            argv.append(flag)
        elif value is False or value is None:
            continue
        elif isinstance(value, list | tuple):
            argv += [flag, ",".join(_toml_value(v) if not isinstance(v, str) else v for v in value)]
        else:
            argv += [flag, value if isinstance(value, str) else _toml_value(value)]
    return argv


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def command_argv(spec: Mapping[str, Any], resume: bool = False) -> list[str]:
    """The ``unmesh`` command line equivalent to a task (without the leading ``unmesh``)."""
    if spec["kind"] == "scene":
        argv = [spec["command"], spec["scene"], "-o", spec["outdir"]]
        for key, value in spec["parameters"].items():
            argv += ["--set", f"{key}={_toml_value(value)}"]
        if spec.get("duration") is not None:
            argv += ["--duration", repr(float(spec["duration"]))]
        if resume:
            argv.append("--resume")
    else:
        argv = [spec["command"], spec["input"], "-o", os.path.join(spec["outdir"], spec["output"])]
        argv += _option_args(spec["parameters"])
    return argv + list(spec.get("options", []))


def run_argv_task(spec: Mapping[str, Any], resume: bool) -> dict[str, Any]:
    """A command through its capability's own parser (``<capability>.cli.register``) and ``run``."""
    module = importlib.import_module(spec["module"])
    parser = _Parser(prog="unmesh")
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)
    module.register(sub)
    argv = command_argv(spec, resume)
    sub_parser = sub.choices[spec["command"]]
    if any("--no-progress" in a.option_strings for a in sub_parser._actions):
        argv.append("--no-progress")
    args = parser.parse_args(argv)
    status = int(args.func(args) or 0)
    if status:
        raise SimulationError(f"unmesh {spec['command']} exited with status {status}")
    return {}


def run_sample_task(spec: Mapping[str, Any], resume: bool) -> dict[str, Any]:
    """``unmesh sample INPUT -o OUT.ply [--spacing D] [--ascii]`` (the same steps as the command)."""
    import numpy as np

    from unmesh import io
    from unmesh.shapes import SHAPES, by_name
    from unmesh.surfels.sampling import sample_mesh

    params = dict(spec["parameters"])
    extra = list(spec.get("options", []))
    spacing = params.pop("spacing", None)
    ascii_ = bool(params.pop("ascii", False))
    while extra:
        opt = extra.pop(0)
        if opt == "--ascii":
            ascii_ = True
        elif opt == "--spacing" and extra:
            spacing = float(extra.pop(0))
        elif opt.startswith("--spacing="):
            spacing = float(opt.split("=", 1)[1])
        elif opt != "--no-progress":
            raise InputError(f"sample: unknown option {opt!r}; expected --spacing D or --ascii")
    if params:
        raise InputError(f"sample: unknown parameter {sorted(params)[0]!r}; expected spacing or ascii")
    out = Path(spec["outdir"]) / spec["output"]
    if out.suffix.lower() != ".ply":
        raise InputError(f"output: expected a .ply file, got {out.name!r}")
    source = str(spec["input"])
    is_shape = source.lower() in SHAPES and not Path(source).exists()
    if is_shape:
        shape = by_name(source)
        bounds = shape.bounds()
    else:
        if not Path(source).exists():
            raise InputError(f"MESH: no such file or built-in shape {source!r}; shapes: {', '.join(sorted(SHAPES))}")
        mesh = io.load_mesh(source)
        bounds = mesh.bounds()
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    if spacing is None:
        spacing = diag / 200.0
    elif isinstance(spacing, bool) or not (np.isfinite(float(spacing)) and float(spacing) > 0):
        raise InputError(f"--spacing: expected a positive number, got {spacing}")
    spacing = float(spacing)
    cloud = shape.surfels(spacing) if is_shape else sample_mesh(mesh, spacing, progress=False)
    io.save(out, cloud, binary=not ascii_)
    r = cloud.radii
    print(f"sampled {source} -> {len(cloud)} surfels, spacing {spacing:.6g}")
    return {"surfels": len(cloud), "spacing": spacing, "radius_mean": float(r.mean()), "radius_max": float(r.max())}
