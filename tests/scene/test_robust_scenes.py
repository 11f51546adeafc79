"""Issue 24 / 16.6 / 23.16: scene values type- and range-checked, memory budget, one error helper."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import pytest

from unmesh.errors import InputError, SceneError
from unmesh.scene import Table, load_scene, parse_infinite, resolve_scene, shipped_scenes

SPH = """
[simulation]
dimension = 2
spacing = 0.05
dt = 0.0005
duration = 0.1
[materials.water]
stiffness = 500.0
{material}
[[objects]]
material = "water"
shape = {{ type = "{kind}", center = {center}, {params} }}
[[boundaries]]
type = "box"
min = [0, 0, 0]
max = [1, 1, 0]
"""

SHELL = """
[simulation]
dt = 0.001
duration = 0.08
[surface]
shape = {{ type = "plane", size = {size}, normal = [0.0, 1.0, 0.0], center = [0.0, 1.0, 0.0] }}
spacing = 0.05
nodes = 60
[material]
ks = 100.0
kb = 10.0
"""

FEM = """
[simulation]
dt = 0.01
duration = 0.1
[material]
young = 50
[[objects]]
mesh = {{ type = "hex_grid", cells = {cells}, origin = [0, 0.5, 0] }}
"""


def sph_scene(tmp_path, kind="box", center="[0.25, 0.25, 0]", params="size = [0.5, 0.5, 1]", material=""):
    from unmesh.sph.scene import build_simulation

    p = tmp_path / "s.toml"
    p.write_text(SPH.format(kind=kind, center=center, params=params, material=material))
    return build_simulation(load_scene(p))


@pytest.mark.parametrize(("params", "center", "message"), [
    ('size = [0.4, "a", 1]', "[0.25, 0.25, 0]", r"key 'objects\[0\]\.shape\.size': expected an array of numbers"),
    ("size = [0.4, [1, 2], 1]", "[0.25, 0.25, 0]", r"key 'objects\[0\]\.shape\.size': expected a rectangular"),
    ("size = [0.5, 0.5, 1]", "[1e300, 1, 0]", r"key 'objects\[0\]\.shape\.center': expected coordinates of magnitude"),
    ("size = [0.5, 0.5, 1e300]", "[0.25, 0.25, 0]", r"key 'objects\[0\]\.shape\.size': expected finite numbers"),
    ("size = { a = 1 }", "[0.25, 0.25, 0]", r"key 'objects\[0\]\.shape\.size': expected a number, string or array"),
])
def test_shape_parameters_are_type_and_range_checked(tmp_path, params, center, message):
    with pytest.raises(SceneError, match=r"s\.toml: " + message):
        sph_scene(tmp_path, params=params, center=center)


def test_infinite_radius_is_refused(tmp_path):
    with pytest.raises(SceneError, match=r"s\.toml: key 'objects\[0\]\.shape\.radius': expected a finite number"):
        sph_scene(tmp_path, kind="sphere", center="[0.5, 0.5, 0]", params="radius = inf")


def test_sph_sampling_beyond_the_memory_budget_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "1M")
    with pytest.raises(SceneError, match=r"s\.toml: key 'objects\[0\]\.shape': sampling this shape at spacing "
                                         r"0\.05 \(about .* lattice points\) would need about .* more than the "
                                         r"memory budget of 1 MiB .*UNMESH_MEMORY_BUDGET"):
        sph_scene(tmp_path, center="[0, 0, 0]", params="size = [1000, 1000, 1]")


def test_shell_plane_of_1e6_is_refused_with_the_estimate(tmp_path):
    from unmesh.shells.scene import build_simulation

    p = tmp_path / "plane.toml"
    p.write_text(SHELL.format(size="[1e6, 1]"))
    with pytest.raises(SceneError, match=r"plane\.toml: key 'surface\.spacing': sampling the surface at spacing "
                                         r"0\.05 \(about 4e\+08 surfels\) would need about 95\.4 GiB"):
        build_simulation(load_scene(p))


def test_fem_hex_grid_of_a_million_cells_is_refused(tmp_path):
    from unmesh.fem.scene import build_simulation

    p = tmp_path / "grid.toml"
    p.write_text(FEM.format(cells="[1000000, 2, 2]"))
    with pytest.raises(SceneError, match=r"grid\.toml: key 'objects\[0\]\.mesh\.cells': a hex grid of "
                                         r"1000000 x 2 x 2 = 4e\+06 cells would need about 30\.5 GiB"):
        build_simulation(load_scene(p))


def test_misspelt_required_key_names_what_was_found(tmp_path):
    p = tmp_path / "typo.toml"
    p.write_text("[simulation]\ndt = 0.001\nduraton = 1.0\n")
    sim = load_scene(p).table("simulation")
    with pytest.raises(SceneError, match=r"typo\.toml: key 'simulation\.duration': missing \(required\); "
                                         r"found 'simulation\.duraton' instead \(misspelt\?\)"):
        sim.number("duration")
    with pytest.raises(SceneError, match=r"key 'simulation\.fps': missing \(required\)$"):
        sim.number("fps")


def test_one_parser_for_inf_and_off():
    assert parse_infinite("off") == math.inf and parse_infinite("Infinity") == math.inf
    assert parse_infinite("-inf") == -math.inf and parse_infinite("offset") == "offset"
    t = Table({"a": "off", "b": math.inf, "c": "none", "d": "x", "e": -math.inf, "f": math.nan}, Path("s.toml"))
    assert t.number("a", infinite=True) == math.inf
    assert t.number("b", infinite=True) == math.inf
    assert t.number("c", infinite=True, positive=True) == math.inf
    with pytest.raises(SceneError, match=r"key 'd': expected a number or 'inf' / 'off', got 'x'"):
        t.number("d", infinite=True)
    with pytest.raises(SceneError, match=r"key 'e': expected a positive number"):
        t.number("e", infinite=True, positive=True)
    with pytest.raises(SceneError, match=r"key 'f': expected a finite number"):
        t.number("f", infinite=True)
    with pytest.raises(SceneError, match=r"key 'b': expected a finite number"):
        t.number("b")


def test_sph_and_shells_read_off_the_same_way(tmp_path):
    sim, _ = sph_scene(tmp_path, material='fracture_stretch = "off"\nmelting_point = inf')
    assert sim.summary_header()["particles"] > 0
    from unmesh.shells.scene import build_simulation

    p = tmp_path / "sheet.toml"
    p.write_text(SHELL.format(size="[1.0, 1.0]") + "[material.fracture]\ngamma_s = inf\ngamma_b = \"off\"\n")
    shell, _ = build_simulation(load_scene(p))
    assert math.isinf(shell.material.fracture_stretch) and math.isinf(shell.material.fracture_bend)


def test_guard_is_the_one_conversion():
    t = Table({"x": 1}, Path("scene.toml"), "objects[2]")
    with pytest.raises(SceneError, match=r"^scene\.toml: key 'objects\[2\]\.x': bad x$"):
        with t.guard("x"):
            raise InputError("bad x")
    with pytest.raises(SceneError, match=r"^scene\.toml: \[objects\[2\]\]: boom$"):
        t.call(None, lambda: (_ for _ in ()).throw(InputError("boom")))
    assert t.wrap_input_error("x", InputError("y")).args[0] == "scene.toml: key 'objects[2].x': y"


def test_one_builder_name_and_deprecated_alias(tmp_path):
    import unmesh.fem
    import unmesh.shells
    import unmesh.sph
    from unmesh.shells.scene import build_shell_simulation

    assert callable(unmesh.sph.build_simulation) and callable(unmesh.fem.build_simulation)
    assert unmesh.shells.build_simulation is unmesh.shells.scene.build_simulation
    p = tmp_path / "sheet.toml"
    p.write_text(SHELL.format(size="[1.0, 1.0]"))
    with pytest.warns(DeprecationWarning, match="build_shell_simulation is deprecated"):
        sim, _ = build_shell_simulation(load_scene(p))
    assert sim is not None


def test_table_does_not_import_a_cycle():
    import ast

    import unmesh.scene.shapes as shapes_module

    tree = ast.parse(Path(shapes_module.__file__).read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(m and m.startswith("unmesh.scene") for m in imported)


def test_shipped_scenes_by_name(tmp_path):
    assert "sph/dam_break" in shipped_scenes() and "shells/tearing_poster" in shipped_scenes("shells")
    assert resolve_scene("dam_break", "sph").name == "dam_break.toml"
    assert resolve_scene("tearing_poster", "shells").parent.name == "shells"
    assert resolve_scene("fem/blob_slicing.toml", "fem").name == "blob_slicing.toml"
    assert resolve_scene("no_such_scene", "sph") == Path("no_such_scene")
    local = tmp_path / "dam_break"
    local.write_text("")
    assert resolve_scene(local, "sph") == local  # an existing path always wins
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SceneError, match=r"no_such_scene: scene file not found \(shipped scenes: 'unmesh scenes'\)"):
            load_scene("no_such_scene")


def test_overlong_scene_name_is_a_scene_error():
    with pytest.raises(SceneError, match="scene file not found"):
        load_scene("x" * 5000 + ".toml")
