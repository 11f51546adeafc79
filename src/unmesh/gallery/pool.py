"""Gallery examples in worker processes: ``unmesh gallery --jobs N``.

Most of a cold gallery run is numba compiling each capability's kernels, which uses one core
whatever numba's thread count. :func:`run_in_workers` runs the examples in ``jobs`` spawned
processes, longest expected first, each process with ``cpu_count // jobs`` numba threads, so
the cores stay busy while one example compiles. An example runs exactly as in-process
(:func:`unmesh.gallery.run.run_one`); only its own progress bars are off (the parent shows one
bar for the gallery). A worker that dies (a crash, out of memory) fails the examples it had,
with a message saying so, and the others still run.

Example
-------
>>> default_jobs() >= 1 and threads_per_job(1) >= 1
True
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

from unmesh.gallery.registry import Example, ExampleContext
from unmesh.gallery.run import ExampleResult, run_one

__all__ = ["MAX_DEFAULT_JOBS", "default_jobs", "run_in_workers", "threads_per_job"]

#: Most worker processes ``--jobs`` defaults to (each example may hold a few GB).
MAX_DEFAULT_JOBS = 4


def _cpus() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def default_jobs() -> int:
    """Worker processes for ``unmesh gallery``: the usable CPUs, at most :data:`MAX_DEFAULT_JOBS`."""
    return min(_cpus(), MAX_DEFAULT_JOBS)


def threads_per_job(jobs: int) -> int:
    """numba threads of each of ``jobs`` workers: the usable CPUs shared out, at least one."""
    return max(1, _cpus() // max(1, int(jobs)))


def _init_worker(threads: int) -> None:
    import numba

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))


def run_in_workers(items: Sequence[tuple[int, Example]], weights: Sequence[float], outdir: Path, quick: bool,
                   jobs: int, on_done: Callable[[int, ExampleResult], None],
                   on_wait: Callable[[list[str]], None] | None = None) -> None:
    """Run ``items`` (``(index, example)``) in ``jobs`` processes; ``on_done(index, result)`` as each ends.

    Parameters
    ----------
    items : sequence of (int, Example)
        The examples and their positions on the page.
    weights : sequence of float
        Expected seconds of each item; the longest start first.
    outdir : Path
        The gallery's root folder.
    quick : bool
        Small, fast versions.
    jobs : int
        Worker processes (>= 1).
    on_done : callable
        Called in this process, in completion order.
    on_wait : callable, optional
        Called about once a second while examples run, with the names of those handed to a
        worker and not finished (a progress bar's heartbeat).
    """
    order = sorted(range(len(items)), key=lambda k: -weights[k])
    broken = _run_pool([items[k] for k in order], outdir, quick, jobs, on_done, on_wait)
    # a worker died (a crash, out of memory) and took the pool with it: the examples it left
    # unfinished run again one per process, so only the one that kills its process fails
    for item in broken:
        for index, ex in _run_pool([item], outdir, quick, 1, on_done, on_wait):
            ctx = ExampleContext(outdir=Path(outdir) / ex.name, root=Path(outdir), quick=quick, progress=False)
            on_done(index, ExampleResult(ex, ctx, 0.0, "the worker process running it died (a crash or out of memory)"))


def _run_pool(items: Sequence[tuple[int, Example]], outdir: Path, quick: bool, jobs: int,
              on_done: Callable[[int, ExampleResult], None],
              on_wait: Callable[[list[str]], None] | None) -> list[tuple[int, Example]]:
    """Run ``items`` in one pool of ``jobs`` processes, in the order given; the items a broken pool left."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init_worker, initargs=(threads_per_job(jobs),))
    broken: list[tuple[int, Example]] = []
    try:
        futures = {pool.submit(run_one, ex, outdir, quick, False): (k, ex) for k, ex in items}
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=lambda f: futures[f][0]):
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    broken.append(futures[fut])
                    continue
                on_done(futures[fut][0], result)
            if on_wait is not None and pending:
                on_wait([futures[f][1].name for f in pending if f.running()])
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
    return sorted(broken, key=lambda item: item[0])
