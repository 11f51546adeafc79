"""SPH surfaces: the surface module stays below the simulation; marching cubes of the density field."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import unmesh.sph.surface as surface_module


def _imported_modules(path: Path) -> set[str]:
    """Every module named by an import statement anywhere in ``path`` (TYPE_CHECKING blocks included)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_surface_module_does_not_import_the_simulation():
    names = _imported_modules(Path(surface_module.__file__))
    assert not any(n == "unmesh.sph.simulation" or n.startswith("unmesh.sph.simulation.") for n in names)
    assert "unmesh.sph.SPHSimulation" not in names


def test_deprecated_write_surfaces_forwards_to_the_simulation(tmp_path):
    calls = []

    class FakeSim:
        def write_surfaces(self, outdir, frame):
            calls.append((outdir, frame))

    with pytest.warns(DeprecationWarning, match="sim.write_surfaces"):
        surface_module.write_surfaces(FakeSim(), tmp_path, 3)
    assert calls == [(tmp_path, 3)]


def test_empty_and_subcritical_density_give_empty_meshes():
    assert len(surface_module.fluid_surface(np.zeros((0, 3)), np.zeros(0), 1.0, 0.1).faces) == 0
    mesh = surface_module.fluid_surface([[0.0, 0, 0]], [1e-9], rest_density=1.0, h=0.1)
    assert len(mesh.faces) == 0 and len(mesh.vertices) == 0
