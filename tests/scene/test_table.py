from pathlib import Path

import numpy as np
import pytest

from unmesh.errors import SceneError
from unmesh.scene import load_scene, parse_override


def write(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


SCENE = """
gravity = [0, -9.81, 0]
[simulation]
dt = 0.001
duration = 2
fps = 30
seed = 4
integrator = "verlet"
surface = true
[materials.water]
density = 1000
[materials.jelly]
density = 1100
young = 1e5
[[objects]]
material = "water"
velocity = [1, 0, 0]
[[objects]]
material = "jelly"
points = [[0, 0, 0], [1, 0, 0]]
"""


def test_reads_every_kind_of_value(tmp_path):
    root = load_scene(write(tmp_path, SCENE))
    sim = root.table("simulation")
    assert sim.number("dt", positive=True) == 0.001
    assert sim.number("duration") == 2.0 and isinstance(sim.number("fps"), float)
    assert sim.integer("seed", minimum=0) == 4
    assert sim.string("integrator", choices=("verlet", "euler")) == "verlet"
    assert sim.boolean("surface") is True
    assert sim.number("cfl", default=0.4) == 0.4
    np.testing.assert_array_equal(root.vector("gravity", 3), [0, -9.81, 0])
    mats = root.tables("materials")
    assert list(mats) == ["water", "jelly"]
    assert mats["jelly"].number("young", positive=True) == 1e5
    for m in mats.values():
        m.number("density", positive=True)
    objs = root.array("objects")
    assert [o.string("material") for o in objs] == ["water", "jelly"]
    np.testing.assert_array_equal(objs[0].vector("velocity", 3), [1, 0, 0])
    assert objs[1].array_of_numbers("points", shape=(None, 3)).shape == (2, 3)
    root.finish()


@pytest.mark.parametrize(
    "text, read, message",
    [
        ("[simulation]\ndt = -1\n", lambda r: r.table("simulation").number("dt", positive=True),
         "scene.toml: key 'simulation.dt': expected a positive number, got -1"),
        ("[simulation]\ndt = 'fast'\n", lambda r: r.table("simulation").number("dt"),
         "key 'simulation.dt': expected a number, got 'fast'"),
        ("[simulation]\n", lambda r: r.table("simulation").number("dt"), "key 'simulation.dt': missing (required)"),
        ("x = true\n", lambda r: r.number("x"), "expected a number, got True"),
        ("g = [0, 1]\n", lambda r: r.vector("g", 3), "key 'g': expected an array of 3 numbers"),
        ("m = 'eulr'\n", lambda r: r.string("m", choices=("euler", "verlet")), "(did you mean 'euler'?)"),
        ("n = 2.5\n", lambda r: r.integer("n"), "key 'n': expected an integer, got 2.5"),
        ("f = 'missing.obj'\n", lambda r: r.path("f"), "key 'f': file not found"),
        ("[[objects]]\nvelocity = 3\n", lambda r: r.array("objects")[0].vector("velocity", 3),
         "key 'objects[0].velocity'"),
        ("objects = 3\n", lambda r: r.array("objects"), "expected an array of tables"),
    ],
)
def test_errors_name_file_and_key(tmp_path, text, read, message):
    root = load_scene(write(tmp_path, text))
    with pytest.raises(SceneError) as info:
        read(root)
    assert message in str(info.value)


def test_unknown_keys_are_reported_with_suggestion(tmp_path):
    root = load_scene(write(tmp_path, "[[objects]]\nvelocty = [1, 0, 0]\n"))
    obj = root.array("objects")[0]
    obj.vector("velocity", 3, default=(0, 0, 0))
    with pytest.raises(SceneError, match=r"unknown key 'objects\[0\].velocty' \(did you mean 'velocity'\?\)"):
        root.finish()


def test_syntax_error_and_missing_file(tmp_path):
    with pytest.raises(SceneError, match=r"scene.toml: invalid TOML: .*line 2"):
        load_scene(write(tmp_path, "a = 1\nb = = 2\n"))
    with pytest.raises(SceneError, match="scene file not found"):
        load_scene(tmp_path / "nope.toml")


def test_paths_are_relative_to_scene_file(tmp_path):
    sub = tmp_path / "scenes"
    sub.mkdir()
    (sub / "mesh.obj").write_text("v 0 0 0\n")
    root = load_scene(write(sub, "mesh = 'mesh.obj'\n"))
    assert root.path("mesh") == (sub / "mesh.obj").resolve()


def test_overrides(tmp_path):
    root = load_scene(write(tmp_path, SCENE), overrides={"simulation.dt": 0.5, "objects[1].material": "water",
                                                        "new.table.value": 3})
    assert root.table("simulation").number("dt") == 0.5
    assert root.array("objects")[1].string("material") == "water"
    assert root.table("new").table("table").integer("value") == 3
    with pytest.raises(SceneError, match="no element 5"):
        load_scene(write(tmp_path, SCENE), overrides={"objects[5].x": 1})
    assert parse_override("a.b=[1, 2]") == ("a.b", [1, 2])
    assert parse_override("mode=euler") == ("mode", "euler")
    with pytest.raises(SceneError, match="KEY=VALUE"):
        parse_override("novalue")
