"""Benchmark of EWA surface splatting: a 10^6-surfel sphere at 1024x1024.

Prints, for warm (compiled) kernels and the median of several frames:

* the full splatting frame time (``SplatRenderer.render`` + normalisation: setup, binning,
  visibility + accumulation passes, resolve) and the surfel rate;
* the same frame with the EWA tile kernel replaced by a fill-only kernel that visits exactly the
  same pixels of the same (surfel, tile) pairs with a trivial depth-test-like write
  (``fill_tiles``), i.e. the memory/loop cost the EWA arithmetic sits on top of;
* the two tile kernels alone, and the per-stage split;
* deferred shading and the end-to-end ``render()`` call (shading included).

Usage::

    python benchmarks/bench_render.py [--surfels 1000000] [--size 1024] [--repeat 7] [--threads N]

Goal (issue): <= 0.3 s per splatting frame on 2 cores, within 3x of the fill-only frame.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def fibonacci_sphere(n: int):
    from unmesh import SurfelCloud

    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5**0.5) * i
    p = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    h = np.sqrt(4 * np.pi / n)
    col = 0.5 + 0.5 * np.stack([np.sin(5 * p[:, 0]), np.sin(5 * p[:, 1]), np.cos(5 * p[:, 2])], 1)
    return SurfelCloud(p, p, radii=np.full(n, 0.9 * h), colors=col)


def median_time(fn, repeat: int, clock=time.perf_counter) -> float:
    times = []
    for _ in range(repeat):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--surfels", type=int, default=1_000_000)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: all)")
    args = ap.parse_args()

    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)
    from unmesh.render import Camera, SplatRenderer, render, shade
    from unmesh.render._kernels import bin_boxes, tile_order
    from unmesh.render._splat_kernels import NPARAM, fill_tiles, gather_rows, splat_setup, splat_tiles

    if args.threads:
        numba.set_num_threads(args.threads)
    n, size = args.surfels, args.size
    cloud = fibonacci_sphere(n)
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=size, height=size, fov=45.0)
    renderer = SplatRenderer(cam)

    def splat_frame():
        renderer.render(cloud)
        return renderer.gbuffer()

    t0 = time.perf_counter()
    g = splat_frame()  # compile (or load from cache) and warm up
    warm = time.perf_counter() - t0
    splat_frame()

    # stage by stage, with the renderer's own reusable buffers
    opt = renderer.options
    f, cx, cy, ortho, near = cam.kernel_params()
    frame = cam.rotation
    tile = opt.tile
    ntx = nty = (size + tile - 1) // tile
    order = tile_order(ntx * nty)
    P = np.empty((n, NPARAM), dtype=renderer.param_dtype)
    box = np.empty((n, 4), dtype=np.int32)
    group = np.empty(n, dtype=np.int8)
    dummy_axes = np.zeros((1, 2, 3))

    def setup():
        splat_setup(cloud.positions, cloud.normals, cloud.radii, dummy_axes, False, cloud.colors, frame, cam.eye, f,
                    cx, cy, ortho, near, size, size, opt.filter_radius, P, box, group)

    setup()
    offsets, items = bin_boxes(box, group, 2, tile, ntx, nty, 8)
    pt = np.empty((len(items), NPARAM), dtype=renderer.param_dtype)
    gather_rows(P, items, pt)
    coff, cpl, cmode = np.zeros(1, dtype=np.int64), np.zeros((0, 4)), np.zeros(1, dtype=np.int8)

    def tiles():
        renderer.clear()
        splat_tiles(pt, items, offsets, order, tile, size, size, f, cx, cy, ortho, near, opt.filter_radius,
                    opt.kappa, opt.depth_tolerance, False, cam.eye, frame, coff, cpl, cmode, True, 1.0,
                    renderer.zvis, renderer.sum_weight, renderer.sum_color, renderer.sum_normal, renderer.sum_depth,
                    renderer.count)

    fill_out = np.zeros((size, size))

    def fill():
        fill_tiles(pt, offsets, order, tile, size, size, fill_out)

    fill()
    tiles()
    t_setup = median_time(setup, args.repeat)
    t_bin = median_time(lambda: bin_boxes(box, group, 2, tile, ntx, nty, 8), args.repeat)
    t_gather = median_time(lambda: gather_rows(P, items, pt), args.repeat)
    t_tiles = median_time(tiles, args.repeat)
    t_fill = median_time(fill, args.repeat)
    t_resolve = median_time(renderer.gbuffer, args.repeat)
    t_frame = median_time(splat_frame, args.repeat)
    t_shade = median_time(lambda: shade(g, cam), args.repeat)
    t_render = median_time(lambda: render(cloud, cam), max(3, args.repeat // 2))
    fill_frame = t_frame - t_tiles + t_fill

    print(f"EWA splatting benchmark: {n} surfels (Fibonacci sphere), {size}x{size}, perspective")
    print(f"numba threads: {numba.get_num_threads()}   threading layer: {numba.threading_layer()}")
    print(f"first frame (compile or cache load): {warm:.2f} s")
    print(f"(surfel, tile) pairs: {len(items)}   covered pixels: {int(g.coverage.sum())}"
          f"   accumulated fragments: {int(renderer.count.sum())}")
    print("stages (median):")
    print(f"  setup {t_setup * 1e3:7.1f} ms   binning {t_bin * 1e3:6.1f} ms   gather {t_gather * 1e3:6.1f} ms")
    print(f"  EWA tiles (visibility + accumulation) {t_tiles * 1e3:7.1f} ms")
    print(f"  fill-only tiles (same pixels)         {t_fill * 1e3:7.1f} ms   ratio {t_tiles / t_fill:.2f}x")
    print(f"  normalisation {t_resolve * 1e3:6.1f} ms   deferred shading {t_shade * 1e3:6.1f} ms")
    print(f"splatting frame: {t_frame:.3f} s  ({n / t_frame / 1e6:.2f} M splats/s)   goal <= 0.3 s")
    print(f"fill-only frame: {fill_frame:.3f} s   splat / fill-only = {t_frame / fill_frame:.2f}x   goal <= 3x")
    print(f"render() end to end incl. shading: {t_render:.3f} s")
    # load-robust figures: CPU time of one thread (on a shared machine wall-clock times of
    # parallel regions include waiting for descheduled worker threads)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    c_frame = median_time(splat_frame, args.repeat, time.process_time)
    c_tiles = median_time(tiles, args.repeat, time.process_time)
    c_fill = median_time(fill, args.repeat, time.process_time)
    numba.set_num_threads(before)
    c_fill_frame = c_frame - c_tiles + c_fill
    print("single-thread CPU time (median):")
    print(f"  splatting frame {c_frame:.3f} s   EWA tiles {c_tiles * 1e3:.1f} ms   fill-only tiles {c_fill * 1e3:.1f} ms"
          f" ({c_tiles / c_fill:.2f}x)")
    print(f"  fill-only frame {c_fill_frame:.3f} s   splat / fill-only = {c_frame / c_fill_frame:.2f}x")
    print(f"  two cores, ideal split: ~{c_frame / 2:.3f} s per splatting frame")


if __name__ == "__main__":
    main()
