"""Painting in a real headless Chromium: pen, mouse and touch strokes, the palette, the pen module.

One studio (coarse blob) and one browser serve the whole module; the tests run in file order
and each starts from the state the previous one left.
"""

from __future__ import annotations

import numpy as np
import pytest

from .conftest import (
    canvas_pixels,
    cloud_state,
    covered_segment,
    image_to_page,
    open_page,
    pen_stroke,
    touch_stroke,
)

RED = np.array([0.8, 0.1, 0.1])


@pytest.fixture(scope="module")
def page(browser, studio):
    p = open_page(browser, studio, has_touch=True)
    yield p
    p.context.close()


def _new_paint(before, after, color, tol=0.3):
    """Surfels of ``after`` close to ``color`` that are not in ``before`` at all (new or repainted)."""
    pos, col = after
    near = np.linalg.norm(col - color, axis=1) < tol
    old = {tuple(p) for p, c in zip(*before, strict=True) if np.linalg.norm(c - color) < tol}
    return np.array([p for p, n in zip(pos, near, strict=True) if n and tuple(p) not in old]).reshape(-1, 3)


def _red_pixels(img):
    img = img.astype(int)
    return (img[..., 0] > 140) & (img[..., 1] < 90) & (img[..., 2] < 90)


def test_pen_stroke_with_rising_pressure(page, studio):
    page.evaluate("window.studio.setColor([0.8, 0.1, 0.1])")
    row, x0, x1 = covered_segment(studio)
    n = 40
    pts = [image_to_page(page, studio, x0 + (x1 - x0) * i / (n - 1), row) for i in range(n)]
    pressures = [0.12 + 0.85 * i / (n - 1) for i in range(n)]
    before, shot_before = cloud_state(studio), canvas_pixels(page)
    forces = page.evaluate("window.studio.stats.forces")
    pen_stroke(page, pts, pressures, tilts=[(8, -4)] * n)
    after, shot_after = cloud_state(studio), canvas_pixels(page)
    # server state: new red surfels, all along the stroke and only near it
    painted = _new_paint(before, after, RED)
    assert len(painted) > 20
    cam = studio.run_in_worker(lambda ws: ws.camera())
    r, c, _ = cam.project(painted)
    size_px = 0.05 * studio.run_in_worker(lambda ws: ws.px_per_unit())
    assert np.all(np.abs(r - row) < 4 * size_px)
    assert np.all((c > x0 - 4 * size_px) & (c < x1 + 4 * size_px))
    u = (c - x0) / (x1 - x0)
    assert (u > 0.8).any() and (u < 0.5).any()
    # wider where the pressure was higher (image rows spanned by the paint, first vs last third)
    lo, hi = r[u < 1 / 3], r[u > 2 / 3]
    assert len(lo) and len(hi)
    width = [np.percentile(v, 95) - np.percentile(v, 5) for v in (lo, hi)]
    assert width[1] > 1.2 * width[0], (width, [np.ptp(r[(u >= a) & (u < a + 0.1)]) for a in np.arange(0, 1, 0.1) if ((u >= a) & (u < a + 0.1)).sum() > 1])
    # the canvas shows it: red pixels appeared along the stroke, in a wider band at the end
    red = _red_pixels(shot_after) & ~_red_pixels(shot_before)
    scale = shot_after.shape[1] / cam.width
    band = red[int((row - 4 * size_px) * scale):int((row + 4 * size_px) * scale)]
    assert band.sum() > 100 and red.sum() < 1.3 * band.sum()
    cols = band.sum(axis=0)
    xa, xb = int(x0 * scale), int(x1 * scale)
    third = (xb - xa) // 3
    assert cols[xb - third:xb].mean() > 1.2 * cols[xa:xa + third].mean()
    assert page.evaluate("window.studio.stats.errors.length") == 0
    # the force gauge received the brush's haptic signal while painting
    assert page.evaluate("window.studio.stats.forces") > forces


