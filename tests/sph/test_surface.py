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


def test_fluid_surface_is_closed_manifold_and_at_the_iso_level():
    """The density surface of a fluid ball: closed, oriented, a sphere, vertices at ρ = level·ρ0 exactly.

    Since marching cubes moved to :func:`unmesh.meshes.marching_cubes` the vertices are placed by
    float64 interpolation of the grid values (scikit-image's own interpolation works in float32);
    the triangulation is unchanged.
    """
    from tests.meshes.test_marching import closed_and_oriented, euler_characteristic, trilinear
    from unmesh.sph.sampling import closest_packing
    from unmesh.sph.surface import density_grid, fluid_surface

    d = 0.02
    ball = closest_packing([-0.2] * 3, [0.2] * 3, d, 3)
    ball = ball[np.linalg.norm(ball, axis=1) < 0.15]
    m = np.full(len(ball), d**3 / np.sqrt(2))
    for level in (0.5, 0.3):
        mesh = fluid_surface(ball, m, rest_density=1.0, h=2 * d, level=level)
        assert closed_and_oriented(mesh) and euler_characteristic(mesh) == 2
        assert mesh.volume() > 0
        step = 2 * d / 4
        grid, lower = density_grid(ball, m, 2 * d, step)
        rho = trilinear(np.pad(grid, 1), lower - step, step, mesh.vertices)
        assert np.abs(rho - level).max() < 1e-12
        radii = np.linalg.norm(mesh.vertices, axis=1)
        assert abs(np.median(radii) - 0.15) < 0.02
