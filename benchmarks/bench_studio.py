"""Benchmark of the painting studio in a real browser (issue 19): input-to-screen latency and
frame rates, measured by the page itself.

A studio serves a blob sampled at ``--spacing`` (``--surfels N`` picks the spacing for about N
surfels) to headless Debian Chromium at ``--size``; scripted pen strokes (DevTools
``Input.dispatchMouseEvent`` with ``pointerType: pen``) arrive at ``--rate`` events per second.
It prints:

* **input-to-screen latency** of paint events: from the pointer event's ``timeStamp`` to the
  moment the page's dab preview of it is drawn (client side, one animation frame), and to the
  moment the server's frame that contains it is drawn on the canvas (median, 90th percentile,
  max), with the split of the latter into stages (means, which add up to the mean total): ``input`` (event -> samples sent:
  the browser's input pipeline and the page's handler), ``queue`` / ``paint`` (ray casts + ``add_samples``) /
  ``render`` / ``encode`` (the server's timings in the frame header), ``up`` (sent -> received
  by the server's event loop) and ``down`` (encoded -> received by the page: event loop,
  WebSocket, the page's main thread), both from the shared wall clock, and ``client``
  (received -> decoded and drawn);
* **frames per second while painting** (model frames drawn per second of stroke) and the tiles
  and bytes per frame (differential updates);
* **frames per second while dragging the view** (low-resolution previews) and the time of the
  full-quality frame after release;
* the engine's share: median ``add_samples`` + ``render`` time of one paint event in process.

``--screenshot PATH`` paints a multi-colour design (object and palette) and saves the studio as
PNG (the image in ``docs/images/studio.png``). Figures depend on the machine and its load.

Usage::

    python benchmarks/bench_studio.py [--spacing 0.035 | --surfels 500000] [--cache DIR] [--size 1280x800]
                                      [--strokes 4] [--rate 120] [--haptics thread|process|off]
                                      [--screenshot docs/images/studio.png]
"""

from __future__ import annotations

