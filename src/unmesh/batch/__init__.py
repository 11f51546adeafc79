"""Batch execution on Dask distributed: parameter sweeps, folders of models, frames in parallel.

``unmesh batch SWEEP.toml -o OUTDIR [--workers N] [--scheduler ADDRESS] [--resume]`` expands a
sweep file (:mod:`unmesh.batch.sweep`, format in ``docs/batch.md``) into tasks, runs each in a
Dask worker exactly as the command would run alone (:mod:`unmesh.batch.tasks`), and records
provenance and status in ``OUTDIR/batch.json`` and the results in ``OUTDIR/batch.csv``
(:mod:`unmesh.batch.manifest`); :func:`plot_metric` draws a figure against a swept parameter.
The same code runs on a local cluster (default) or any Dask deployment given its scheduler.
Dask is optional: ``pip install 'unmesh[batch]'``.

Example
-------
>>> from unmesh.batch import task_id
>>> task_id({"simulation.spacing": 0.02})
'spacing=0.02-470b6b5a'
"""

from __future__ import annotations

from unmesh.batch.engine import run_batch
from unmesh.batch.manifest import load_manifest, versions, write_csv
from unmesh.batch.plot import plot_metric
from unmesh.batch.sweep import Sweep, Task, expand, load_sweep, task_id
from unmesh.batch.tasks import COMMANDS, Command, TaskFailed, register_command, run_task

__all__ = [
    "COMMANDS",
    "Command",
    "Sweep",
    "Task",
    "TaskFailed",
    "expand",
    "load_manifest",
    "load_sweep",
    "plot_metric",
    "register_command",
    "run_batch",
    "run_task",
    "task_id",
    "versions",
    "write_csv",
]
