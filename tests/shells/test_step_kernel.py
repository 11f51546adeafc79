"""The one-kernel shell step and the vectorised force blocks (issue 6) against the plain computations."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shells.conftest import Box, grid_cloud, grid_nodes, sphere_with_nodes
from unmesh.shells import MaterialRegion, PlaneCollider, Pressure, ShellMaterial, ShellSimulation, SphereCollider
from unmesh.shells.energy import FiberState, elastic_forces_reference
from unmesh.shells.forces import elastic_forces
from unmesh.shells.nodes import build_topology
from unmesh.shells.plasticity import Plasticity
from unmesh.shells.topology import ShellTopology


def test_fast_atan2_is_within_two_ulp_of_numpy():
    from unmesh._linalg_kernels import atan2_batch as run

    rng = np.random.default_rng(7)
    y = rng.normal(size=200_000) * np.exp(3 * rng.normal(size=200_000))
    x = rng.normal(size=200_000) * np.exp(3 * rng.normal(size=200_000))
    t = np.linspace(-4 * np.pi, 4 * np.pi, 100_001)                  # every octant boundary
    y, x = np.concatenate([y, np.sin(t), [0.0, 1.0, -1.0, 0.0]]), np.concatenate([x, np.cos(t), [0.0, 0.0, 0.0, -1.0]])
    out = np.empty_like(y)
    run(y, x, out)
    ref = np.arctan2(y, x)
    ref[(y == 0) & (x == 0)] = 0.0
    err = np.abs(out - ref)
    # -pi and pi (a zero y on the negative x axis) are the same angle
    err = np.minimum(err, np.abs(err - 2 * np.pi))
    assert (err <= 2 * np.spacing(np.maximum(np.abs(ref), 1e-300)) + 1e-300).all()


def test_force_blocks_and_the_scalar_path_for_large_fans_match_the_reference():
    """Nodes with more fibers than a block holds take the scalar path; both give the reference forces."""
    from unmesh.shells._block_kernels import BLK

    i = np.arange(150) + 0.5
    phi, theta = np.arccos(1 - 2 * i / 150), np.pi * (1 + 5**0.5) * i
    n = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)
    topo = build_topology(n, n, neighbors=8)
    rng = np.random.default_rng(3)
    reps = BLK // int(np.diff(topo.fiber_offsets).min()) + 1
    big = ShellTopology.build(topo.n_nodes, topo.neighbor_offsets, topo.neighbors, topo.pairs, topo.pair_center,
                              np.concatenate([np.tile(topo.fibers[:40], (reps, 1)), topo.fibers[40:]]), topo.soft)
    counts = np.diff(big.fiber_offsets)
    assert counts.max() > BLK and (counts[counts > 0] <= BLK).any()
    base = FiberState.at_rest(n, big)
    f = len(base)
    state = FiberState(base.length_orig, base.angle_orig, rng.uniform(-0.02, 0.02, f) * base.length_orig,
                       rng.uniform(-0.1, 0.1, f), rng.uniform(0.5, 2, f), rng.uniform(0.5, 2, f), base.fracture_stretch,
                       base.fracture_bend)
    y = n + rng.normal(scale=0.05, size=n.shape)
    f_ref, e_ref = elastic_forces_reference(y, big, state, 25.0, 7.0)
    r = elastic_forces(y, big, state, 25.0, 7.0)
    np.testing.assert_allclose(r.forces, f_ref, atol=1e-10 * np.abs(f_ref).max())
    assert r.energy == pytest.approx(e_ref, rel=1e-12)


def _pair(make, steps):
    """The same simulation stepped with the one-kernel step and with the plain step."""
    fused, plain = make(), make()
    plain.fused = False
    for _ in range(steps):
        fused.step()
        plain.step()
        assert fused.check() == plain.check()
    assert fused._stepper() is not None and plain._stepper() is None
    return fused, plain


def _same(a, b, scale):
    np.testing.assert_allclose(a.x, b.x, atol=1e-9 * scale)
    np.testing.assert_allclose(a.v, b.v, atol=1e-8 * max(np.abs(b.v).max(), 1e-12))
    np.testing.assert_allclose(a.acc, b.acc, atol=1e-7 * max(np.abs(b.acc).max(), 1e-12))
    assert a.time == b.time and a.steps == b.steps
    assert a.elastic_energy() == pytest.approx(b.elastic_energy(), rel=1e-7, abs=1e-12)
    for name in ("length_plastic", "angle_plastic", "fracture_bend"):
        np.testing.assert_allclose(getattr(a.fibers, name), getattr(b.fibers, name), atol=1e-9, err_msg=name)


def test_one_kernel_step_equals_the_plain_step_with_colliders_plasticity_and_pressure():
    cloud, idx = sphere_with_nodes()

    def make():
        mat = ShellMaterial(ks=200.0, kb=200.0, damping=0.5, density=2.0,
                            plasticity=Plasticity(creep_stretch=3.0, creep_bend=3.0, yield_stretch=0.01,
                                                  yield_bend=0.02, weakening=0.5))
        return ShellSimulation(cloud, mat, 0.002, node_indices=idx, gravity=(0, -9.81, 0), total_area=4 * np.pi,
                               velocity=(0.3, -1.0, 0.0), pressure=Pressure(pressure=1.0, rate=20.0),
                               colliders=[PlaneCollider((0, -1.05, 0), (0, 1, 0), 0.3, 0.5),
                                          SphereCollider((1.2, -0.6, 0), 0.5, 0.2, 0.3)])

    # contacts with friction make the motion chaotic (round-off grows exponentially), so the
    # steps are compared one by one from the same state
    import copy

    plain = make()
    plain.fused = False
    hits = 0
    for k in range(300):
        if k % 20 == 19:
            fused = copy.deepcopy(plain)
            fused.fused = True
            fused.step()
            plain.step()
            assert fused.check() == plain.check()
            _same(fused, plain, 1.0)
            np.testing.assert_allclose(fused.x, plain.x, atol=1e-14)
            hits += (plain.x[:, 1] < -1.0499).sum() + (np.linalg.norm(plain.x - [1.2, -0.6, 0], axis=1) < 0.5001).sum()
        else:
            plain.step()
    assert hits > 10 and (np.abs(plain.fibers.length_plastic) > 0).sum() > 10     # it hit, it yielded
    a, b = _pair(make, 40)          # and the first steps (before contact) together
    _same(a, b, 1.0)


def test_one_kernel_step_equals_the_plain_step_with_handles_pins_pulls_and_cracks():
    cloud = grid_cloud(61, 21, 0.02)
    idx = grid_nodes(61, 21, 2)

    def make():
        mat = ShellMaterial(ks=1000.0, kb=100.0, damping=2.0, density=2.0, fracture_stretch=0.03,
                            regions=(MaterialRegion(Box([-0.03, -1, -1], [0.03, 1, 1]), fracture=0.5),
                                     MaterialRegion(Box([-1, -1, -1], [-0.4, 1, 1]), fracture=5.0),
                                     MaterialRegion(Box([0.4, -1, -1], [1, 1, 1]), fracture=5.0)))
        return ShellSimulation(cloud, mat, 0.0005, node_indices=idx, gravity=(0, -1.0, 0), total_area=1.2 * 0.4,
                               pinned=[Box([-1, -1, 0.19], [-0.55, 1, 1])],
                               pulls=[{"region": Box([-0.1, -1, -1], [0.1, 1, 1]), "force": (0, 0.01, 0), "ramp": 0.1}],
                               handles=[{"region": Box([-1, -1, -1], [-0.55, 1, 1]), "velocity": (-0.2, 0, 0)},
                                        {"region": Box([0.55, -1, -1], [1, 1, 1]), "velocity": (0.2, 0, 0.01),
                                         "stop": 0.3}])

    a, b = _pair(make, 700)
    assert len(b.cracks) >= 1 and len(a.cracks) == len(b.cracks)
    np.testing.assert_array_equal(a.topology.fibers, b.topology.fibers)
    _same(a, b, 1.0)


def test_changing_kinematic_nodes_rebuilds_the_one_kernel_step():
    cloud, idx = sphere_with_nodes()

    def make():
        top = np.flatnonzero(cloud.positions[idx, 1] > 0.85)
        return ShellSimulation(cloud, ShellMaterial(ks=200.0, kb=200.0, damping=3.0, density=2.0), 0.002,
                               node_indices=idx, gravity=(0, 0, 0), total_area=4 * np.pi,
                               handles=[{"region": top, "velocity": (0.0, -0.5, 0.0)}])

    a, b = make(), make()
    b.fused = False
    for sim in (a, b):
        for _ in range(50):
            sim.step()
        sim.handles = ()
        sim.fixed[:] = False
        for _ in range(50):
            sim.step()
    _same(a, b, 1.0)


def test_check_statistics_match_numpy():
    from unmesh.shells._step_kernels import check_stats

    rng = np.random.default_rng(2)
    x, v, m = rng.normal(size=(50, 3)), rng.normal(size=(50, 3)), rng.uniform(1, 2, 50)
    ang, prev = rng.normal(size=80) * 3, rng.normal(size=80) * 3
    es, eb = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50)
    finite, ke, vmax2, jumps, elastic = check_stats(x, v, m, ang, prev, es, eb)
    assert finite and jumps == int((np.abs(ang - prev) > np.pi / 2).sum())
    assert ke == pytest.approx(0.5 * (m * (v**2).sum(axis=1)).sum(), rel=1e-14)
    assert vmax2 == pytest.approx((v**2).sum(axis=1).max(), rel=1e-14)
    assert elastic == pytest.approx(es.sum() + eb.sum(), rel=1e-14)
    v[7, 1] = np.nan
    assert not check_stats(x, v, m, ang, np.zeros(0), es, eb)[0]
    assert check_stats(x, np.zeros_like(v), m, ang, np.zeros(0), es, eb)[3] == 0


def test_one_kernel_step_is_the_same_on_one_and_on_two_threads(monkeypatch):
    """Fixed node and fiber ranges: the step does not depend on the number of threads."""
    import numba

    from unmesh import _threads as sim_threads

    cloud, idx = sphere_with_nodes()

    def make():
        mat = ShellMaterial(ks=200.0, kb=200.0, damping=0.5, density=2.0,
                            plasticity=Plasticity(creep_stretch=3.0, creep_bend=3.0, yield_stretch=0.01,
                                                  yield_bend=0.02))
        return ShellSimulation(cloud, mat, 0.002, node_indices=idx, gravity=(0, -9.81, 0), total_area=4 * np.pi,
                               velocity=(0.3, -1.0, 0.0), colliders=[PlaneCollider((0, -1.05, 0), (0, 1, 0), 0.3, 0.5)])

    runs = []
    threads = numba.get_num_threads()
    for count, minimum in ((1, 10**12), (min(2, numba.config.NUMBA_NUM_THREADS), 0)):
        monkeypatch.setattr(sim_threads, "PARALLEL_MIN", minimum)
        numba.set_num_threads(count)
        try:
            sim = make()
            for _ in range(120):
                sim.step()
            runs.append((sim.x.copy(), sim.v.copy(), sim.fibers.length_plastic.copy()))
        finally:
            numba.set_num_threads(threads)
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a, b)


def test_force_pass_counts_the_degenerate_fibers_of_the_reference():
    """The one-kernel step finds degenerate fibers in its force pass (block and scalar paths),
    from the gathered edge vectors and the new umbrella vectors: the fibers the numpy test finds."""
    from unmesh.shells import _force_kernels
    from unmesh.shells._block_kernels import BLK
    from unmesh.shells.fibers import degenerate
    from unmesh.shells.forces import FORCE_CHUNKS, arc_gram

    i = np.arange(150) + 0.5
    phi, theta = np.arccos(1 - 2 * i / 150), np.pi * (1 + 5**0.5) * i
    n = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)
    topo = build_topology(n, n, neighbors=8)
    reps = BLK // int(np.diff(topo.fiber_offsets).min()) + 1
    big = ShellTopology.build(topo.n_nodes, topo.neighbor_offsets, topo.neighbors, topo.pairs, topo.pair_center,
                              np.concatenate([np.tile(topo.fibers[:40], (reps, 1)), topo.fibers[40:]]), topo.soft)
    assert np.diff(big.fiber_offsets).max() > BLK                      # both paths
    state = FiberState.at_rest(n, big)
    y = n + np.random.default_rng(9).normal(scale=0.08, size=n.shape)   # shaken: some fibers degenerate
    nn, nf = len(n), len(big.fibers)
    out = [np.empty((nn, 3)), np.empty(nf), np.empty(nf), np.empty((nn, 3)), np.empty((nn, 3)), np.empty((nn, 4)),
           np.empty(nn), np.empty(nn)]
    counts = np.diff(big.fiber_offsets)
    bad = 0
    for c in range(FORCE_CHUNKS):
        _, b = _force_kernels.chunk_forces(c * nn // FORCE_CHUNKS, (c + 1) * nn // FORCE_CHUNKS, y, big.pairs,
                                     big.pair_offsets[:-1], np.diff(big.pair_offsets), big.soft, big.fibers,
                                     big.fiber_offsets[:-1], counts, state.length_orig, state.length_plastic,
                                     state.angle_orig, state.angle_plastic, state.stretch_scale, state.bend_scale, 1.0,
                                     1.0, arc_gram(4), state.rest_angle(), np.zeros((nn, 2)), np.zeros((nn, 3)),
                                     np.empty(27 * BLK), np.empty((int(counts.max()), 15)), *out[1:], np.zeros(0, bool),
                                     False, 0.09)
        bad += b
    f, s = big.fibers, out[3]
    ref = degenerate(y[f[:, 0]], y[f[:, 1]], y[f[:, 2]], s[f[:, 1]], big.soft[f[:, 1]], 0.3)
    assert 0 < ref.sum() < nf
    assert bad == ref.sum()
