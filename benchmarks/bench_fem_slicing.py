"""Per-frame time of slicing an organic shape (thesis Fig. 9.10, Table 9.1).

Thesis (Pentium 4, 3 GHz): the bunny, 24,079 -> 46,132 nodes and 8,278 -> 44,118 elements,
6.08 s per frame, 3.56 s without recomputing basis functions. Goal here: under 1 s.

The shape is the built-in blob tetrahedralised with TetGen (``--resolution 24``: 11,132 nodes,
44,903 tetrahedra), or the Stanford bunny from the test models (``--bunny PATH``; the scan is
open, so it is closed first by marching cubes of its winding-number inside test, at
``--bunny-resolution 76``: 24,138 nodes and 81,384 tetrahedra, the thesis' 24,079 nodes). It rests on the ground (Y = 3000, ν = 0.3,
ρ = 1, Δt = 0.04, one step per frame at 25 fps) while a blade moves on a curved path through
its neck, one cut per frame. Prints the per-frame time split into cutting, re-integration of
the changed elements, and the dynamics solve, the CPU time (all threads, and the main thread's:
the LU preconditioner is refactorised in a background thread), and the node/element counts.

Usage: ``python benchmarks/bench_fem_slicing.py [--resolution 24] [--frames 30] [--bunny PATH]``
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np


def closed_bunny(path: Path, resolution: int) -> object:
    """The Stanford bunny closed by marching cubes of its inside test, scaled to height 1.4."""
    from skimage.measure import marching_cubes

    from unmesh import io
    from unmesh.meshes import TriangleMesh
    from unmesh.shapes import MeshShape

    scan = io.load_mesh(path)
    shape = MeshShape(scan)
    lo, hi = shape.bounds()
    pad = 0.03 * (hi - lo).max()
    axes = [np.linspace(lo[k] - pad, hi[k] + pad, int(resolution * (hi[k] - lo[k]) / (hi - lo).max()) + 3) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = shape.contains(grid).reshape(len(axes[0]), len(axes[1]), len(axes[2])).astype(float)
    verts, faces, _, _ = marching_cubes(inside, 0.5, spacing=tuple(a[1] - a[0] for a in axes))
    verts += [a[0] for a in axes]
    verts = (verts - verts.min(axis=0)) * (1.4 / np.ptp(verts[:, 1]))
    verts[:, [0, 2]] -= verts[:, [0, 2]].mean(axis=0)
    return TriangleMesh(verts, faces[:, ::-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=24, help="blob surface resolution (default 24: 11,132 nodes)")
    ap.add_argument("--frames", type=int, default=30, help="frames to simulate (default 30)")
    ap.add_argument("--bunny", type=Path, default=None, help="use this (Stanford bunny) OBJ instead of the blob")
    ap.add_argument("--bunny-resolution", type=int, default=76,
                    help="marching-cubes resolution of the closed bunny (default 76: 24,138 nodes, the thesis' 24,079)")
    ap.add_argument("--solver", default="auto", choices=("auto", "lu-pcg", "cg", "direct"),
                    help="linear solver of the implicit step (default auto: CG, LU-preconditioned when slow)")
    ap.add_argument("--young", type=float, default=3e3, help="Young's modulus (default 3000, Appendix F.3, Fig. 9.10)")
    args = ap.parse_args()
    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)
    from unmesh.fem import tetrahedralize
    from unmesh.fem.dynamics import Dynamics, Ground
    from unmesh.fem.events import BladeEvent
    from unmesh.fem.simulation import FemSimulation
    from unmesh.shapes import Blob

    t = time.perf_counter()
    if args.bunny is not None:
        surf = closed_bunny(args.bunny, args.bunny_resolution)
        mesh = tetrahedralize(surf)
    else:
        mesh = tetrahedralize(Blob(center=(0, 0.46, 0)).mesh(resolution=args.resolution))
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    mesh = mesh.replace_points(mesh.points - [0.0, lo[1], 0.0])
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    print(f"mesh: {mesh.n_nodes} nodes, {mesh.n_elements} tetrahedra ({time.perf_counter() - t:.1f} s to build)")
    span = hi - lo
    x0 = lo[0] + 0.62 * span[0]
    path = np.array([[[x0 - 0.06 * span[0], hi[1] + 0.1, lo[2] - 0.1], [x0 - 0.06 * span[0], hi[1] + 0.1, hi[2] + 0.1]],
                     [[x0, lo[1] + 0.5 * span[1], lo[2] - 0.1], [x0, lo[1] + 0.5 * span[1], hi[2] + 0.1]],
                     [[x0 + 0.12 * span[0], lo[1] - 0.05, lo[2] - 0.1], [x0 + 0.12 * span[0], lo[1] - 0.05, hi[2] + 0.1]]])
    dt = 0.04
    # the blade enters the material after a few frames and sweeps through it during the run
    blade = BladeEvent(0.0, dt * args.frames, path)
    t = time.perf_counter()
    dyn = Dynamics(mesh, args.young, 0.3, 1.0, ground=Ground(friction=0.6), solver=args.solver)
    sim = FemSimulation(dyn, dt, [blade])
    sim.step()  # JIT and first factorisation
    sim.frame_record()  # reset the per-frame timers, so the setup step is not counted in frame 1
    print(f"setup (integration, first step): {time.perf_counter() - t:.1f} s")
    rec = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(args.frames - 1):
            t, c, th = time.perf_counter(), time.process_time(), time.thread_time()
            sim.step()
            wall, cpu, main = time.perf_counter() - t, time.process_time() - c, time.thread_time() - th
            r = sim.frame_record()
            rec.append((wall, r["cut_seconds"], r["reintegration_seconds"], r["solve_seconds"], r["cg_iterations"],
                        r["nodes"], r["elements"], cpu, main))
            print(f"  frame {len(rec)}: {wall:.2f} s = cut {r['cut_seconds']:.2f} + re-integration "
                  f"{r['reintegration_seconds']:.2f} + solve {r['solve_seconds']:.2f} s, {r['cg_iterations']} "
                  f"iterations, {r['nodes']} nodes", flush=True)
    a = np.array(rec)
    cutting = a[:, 1] > 0
    print(f"frames with a cut: {int(cutting.sum())} of {len(a)}")
    print(f"per frame (mean over all frames): total {a[:, 0].mean():.2f} s = cut {a[:, 1].mean():.2f} + "
          f"re-integration {a[:, 2].mean():.2f} + solve {a[:, 3].mean():.2f} s; {a[:, 4].mean():.0f} CG iterations; "
          f"CPU {a[:, 7].mean():.2f} s per frame (all threads; main thread {a[:, 8].mean():.2f} s)")
    if cutting.any():
        print(f"per cutting frame: total {a[cutting, 0].mean():.2f} s (solve {a[cutting, 3].mean():.2f} s, includes "
              f"the refactorisation)")
    if (~cutting).any():
        print(f"per frame without a cut: {a[~cutting, 0].mean():.2f} s")
    print(f"nodes {mesh.n_nodes} -> {int(a[-1, 5])}, elements {mesh.n_elements} -> {int(a[-1, 6])}, "
          f"{dyn.n_solid_pieces} pieces at the end")
    lag = dyn.lagged
    print(f"solver {args.solver}: {lag.factorizations} LU factorisations in {args.frames} steps "
          f"({lag.background_factorizations} in the background, {lag.waited:.2f} s "
          f"waited for them), the factorisation kept across {lag.remaps} cuts; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    from unmesh._threads import _TUNERS

    chosen = [f"{key} ({2 ** (size - 1)}+ items): {'1 thread' if t.serial else 'all'} "
              f"(probed {t.best[True] * 1e3:.1f} vs {t.best[False] * 1e3:.1f} ms, {t.calls} calls)"
              for (key, size), t in sorted(_TUNERS.items()) if key.startswith("fem.")]
    print(f"numba threads: {numba.get_num_threads()}; tuner's last choices: " + ("; ".join(chosen) or "none"))
    print("thesis: 6.08 s per frame (3.56 s without recomputing basis functions), 24079 -> 46132 nodes")


if __name__ == "__main__":
    main()
