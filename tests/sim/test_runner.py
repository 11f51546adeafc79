"""The shared runner, exercised with a small analytic simulation."""

import json
from pathlib import Path

import numpy as np
import pytest

from unmesh.errors import InputError, SimulationError, UnstableSimulationError
from unmesh.io.atomic import atomic_write_text
from unmesh.sim import RunSettings, Simulation, run


class Oscillator(Simulation):
    """x'' = -w^2 x by symplectic Euler; random kicks test RNG checkpointing."""

    name = "oscillator"

    def __init__(self, dt=0.01, omega=2.0, noise=0.0, blow_up_at=None, interrupt_at=None):
        self.time = 0.0
        self.dt = dt
        self.omega = omega
        self.x = np.array([1.0, 0.0])
        self.v = np.array([0.0, 1.0])
        self.noise = noise
        self.rng = np.random.default_rng(7)
        self.blow_up_at = blow_up_at
        self.interrupt_at = interrupt_at
        self.steps = 0

    def step(self):
        self.steps += 1
        if self.interrupt_at is not None and self.steps == self.interrupt_at:
            raise KeyboardInterrupt
        self.v -= self.dt * self.omega**2 * self.x
        self.v += self.noise * self.rng.normal(size=2)
        self.x += self.dt * self.v
        if self.blow_up_at is not None and self.time >= self.blow_up_at:
            self.x[:] = np.nan
        self.time += self.dt
        return self.dt

    def check(self):
        return None if np.all(np.isfinite(self.x)) else "NaN in positions"

    def write_frame(self, outdir: Path, frame: int):
        atomic_write_text(outdir / "frames" / f"frame_{frame:05d}.txt", " ".join(map(repr, self.x)))
        return [f"frames/frame_{frame:05d}.txt"]

    def frame_record(self):
        return {"energy": 0.5 * float(self.v @ self.v + self.omega**2 * self.x @ self.x), "x": self.x}

    def summary_header(self):
        return {"particles": 2}

    def state_dict(self):
        return {"time": self.time, "x": self.x.copy(), "v": self.v.copy(), "steps": self.steps,
                "rng": self.rng.bit_generator.state}

    def load_state_dict(self, s):
        self.time = float(s["time"])
        self.x = s["x"].copy()
        self.v = s["v"].copy()
        self.steps = int(s["steps"])
        self.rng.bit_generator.state = s["rng"]


def summary(out):
    return json.loads((out / "summary.json").read_text())


