"""Sampling speed: LDC sampling of igea and the bunny, normal estimation for 10^6 points.

Run: ``python benchmarks/bench_sampling.py`` (needs ../shared/data/models for the
mesh figures). Numba kernels are compiled by a warm-up call first; every figure is
the minimum and median of ``REPEAT`` runs.

Figures printed:
- LDC sampling (``sample_mesh``: ray casting + normals + covering radii) of igea
  (268k triangles) and the bunny (69k triangles) at spacing = bounding-box diagonal
  / 200 (the CLI default) and / 600: time, sample count, and the split between the
  ray casting (``ldc_samples``) and the radius estimation.
- ``estimate_normals`` (PCA + MST orientation, k = 16) and ``estimate_radii``
  (k = 8) for 10^6 points (LDC samples of igea).
- ``cluster`` of the same 10^6 points into 10^4 clusters (Pauly et al. 2002).
- Blob surfels (Poisson-disk sampling on the exact surface) at spacing 0.01.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from unmesh.surfels import cluster, estimate_normals, estimate_radii, sample_mesh
from unmesh.surfels.sampling import ldc_samples

MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"
REPEAT = 3


def timed(fn, repeat=REPEAT):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times), out


def warm_up() -> None:
    from unmesh.shapes import Blob, Sphere

    mesh = Sphere().mesh(resolution=8)
    cloud = sample_mesh(mesh, 0.3)
    estimate_normals(cloud.positions)
    cluster(cloud.positions, target=10)
    Blob().surfels(0.1)


def main() -> int:
    from unmesh import io
    from unmesh.shapes import Blob

    warm_up()
    print(f"(min / median of {REPEAT} runs, seconds)")
    if MODELS.is_dir():
        print("LDC sampling: sample_mesh (rays + normals + radii)   [ray casting only]")
        for name in ("igea.ply", "stanford-bunny.obj"):
            mesh = io.load_mesh(MODELS / name)
            lo, hi = mesh.bounds()
            diag = float(np.linalg.norm(hi - lo))
            for div in (200, 600):
                d = diag / div
                t_min, t_med, cloud = timed(lambda mesh=mesh, d=d: sample_mesh(mesh, d))
                r_min, _, _ = timed(lambda mesh=mesh, d=d: ldc_samples(mesh.vertices, mesh.faces, d))
                print(f"  {name:20s} {len(mesh.faces):7d} tri  d = diag/{div:<4d} {len(cloud):9d} samples  "
                      f"{t_min:7.3f} {t_med:7.3f}   [{r_min:6.3f}]   "
                      f"({len(cloud) / t_min / 1e6:.2f} M samples/s)")
        mesh = io.load_mesh(MODELS / "igea.ply")
        lo, hi = mesh.bounds()
        pts = ldc_samples(mesh.vertices, mesh.faces, float(np.linalg.norm(hi - lo)) / 850)[0][:1_000_000]
        source = "igea LDC samples"
    else:
        print(f"models not found at {MODELS}; LDC figures skipped, using sphere points")
        from unmesh.shapes import Sphere

        pts = Sphere().surfels(0.0035).positions[:1_000_000]
        source = "sphere lattice"
    print(f"10^6 points ({len(pts)} {source})")
    t_min, t_med, normals = timed(lambda: estimate_normals(pts, k=16))
    print(f"  estimate_normals k=16                 {t_min:7.3f} {t_med:7.3f}")
    t_min, t_med, _ = timed(lambda: estimate_radii(pts, normals, k=8))
    print(f"  estimate_radii k=8                    {t_min:7.3f} {t_med:7.3f}")
    t_min, t_med, _ = timed(lambda: cluster(pts, target=10_000))
    print(f"  cluster target=10^4                   {t_min:7.3f} {t_med:7.3f}")
    t_min, t_med, cloud = timed(lambda: Blob().surfels(0.01), repeat=2)
    print(f"blob surfels spacing 0.01 ({len(cloud)} surfels)  {t_min:7.3f} {t_med:7.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
