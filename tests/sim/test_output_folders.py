"""Output folders of the shared runner: the frames.json manifest, refusing non-empty folders,
--force, resume after an interruption or kill -9, SIGTERM and write errors in summary.json."""

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from unmesh.errors import InputError, SimulationError
from unmesh.io.atomic import atomic_write_text
from unmesh.sim import MANIFEST, RunSettings, read_manifest, read_summary, run

from .test_runner import Oscillator

SRC = Path(__file__).resolve().parents[2] / "src"


class WithStatic(Oscillator):
    def write_static(self, outdir):
        atomic_write_text(outdir / "boundary.txt", "wall")
        return ["boundary.txt"]


def summary(out):
    return json.loads((out / "summary.json").read_text())


def manifest(out):
    return json.loads((out / MANIFEST).read_text())


def test_manifest_lists_every_file_with_frame_times(tmp_path):
    run(WithStatic(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    m = manifest(tmp_path)
    assert m["static"] == ["boundary.txt"] and m["fps"] == 10.0 and m["simulation"] == "oscillator"
    assert [e["frame"] for e in m["frames"]] == list(range(11))
    assert [e["files"] for e in m["frames"]] == [[f"frames/frame_{k:05d}.txt"] for k in range(11)]
    assert [e["time"] for e in m["frames"]] == [f["time"] for f in summary(tmp_path)["frames"]]
    assert read_manifest(tmp_path) == m
    s = summary(tmp_path)
    assert s["status"] == "completed" and s["process"]["pid"] == os.getpid()


def test_write_frame_paths_must_lie_in_the_folder(tmp_path):
    class Outside(Oscillator):
        def write_frame(self, outdir, frame):
            return [str(tmp_path / "elsewhere.txt")]

    with pytest.raises(InputError, match="inside"):
        run(Outside(), tmp_path / "out", RunSettings(duration=0.2, fps=10), progress=False)
    assert summary(tmp_path / "out")["status"] == "failed"


def test_a_non_empty_folder_is_refused_without_force(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match=r"outdir: expected a new or empty folder.*notes\.txt.*--force"):
        run(Oscillator(), tmp_path, RunSettings(duration=0.2, fps=10), progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # nothing written, nothing removed
    # a previous run is refused too, with the hint to resume or force
    out = tmp_path / "run"
    run(Oscillator(), out, RunSettings(duration=0.2, fps=10), progress=False)
    before = (out / "summary.json").read_text()
    with pytest.raises(InputError, match=r"previous run \(status 'completed'\).*--resume.*--force"):
        run(Oscillator(), out, RunSettings(duration=0.2, fps=10), progress=False)
    assert (out / "summary.json").read_text() == before
    # an empty folder is fine
    (tmp_path / "empty").mkdir()
    assert run(Oscillator(), tmp_path / "empty", RunSettings(duration=0.2, fps=10), progress=False).status == "completed"


def test_force_keeps_every_file_the_previous_run_did_not_write(tmp_path):
    run(WithStatic(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "frames" / "frame_00077.txt").write_text("a user's file that looks like a frame")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "frame_00001.txt").write_text("another tool's frame")
    run(Oscillator(), tmp_path, RunSettings(duration=0.3, fps=10), progress=False, force=True)
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert (tmp_path / "frames" / "frame_00077.txt").is_file() and (tmp_path / "other" / "frame_00001.txt").is_file()
    assert not (tmp_path / "boundary.txt").exists()  # the old run's static file (this run has none)
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == \
        [f"frame_{k:05d}.txt" for k in range(4)] + ["frame_00077.txt"]
    assert [e["frame"] for e in manifest(tmp_path)["frames"]] == [0, 1, 2, 3]
    # a manifest entry pointing outside the folder is never followed
    victim = tmp_path.parent / f"{tmp_path.name}_victim.txt"
    victim.write_text("keep")
    m = manifest(tmp_path)
    m["frames"][0]["files"].append(f"../{victim.name}")
    m["static"].append(str(victim))
    (tmp_path / MANIFEST).write_text(json.dumps(m))
    run(Oscillator(), tmp_path, RunSettings(duration=0.1, fps=10), progress=False, force=True)
    assert victim.read_text() == "keep"


def test_force_removes_the_emptied_folders_of_the_previous_run(tmp_path):
    run(Oscillator(), tmp_path, RunSettings(duration=0.2, fps=10), progress=False)

    class Elsewhere(Oscillator):
        def write_frame(self, outdir, frame):
            atomic_write_text(outdir / "data" / f"f{frame}.txt", "x")
            return [f"data/f{frame}.txt"]

    run(Elsewhere(), tmp_path, RunSettings(duration=0.2, fps=10), progress=False, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.npz", "data", MANIFEST, "summary.json"]


def test_resume_drops_frames_after_the_checkpoint(tmp_path):
    settings = RunSettings(duration=1.0, fps=10, checkpoint_every=2)
    with pytest.raises(KeyboardInterrupt):
        run(Oscillator(interrupt_at=55), tmp_path, settings, progress=False)
    assert [e["frame"] for e in manifest(tmp_path)["frames"]] == list(range(6))
    s = summary(tmp_path)
    assert s["status"] == "interrupted" and "--resume (from frame 4)" in s["message"]
    # resuming to a duration that ends at the checkpoint: frame 5 (written after it) is dropped
    run(Oscillator(), tmp_path, settings.replace(duration=0.4), resume=True, progress=False)
    assert [e["frame"] for e in manifest(tmp_path)["frames"]] == list(range(5))
    assert not (tmp_path / "frames" / "frame_00005.txt").exists()
    assert [f["frame"] for f in summary(tmp_path)["frames"]] == list(range(5))
    run(Oscillator(), tmp_path, settings, resume=True, progress=False)
    m = manifest(tmp_path)
    assert [e["frame"] for e in m["frames"]] == list(range(11))
    assert all((tmp_path / f).is_file() for e in m["frames"] for f in e["files"])


def test_resume_of_a_checkpoint_without_manifest_says_so(tmp_path):
    from unmesh.sim.checkpoint import load_checkpoint, save_checkpoint

    run(Oscillator(), tmp_path, RunSettings(duration=0.2, fps=10), progress=False)
    state, meta = load_checkpoint(tmp_path / "checkpoint.npz")
    del meta["manifest"]
    save_checkpoint(tmp_path / "checkpoint.npz", state, meta)
    with pytest.raises(SimulationError, match=r"predates frames\.json.*--force"):
        run(Oscillator(), tmp_path, RunSettings(duration=0.4, fps=10), resume=True, progress=False)


def test_write_errors_mark_the_run_failed(tmp_path):
    class DiskFull(Oscillator):
        def write_frame(self, outdir, frame):
            if frame == 3:
                raise OSError(errno.ENOSPC, "No space left on device")
            return super().write_frame(outdir, frame)

    with pytest.raises(OSError, match="No space"):
        run(DiskFull(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    s = summary(tmp_path)
    assert s["status"] == "failed" and "No space left" in s["message"]
    assert s["frames"][-1]["frame"] == 2


def test_a_failing_summary_write_still_records_failed_in_place(tmp_path, monkeypatch):
    import unmesh.sim.runner as runner

    real = runner.atomic_write_json
    calls = {"n": 0}

    def flaky(path, obj):
        calls["n"] += 1
        if calls["n"] > 6:  # the disk is full from here on: atomic rewrites need new blocks
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, obj)

    monkeypatch.setattr(runner, "atomic_write_json", flaky)
    with pytest.raises(OSError):
        run(Oscillator(), tmp_path, RunSettings(duration=1.0, fps=10), progress=False)
    s = summary(tmp_path)
    assert s["status"] == "failed" and "No space left" in s["message"] and s["frames"]


def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_running_summary_of_a_dead_process_reads_as_interrupted(tmp_path):
    import socket

    run(Oscillator(), tmp_path, RunSettings(duration=0.2, fps=10), progress=False)
    s = summary(tmp_path)
    s["status"] = "running"
    s["process"] = {"pid": _dead_pid(), "host": socket.gethostname(), "start": None}
    (tmp_path / "summary.json").write_text(json.dumps(s))
    r = read_summary(tmp_path)
    assert r["status"] == "interrupted" and "killed" in r["message"]
    assert summary(tmp_path)["status"] == "running"  # inspection changes nothing
    # a live process (our parent) writing the folder: refused, even with force and for resume
    s["process"] = {"pid": os.getppid(), "host": socket.gethostname(), "start": None}
    (tmp_path / "summary.json").write_text(json.dumps(s))
    assert read_summary(tmp_path)["status"] == "running"
    with pytest.raises(SimulationError, match="being written by process"):
        run(Oscillator(), tmp_path, RunSettings(duration=0.2, fps=10), progress=False, force=True)
    with pytest.raises(SimulationError, match="being written by process"):
        run(Oscillator(), tmp_path, RunSettings(duration=0.4, fps=10), progress=False, resume=True)


SLOW_RUN = """
import sys, time
sys.path.insert(0, {src!r}); sys.path.insert(0, {tests!r})
from sim.test_runner import Oscillator
from unmesh.sim import RunSettings, run

class Slow(Oscillator):
    def step(self):
        time.sleep(0.01)
        return super().step()

run(Slow(), {out!r}, RunSettings(duration=100.0, fps=10, checkpoint_every=2), progress=False, resume={resume})
"""


def _start(out, resume=False):
    code = SLOW_RUN.format(src=str(SRC), tests=str(Path(__file__).resolve().parents[1]), out=str(out), resume=resume)
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], stderr=subprocess.PIPE)


def _wait_for_frame(out, frame, proc, timeout=120.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = read_manifest(out)
        if m and m["frames"] and m["frames"][-1]["frame"] >= frame:
            return
        if proc.poll() is not None:
            raise AssertionError(f"the run ended early: {proc.stderr.read().decode()}")
        time.sleep(0.05)
    proc.kill()
    raise AssertionError("the run did not reach the frame in time")


def test_sigterm_records_terminated(tmp_path):
    out = tmp_path / "out"
    proc = _start(out)
    _wait_for_frame(out, 3, proc)
    proc.send_signal(signal.SIGTERM)
    rc = proc.wait(timeout=60)
    assert rc == -signal.SIGTERM  # ended by the signal, as without the runner
    s = summary(out)
    assert s["status"] == "terminated" and "SIGTERM" in s["message"] and "--resume" in s["message"]
    assert read_summary(out)["status"] == "terminated"


def test_kill_9_then_resume_continues_the_manifest(tmp_path):
    from unmesh.sim.checkpoint import load_checkpoint

    out = tmp_path / "out"
    proc = _start(out)
    _wait_for_frame(out, 7, proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert summary(out)["status"] == "running"
    assert read_summary(out)["status"] == "interrupted"
    # a fresh run is refused; --resume continues from the checkpoint, later frames dropped
    with pytest.raises(InputError):
        run(Oscillator(), out, RunSettings(duration=1.0, fps=10), progress=False)
    before = manifest(out)
    ckpt = int(load_checkpoint(out / "checkpoint.npz")[1]["frame"])
    later = [f for e in before["frames"] if e["frame"] > ckpt for f in e["files"]]
    settings = RunSettings(duration=ckpt / 10, fps=10, checkpoint_every=2)
    run(Oscillator(), out, settings, resume=True, progress=False)
    assert [e["frame"] for e in manifest(out)["frames"]] == list(range(ckpt + 1))
    assert not any((out / f).exists() for f in later)
    res = run(Oscillator(), out, settings.replace(duration=1.5), resume=True, progress=False)
    assert res.status == "completed" and summary(out)["status"] == "completed"
    m = manifest(out)
    assert [e["frame"] for e in m["frames"]] == list(range(16))
    assert all((out / f).is_file() for e in m["frames"] for f in e["files"])
    assert [f["frame"] for f in summary(out)["frames"]] == list(range(16))
