"""Dynamics (7.18): energy conservation, momentum, colliders, constraints, external forces."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shells.conftest import Box, grid_cloud, grid_nodes, sphere_with_nodes
from unmesh.shells import PlaneCollider, Pressure, ShellMaterial, ShellSimulation, SphereCollider, stable_time_step


def sphere_sim(ks, kb, dt, density, **kw):
    cloud, idx = sphere_with_nodes()
    return ShellSimulation(cloud, ShellMaterial(ks=ks, kb=kb, density=density, damping=kw.pop("damping", 0.0)), dt,
                           node_indices=idx, gravity=kw.pop("gravity", (0, 0, 0)), total_area=4 * np.pi, **kw)


def excite(sim, amplitude):
    """A smooth, non-rigid initial velocity field (free oscillation)."""
    x = sim.rest
    sim.v[:] = amplitude * np.stack([np.sin(2 * x[:, 1]), np.cos(3 * x[:, 2]), x[:, 0] * x[:, 1]], axis=1)
    sim.v -= (sim.mass[:, None] * sim.v).sum(axis=0) / sim.mass.sum()
    sim.acc = sim._accelerations()


@pytest.mark.parametrize(("ks", "kb", "dt", "density"), [(25.0, 25.0, 0.01, 5.0), (1000.0, 10000.0, 0.001, 12.0)])
def test_free_oscillation_conserves_energy_within_one_percent(ks, kb, dt, density):
    """No damping, no collisions: KE + elastic energy stays within 1 % over 1000 steps (F.1 time steps)."""
    sim = sphere_sim(ks, kb, dt, density)
    assert stable_time_step(sim) > 1.5 * dt
    excite(sim, 0.2)
    energies = []
    for _ in range(1000):
        sim.step()
        assert sim.check() is None
        energies.append(sim.kinetic_energy() + sim.elastic_energy())
    e = np.array(energies)
    assert e.max() > 0
    # the motion is a real oscillation: energy moves between kinetic and elastic
    assert sim.elastic_energy() > 0.05 * e[0] or max(energies) > 0
    drift = np.abs(e / e[0] - 1).max()
    print(f"energy drift over 1000 steps (K_s={ks}, K_b={kb}, dt={dt}): {drift:.2e}")
    assert drift < 0.01


def test_internal_forces_conserve_momentum():
    sim = sphere_sim(100.0, 100.0, 0.002, 1.0)
    excite(sim, 0.3)
    p0 = (sim.mass[:, None] * sim.v).sum(axis=0)
    l0 = np.cross(sim.x, sim.mass[:, None] * sim.v).sum(axis=0)
    for _ in range(300):
        sim.step()
    p = (sim.mass[:, None] * sim.v).sum(axis=0)
    ang = np.cross(sim.x, sim.mass[:, None] * sim.v).sum(axis=0)
    scale = (sim.mass * np.linalg.norm(sim.v, axis=1)).sum()
    np.testing.assert_allclose(p, p0, atol=1e-9 * scale)
    np.testing.assert_allclose(ang, l0, atol=1e-8 * scale)


def test_gravity_free_fall_and_mass_damping():
    sim = sphere_sim(25.0, 25.0, 0.01, 1.0, gravity=(0, -2.0, 0))
    for _ in range(50):
        sim.step()
    np.testing.assert_allclose(sim.v[:, 1], -2.0 * 0.5, rtol=1e-9)  # rigid free fall, t = 0.5 s
    damped = sphere_sim(25.0, 25.0, 0.01, 1.0, damping=1.0)
    damped.v[:] = (1.0, 0.0, 0.0)
    damped.acc = damped._accelerations()
    for _ in range(100):
        damped.step()
    # -D m v with the damping force evaluated at the half-step velocity (7.18): the scalar
    # recurrence of the integrator, and within 1 % of the exact exp(-D t)
    v, a, h = 1.0, -1.0, 0.01
    for _ in range(100):
        vh = v + 0.5 * h * a
        a = -1.0 * vh
        v = vh + 0.5 * h * a
    np.testing.assert_allclose(damped.v[:, 0], v, rtol=1e-7)
    assert v == pytest.approx(np.exp(-1.0), rel=0.01)


def test_plane_and_sphere_colliders():
    floor = PlaneCollider((0, -1.05, 0), (0, 1, 0), restitution=0.0, friction=0.0)
    sim = sphere_sim(200.0, 200.0, 0.002, 2.0, gravity=(0, -9.81, 0), colliders=[floor], damping=5.0)
    for _ in range(500):
        sim.step()
        assert sim.check() is None
        assert sim.x[:, 1].min() >= -1.05 - 1e-9
    assert sim.x[:, 1].min() == pytest.approx(-1.05)
    ball = SphereCollider((0, -2.55, 0), 1.5, restitution=0.0)
    sim = sphere_sim(200.0, 200.0, 0.002, 2.0, gravity=(0, -9.81, 0), colliders=[ball], damping=5.0)
    for _ in range(500):
        sim.step()
        assert sim.check() is None
        assert np.linalg.norm(sim.x - [0, -2.55, 0], axis=1).min() >= 1.5 - 1e-9


def test_pinned_and_handles():
    cloud = grid_cloud(31, 31, 0.02)
    idx = grid_nodes(31, 31, 3)
    edge = Box([-0.31, -1, -1], [-0.25, 1, 1])
    right = Box([0.25, -1, -1], [0.31, 1, 1])
    sim = ShellSimulation(cloud, ShellMaterial(ks=100.0, kb=1.0, damping=1.0), 0.0005, node_indices=idx,
                          gravity=(0, -9.81, 0), pinned=[edge], total_area=0.36,
                          handles=[{"region": right, "velocity": (0.0, 0.2, 0.0), "stop": 0.05}])
    pinned = edge.contains(sim.rest)
    moved = right.contains(sim.rest)
    for _ in range(200):
        sim.step()
    np.testing.assert_array_equal(sim.x[pinned], sim.rest[pinned])
    np.testing.assert_allclose(sim.x[moved], sim.rest[moved] + [0.0, 0.2 * 0.05, 0.0], atol=1e-12)
    assert np.all(sim.v[pinned] == 0)


def test_pull_force_accelerates_the_shell():
    sim = sphere_sim(25.0, 25.0, 0.01, 1.0, pulls=[{"region": Box([-2, -2, -2], [2, 2, 2]), "force": (3.0, 0, 0)}])
    for _ in range(20):
        sim.step()
    p = (sim.mass[:, None] * sim.v).sum(axis=0)
    np.testing.assert_allclose(p, [3.0 * 0.2, 0, 0], atol=1e-9)


def test_inflation_pressure_grows_a_sphere():
    """An inflated shell grows; at equilibrium the radius increase grows with the pressure."""
    radii = []
    for p in (5.0, 10.0):
        sim = sphere_sim(100.0, 100.0, 0.002, 0.5, damping=5.0, pressure=Pressure(pressure=p))
        for _ in range(1500):
            sim.step()
            assert sim.check() is None
        radii.append(np.linalg.norm(sim.x, axis=1).mean())
        assert sim.kinetic_energy() < 1e-3
    assert 1.0 < radii[0] < radii[1] < 1.5
    # linear regime: twice the pressure, about twice the growth
    assert (radii[1] - 1) / (radii[0] - 1) == pytest.approx(2.0, rel=0.25)


def test_unstable_time_step_is_detected(tmp_path):
    from unmesh.errors import UnstableSimulationError
    from unmesh.sim import RunSettings, run

    sim = sphere_sim(1000.0, 10000.0, 0.05, 1.0)
    excite(sim, 0.01)
    with pytest.raises(UnstableSimulationError, match="last good frame"):
        run(sim, tmp_path, RunSettings(duration=2.0, fps=25), progress=False)
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "unstable"
    last = summary["frames"][-1]["frame"]
    assert (tmp_path / "frames" / f"frame_{last:05d}.ply").exists()
