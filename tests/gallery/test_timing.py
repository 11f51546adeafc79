"""The gallery's progress bar weighs examples by their expected time (issue 23, item 12)."""

import json
import time

from unmesh.gallery import ExampleContext, example, select
from unmesh.gallery.page import run_examples
from unmesh.gallery.registry import Example
from unmesh.gallery.timing import DEFAULT_SECONDS, TIMINGS_FILE, expected_seconds, load_timings, record


@example("zz-timing-fast", "fast", section="Tests")
def _fast(ctx: ExampleContext):
    pass


@example("zz-timing-slow", "slow", section="Tests")
def _slow(ctx: ExampleContext):
    time.sleep(0.2)


def _ex(name):
    return Example(name, name, "Tests", lambda ctx: None, "")


def test_weights_come_from_the_last_run_then_the_shipped_table_then_the_median(tmp_path):
    assert expected_seconds([_ex("zz-unknown")], tmp_path, quick=True) == [DEFAULT_SECONDS]
    shipped = expected_seconds([_ex("csg-fig48")], tmp_path, quick=True)[0]
    assert shipped != DEFAULT_SECONDS          # measured defaults ship with the package
    record(tmp_path, True, {"zz-a": 2.0, "zz-b": 8.0})
    record(tmp_path, False, {"zz-a": 50.0})
    w = expected_seconds([_ex("zz-a"), _ex("zz-b"), _ex("zz-c")], tmp_path, quick=True)
    assert w[:2] == [2.0, 8.0] and w[2] == 5.0            # unknown: median of the known ones
    assert expected_seconds([_ex("zz-a")], tmp_path, quick=False) == [50.0]   # per mode
    assert load_timings(tmp_path) == {"quick": {"zz-a": 2.0, "zz-b": 8.0}, "full": {"zz-a": 50.0}}


def test_a_damaged_timings_file_is_ignored(tmp_path):
    (tmp_path / TIMINGS_FILE).write_text("{not json")
    assert expected_seconds([_ex("zz-x")], tmp_path, quick=True) == [DEFAULT_SECONDS]
    (tmp_path / TIMINGS_FILE).write_text(json.dumps({"quick": {"zz-x": "soon", "zz-y": -1, "zz-z": 3}}))
    assert load_timings(tmp_path) == {"quick": {"zz-z": 3.0}}


def test_a_run_records_its_times_and_the_bar_counts_expected_seconds(tmp_path, monkeypatch):
    import tqdm

    seen = {}
    real = tqdm.tqdm

    class Spy(real):
        def __init__(self, *a, **k):
            seen["total"] = k.get("total")
            seen["updates"] = []
            super().__init__(*a, **k)

        def update(self, n=1):
            seen["updates"].append(n)
            return super().update(n)

    monkeypatch.setattr(tqdm, "tqdm", Spy)
    record(tmp_path, True, {"zz-timing-fast": 1.0, "zz-timing-slow": 30.0})
    run_examples(select("zz-timing-*"), tmp_path, quick=True, progress=False)
    assert seen["total"] == 31.0 and seen["updates"] == [1.0, 30.0]
    got = load_timings(tmp_path)["quick"]
    assert got["zz-timing-slow"] >= 0.2 and got["zz-timing-fast"] < 0.2
