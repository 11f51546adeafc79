"""The studio's server side without a browser (issue 19): bench_studio's pen strokes replayed in
real time against a :class:`~unmesh.paint.studio.workspace.Workspace`.

Each stroke (60 pen events at 120 per second along a row across the model, pressure 0.3 to 0.9,
brush size 0.05) is resampled as the page does (two fifths of the brush size on the screen) and
batched per animation frame (1/60 s); the messages are handed to the workspace when their time
has come, like the server's worker takes them, and a frame is rendered after each batch. It
prints the latency from a pen event to the frame that shows it (median, p90, max; no network,
no page), the painted frames per second, the samples given to ``add_samples`` and the engine's paint
events (``paint_event`` calls: the engine adds events between samples farther apart than its dab
step) per stroke,
the CPU time, and how long the ``end`` message took (the fifth stroke's starts an autosave).

``--steady`` replays the same strokes without real time (every message is handled and a frame
rendered at once, the studio's clock stopped, no autosave), so that the work is the same on every
run: it prints the CPU time of each stroke (the row capacity's growth and other hitches show as
one slow stroke), where it went, and a digest of the final rows and image (equal digests: the
same painting, for A/B runs of two versions).

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/bench_studio_replay.py [--surfels 500000] [--cache DIR]
        [--haptics off|thread|process] [--strokes 4] [--steady]
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spacing", type=float, default=0.035)
    ap.add_argument("--surfels", type=int, help="pick the spacing for about this many surfels")
    ap.add_argument("--cache", help="folder for the sampled model (PLY), as bench_studio.py")
    ap.add_argument("--haptics", choices=("thread", "process", "off"), default="off")
    ap.add_argument("--strokes", type=int, default=4)
    ap.add_argument("--steady", action="store_true", help="no real time: CPU per stroke and a digest of the result")
    args = ap.parse_args()

    import unmesh.paint.session as session_module
    from unmesh.paint.session import PaintOptions, Session
    from unmesh.paint.studio.frames import decode
    from unmesh.paint.studio.workspace import Workspace
    from unmesh.shapes import Blob

    spacing = args.spacing
    if args.surfels:
        spacing = 0.01 * math.sqrt(len(Blob().surfels(spacing=0.01)) / args.surfels)  # pilot as bench_studio's
    cached = Path(args.cache) / f"blob_{spacing:.6g}.ply" if args.cache else None
    if cached is not None and cached.is_file():
        from unmesh.io import load_surfels

        cloud = load_surfels(cached)
    else:
        cloud = Blob().surfels(spacing=spacing)
        if cached is not None:
            from unmesh.io import save

            cached.parent.mkdir(parents=True, exist_ok=True)
            save(cached, cloud)
    haptics = {"thread": "thread", "process": "process", "off": False}[args.haptics]
    if args.steady:
        import unmesh.paint.studio.workspace as workspace_module

        class StoppedClock:  # the studio's clock (sample times) stands still; timers run
            perf_counter, time = staticmethod(time.perf_counter), staticmethod(time.time)
            monotonic = staticmethod(lambda: 0.0)

        workspace_module.time = StoppedClock
    ws = Workspace(Session(cloud, PaintOptions(haptics=haptics)), Path(tempfile.mkdtemp()) / "o.ply",
                   advance_every=None, autosave_every=10**9 if args.steady else 5)
    if args.steady:
        ws.paint_budget = None  # every frame paints all its samples
    ws.handle({"type": "hello", "width": 956, "height": 760})  # bench_studio's model image
    ws.frames()
    cov = ws.session.render(ws.camera(), brush=False).coverage
    print(f"model: blob, {len(cloud)} surfels; image {ws.width}x{ws.height}; haptic loop {args.haptics}")

    def segment(lo: float, hi: float, length: float = 0.6) -> tuple[float, float, float]:
        best = (0, 0, 0)
        for r in range(int(lo * cov.shape[0]), int(hi * cov.shape[0]), 4):
            edges = np.flatnonzero(np.diff(np.concatenate([[0], cov[r].astype(int), [0]])))
            for a, b in zip(edges[::2], edges[1::2], strict=True):
                if b - a > best[2] - best[1]:
                    best = (r, a, b)
        r, a, b = best
        return r + 0.5, 0.5 * (a + b) - 0.5 * length * (b - a), 0.5 * (a + b) + 0.5 * length * (b - a)

    step = max(1.0, 0.4 * 0.05 * ws.px_per_unit())  # the page's resampling distance (pixels)
    lat: list[float] = []
    fps, samples, events, ends = [], [], [], []
    calls = [0]
    paint_event = session_module.paint_event

    def counted(*a, **k):
        calls[0] += 1
        return paint_event(*a, **k)

    session_module.paint_event = counted

    spent: dict[str, float] = {}

    def timed(obj, name, key):
        f = getattr(obj, name)

        def g(*a, **kw):
            t = time.process_time()
            try:
                return f(*a, **kw)
            finally:
                spent[key] = spent.get(key, 0.0) + time.process_time() - t
        setattr(obj, name, g)

    dur = 59 / 120  # seconds per stroke: 60 pen events at 120 per second

    def stroke_batches(k: int) -> dict[int, list]:
        """Stroke ``k``'s pen samples, batched by the animation frame (60 per second) they are sent at."""
        row, x0, x1 = segment(0.35 + 0.08 * k, 0.45 + 0.08 * k)
        n = int((x1 - x0) / step)
        rows = [[1000 * dur * i * step / (x1 - x0), x0 + i * step, row, 0.3 + 0.6 * i * step / (x1 - x0), 0, 0]
                for i in range(n + 1)]
        batches: dict[int, list] = {}
        for r in rows:
            batches.setdefault(int(r[0] / (1000 / 60)) + 1, []).append(r)
        return batches

    def steady_stroke(k: int) -> None:
        batches = stroke_batches(k)
        ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.05},
                   "paint": {"type": "oil", "color": [0.14, 0.18, 0.62]}})
        for _, b in sorted(batches.items()):
            ws.handle({"type": "samples", "samples": b, "ts": b[-1][0]})
            ws.frames()
        ws.handle({"type": "end"})
        ws.frames()

    if args.steady:
        import hashlib

        from unmesh.paint.brush import BrushState

        steady_stroke(0)  # warm-up
        timed(session_module.Session, "add_samples", "add_samples")
        timed(session_module, "paint_event", "paint_event")
        timed(BrushState, "simulate", "simulate")
        timed(session_module.Session, "render", "render")
        cpu = []
        for k in range(args.strokes):
            c0, calls[0] = time.process_time(), 0
            steady_stroke(k % 4)
            cpu.append(time.process_time() - c0)
            print(f"stroke {k + 1}: CPU {1000 * cpu[-1]:.0f} ms, {calls[0]} paint events, {ws.session.surface.n} rows")
        s = ws.session.surface
        h = hashlib.sha1()
        for name in sorted(session_module.FIELDS):
            h.update(np.ascontiguousarray(getattr(s, name)).tobytes())
        img = ws.session.render(ws.camera(), brush=False).color
        print(f"CPU {sum(cpu):.2f} s for {args.strokes} strokes (min {1000 * min(cpu):.0f}, max {1000 * max(cpu):.0f} ms); "
              "of it (s): " + ", ".join(f"{k} {v:.2f}" for k, v in spent.items()))
        print(f"digest: rows {h.hexdigest()[:16]}, image {hashlib.sha1(np.ascontiguousarray(img).tobytes()).hexdigest()[:16]}")
        ws.shutdown()
        return

    def stroke(k: int) -> None:
        batches = stroke_batches(k)
        queue = [(key * 1000 / 60, b) for key, b in sorted(batches.items())]
        ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.05},
                   "paint": {"type": "oil", "color": [0.14, 0.18, 0.62]}})
        count = [0]
        add = ws.session.add_samples
        ws.session.add_samples = lambda sid, s: count.__setitem__(0, count[0] + len(s)) or add(sid, s)
        t0, frames, calls[0] = time.perf_counter(), 0, 0
        while queue or ws.backlog:
            now = 1000 * (time.perf_counter() - t0)
            due = [b for t, b in queue if t <= now]
            queue = [(t, b) for t, b in queue if t > now]
            if not due and not ws.backlog:
                time.sleep(max(0.0, (queue[0][0] - now) / 1000))
                continue
            for b in due:
                ws.handle({"type": "samples", "samples": b, "ts": b[-1][0]})
            for f in ws.frames():
                head = decode(f)[0]
                if head["target"] == "model" and head.get("ts") is not None:
                    frames += 1
                    lat.append(1000 * (time.perf_counter() - t0) - head["ts"])
        span = time.perf_counter() - t0
        t = time.perf_counter()
        ws.handle({"type": "end"})
        ws.frames()
        ends.append(1000 * (time.perf_counter() - t))
        del ws.session.add_samples
        fps.append(frames / max(span, dur))
        samples.append(count[0])
        events.append(calls[0])

    stroke(0)  # warm-up
    lat.clear()
    fps.clear()
    samples.clear()
    events.clear()
    ends.clear()
    c0 = time.process_time()
    for k in range(args.strokes):
        stroke(k % 4)
    cpu = time.process_time() - c0
    q = np.percentile(lat, [50, 90, 100])
    print(f"pen event -> frame: median {q[0]:.0f} ms, p90 {q[1]:.0f} ms, max {q[2]:.0f} ms ({len(lat)} frames)")
    print(f"painted frames per second: {statistics.median(fps):.1f} (median over strokes)")
    print(f"per stroke: {samples} samples to add_samples, {events} paint events (with the 'end' tail); "
          f"CPU {cpu:.2f} s for {args.strokes} strokes of 0.49 s")
    print(f"'end' handled in (ms): {[round(e) for e in ends]} (the 5th stroke's end starts an autosave)")
    ws.shutdown()


if __name__ == "__main__":
    main()
