"""batch.csv figures, batch.json versions, the --plot figure, and frames rendered in parallel."""

from __future__ import annotations

import filecmp
import json
import os
from pathlib import Path

import numpy as np
import pytest

from unmesh.batch import load_manifest, plot_metric, write_csv
from unmesh.batch.manifest import flatten_figures, versions, write_manifest
from unmesh.batch.plot import metric_table
from unmesh.errors import FormatError, InputError


def _fake_batch(tmp_path: Path) -> Path:
    """A batch of 6 done tasks (viscosity x spacing) with summaries whose front = 1 - viscosity."""
    out = tmp_path / "out"
    tasks = []
    for v in (0.0, 0.01, 0.05):
        for s in (0.02, 0.015):
            tid = f"v{v}_s{s}"
            (out / tid).mkdir(parents=True)
            summary = {"status": "completed", "steps": 10, "frames": [{"frame": 0, "front": 0.0},
                                                                       {"frame": 5, "front": 1.0 - v, "m": [1, 2]}]}
            (out / tid / "summary.json").write_text(json.dumps(summary))
            tasks.append({"id": tid, "parameters": {"materials.water.viscosity": v, "simulation.spacing": s},
                          "input": None, "status": "done", "error": None, "wall_seconds": 1.5, "worker": "w",
                          "output": os.fspath(out / tid), "figures": {}})
    tasks.append({"id": "broken", "parameters": {"materials.water.viscosity": 0.5, "simulation.spacing": 0.02},
                  "input": None, "status": "failed", "error": "ValueError: boom", "wall_seconds": None,
                  "worker": None, "output": None, "figures": {}})
    write_manifest(out, {"versions": versions(), "command": "sph", "tasks": tasks})
    return out


def test_versions_name_the_libraries():
    v = versions()
    import numba
    import numpy

    assert v["numpy"] == numpy.__version__ and v["numba"] == numba.__version__
    assert {"unmesh", "dask", "distributed", "python"} <= set(v)


def test_flatten_figures_takes_scalars_and_the_last_frame():
    figs = flatten_figures({"status": "completed", "message": "", "objects": ["a"], "pieces": 3,
                            "frames": [{"frame": 0}, {"frame": 2, "energy": {"kinetic": 0.5}, "p": [1.0, 2.0]}]})
    assert figs == {"run_status": "completed", "run_message": "", "pieces": 3, "final.frame": 2,
                    "final.energy.kinetic": 0.5, "final.p.0": 1.0, "final.p.1": 2.0}


def test_csv_has_parameters_and_summary_figures(tmp_path):
    out = _fake_batch(tmp_path)
    write_csv(out, load_manifest(out))
    lines = (out / "batch.csv").read_text().splitlines()
    head = lines[0].split(",")
    assert head[:6] == ["id", "status", "materials.water.viscosity", "simulation.spacing", "wall_seconds", "worker"]
    assert {"final.front", "steps", "final.m.0"} <= set(head)
    row = dict(zip(head, lines[3].split(","), strict=True))
    assert row["id"] == "v0.01_s0.02" and float(row["final.front"]) == 0.99
    assert lines[-1].startswith("broken,failed,0.5,0.02,,,ValueError: boom")


def test_plot_against_a_swept_parameter(tmp_path):
    out = _fake_batch(tmp_path)
    mkey, key, lines = metric_table(out, "front", "viscosity")
    assert (mkey, key) == ("final.front", "materials.water.viscosity")
    assert sorted(lines) == ["spacing=0.015", "spacing=0.02"]
    assert sorted(lines["spacing=0.02"]) == [(0.0, 1.0), (0.01, 0.99), (0.05, 0.95)]
    pytest.importorskip("matplotlib")
    from PIL import Image

    path = plot_metric(out, "final.front", "viscosity", tmp_path / "plot.png")
    with Image.open(path) as im:
        assert im.size[0] > 300 and im.size[1] > 200
        assert len(np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)) > 10


def test_plot_errors_name_the_choices(tmp_path):
    out = _fake_batch(tmp_path)
    with pytest.raises(InputError, match=r"--against: no 'density'.*materials\.water\.viscosity"):
        metric_table(out, "front", "density")
    with pytest.raises(InputError, match="--plot: no 'nothing'"):
        metric_table(out, "nothing", "viscosity")
    with pytest.raises(InputError, match=r"no batch\.json"):
        metric_table(tmp_path, "front", "viscosity")
    (tmp_path / "batch.json").write_text("{")
    with pytest.raises(FormatError, match="not a batch manifest"):
        load_manifest(tmp_path)


