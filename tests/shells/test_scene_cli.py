"""Scene files, the ``unmesh shell`` command, output contract and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from unmesh.errors import SceneError
from unmesh.scene import load_scene
from unmesh.shells.scene import build_simulation

SHEET = """
[simulation]
dt = 0.001
fps = 25
duration = 0.08
gravity = [0.0, -9.81, 0.0]

[surface]
shape = {{ type = "plane", size = [1.0, 1.0], normal = [0.0, 1.0, 0.0], center = [0.0, 1.0, 0.0] }}
spacing = 0.05
nodes = {nodes}
neighbors = 12

[material]
ks = 100.0
kb = 10.0
damping = 1.0
{extra}

[[pinned]]
region = {{ type = "box", center = [-0.5, 1.0, 0.0], size = [0.3, 0.2, 1.2] }}
"""


def write(tmp_path, nodes=60, extra="", name="sheet.toml"):
    p = tmp_path / name
    p.write_text(SHEET.format(nodes=nodes, extra=extra))
    return p


def test_cli_writes_the_documented_outputs(tmp_path):
    from unmesh import io
    from unmesh.cli import main

    scene = write(tmp_path)
    out = tmp_path / "out"
    assert main(["shell", str(scene), "-o", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert {"nodes", "surfels", "fibers_initial", "frames"} <= set(summary)
    assert summary["nodes"] == 60 and summary["surfels"] == 400
    frame = summary["frames"][-1]
    for key in ("frame", "time", "kinetic_energy", "elastic_energy", "linear_momentum", "fibers", "cracks",
                "components", "force_seconds", "fracture_seconds", "surface_seconds"):
        assert key in frame
    assert len(frame["linear_momentum"]) == 3 and frame["components"] == 1 and frame["cracks"] == 0
    assert len(summary["frames"]) == 3   # frames 0, 1, 2 at 25 fps over 0.08 s
    cloud = io.load(out / "frames" / "frame_00002.ply")
    assert len(cloud) == 400 and "discontinuity" in cloud.attributes
    nodes = io.load(out / "nodes" / "frame_00002.ply")
    assert len(nodes) == 60 and {"vx", "vy", "vz"} <= set(nodes.attributes)
    header = (out / "frames" / "frame_00002.ply").read_bytes()[:600].decode("latin-1")
    for prop in ("x", "y", "z", "nx", "ny", "nz", "radius", "red", "green", "blue", "discontinuity"):
        assert f" {prop}\n" in header
    assert (out / "fibers" / "frame_00002.npz").exists()
    manifest = json.loads((out / "frames.json").read_text())
    assert manifest["static"] == [] and manifest["fps"] == 25
    assert [e["files"] for e in manifest["frames"]] == [
        [f"frames/frame_{k:05d}.ply", f"nodes/frame_{k:05d}.ply", f"fibers/frame_{k:05d}.npz"] for k in range(3)]
    # the sheet sags under gravity
    assert cloud.positions[:, 1].min() < 1.0


def test_resume_continues_a_run(tmp_path):
    from unmesh.shells.cli import _build
    from unmesh.sim.cli import run_scene

    scene = write(tmp_path)
    out = tmp_path / "out"
    run_scene(scene, out, _build, duration=0.04, progress=False)
    r = run_scene(scene, out, _build, duration=0.08, resume=True, progress=False)
    direct = run_scene(scene, tmp_path / "direct", _build, duration=0.08, progress=False)
    a = json.loads((out / "summary.json").read_text())["frames"][-1]
    b = json.loads((tmp_path / "direct" / "summary.json").read_text())["frames"][-1]
    assert r.frames == 2
    assert a["kinetic_energy"] == pytest.approx(b["kinetic_energy"], rel=1e-9)
    assert direct.status == "completed"


def test_scene_errors_name_file_and_key(tmp_path):
    with pytest.raises(SceneError, match=r"sheet.toml: unknown key 'material.stifness'"):
        build_simulation(load_scene(write(tmp_path, extra="stifness = 3")))
    with pytest.raises(SceneError, match=r"sheet.toml: key 'surface.nodes': expected fewer simulation nodes"):
        build_simulation(load_scene(write(tmp_path, nodes=5000)))
    with pytest.raises(SceneError, match="at least 10 simulation nodes"):
        build_simulation(load_scene(write(tmp_path, nodes=4)))
    with pytest.raises(SceneError, match=r"material\.fracture\.gamma_s"):
        build_simulation(load_scene(write(tmp_path, extra="[material.fracture]\ngamma_s = -1")))


def test_disconnected_input_is_rejected(tmp_path):
    from unmesh import io
    from unmesh.shapes import Sphere
    from unmesh.surfels import SurfelCloud

    a = Sphere(radius=0.5).surfels(0.05)
    b = a.transformed(np.array([[1, 0, 0, 5.0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    io.save(tmp_path / "two.ply", SurfelCloud.concatenate([a, b]))
    scene = tmp_path / "two.toml"
    scene.write_text('[simulation]\ndt = 0.001\nduration = 0.1\n[surface]\nsurfels = "two.ply"\nnodes = 200\n'
                     '[material]\nks = 1.0\nkb = 1.0\n')
    with pytest.raises(SceneError, match="disconnected"):
        build_simulation(load_scene(scene))


def test_non_manifold_mesh_is_rejected(tmp_path):
    from unmesh import io
    from unmesh.meshes import TriangleMesh

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]])
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])   # three triangles share the edge 0-1
    io.save(tmp_path / "fin.obj", TriangleMesh(v, f))
    scene = tmp_path / "fin.toml"
    scene.write_text('[simulation]\ndt = 0.001\nduration = 0.1\n[surface]\nshape = { file = "fin.obj" }\n'
                     'spacing = 0.02\nnodes = 50\n[material]\nks = 1.0\nkb = 1.0\n')
    with pytest.raises(SceneError, match="non-manifold"):
        build_simulation(load_scene(scene))


@pytest.mark.parametrize("name", ["elastic_drop", "plastic_drop", "tearing_poster", "balloon", "hanging_sheet"])
def test_shipped_scenes_build(name):
    from unmesh.scenes import path

    sim, settings = build_simulation(load_scene(path(f"shells/{name}.toml"), {
        "surface.nodes": 150, "surface.spacing": {"elastic_drop": 1.0, "plastic_drop": 1.2, "tearing_poster": 0.8,
                                                 "balloon": 0.8, "hanging_sheet": 0.03}[name]}))
    assert len(sim.rest) == 150 and settings.duration > 0
