"""The batch engine on a real 2-worker local cluster: outputs equal serial runs, retries, failures, resume, Ctrl-C."""

from __future__ import annotations

import filecmp
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from unmesh.batch import COMMANDS, Command, load_manifest, run_batch
from unmesh.errors import InputError, MissingDependencyError

pytest.importorskip("distributed")


def _sweep(tmp_path: Path, text: str) -> Path:
    f = tmp_path / "sweep.toml"
    f.write_text(text)
    return f


@pytest.fixture
def counting(monkeypatch):
    monkeypatch.setitem(COMMANDS, "count", Command("count", "inputs", "tests.batch.helpers",
                                                   "tests.batch.helpers:count_runner", accepts_names=True))


def test_sample_sweep_on_two_workers_equals_serial_runs(tmp_path, capsys):
    from unmesh.cli import main

    f = _sweep(tmp_path, 'command = "sample"\ninputs = ["sphere", "torus"]\n[sweep]\nspacing = [0.2, 0.12]\n')
    out = tmp_path / "out"
    assert main(["batch", os.fspath(f), "-o", os.fspath(out), "--workers", "2", "--no-progress"]) == 0
    text = capsys.readouterr()
    assert "local cluster of 2 worker processes" in text.err and "4 of 4 tasks done" in text.out
    manifest = json.loads((out / "batch.json").read_text())
    assert set(manifest["versions"]) >= {"unmesh", "numba", "numpy", "dask"}
    assert [t["status"] for t in manifest["tasks"]] == ["done"] * 4
    assert len({t["worker"] for t in manifest["tasks"]}) >= 1
    for t in manifest["tasks"]:
        alone = tmp_path / f"alone_{t['id']}.ply"
        assert main(["sample", t["input"], "-o", os.fspath(alone), "--spacing", repr(t["parameters"]["spacing"])]) == 0
        assert filecmp.cmp(alone, Path(t["output"]), shallow=False), t["id"]
        assert t["figures"]["surfels"] > 0
    rows = (out / "batch.csv").read_text().splitlines()
    assert rows[0].startswith("id,status,input,spacing,wall_seconds,worker,error,")
    assert len(rows) == 5 and "surfels" in rows[0]


@pytest.mark.slow
def test_sph_sweep_equals_serial_runs(tmp_path, client):
    from unmesh.scenes import __file__ as scenes_init
    from unmesh.sim.cli import run_scene
    from unmesh.sph.scene import build_simulation

    scene = Path(scenes_init).parent / "sph" / "elastic_cube_2d.toml"
    (tmp_path / "cube.toml").write_text(scene.read_text())
    f = _sweep(tmp_path, 'command = "sph"\nscene = "cube.toml"\nduration = 0.005\n'
                         '[sweep]\n"simulation.spacing" = [0.05]\n"materials.rubber.xsph" = [0.1, 0.3]\n')
    manifest = run_batch(f, tmp_path / "out", client=client, progress=False, log=None)
    assert [t["status"] for t in manifest["tasks"]] == ["done", "done"]
    for t in manifest["tasks"]:
        alone = tmp_path / "alone" / t["id"]
        run_scene(tmp_path / "cube.toml", alone, build_simulation, overrides=t["parameters"], duration=0.005,
                  progress=False)
        got = Path(t["output"])
        frames = sorted(p.name for p in (alone / "frames").iterdir())
        assert frames and frames == sorted(p.name for p in (got / "frames").iterdir())
        for name in frames:
            assert filecmp.cmp(alone / "frames" / name, got / "frames" / name, shallow=False)
        a, b = (json.loads((d / "summary.json").read_text()) for d in (alone, got))
        for d in (a, b):
            d.pop("wall_seconds"), d.pop("process", None)  # run metadata: wall time, pid/host/start
        for rec in (*a["frames"], *b["frames"]):
            rec.pop("step_seconds", None)
        assert a == b
        with np.load(alone / "checkpoint.npz") as ca, np.load(got / "checkpoint.npz") as cb:
            for k in ca.files:
                if not k.startswith("__"):   # __json__ holds the run's wall times
                    assert np.array_equal(ca[k], cb[k]), k


