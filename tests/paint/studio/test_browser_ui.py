"""The studio's controls in a real headless Chromium: the replay and load buttons with their file
choosers (upload into the output folder, then replay or load), keyboard navigation (the tab order
reaches every control) and the keyboard shortcuts.

One studio (coarse blob, fresh session) and one page serve the module; the tests run in file order.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from .conftest import canvas_pixels, cloud_state, covered_segment, image_to_page, new_session, open_page, pen_stroke

VIRIDIAN = (0.05, 0.5, 0.38)
RED = (0.8, 0.1, 0.1)


@pytest.fixture(scope="module")
def page(browser, studio):
    p = open_page(browser, studio)
    yield p
    p.context.close()


def _painted_session(studio, color, row_frac=(0.45, 0.75)):
    """A fresh session of the studio's model with one stroke across it, painted in process."""
    from unmesh.paint.strokes import Brush, Paint, Sample

    s = new_session()
    cam = studio.run_in_worker(lambda ws: ws.camera())
    row, x0, x1 = covered_segment(studio, row_frac=row_frac)
    pts = [s.pick(cam, x0 + (x1 - x0) * i / 23, row) for i in range(24)]
    samples = [Sample(0.01 * i, tuple(p), 0.8) for i, p in enumerate(pts) if p is not None]
    s.stroke(samples, Brush("round", 0.06), Paint("oil", color))
    return s


def _choose_file(page, button, path):
    with page.expect_file_chooser() as chooser:
        page.click(button)
    chooser.value.set_files(str(path))


def _wait_reply(page, kind):
    page.wait_for_function(f"window.studio.stats.replies.includes('{kind}')", timeout=60000)
    page.evaluate("window.studio.sync()")


def _near(img, color, tol=40):
    return np.linalg.norm(img.astype(float) - 255 * np.asarray(color), axis=2) < tol


def test_replay_button_uploads_and_paints_a_stroke_file(page, studio, tmp_path):
    s = _painted_session(studio, VIRIDIAN)
    data = s.strokes_json()
    strokes = tmp_path / "my design.json"  # outside the output folder; the page uploads it
    strokes.write_text(json.dumps(data))
    before = canvas_pixels(page)
    _choose_file(page, "#replay", strokes)
    _wait_reply(page, "replayed")
    folder = studio.workspace.folder
    assert json.loads((folder / "my_design.json").read_text()) == data  # uploaded under a safe name
    # the server's model is the stroke file replayed on the same model, exactly
    pos, col = cloud_state(studio)
    c = s.cloud()
    assert pos.shape == c.positions.shape
    assert np.allclose(pos, c.positions, atol=1e-12) and np.allclose(col, c.colors, atol=1e-12)
    assert page.locator("#message").inner_text().startswith("replayed 1 strokes from my_design.json")
    assert page.locator("#strokes").inner_text() == "1"
    # and the canvas shows it
    after = canvas_pixels(page)
    assert _near(after, VIRIDIAN).sum() > _near(before, VIRIDIAN).sum() + 200


def test_load_button_uploads_and_opens_a_painted_ply(page, studio, tmp_path):
    from unmesh.paint.session import Session

    s = _painted_session(studio, RED, row_frac=(0.3, 0.5))
    ply = tmp_path / "painted model.ply"
    s.save(ply)
    _choose_file(page, "#load", ply)
    _wait_reply(page, "loaded")
    assert (studio.workspace.folder / "painted_model.ply").is_file()
    want = Session.load(ply).cloud()
    pos, col = cloud_state(studio)
    assert np.array_equal(pos, want.positions) and np.array_equal(col, want.colors)
    assert "loaded painted_model.ply" in page.locator("#message").inner_text()
    assert _near(canvas_pixels(page), RED).sum() > 200


