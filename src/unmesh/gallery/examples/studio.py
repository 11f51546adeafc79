"""Gallery example of the painting studio in the browser (issue 19): ``paint-studio``.

The example starts the studio (:mod:`unmesh.paint.studio`) on the built-in blob, opens it in
headless Chromium through Playwright, paints a few strokes with a scripted pen (DevTools
``Input.dispatchMouseEvent`` with ``pointerType: "pen"``, pressure and tilt): paint mixed on the
palette, then a multi-colour design on the blob; and takes a screenshot of the page. It reports
the latencies the page measured while it painted.

It needs Playwright for Python (the ``studio`` extra: ``pip install "unmesh[studio]"``) and
Debian's Chromium (``sh .ci/install-browser``; ``UNMESH_CHROMIUM`` names another executable);
the README's gallery command installs both. Without them the example fails with a
:class:`~unmesh.errors.MissingDependencyError` that says what to install (the gallery records
it and goes on with the other examples); it never skips silently.
"""

from __future__ import annotations

import math
import os
import statistics
import time
from pathlib import Path
from typing import Any

from unmesh.errors import MissingDependencyError
from unmesh.gallery.registry import ExampleContext, example

__all__ = ["CHROMIUM_ARGS", "chromium_path", "paint_design", "pen_stroke"]

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run"]
_INSTALL = 'pip install "unmesh[studio]" and sh .ci/install-browser (Debian\'s chromium)'


def chromium_path() -> str:
    """The Chromium executable (``UNMESH_CHROMIUM``, default ``/usr/bin/chromium``); raises
    MissingDependencyError when it or Playwright is missing."""
    path = os.environ.get("UNMESH_CHROMIUM", "/usr/bin/chromium")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        raise MissingDependencyError(f"the studio screenshot needs Playwright for Python: {_INSTALL}") from None
    if not Path(path).is_file():
        raise MissingDependencyError(f"the studio screenshot needs Chromium at {path}: {_INSTALL}")
    return path


def pen_stroke(page: Any, points: list[tuple[float, float]], pressures: list[float], rate: float = 120.0,
               color: tuple[float, float, float] | None = None, tilt: tuple[float, float] = (0.0, 0.0)) -> float:
    """Draw one pen stroke through page coordinates ``points`` at ``rate`` events per second, then
    wait until the studio drew its frames; returns the stroke's duration in seconds."""
    if color is not None:
        page.evaluate(f"window.studio.setColor({list(color)})")
    cdp = page.context.new_cdp_session(page)

    def event(kind: str, i: int, buttons: int) -> None:
        cdp.send("Input.dispatchMouseEvent", {
            "type": kind, "x": points[i][0], "y": points[i][1], "button": "left", "buttons": buttons,
            "pointerType": "pen", "force": pressures[i], "tiltX": tilt[0], "tiltY": tilt[1],
            "clickCount": 1 if buttons else 0})

    event("mouseMoved", 0, 0)
    event("mousePressed", 0, 1)
    t0 = time.perf_counter()
    for i in range(1, len(points)):
        event("mouseMoved", i, 1)
        wait = t0 + i / rate - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    event("mouseReleased", len(points) - 1, 0)
    cdp.detach()
    page.evaluate("window.studio.sync()")
    return time.perf_counter() - t0


def _to_page(page: Any, camera: Any, x: float, y: float) -> tuple[float, float]:
    box = page.locator("#overlay").bounding_box()
    return box["x"] + x * box["width"] / camera.width, box["y"] + y * box["height"] / camera.height