def test_failing_task_is_retried_once_then_recorded_and_others_go_on(tmp_path, client, counting):
    f = _sweep(tmp_path, 'command = "count"\ninputs = "n"\n[[runs]]\nx = 1\n[[runs]]\nx = 2\nfail = true\n'
                         '[[runs]]\nx = 3\nflaky = true\n')
    out = tmp_path / "out"
    manifest = run_batch(f, out, client=client, progress=False, log=None)
    by_x = {t["parameters"]["x"]: t for t in manifest["tasks"]}
    assert by_x[1]["status"] == "done" and by_x[3]["status"] == "done"
    assert by_x[2]["status"] == "failed"
    assert by_x[2]["error"] == f"ValueError: task {by_x[2]['id']} failed on attempt 2"   # one line
    assert by_x[2]["worker"].startswith("tcp://")
    attempts = {x: len((out / "attempts" / t["id"]).read_text()) for x, t in by_x.items()}
    assert attempts == {1: 1, 2: 2, 3: 2}
    assert load_manifest(out) == manifest
    csv = (out / "batch.csv").read_text()
    assert "double" in csv.splitlines()[0] and ",failed," in csv


def test_resume_skips_done_tasks_and_reruns_the_rest(tmp_path, client, counting):
    f = _sweep(tmp_path, 'command = "count"\ninputs = "n"\n[sweep]\nx = [1, 2, 3]\n')
    out = tmp_path / "out"
    out.mkdir()
    (out / "broken").write_text("")            # every task fails
    with pytest.raises(InputError, match="not empty and holds no batch"):
        run_batch(f, out, client=client, progress=False, log=None)
    (out / "broken").unlink()
    first = run_batch(f, out, client=client, progress=False, log=None)
    assert [t["status"] for t in first["tasks"]] == ["done"] * 3
    with pytest.raises(InputError, match="--resume"):
        run_batch(f, out, client=client, progress=False, log=None)
    # mark one task failed as if it had broken, and resume: only that one reruns
    manifest = load_manifest(out)
    manifest["tasks"][1].update(status="failed", error="ValueError: boom")
    (out / "batch.json").write_text(json.dumps(manifest))
    again = run_batch(f, out, client=client, progress=False, resume=True, log=None)
    assert [t["status"] for t in again["tasks"]] == ["done"] * 3
    attempts = [len((out / "attempts" / t["id"]).read_text()) for t in again["tasks"]]
    assert attempts == [1, 2, 1]
    assert again["tasks"][0] == first["tasks"][0]


def test_ctrl_c_cancels_and_leaves_a_consistent_manifest(tmp_path, client, counting, monkeypatch):
    import distributed

    f = _sweep(tmp_path, 'command = "count"\ninputs = "n"\n[sweep]\nx = [1, 2, 3, 4]\n')
    out = tmp_path / "out"

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(distributed, "wait", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_batch(f, out, client=client, progress=False, log=None)
    manifest = load_manifest(out)
    assert [t["status"] for t in manifest["tasks"]] == ["pending"] * 4
    assert all(t["error"] == "cancelled (interrupted)" for t in manifest["tasks"])
    monkeypatch.undo()
    monkeypatch.setitem(COMMANDS, "count", Command("count", "inputs", "tests.batch.helpers",
                                                   "tests.batch.helpers:count_runner", accepts_names=True))
    resumed = run_batch(f, out, client=client, progress=False, log=None, resume=True)
    assert [t["status"] for t in resumed["tasks"]] == ["done"] * 4


def test_missing_dask_names_the_extra(tmp_path, monkeypatch, counting):
    from unmesh.distributed import connect

    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(MissingDependencyError, match=r"pip install 'unmesh\[batch\]'"), connect(workers=1):
        pass
    f = _sweep(tmp_path, 'command = "count"\ninputs = "n"\n[sweep]\nx = [1]\n')
    with pytest.raises(MissingDependencyError, match=r"unmesh\[batch\]"):
        run_batch(f, tmp_path / "out", progress=False, log=None)


def test_local_workers_do_not_oversubscribe_the_cores(client):
    threads = client.run(lambda: __import__("numba").config.NUMBA_NUM_THREADS)
    assert len(threads) == 2
    assert set(threads.values()) == {max(1, (os.cpu_count() or 1) // 2)}
    assert {w["nthreads"] for w in client.scheduler_info(n_workers=-1)["workers"].values()} == {1}


def test_workers_and_scheduler_exclude_each_other():
    from unmesh.distributed import connect

    with pytest.raises(InputError, match="--workers/--scheduler"), connect(workers=2, scheduler="tcp://127.0.0.1:1"):
        pass
    with pytest.raises(InputError, match="--workers: expected a positive"), connect(workers=0):
        pass
