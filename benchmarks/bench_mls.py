"""MLS benchmark: projections/s and rays/s on a 10^6-surfel sphere.

Run: ``python benchmarks/bench_mls.py [--surfels N] [--queries Q] [--rays R]``.
Prints the set-up time (grid build), projection throughput for points within a
few sample spacings of the surface, and ray-casting throughput for a square
orthographic-like image looking at the sphere (about 78 % of the rays hit), plus
the accuracy of both against the exact sphere.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from unmesh import mls
from unmesh.surfels import SurfelCloud


def sphere_cloud(spacing: float) -> SurfelCloud:
    """Fibonacci unit sphere, nearest-neighbour spacing about ``spacing``, radii 0.65 spacings."""
    n = int(np.rint(8 * np.pi / (np.sqrt(3) * spacing**2)))
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    nrm = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return SurfelCloud(nrm, nrm, radii=np.full(n, 0.65 * spacing))


def ray_sphere(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """First t > 0 on the unit sphere (inf for misses)."""
    a = np.einsum("ij,ij->i", d, d)
    b = 2 * np.einsum("ij,ij->i", o, d)
    c = np.einsum("ij,ij->i", o, o) - 1.0
    disc = b * b - 4 * a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    t1, t2 = (-b - sq) / (2 * a), (-b + sq) / (2 * a)
    return np.where(disc >= 0, np.where(t1 > 0, t1, np.where(t2 > 0, t2, np.inf)), np.inf)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surfels", type=int, default=1_000_000)
    ap.add_argument("--queries", type=int, default=1_000_000)
    ap.add_argument("--rays", type=int, default=1_000_000)
    args = ap.parse_args()
    import numba

    spacing = float(np.sqrt(8 * np.pi / (np.sqrt(3) * args.surfels)))
    cloud = sphere_cloud(spacing)
    print(f"sphere: {len(cloud)} surfels, spacing {spacing:.3g}, numba threads {numba.get_num_threads()}")

    # warm-up (compilation / cache load) on a tiny cloud
    small = sphere_cloud(0.1)
    mls.project(small, [[0, 0, 1.05]])
    mls.intersect(small, [[0, 0, 3.0]], [[0, 0, -1.0]])

    t0 = time.perf_counter()
    surf = mls.MLSSurface(cloud)
    t_build = time.perf_counter() - t0
    print(f"MLSSurface build (grid): {t_build:.2f} s; support {surf.support:.3g}")

    rng = np.random.default_rng(0)
    v = rng.normal(size=(args.queries, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    x = v * (1 + rng.uniform(-3, 3, (args.queries, 1)) * spacing)
    t0 = time.perf_counter()
    p, n = mls.project(surf, x)
    dt = time.perf_counter() - t0
    err = np.abs(np.linalg.norm(p, axis=1) - 1)
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, p / np.linalg.norm(p, axis=1, keepdims=True)), -1, 1)))
    print(f"project: {args.queries} points in {dt:.2f} s = {args.queries / dt:,.0f} projections/s; "
          f"max |dist| {err.max():.2e}, max normal error {ang.max():.3f} deg")

    side = int(np.rint(np.sqrt(args.rays)))
    u = (np.arange(side) + 0.5) / side * 2.4 - 1.2
    uu, vv = np.meshgrid(u, u)
    o = np.stack([uu.ravel(), vv.ravel(), np.full(side * side, 3.0)], axis=1)
    d = np.tile([0.0, 0.0, -1.0], (side * side, 1))
    t0 = time.perf_counter()
    surf.ray_grid()
    print(f"ray grid build (first intersect call only): {time.perf_counter() - t0:.2f} s")
    t0 = time.perf_counter()
    t, hit = mls.intersect(surf, o, d)
    dt = time.perf_counter() - t0
    te = ray_sphere(o, d)
    both = hit & np.isfinite(te)
    print(f"intersect: {side * side} rays in {dt:.2f} s = {side * side / dt:,.0f} rays/s; hits {hit.mean():.1%} "
          f"(exact {np.isfinite(te).mean():.1%}); max |t error| {np.abs(t[both] - te[both]).max():.2e}")


if __name__ == "__main__":
    main()
