"""Benchmark: ``unmesh batch`` on 1 and 2 local workers, 8 SPH tasks of at least 5 s each.

The tasks are the 2D elastic cube (``examples/sph/elastic_cube_2d.toml``) at ``--spacing`` with 8
values of the XSPH factor; the simulated duration is calibrated first (one task run alone, in
this process) so that a task takes about ``--task-seconds`` (default 6 s). Then the batch runs on
a local cluster of 1 worker and of 2 workers (one Dask thread and one numba thread per worker,
the cluster started before the clock starts) and prints:

* the wall time of each batch and the speed-up of 2 workers over 1 (goal: at least 1.8x);
* the scheduling overhead: batch wall time minus the tasks' own wall time per worker
  (sum of task times / workers), as a share of the task time (goal: under 5 %);
* the cluster's start-up time (not part of either figure).

Timings on a shared or loaded machine are not trustworthy; the script prints the load average.

Usage::

    python benchmarks/bench_batch.py [--tasks 8] [--task-seconds 6] [--spacing 0.02]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", type=int, default=8)
    ap.add_argument("--task-seconds", type=float, default=6.0)
    ap.add_argument("--spacing", type=float, default=0.02)
    ap.add_argument("--keep", metavar="DIR", help="write the batches here instead of a temporary folder")
    args = ap.parse_args()

    from unmesh.batch import run_batch
    from unmesh.distributed import connect
    from unmesh.scenes import __file__ as scenes_init
    from unmesh.sim.cli import run_scene
    from unmesh.sph.scene import build_simulation

    scene = Path(scenes_init).parent / "sph" / "elastic_cube_2d.toml"
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_batch_"))
    root.mkdir(parents=True, exist_ok=True)
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores (timings on a loaded "
          "machine are not trustworthy)")

    over = {"simulation.spacing": args.spacing, "materials.rubber.xsph": 0.1}
    run_scene(scene, root / "warm", build_simulation, overrides=over, duration=0.02, progress=False)  # compile
    probe = 0.1
    t0 = time.perf_counter()
    run_scene(scene, root / "calib", build_simulation, overrides=over, duration=probe, progress=False)
    per_second = (time.perf_counter() - t0) / probe
    duration = round(args.task_seconds / per_second, 3)
    print(f"calibration: {per_second:.1f} s of wall time per simulated second -> duration {duration} s per task")

    xsph = ", ".join(f"{0.05 + 0.05 * k:.2f}" for k in range(args.tasks))
    sweep = root / "sweep.toml"
    sweep.write_text(f'command = "sph"\nscene = "{scene}"\nduration = {duration}\n[sweep]\n'
                     f'"simulation.spacing" = [{args.spacing}]\n"materials.rubber.xsph" = [{xsph}]\n')
    results = {}
    for n in (1, 2):
        t0 = time.perf_counter()
        with connect(workers=n, numba_threads=1, dashboard=None, progress_output=None) as client:
            startup = time.perf_counter() - t0
            client.run(lambda: __import__("unmesh.sph.scene"))   # imports outside the clock, as in a warm cluster
            t0 = time.perf_counter()
            manifest = run_batch(sweep, root / f"out{n}", client=client, progress=False, log=None)
            wall = time.perf_counter() - t0
        tasks = manifest["tasks"]
        assert all(t["status"] == "done" for t in tasks), [t["error"] for t in tasks]
        busy = sum(t["wall_seconds"] for t in tasks)
        overhead = wall - busy / n
        results[n] = wall
        workers = sorted({t["worker"] for t in tasks})
        print(f"{n} worker{'s' if n > 1 else ' '}: batch {wall:6.1f} s, tasks {busy:6.1f} s "
              f"(min {min(t['wall_seconds'] for t in tasks):.1f} s each), overhead {overhead:+.2f} s = "
              f"{100 * overhead / (busy / n):+.1f} % of the task time; cluster start-up {startup:.1f} s; "
              f"{len(workers)} workers used")
    print(f"speed-up 2 workers / 1 worker: {results[1] / results[2]:.2f}x (goal >= 1.8x)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
