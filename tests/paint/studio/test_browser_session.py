"""A studio session in a real headless Chromium: view, undo, save, replay, cross-origin pages.

Rotate the view and paint again; undo restores the previous state exactly and redo the next;
the saved PLY reloads equal; replaying the recorded strokes headless (``unmesh paint --replay``)
gives the same model. A page of another origin cannot open the session's WebSocket or upload.
"""

from __future__ import annotations

import functools
import http.server
import threading

import numpy as np
import pytest

from .conftest import SPACING, cloud_state, covered_segment, image_to_page, open_page, pen_stroke


@pytest.fixture(scope="module")
def page(browser, studio):
    p = open_page(browser, studio)
    yield p
    p.context.close()


def _stroke(page, studio, color, pressure=0.7, row_frac=(0.45, 0.75)):
    page.evaluate(f"window.studio.setColor({list(color)})")
    row, x0, x1 = covered_segment(studio, row_frac=row_frac, length_frac=0.5)
    pts = [image_to_page(page, studio, x0 + (x1 - x0) * i / 15, row) for i in range(16)]
    pen_stroke(page, pts, [pressure] * 16)


def _equal(a, b):
    return a[0].shape == b[0].shape and np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_rotate_paint_undo_save_replay(page, studio, tmp_path):
    _stroke(page, studio, (0.8, 0.1, 0.1))
    # rotate with a right drag: the server's view follows, previews while dragging, full on release
    yaw0 = studio.run_in_worker(lambda ws: ws.view.yaw)
    box = page.locator("#overlay").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.down(button="right")
    for i in range(1, 9):
        page.mouse.move(cx - 12 * i, cy)
    page.mouse.up(button="right")
    page.evaluate("window.studio.sync()")
    yaw1 = studio.run_in_worker(lambda ws: ws.view.yaw)
    assert yaw1 == pytest.approx(yaw0 + 0.4 * 96, abs=1e-6)
    s1 = cloud_state(studio)
    _stroke(page, studio, (0.14, 0.18, 0.62), row_frac=(0.35, 0.6))
    s2 = cloud_state(studio)
    assert not _equal(s1, s2)
    page.click("#undo")
    page.evaluate("window.studio.sync()")
    assert _equal(cloud_state(studio), s1)
    page.click("#redo")
    page.evaluate("window.studio.sync()")
    assert _equal(cloud_state(studio), s2)
    # save and reload
    page.click("#save")
    page.click("#record")
    page.evaluate("window.studio.sync()")
    folder = studio.workspace.folder
    saved = folder / studio.workspace.out_path.name
    record = folder / (saved.stem + "_strokes.json")
    assert saved.is_file() and record.is_file()
    from unmesh.paint.session import Session

    reloaded = Session.load(saved)
    c = reloaded.cloud()
    assert _equal((c.positions, c.colors), s2)
    # export a PNG of the view; load the saved model back into the studio
    page.click("#export")
    page.evaluate("window.studio.sync()")
    from PIL import Image

    cam = studio.run_in_worker(lambda ws: ws.camera())
    with Image.open(folder / (saved.stem + ".png")) as im:
        assert im.size == (cam.width, cam.height)
    page.evaluate(f"window.studio.send({{type: 'load', name: '{saved.name}'}})")
    page.evaluate("window.studio.sync()")
    assert "loaded" in page.evaluate("window.studio.stats.replies")
    assert _equal(cloud_state(studio), s2)
    # replay the recording without a browser: ``unmesh paint blob --replay`` (in this process)
    from unmesh.cli import main

    out = tmp_path / "replayed.ply"
    assert main(["paint", "blob", "--spacing", str(SPACING), "--replay", str(record), "-o", str(out)]) == 0
    r = Session.load(out).cloud()
    assert r.positions.shape == c.positions.shape
    assert np.allclose(r.positions, c.positions, atol=1e-12) and np.allclose(r.colors, c.colors, atol=1e-12)


@pytest.fixture(scope="module")
def other_origin(tmp_path_factory):
    root = tmp_path_factory.mktemp("other")
    (root / "index.html").write_text("<!doctype html><title>other site</title>")
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


_TRY_WS = """async (url) => new Promise((resolve) => {
    const ws = new WebSocket(url);
    ws.onopen = () => { ws.close(); resolve('open'); };
    ws.onclose = (e) => resolve('closed ' + e.code);
})"""


def test_cross_origin_page_is_refused(browser, studio, page, other_origin):
    ws_url = f"ws://127.0.0.1:{studio.port}/ws?token={studio.token}"
    # the studio's own page with the right token connects; with a wrong or no token it does not
    assert page.evaluate(_TRY_WS, ws_url) == "open"
    assert page.evaluate(_TRY_WS, ws_url[:-3] + "abc").startswith("closed")
    assert page.evaluate(_TRY_WS, f"ws://127.0.0.1:{studio.port}/ws").startswith("closed")
    # another site's page knowing the token still cannot
    ctx = browser.new_context()
    evil = ctx.new_page()
    evil.goto(other_origin)
    assert evil.evaluate(_TRY_WS, ws_url).startswith("closed")
    status = evil.evaluate("""async (url) => {
        try { const r = await fetch(url, {method: 'POST', body: '{}'}); return r.status; }
        catch (e) { return 'blocked'; }
    }""", f"http://127.0.0.1:{studio.port}/api/upload?token={studio.token}&name=evil.json")
    assert status in (403, "blocked")
    assert not (studio.workspace.folder / "evil.json").exists()
    ctx.close()
    # and the session keeps working for its own page
    assert page.evaluate("window.studio.sync().then(() => window.studio.connected)")
