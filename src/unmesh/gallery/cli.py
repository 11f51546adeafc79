"""``unmesh gallery``: run every registered example on built-in data and build index.html."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["register", "run"]


def register(sub: Any) -> None:
    p = sub.add_parser("gallery", help="run all examples on built-in data and write an HTML gallery", description=__doc__)
    p.add_argument("-o", "--output", default="unmesh-gallery", help="output directory (default: unmesh-gallery)")
    p.add_argument("--only", metavar="NAME", help="comma-separated example names or glob patterns")
    p.add_argument("--quick", action="store_true", help="small, fast versions of every example")
    p.add_argument("--list", action="store_true", help="list the examples and exit")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.add_argument("-j", "--jobs", type=int, default=None, metavar="N",
                   help="run the examples in N worker processes, each with CPUs/N numba threads "
                        "(default: the number of CPUs, at most 4; 1 runs them in this process)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys

    from unmesh.errors import InputError, SimulationError
    from unmesh.gallery import select
    from unmesh.gallery.page import run_examples
    from unmesh.gallery.pool import default_jobs

    examples = select(args.only)
    if args.list:
        for e in examples:
            print(f"{e.name:32s} {e.section}: {e.title}")
        return 0
    jobs = default_jobs() if args.jobs is None else args.jobs
    if jobs < 1:
        raise InputError(f"--jobs: expected a number of worker processes >= 1, got {args.jobs}")
    out = Path(args.output)
    results = run_examples(examples, out, quick=args.quick, progress=not args.no_progress, jobs=jobs)
    failed = [r.example.name for r in results if r.error]
    print(f"gallery: {len(results) - len(failed)} of {len(results)} examples ok; open {out / 'index.html'}")
    for r in results:
        if r.error:
            print(f"--- {r.example.name} failed:\n{r.error}", file=sys.stderr)
    if failed:
        raise SimulationError(f"{len(failed)} of {len(results)} gallery examples failed: {', '.join(failed)}")
    return 0
