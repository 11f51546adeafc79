"""VTU/PVD output, scene files, the ``unmesh fem`` command and the run contract."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from unmesh.errors import FormatError, SceneError, UnstableSimulationError
from unmesh.fem import cut_by_plane, hex_grid, voronoi_foam
from unmesh.fem.vtk_io import read_vtu, write_pvd, write_vtu


def test_vtu_round_trip_and_vtk_reader(tmp_path, rng):
    m = cut_by_plane(voronoi_foam(10, seed=3), (0.5, 0.5, 0.5), (1.0, 0.3, 0.2))
    u = rng.normal(size=(m.n_nodes, 3)) * 1e-3
    write_vtu(tmp_path / "a.vtu", m, u, point_data={"velocity": u}, cell_data={"flag": np.ones(m.n_elements)})
    back, pdata = read_vtu(tmp_path / "a.vtu")
    np.testing.assert_allclose(back.points, m.points, atol=1e-15)
    np.testing.assert_allclose(pdata["displacement"], u)
    np.testing.assert_allclose(back.volumes(), m.volumes(), rtol=1e-12)
    vtk = pytest.importorskip("vtk")
    write_vtu(tmp_path / "b.vtu", m)
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(tmp_path / "b.vtu"))
    r.Update()
    g = r.GetOutput()
    assert g.GetNumberOfCells() == m.n_elements and g.GetNumberOfPoints() == m.n_nodes
    assert {g.GetCellType(i) for i in range(m.n_elements)} == {42}
    from vtk.util.numpy_support import vtk_to_numpy

    cs = vtk.vtkCellSizeFilter()
    cs.SetInputData(g)
    cs.Update()
    vols = vtk_to_numpy(cs.GetOutput().GetCellData().GetArray("Volume"))
    np.testing.assert_allclose(vols, m.volumes(), rtol=1e-9)


def test_pvd_and_bad_files(tmp_path):
    write_pvd(tmp_path / "s.pvd", ["mesh_00000.vtu", "mesh_00001.vtu"], [0.0, 0.5])
    text = (tmp_path / "s.pvd").read_text()
    assert 'timestep="0.5"' in text and "mesh_00001.vtu" in text
    (tmp_path / "bad.vtu").write_text("<VTKFile type='PolyData'></VTKFile>")
    with pytest.raises(FormatError, match=r"bad\.vtu"):
        read_vtu(tmp_path / "bad.vtu")
    (tmp_path / "junk.vtu").write_text("not xml")
    with pytest.raises(FormatError, match=r"junk\.vtu"):
        read_vtu(tmp_path / "junk.vtu")


SCENE = """
[simulation]
dt = 0.01
duration = 0.2
fps = 20
[material]
young = 50
poisson = 0.3
[ground]
friction = 0.5
[[objects]]
mesh = { type = "hex_grid", cells = [2, 2, 2], origin = [0, 0.2, 0] }
[[cuts]]
type = "plane"
time = 0.0
origin = [0.5, 0.7, 0.5]
normal = [0.2, 1.0, 0.1]
[[cuts]]
type = "polygon"
time = 0.05
points = [[-1, 0.6, -1], [2, 0.6, -1], [2, 0.6, 2], [-1, 0.6, 2]]
"""


def test_cli_writes_the_contract_files(tmp_path, capsys):
    from unmesh.cli import main

    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    assert main(["fem", str(scene), "-o", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["nodes_initial"] == 27 and summary["elements_initial"] == 8
    keys = {"frame", "time", "nodes", "elements", "volume", "kinetic_energy", "elastic_energy", "solve_seconds",
            "reintegration_seconds"}
    assert len(summary["frames"]) == 5
    for f in summary["frames"]:
        assert keys <= set(f)
        assert f["volume"] == pytest.approx(1.0, abs=1e-9)
    assert summary["frames"][-1]["nodes"] > 27
    for k in range(5):
        assert (out / "frames" / f"mesh_{k:05d}.vtu").is_file() and (out / "frames" / f"surface_{k:05d}.ply").is_file()
    # the manifest lists every per-frame file; mesh.pvd (a static file) lists the vtu files relative to itself
    manifest = json.loads((out / "frames.json").read_text())
    assert manifest["static"] == ["mesh.pvd"]
    assert [e["files"] for e in manifest["frames"]] == \
        [[f"frames/mesh_{k:05d}.vtu", f"frames/surface_{k:05d}.ply"] for k in range(5)]
    pvd = (out / "mesh.pvd").read_text()
    assert pvd.count("<DataSet") == 5 and 'file="frames/mesh_00004.vtu"' in pvd
    assert not list(out.glob("*.vtu")) and not list(out.glob("surface_*.ply"))
    mesh, _ = read_vtu(out / "frames" / "mesh_00004.vtu", check=False)
    assert mesh.n_nodes == summary["frames"][-1]["nodes"]
    from unmesh import io

    surf = io.load_mesh(out / "frames" / "surface_00004.ply")
    assert len(surf.boundary_edges()) == 0
    # a fresh run into the used folder is refused without --force
    assert main(["fem", str(scene), "-o", str(out), "--no-progress"]) == 1
    assert "--force" in capsys.readouterr().err
    # --duration and --resume continue from the checkpoint
    assert main(["fem", str(scene), "-o", str(out), "--no-progress", "--duration", "0.3", "--resume"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["frames"]) == 7 and summary["frames"][-1]["time"] == pytest.approx(0.3)
    pvd = (out / "mesh.pvd").read_text()
    assert pvd.count("<DataSet") == 7 and 'file="frames/mesh_00006.vtu"' in pvd
    assert len(json.loads((out / "frames.json").read_text())["frames"]) == 7


@pytest.mark.parametrize(("patch", "message"), [
    ("young = 50\n", "young = -1\n"),
    ('type = "hex_grid"', 'type = "hexgrid"'),
    ("friction = 0.5", "fricton = 0.5"),
    ("origin = [0, 0.2, 0]", "origin = [0, -0.2, 0]"),
])
def test_scene_errors_name_the_key(tmp_path, patch, message):
    from unmesh.fem.scene import build_simulation
    from unmesh.scene import load_scene

    scene = tmp_path / "bad.toml"
    scene.write_text(SCENE.replace(patch, message))
    with pytest.raises(SceneError, match=r"bad\.toml"):
        build_simulation(load_scene(scene))


def test_nan_stops_the_run_with_the_last_good_frame(tmp_path):
    from unmesh.fem.dynamics import Dynamics
    from unmesh.fem.simulation import FemSimulation
    from unmesh.sim import RunSettings, run

    class Broken(FemSimulation):
        def step(self):
            dt = super().step()
            if self.time > 0.15:
                self.dyn.u[0, 0] = np.nan
            return dt

    sim = Broken(Dynamics(hex_grid((1, 1, 1)), 50.0, 0.3), dt=0.01)
    with pytest.raises(UnstableSimulationError, match="NaN"):
        run(sim, tmp_path, RunSettings(duration=0.5, fps=10), progress=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "unstable"
    assert summary["frames"][-1]["frame"] == 1
    assert (tmp_path / "frames" / "mesh_00001.vtu").is_file() and not (tmp_path / "frames" / "mesh_00002.vtu").exists()


SCENES = Path(__file__).resolve().parents[2] / "src" / "unmesh" / "scenes" / "fem"


@pytest.mark.parametrize("name", ["single_element", "random_planes_cube", "progressive_slicing", "cantilever",
                                  "blob_slicing"])
def test_shipped_scenes_build(name):
    from unmesh.fem.scene import build_simulation
    from unmesh.scene import load_scene

    overrides = {"simulation.duration": 0.05}
    if name == "blob_slicing":
        overrides["objects[0].mesh.spacing"] = 0.15
    sim, settings = build_simulation(load_scene(SCENES / f"{name}.toml", overrides))
    assert sim.dyn.mesh.n_elements >= 1 and settings.duration == 0.05


def test_cantilever_scene_settles_at_the_static_deflection(tmp_path):
    from unmesh.fem.scene import build_simulation
    from unmesh.scene import load_scene
    from unmesh.sim import run

    sim, settings = build_simulation(load_scene(SCENES / "cantilever.toml"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run(sim, tmp_path, settings, progress=False)
    tip = np.isclose(sim.dyn.mesh.points[:, 0], 10)
    deflection = -sim.dyn.u[tip, 1].mean()
    from unmesh.fem import solve_static

    m = sim.dyn.mesh
    f = np.zeros((m.n_nodes, 3))
    f[tip, 1] = -1.0 / tip.sum()
    static = -solve_static(m, 1e3, 0.3, np.flatnonzero(np.isclose(m.points[:, 0], 0)), f)[tip, 1].mean()
    assert deflection == pytest.approx(static, rel=1e-3)
    shutil.rmtree(tmp_path, ignore_errors=True)