def test_frames_times_and_summary(tmp_path):
    res = run(Oscillator(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    s = summary(tmp_path)
    assert res.status == "completed" and s["status"] == "completed"
    assert [f["frame"] for f in s["frames"]] == list(range(11))
    times = np.array([f["time"] for f in s["frames"]])
    np.testing.assert_allclose(times, np.arange(11) / 10, atol=0.011)
    assert s["steps"] == res.steps and 99 <= res.steps <= 101 and s["particles"] == 2
    assert all(f["step_seconds"] >= 0 for f in s["frames"])
    assert len(list((tmp_path / "frames").glob("*.txt"))) == 11
    # symplectic Euler keeps the oscillator energy bounded
    energies = np.array([f["energy"] for f in s["frames"]])
    assert np.ptp(energies) / energies[0] < 0.05


def test_resume_equals_uninterrupted_run(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    run(Oscillator(noise=0.01), a, RunSettings(duration=1.0, fps=10), progress=False)
    with pytest.raises(KeyboardInterrupt):
        run(Oscillator(noise=0.01, interrupt_at=55), b, RunSettings(duration=1.0, fps=10), progress=False)
    s = summary(b)
    assert s["status"] == "interrupted" and "--resume" in s["message"]
    assert s["frames"][-1]["frame"] == 5
    res = run(Oscillator(noise=0.01), b, RunSettings(duration=1.0, fps=10), resume=True, progress=False)
    assert res.status == "completed"
    sa, sb = summary(a), summary(b)
    assert [f["frame"] for f in sb["frames"]] == list(range(11))
    np.testing.assert_allclose([f["x"] for f in sa["frames"]], [f["x"] for f in sb["frames"]], rtol=0, atol=0)
    assert sa["steps"] == sb["steps"]
    for k in range(11):
        assert (a / "frames" / f"frame_{k:05d}.txt").read_text() == (b / "frames" / f"frame_{k:05d}.txt").read_text()


def test_resume_to_longer_duration(tmp_path):
    run(Oscillator(), tmp_path, RunSettings(duration=0.5, fps=10), progress=False)
    run(Oscillator(), tmp_path, RunSettings(duration=1.0, fps=10), resume=True, progress=False)
    assert [f["frame"] for f in summary(tmp_path)["frames"]] == list(range(11))


def test_instability_stops_and_keeps_last_good_frame(tmp_path):
    with pytest.raises(UnstableSimulationError) as info:
        run(Oscillator(blow_up_at=0.42), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    msg = str(info.value)
    assert "NaN in positions" in msg and "last good frame 4" in msg and "smaller time step" in msg
    s = summary(tmp_path)
    assert s["status"] == "unstable" and s["frames"][-1]["frame"] == 4
    assert sorted(p.name for p in (tmp_path / "frames").iterdir())[-1] == "frame_00004.txt"
    assert "nan" not in (tmp_path / "frames" / "frame_00004.txt").read_text()
    # the checkpoint is the last good state and resuming from it works
    res = run(Oscillator(), tmp_path, RunSettings(duration=1.0, fps=10), resume=True, progress=False)
    assert res.status == "completed"


def test_nonfinite_diagnostics_are_unstable(tmp_path):
    class Bad(Oscillator):
        def frame_record(self):
            return {"energy": float("inf") if self.time > 0.25 else 1.0}

    with pytest.raises(UnstableSimulationError, match="non-finite energy"):
        run(Bad(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)


def test_forced_fresh_run_removes_the_previous_runs_frames(tmp_path):
    run(Oscillator(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    run(Oscillator(), tmp_path, RunSettings(duration=0.3, fps=10), progress=False, force=True)
    assert len(list((tmp_path / "frames").glob("*.txt"))) == 4


def test_resume_without_checkpoint_and_bad_settings(tmp_path):
    with pytest.raises(SimulationError, match="no checkpoint"):
        run(Oscillator(), tmp_path, RunSettings(duration=1.0), resume=True, progress=False)
    with pytest.raises(InputError, match="duration"):
        RunSettings(duration=0)
    with pytest.raises(InputError, match="fps"):
        RunSettings(duration=1, fps=-1)


class StrictOscillator(Oscillator):
    """Restores in place, so a checkpoint of the wrong shape fails inside load_state_dict."""

    def load_state_dict(self, s):
        super().load_state_dict(s)
        self.x = np.array([1.0, 0.0])
        self.x[:] = s["x"]


def test_foreign_checkpoint_with_matching_keys_but_other_shapes(tmp_path):
    from unmesh.sim.checkpoint import expect_shapes, load_checkpoint, save_checkpoint

    run(StrictOscillator(), tmp_path, RunSettings(duration=0.1, fps=20), progress=False)
    ck = tmp_path / "checkpoint.npz"
    state, meta = load_checkpoint(ck)
    state = dict(state, x=np.zeros(3))
    save_checkpoint(ck, state, meta)
    # a simulation that checks its shapes names the array and both shapes
    with pytest.raises(SimulationError, match=r"checkpoint\.npz: array 'x' has shape \(3,\) but this scene needs "
                                              r"\(2,\) \(the checkpoint belongs to another scene\)"):
        expect_shapes(load_checkpoint(ck)[0], {"x": (2,), "v": (2,)})
    # one that does not still gets one line naming the checkpoint, not an unexpected ValueError
    with pytest.raises(SimulationError, match=r"checkpoint\.npz: the checkpoint does not fit this scene \(ValueError: "):
        run(StrictOscillator(), tmp_path, RunSettings(duration=0.2, fps=20), resume=True, progress=False)
