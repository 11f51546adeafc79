"""Plasticity, creep and weakening (7.19-7.23, 7.25) and per-fiber materials (7.3.4)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shells.conftest import sphere_with_nodes
from unmesh.errors import InputError
from unmesh.shells import FiberState, Plasticity, ShellMaterial, ShellSimulation
from unmesh.shells.material import Anisotropy, MaterialRegion


def test_update_rules_match_equations():
    p = Plasticity(creep_stretch=2.0, creep_bend=3.0, yield_stretch=0.1, yield_bend=0.2, weakening=0.5)
    s = FiberState.uniform([1.0, 1.0, 2.0], [0.1, 0.1, 0.0], fracture_bend=1.0)
    lengths = np.array([1.05, 1.2, 1.5])   # strains 0.05 (below), 0.2, -0.25 (above beta_s = 0.1)
    angles = np.array([0.25, 0.5, 0.0])    # dtheta 0.15 (below), 0.4 (above beta_b = 0.2), 0
    ns, nb = p.update(s, lengths, angles, dt=0.01)
    assert (ns, nb) == (2, 1)
    np.testing.assert_allclose(s.length_plastic, [0.0, 2.0 * 0.2 * 0.01, -2.0 * 0.5 * 0.01])  # (7.22)
    dth = 3.0 * 0.4 * 0.01
    np.testing.assert_allclose(s.angle_plastic, [0.0, dth, 0.0])                            # (7.23)
    np.testing.assert_allclose(s.fracture_bend, [1.0, 1.0 - 0.5 * dth, 1.0])                # (7.25)


def test_creep_converges_to_the_held_shape():
    """Held deformation above the yield: the rest length creeps towards it exponentially."""
    p = Plasticity(creep_stretch=2.0, yield_stretch=0.01)
    s = FiberState.uniform([1.0], [0.0])
    for _ in range(1000):
        p.update(s, np.array([1.5]), np.array([0.0]), dt=0.001)
    # l0 approaches 1.5 until the strain (1.5 - l0) / l0 falls below the yield threshold
    assert s.rest_length()[0] == pytest.approx(1.5 - 0.5 * np.exp(-2.0), rel=2e-3)
    with pytest.raises(InputError):
        Plasticity(yield_stretch=-1.0)


def test_plastic_shell_keeps_its_dent():
    """Push a patch of a plastic sphere in and release it: the dent stays (Fig. 7.5)."""
    cloud, idx = sphere_with_nodes()
    results = {}
    for name, plast in (("elastic", Plasticity()),
                        ("plastic", Plasticity(creep_stretch=5.0, creep_bend=5.0, yield_stretch=0.01, yield_bend=0.01))):
        mat = ShellMaterial(ks=200.0, kb=200.0, damping=3.0, density=2.0, plasticity=plast)
        top = np.flatnonzero(cloud.positions[idx, 1] > 0.85)
        bottom = np.flatnonzero(cloud.positions[idx, 1] < -0.85)
        sim = ShellSimulation(cloud, mat, 0.002, node_indices=idx, gravity=(0, 0, 0), total_area=4 * np.pi,
                              pinned=[bottom],
                              handles=[{"region": top, "velocity": (0.0, -0.5, 0.0), "stop": 0.3}])

        def height(sim=sim, top=top):
            return sim.x[top, 1].mean()

        top0 = height()
        for _ in range(300):
            sim.step()
        sim.handles = ()
        sim.fixed[:] = False
        sim.fixed[bottom] = True
        for _ in range(1500):
            sim.step()
            assert sim.check() is None
        results[name] = top0 - height()
    print(results)
    assert results["elastic"] < 0.02    # springs back (pushed in by 0.15)
    assert results["plastic"] > 0.05    # stays dented


def test_anisotropy_and_regions_set_fiber_factors():
    from unmesh.shapes import Sphere

    rest = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0], [1, -1, 0]])
    fibers = np.array([[0, 1, 2], [3, 1, 4]])
    mat = ShellMaterial(ks=1.0, kb=1.0, fracture_stretch=0.1, anisotropy=Anisotropy((1, 0, 0), (3.0, 1.0), (1.0, 2.0)),
                        regions=(MaterialRegion(Sphere(center=(1, 0, 0), radius=0.1), stretch=2.0, fracture=0.5),))
    f = mat.fiber_material(fibers, rest)
    np.testing.assert_allclose(f["stretch_scale"], [6.0, 2.0])   # along x: 3, across: 1; both x2 in the region
    np.testing.assert_allclose(f["bend_scale"], [1.0, 2.0])
    np.testing.assert_allclose(f["fracture_stretch"], [0.05, 0.05])


def test_anisotropic_sheet_is_stiffer_along_its_fibers():
    """Stretching along the stiff direction stores more energy than across it (7.3.4)."""
    from unmesh.shells import elastic_energy, grid_sheet

    x, topo = grid_sheet(9, 9, 0.1, jitter=0.2)
    mat = ShellMaterial(ks=1.0, kb=0.0, anisotropy=Anisotropy((1, 0, 0), (4.0, 1.0)))
    state = FiberState.at_rest(x, topo, **mat.fiber_material(topo.fibers, x))
    ex = elastic_energy(x * [1.02, 1.0, 1.0], topo, state, 1.0, 0.0)
    ey = elastic_energy(x * [1.0, 1.02, 1.0], topo, state, 1.0, 0.0)
    assert ex > 1.5 * ey
