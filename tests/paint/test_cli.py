"""``unmesh paint MODEL --replay``: deterministic output, one-line errors."""

import json

import pytest

from unmesh.cli import main
from unmesh.io import load_surfels
from unmesh.paint import PaintOptions, Session


def _strokes(path):
    data = {"version": 1, "strokes": [{"brush": {"type": "round", "size": 0.05},
                                       "paint": {"type": "oil", "color": [0.8, 0.1, 0.1]},
                                       "samples": [{"t": 0.05 * i, "point": [-0.2 + 0.05 * i, 0.0, 0.0],
                                                    "pressure": 0.7, "tilt": [0, 0]} for i in range(5)],
                                       "advance": [0.5]}]}
    path.write_text(json.dumps(data))
    return path


def test_replay_twice_gives_the_same_ply(tmp_path, monkeypatch, plane_cloud):
    from unmesh.io import save

    model = tmp_path / "canvas.ply"
    save(model, plane_cloud)
    s = _strokes(tmp_path / "s.json")
    monkeypatch.chdir(tmp_path)
    assert main(["paint", str(model), "--replay", str(s), "--render", "a.png", "--size", "64x48"]) == 0
    first = (tmp_path / "canvas_painted.ply").read_bytes()
    assert main(["paint", str(model), "--replay", str(s), "-o", "b.ply"]) == 0
    assert (tmp_path / "b.ply").read_bytes() == first
    assert (tmp_path / "a.png").exists()
    # the painted PLY continues the session: its stroke record is the file's
    loaded = Session.load(tmp_path / "b.ply", PaintOptions(haptics=False))
    assert loaded.strokes_json()["strokes"][0]["advance"] == [0.5]
    assert len(load_surfels(tmp_path / "b.ply")) > len(plane_cloud)


@pytest.mark.parametrize("content, msg", [
    ("", "empty"),
    ("[1, 2", "not valid JSON"),
    ('{"version": 1, "strokes": [{"paint": {"type": "tempera"}, "samples": [{"point": [0,0,0]}]}]}',
     "strokes[0].paint.type"),
    ('{"version": 1, "strokes": [{"samples": [{"point": [0, 0, 0]}, {"point": [0, 9, 0]}]}]}',
     "strokes[0].samples[1].point: misses the model"),
])
def test_bad_stroke_files(tmp_path, capsys, plane_cloud, content, msg):
    from unmesh.io import save

    model = tmp_path / "canvas.ply"
    save(model, plane_cloud)
    s = tmp_path / "s.json"
    s.write_text(content)
    assert main(["paint", str(model), "--replay", str(s), "-o", str(tmp_path / "o.ply")]) == 1
    err = capsys.readouterr().err.strip()
    assert msg in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o.ply").exists()


def test_unknown_model(capsys):
    assert main(["paint", "no_such_model_xyz", "--replay", "x.json"]) == 1
    assert "no such file or built-in shape" in capsys.readouterr().err
