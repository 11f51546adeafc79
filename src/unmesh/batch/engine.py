"""Run a sweep's tasks on Dask distributed, keeping ``OUTDIR/batch.json`` consistent at every moment.

Each task runs :func:`unmesh.batch.tasks.run_task` in a worker and writes into
``OUTDIR/<task-id>/``. A failing task is retried once by Dask (``retries=1``), then recorded as
failed with its one-line error while the other tasks go on. A worker that dies mid-task has
its task rerun elsewhere by the scheduler. ``resume=True`` skips the done tasks and reruns
the rest (simulations continue from their checkpoints). Ctrl-C cancels the queued and running
tasks, marks them pending again and leaves ``batch.json`` and ``batch.csv`` consistent.

Example
-------
>>> manifest = run_batch("sweep.toml", "out", workers=2)          # doctest: +SKIP
>>> [t["status"] for t in manifest["tasks"]]                      # doctest: +SKIP
['done', 'done', 'done', 'done']
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

from unmesh.batch.manifest import load_manifest, new_manifest, write_csv, write_manifest
from unmesh.batch.sweep import Sweep, load_sweep
from unmesh.batch.tasks import TaskFailed, one_line, run_task, task_spec
from unmesh.errors import InputError

__all__ = ["run_batch"]

#: Files and folders of a batch in OUTDIR besides the task folders.
_OWN = {"batch.json", "batch.csv", "logs"}


def _check_outdir(outdir: Path, sweep: Sweep, previous: dict[str, Any] | None, resume: bool) -> None:
    if previous is not None:
        if not resume:
            raise InputError(f"-o: {outdir} already holds a batch (batch.json); continue it with --resume "
                             "or choose another output directory")
        ids = {t.id for t in sweep.tasks}
        old = {t.get("id") for t in previous["tasks"]}
        if previous.get("command") != sweep.command or not (ids & old or not old):
            raise InputError(f"--resume: {outdir}/batch.json belongs to another sweep (command "
                             f"{previous.get('command')!r}, no task ids in common with {sweep.path.name})")
        return
    if outdir.exists():
        if not outdir.is_dir():
            raise InputError(f"-o: expected a directory, got the file {outdir}")
        if any(p.name not in _OWN and not p.name.startswith(".") for p in outdir.iterdir()):
            raise InputError(f"-o: {outdir} is not empty and holds no batch; choose an empty or new directory")


def run_batch(sweep: Sweep | str | os.PathLike[str], outdir: str | os.PathLike[str], *, workers: int | None = None,
              scheduler: str | None = None, resume: bool = False, progress: bool = True, client: Any = None,
              retries: int = 1, numba_threads: int | None = None, poll_seconds: float = 0.5,
              log: Any = "stderr") -> dict[str, Any]:
    """Run every task of a sweep on Dask distributed; returns the final manifest (``batch.json``).

    Parameters
    ----------
    sweep : Sweep or path-like
        A sweep (:func:`unmesh.batch.load_sweep`) or its file.
    outdir : path-like
        Output directory: ``batch.json``, ``batch.csv``, ``logs/`` and one folder per task.
    workers : int, optional
        Worker processes of a new local cluster (default: one per core).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``) instead of a local cluster.
    resume : bool
        Continue the batch already in ``outdir``: skip done tasks, rerun the others.
    progress : bool
        A progress bar over tasks.
    client : distributed.Client, optional
        Use this client (then ``workers``/``scheduler`` are ignored).
    retries : int
        Reruns of a failing task before it is recorded as failed.
    numba_threads : int, optional
        Numba threads per task (default: as :func:`unmesh.distributed.connect` chooses).
    poll_seconds : float
        How often the running tasks' workers are read from the scheduler.
    log : file, "stderr" or None
        Where the cluster and dashboard addresses are printed (default ``sys.stderr``; ``None``: silent).

    Raises
    ------
    unmesh.errors.InputError
        ``outdir`` is not empty and holds no batch, or holds one without ``resume``.
    unmesh.errors.SceneError
        A bad sweep file.
    unmesh.errors.MissingDependencyError
        Dask distributed is not installed (``pip install 'unmesh[batch]'``).
    KeyboardInterrupt
        After cancelling the tasks and writing a consistent ``batch.json``.
    """
    from tqdm.auto import tqdm

    from unmesh.distributed import connect, require_dask, submit_all

    sw = sweep if isinstance(sweep, Sweep) else load_sweep(sweep)
    out = Path(outdir).resolve()
    previous = load_manifest(out) if out.is_dir() else None
    _check_outdir(out, sw, previous, resume)
    distributed = require_dask()
    out.mkdir(parents=True, exist_ok=True)
    manifest = new_manifest(sw, previous if resume else None)
    records = {rec["id"]: rec for rec in manifest["tasks"]}
    write_manifest(out, manifest)
    todo = [t for t in sw.tasks if records[t.id]["status"] != "done"]
    with contextlib.ExitStack() as stack:
        if client is None and todo:
            client = stack.enter_context(connect(workers, scheduler, numba_threads=numba_threads, progress_output=log))
        # a local cluster limits numba through NUMBA_NUM_THREADS; on an existing cluster each task limits itself
        threads = numba_threads if numba_threads is not None else (1 if scheduler is not None else None)
        specs = {t.id: task_spec(sw, t, out, resume=resume, numba_threads=threads) for t in todo}
        futures = submit_all(client, run_task, [(tid, (spec,)) for tid, spec in specs.items()], retries=retries) \
            if todo else {}
        key_to_id = {fut.key: tid for fut, tid in futures.items()}
        bar = tqdm(total=len(sw.tasks), initial=len(sw.tasks) - len(todo), desc="batch", unit="task",
                   disable=not progress)
        waiting = set(futures)
        try:
            while waiting:
                try:
                    done, not_done = distributed.wait(list(waiting), timeout=poll_seconds, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    done, not_done = set(), waiting
                changed = _mark_running(client, key_to_id, records)
                for fut in done:
                    _record(records[futures[fut]], fut)
                    bar.update(1)
                    changed = True
                waiting = set(not_done)
                if changed:
                    write_manifest(out, manifest)
        except BaseException:
            if client is not None and waiting:
                client.cancel(list(waiting), force=True)
            for fut in waiting:
                rec = records[futures[fut]]
                rec.update(status="pending", error="cancelled (interrupted)", worker=None)
            write_manifest(out, manifest)
            write_csv(out, manifest)
            raise
        finally:
            bar.close()
    write_manifest(out, manifest)
    write_csv(out, manifest)
    return manifest


def _mark_running(client: Any, key_to_id: dict[Any, str], records: dict[str, dict[str, Any]]) -> bool:
    """Mark the tasks the scheduler is processing as running on their worker; True if one changed."""
    try:
        processing = client.processing()
    except Exception:  # the scheduler view is a convenience; results come from the futures
        return False
    changed = False
    for worker, keys in processing.items():
        for key in keys:
            tid = key_to_id.get(key)
            rec = records.get(tid) if tid is not None else None
            if rec is not None and rec["status"] in ("pending", "running") and \
                    (rec["status"] != "running" or rec["worker"] != worker):
                rec.update(status="running", worker=worker, error=None)
                changed = True
    return changed


def _record(rec: dict[str, Any], fut: Any) -> None:
    if fut.status == "finished":
        res = fut.result()
        rec.update(status="done", error=None, wall_seconds=round(float(res["wall_seconds"]), 6),
                   worker=res["worker"], output=res["output"], figures=res.get("figures", {}),
                   resumed=bool(res.get("resumed")))
        return
    if fut.status == "cancelled":
        rec.update(status="pending", error="cancelled", worker=None)
        return
    exc = fut.exception()
    worker = exc.worker if isinstance(exc, TaskFailed) else rec.get("worker")
    rec.update(status="failed", error=one_line(exc), worker=worker, wall_seconds=None, output=None)
