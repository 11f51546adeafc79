"""The shared simulation command plumbing, with a toy builder."""

import argparse
import json

import pytest

from unmesh.scene import Table
from unmesh.sim import RunSettings
from unmesh.sim.cli import add_run_arguments, run_scene, run_scene_command

from .test_runner import Oscillator


def build(scene: Table):
    sim_t = scene.table("simulation")
    dt = sim_t.number("dt", positive=True)
    settings = RunSettings(duration=sim_t.number("duration", positive=True), fps=sim_t.number("fps", default=10.0))
    omega = scene.number("omega", default=2.0, positive=True)
    scene.finish()
    return Oscillator(dt=dt, omega=omega), settings


def scene_file(tmp_path, extra=""):
    p = tmp_path / "osc.toml"
    p.write_text(f"omega = 3.0\n{extra}[simulation]\ndt = 0.01\nduration = 0.5\nfps = 10\n")
    return p


def parse(argv):
    p = argparse.ArgumentParser()
    add_run_arguments(p)
    return p.parse_args(argv)


def test_command_runs_scene_with_overrides(tmp_path, capsys):
    out = tmp_path / "out"
    args = parse([str(scene_file(tmp_path)), "-o", str(out), "--duration", "0.3", "--set", "simulation.fps=20",
                  "--no-progress"])
    assert run_scene_command(args, build) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "completed" and len(s["frames"]) == 7
    assert "completed" in capsys.readouterr().out


def test_typo_in_scene_is_a_scene_error(tmp_path):
    from unmesh.errors import SceneError

    with pytest.raises(SceneError, match="unknown key 'omga' \\(did you mean 'omega'\\?\\)"):
        run_scene(scene_file(tmp_path, "omga = 1\n"), tmp_path / "o", build, progress=False)
