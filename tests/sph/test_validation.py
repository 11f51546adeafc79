"""Validation against experiment: the dam break of Martin & Moyce (1952), n² = 2 (slow)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.scene import load_scene
from unmesh.scenes import path as scene_path
from unmesh.sph.front import surge_front
from unmesh.sph.scene import build_simulation

#: Martin & Moyce (1952), Phil. Trans. R. Soc. A 244, Fig. 3, n² = 2, a = 2.25 in: surge front
#: Z = x/a over T = t·√(2g/a) (digitised values as distributed with PySPH, pysph/examples/db_exp_data.py).
MARTIN_MOYCE_T = np.array([0.832, 1.219, 1.997, 2.547, 3.345])
MARTIN_MOYCE_Z = np.array([1.217, 1.474, 2.292, 2.995, 4.134])


@pytest.mark.slow
def test_dam_break_front_matches_martin_moyce():
    """The shipped 3D dam break (a = 0.25 m, a/20 resolution) against the measured surge front.

    The tank walls are no-slip (``no_slip = true``: the walls apply the water's own effective
    viscosity, no free parameter; docs/sph_scene.md). Issue 4 sets the goal "within 10 % for
    T <= 3". Measured at a/20: +7.9, +8.5, -1.1, -6.1 % at T = 0.83, 1.22, 2.00, 2.55 and
    -10.5 % at T = 3.35 (before the tensile correction's background and the hydrostatic wall pressure
    +8.2, +8.5, -0.8, -6.1, -10.0 %) (free-slip walls: +12.9, +16.0, +10.0, +8.2, +6.0 %). The deviations
    are printed (and by ``benchmarks/bench_sph.py``) for the report.
    """
    a = 0.25
    spacing = a / 20
    sim, _ = build_simulation(load_scene(scene_path("sph/dam_break.toml"), {"simulation.spacing": spacing}))
    assert all(p.no_slip for p in sim.planes)
    g = 9.81
    fronts = []
    for big_t in MARTIN_MOYCE_T:
        t = big_t / np.sqrt(2 * g / a)
        while sim.time < t:
            sim.step()
            assert sim.check() is None
        fronts.append(surge_front(sim.particles().positions, spacing) / a)
    fronts = np.asarray(fronts)
    dev = (fronts - MARTIN_MOYCE_Z) / MARTIN_MOYCE_Z
    for big_t, z_exp, z_sim, e in zip(MARTIN_MOYCE_T, MARTIN_MOYCE_Z, fronts, dev, strict=True):
        print(f"T = {big_t:.3f}: Martin & Moyce Z = {z_exp:.3f}, SPH Z = {z_sim:.3f} ({100 * e:+.1f} %)")
    print(f"mean |deviation| {100 * np.mean(np.abs(dev)):.1f} %, max {100 * np.max(np.abs(dev)):.1f} %")
    assert np.all(np.diff(fronts) > 0)
    assert np.max(np.abs(dev[MARTIN_MOYCE_T <= 3.0])) < 0.10  # the goal of issue 4
    assert np.max(np.abs(dev)) < 0.12
    assert np.mean(np.abs(dev)) < 0.08
