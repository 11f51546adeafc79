"""Per-frame times of point-sampled thin shells at the sizes of Table 7.1 (thesis chapter 7).

Table 7.1 (Pentium 4, 3 GHz) reports the average time per *rendered frame*: the force
computation and integration of all the simulation steps in that frame, fracture testing and
neighbourhood recomputation, and the animation of the dense surface (done once per frame):

    Figure  nodes   points   forces  fracture  surface  total [ms]
    7.5       931     9835        7        -       64     71
    7.10     1170    24578       24       23      166    212
    7.4      1987    40880      222        -      325    547
    7.8     11860   240000     1533     6066     1459   9058

The thesis states Delta t per example (Appendix F.1: 0.01 for Figs. 7.4/7.5, 0.001 for
7.8/7.10) but no frame rate. We assume 25 frames per second (European video; 30 fps would
mean fewer steps per frame, so 25 is the conservative choice): 4 steps per frame at
Delta t = 0.01 and 40 at 0.001. The shipped scenes are run at the node and surfel counts of
the table (the Fig. 7.5 row uses the Max Planck bust when the test models are present, else
the procedural blob); times are wall-clock averages over the measured frames, without file
output (reported separately). By default every row runs its scene's whole animation (the
table gives averages over the animation; the torn poster's crack events, which dominate its
cost, happen in the middle of it). The goal is at least 20x faster than the thesis for the
rows of Figs. 7.5, 7.4 and 7.8; the balloon (7.10) is reported too.

Run:  python benchmarks/bench_shells.py [--frames N] [--rows 7.5,7.4,7.8,7.10] [--threads N]
      (--frames N: only the first N frames of each scene; 0, the default, the whole scene)

On a machine shared with other busy processes the wall-clock times say little; the 'cpu'
column (process CPU time per frame) with ``--threads 1`` is the robust figure.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

THESIS = {  # figure: (nodes, points, forces, fracture, surface, total) in ms
    "7.5": (931, 9835, 7, 0, 64, 71),
    "7.10": (1170, 24578, 24, 23, 166, 212),
    "7.4": (1987, 40880, 222, 0, 325, 547),
    "7.8": (11860, 240000, 1533, 6066, 1459, 9058),
}
FPS = 25.0
MODEL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "models" / "max-planck-decimated.obj"


def overrides(figure: str) -> tuple[str, dict]:
    """Scene and overrides that give the node/surfel counts of a Table 7.1 row."""
    if figure == "7.5":
        if MODEL.exists():
            return "plastic_drop", {"surface.nodes": 931, "surface.spacing": 0.527,
                                    "surface.shape": {"file": str(MODEL), "scale": 0.1, "center": [0, 20, 0]}}
        return "plastic_drop", {"surface.nodes": 931}
    if figure == "7.10":
        return "balloon", {"surface.nodes": 1170}
    if figure == "7.4":
        return "elastic_drop", {"surface.nodes": 1987}
    return "tearing_poster", {"surface.nodes": 11860, "surface.spacing": 0.0825}


def measure(figure: str, frames: int) -> dict:
    from unmesh.scene import load_scene
    from unmesh.scenes import path
    from unmesh.shells.scene import build_simulation

    name, over = overrides(figure)
    t0 = time.perf_counter()
    sim, settings = build_simulation(load_scene(path(f"shells/{name}.toml"), over))
    setup = time.perf_counter() - t0
    steps = round(1.0 / FPS / sim.dt)
    if frames <= 0:  # the whole animation of the scene, as the thesis averaged
        frames = round(settings.duration * FPS)
    for _ in range(max(steps, 12)):  # load the compiled kernels (numba cache), choose threads, before timing
        sim.step()
    sim.deformed_surface()
    sim.frame_record()
    rows = []
    io_time = 0.0
    import tempfile

    tmp = Path(tempfile.mkdtemp())
    cpu = 0.0
    for k in range(frames):
        c = time.process_time()
        t = time.perf_counter()
        for _ in range(steps):
            sim.step()
            reason = sim.check()
            if reason:
                raise RuntimeError(f"{name}: {reason}")
        sim.deformed_surface()
        total = time.perf_counter() - t
        cpu += time.process_time() - c
        rec = sim.frame_record()
        rows.append((rec["force_seconds"], rec["fracture_seconds"], rec["surface_seconds"], total))
        if k == frames - 1:
            t = time.perf_counter()
            sim.write_frame(tmp, k)
            io_time = time.perf_counter() - t
    from unmesh._threads import _TUNERS

    tuner = _TUNERS.get(("step", len(sim.topology.fibers).bit_length()))
    threads = "-" if tuner is None else ("1" if tuner.serial else "all")
    r = np.array(rows) * 1000.0
    return {"threads": threads, "figure": figure, "scene": name, "nodes": len(sim.rest), "points": len(sim.cloud),
            "fibers": len(sim.topology.fibers), "frames": frames, "steps_per_frame": steps, "dt": sim.dt, "setup_s": setup,
            "forces": r[:, 0].mean(), "fracture": r[:, 1].mean(), "surface": r[:, 2].mean(), "total": r[:, 3].mean(),
            "io": io_time * 1000.0, "cracks": len(sim.cracks), "cpu": 1000.0 * cpu / frames}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=0,
                    help="frames measured per row (default 0: the scene's whole duration, as Table 7.1 averages)")
    ap.add_argument("--rows", default="7.5,7.10,7.4,7.8", help="Table 7.1 rows (figure numbers)")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's)")
    args = ap.parse_args()
    import os

    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)

    if args.threads:
        numba.set_num_threads(args.threads)
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"Thin shells, per rendered frame at {FPS:g} fps (steps per frame = (1/fps)/dt, dt from F.1);")
    print(f"numba threads: {numba.get_num_threads()} of {os.cpu_count()} CPUs, load average {load}.")
    print("forces = forces + integration, fracture = testing + rebuild, surface = dense-surface skinning.\n")
    head = (f"{'fig':>5} {'nodes':>6} {'points':>7} {'fibers':>7} {'frames':>6} {'steps':>5} | {'forces':>8} {'fract.':>8} "
            f"{'surface':>8} {'total':>8} | {'thesis':>7} {'speed-up':>8} | {'cpu':>7} | {'write':>6} {'setup':>6} "
            f"{'thr':>4}")
    print(head)
    print("-" * len(head))
    for fig in [s.strip() for s in args.rows.split(",") if s.strip()]:
        m = measure(fig, args.frames)
        th = THESIS[fig][5]
        print(f"{fig:>5} {m['nodes']:6d} {m['points']:7d} {m['fibers']:7d} {m['frames']:6d} {m['steps_per_frame']:5d} | "
              f"{m['forces']:7.1f}  {m['fracture']:7.1f}  {m['surface']:7.1f}  {m['total']:7.1f}  | "
              f"{th:6d}  {th / m['total']:7.1f}x | {m['cpu']:7.1f} | {m['io']:5.0f}  {m['setup_s']:5.1f}s"
              + f"  {m['threads']:>3}" + (f"   ({m['cracks']} cracks)" if m["cracks"] else ""))
    print("\nAll times in ms (setup in s): wall-clock averages per frame. 'cpu' is the process CPU time per")
    print("frame (all threads; less sensitive to other load). 'write' is the time to write one frame's files")
    print("(not in 'total'). 'thr': threads the time step chose by timing (1, or all of numba's threads;")
    print("'-' = below unmesh._threads.PARALLEL_MIN or one thread only); the results do not depend on it.")
    print(f"Load average at the end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}.")


if __name__ == "__main__":
    main()
