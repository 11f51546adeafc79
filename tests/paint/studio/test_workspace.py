"""The workspace without a server: background drying between strokes is recorded and replays."""

from __future__ import annotations

import time

import numpy as np

from unmesh.paint.session import PaintOptions, Session
from unmesh.paint.studio.workspace import Workspace
from unmesh.shapes import by_name


def _session():
    # a plane seen from above (pitch 60): seen edge on (pitch 0) its surfels would all be back-face culled
    return Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))


def test_tick_advances_between_strokes_and_replays(tmp_path):
    ws = Workspace(_session(), tmp_path / "p.ply", advance_every=0.01)
    ws.handle({"type": "hello", "width": 120, "height": 90, "view": {"yaw": 0, "pitch": 60, "zoom": 1, "pan": [0, 0]}})
    ws.frames()
    assert not ws.tick() or ws.strokes == 0  # nothing painted: nothing to dry
    ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.08},
               "paint": {"type": "watercolor", "color": [0.1, 0.3, 0.9], "drying": 0.5}})
    ws.handle({"type": "samples", "samples": [[0, 50 + 2 * i, 45, 0.8, 0, 0] for i in range(8)]})
    assert ws.tick() is False  # never during a stroke
    ws.handle({"type": "end"})
    frames = ws.frames()
    assert frames and ws.strokes == 1
    time.sleep(0.02)
    assert ws.tick() is True
    data = ws.session.strokes_json()
    assert data["strokes"][-1].get("advance")
    again = _session()
    again.replay(data)
    a, b = ws.session.cloud(), again.cloud()
    assert np.array_equal(a.positions, b.positions) and np.allclose(a.colors, b.colors, atol=1e-12)
    assert ws.shutdown() == tmp_path / "p.ply" and (tmp_path / "p_strokes.json").is_file()


def _stroke_rows(n=12):
    return [[10 * i, 40 + 3 * i, 45, 0.5 + 0.03 * i, 0, 0] for i in range(n)]


def _begin(ws):
    ws.handle({"type": "hello", "width": 120, "height": 90, "view": {"yaw": 0, "pitch": 60, "zoom": 1, "pan": [0, 0]}})
    ws.frames()
    ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.08},
               "paint": {"type": "oil", "color": [0.8, 0.1, 0.1], "drying": 0.1}})


def _arc_samples(ws, rows):
    """How many samples the studio's resampling gives the engine for ``rows`` before the stroke
    ends: the first point, then one per dab spacing of arc length along the ray-cast polyline."""
    cam = ws.camera()
    pts = np.array([ws.session.pick(cam, r[1], r[2]) for r in rows])
    spacing = ws._stroke["resampler"].spacing
    return 1 + int(np.floor(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() / spacing))


def test_queued_samples_are_painted_in_one_engine_call_with_the_same_samples(tmp_path):
    """Three ``samples`` messages handled before a frame cost one ``add_samples``, which gets the
    same samples as from a single message with all the rows (times relative to the stroke's start):
    the ray-cast points resampled at the engine's dab spacing (test_resample.py)."""
    rows = _stroke_rows()
    got = []
    for split in ([rows], [rows[:3], rows[3:7], rows[7:]]):
        ws = Workspace(_session(), tmp_path / f"p{len(split)}.ply", advance_every=None)
        calls = []
        add = ws.session.add_samples
        ws.session.add_samples = lambda sid, samples, add=add, calls=calls: calls.append(list(samples)) or add(sid, samples)
        _begin(ws)
        for part in split:
            ws.handle({"type": "samples", "samples": part, "ts": 1.0})
        assert calls == []  # checked, not painted yet
        expected = _arc_samples(ws, rows)  # (ray cast before painting, as the frame does)
        frames = ws.frames(queue_ms=1.0, received_at=2.0)
        assert len(calls) == 1 and len(calls[0]) == expected and frames
        t0 = calls[0][0].t
        got.append([(round(s.t - t0, 9), s.point, s.pressure, s.tilt) for s in calls[0]])
        ws.handle({"type": "end"})
        assert ws.strokes == 1
        ws.shutdown()
    assert got[0] == got[1]


def test_malformed_samples_are_refused_when_they_arrive(tmp_path):
    import pytest

    from unmesh.errors import InputError

    ws = Workspace(_session(), tmp_path / "p.ply", advance_every=None)
    _begin(ws)
    with pytest.raises(InputError, match=r"samples\[1\].pressure"):
        ws.handle({"type": "samples", "samples": [[0, 40, 45, 0.5, 0, 0], [1, 41, 45, 2.0, 0, 0]]})
    ws.handle({"type": "end"})
    assert ws.strokes == 0  # nothing of the refused message was painted
    ws.shutdown()


def test_preview_resolution_follows_the_render_time(tmp_path):
    from unmesh.paint.studio.workspace import PREVIEW_FAST, PREVIEW_SCALES, PREVIEW_SLOW

    ws = Workspace(_session(), tmp_path / "p.ply", advance_every=None)
    seen = [ws.preview_scale]
    for t in (2 * PREVIEW_SLOW, 2 * PREVIEW_SLOW, 2 * PREVIEW_SLOW, PREVIEW_FAST / 2, PREVIEW_FAST / 2,
              PREVIEW_FAST / 2, (PREVIEW_FAST + PREVIEW_SLOW) / 2):
        ws._adapt_preview(t)
        seen.append(ws.preview_scale)
    assert seen == [2, 3, 4, 4, 3, 2, 2, 2] and PREVIEW_SCALES == (2, 3, 4)
    ws.shutdown()


