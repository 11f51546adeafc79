"""The studio's resampling of pen samples at the engine's dab spacing (DabResampler): against a
brute-force arc-length parametrisation, independent of how the points are split into messages
and frames, recorded as painted (replay gives the same model), and painting what the engine's
own subdivision of the raw samples paints, within the dab spacing."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.paint.session import DAB_STEP, PaintOptions, Session, _subdivide
from unmesh.paint.strokes import Brush, Paint, Sample
from unmesh.paint.studio.resample import DabResampler
from unmesh.paint.studio.workspace import Workspace
from unmesh.shapes import by_name


def _polyline(rng, n=40):
    t = np.cumsum(rng.uniform(0.0, 0.02, n))
    p = np.cumsum(rng.normal(0.0, 0.03, (n, 3)), axis=0)
    p[5] = p[4]  # a repeated point (the pen stood still)
    return [(float(t[i]), tuple(map(float, p[i])), float(rng.uniform()), (float(rng.uniform(-30, 30)), 0.0))
            for i in range(n)]


def _run(points, spacing, cuts):
    r = DabResampler(spacing, max_gap=10.0)  # (no jumps here: test_jumps_... below)
    out, start = [], 0
    for c in [*cuts, len(points)]:
        for p in points[start:c]:
            out += r.push(p)
        start = c
    return out + r.finish()


def test_resampled_points_follow_the_polyline_at_the_spacing_whatever_the_split():
    rng = np.random.default_rng(7)
    pts = _polyline(rng)
    spacing = 0.021
    got = _run(pts, spacing, [])
    for cuts in ([1], [3, 4, 17], list(range(1, 40, 2))):
        assert _run(pts, spacing, cuts) == got  # bit for bit
    # brute force: arc length of every input point, every quantity interpolated at k * spacing
    xyz = np.array([p[1] for p in pts])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xyz, axis=0), axis=1))])
    s = np.arange(int(np.floor(arc[-1] / spacing)) + 1) * spacing
    # every quantity interpolated within the segment holding arc length s (a repeated point:
    # the segment after it starts from its later sample, where the pen stood still until then)
    vals = np.array([[p[0], *p[1], p[2], p[3][0]] for p in pts])
    i = np.maximum(np.searchsorted(arc, s, side="left"), 1)
    f = (s - arc[i - 1]) / (arc[i] - arc[i - 1])
    ref = vals[i - 1] + f[:, None] * (vals[i] - vals[i - 1])
    assert len(got) == len(s) + 1 and got[-1] == pts[-1]  # ... and the stroke's last point
    body = got[:-1]
    np.testing.assert_allclose([[g[0], *g[1], g[2], g[3][0]] for g in body], ref, atol=1e-9)
    gap = np.linalg.norm(np.diff(np.array([g[1] for g in got]), axis=0), axis=1)
    assert gap.max() <= spacing * (1 + 1e-12)  # chords never longer than the arc between them


def test_resampler_refuses_a_bad_spacing_and_starts_over_after_finish():
    for bad in (0.0, -1.0, float("nan"), True, "1"):
        with pytest.raises(InputError, match="spacing"):
            DabResampler(bad)
    r = DabResampler(1.0)
    a = (0.0, (0.0, 0.0, 0.0), 0.5, (0.0, 0.0))
    assert r.push(a) == [a] and r.finish() == []  # a single point: emitted at once, no tail
    assert r.push(a) == [a]  # a new polyline


def _studio_stroke(tmp_path, name, split, budget=None):
    session = Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))
    ws = Workspace(session, tmp_path / f"{name}.ply", advance_every=None)
    ws.handle({"type": "hello", "width": 120, "height": 90, "view": {"yaw": 0, "pitch": 60, "zoom": 1, "pan": [0, 0]}})
    ws.frames()
    ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.08},
               "paint": {"type": "oil", "color": [0.8, 0.1, 0.1], "drying": 0.1}})
    rows = [[10 * i, 30 + 3 * i + 0.5 * (i % 3), 45 + 0.7 * i, 0.4 + 0.03 * i, 0, 0] for i in range(18)]
    ws.handle({"type": "samples", "samples": rows[:1], "ts": 1.0})
    ws.frames()  # the first sample (and the cost of one)
    if budget is not None:
        ws.paint_budget = budget * ws._sample_cost
    start = 1
    for c in [*split, len(rows)]:  # the messages that queued while the engine painted the first
        ws.handle({"type": "samples", "samples": rows[start:c], "ts": float(c)})
        start = c
    while ws.backlog:
        ws.frames()
    picks = [ws.session.pick(ws.camera(), r[1], r[2]) for r in rows]
    ws.handle({"type": "end"})
    ws.frames()
    return ws, picks


def test_studio_stroke_does_not_depend_on_batching_and_replays_to_the_same_model(tmp_path):
    ws, _ = _studio_stroke(tmp_path, "one", [])
    data = ws.session.strokes_json()
    samples = [Sample(s["t"], s["point"], s["pressure"], s["tilt"]) for s in data["strokes"][0]["samples"]]
    # the engine paints exactly the recorded samples: no event added between them
    assert len(_subdivide(None, samples, DAB_STEP * 0.08)) == len(samples)
    a = ws.session.cloud()
    again = Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))
    again.replay(data)
    b = again.cloud()
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.colors, b.colors)
    for name, split, budget in (("msgs", [2, 7, 8, 11], None), ("budget", [4, 9], 1.5)):
        other, _ = _studio_stroke(tmp_path, name, split, budget)
        c = other.session.cloud()
        t0 = other.session.strokes_json()["strokes"][0]["samples"][0]["t"]
        u0 = data["strokes"][0]["samples"][0]["t"]
        rel = [(round(s["t"] - t0, 9), s["point"], s["pressure"]) for s in other.session.strokes_json()["strokes"][0]["samples"]]
        assert rel == [(round(s["t"] - u0, 9), s["point"], s["pressure"]) for s in data["strokes"][0]["samples"]]
        assert len(c) == len(a)  # (the sessions' clocks start at different times: equal to rounding)
        np.testing.assert_allclose(c.positions, a.positions, atol=1e-12)
        np.testing.assert_allclose(c.colors, a.colors, atol=1e-12)
        other.shutdown()
    ws.shutdown()
    again.close()


def test_resampled_stroke_paints_what_the_raw_samples_paint_within_the_dab_spacing(tmp_path):
    """The engine painting the raw ray-cast samples (subdivided by the engine where they are more
    than a dab step apart: more events) and the studio's resampled samples paint
    a stroke of the same length, area and colour, seen from above. (The bristles' imprint differs:
    the brush is simulated per event, so it depends on the events' spacing as on the page's.)"""
    from unmesh.render import Camera

    ws, picks = _studio_stroke(tmp_path, "resampled", [])
    rec = ws.session.strokes_json()["strokes"][0]["samples"]
    raw = [Sample(rec[0]["t"] + 0.01 * i, tuple(p), 0.4 + 0.03 * i) for i, p in enumerate(picks)]
    assert len(_subdivide(None, raw, DAB_STEP * 0.08)) > len(rec)
    sessions = [Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False)) for _ in range(2)]
    sessions[0].stroke(raw, Brush("round", 0.08), Paint("oil", (0.8, 0.1, 0.1), drying=0.1))
    cam = Camera((0, 2.0, 0), (0, 0, 0), up=(0, 0, -1), width=400, height=400)  # the plane from above
    a, b, clean = (s.render(cam, brush=False).color for s in (ws.session, *sessions))
    ma, mb = (np.abs(img - clean).max(axis=-1) > 0.05 for img in (a, b))
    assert abs(int(ma.sum()) - int(mb.sum())) < 0.05 * mb.sum()  # painted area
    np.testing.assert_allclose(a[ma].mean(axis=0), b[mb].mean(axis=0), atol=0.03)  # mean colour
    cols_a, cols_b = np.flatnonzero(ma.any(axis=0)), np.flatnonzero(mb.any(axis=0))
    assert abs(cols_a[0] - cols_b[0]) <= 2 and abs(cols_a[-1] - cols_b[-1]) <= 2  # the stroke's ends
    ws.shutdown()
    for s in sessions:
        s.close()


def test_jumps_are_not_resampled_and_a_miss_restarts_the_polyline(tmp_path):
    """A segment longer than max_gap gives its two ends (the engine paints across it as before),
    never resampled points in the air; in the studio a stroke off the model and back paints
    without error, the samples on either side resampled separately."""
    r = DabResampler(1.0, max_gap=3.0)
    p = [(0.0, (0.0, 0.0, 0.0), 0.5, (0.0, 0.0)), (1.0, (2.5, 0.0, 0.0), 0.5, (0.0, 0.0)),
         (2.0, (9.0, 0.0, 0.0), 0.5, (0.0, 0.0)), (3.0, (10.5, 0.0, 0.0), 0.5, (0.0, 0.0))]
    out = [q[1][0] for q in r.push(p[0]) + r.push(p[1]) + r.push(p[2]) + r.push(p[3]) + r.finish()]
    assert out == [0.0, 1.0, 2.0, 2.5, 9.0, 10.0, 10.5]
    assert DabResampler(0.5).max_gap == 2.0
    with pytest.raises(InputError, match="max_gap"):
        DabResampler(1.0, max_gap=0.0)

    session = Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))
    ws = Workspace(session, tmp_path / "gap.ply", advance_every=None)
    ws.handle({"type": "hello", "width": 120, "height": 90, "view": {"yaw": 0, "pitch": 60, "zoom": 1, "pan": [0, 0]}})
    ws.frames()
    cam = ws.camera()
    xs = [34 + 2.5 * i for i in range(21)]
    hits = [session.pick(cam, x, 45) is not None for x in xs]
    ys = [45 if i < 8 or i > 12 else 5 for i in range(21)]  # rows 8-12 off the model (above it)
    assert all(hits) and not any(session.pick(cam, xs[i], 5) is not None for i in range(8, 13))
    before, after = session.pick(cam, xs[7], 45), session.pick(cam, xs[13], 45)  # (ray cast before painting)
    ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.08}, "paint": {"type": "oil", "color": [0.8, 0.1, 0.1]}})
    ws.handle({"type": "samples", "samples": [[10 * i, xs[i], ys[i], 0.7, 0, 0] for i in range(21)], "ts": 1.0})
    assert ws.frames() and ws.handle({"type": "end"})[0]["painted"]
    pts = np.array([s["point"] for s in ws.session.strokes_json()["strokes"][0]["samples"]])
    k = int(np.flatnonzero(np.linalg.norm(pts - before, axis=1) < 1e-12)[0])
    assert np.allclose(pts[k + 1], after, atol=1e-12)  # the gap's two ends follow each other
    ws.shutdown()
