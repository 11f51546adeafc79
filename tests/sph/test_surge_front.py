"""Issue 21: the dam break's surge front in the SPH frame records (``final.surge_front`` in batch.csv)."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from unmesh import io
from unmesh.scene import load_scene
from unmesh.sim import run
from unmesh.sph.front import surge_front
from unmesh.sph.scene import build_simulation


def test_surge_front_against_brute_force(rng):
    x = rng.random((300, 3))
    x[:5, 0] += np.array([3.0, 4.0, 5.0, 6.0, 7.0])  # droplets ahead of the body
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    np.fill_diagonal(d, np.inf)
    want = x[d.min(axis=1) < 1.5 * 0.1, 0].max()
    assert surge_front(x, 0.1) == want
    assert surge_front(x[:1], 0.1) == x[0, 0] and surge_front(np.zeros((0, 3)), 0.1) == 0.0
    assert surge_front(np.array([[0, 0, 0], [9.0, 0, 0]]), 0.1) == 9.0  # no pair: the largest of all, finite


DAM_2D = """
[simulation]
dimension = 2
spacing = 0.025
dt = 0.001
duration = 0.15
fps = 20
[materials.water]
stiffness = 500.0
[[objects]]
material = "water"
shape = { type = "box", center = [0.125, 0.25, 0], size = [0.25, 0.5, 1] }
[[boundaries]]
type = "box"
min = [0, 0, 0]
max = [1, 1, 0]
"""


def test_dam_break_summary_records_the_front(tmp_path):
    spacing = 0.025
    scene = tmp_path / "dam.toml"
    scene.write_text(DAM_2D)
    sim, settings = build_simulation(load_scene(scene))
    run(sim, tmp_path / "out", settings, progress=False)
    tmp_path = tmp_path / "out"
    frames = json.loads((tmp_path / "summary.json").read_text())["frames"]
    fronts = [f["surge_front"] for f in frames]
    assert len(fronts) == 4 and fronts[0] == pytest.approx(0.25, abs=spacing)  # the column's face, x = a
    assert all(b > a for a, b in itertools.pairwise(fronts))
    last = io.load(tmp_path / "frames" / "frame_00003.ply").positions
    assert fronts[-1] == pytest.approx(surge_front(last, spacing), abs=1e-6)  # frames are float32
