"""A thin layer over Dask distributed: a client from ``--workers``/``--scheduler``, and task maps.

Used by ``unmesh batch`` (parameter sweeps, folders of models) and ``unmesh render OUTDIR
--workers N`` (frames in parallel). There is no scheduler, queue or RPC of our own: everything
runs on Dask distributed, so the same code uses a :class:`distributed.LocalCluster` on a
laptop (the default) or any existing Dask deployment (``dask scheduler`` + ``dask worker``,
dask-jobqueue, Kubernetes) given its address.

Dask is an optional dependency (``pip install 'unmesh[batch]'``), imported only inside these
functions; without it they raise :class:`unmesh.errors.MissingDependencyError` naming the extra.

Threads: the default local cluster starts one worker process per core with one Dask thread
each, and limits numba to ``cores // workers`` threads per worker (``NUMBA_NUM_THREADS`` set in
the worker processes before numba starts), so workers never oversubscribe the cores. On an
existing cluster the ``NumbaThreads`` worker plugin (a :class:`distributed.WorkerPlugin`) sets ``NUMBA_NUM_THREADS`` in workers
that have not started numba yet, and every task calls :func:`limit_numba_threads` itself.

Example
-------
>>> with connect(workers=2, progress_output=None) as client:      # doctest: +SKIP
...     squares = ordered_map(client, pow, [(k, 2) for k in range(8)], progress=False)
>>> squares                                                       # doctest: +SKIP
[0, 1, 4, 9, 16, 25, 36, 49]
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from unmesh.errors import InputError, MissingDependencyError

__all__ = [
    "EXTRA",
    "connect",
    "dashboard_address",
    "imap_ordered",
    "limit_numba_threads",
    "ordered_map",
    "require_dask",
    "submit_all",
    "worker_name",
]

#: The pip extra that installs Dask distributed.
EXTRA = "unmesh[batch]"


def require_dask() -> Any:
    """Import and return the :mod:`distributed` module, or raise naming the ``unmesh[batch]`` extra.

    Raises
    ------
    unmesh.errors.MissingDependencyError
        When Dask distributed is not installed.
    """
    try:
        import distributed
    except ImportError as exc:
        raise MissingDependencyError(
            f"parallel runs need Dask distributed, which is not installed ({exc}); "
            f"install it with: pip install '{EXTRA}'") from None
    return distributed


def limit_numba_threads(threads: int | None) -> int:
    """Run numba's parallel kernels of this thread on at most ``threads`` threads; returns the count used.

    ``None`` keeps numba's count. Numba's setting is per calling thread, so a task calls this itself.
    """
    import numba

    if threads is None:
        return int(numba.get_num_threads())
    n = max(1, min(int(threads), int(numba.config.NUMBA_NUM_THREADS)))
    numba.set_num_threads(n)
    return n


def worker_name() -> str:
    """The address of the Dask worker running the calling task (``host:pid`` outside a worker)."""
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        import socket

        return f"{socket.gethostname()}:{os.getpid()}"


def _numba_threads_class() -> type:
    """The :class:`NumbaThreads` worker plugin class (created on first use: it subclasses Dask's)."""
    cls = globals().get("_NUMBA_THREADS_CLASS")
    if cls is not None:
        return cls
    distributed = require_dask()

    class NumbaThreads(distributed.WorkerPlugin):
        """Dask worker plugin: set ``NUMBA_NUM_THREADS`` in workers where numba has not started yet."""

        name = "unmesh-numba-threads"

        def __init__(self, threads: int = 1) -> None:
            self.threads = int(threads)

        def setup(self, worker: Any) -> None:
            if "numba" not in sys.modules and "NUMBA_NUM_THREADS" not in os.environ:
                os.environ["NUMBA_NUM_THREADS"] = str(self.threads)

    NumbaThreads.__module__ = __name__
    NumbaThreads.__qualname__ = "NumbaThreads"
    globals()["_NUMBA_THREADS_CLASS"] = NumbaThreads
    return NumbaThreads


def __getattr__(name: str) -> Any:
    # ``NumbaThreads`` subclasses distributed.WorkerPlugin, so it exists only once Dask is imported;
    # workers unpickle it by this name.
    if name == "NumbaThreads":
        return _numba_threads_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def dashboard_address(client: Any) -> str | None:
    """The Dask dashboard's address of ``client``'s scheduler, or ``None`` when it has none (no bokeh)."""
    import importlib.util

    if importlib.util.find_spec("bokeh") is None:  # the scheduler keeps the port but serves no dashboard
        return None
    try:
        info = client.scheduler_info()
    except Exception:  # a dashboard is a convenience: never fail a run over it
        return None
    if "dashboard" not in info.get("services", {}):
        return None
    return str(client.dashboard_link)


@contextlib.contextmanager
def connect(workers: int | None = None, scheduler: str | None = None, *, numba_threads: int | None = None,
            dashboard: str | None = ":8787", progress_output: Any = "stderr") -> Iterator[Any]:
    """A Dask client: a new local cluster (default) or an existing scheduler; closed on exit.

    Parameters
    ----------
    workers : int, optional
        Worker processes of the local cluster (default: one per core), one thread each.
    scheduler : str, optional
        Address of an existing scheduler (``tcp://host:8786``); excludes ``workers``.
    numba_threads : int, optional
        Numba threads per worker (default: ``cores // workers`` locally, 1 on an existing cluster).
    dashboard : str or None
        Dashboard address of a local cluster (``None``: any free port).
    progress_output : file, "stderr" or None
        Where the cluster and dashboard addresses are printed (default ``sys.stderr``; ``None``: silent).

    Raises
    ------
    unmesh.errors.InputError
        Both ``workers`` and ``scheduler``, or a worker count below 1.
    unmesh.errors.MissingDependencyError
        Dask distributed is not installed.
    """
    if workers is not None and scheduler is not None:
        raise InputError(f"--workers/--scheduler: expected one of them, got --workers {workers} and "
                         f"--scheduler {scheduler!r} (an existing cluster has its own workers)")
    if workers is not None and int(workers) < 1:
        raise InputError(f"--workers: expected a positive number of worker processes, got {workers}")
    if numba_threads is not None and int(numba_threads) < 1:
        raise InputError(f"numba_threads: expected a positive number, got {numba_threads}")
    distributed = require_dask()
    import logging

    cores = os.cpu_count() or 1
    with contextlib.ExitStack() as stack:
        if scheduler is not None:
            client = stack.enter_context(distributed.Client(scheduler, timeout="30s"))
            threads = 1 if numba_threads is None else int(numba_threads)
            plugin = _numba_threads_class()
            client.register_plugin(plugin(threads), name=plugin.name)
            where = f"scheduler {scheduler}"
        else:
            n = cores if workers is None else int(workers)
            threads = max(1, cores // n) if numba_threads is None else int(numba_threads)
            env = {"NUMBA_NUM_THREADS": str(threads), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                   "OPENBLAS_NUM_THREADS": "1"}
            import dask

            # one task per worker thread at a time (the rest wait on the scheduler): long tasks
            # balance over workers, and a task the scheduler shows on a worker is running there
            stack.enter_context(dask.config.set({"distributed.scheduler.worker-saturation": 1.0}))
            with warnings.catch_warnings():
                # a busy dashboard port moves to a free one; the address printed below is the real one
                warnings.filterwarnings("ignore", message=r"Port \d+ is already in use")
                cluster = stack.enter_context(distributed.LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True, env=env, silence_logs=logging.ERROR,
                    dashboard_address=dashboard if dashboard is not None else ":0"))
            client = stack.enter_context(distributed.Client(cluster))
            where = f"local cluster of {n} worker process{'es' if n != 1 else ''}"
        if isinstance(progress_output, str):
            progress_output = sys.stderr
        if progress_output is not None:
            link = dashboard_address(client)
            print(f"dask: {where}, numba threads per worker {threads}; dashboard: "
                  f"{link or 'none (install bokeh for it)'}", file=progress_output)
        yield client


def submit_all(client: Any, fn: Callable[..., Any], calls: Sequence[tuple[str, tuple[Any, ...]]], *,
               retries: int = 1) -> dict[Any, str]:
    """Submit ``fn(*args)`` for each ``(name, args)``; returns ``{future: name}``.

    Task keys are ``"<fn>-<name>-<token>"`` (readable in the dashboard); ``retries`` reruns a failing
    call that many times before its future holds the error.
    """
    import uuid

    futures: dict[Any, str] = {}
    base = getattr(fn, "__name__", "task").strip("_")
    token = uuid.uuid4().hex[:8]  # one submission's keys never meet an earlier one's results
    for name, args in calls:
        fut = client.submit(fn, *args, key=f"{base}-{name}-{token}", retries=int(retries), pure=False)
        futures[fut] = name
    return futures


def imap_ordered(client: Any, fn: Callable[..., Any], args: Sequence[tuple[Any, ...]], *, retries: int = 1,
                 progress: bool = True, desc: str = "tasks") -> Iterator[Any]:
    """Yield ``fn(*a)`` for each ``a`` of ``args`` in order, computed on the cluster (all submitted at once).

    Results wait on the workers until their turn, so a long sequence (video frames) streams
    through the client. A call that still fails after ``retries`` reruns raises its error
    here; the remaining calls are then cancelled, as on Ctrl-C or when the consumer stops early.
    """
    from tqdm.auto import tqdm

    width = len(str(max(len(args) - 1, 0)))
    futures = list(submit_all(client, fn, [(f"{k:0{width}d}", a) for k, a in enumerate(args)], retries=retries))
    try:
        with tqdm(total=len(futures), desc=desc, unit="task", disable=not progress) as bar:
            for k, fut in enumerate(futures):
                value = fut.result()
                futures[k] = None  # release the result on the cluster
                fut.release()
                bar.update(1)
                yield value
    finally:
        rest = [f for f in futures if f is not None]
        if rest:
            client.cancel(rest, force=True)


def ordered_map(client: Any, fn: Callable[..., Any], args: Sequence[tuple[Any, ...]], *, retries: int = 1,
                progress: bool = True, desc: str = "tasks") -> list[Any]:
    """``[fn(*a) for a in args]`` on the cluster, in order (see :func:`imap_ordered`)."""
    return list(imap_ordered(client, fn, args, retries=retries, progress=progress, desc=desc))
