"""Benchmark: 3D painting (thesis 5.8) on a ~500k-surfel blob at 1024x768.

Prints:

* paint events per second including each event's differential render update (goal >= 30;
  thesis: 30 Hz on a 2004 Pentium 4), and the event alone (brush + transfer + resampling);
* the time of a differential update of about 5,000 surfels (goal <= 5 ms; thesis 15 ms);
* the time of a full update (goal <= 0.2 s);
* the haptic loop's measured rate and jitter while painting (goal 1 kHz, jitter < 1 ms).

Timings are warm (a first stroke compiles the numba kernels). On a shared or loaded machine
they are not trustworthy; the script prints the load average.

Usage::

    python benchmarks/bench_paint.py [--surfels 500000] [--events 60] [--size 1024x768] [--haptics process]
                                     [--brush-size 0.05]   # the studio benchmark's brush (default 12 spacings)
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--surfels", type=int, default=500_000)
    ap.add_argument("--events", type=int, default=60)
    ap.add_argument("--size", default="1024x768")
    ap.add_argument("--haptics", choices=("thread", "process"), default="process",
                    help="haptic loop in a thread or in its own process (default)")
    ap.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "unmesh_bench_paint_{n}.ply"),
                    help="sampled model cache (sampling 500k surfels takes minutes)")
    ap.add_argument("--brush-size", type=float, default=None,
                    help="round brush size in world units (default 12 surfel spacings; the studio benchmark uses 0.05)")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))

    import numpy as np

    from unmesh.paint import Brush, Paint, PaintOptions, Sample, Session
    from unmesh.render import Camera
    from unmesh.render.splat import SurfelArrays
    from unmesh.shapes import by_name

    print(f"load average: {os.getloadavg()}")
    from unmesh.io import load_surfels, save

    blob = by_name("blob")
    # the blob's sampler gives about 0.68 area / spacing^2 surfels
    spacing = float(np.sqrt(0.68 * blob.area() / args.surfels))
    cache = args.cache.format(n=args.surfels)
    t = time.perf_counter()
    if os.path.exists(cache):
        cloud = load_surfels(cache)
    else:
        cloud = blob.surfels(spacing)
        save(cache, cloud)
    print(f"model: blob, {len(cloud)} surfels (spacing {spacing:.4g}), sampled or loaded in "
          f"{time.perf_counter() - t:.1f} s")
    s = Session(cloud, PaintOptions(haptics=args.haptics))
    b = cloud.bounds()
    cam = Camera.framing(b, w, h, direction=(0.0, 0.15, 1.0))

    # points on the front of the blob: the visible surface point of pixels along a line
    s.render(cam)
    pts = []
    for k in range(args.events + 20):
        x = w * (0.35 + 0.3 * k / (args.events + 20))
        y = h * (0.55 + 0.05 * np.sin(k / 5))
        p = s.pick(cam, x, y)
        if p is not None:
            pts.append(p)
    brush = Brush("round", args.brush_size if args.brush_size is not None else 6 * spacing * 2)
    paint = Paint("oil", (0.8, 0.15, 0.1))
    # warm-up (numba compilation of the buffer splatting)
    sid = s.begin_stroke(brush, paint)
    s.add_samples(sid, [Sample(0.0, tuple(pts[0]), 0.7)])
    s.render(cam)
    s.end_stroke(sid)

    t_full, c_full = [], []
    for _ in range(3):
        t, c = time.perf_counter(), time.process_time()
        s.render(cam, full=True)
        t_full.append(time.perf_counter() - t)
        c_full.append(time.process_time() - c)

    sid = s.begin_stroke(brush, Paint("oil", (0.1, 0.3, 0.8)))
    ev, ev_cpu, upd, upd_cpu, counts = [], [], [], [], []
    for k, p in enumerate(pts[1:args.events + 1]):
        t0, c0 = time.perf_counter(), time.process_time()
        s.add_samples(sid, [Sample(0.02 * (k + 1), tuple(p), 0.7)])
        t1, c1 = time.perf_counter(), time.process_time()
        ev_cpu.append(c1 - c0)
        s.render(cam)
        t2 = time.perf_counter()
        upd_cpu.append(time.process_time() - c1)
        ev.append(t1 - t0)
        upd.append(t2 - t1)
        counts.append(s._view.last_count)
    # a render with nothing repainted: only the image composition of every frame (the windows
    # of the old and the new brush rewritten, the brush and its shadow drawn)
    comp, comp_cpu = [], []
    for _ in range(5):
        t, c = time.perf_counter(), time.process_time()
        s.render(cam)
        comp.append(time.perf_counter() - t)
        comp_cpu.append(time.process_time() - c)
    s.end_stroke(sid)
    ev_a, upd_a = np.array(ev), np.array(upd)
    print(f"brush: round, size {brush.size:.4g}")
    print(f"paint events: {len(ev)}; event alone {1e3 * np.median(ev_a):.1f} ms median ({1e3 * np.median(ev_cpu):.1f} ms "
          f"CPU); with the differential "
          f"update {1.0 / np.median(ev_a + upd_a):.1f} events/s (median), {len(ev) / (ev_a + upd_a).sum():.1f} events/s (mean)")
    print(f"differential updates per event: {int(np.median(counts))} surfels median, {1e3 * np.median(upd_a):.1f} ms "
          f"median, {1e3 * np.median(upd_cpu):.1f} ms CPU (unsplat/splat, normalising and shading their window, and "
          f"the image composition: {1e3 * np.median(comp):.1f} ms median, {1e3 * np.median(comp_cpu):.1f} ms CPU, "
          f"with nothing repainted)")

    # a differential update of 5,000 surfels: unsplat + splat of the same 5,000 visible rows
    r = s._view.renderer
    rows = s.surface.visible_rows()[:2500]
    arr = SurfelArrays(np.ascontiguousarray(s.surface.pos[rows]), np.ascontiguousarray(s.surface.nrm[rows]),
                       np.ascontiguousarray(s.surface.rad[rows]), None, s.surface.colors(rows))
    times, cpu = [], []
    for _ in range(10):
        t, c = time.perf_counter(), time.process_time()
        r.unsplat(arr)
        r.splat(arr)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    print(f"differential update of 5,000 surfels (2,500 unsplat + 2,500 splat): {1e3 * np.median(times):.2f} ms median, "
          f"{1e3 * np.median(cpu):.2f} ms CPU")
    t = time.perf_counter()
    r.gbuffer()
    print(f"  normalising the {w}x{h} G-buffer after it: {1e3 * (time.perf_counter() - t):.1f} ms")
    print(f"full update: {np.median(t_full):.3f} s median of {len(t_full)}, {np.median(c_full):.3f} s CPU of this process "
          f"({len(s.surface.visible_rows())} surfels)")
    st = s.haptic_stats()
    print(f"haptic loop ({args.haptics}) while painting: {st['rate']:.0f} Hz, jitter (std of the period) {1e3 * st['jitter']:.3f} ms, "
          f"largest period error {1e3 * st['max_error']:.2f} ms over {int(st['samples'])} periods")
    s.close()


if __name__ == "__main__":
    main()
