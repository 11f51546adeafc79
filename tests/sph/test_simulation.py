"""Dynamics of elastic solids: rigid rotation, bouncing, inherent plasticity, fracture, collisions."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from unmesh.spatial import radius_pairs
from unmesh.sph import Material, Plane, SPHConfig, SPHObject, SPHSimulation
from unmesh.sph.sampling import closest_packing


def rigid_fit_deviation(x0: np.ndarray, x: np.ndarray, dim: int) -> float:
    """RMS distance to the best rigid motion of the rest shape (Kabsch), shape (N, 3) arrays."""
    c0 = x0.mean(axis=0)
    c = x.mean(axis=0)
    a = (x - c)[:, :dim].T @ (x0 - c0)[:, :dim]
    u, _, vt = np.linalg.svd(a)
    if np.linalg.det(u @ vt) < 0:
        u[:, -1] *= -1
    fit = (x0 - c0)[:, :dim] @ (u @ vt).T + c[:dim]
    return float(np.sqrt(np.mean(np.sum((x[:, :dim] - fit) ** 2, axis=1))))


def components(x: np.ndarray, radius: float, dim: int) -> int:
    pairs = radius_pairs(x[:, :dim], radius)
    n = len(x)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return int(connected_components(graph, directed=False)[0])


def test_rigidly_rotating_solid_keeps_its_shape():
    """A spinning elastic square (no gravity) stays rigid; its lattice rotates with it; L is conserved."""
    d, size, omega = 0.01, 0.1, 5.0
    x = closest_packing([-size / 2] * 3, [size / 2] * 3, d, 2)
    mat = Material("rubber", stiffness=200.0, elastic_stiffness=5e6)
    sim = SPHSimulation(SPHConfig(dim=2, spacing=d, dt=1e-3, cfl=0.3, gravity=(0, 0, 0)), {"rubber": mat},
                        [SPHObject("square", x, "rubber", phase="solid", angular_velocity=(0, 0, omega))])
    x0 = sim.particles().positions
    l0 = sim.particles().angular_momentum()[2]
    while sim.time < 0.3:
        sim.step()
    s = sim.particles()
    dev = rigid_fit_deviation(x0, s.positions, 2)
    assert dev < 0.01 * size, dev
    assert abs(s.angular_momentum()[2] - l0) < 1e-10 * abs(l0)
    # every lattice transformation A_i has turned by ω t (8.23-8.24)
    angles = np.arctan2(sim.lattice_transforms()[:, 1, 0], sim.lattice_transforms()[:, 0, 0])
    assert np.allclose(np.unwrap(angles), omega * sim.time, atol=0.05)
    assert sim.check() is None


def test_elastic_cube_bounces_and_keeps_its_shape():
    """A 2D elastic cube dropped on the floor bounces back up and keeps its shape (Fig. 8.7a)."""
    d, size = 0.02, 0.2
    x = closest_packing([-0.1, 0.25, 0], [0.1, 0.45, 0], d, 2)
    mat = Material("rubber", stiffness=200.0, xsph=0.1, elastic_stiffness=2e7)
    sim = SPHSimulation(SPHConfig(dim=2, spacing=d, dt=1e-3, cfl=0.3, gravity=(0, -9.81, 0)), {"rubber": mat},
                        [SPHObject("cube", x, "rubber", phase="solid")], planes=[Plane((0, 0, 0), (0, 1, 0))])
    x0 = sim.particles().positions
    touched = False
    rebound = 0.0
    worst = 0.0
    while sim.time < 0.6:
        sim.step()
        s = sim.particles()
        if s.positions[:, 1].min() < 0.6 * d:
            touched = True
        if touched:
            rebound = max(rebound, float(s.velocities[:, 1].mean()))
        worst = max(worst, rigid_fit_deviation(x0, s.positions, 2))
    print(f"bouncing cube: rebound {rebound:.2f} m/s, worst rigid-fit deviation {worst / size:.2%} of the edge")
    assert touched and rebound > 0.5
    assert worst < 0.05 * size
    assert rigid_fit_deviation(x0, sim.particles().positions, 2) < 0.03 * size


def test_stretched_beyond_limit_fractures():
    """A bar pulled apart fast breaks into pieces; pulled slowly it stays one piece (section 8.2.5)."""
    d = 0.01
    x = closest_packing([-0.2, -0.04, 0], [0.2, 0.04, 0], d, 2)
    mat = Material("chalk", stiffness=200.0, elastic_stiffness=2e6, docking_rate=1e4, docking_gain=1e3,
                   docking_loss=1e6, fracture_stretch=0.2)
    counts = {}
    for speed in (0.05, 3.0):
        bar = SPHObject("bar", x, "chalk", phase="solid")
        sim = SPHSimulation(SPHConfig(dim=2, spacing=d, dt=1e-3, cfl=0.3, gravity=(0, 0, 0)), {"chalk": mat}, [bar])
        o = np.argsort(sim.uid)
        sim.v[o, 0] = np.sign(x[:, 0]) * speed
        while sim.time < 0.15:
            sim.step()
        counts[speed] = components(sim.particles().positions, 1.5 * d, 2)
    assert counts[0.05] == 1
    assert counts[3.0] >= 2


def test_inherent_plasticity_changes_the_rest_shape():
    """A soft block squashed fast keeps a permanent deformation: the reassigned lattice is the new rest state."""
    d = 0.01
    x = closest_packing([-0.05, -0.05, 0], [0.05, 0.05, 0], d, 2)
    mat = Material("clay", stiffness=200.0, viscosity=0.05, elastic_stiffness=3e5, goal_deformation=0.9)
    sim = SPHSimulation(SPHConfig(dim=2, spacing=d, dt=1e-3, cfl=0.3, gravity=(0, 0, 0)), {"clay": mat},
                        [SPHObject("block", x, "clay", phase="solid")])
    o = np.argsort(sim.uid)
    sim.v[o, 1] = -4.0 * x[:, 1] / 0.05  # squash vertically, stretch horizontally
    sim.v[o, 0] = 4.0 * x[:, 0] / 0.05
    ke0 = sim.particles().kinetic_energy()
    extent0 = np.ptp(x[:, :2], axis=0)
    while sim.time < 0.4:
        sim.step()
    s = sim.particles()
    extent = np.ptp(s.positions[:, :2], axis=0)
    assert s.kinetic_energy() < 0.01 * ke0  # it came to rest...
    assert extent[0] > extent0[0] + 0.5 * d and extent[1] < extent0[1] - 0.5 * d  # ...squashed
    assert components(s.positions, 1.5 * d, 2) == 1  # in one piece


def test_objects_collide_without_sticking_or_interpenetrating():
    """Two elastic blocks of different objects meet head-on: repulsive-only pair forces (8.37)."""
    d = 0.01
    a = closest_packing([-0.12, -0.04, 0], [-0.02, 0.04, 0], d, 2)
    b = closest_packing([0.02, -0.04, 0], [0.12, 0.04, 0], d, 2)
    mat = Material("rubber", stiffness=500.0, elastic_stiffness=5e6)
    sim = SPHSimulation(SPHConfig(dim=2, spacing=d, dt=1e-3, cfl=0.3, gravity=(0, 0, 0)), {"rubber": mat},
                        [SPHObject("a", a, "rubber", phase="solid", velocity=(1.0, 0, 0)),
                         SPHObject("b", b, "rubber", phase="solid", velocity=(-1.0, 0, 0))])
    p0 = sim.particles().linear_momentum()
    gap = np.inf
    while sim.time < 0.12:
        sim.step()
        s = sim.particles()
        xa = s.positions[s.objects == 0, 0].max()
        xb = s.positions[s.objects == 1, 0].min()
        gap = min(gap, xb - xa)
    s = sim.particles()
    va = s.velocities[s.objects == 0, 0].mean()
    vb = s.velocities[s.objects == 1, 0].mean()
    assert gap > 0.0  # no interpenetration
    assert va < 0 < vb  # they bounced apart instead of sticking
    assert np.allclose(s.linear_momentum(), p0, atol=1e-12)