def test_mouse_stroke_paints_with_slider_pressure(page, studio):
    page.evaluate("window.studio.setColor([0.16, 0.52, 0.8])")
    row, x0, x1 = covered_segment(studio, row_frac=(0.3, 0.45), length_frac=0.4)
    before = cloud_state(studio)
    page.mouse.move(*image_to_page(page, studio, x0, row))
    page.mouse.down()
    for i in range(1, 16):
        page.mouse.move(*image_to_page(page, studio, x0 + (x1 - x0) * i / 15, row))
    page.mouse.up()
    page.evaluate("window.studio.sync()")
    painted = _new_paint(before, cloud_state(studio), np.array([0.16, 0.52, 0.8]))
    assert len(painted) > 10


def test_touch_stroke_paints(page, studio):
    page.evaluate("window.studio.setColor([0.05, 0.5, 0.38])")
    row, x0, x1 = covered_segment(studio, row_frac=(0.55, 0.8), length_frac=0.3)
    before = cloud_state(studio)
    touch_stroke(page, [image_to_page(page, studio, x0 + (x1 - x0) * i / 12, row) for i in range(13)])
    painted = _new_paint(before, cloud_state(studio), np.array([0.05, 0.5, 0.38]))
    assert len(painted) > 10


@pytest.mark.slow
def test_palette_mixing_and_pick(page, studio):
    box = page.locator("#palette").bounding_box()
    yellow = [0.98, 0.86, 0.12]
    page.evaluate(f"window.studio.setColor({yellow})")
    y = box["y"] + box["height"] * 0.5
    pts = [(box["x"] + box["width"] * (0.2 + 0.5 * i / 20), y) for i in range(21)]
    before = studio.run_in_worker(lambda ws: ws.palette.session.cloud().colors.copy())
    pen_stroke(page, pts, [0.8] * 21)
    after = studio.run_in_worker(lambda ws: ws.palette.session.cloud().colors)
    assert len(after) > len(before) or not np.array_equal(after[:len(before)], before)
    # Alt+click on the painted band loads the brush with that paint
    page.keyboard.down("Alt")
    page.mouse.click(box["x"] + box["width"] * 0.45, y)
    page.keyboard.up("Alt")
    page.evaluate("window.studio.sync()")
    color = page.evaluate("window.studio.tools.color")
    assert np.linalg.norm(np.array(color) - yellow) < 0.25


def test_pen_module_spacing_pressure_tilt(page):
    res = page.evaluate("""async () => {
        const m = await import('/static/js/pen.js');
        const line = (n) => Array.from({length: n + 1}, (_, i) => ({t: 10 * i / n, x: 100 * i / n, y: 0,
                                                               p: 0.2 + 0.6 * i / n, ax: 0, ay: 0}));
        const run = (pts) => { const r = new m.Resampler(4); return pts.flatMap((p) => r.push(p)); };
        return {slow: run(line(200)), fast: run(line(3)),
                mouse: m.pressureOf({pointerType: 'mouse', pressure: 0.9}, 0.3),
                nopressure: m.pressureOf({pointerType: 'pen', pressure: 0.5}, 0.3),
                pen: m.pressureOf({pointerType: 'pen', pressure: 0.73}, 0.3),
                tilt: m.tiltOf({pointerType: 'pen', tiltX: 20, tiltY: -10}),
                alt: m.tiltOf({pointerType: 'pen', altitudeAngle: Math.PI / 4, azimuthAngle: 0}),
                mousetilt: m.tiltOf({pointerType: 'mouse', tiltX: 20, tiltY: 5})};
    }""")
    slow, fast = np.array(res["slow"]), np.array(res["fast"])
    # dab spacing by distance: the same samples whether the pointer reported 4 or 201 points
    assert len(slow) == len(fast) == 26
    assert np.allclose(slow, fast, atol=0.02)
    assert np.allclose(np.diff(slow[:, 1]), 4.0, atol=0.02)
    assert res["mouse"] == 0.3 and res["nopressure"] == 0.3 and res["pen"] == 0.73
    assert res["tilt"] == [-10, 20] and res["mousetilt"] == [0, 0]
    assert res["alt"][0] == pytest.approx(0, abs=1e-9) and res["alt"][1] == pytest.approx(45)
