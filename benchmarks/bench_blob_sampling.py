"""Blob surfels: cost of the curvature-adaptive Poisson-disk sampling (stop 36, ear tips).

Run: ``NUMBA_NUM_THREADS=1 python benchmarks/bench_blob_sampling.py``. For each spacing the
uniform (``adaptive=False``) and adaptive samplings of the same candidate mesh are timed
alternately (process CPU time, ``REPEAT`` pairs after a warm-up; min / median), with the
sample counts and the largest splat radius within 3 spacings of an ear apex over the median
radius (the radii of ``Blob.surfels``: ``estimate_radii(smooth=True)``).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

REPEAT = 5


def main() -> int:
    from unmesh.shapes import Blob
    from unmesh.shapes._meshing import marching_mesh, project_to_zero
    from unmesh.shapes._sampling import poisson_surface
    from unmesh.shapes.blob import CANDIDATE_CELLS, _part_bounds, _parts
    from unmesh.surfels.radii import estimate_radii

    blob = Blob()
    imp = blob._implicit_local
    centers, semi, rots, _ = _parts()
    tips = project_to_zero(imp, np.array([centers[k] + rots[k] @ np.array([0.0, semi[k, 1], 0.0]) for k in (4, 5)]),
                           0.01, 20)
    lo, hi = _part_bounds()
    poisson_surface(*marching_mesh(imp, lo, hi, 0.07, lipschitz=True), 0.1, imp)  # warm-up (numba)
    print(f"(process CPU time, min / median of {REPEAT} alternating runs, seconds)")
    print(" spacing | uniform: samples  time          tip/median | adaptive: samples  time          tip/median")
    for h in (0.01, 0.015, 0.02, 0.03):
        verts, faces = marching_mesh(imp, lo, hi, max(0.7 * h, blob.size() / CANDIDATE_CELLS), lipschitz=True)
        times: dict[bool, list[float]] = {False: [], True: []}
        out: dict[bool, np.ndarray] = {}
        for _ in range(REPEAT):
            for adaptive in (False, True):
                t0 = time.process_time()
                out[adaptive] = poisson_surface(verts, faces, h, imp, adaptive=adaptive)
                times[adaptive].append(time.process_time() - t0)
        cols = []
        for adaptive in (False, True):
            pos = out[adaptive]
            r = estimate_radii(pos, imp(pos)[1], smooth=True)
            near = np.linalg.norm(pos[:, None] - tips[None], axis=2).min(axis=1) < 3 * h
            cols.append(f"{len(pos):8d}  {min(times[adaptive]):6.3f} {statistics.median(times[adaptive]):6.3f}"
                        f"   {r[near].max() / np.median(r):5.2f}")
        print(f" {h:7.3f} | {cols[0]}     | {cols[1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
