"""MLS benchmark: projections/s and rays/s on a 10^6-surfel sphere, and clouds whose radii vary.

Run: ``python benchmarks/bench_mls.py [--surfels N] [--queries Q] [--rays R] [--threads T]
[--models DIR] [--skip-sphere]``.

Prints, with wall-clock and CPU time (``time.process_time``, all threads; on a shared
machine CPU time is the steadier figure, and ``--threads 1`` gives single-core rates):

* a Fibonacci unit sphere of N surfels (default 10^6, equal radii): set-up time
  (level grids, ray grids), projection throughput for points within three sample
  spacings of the surface, and ray-casting throughput for a square grid of parallel
  rays looking at the sphere (about 55 % of them hit), with the accuracy of both
  against the exact sphere;
* ``unmesh.shapes.Blob().surfels(spacing=0.02)`` (6,467 surfels, radii 0.013–0.071):
  the support levels, ``intersect`` on the 512×512 camera rays, and warm
  ``render(..., method="raycast")`` times at 210×170 and 512×512;
* the Stanford bunny LDC-sampled with ``unmesh.surfels.sample_mesh`` at 1/150 of its
  extent (radii vary about 30-fold), when ``DIR/stanford-bunny.obj`` exists:
  ``intersect`` on 512×512 camera rays and projection throughput.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from unmesh import mls
from unmesh.surfels import SurfelCloud

DEFAULT_MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


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


class Timer:
    """Wall-clock and CPU time of a block."""

    def __enter__(self) -> Timer:
        self.w0, self.c0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall = time.perf_counter() - self.w0
        self.cpu = time.process_time() - self.c0

    def rate(self, n: int, unit: str) -> str:
        return (f"{self.wall:.2f} s wall ({n / self.wall:,.0f} {unit}/s), {self.cpu:.2f} s CPU "
                f"({n / self.cpu:,.0f} {unit}/CPU-s)")


def camera_rays(cloud: SurfelCloud, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    from unmesh.render import Camera

    o, d = Camera.framing(cloud.bounds(), width, height).rays()
    return o.reshape(-1, 3), d.reshape(-1, 3)


def describe_levels(surf: mls.MLSSurface) -> str:
    return ", ".join(f"{g.n_points} samples / cell {g.cell_size:.3g}" for g in surf.level_grids)


def neighbour_stats(surf: mls.MLSSurface, x: np.ndarray, sample: int = 4000) -> str:
    """Mean neighbours (samples whose kernel reaches x, ``‖x − x_i‖ < cutoff·σ_i``) and mean candidates
    scanned by the kernels (samples in the 27-cell stencils of every level grid) per query point,
    on at most ``sample`` of the points ``x``; plus what one grid sized for the largest support
    would scan."""
    from unmesh.spatial import radius_neighbors
    from unmesh.spatial._kernels import point_cell, stencil_ranges

    rng = np.random.default_rng(1)
    x = x[rng.choice(len(x), min(sample, len(x)), replace=False)]
    pos = surf.cloud.positions
    supp = surf.cutoff * surf.sigmas
    off, idx = radius_neighbors(pos, surf.support, queries=x)
    q = np.repeat(np.arange(len(x)), np.diff(off))
    reach = np.sum((pos[idx] - x[q]) ** 2, axis=1) < supp[idx] ** 2
    nbrs = np.bincount(q[reach], minlength=len(x))
    scanned = np.zeros(len(x))
    ranges = np.empty((9, 2), np.int64)
    for g in surf.level_grids:
        for i, c in enumerate(x):
            ns = stencil_ranges(*point_cell(c, g.origin, g.inv_cell, g.dims), 1, g.dims, g.cell_keys, g.cell_start,
                                ranges)
            scanned[i] += np.sum(ranges[:ns, 1] - ranges[:ns, 0])
    return (f"mean neighbours/query {nbrs.mean():.1f} (max {nbrs.max()}), mean scanned by the level grids "
            f"{scanned.mean():.1f}, within the largest support {np.diff(off).mean():.1f}")


def bench_sphere(args: argparse.Namespace) -> None:
    spacing = float(np.sqrt(8 * np.pi / (np.sqrt(3) * args.surfels)))
    cloud = sphere_cloud(spacing)
    print(f"\n== sphere: {len(cloud)} surfels, spacing {spacing:.3g}")
    with Timer() as t:
        surf = mls.MLSSurface(cloud)
    print(f"MLSSurface build (level grids): {t.wall:.2f} s wall, {t.cpu:.2f} s CPU; support {surf.support:.3g}; "
          f"levels: {describe_levels(surf)}")
    with Timer() as t:
        surf.ray_grid()
    print(f"ray grid build (first intersect call only): {t.wall:.2f} s wall, {t.cpu:.2f} s CPU")

    rng = np.random.default_rng(0)
    v = rng.normal(size=(args.queries, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    x = v * (1 + rng.uniform(-3, 3, (args.queries, 1)) * spacing)
    with Timer() as t:
        p, n = mls.project(surf, x)
    err = np.abs(np.linalg.norm(p, axis=1) - 1)
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, p / np.linalg.norm(p, axis=1, keepdims=True)), -1, 1)))
    print(f"project: {args.queries} points in {t.rate(args.queries, 'projections')}; max |dist| {err.max():.2e}, "
          f"max normal error {ang.max():.3f} deg")
    print(f"  {neighbour_stats(surf, p[np.isfinite(p[:, 0])])}")

    side = int(np.rint(np.sqrt(args.rays)))
    u = (np.arange(side) + 0.5) / side * 2.4 - 1.2
    uu, vv = np.meshgrid(u, u)
    o = np.stack([uu.ravel(), vv.ravel(), np.full(side * side, 3.0)], axis=1)
    d = np.tile([0.0, 0.0, -1.0], (side * side, 1))
    with Timer() as t:
        th, hit = mls.intersect(surf, o, d)
    te = ray_sphere(o, d)
    both = hit & np.isfinite(te)
    print(f"intersect: {side * side} rays in {t.rate(side * side, 'rays')}; hits {hit.mean():.1%} "
          f"(exact {np.isfinite(te).mean():.1%}); max |t error| {np.abs(th[both] - te[both]).max():.2e}")


def bench_blob() -> None:
    from unmesh.render import Camera, render
    from unmesh.shapes import Blob

    cloud = Blob().surfels(spacing=0.02)
    print(f"\n== Blob().surfels(spacing=0.02): {len(cloud)} surfels, radii {cloud.radii.min():.3g}..{cloud.radii.max():.3g}"
          f" (mean {cloud.radii.mean():.3g})")
    with Timer() as t:
        surf = mls.MLSSurface(cloud)
        surf.ray_grid()
    print(f"MLSSurface + ray grids: {t.wall:.3f} s; levels: {describe_levels(surf)}")
    o, d = camera_rays(cloud, 512, 512)
    with Timer() as t:
        th, hit = mls.intersect(surf, o, d)
    print(f"intersect 512x512 camera rays: {t.rate(len(o), 'rays')}; hits {hit.mean():.1%}")
    x = o[hit] + th[hit, None] * d[hit]
    print(f"  at the hits: {neighbour_stats(surf, x)}")
    with Timer() as t:
        mls.interpolate(surf, x, cloud.colors)
    print(f"interpolate colours at the {len(x)} hits: {t.rate(len(x), 'points')}")
    for w, h in ((210, 170), (512, 512)):
        cam = Camera.framing(cloud.bounds(), w, h)
        render(cloud, cam, method="raycast")  # warm-up (compilation, caches)
        with Timer() as t:
            render(cloud, cam, method="raycast")
        print(f"render(method='raycast') {w}x{h} warm: {t.wall:.2f} s wall, {t.cpu:.2f} s CPU")


def bench_bunny(models: Path) -> None:
    path = models / "stanford-bunny.obj"
    if not path.exists():
        print(f"\n== bunny: {path} not found, skipped")
        return
    from unmesh.io import load_mesh
    from unmesh.surfels import sample_mesh

    mesh = load_mesh(path)
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    cloud = sample_mesh(mesh, extent / 150)
    print(f"\n== bunny LDC-sampled at extent/150: {len(cloud)} surfels, radii {cloud.radii.min():.3g}.."
          f"{cloud.radii.max():.3g} (median {np.median(cloud.radii):.3g})")
    with Timer() as t:
        surf = mls.MLSSurface(cloud)
        surf.ray_grid()
    print(f"MLSSurface + ray grids: {t.wall:.3f} s; levels: {describe_levels(surf)}")
    o, d = camera_rays(cloud, 512, 512)
    with Timer() as t:
        th, hit = mls.intersect(surf, o, d)
    print(f"intersect 512x512 camera rays: {t.rate(len(o), 'rays')}; hits {hit.mean():.1%}")
    x = o[hit] + th[hit, None] * d[hit] + 0.5 * np.median(cloud.radii) * d[hit] / np.linalg.norm(d[hit], axis=1,
                                                                                                  keepdims=True)
    with Timer() as t:
        mls.project(surf, x)
    print(f"project {len(x)} points half a radius behind the hits: {t.rate(len(x), 'projections')}")
    print(f"  at the hits: {neighbour_stats(surf, o[hit] + th[hit, None] * d[hit])}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surfels", type=int, default=1_000_000)
    ap.add_argument("--queries", type=int, default=1_000_000)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: all)")
    ap.add_argument("--models", type=Path, default=DEFAULT_MODELS, help="directory with stanford-bunny.obj")
    ap.add_argument("--skip-sphere", action="store_true", help="only the varying-radius clouds")
    args = ap.parse_args()
    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)

    if args.threads:
        numba.set_num_threads(args.threads)
    print(f"numba threads {numba.get_num_threads()} ({numba.config.THREADING_LAYER} layer requested)")
    # warm-up (compilation / cache load) on a tiny cloud
    small = sphere_cloud(0.1)
    mls.project(small, [[0, 0, 1.05]])
    mls.intersect(small, [[0, 0, 3.0]], [[0, 0, -1.0]])
    mls.interpolate(small, [[0, 0, 1.0]], small.colors)
    if not args.skip_sphere:
        bench_sphere(args)
    bench_blob()
    bench_bunny(args.models)


if __name__ == "__main__":
    main()
