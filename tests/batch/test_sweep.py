"""Sweep files: parsing, expansion (cartesian product, runs), task ids (readable, stable, unique)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.batch import COMMANDS, Command, expand, load_sweep, task_id
from unmesh.errors import SceneError

SCENE = "[simulation]\ndt = 0.001\n"


def _write(tmp_path: Path, text: str, scene: bool = True) -> Path:
    if scene:
        (tmp_path / "base.toml").write_text(SCENE)
    f = tmp_path / "sweep.toml"
    f.write_text(text)
    return f


def test_sweep_is_the_cartesian_product_first_key_slowest(tmp_path):
    f = _write(tmp_path, 'command = "sph"\nscene = "base.toml"\nduration = 0.5\n[sweep]\n'
                         '"materials.water.viscosity" = [0.0, 0.01, 0.05]\n"simulation.spacing" = [0.02, 0.015]\n')
    sw = load_sweep(f)
    assert sw.command == "sph" and sw.duration == 0.5 and sw.scene == (tmp_path / "base.toml").resolve()
    params = [t.params for t in sw.tasks]
    assert params == [{"materials.water.viscosity": v, "simulation.spacing": s}
                      for v in (0.0, 0.01, 0.05) for s in (0.02, 0.015)]
    assert len({t.id for t in sw.tasks}) == 6
    assert sw.tasks[1].id.startswith("viscosity=0.0_spacing=0.015-")


def test_bare_dotted_keys_are_the_same_as_quoted_ones(tmp_path):
    a = _write(tmp_path, 'command = "sph"\nscene = "base.toml"\n[sweep]\n"simulation.spacing" = [0.02]\n')
    ids_a = [t.id for t in load_sweep(a).tasks]
    b = _write(tmp_path, 'command = "sph"\nscene = "base.toml"\n[sweep]\nsimulation.spacing = [0.02]\n')
    assert [t.id for t in load_sweep(b).tasks] == ids_a


def test_runs_with_explicit_sets_and_ids(tmp_path):
    f = _write(tmp_path, 'command = "shell"\nscene = "base.toml"\n'
                         '[[runs]]\nid = "soft"\n"materials.paper.stiffness" = 1e3\n'
                         '[[runs]]\n"materials.paper.stiffness" = 1e4\n"simulation.dt" = 1e-4\n')
    sw = load_sweep(f)
    assert sw.tasks[0].id == "soft"
    assert sw.tasks[1].params == {"materials.paper.stiffness": 1e4, "simulation.dt": 1e-4}
    assert re.match(r"^stiffness=10000.0_dt=0.0001-[0-9a-f]{8}$", sw.tasks[1].id)


def test_runs_times_sweep():
    sets = expand({"b": [1, 2]}, [{"a": 0}, {"a": 1, "id": "x"}])
    assert sets == [(None, {"a": 0, "b": 1}), (None, {"a": 0, "b": 2}), ("x", {"a": 1, "b": 1}),
                    ("x", {"a": 1, "b": 2})]


def test_inputs_glob_relative_to_the_sweep_file(tmp_path):
    (tmp_path / "scans").mkdir()
    for name in ("b.ply", "a.ply", "c.obj"):
        (tmp_path / "scans" / name).write_text("x")
    f = _write(tmp_path, 'command = "sample"\ninputs = ["scans/*.ply", "torus"]\n[sweep]\nspacing = [0.1, 0.2]\n',
               scene=False)
    sw = load_sweep(f)
    assert [(Path(t.input).name if t.input != "torus" else t.input, t.params["spacing"]) for t in sw.tasks] == [
        ("a.ply", 0.1), ("a.ply", 0.2), ("b.ply", 0.1), ("b.ply", 0.2), ("torus", 0.1), ("torus", 0.2)]
    assert sw.tasks[0].id.startswith("a_spacing=0.1-")
    assert sw.tasks[4].id.startswith("torus_spacing=0.1-")


@pytest.mark.parametrize(("text", "message"), [
    ('command = "sph"\nscene = "base.toml"\n[swep]\na = [1]\n', "did you mean 'sweep'"),
    ('command = "nope"\nscene = "base.toml"\n', "unknown command 'nope'"),
    ('command = "sph"\nscene = "missing.toml"\n', "no such file 'missing.toml'"),
    ('command = "sph"\n', "'scene': expected the base scene"),
    ('command = "sph"\nscene = "base.toml"\n[sweep]\na = 1\n', "expected a non-empty list"),
    ('command = "sph"\nscene = "base.toml"\n[sweep]\na = [1, 1]\n', "values repeat"),
    ('command = "sph"\nscene = "base.toml"\nduration = -1\n', "'duration': expected a positive number"),
    ('command = "sph"\nscene = "base.toml"\n[[runs]]\na = 1\n[[runs]]\na = 1\n', "are the same"),
    ('command = "sph"\nscene = "base.toml"\n[[runs]]\nid = "a/b"\n', "'id': expected letters"),
    ('command = "sph"\nscene = "base.toml"\n[sweep]\na = [1]\n[[runs]]\na = 2\n', "also swept"),
    ('command = "sample"\ninputs = "nothing/*.ply"\n', "matches no file"),
    ('command = "render"\ninputs = "nofile.ply"\n', "no such file 'nofile.ply'"),
    ('command = "sample"\nscene = "base.toml"\n', "give 'inputs' instead"),
    ('command = "sph"\nscene = "base.toml"\noptions = ["--resume"]\n', "runs its scene in-process"),
])
def test_bad_sweep_files_name_the_key(tmp_path, text, message):
    f = _write(tmp_path, text)
    with pytest.raises(SceneError, match=re.escape(message)):
        load_sweep(f)


def test_commands_whose_module_is_missing_are_refused_clearly(tmp_path, monkeypatch):
    monkeypatch.setitem(COMMANDS, "future", Command("future", "scene", "unmesh.no_such_capability.cli",
                                                    "unmesh.batch.tasks:run_argv_task"))
    f = _write(tmp_path, 'command = "future"\nscene = "base.toml"\n')
    with pytest.raises(SceneError, match=r"'future' is not available .*unmesh\.no_such_capability\.cli is missing"):
        load_sweep(f)


def test_registered_commands_are_usable(tmp_path, monkeypatch):
    monkeypatch.setitem(COMMANDS, "mine", Command("mine", "scene", "unmesh.sph.scene", "unmesh.batch.tasks:run_argv_task"))
    f = _write(tmp_path, 'command = "mine"\nscene = "base.toml"\n[sweep]\nx = [1, 2]\n')
    assert len(load_sweep(f).tasks) == 2


values = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=False, allow_infinity=False),
                   st.booleans(), st.text(max_size=12), st.lists(st.integers(-5, 5), max_size=3))
keys = st.from_regex(r"[a-z_]{1,8}(\.[a-z_]{1,8}){0,2}", fullmatch=True)
param_sets = st.dictionaries(keys, values, max_size=4)


@settings(max_examples=60, deadline=None)
@given(param_sets, st.randoms())
def test_ids_are_stable_and_safe(params, rnd):
    items = list(params.items())
    rnd.shuffle(items)
    tid = task_id(params)
    assert task_id(dict(items)) == tid                     # independent of key order
    assert task_id(dict(params)) == tid                    # a pure function of the task
    assert re.fullmatch(r"[A-Za-z0-9.,+=_\-]+", tid) and len(tid) <= 90
    assert not tid.startswith((".", "-"))


@settings(max_examples=60, deadline=None)
@given(st.lists(param_sets, min_size=2, max_size=6, unique_by=lambda d: repr(sorted(d.items(), key=str))))
def test_ids_of_different_tasks_differ(sets):
    canon = {repr(sorted(((k, repr(v)) for k, v in d.items()))) for d in sets}
    ids = {task_id(d) for d in sets}
    assert len(ids) == len(canon)


def test_id_is_readable_and_known():
    assert task_id({"materials.water.viscosity": 0.01, "simulation.spacing": 0.02}) == \
        "viscosity=0.01_spacing=0.02-30bd46ed"
    assert task_id({"objects[0].velocity": [0, -1, 0]}).startswith("velocity=0,-1,0-")
