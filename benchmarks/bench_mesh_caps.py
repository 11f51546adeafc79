"""LDC sampling with and without the refinement of caps sharper than the ray spacing (stop 37).

Run: ``NUMBA_NUM_THREADS=1 python benchmarks/bench_mesh_caps.py``. For each mesh ``sample_mesh``
with ``refine=False`` (the plain lattice samples) and ``refine=True`` (the default) run alternately
after a warm-up; process CPU time, min / median of ``REPEAT`` pairs (``--models DIR``: where the
models are, default ``../shared/data/models``). Printed with the sample
counts and the largest radius within 3 spacings of the tips over the median radius (the blob's
ear apices, the ellipsoid's ends, the bunny's two highest ear points; the whole cloud for the
box, where no refinement happens). The models (bunny, igea) are used when
``../shared/data/models`` exists.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"
REPEAT = 5


def _tip_ratio(cloud, tips, d):
    if tips is None:
        return cloud.radii.max() / np.median(cloud.radii)
    near = np.linalg.norm(cloud.positions[:, None, :] - tips[None], axis=2).min(axis=1) < 3 * d
    return cloud.radii[near].max() / np.median(cloud.radii)


def cases(models: Path):
    from unmesh.shapes import Blob, Box, Sphere, euler_rotation

    mesh = Blob().mesh(0.01)
    v = mesh.vertices
    ears = np.array([v[np.argmax(np.where(side, v[:, 1], -np.inf))] for side in (v[:, 2] < 0, v[:, 2] > 0)])
    yield "blob mesh 0.01, d 0.016 (paint-art)", mesh, 0.016, ears
    yield "blob mesh 0.01, d 0.03", mesh, 0.03, ears
    rot = euler_rotation([20, 30, 40])
    m = np.eye(4)
    m[:3, :3] = rot @ np.diag([0.5, 0.08, 0.08])
    tips = np.array([rot @ [0.5, 0, 0], rot @ [-0.5, 0, 0]])
    yield "thin ellipsoid, d 0.03", Sphere().mesh(resolution=16).transformed(m), 0.03, tips
    yield "box (creases only), d 0.025", Box(size=(1.0, 0.6, 0.4), rotation=euler_rotation([10, 20, 30])).mesh(
        resolution=48), 0.025, None
    if models.is_dir():
        from unmesh.io import load_mesh

        for name, divs in (("stanford-bunny.obj", (100, 200)), ("igea.ply", (200,)), ("fandisk.obj", (200,))):
            mesh = load_mesh(models / name)
            lo, hi = mesh.bounds()
            diag = float(np.linalg.norm(hi - lo))
            tips = None
            if name.startswith("stanford"):  # the two ears' highest points (one per side of x = -0.04)
                v = mesh.vertices
                tips = np.array([v[np.argmax(np.where(side, v[:, 1], -np.inf))]
                                 for side in (v[:, 0] < -0.04, v[:, 0] >= -0.04)])
            for div in divs:
                yield f"{name} d = diag/{div}", mesh, diag / div, tips


def main() -> int:
    from unmesh.shapes import Sphere
    from unmesh.surfels import sample_mesh

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=MODELS)
    args = ap.parse_args()
    sample_mesh(Sphere().mesh(resolution=8), 0.3)  # warm-up (numba)
    print(f"(process CPU time, min / median of {REPEAT} alternating runs, seconds)")
    print(f"{'mesh':42s} | plain: samples  time           tips/median | refined: samples  time           tips/median")
    for name, mesh, d, tips in cases(args.models):
        sample_mesh(mesh, d)
        times: dict[bool, list[float]] = {False: [], True: []}
        out = {}
        for _ in range(REPEAT):
            for refine in (False, True):
                t0 = time.process_time()
                out[refine] = sample_mesh(mesh, d, refine=refine)
                times[refine].append(time.process_time() - t0)
        row = f"{name:42s}"
        for refine in (False, True):
            t = times[refine]
            row += (f" | {len(out[refine]):8d}  {min(t):6.3f} {statistics.median(t):6.3f}  "
                    f"{_tip_ratio(out[refine], tips, d):5.2f}")
        print(row, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