def test_frames_convert_and_diff_only_the_changed_windows_yet_match_the_engine_image(tmp_path):
    """While painting, each frame converts and compares only the engine's changed windows; the
    image the page is sent stays equal to the engine's image, also when another render (an
    export) came between two frames."""
    from unmesh.paint.studio.frames import to_uint8

    fine = Session(by_name("plane", size=1.0).surfels(0.015), PaintOptions(haptics=False))  # no full updates
    ws = Workspace(fine, tmp_path / "p.ply", advance_every=None)
    ws.handle({"type": "hello", "width": 120, "height": 90, "view": {"yaw": 0, "pitch": 60, "zoom": 1, "pan": [0, 0]}})
    ws.frames()
    ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.03}, "paint": {"type": "oil", "color": [0.8, 0.1, 0.1]}})
    converted = []
    orig = ws._model_image
    ws._model_image = lambda color, windows: converted.append(windows) or orig(color, windows)
    for k in range(4):
        ws.handle({"type": "samples", "samples": [[10 * k, 50 + 3 * k, 45, 0.6, 0, 0]], "ts": float(k)})
        if k == 2:
            ws.handle({"type": "export", "name": "mid.png"})  # a render the frames did not see
        ws.frames()
        shown = ws.encoder._last["model"]
        np.testing.assert_array_equal(shown, to_uint8(ws.session.render(ws.camera()).color))
        ws._model_serial = (id(ws.session), ws.session.render_serial)  # the check's render is not a frame
    assert converted[0] is not None and converted[1] is not None  # windows while painting ...
    assert converted[2] is None  # ... but the whole image after a render between frames
    ws.handle({"type": "end"})
    ws.shutdown()


def test_a_frame_paints_within_its_budget_and_the_rest_follows_in_the_next_frames(tmp_path):
    """With a paint budget of about one sample, queued samples are painted one per frame (a frame
    each, time stamps of the painted samples, the message's once all its samples are painted),
    and the model ends equal to painting them all in one call."""
    from unmesh.paint.studio.frames import decode

    rows = _stroke_rows(6)
    clouds = []
    for budget in (None, "one"):
        ws = Workspace(_session(), tmp_path / f"b{budget}.ply", advance_every=None)
        _begin(ws)
        calls = []
        add = ws.session.add_samples
        ws.session.add_samples = lambda sid, samples, add=add, calls=calls: calls.append(len(samples)) or add(sid, samples)
        ws.handle({"type": "samples", "samples": rows[:1], "ts": 0.5})
        ws.frames()  # measures the cost of one sample
        n = _arc_samples(ws, rows)  # samples the engine gets before the stroke ends (resampled)
        ws.handle({"type": "samples", "samples": rows[1:3], "ts": 25.0})
        ws.handle({"type": "samples", "samples": rows[3:], "ts": 55.0})
        if budget is None:
            ws.paint_budget = None
            heads = [decode(f)[0] for f in ws.frames() if decode(f)[0]["target"] == "model"]
            assert calls == [1, n - 1] and ws.backlog == 0 and heads[-1]["ts"] == 55.0
        else:
            ws.paint_budget = 1.5 * ws._sample_cost  # about one sample a frame
            stamps = []
            while ws.backlog:
                heads = [decode(f)[0] for f in ws.frames() if decode(f)[0]["target"] == "model"]
                stamps.append(heads[-1]["ts"] if heads else None)
            assert calls[0] == 1 and sum(calls) == n and len(calls) >= 3 and max(calls[1:]) <= 2
            assert stamps[-1] == 55.0 and stamps == sorted(stamps)
            assert set(stamps) <= {25.0, 55.0, *(float(r[0]) for r in rows)}
        ws.handle({"type": "end"})
        clouds.append(ws.session.cloud())
        ws.shutdown()
    a, b = clouds  # (the two sessions' clocks start at different times: equal to rounding)
    assert len(a) == len(b)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-12)
    np.testing.assert_allclose(a.colors, b.colors, atol=1e-12)


def test_autosave_writes_the_model_as_it_was_while_painting_goes_on(tmp_path):
    """An autosave copies the model at the stroke's end and writes it on its own thread: the next
    stroke paints meanwhile, the file reloads to the model of that moment, and the ``autosaved``
    reply comes with the next ``sync`` (which waits for the write)."""
    ws = Workspace(_session(), tmp_path / "p.ply", autosave_every=1, advance_every=None)
    _begin(ws)
    ws.handle({"type": "samples", "samples": _stroke_rows(6), "ts": 1.0})
    assert [r["type"] for r in ws.handle({"type": "end"})] == ["ended"]
    first = ws.session.cloud()
    first = (first.positions.copy(), first.colors.copy())
    ws.handle({"type": "begin", "brush": {"type": "round", "size": 0.08},
               "paint": {"type": "oil", "color": [0.1, 0.7, 0.1], "drying": 0.1}})
    ws.handle({"type": "samples", "samples": [[10 * i, 40 + 3 * i, 60, 0.9, 0, 0] for i in range(6)], "ts": 2.0})
    ws.frames()  # the second stroke painted (perhaps before the autosave was written)
    assert [r["type"] for r in ws.handle({"type": "sync", "id": 1})] == ["autosaved", "synced"]
    assert ws.notices() == []
    saved = Session.load(tmp_path / "p.autosave.ply", PaintOptions(haptics=False))
    np.testing.assert_array_equal(saved.cloud().positions, first[0])
    np.testing.assert_array_equal(saved.cloud().colors, first[1])
    assert len(saved.strokes_json()["strokes"]) == 1
    ws.handle({"type": "end"})
    assert [r["type"] for r in ws.handle({"type": "sync", "id": 2})] == ["autosaved", "synced"]
    assert len(Session.load(tmp_path / "p.autosave.ply").strokes_json()["strokes"]) == 2
    saved.close()
    ws.shutdown()
