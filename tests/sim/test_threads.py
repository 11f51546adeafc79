"""The one thread policy (:mod:`unmesh._threads`): the tuner of shells and FEM, serial regions, small-work policy."""

from __future__ import annotations

import numba
import pytest

from unmesh import _threads as threads
from unmesh._threads import SERIAL_BELOW, _Tuner, available_threads, serial_if_small, serial_region, threads_for

TWO = min(2, numba.config.NUMBA_NUM_THREADS)


@pytest.fixture
def restore_threads():
    before = numba.get_num_threads()
    yield
    numba.set_num_threads(before)


def test_tuner_keeps_the_faster_choice_and_probes_again_after_its_period():
    t = _Tuner(period=20)
    for _ in range(2 * t.PROBE):
        serial = t.choose_serial()
        t.record(serial, 1.0 if serial else 3.0)
    assert t.choose_serial() is True
    for _ in range(20 - 2 * t.PROBE):
        assert t.choose_serial() is True
        t.record(True, 1.0)
    for _ in range(2 * t.PROBE):                                # the next probe round: load changed
        serial = t.choose_serial()
        t.record(serial, 5.0 if serial else 2.0)
    assert t.choose_serial() is False


@pytest.mark.skipif(TWO < 2, reason="needs two numba threads")
def test_threads_for_inside_a_serial_region_may_use_the_outer_threads(restore_threads, monkeypatch):
    monkeypatch.setattr(threads, "_TUNERS", {})
    numba.set_num_threads(TWO)
    seen = []
    with serial_region():
        assert numba.get_num_threads() == 1
        assert available_threads() == TWO
        for _ in range(2 * _Tuner.PROBE):                       # a probe round: both choices
            with threads_for(10**6, key="test"):
                seen.append(numba.get_num_threads())
            assert numba.get_num_threads() == 1
        with threads_for(10, key="test"):                       # below the minimum
            assert numba.get_num_threads() == 1
        with serial_region():                                   # nested: still the outermost count
            assert available_threads() == TWO
    assert sorted(set(seen)) == [1, TWO]
    assert numba.get_num_threads() == TWO


def test_a_users_single_thread_is_respected_inside_serial_regions(restore_threads, monkeypatch):
    monkeypatch.setattr(threads, "_TUNERS", {})
    numba.set_num_threads(1)
    with serial_region():
        assert available_threads() == 1
        for _ in range(2 * _Tuner.PROBE):
            with threads_for(10**6, key="test"):
                assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == 1


def test_a_disabled_serial_region_changes_nothing(restore_threads):
    numba.set_num_threads(TWO)
    with serial_region(False):
        assert numba.get_num_threads() == TWO
        assert available_threads() == TWO


@pytest.mark.skipif(TWO != 2, reason="needs exactly two numba threads")
def test_background_work_keeps_its_core(restore_threads, monkeypatch):
    import threading

    from unmesh._threads import background_work

    monkeypatch.setattr(threads, "_TUNERS", {})
    numba.set_num_threads(2)
    started, release = threading.Event(), threading.Event()

    def work():
        with background_work():
            started.set()
            release.wait(10)

    t = threading.Thread(target=work)
    t.start()
    started.wait(10)
    try:
        for _ in range(2 * _Tuner.PROBE):
            with threads_for(10**6, key="test") as tf:
                assert tf.serial and numba.get_num_threads() == 1
        assert not threads._TUNERS                              # no timings taken meanwhile
    finally:
        release.set()
        t.join()
    with threads_for(10**6, key="test") as tf:
        assert tf.threads == 2


def test_import_sets_a_short_openmp_spin_unless_the_user_set_one():
    """``import unmesh`` bounds libgomp's spinning (a busy machine) but keeps the user's value."""
    import os
    import subprocess
    import sys

    code = "import os, unmesh; print(os.environ['GOMP_SPINCOUNT'])"
    env = {k: v for k, v in os.environ.items() if k != "GOMP_SPINCOUNT"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "30000"
    out = subprocess.run([sys.executable, "-c", code], env={**env, "GOMP_SPINCOUNT": "7"}, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "7"


def test_serial_if_small_runs_small_work_on_one_thread_and_leaves_large_work_alone():
    before = numba.get_num_threads()
    numba.set_num_threads(TWO)
    try:
        with serial_if_small(SERIAL_BELOW - 1):
            assert numba.get_num_threads() == 1
            assert available_threads() == TWO      # a threads_for inside may still use the outer count
        assert numba.get_num_threads() == TWO
        with serial_if_small(SERIAL_BELOW):
            assert numba.get_num_threads() == TWO
        with serial_if_small(10, below=10):
            assert numba.get_num_threads() == TWO
        with serial_if_small(9, below=10):
            assert numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(before)


def test_deprecated_sim_threads_is_the_shared_module():
    import importlib
    import sys
    import warnings

    sys.modules.pop("unmesh.sim.threads", None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = importlib.import_module("unmesh.sim.threads")
    assert any(issubclass(w.category, DeprecationWarning) for w in caught)
    assert old.threads_for is threads_for and old.serial_region is serial_region
    assert old._TUNERS is threads._TUNERS and old.serial_if_small is serial_if_small


def test_every_layer_uses_the_one_policy():
    from unmesh.render import _kernels as render_kernels
    from unmesh.spatial import kdtree, neighbors

    assert render_kernels.serial_if_small is serial_if_small
    assert kdtree.serial_if_small is serial_if_small and neighbors.serial_if_small is serial_if_small
    assert render_kernels.SERIAL_BELOW == kdtree.SERIAL_BELOW == SERIAL_BELOW
