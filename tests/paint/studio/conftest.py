"""Fixtures of the studio tests: one studio server and one headless Chromium per test module.

The browser is Debian's ``/usr/bin/chromium`` (Playwright never downloads one here); when it is
missing the browser tests FAIL with the command that installs it (``.ci/install-browser``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = os.environ.get("UNMESH_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run"]
#: Surfel spacing of the test model (a coarse blob: fast, still a few thousand surfels).
SPACING = 0.035
VIEWPORT = {"width": 840, "height": 540}


def model_cloud(spacing: float = SPACING):
    """The test model: what ``unmesh paint blob --spacing SPACING`` paints on."""
    from unmesh.shapes import Blob

    return Blob().surfels(spacing=spacing)


def new_session(spacing: float = SPACING):
    from unmesh.paint.session import Session

    return Session(model_cloud(spacing))


@pytest.fixture(scope="module")
def browser():
    """Headless Debian Chromium through Playwright; fails (never skips) when it is missing."""
    if not Path(CHROMIUM).is_file():
        pytest.fail(f"browser tests need Chromium at {CHROMIUM}: run .ci/install-browser (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    try:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
    except Exception:
        pw.stop()
        raise
    yield b
    b.close()
    pw.stop()


@pytest.fixture(scope="module")
def studio(tmp_path_factory):
    """A studio on a coarse blob, served from a background thread; output in a fresh folder."""
    from unmesh.paint.studio.server import BackgroundStudio
    from unmesh.paint.studio.workspace import Workspace

    out = tmp_path_factory.mktemp("studio") / "blob_painted.ply"
    ws = Workspace(new_session(), out, autosave_every=3, advance_every=None)
    _warm_up(ws.camera())
    bg = BackgroundStudio(ws)
    with bg as s:
        yield s


def _warm_up(camera) -> None:
    """Render and paint once on a throwaway session, so numba compiles the splatting and paint
    kernels here and not while a page waits for its first frames (on a cold cache that takes
    over a minute when another test worker compiles at the same time)."""
    from unmesh.paint import Brush, Paint, Sample

    s = new_session()
    s.render(camera)
    p = s.cloud().positions[0]
    s.stroke([Sample(0.05 * k, p, 0.6) for k in range(3)], brush=Brush("round", 0.04), paint=Paint("oil", (0.9, 0.1, 0.1)))
    s.render(camera)


def open_page(browser, studio, **context_args):
    """A page of the studio, connected, with its first frames drawn."""
    context = browser.new_context(viewport=VIEWPORT, bypass_csp=True, **context_args)  # page.evaluate needs eval
    page = context.new_page()
    page.on("pageerror", lambda exc: print("page error:", exc))
    page.goto(studio.url)
    page.wait_for_function("window.studio && window.studio.connected && window.studio.stats.modelFrames > 0",
                           timeout=60000)
    page.evaluate("window.studio.sync()")
    return page


def canvas_pixels(page) -> np.ndarray:
    """The model canvas as an (H, W, 3) uint8 array (a screenshot of the element)."""
    import io

    from PIL import Image

    png = page.locator("#view").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def covered_segment(studio, row_frac=(0.45, 0.75), length_frac=0.5):
    """A horizontal segment (image pixels) across the model's widest covered run in a band of rows."""
    res = studio.run_in_worker(lambda ws: ws.session.render(ws.camera(), brush=False))
    cov = res.coverage
    h = cov.shape[0]
    best = (0, 0, 0)
    for r in range(int(row_frac[0] * h), int(row_frac[1] * h), 4):
        row = np.concatenate([[False], cov[r], [False]]).astype(int)
        edges = np.flatnonzero(np.diff(row))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a > best[2] - best[1]:
                best = (r, a, b)
    r, a, b = best
    mid, half = 0.5 * (a + b), 0.5 * length_frac * (b - a)
    return r + 0.5, mid - half, mid + half


def image_to_page(page, studio, x, y):
    cam = studio.run_in_worker(lambda ws: ws.camera())
    box = canvas_box(page)
    return box["x"] + x * box["width"] / cam.width, box["y"] + y * box["height"] / cam.height


def cloud_state(studio):
    """(positions, colours) of the model's visible surfels, copied on the worker thread."""
    return studio.run_in_worker(lambda ws: (ws.session.cloud().positions.copy(), ws.session.cloud().colors.copy()))


def canvas_box(page) -> dict:
    return page.locator("#overlay").bounding_box()


def model_pixel(page, studio, point) -> tuple[float, float]:
    """Page coordinates (CSS px) of a world point in the current view."""
    cam = studio.run_in_worker(lambda ws: ws.camera())
    row, col, _ = cam.project(np.asarray([point], dtype=float))
    box = canvas_box(page)
    return box["x"] + float(col[0]) * box["width"] / cam.width, box["y"] + float(row[0]) * box["height"] / cam.height


def pen_stroke(page, points, pressures, tilts=None, pointer="pen", steps=1):
    """Draw through the DevTools protocol: pressed, moved along ``points``, released."""
    import time

    cdp = page.context.new_cdp_session(page)
    tilts = tilts or [(0, 0)] * len(points)
    t0 = time.time()  # events 10 ms apart whatever the load: the sample times (and so the paint) are reproducible

    def event(kind, i, buttons):
        x, y = points[i]
        params = {"type": kind, "x": x, "y": y, "button": "left", "buttons": buttons, "pointerType": pointer,
                  "force": pressures[i], "tiltX": tilts[i][0], "tiltY": tilts[i][1], "clickCount": 1 if buttons else 0,
                  "timestamp": t0 + 0.01 * i}
        if pointer == "mouse":
            for k in ("force", "tiltX", "tiltY"):
                params.pop(k)
        cdp.send("Input.dispatchMouseEvent", params)

    event("mouseMoved", 0, 0)
    event("mousePressed", 0, 1)
    for i in range(1, len(points)):
        event("mouseMoved", i, 1)
    event("mouseReleased", len(points) - 1, 0)
    cdp.detach()
    page.evaluate("window.studio.sync()")


def touch_stroke(page, points):
    cdp = page.context.new_cdp_session(page)
    cdp.send("Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": [{"x": points[0][0], "y": points[0][1]}]})
    for x, y in points[1:]:
        cdp.send("Input.dispatchTouchEvent", {"type": "touchMove", "touchPoints": [{"x": x, "y": y}]})
    cdp.send("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})
    cdp.detach()
    page.evaluate("window.studio.sync()")
