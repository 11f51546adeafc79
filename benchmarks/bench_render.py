"""Benchmark of EWA surface splatting: ``unmesh.render.render()`` end to end (issue 22, item 1).

The case of the issue: a 10^6-surfel unit sphere (Fibonacci points), orthographic camera,
1024x1024, surfel radii ``k`` times the point spacing ``h = sqrt(4 pi / N)`` for ``k`` in
0.7, 1.0, 1.5, 2.0 (1.5 h is about 2.2 px). For each ``k`` it prints, from warm (compiled)
kernels and the median of several calls:

* the headline: ``render()`` end to end (splatting, normalisation, deferred shading, result);
* a plain single-threaded fill-only kernel written here (:func:`fill_only`): project every
  surfel, fill its footprint (the disc of the projected radius, at least the screen-filter
  radius) with a depth test, nothing else; measured on the same surfels in the same run, with
  the ratio ``render() / fill-only`` (goal <= 3x; ``render()`` goal <= 0.2 s on 2 cores);
* the stage split of ``render()``: set-up, binning (fused with the set-up in one pass,
  :func:`~unmesh.render._splat_kernels.splat_setup_bin`; binning = fused pass minus set-up
  alone), tile kernel (which gathers each tile's parameter rows itself; the same gathering as
  one separate pass is printed beside it), normalisation, shading, buffer allocation and
  copies, and the pipeline overhead (the rest of ``render()``);
* the tile kernel next to the fill-only tile kernel
  (:func:`~unmesh.render._splat_kernels.fill_tiles`, the same pixels of the same (surfel, tile)
  pairs without EWA arithmetic) and the single-thread CPU time of ``render()``, which is robust
  to load on a shared machine (wall-clock times of parallel regions include waiting for
  descheduled threads; compare fractions there, not absolute times).

Usage::

    python benchmarks/bench_render.py [--quick] [--surfels 1000000] [--size 1024] [--repeat 5]
                                      [--k 0.7 1.0 1.5 2.0] [--threads N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from numba import njit


def fibonacci_sphere(n: int, k: float):
    """Unit sphere of ``n`` surfels with radii ``k`` times the spacing, and that spacing."""
    from unmesh import SurfelCloud

    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5**0.5) * i
    p = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    h = np.sqrt(4 * np.pi / n)
    col = 0.5 + 0.5 * np.stack([np.sin(5 * p[:, 0]), np.sin(5 * p[:, 1]), np.cos(5 * p[:, 2])], 1)
    return SurfelCloud(p, p, radii=np.full(n, k * h), colors=col), h


@njit(cache=False)
def fill_only(pos, radii, frame, eye, f, cx, cy, rfilter, zbuf, ibuf):
    """Plain single-threaded baseline (orthographic): for every surfel, the pixels of its
    footprint (disc of radius ``max(f r, rfilter)`` pixels around the projected centre) get
    ``zbuf = z``, ``ibuf = i`` where ``z < zbuf`` (depth test). Returns the number of writes."""
    H, W = zbuf.shape
    writes = 0
    for i in range(pos.shape[0]):
        qx = pos[i, 0] - eye[0]
        qy = pos[i, 1] - eye[1]
        qz = pos[i, 2] - eye[2]
        x = frame[0, 0] * qx + frame[0, 1] * qy + frame[0, 2] * qz
        y = frame[1, 0] * qx + frame[1, 1] * qy + frame[1, 2] * qz
        z = frame[2, 0] * qx + frame[2, 1] * qy + frame[2, 2] * qz
        sx = cx + f * x
        sy = cy - f * y
        rp = max(f * radii[i], rfilter)
        x0 = max(int(np.ceil(sx - rp - 0.5)), 0)
        x1 = min(int(np.floor(sx + rp - 0.5)), W - 1)
        y0 = max(int(np.ceil(sy - rp - 0.5)), 0)
        y1 = min(int(np.floor(sy + rp - 0.5)), H - 1)
        r2 = rp * rp
        for py in range(y0, y1 + 1):
            dy = py + 0.5 - sy
            for px in range(x0, x1 + 1):
                dx = px + 0.5 - sx
                if dx * dx + dy * dy <= r2 and z < zbuf[py, px]:
                    zbuf[py, px] = z
                    ibuf[py, px] = i
                    writes += 1
    return writes


def median_time(fn, repeat: int, clock=time.perf_counter) -> float:
    times = []
    for _ in range(repeat):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return statistics.median(times)


#: untimed render() calls before the first case's timed ones (see bench_case)
WARM_CALLS = 8
_WARMED: list[list[float]] = []
#: the first full-size render() call of the process (after compiling the kernels on a small image)
_FIRST: list[float] = []


def bench_case(n: int, size: int, k: float, repeat: int) -> dict[str, float]:
    import numba

    from unmesh.render import Camera, SplatRenderer, render, shade
    from unmesh.render._kernels import tile_order
    from unmesh.render._splat_kernels import (
        NPARAM,
        fill_tiles,
        gather_rows,
        splat_resolve,
        splat_setup,
        splat_setup_bin,
        splat_tiles,
    )
    from unmesh.render.shading import GBuffer, RenderResult

    cloud, h = fibonacci_sphere(n, k)
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), width=size, height=size, ortho=2.5)
    f, cx, cy, ortho, near = cam.kernel_params()
    frame = cam.rotation
    eye = np.asarray(cam.eye, dtype=np.float64)

    def frame_render():
        return render(cloud, cam)

    if not _WARMED:
        # compile (or load from the cache) every kernel on a small image first, so that the first
        # full-size call below is what a user's first render() in a process costs (cold memory)
        render(fibonacci_sphere(20_000, k)[0], cam.resized(64, 64))
        t0 = time.perf_counter()
        frame_render()
        _FIRST.append(time.perf_counter() - t0)
    else:
        frame_render()  # warm up
    # the process's first calls are slower: glibc serves the large temporaries by mmap (fresh
    # pages, page faults) until its mmap threshold has risen to their size (measured at stop 34:
    # calls 2-6 160 ms, then 110-115 ms at 0.7x). The timed calls are the steady state; the first
    # call and the warm-up calls are printed with the first case.
    warm = []
    for _ in range(WARM_CALLS if not _WARMED else 1):
        t0 = time.perf_counter()
        res = frame_render()
        warm.append(time.perf_counter() - t0)
    _WARMED.append(warm)
    t_render = median_time(frame_render, repeat)

    # the fill-only single-threaded baseline, same surfels, same run
    rf = SplatRenderer(cam).options.filter_radius
    zbuf = np.full((size, size), np.inf)
    ibuf = np.full((size, size), -1, dtype=np.int64)

    def fill():
        zbuf.fill(np.inf)
        return fill_only(cloud.positions, cloud.radii, frame, eye, f, cx, cy, rf, zbuf, ibuf)

    fill()
    t_fill = median_time(fill, repeat)

    # stage split, with the kernels render() calls and its arguments
    renderer = SplatRenderer(cam)
    opt = renderer.options
    tile = opt.tile
    ntx = nty = (size + tile - 1) // tile
    order = tile_order(ntx * nty)
    P = np.empty((n, NPARAM), dtype=renderer.param_dtype)
    box = np.empty((n, 4), dtype=np.int32)
    group = np.empty(n, dtype=np.int8)
    axes = np.zeros((1, 2, 3))
    args = (cloud.positions, cloud.normals, cloud.radii, axes, False, cloud.colors, frame, cam.eye, f, cx, cy,
            ortho, near, size, size, opt.filter_radius, P, box, group)

    def setup_bin():
        return splat_setup_bin(*args, tile, ntx, nty, 8)

    offsets, items, _ = setup_bin()
    pt = np.empty((len(items), NPARAM), dtype=renderer.param_dtype)
    gather_rows(P, items, pt)
    coff, cpl, cmode = np.zeros(1, dtype=np.int64), np.zeros((0, 4)), np.zeros(1, dtype=np.int8)

    def tiles():  # a full update overwrites the sums: render() does not clear them (SplatRenderer._reset)
        renderer._reset(None)
        splat_tiles(P, items, offsets, order, tile, size, size, f, cx, cy, ortho, near, opt.filter_radius,
                    opt.kappa, opt.depth_tolerance, False, cam.eye, frame, coff, cpl, cmode, None, None, True, 1.0,
                    renderer.zvis, renderer.sum_weight, renderer.sum_color, renderer.sum_normal, renderer.sum_depth,
                    renderer.count, renderer._dirty)

    def clear_only():
        renderer._reset(None)

    fill_out = np.zeros((size, size))
    g = GBuffer.empty(size, size)

    def resolve():
        splat_resolve(renderer.sum_weight, renderer.sum_color, renderer.sum_normal, renderer.sum_depth,
                      renderer.count, frame, g.albedo, g.normal, g.depth, g.coverage, g.weight)

    def buffers():  # what render() allocates and copies around the kernels
        gb = GBuffer.empty(size, size)
        SplatRenderer(cam)  # (its buffers are allocated on first use: render() takes the thread's)
        gb.depth.copy()
        RenderResult.from_gbuffer(gb, cam, np.empty((size, size, 3)), copy=False)

    tiles()
    resolve()
    fill_tiles(pt, offsets, order, tile, size, size, fill_out)
    s = {
        "render": t_render,
        "fill_only": t_fill,
        "setup": median_time(lambda: splat_setup(*args), repeat),
        "setup_bin": median_time(setup_bin, repeat),
        "gather": median_time(lambda: gather_rows(P, items, pt), repeat),
        "tiles": median_time(tiles, repeat) - median_time(clear_only, repeat),
        "fill_tiles": median_time(lambda: fill_tiles(pt, offsets, order, tile, size, size, fill_out), repeat),
        "resolve": median_time(resolve, repeat),
        "shade": median_time(lambda: shade(res.gbuffer(), cam), repeat),
        "buffers": median_time(buffers, repeat),
    }
    s["binning"] = max(s["setup_bin"] - s["setup"], 0.0)
    s["pipeline"] = t_render - (s["setup_bin"] + s["tiles"] + s["resolve"] + s["shade"] + s["buffers"])
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        frame_render()
        s["render_cpu1"] = median_time(frame_render, repeat, time.process_time)
        s["fill_only_cpu"] = median_time(fill, repeat, time.process_time)
    finally:
        numba.set_num_threads(before)
    s["pairs"] = float(len(items))
    s["covered"] = float(res.coverage.sum())
    s["radius_px"] = k * h * f
    return s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="1/10 of the surfels (radii in pixels as in the full case "
                                                         "at size/sqrt(10)), fewer repeats")
    ap.add_argument("--surfels", type=int, default=1_000_000)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--k", type=float, nargs="+", default=[0.7, 1.0, 1.5, 2.0], help="radii in units of the spacing")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: all)")
    args = ap.parse_args()
    n, size, repeat = args.surfels, args.size, args.repeat
    if args.quick:
        n, size, repeat = n // 10, round(size / 10**0.5), min(repeat, 3)

    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)

    if args.threads:
        numba.set_num_threads(args.threads)
    load = os.getloadavg()
    print(f"render() end to end: {n} surfels (Fibonacci unit sphere), {size}x{size}, orthographic")
    print(f"numba threads: {numba.get_num_threads()}   threading layer: {numba.threading_layer()}   "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print("goals: render() <= 0.2 s on 2 cores (full case) and <= 3x the fill-only single-threaded kernel")
    rows = []
    for k in args.k:
        s = bench_case(n, size, k, repeat)
        rows.append((k, s))
        ms = {key: 1e3 * v for key, v in s.items()}
        if len(_WARMED) == 1:
            print(f"first render() call of the process (kernels loaded): {1e3 * _FIRST[0]:.0f} ms; then the "
                  "warm-up calls (ms), untimed: " + " ".join(f"{1e3 * t:.0f}" for t in _WARMED[0]))
        print(f"\nradii {k:.1f} x spacing ({s['radius_px']:.2f} px): render() {s['render']:.3f} s   fill-only "
              f"{s['fill_only']:.3f} s   ratio {s['render'] / s['fill_only']:.2f}x")
        stages = [("set-up", "setup"), ("binning", "binning"), ("tile kernel", "tiles"),
                  ("normalisation", "resolve"), ("shading", "shade"), ("buffers/copies", "buffers"),
                  ("pipeline", "pipeline")]
        print("  stages of render() (median ms, % of render()):")
        print("   " + "   ".join(f"{label} {ms[key]:.1f} ({100 * s[key] / s['render']:.0f}%)" for label, key in stages))
        print(f"  tile kernel {ms['tiles']:.1f} ms (its gathering as one pass: {ms['gather']:.1f} ms) "
              f"vs fill-only tiles {ms['fill_tiles']:.1f} ms "
              f"({s['tiles'] / s['fill_tiles']:.2f}x)   (surfel, tile) pairs {int(s['pairs'])}   "
              f"covered pixels {int(s['covered'])}")
        print(f"  single-thread CPU time: render() {s['render_cpu1']:.3f} s   fill-only {s['fill_only_cpu']:.3f} s   "
              f"ratio {s['render_cpu1'] / s['fill_only_cpu']:.2f}x")
    print("\nsummary   k   render() s   fill-only s   ratio   1-thread CPU ratio")
    for k, s in rows:
        print(f"        {k:4.1f}   {s['render']:9.3f}   {s['fill_only']:10.3f}   {s['render'] / s['fill_only']:5.2f}x"
              f"   {s['render_cpu1'] / s['fill_only_cpu']:5.2f}x")


if __name__ == "__main__":
    main()
