"""``unmesh batch``: run a sweep of simulations, renders or conversions on Dask distributed.

Examples::

    unmesh batch sweep.toml -o out                        # local cluster, one worker per core
    unmesh batch sweep.toml -o out --workers 2
    unmesh batch sweep.toml -o out --scheduler tcp://10.0.0.5:8786   # an existing Dask cluster
    unmesh batch sweep.toml -o out --resume               # skip done tasks, rerun the others
    unmesh batch sweep.toml --list                        # the task ids, without running
    unmesh batch --plot final.kinetic_energy --against viscosity out -o plot.png

The sweep file format is in docs/batch.md. Each task writes into OUTDIR/<task-id>/;
OUTDIR/batch.json records versions, parameters, status, errors, wall times and workers,
OUTDIR/batch.csv the parameters and the figures of every task's summary.json.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["register", "run"]


def register(sub: Any) -> None:
    """Add the ``batch`` sub-command.

    Example
    -------
    >>> import argparse
    >>> sub = argparse.ArgumentParser().add_subparsers()
    >>> register(sub)
    >>> sorted(sub.choices)
    ['batch']
    """
    p = sub.add_parser("batch", help="run a parameter sweep or a folder of inputs on Dask distributed",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", metavar="SWEEP.toml|OUTDIR", help="sweep file (or, with --plot, a batch output directory)")
    p.add_argument("-o", "--output", metavar="OUTDIR|PLOT.png", help="output directory (or plot image with --plot)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N", help="worker processes of a local cluster (default: cores)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="use an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--resume", action="store_true", help="continue OUTDIR's batch: skip done tasks, rerun the rest")
    p.add_argument("--list", action="store_true", help="print the tasks of the sweep and exit")
    p.add_argument("--plot", metavar="METRIC", help="plot a figure of batch.csv of OUTDIR (needs --against)")
    p.add_argument("--against", metavar="KEY", help="the swept parameter on the x axis of --plot")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from unmesh.errors import InputError

    if args.plot is not None or args.against is not None:
        if args.plot is None or args.against is None:
            raise InputError("--plot/--against: expected both, e.g. --plot final.kinetic_energy --against viscosity")
        if args.output is None:
            raise InputError("-o: expected the plot image, e.g. -o plot.png")
        from unmesh.batch.plot import plot_metric

        path = plot_metric(args.source, args.plot, args.against, args.output)
        print(f"wrote {path}")
        return 0
    from unmesh.batch.sweep import load_sweep

    sweep = load_sweep(args.source)
    if args.list:
        for t in sweep.tasks:
            extra = f"  {t.input}" if t.input is not None else ""
            print(f"{t.id}{extra}  {t.params}")
        print(f"{len(sweep.tasks)} tasks of command {sweep.command}")
        return 0
    if args.output is None:
        raise InputError("-o: expected the output directory, e.g. -o out")
    import signal
    import threading

    from unmesh.batch.engine import run_batch

    def terminated(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt  # SIGTERM (a batch job's end, `kill`) stops like Ctrl-C: tasks cancelled, batch.json kept

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, terminated) if main_thread else None
    try:
        manifest = run_batch(sweep, args.output, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                             progress=not args.no_progress)
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
    tasks = manifest["tasks"]
    done = sum(t["status"] == "done" for t in tasks)
    failed = [t for t in tasks if t["status"] == "failed"]
    print(f"{sweep.path.name}: {done} of {len(tasks)} tasks done, {len(failed)} failed -> {args.output} "
          "(batch.json, batch.csv)")
    for t in failed:
        print(f"unmesh: task {t['id']} failed: {t['error']}", file=sys.stderr)
    return 1 if failed else 0
