"""Fuzzing the loaders (issue 24): mutated PLY, OBJ/MTL, OFF, VTU, PVD, scene and checkpoint files
raise only the documented errors and write nothing.

The default suite runs a few hundred seeded mutations per format (the whole file takes
well under a minute); ``-m slow`` runs thousands. The mutator is :mod:`tests.fuzz.mutate`.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.fuzz.mutate import mutate
from unmesh.errors import FormatError, InputError, SceneError, SimulationError

FEM_SCENE = b"""
[simulation]
dt = 0.01
duration = 0.1
fps = 30
[material]
young = 50
poisson = 0.3
density = 1000
[ground]
height = 0.0
[[objects]]
mesh = { type = "hex_grid", cells = [1, 1, 2], size = [1, 1, 1], origin = [0, 0.5, 0] }
velocity = [0, -1, 0]
[[boundary]]
select = { box = [[-0.01, 0.49, -0.01], [1.01, 0.51, 1.01]] }
velocity = [0, 0, 0]
stop = "off"
[[loads]]
select = { nodes = [0, 5, 7] }
force = [0, -1, 0]
"""

SPH_SCENE = b"""
[simulation]
dimension = 2
spacing = 0.1
dt = 0.001
duration = 0.1
[materials.water]
stiffness = 500.0
fracture_stretch = "off"
[[objects]]
material = "water"
shape = { type = "box", center = [0.25, 0.25, 0], size = [0.5, 0.5, 1] }
velocity = [0, 0, 0]
[[boundaries]]
type = "box"
min = [0, 0, 0]
max = [1, 1, 0]
"""


def _seeds(tmp: Path) -> dict[str, bytes]:
    from unmesh import io
    from unmesh.meshes import TriangleMesh
    from unmesh.particles import Particles
    from unmesh.surfels import SurfelCloud

    rng = np.random.default_rng(0)
    mesh = TriangleMesh(rng.random((6, 3)), [[0, 1, 2], [2, 3, 4], [4, 5, 0], [1, 3, 5]], uv=rng.random((6, 2)),
                        vertex_colors=rng.random((6, 3)))
    cloud = SurfelCloud(rng.random((5, 3)), np.tile([0, 0, 1.0], (5, 1)), radii=np.full(5, 0.1))
    parts = Particles(rng.random((4, 3)), attributes={"density": rng.random(4), "id": np.arange(4, dtype=np.int64)})
    out = {}
    for name, obj, binary in [("mesh_ascii.ply", mesh, False), ("mesh_binary.ply", mesh, True),
                              ("surfels_ascii.ply", cloud, False), ("surfels_binary.ply", cloud, True),
                              ("particles.ply", parts, True), ("mesh.obj", mesh, True), ("mesh.off", mesh, True)]:
        io.save(tmp / name, obj, binary=binary)
        out[name] = (tmp / name).read_bytes()
    out["materials.obj"] = (b"mtllib m.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 1\nvn 0 0 1\n"
                            b"f 1/1/1 2/2/1 3/1/1\nusemtl b\nf -1//1 -2//1 -3//1 4//1\n")
    return out


def _check(tmp: Path, data: bytes, name: str, load: Callable[[Path], object], allowed: tuple[type, ...]) -> None:
    sub = tmp / "case"
    sub.mkdir(exist_ok=True)
    for extra in ("m.mtl",):
        (sub / extra).write_text("newmtl a\nKd 1 0 0\nmap_Kd missing.png\nnewmtl b\nKd 0 1 0\n")
    p = sub / name
    p.write_bytes(data)
    before = sorted(os.listdir(sub))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            load(p)
        except allowed:
            pass
        except Exception as exc:  # pragma: no cover - the failure report
            raise AssertionError(f"{name}: undocumented {type(exc).__name__}: {exc!s:.300}\n"
                                 f"input (first 400 bytes): {data[:400]!r}") from exc
    assert sorted(os.listdir(sub)) == before, "a loader wrote files"


def _load_any(p: Path) -> object:
    from unmesh import io

    return io.load(p)


def _load_vtu(p: Path) -> object:
    from unmesh.fem.vtk_io import read_vtu

    return read_vtu(p)


def _build(kind: str) -> Callable[[Path], object]:
    def build(p: Path) -> object:
        from unmesh.scene import load_scene

        if kind == "fem":
            from unmesh.fem.scene import build_simulation
        else:
            from unmesh.sph.scene import build_simulation
        return build_simulation(load_scene(p))
    return build


def _load_checkpoint(p: Path) -> object:
    from unmesh.sim.checkpoint import load_checkpoint

    state, meta = load_checkpoint(p)
    state["points"]  # a key another simulation would ask for
    return meta


LOADER_ERRORS = (FormatError, InputError)


def _fuzz_files(tmp_path: Path, count: int, seed: int) -> None:
    seeds = _seeds(tmp_path)
    rng = np.random.default_rng(seed)
    for name, data in seeds.items():
        for _ in range(count):
            _check(tmp_path, mutate(data, rng), name, _load_any, LOADER_ERRORS)


def _fuzz_vtu(tmp_path: Path, count: int, seed: int) -> None:
    from unmesh.fem import hex_grid
    from unmesh.fem.vtk_io import write_vtu

    write_vtu(tmp_path / "m.vtu", hex_grid((2, 1, 1)), displacement=np.full((12, 3), 0.01))
    data = (tmp_path / "m.vtu").read_bytes()
    rng = np.random.default_rng(seed)
    for _ in range(count):
        _check(tmp_path, mutate(data, rng), "m.vtu", _load_vtu, (FormatError,))


def _load_pvd(p: Path) -> object:
    from unmesh.fem.vtk_io import read_series

    return list(read_series(p))


def _fuzz_pvd(tmp_path: Path, count: int, seed: int) -> None:
    from unmesh.fem import hex_grid
    from unmesh.fem.vtk_io import write_pvd, write_vtu

    case = tmp_path / "case"
    case.mkdir(exist_ok=True)
    for k in range(2):  # the series' frames sit next to the mutated .pvd
        write_vtu(case / f"m{k}.vtu", hex_grid((k + 1, 1, 1)))
    write_pvd(tmp_path / "s.pvd", ["m0.vtu", "m1.vtu"], [0.0, 0.25])
    data = (tmp_path / "s.pvd").read_bytes()
    rng = np.random.default_rng(seed)
    for _ in range(count):
        _check(tmp_path, mutate(data, rng), "s.pvd", _load_pvd, (FormatError,))


def _fuzz_scenes(tmp_path: Path, count: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    for kind, data, n in (("fem", FEM_SCENE, count), ("sph", SPH_SCENE, max(1, count // 2))):
        for _ in range(n):
            _check(tmp_path, mutate(data, rng), f"{kind}.toml", _build(kind), (SceneError,))


def _fuzz_checkpoints(tmp_path: Path, count: int, seed: int) -> None:
    from unmesh.sim.checkpoint import save_checkpoint

    save_checkpoint(tmp_path / "c.npz", {"points": np.zeros((3, 3)), "time": 0.5},
                    {"frame": 3, "steps": 30, "wall_seconds": 1.0, "frames": [{"frame": 0}]})
    data = (tmp_path / "c.npz").read_bytes()
    rng = np.random.default_rng(seed)
    for _ in range(count):
        _check(tmp_path, mutate(data, rng), "checkpoint.npz", _load_checkpoint, (SimulationError,))


@pytest.fixture(autouse=True)
def _small_budget(monkeypatch):
    # keeps fuzzed sizes cheap: anything needing more than 64 MiB is refused up front
    monkeypatch.setenv("UNMESH_MEMORY_BUDGET", "64M")


def test_fuzz_mesh_and_point_files(tmp_path):
    _fuzz_files(tmp_path, 150, seed=1)


def test_fuzz_vtu(tmp_path):
    _fuzz_vtu(tmp_path, 200, seed=2)


def test_fuzz_pvd(tmp_path):
    _fuzz_pvd(tmp_path, 150, seed=5)


def test_fuzz_scenes(tmp_path):
    _fuzz_scenes(tmp_path, 120, seed=3)


def test_fuzz_checkpoints(tmp_path):
    _fuzz_checkpoints(tmp_path, 200, seed=4)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12])
def test_fuzz_many(tmp_path, seed):
    _fuzz_files(tmp_path, 1500, seed=seed)
    _fuzz_vtu(tmp_path, 1500, seed=seed)
    _fuzz_pvd(tmp_path, 1000, seed=seed)
    _fuzz_checkpoints(tmp_path, 1500, seed=seed)
    _fuzz_scenes(tmp_path, 500, seed=seed)
