"""``OUTDIR/batch.json`` (provenance and status of every task) and ``OUTDIR/batch.csv`` (results at a glance).

``batch.json`` is rewritten atomically whenever a task changes state::

    {"versions": {"unmesh": ..., "numba": ..., "numpy": ..., "dask": ..., "distributed": ..., "python": ...},
     "command": "sph", "sweep": "/abs/sweep.toml", "started": "...", "updated": "...",
     "tasks": [{"id": ..., "parameters": {...}, "input": ..., "status": "pending" | "running" | "done" | "failed",
                "error": "...", "wall_seconds": ..., "worker": ..., "output": "...",
                "figures": {...}}, ...]}

``batch.csv`` has one row per task: id, status, input, the parameters (full dotted keys), the
wall time, then the figures of the task's ``summary.json`` (top-level numbers and, prefixed
``final.``, the numbers of its last frame record, lists flattened as ``key.0``, ``key.1``...)
or, for commands without a summary, the figures the task reported.

Example
-------
>>> flatten_figures({"status": "completed", "steps": 10, "frames": [{"frame": 0}, {"frame": 3, "e": [1.0, 2.0]}]})
{'run_status': 'completed', 'steps': 10, 'final.frame': 3, 'final.e.0': 1.0, 'final.e.1': 2.0}
"""

from __future__ import annotations

import csv
import io as _io
import json
import os
import platform
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from unmesh.errors import FormatError
from unmesh.io.atomic import atomic_write_json, atomic_write_text

__all__ = ["STATUSES", "flatten_figures", "load_manifest", "new_manifest", "task_figures", "versions",
           "write_csv", "write_manifest"]

#: The states of a task.
STATUSES = ("pending", "running", "done", "failed")


def versions() -> dict[str, str | None]:
    """Versions of unmesh, numba, numpy, dask, distributed and Python (``None``: not installed)."""
    from importlib import metadata

    from unmesh._version import __version__

    out: dict[str, str | None] = {"unmesh": __version__}
    for name in ("numba", "numpy", "dask", "distributed"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    out["python"] = platform.python_version()
    return out


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def new_manifest(sweep: Any, previous: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The manifest of a sweep's tasks; with ``previous`` (``--resume``), done tasks keep their record."""
    old = {t["id"]: t for t in (previous or {}).get("tasks", [])}
    tasks = []
    for task in sweep.tasks:
        rec = old.get(task.id)
        if rec is not None and rec.get("status") == "done":
            tasks.append(dict(rec))
            continue
        tasks.append({"id": task.id, "parameters": task.params, "input": task.input, "status": "pending",
                      "error": None, "wall_seconds": None, "worker": None, "output": None, "figures": {}})
    started = (previous or {}).get("started", _now())
    return {"versions": versions(), "command": sweep.command, "sweep": os.fspath(sweep.path),
            "scene": None if sweep.scene is None else os.fspath(sweep.scene), "started": started,
            "updated": _now(), "tasks": tasks}


def write_manifest(outdir: str | os.PathLike[str], manifest: dict[str, Any]) -> Path:
    """Write ``OUTDIR/batch.json`` atomically."""
    manifest["updated"] = _now()
    path = Path(outdir) / "batch.json"
    atomic_write_json(path, manifest)
    return path


def load_manifest(outdir: str | os.PathLike[str]) -> dict[str, Any] | None:
    """``OUTDIR/batch.json``, or ``None`` when there is none.

    Raises
    ------
    unmesh.errors.FormatError
        The file is not a batch manifest.
    """
    path = Path(outdir) / "batch.json"
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path}: not a batch manifest (invalid JSON: {exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("tasks"), list):
        raise FormatError(f"{path}: not a batch manifest (no 'tasks' list)")
    return data


def _flat(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, bool) or isinstance(value, int | float | str) or value is None:
        if not isinstance(value, str) or prefix in ("run_status", "run_message"):
            out[prefix] = value
        return
    if isinstance(value, Mapping):
        for k, v in value.items():
            _flat(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(value, list | tuple) and all(not isinstance(v, list | tuple | Mapping) for v in value):
        for k, v in enumerate(value):
            _flat(f"{prefix}.{k}", v, out)


def flatten_figures(summary: Mapping[str, Any]) -> dict[str, Any]:
    """Scalar figures of a ``summary.json``: top-level values and the last frame record as ``final.*``."""
    out: dict[str, Any] = {}
    for key, value in summary.items():
        if key == "frames":
            continue
        # the run's own status and message, named apart from the task's status column
        _flat(f"run_{key}" if key in ("status", "message") else str(key), value, out)
    frames = summary.get("frames")
    if isinstance(frames, list) and frames and isinstance(frames[-1], Mapping):
        _flat("final", frames[-1], out)
    return out


def task_figures(record: Mapping[str, Any], outdir: str | os.PathLike[str]) -> dict[str, Any]:
    """The figures of a task: its ``summary.json`` (flattened) if it has one, else its reported figures."""
    summary = Path(outdir) / str(record["id"]) / "summary.json"
    if summary.is_file():
        try:
            return flatten_figures(json.loads(summary.read_text(encoding="utf-8")))
        except (json.JSONDecodeError, UnicodeDecodeError):
            return {}
    figures: dict[str, Any] = {}
    _flat("", record.get("figures") or {}, figures)
    return figures


def _cell(value: Any) -> Any:
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | tuple | dict):
        return json.dumps(value)
    return "" if value is None else value


def write_csv(outdir: str | os.PathLike[str], manifest: Mapping[str, Any]) -> Path:
    """Write ``OUTDIR/batch.csv`` (atomically) from the manifest and the tasks' summaries."""
    tasks: Iterable[Mapping[str, Any]] = manifest.get("tasks", [])
    rows = []
    params: dict[str, None] = {}
    figures: dict[str, None] = {}
    has_input = False
    for rec in tasks:
        figs = task_figures(rec, outdir) if rec.get("status") == "done" else {}
        rows.append((rec, figs))
        params.update(dict.fromkeys(rec.get("parameters", {})))
        figures.update(dict.fromkeys(figs))
        has_input = has_input or rec.get("input") is not None
    head = ["id", "status", *(["input"] if has_input else []), *params, "wall_seconds", "worker", "error"]
    fig_cols = [f for f in figures if f not in head]
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head + fig_cols)
    for rec, figs in rows:
        p = rec.get("parameters", {})
        row = [rec["id"], rec.get("status"), *([rec.get("input")] if has_input else []),
               *(p.get(k) for k in params), rec.get("wall_seconds"), rec.get("worker"), rec.get("error")]
        w.writerow([_cell(v) for v in row] + [_cell(figs.get(f)) for f in fig_cols])
    path = Path(outdir) / "batch.csv"
    atomic_write_text(path, buf.getvalue())
    return path