def paint_design(page: Any, studio: Any, rate: float = 120.0, strokes: int = 4) -> int:
    """Mix paint on the palette and paint ``strokes`` coloured arcs across the model in the home
    view; the pen is left hovering over the model (its brush cursor shows). Returns the strokes drawn."""
    page.evaluate("window.studio.nav.preset('home', window.studio.server.presets)")
    page.evaluate("window.studio.sync()")
    box = page.locator("#palette").bounding_box()
    colors = [(0.98, 0.86, 0.12), (0.8, 0.1, 0.1), (0.16, 0.52, 0.8), (0.05, 0.5, 0.38), (0.55, 0.05, 0.2)]
    n = 0
    for k, c in enumerate(colors[:max(2, strokes)]):
        y = box["y"] + box["height"] * (0.2 + 0.15 * k)
        pts = [(box["x"] + box["width"] * (0.1 + 0.35 * i / 24 + 0.1 * k), y + 6 * math.sin(i / 3)) for i in range(25)]
        pen_stroke(page, pts, [0.85] * 25, rate, color=c)
        n += 1
    cam = studio.run_in_worker(lambda ws: ws.camera())
    cx, cy = cam.width * 0.5, cam.height * 0.5
    page.evaluate("window.studio.choose('brush', 'round')")
    for k, (c, dy) in enumerate(zip(colors[:strokes], (-0.02, 0.05, 0.12, 0.19, 0.26), strict=False)):
        pts = []
        for i in range(30):
            a = math.pi * 0.9 + (math.pi * 0.1 - math.pi * 0.9) * i / 29
            pts.append(_to_page(page, cam, cx - 0.08 * cam.width + 0.1 * cam.width * math.cos(a),
                                cy + dy * cam.height + 0.03 * cam.height * math.sin(a)))
        pen_stroke(page, pts, [0.4 + 0.5 * math.sin(math.pi * i / 29) for i in range(30)], rate, color=c,
                   tilt=(10.0 * (k - 1), 0.0))
        n += 1
    page.evaluate("window.studio.setColor([0.98, 0.86, 0.12])")
    page.mouse.move(*_to_page(page, cam, cx + 0.05 * cam.width, cy))
    return n


@example("paint-studio", "The painting studio in the browser: palette, brush and a design on the blob (issue 19)",
         section="Painting")
def paint_studio(ctx: ExampleContext) -> None:
    """Start ``unmesh paint blob``'s studio, paint with a scripted pen in headless Chromium, screenshot it."""
    chromium = chromium_path()
    from playwright.sync_api import sync_playwright

    from unmesh.paint.session import Session
    from unmesh.paint.studio.server import BackgroundStudio
    from unmesh.paint.studio.workspace import Workspace
    from unmesh.shapes import Blob

    spacing, viewport, strokes = (0.028, (1200, 720), 2) if ctx.quick else (0.02, (1280, 800), 4)
    cloud = Blob().surfels(spacing=spacing)
    out = ctx.path("blob_painted.ply")
    with BackgroundStudio(Workspace(Session(cloud), out, advance_every=None)) as studio:
        pw = sync_playwright().start()
        try:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]},
                                       bypass_csp=True).new_page()  # page.evaluate needs eval
            page.goto(studio.url)
            page.wait_for_function("window.studio && window.studio.connected && window.studio.stats.modelFrames > 0",
                                   timeout=120000)
            page.evaluate("window.studio.sync()")
            t0 = time.perf_counter()
            n = paint_design(page, studio, strokes=strokes)
            painting = time.perf_counter() - t0
            stats = page.evaluate("({p: window.studio.stats.previewLatencies, l: window.studio.stats.latencies})")
            shot = ctx.path("studio.png")
            page.screenshot(path=str(shot))
            browser.close()
        finally:
            pw.stop()
    # leaving the studio saved the model (its shutdown, as on Ctrl-C)
    ctx.image(shot, f"The studio in headless Chromium after {n} scripted pen strokes: {n // 2} colours on the palette "
                    f"(right) and {n // 2} coloured bands across the blob, the brush cursor over the model.")
    ctx.file(out, "the painted model (PLY with paint attributes; unmesh paint blob_painted.ply reopens it)")
    ctx.metric("surfels: model / painted", f"{len(cloud)} / {len(Session.load(out).cloud())}")
    ctx.metric("pen strokes (palette + model)", n)
    ctx.metric("painting time, all strokes", round(painting, 1), "s")
    if stats["p"]:
        ctx.metric("pen event to dab preview, median", round(statistics.median(stats["p"]), 1), "ms")
    if stats["l"]:
        ctx.metric("pen event to painted frame, median", round(statistics.median(stats["l"]), 1), "ms")