def test_plot_command_line(tmp_path):
    pytest.importorskip("matplotlib")
    from unmesh.cli import main

    out = _fake_batch(tmp_path)
    assert main(["batch", "--plot", "front", "--against", "spacing", os.fspath(out), "-o",
                 os.fspath(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").stat().st_size > 1000


def test_frames_rendered_on_two_workers_equal_serial_render(tmp_path, client):
    from unmesh import Particles, io
    from unmesh.render.parallel import render_sequence_parallel
    from unmesh.render.sequence import render_sequence

    sim = tmp_path / "sim"
    rng = np.random.default_rng(3)
    for k in range(5):
        pts = rng.random((40, 3)) * [1, 1, 0] + [0.1 * k, 0, 0]
        io.save(sim / "frames" / f"frame_{k:05d}.ply", Particles(pts, attributes={"density": rng.random(40)}))
    io.save(sim / "boundary.ply", Particles(rng.random((30, 3)) * [2, 0.05, 0]))
    serial = render_sequence(sim, tmp_path / "serial", width=48, height=32, color_by="density", progress=False)
    par = render_sequence_parallel(sim, tmp_path / "par", client=client, width=48, height=32, color_by="density",
                                   progress=False)
    names = sorted(p.name for p in serial.iterdir())
    assert len(names) == 5 and names == sorted(p.name for p in par.iterdir())
    for name in names:
        assert filecmp.cmp(serial / name, par / name, shallow=False), name
    gif_a = render_sequence(sim, tmp_path / "a.gif", width=48, height=32, progress=False)
    gif_b = render_sequence_parallel(sim, tmp_path / "b.gif", client=client, width=48, height=32, progress=False)
    assert gif_a.read_bytes() == gif_b.read_bytes()


def test_render_command_line_with_a_scheduler(tmp_path, client, capsys):
    from unmesh import Particles, io
    from unmesh.cli import main

    sim = tmp_path / "sim"
    for k in range(3):
        io.save(sim / "frames" / f"frame_{k:05d}.ply", Particles([[0.1 * k, 0, 0], [0, 0.2, 0], [0.3, 0.1, 0]]))
    args = ["render", os.fspath(sim), "--size", "40x30", "--no-progress"]
    assert main([*args, "-o", os.fspath(tmp_path / "serial")]) == 0
    assert main([*args, "-o", os.fspath(tmp_path / "par"), "--scheduler", client.scheduler.address]) == 0
    for k in range(3):
        name = f"frame_{k:05d}.png"
        assert filecmp.cmp(tmp_path / "serial" / name, tmp_path / "par" / name, shallow=False)
    assert main(["render", os.fspath(sim / "frames" / "frame_00000.ply"), "-o", os.fspath(tmp_path / "a.png"),
                 "--workers", "2"]) == 1
    assert "--workers/--scheduler: only for frame sequences" in capsys.readouterr().err


@pytest.mark.parametrize("folder", ["src/unmesh/scenes/batch", "examples/batch"])
def test_shipped_dam_break_sweep_plots_the_surge_front(tmp_path, folder):
    """The sweep's plot line names the SPH summary's ``surge_front`` (final.surge_front in batch.csv)."""
    import re
    import shlex

    from unmesh.batch.sweep import load_sweep

    path = Path(__file__).resolve().parents[2] / folder / "dam_break_viscosity.toml"
    sweep = load_sweep(path)
    assert sweep.command == "sph" and sweep.duration == 0.3 and sweep.scene.is_file()
    plot = shlex.split(re.search(r"# Plot: +(unmesh batch .*)", path.read_text()).group(1))
    metric, against = plot[plot.index("--plot") + 1], plot[plot.index("--against") + 1]
    out = _fake_batch(tmp_path)
    for rec in load_manifest(out)["tasks"][:-1]:
        f = out / rec["id"] / "summary.json"
        summary = json.loads(f.read_text())
        summary["frames"][-1]["surge_front"] = 1.0 - rec["parameters"]["materials.water.viscosity"]
        f.write_text(json.dumps(summary))
    mkey, key, lines = metric_table(out, metric, against)
    assert (mkey, key) == ("final.surge_front", "materials.water.viscosity")
    assert sorted(lines["spacing=0.02"]) == [(0.0, 1.0), (0.01, 0.99), (0.05, 0.95)]
