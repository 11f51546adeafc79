"""Benchmark: ``unmesh batch --scheduler`` on a simulated cluster, with a worker killed mid-batch.

Starts ``dask scheduler`` and ``--workers`` (default 3) separate ``dask worker`` processes (no
nanny, one thread each) on 127.0.0.1 only, then runs a sweep of ``--tasks`` small SPH tasks (the
2D elastic cube, ``--duration`` simulated seconds each) through ``run_batch(scheduler=...)``, the
same code path as ``unmesh batch SWEEP -o OUT --scheduler tcp://127.0.0.1:PORT``. As soon as a
worker is processing a task (after ``--kill-after`` tasks are done), that worker process is
killed with SIGKILL. Prints how the tasks spread over the workers, which task was running on
the killed worker and where it was rerun, and checks that every task is done and that each
task's frames equal those of the same task in an undisturbed serial run (nothing lost).

Usage::

    python benchmarks/bench_batch_cluster.py [--workers 3] [--tasks 9] [--duration 0.1]
"""

from __future__ import annotations

import argparse
import collections
import filecmp
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def _wait_for(path: Path, timeout: float = 60.0) -> None:
    end = time.time() + timeout
    while not path.exists():
        if time.time() > end:
            raise TimeoutError(f"{path} did not appear")
        time.sleep(0.2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=3)
    ap.add_argument("--tasks", type=int, default=9)
    ap.add_argument("--duration", type=float, default=0.1)
    ap.add_argument("--spacing", type=float, default=0.03)
    ap.add_argument("--kill-after", type=int, default=2, help="done tasks before a busy worker is killed")
    args = ap.parse_args()

    import distributed

    from unmesh.batch import load_manifest, run_batch
    from unmesh.scenes import __file__ as scenes_init
    from unmesh.sim.cli import run_scene
    from unmesh.sph.scene import build_simulation

    root = Path(tempfile.mkdtemp(prefix="bench_cluster_"))
    dask = shutil.which("dask", path=os.path.dirname(sys.executable)) or "dask"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    procs: list[subprocess.Popen] = []
    print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores (timings on a loaded machine "
          "are not trustworthy)")
    try:
        sched_file = root / "scheduler.json"
        procs.append(subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                       "--scheduler-file", os.fspath(sched_file)], env=env,
                                      stdout=subprocess.DEVNULL, stderr=open(root / "scheduler.log", "w")))
        _wait_for(sched_file)
        address = json.loads(sched_file.read_text())["address"]
        workers = {}
        for k in range(args.workers):
            p = subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--no-nanny", "--name", f"w{k}",
                                  "--host", "127.0.0.1", "--no-dashboard"], env=env, stdout=subprocess.DEVNULL,
                                 stderr=open(root / f"worker{k}.log", "w"))
            procs.append(p)
            workers[f"w{k}"] = p
        client = distributed.Client(address)
        client.wait_for_workers(args.workers, timeout=120)
        by_addr = {w["name"]: addr for addr, w in client.scheduler_info(n_workers=-1)["workers"].items()}
        addr_to_name = {a: n for n, a in by_addr.items()}
        print(f"scheduler {address}; workers {', '.join(f'{n}={a}' for n, a in sorted(by_addr.items()))}")

        scene = Path(scenes_init).parent / "sph" / "elastic_cube_2d.toml"
        xsph = ", ".join(f"{0.05 + 0.05 * k:.2f}" for k in range(args.tasks))
        sweep = root / "sweep.toml"
        sweep.write_text(f'command = "sph"\nscene = "{scene}"\nduration = {args.duration}\n[sweep]\n'
                         f'"simulation.spacing" = [{args.spacing}]\n"materials.rubber.xsph" = [{xsph}]\n')
        out = root / "out"
        killed: dict[str, str] = {}

        def killer() -> None:
            while not killed:
                time.sleep(0.2)
                m = load_manifest(out) if (out / "batch.json").exists() else None
                if m is None:
                    continue
                done = sum(t["status"] == "done" for t in m["tasks"])
                if done < args.kill_after:
                    continue
                for addr, keys in client.processing().items():
                    if keys:
                        name = addr_to_name[addr]
                        running = next(t["id"] for t in m["tasks"] if t["status"] == "running" and t["worker"] == addr) \
                            if any(t["status"] == "running" and t["worker"] == addr for t in m["tasks"]) else None
                        workers[name].send_signal(signal.SIGKILL)
                        killed.update(name=name, addr=addr, task=running or "?", at=f"{done} tasks done")
                        return

        thread = threading.Thread(target=killer, daemon=True)
        thread.start()
        t0 = time.perf_counter()
        manifest = run_batch(sweep, out, scheduler=address, progress=False, log=sys.stdout, poll_seconds=0.2)
        wall = time.perf_counter() - t0
        thread.join(timeout=1)
        tasks = manifest["tasks"]
        spread = collections.Counter(addr_to_name.get(t["worker"], t["worker"]) for t in tasks)
        print(f"batch of {len(tasks)} tasks in {wall:.1f} s; tasks per worker: {dict(sorted(spread.items()))}")
        if killed:
            rerun = next((t for t in tasks if t["id"] == killed["task"]), None)
            where = addr_to_name.get(rerun["worker"], rerun["worker"]) if rerun else "?"
            print(f"killed worker {killed['name']} (SIGKILL) after {killed['at']} while it ran task "
                  f"{killed['task']}; that task finished on {where}")
        else:
            print("no worker was killed (the batch ended first; use more or longer tasks)")
        statuses = collections.Counter(t["status"] for t in tasks)
        print(f"statuses: {dict(statuses)}")
        lost = 0
        for t in tasks:
            alone = root / "alone" / t["id"]
            run_scene(scene, alone, build_simulation, overrides=t["parameters"], duration=args.duration,
                      progress=False)
            names = sorted(p.name for p in (alone / "frames").iterdir())
            got = Path(t["output"]) / "frames"
            same = all(filecmp.cmp(alone / "frames" / n, got / n, shallow=False) for n in names) and \
                names == sorted(p.name for p in got.iterdir())
            lost += not same
        print(f"tasks whose frames differ from an undisturbed serial run: {lost} of {len(tasks)}")
        client.close()
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        print(f"logs and outputs in {root}")


if __name__ == "__main__":
    main()