_MARK_CONTROLS = """() => {
    const all = [...document.querySelectorAll('button, input, select, textarea, a[href], [tabindex]')]
        .filter((e) => !e.hidden && e.offsetParent !== null && !e.disabled);
    all.forEach((e, i) => { e.dataset.ctl = String(i); });
    return all.map((e) => e.id || e.dataset.brush || e.dataset.paint || e.dataset.view || e.title || e.tagName);
}"""


def test_tab_order_reaches_every_control(page):
    names = page.evaluate(_MARK_CONTROLS)
    assert len(names) >= 30  # toolbar, view bar, swatches, picker, session buttons
    page.evaluate("document.activeElement && document.activeElement.blur()")
    seen = []
    for _ in range(3 * len(names)):
        page.keyboard.press("Tab")
        idx = page.evaluate("document.activeElement && document.activeElement.dataset.ctl")
        if idx is not None and seen and int(idx) == seen[0]:
            break  # wrapped around
        if idx is not None:
            seen.append(int(idx))
    missing = [names[i] for i in range(len(names)) if i not in seen]
    assert not missing, f"not reachable with Tab: {missing}"
    start = seen.index(min(seen))  # Tab starts after the last focused control: a rotation of the layout order
    assert seen[start:] + seen[:start] == sorted(seen), "tab order follows the page's layout"
    page.keyboard.press("Escape")


def _view(studio):
    return studio.run_in_worker(lambda ws: ws.view)


def test_keyboard_shortcuts(page, studio):
    page.evaluate("document.activeElement && document.activeElement.blur()")
    tools = "window.studio.tools"
    # brushes and sizes
    page.keyboard.press("2")
    assert page.evaluate(f"{tools}.brush") == "flat"
    assert page.locator('[data-brush="flat"]').get_attribute("class").split().count("on") == 1
    page.keyboard.press("3")
    assert page.evaluate(f"{tools}.brush") == "pencil"
    page.keyboard.press("1")
    assert page.evaluate(f"{tools}.brush") == "round"
    size = page.evaluate(f"{tools}.size")
    page.keyboard.press("]")
    bigger = page.evaluate(f"{tools}.size")
    page.keyboard.press("[")
    page.keyboard.press("[")
    assert bigger > size > page.evaluate(f"{tools}.size")
    # view: arrows turn, Shift+arrows by 45 degrees, +/- zoom, Home resets
    page.keyboard.press("Home")
    page.evaluate("window.studio.sync()")
    home = _view(studio)
    page.keyboard.press("ArrowLeft")
    page.keyboard.press("Shift+ArrowUp")
    page.keyboard.press("+")
    page.evaluate("window.studio.sync()")
    v = _view(studio)
    assert v.yaw == pytest.approx(home.yaw - 10) and v.pitch == pytest.approx(home.pitch + 45)
    assert v.zoom == pytest.approx(1.2 * home.zoom)
    page.keyboard.press("-")
    page.keyboard.press("0")
    page.evaluate("window.studio.sync()")
    assert _view(studio) == home
    # a focused slider takes the arrow keys itself
    page.focus("#size")
    size = page.evaluate(f"{tools}.size")
    page.keyboard.press("ArrowRight")
    page.evaluate("window.studio.sync()")
    assert page.evaluate(f"{tools}.size") == pytest.approx(size + 0.005)
    assert _view(studio) == home
    page.evaluate("document.activeElement.blur()")
    # undo, redo, save
    s0 = cloud_state(studio)
    row, x0, x1 = covered_segment(studio, row_frac=(0.55, 0.8))
    pen_stroke(page, [image_to_page(page, studio, x0 + (x1 - x0) * i / 11, row) for i in range(12)], [0.7] * 12)
    s1 = cloud_state(studio)
    assert not np.array_equal(s0[1], s1[1]) or s0[0].shape != s1[0].shape
    for key, want in (("Control+z", s0), ("Control+Shift+Z", s1), ("Control+z", s0), ("Control+y", s1)):
        page.keyboard.press(key)
        page.evaluate("window.studio.sync()")
        got = cloud_state(studio)
        assert got[0].shape == want[0].shape and np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), key
        shown = int(page.locator("#strokes").inner_text())
        assert shown == studio.run_in_worker(lambda ws: ws.strokes), key  # page and server count alike
    out = studio.workspace.out_path
    assert not out.exists()
    page.keyboard.press("Control+s")
    page.evaluate("window.studio.sync()")
    assert out.is_file()


