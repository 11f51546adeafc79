"""The workspace without a server: background drying between strokes is recorded and replays."""

from __future__ import annotations

import time

import numpy as np

from unmesh.paint.session import PaintOptions, Session
from unmesh.paint.studio.workspace import Workspace
from unmesh.shapes import by_name


def _session():
    return Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))


def test_tick_advances_between_strokes_and_replays(tmp_path):
    ws = Workspace(_session(), tmp_path / "p.ply", advance_every=0.01)
    ws.handle({"type": "hello", "width": 120, "height": 90, "view": {"yaw": 0, "pitch": 0, "zoom": 1, "pan": [0, 0]}})
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
