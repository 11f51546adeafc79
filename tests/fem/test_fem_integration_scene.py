"""Issue 22 item 3: the element integration rule as the scene key ``simulation.integration``,
taken by ``Dynamics`` and kept through cuts and checkpoints."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import SceneError
from unmesh.fem import solve_static
from unmesh.fem.assembly import element_stiffness
from unmesh.fem.hexcells import hex_cells
from unmesh.fem.scene import build_simulation
from unmesh.scene import load_scene
from unmesh.sim import run

SCENES = __import__("pathlib").Path(__file__).resolve().parents[2] / "src" / "unmesh" / "scenes" / "fem"
E, NU = 1e3, 0.3
KAPPA = 10 * (1 + NU) / (12 + 11 * NU)
TIMOSHENKO = 4.0 + 10.0 / (KAPPA * E / (2 * (1 + NU)))  # 4.0306

CUT = """
[simulation]
dt = 0.01
duration = 0.01
gravity = [0, 0, 0]
integration = "{rule}"
[material]
young = 1000.0
[[objects]]
mesh = {{ type = "hex_grid", cells = [2, 1, 1], size = [2, 1, 1] }}
[[cuts]]
type = "plane"
origin = [0.5, 0.5, 0.5]
normal = {normal}
"""


def _cantilever(rule: str, cells: list[int], tmp_path) -> tuple[float, object]:
    sim, settings = build_simulation(load_scene(SCENES / "cantilever.toml", {"simulation.integration": rule,
                                                                            "objects[0].mesh.cells": cells}))
    run(sim, tmp_path, settings, progress=False)
    tip = np.isclose(sim.dyn.mesh.points[:, 0], 10)
    return float(-sim.dyn.u[tip, 1].mean()), sim


def test_integration_key_reaches_the_dynamics(tmp_path):
    d, sim = _cantilever("incompatible", [20, 2, 2], tmp_path)
    assert sim.dyn.rule.kind == "incompatible"
    m = sim.dyn.mesh
    tip = np.isclose(m.points[:, 0], 10)
    f = np.zeros((m.n_nodes, 3))
    f[tip, 1] = -1.0 / tip.sum()  # the scene splits the load evenly
    static = -solve_static(m, E, NU, np.flatnonzero(np.isclose(m.points[:, 0], 0)), f, rule="incompatible")
    assert d == pytest.approx(static[tip, 1].mean(), rel=1e-3)
    assert d == pytest.approx(TIMOSHENKO, rel=0.015)  # the thesis rule gives 2.79 on 20x2x2


@pytest.mark.parametrize(("value", "message"), [
    ('"simpson"', r"key 'simulation\.integration': integration: expected one of thesis, subtet, trilinear, "
                  r"incompatible, got 'simpson'"),
    ('"subtet:x"', r"key 'simulation\.integration': integration: expected 'kind' or 'kind:order'"),
    ("2", r"key 'simulation\.integration': expected a string, got"),
])
def test_bad_integration_values_name_the_key(tmp_path, value, message):
    p = tmp_path / "c.toml"
    p.write_text(CUT.format(rule="thesis", normal="[1, 0, 0]").replace('"thesis"', value))
    with pytest.raises(SceneError, match=r"c\.toml: " + message):
        build_simulation(load_scene(p))


@pytest.mark.parametrize(("normal", "hexes"), [("[1, 0, 0]", 3), ("[1, 0.3, 0.2]", 3), ("[1, 1, 1]", 0)])
def test_after_a_cut_incompatible_stiffness_is_rebuilt_from_the_mesh(tmp_path, normal, hexes):
    """A cut that leaves hexahedra (boxes, or slanted ones) gives them the incompatible stiffness of
    the cut mesh; pieces that are no hexahedra (a cut through the diagonal) get the thesis rule."""
    p = tmp_path / "c.toml"
    p.write_text(CUT.format(rule="incompatible", normal=normal))
    sim, _ = build_simulation(load_scene(p))
    sim.step()
    dyn = sim.dyn
    mesh = dyn.mesh
    assert mesh.n_elements in (3, 4) and dyn._pending is None
    is_hex = hex_cells(mesh)[0]
    full = element_stiffness(mesh, E, NU, rule="incompatible")
    thesis = element_stiffness(mesh, E, NU, rule="thesis")
    for e in range(mesh.n_elements):
        want = full if is_hex[e] else thesis
        np.testing.assert_allclose(dyn.kstiff.matrix(e), want.matrix(e), rtol=1e-12, atol=1e-9)
    assert int(is_hex.sum()) == hexes
    # the incompatible cells differ from the thesis rule's (the rule really changed them)
    for h in np.flatnonzero(is_hex):
        assert not np.allclose(full.matrix(h), thesis.matrix(h))


def test_checkpoint_keeps_the_rule(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text(CUT.format(rule="incompatible", normal="[1, 0, 0]"))
    sim, _ = build_simulation(load_scene(p))
    state = sim.state_dict()
    sim.load_state_dict(state)
    assert sim.dyn.rule.kind == "incompatible"


@pytest.mark.slow
def test_cantilever_scene_with_incompatible_modes_is_within_2_percent_of_timoshenko(tmp_path):
    """60×6×6 cube cells: 3.9974 (−0.83 %) against 3.809 (−5.5 %) with the thesis rule."""
    d, _ = _cantilever("incompatible", [60, 6, 6], tmp_path)
    assert d == pytest.approx(TIMOSHENKO, rel=0.02)