_PREVIEW = """() => {
    const c = document.getElementById('preview');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let n = 0, r = 0, g = 0, b = 0, x0 = 1e9, x1 = -1;
    for (let i = 0; i < d.length; i += 4) {
        if (d[i + 3] > 200) {
            n += 1; r += d[i]; g += d[i + 1]; b += d[i + 2];
            const x = (i / 4) % c.width; x0 = Math.min(x0, x); x1 = Math.max(x1, x);
        }
    }
    return {n, rgb: n ? [r / n, g / n, b / n] : null, x0, x1};
}"""


def test_dab_preview_at_once_then_server_tiles(page, studio):
    """While the engine is busy the page draws the stroke's dabs at once (the preview layer), and
    replaces them by the server's painted tiles; each painted frame reports its latency split."""
    import threading

    page.evaluate("window.studio.setColor([0.14, 0.18, 0.62]); window.studio.stats.stages.length = 0")
    row, x0, x1 = covered_segment(studio, row_frac=(0.4, 0.7))
    pts = [image_to_page(page, studio, x0 + (x1 - x0) * i / 11, row) for i in range(12)]
    release = threading.Event()
    studio.pool.submit(release.wait)  # the worker thread is busy: no frame can come
    try:
        cdp = page.context.new_cdp_session(page)
        for kind, (x, y), buttons in ([("mouseMoved", pts[0], 0), ("mousePressed", pts[0], 1)]
                                      + [("mouseMoved", p, 1) for p in pts[1:]]):
            cdp.send("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left", "buttons": buttons,
                                                  "pointerType": "pen", "force": 0.8, "clickCount": 1 if buttons else 0})
        page.wait_for_timeout(100)  # a few animation frames
        pre = page.evaluate(_PREVIEW)
        cdp.send("Input.dispatchMouseEvent", {"type": "mouseReleased", "x": pts[-1][0], "y": pts[-1][1],
                                              "button": "left", "buttons": 0, "pointerType": "pen"})
        cdp.detach()
    finally:
        release.set()
    assert pre["n"] > 300, pre  # a band of dabs along the stroke ...
    assert np.allclose(pre["rgb"], [0.14 * 255, 0.18 * 255, 0.62 * 255], atol=3), pre  # ... in the brush colour
    # from the first sample to the last, a footprint radius beyond (image pixels = canvas pixels)
    r = 1.6 * page.evaluate("window.studio.tools.size * window.studio.server.px_per_unit")
    assert x0 - r - 2 <= pre["x0"] <= x0 and x1 <= pre["x1"] <= x1 + r + 2, (pre, x0, x1, r)
    page.evaluate("window.studio.sync()")
    assert page.evaluate(_PREVIEW)["n"] == 0  # replaced by the server's frame
    stages = page.evaluate("window.studio.stats.stages")
    assert stages, "painted frames carry the pen event's time stamp"
    s = stages[-1]
    assert {"queue", "paint", "render", "encode"} <= set(s["srv"]) and s["total"] >= s["client"] >= 0
    # the stages are disjoint parts of the time from sending the samples to receiving the frame
    parts = [s["up"], s["srv"]["queue"], s["srv"]["paint"], s["srv"]["render"], s["srv"]["encode"], s["down"]]
    assert min(parts) >= -2 and sum(parts) <= s["wire"] + 3, s
    assert s["srv"]["queue"] >= 50  # the worker was held busy while the pen moved