import argparse
import atexit
import math
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "paint" / "studio"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spacing", type=float, default=0.035)
    ap.add_argument("--surfels", type=int, help="pick the spacing for about this many surfels")
    ap.add_argument("--cache", help="folder for the sampled model (PLY): sampled once, loaded on later runs")
    ap.add_argument("--size", default="1280x800", help="browser viewport WxH")
    ap.add_argument("--strokes", type=int, default=4)
    ap.add_argument("--rate", type=float, default=120.0, help="pen events per second")
    ap.add_argument("--haptics", choices=("thread", "process", "off"), default="thread",
                    help="the engine's 1 kHz haptic loop: in a thread (default), a process, or off")
    ap.add_argument("--screenshot", help="paint a design and save the studio to this PNG")
    args = ap.parse_args()

    from playwright.sync_api import sync_playwright

    from conftest import covered_segment, image_to_page
    from unmesh.gallery.examples.studio import CHROMIUM_ARGS, chromium_path, paint_design
    from unmesh.gallery.examples.studio import pen_stroke as stroke
    from unmesh.paint.session import PaintOptions, Session
    from unmesh.paint.strokes import Brush, Paint, Sample
    from unmesh.paint.studio.server import BackgroundStudio
    from unmesh.paint.studio.workspace import Workspace
    from unmesh.shapes import Blob

    spacing = args.spacing
    if args.surfels:
        # the pilot at 0.01 (26k surfels): at coarser spacings the ear caps' refinement
        # (shapes._sampling) is a larger share and the estimate would fall short
        n0 = len(Blob().surfels(spacing=0.01))
        spacing = 0.01 * math.sqrt(n0 / args.surfels)
    t = time.perf_counter()
    cached = Path(args.cache) / f"blob_{spacing:.6g}.ply" if args.cache else None
    if cached is not None and cached.is_file():
        from unmesh.io import load_surfels

        cloud, how = load_surfels(cached), f"loaded from {cached}"
    else:
        cloud, how = Blob().surfels(spacing=spacing), "sampled"
        if cached is not None:
            from unmesh.io import save

            cached.parent.mkdir(parents=True, exist_ok=True)
            save(cached, cloud)
    print(f"model: blob, spacing {spacing:.4g}, {len(cloud)} surfels ({how} in {time.perf_counter() - t:.1f} s)")
    w, h = (int(v) for v in args.size.split("x"))
    haptics = {"thread": "thread", "process": "process", "off": False}[args.haptics]
    print(f"haptic loop: {args.haptics}")
    folder = Path(tempfile.mkdtemp(prefix="unmesh_bench_studio_"))
    atexit.register(shutil.rmtree, folder, True)  # the saved model and its autosave: ~0.4 GB at 500k surfels
    out = folder / "blob_painted.ply"
    with BackgroundStudio(Workspace(Session(cloud, PaintOptions(haptics=haptics)), out, advance_every=None)) as studio:
        pw = sync_playwright().start()
        browser = pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        page = browser.new_context(viewport={"width": w, "height": h}, bypass_csp=True).new_page()
        t = time.perf_counter()
        page.goto(studio.url)
        page.wait_for_function("window.studio && window.studio.connected && window.studio.stats.modelFrames > 0",
                               timeout=300000)
        page.evaluate("window.studio.sync()")
        cam = studio.run_in_worker(lambda ws: ws.camera())
        print(f"page open with first frame: {time.perf_counter() - t:.2f} s; model image {cam.width}x{cam.height}")

        # warm-up stroke (first paint event compiles nothing but fills caches)
        row, x0, x1 = covered_segment(studio)
        stroke(page, [image_to_page(page, studio, x0 + (x1 - x0) * i / 9, row) for i in range(10)], [0.6] * 10,
               args.rate, color=(0.8, 0.1, 0.1))
        page.evaluate("window.studio.stats.latencies.length = 0")
        lat, fps, tiles, kb, prev, stages = [], [], [], [], [], []
        for k in range(args.strokes):
            row, x0, x1 = covered_segment(studio, row_frac=(0.35 + 0.08 * k, 0.45 + 0.08 * k), length_frac=0.6)
            n = 60
            pts = [image_to_page(page, studio, x0 + (x1 - x0) * i / (n - 1), row) for i in range(n)]
            before = page.evaluate("({f: window.studio.stats.modelFrames, t: window.studio.stats.tiles, "
                                   "b: window.studio.stats.bytes})")
            page.evaluate("window.studio.stats.latencies.length = 0; window.studio.stats.stages.length = 0; "
                          "window.studio.stats.previewLatencies.length = 0")
            dur = stroke(page, pts, [0.3 + 0.6 * i / (n - 1) for i in range(n)], args.rate, color=(0.14, 0.18, 0.62))
            after = page.evaluate("({f: window.studio.stats.modelFrames, t: window.studio.stats.tiles, "
                                  "b: window.studio.stats.bytes, l: window.studio.stats.latencies, "
                                  "p: window.studio.stats.previewLatencies, s: window.studio.stats.stages})")
            frames = after["f"] - before["f"]
            lat += after["l"]
            prev += after["p"]
            stages += after["s"]
            fps.append(frames / dur)
            tiles.append((after["t"] - before["t"]) / max(frames, 1))
            kb.append((after["b"] - before["b"]) / max(frames, 1) / 1024)
        q = np.percentile(lat, [50, 90, 100]) if lat else [float("nan")] * 3
        print(f"paint: {len(lat)} frames over {args.strokes} strokes of 60 pen events at {args.rate:.0f}/s")
        qp = np.percentile(prev, [50, 90, 100]) if prev else [float("nan")] * 3
        print(f"  input-to-screen latency, dab preview: median {qp[0]:.0f} ms, p90 {qp[1]:.0f} ms, max {qp[2]:.0f} ms")
        print(f"  input-to-screen latency, server frame: median {q[0]:.0f} ms, p90 {q[1]:.0f} ms, max {q[2]:.0f} ms")
        print("  server frame latency split (means, ms): " + stage_split(stages))
        print(f"  frames per second while painting: {statistics.median(fps):.1f} (median over strokes)")
        print(f"  per frame: {statistics.median(tiles):.1f} tiles, {statistics.median(kb):.1f} KiB")

        # view drag: previews while dragging, full frame on release
        box = page.locator("#overlay").bounding_box()
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        f0 = page.evaluate("window.studio.stats.modelFrames")
        page.mouse.move(cx, cy)
        page.mouse.down(button="right")
        t = time.perf_counter()
        for i in range(1, 41):
            page.mouse.move(cx - 6 * i, cy + 2 * i)
            time.sleep(max(0.0, t + i / 60 - time.perf_counter()))
        drag = time.perf_counter() - t
        f1 = page.evaluate("window.studio.stats.modelFrames")
        page.mouse.up(button="right")
        t = time.perf_counter()
        page.evaluate("window.studio.sync()")
        scale = studio.run_in_worker(lambda ws: ws.preview_scale)
        print(f"view drag: {(f1 - f0) / drag:.1f} preview frames per second over {drag:.2f} s "
              f"(preview at 1/{scale} resolution, {page.evaluate('window.studio.stats.dropped')} stale frames skipped); "
              f"full frame after release {1000 * (time.perf_counter() - t):.0f} ms")

        # the engine alone, in process (one paint event + its differential render)
        row, x0, x1 = covered_segment(studio)

        def engine_event(ws):
            s, camera = ws.session, ws.camera()
            s.render(camera)
            pts = [s.pick(camera, x0 + (x1 - x0) * i / 19, row) for i in range(20)]
            times, rtimes, ptimes = [], [], []
            sid = s.begin_stroke(Brush("round", 0.05), Paint("oil", (0.9, 0.8, 0.1)))
            for i, p in enumerate(pts):
                if p is None:
                    continue
                t0 = time.perf_counter()
                s.pick(camera, x0 + (x1 - x0) * i / 19, row)
                t1 = time.perf_counter()
                s.add_samples(sid, [Sample(0.02 * i, tuple(p), 0.7)])
                t2 = time.perf_counter()
                s.render(camera)
                t3 = time.perf_counter()
                ptimes.append(t1 - t0)
                times.append(t2 - t1)
                rtimes.append(t3 - t2)
            s.end_stroke(sid)
            s.undo()
            return statistics.median(ptimes), statistics.median(times), statistics.median(rtimes)

        tp, te, tr = studio.run_in_worker(engine_event)
        print(f"engine, one paint event in process: pick {1000 * tp:.1f} ms, add_samples {1000 * te:.1f} ms, "
              f"differential render {1000 * tr:.1f} ms")

        if args.screenshot:
            for _ in range(args.strokes + 1):  # a clean blob for the design: undo the measured strokes
                page.evaluate("window.studio.send({type: 'undo'})")
            paint_design(page, studio, args.rate)  # the gallery example's design (paint-studio)
            Path(args.screenshot).parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=args.screenshot)
            print(f"wrote {args.screenshot}")
        browser.close()
        pw.stop()


def stage_split(stages):
    """Means of the latency stages of the page's ``stats.stages`` records (means add up: ``other``
    is the total minus the stages, i.e. the gaps between them)."""
    keys = ("input", "up", "queue", "paint", "render", "encode", "down", "client")

    def parts(s):
        return {"input": s["input"], "up": s["up"], **{k: s["srv"].get(k) for k in ("queue", "paint", "render")},
                "encode": s["srv"].get("encode"), "down": s["down"], "client": s["client"]}

    rows = [parts(s) for s in stages]
    full = [(r, s["total"]) for r, s in zip(rows, stages, strict=True) if all(r[k] is not None for k in keys)]
    if not full:
        return "no complete records"
    mean = {k: statistics.fmean(r[k] for r, _ in full) for k in keys}
    total = statistics.fmean(t for _, t in full)
    mean["other"] = total - sum(mean.values())
    return ", ".join(f"{k} {v:.1f}" for k, v in mean.items()) + f" (= total {total:.1f}, {len(full)} frames)"


if __name__ == "__main__":
    main()
