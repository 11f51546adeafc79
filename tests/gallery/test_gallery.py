import pytest

from unmesh.errors import InputError
from unmesh.gallery import ExampleContext, example, select
from unmesh.gallery.page import run_examples


@example("zz-test-ok", "A passing example", section="Tests")
def _ok(ctx: ExampleContext):
    p = ctx.path("note.txt")
    p.write_text("hi")
    ctx.file(p, "a note")
    ctx.metric("answer", 42.0, "units")
    ctx.text("explanation")


@example("zz-test-fail", "A failing example", section="Tests")
def _fail(ctx: ExampleContext):
    raise RuntimeError("deliberate")


def test_select_patterns_and_unknown():
    names = [e.name for e in select("zz-test-*")]
    assert names == ["zz-test-ok", "zz-test-fail"]
    with pytest.raises(InputError, match="no example matches nope"):
        select("nope")


def test_run_writes_index_and_records_failures(tmp_path):
    results = run_examples(select("zz-test-*"), tmp_path, quick=True, progress=False)
    assert [r.error is None for r in results] == [True, False]
    html = (tmp_path / "index.html").read_text()
    assert "A passing example" in html and "42" in html and "zz-test-ok/note.txt" in html
    assert "deliberate" in html and "This example failed" in html


def test_timed_reports_the_warm_call():
    import time

    from unmesh.gallery.registry import timed

    calls = []

    def slow_first(x):
        if not calls:
            time.sleep(0.3)  # stands in for numba compilation
        calls.append(x)
        return 2 * x

    assert timed(slow_first, 21)[0] == 42 and timed(slow_first, 1)[1] < 0.2
    warmed = []
    out, seconds = timed(lambda: 7, warm=lambda: warmed.append(1))
    assert (out, warmed) == (7, [1]) and seconds < 0.2


def test_index_html_has_the_umask_mode(tmp_path):
    import os

    run_examples(select("zz-test-ok"), tmp_path, quick=True, progress=False)
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "index.html").stat().st_mode & 0o777 == 0o666 & ~umask


def test_keep_frames_thins_a_run_consistently(tmp_path):
    import json

    from unmesh.sim.runner import read_manifest

    run = tmp_path / "ex" / "run"
    (run / "frames").mkdir(parents=True)
    entries = []
    for k in range(5):
        (run / "frames" / f"frame_{k:05d}.ply").write_text("x")
        entries.append({"frame": k, "time": 0.1 * k, "files": [f"frames/frame_{k:05d}.ply"]})
    (run / "boundary.ply").write_text("b")
    (run / "checkpoint.npz").write_text("c")
    (run / "frames.json").write_text(json.dumps({"frames": entries, "static": ["boundary.ply"], "fps": 10.0}))
    ctx = ExampleContext(tmp_path / "ex", tmp_path)
    kept = ctx.keep_frames(run, [0, 3])
    assert [e["frame"] for e in kept] == [0, 3]
    assert sorted(p.name for p in (run / "frames").iterdir()) == ["frame_00000.ply", "frame_00003.ply"]
    assert (run / "boundary.ply").is_file() and not (run / "checkpoint.npz").exists()
    m = read_manifest(run)
    assert [e["frame"] for e in m["frames"]] == [0, 3] and m["static"] == ["boundary.ply"] and m["fps"] == 10.0


def test_worker_processes_give_the_same_page_in_the_same_order(tmp_path):
    serial = run_examples(select("zz-test-*"), tmp_path / "serial", quick=True, progress=False)
    pooled = run_examples(select("zz-test-*"), tmp_path / "pooled", quick=True, progress=False, jobs=2)
    assert [r.example.name for r in pooled] == [r.example.name for r in serial] == ["zz-test-ok", "zz-test-fail"]
    assert [r.error is None for r in pooled] == [True, False] and "deliberate" in pooled[1].error
    assert pooled[0].context.metrics == serial[0].context.metrics == [("answer", 42.0, "units")]
    assert (tmp_path / "pooled" / "zz-test-ok" / "note.txt").read_text() == "hi"
    html = (tmp_path / "pooled" / "index.html").read_text()
    assert html.index("A passing example") < html.index("A failing example") and "deliberate" in html


def test_jobs_must_be_positive(capsys):
    from unmesh.cli import main

    assert main(["gallery", "--only", "zz-test-ok", "--jobs", "0", "-o", "/nonexistent/x"]) == 1
    assert "--jobs" in capsys.readouterr().err


@example("zz-crash-exit", "An example whose process dies", section="Tests")
def _dies(ctx: ExampleContext):
    import os

    os._exit(3)


def test_a_dying_worker_fails_only_its_own_example(tmp_path):
    results = run_examples(select("zz-test-ok,zz-crash-exit"), tmp_path, quick=True, progress=False, jobs=2)
    assert [r.example.name for r in results] == ["zz-test-ok", "zz-crash-exit"]
    assert results[0].error is None and results[0].context.metrics == [("answer", 42.0, "units")]
    assert "worker process running it died" in results[1].error
