"""Membrane/bending energy and forces (7.5-7.17): rest state, gradients, invariances, kernels."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from unmesh.shells.energy import FiberState, elastic_energy, elastic_forces_reference, umbrella_normals
from unmesh.shells.forces import elastic_forces
from unmesh.shells.nodes import build_topology, grid_sheet
from unmesh.shells.topology import ShellTopology


def sphere_nodes(n=150, radius=1.0):
    """Fibonacci points on a sphere with outward normals."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    normals = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)
    return radius * normals, normals


@pytest.fixture(scope="module")
def sheet():
    x, topo = grid_sheet(9, 8, spacing=0.1, jitter=0.3, seed=3)
    return x, topo


@pytest.fixture(scope="module")
def sphere():
    x, n = sphere_nodes()
    return x, build_topology(x, n, neighbors=8)


def random_state(x, topo, rng):
    """Rest state with random plastic offsets and per-fiber stiffness scales."""
    base = FiberState.at_rest(x, topo)
    f = len(base)
    return dataclasses.replace(base, length_plastic=rng.uniform(-0.02, 0.02, f) * base.length_orig,
                               angle_plastic=rng.uniform(-0.1, 0.1, f), stretch_scale=rng.uniform(0.5, 2, f),
                               bend_scale=rng.uniform(0.5, 2, f))


def fd_forces(x, topo, state, ks, kb, nodes, h=1e-6):
    out = np.zeros((len(nodes), 3))
    for row, i in enumerate(nodes):
        for c in range(3):
            p, m = x.copy(), x.copy()
            p[i, c] += h
            m[i, c] -= h
            out[row, c] = -(elastic_energy(p, topo, state, ks, kb) - elastic_energy(m, topo, state, ks, kb)) / (2 * h)
    return out


@pytest.mark.parametrize("shape", ["sheet", "sphere"])
def test_rest_state_has_zero_energy_and_force(shape, request):
    """At rest every fiber has l = l0 and theta = theta0: zero energy and force up to round-off."""
    x, topo = request.getfixturevalue(shape)
    state = FiberState.at_rest(x, topo)
    r = elastic_forces(x, topo, state, 1000.0, 10000.0)
    # scale: the forces of a 1 % perturbation
    loaded = elastic_forces(x * 1.01, topo, state, 1000.0, 10000.0)
    scale = np.abs(loaded.forces).max()
    assert np.abs(r.forces).max() < 1e-11 * scale
    assert r.energy < 1e-20 * loaded.energy
    f, e = elastic_forces_reference(x, topo, state, 1000.0, 10000.0)
    assert np.abs(f).max() < 1e-11 * scale and e < 1e-20 * loaded.energy


@pytest.mark.parametrize("shape", ["sheet", "sphere"])
def test_forces_are_negative_energy_gradient(shape, request, rng):
    x, topo = request.getfixturevalue(shape)
    state = random_state(x, topo, rng)
    scale = 0.03 if shape == "sheet" else 0.05
    y = x + rng.normal(scale=scale, size=x.shape)
    ks, kb = 25.0, 7.0
    f_ref, e_ref = elastic_forces_reference(y, topo, state, ks, kb)
    nodes = rng.choice(len(x), 30, replace=False)
    fd = fd_forces(y, topo, state, ks, kb, nodes)
    np.testing.assert_allclose(f_ref[nodes], fd, atol=1e-6 * np.abs(fd).max())
    r = elastic_forces(y, topo, state, ks, kb)
    np.testing.assert_allclose(r.forces, f_ref, atol=1e-10 * np.abs(f_ref).max())
    assert r.energy == pytest.approx(e_ref, rel=1e-12)
    e_s, e_b = elastic_energy(y, topo, state, ks, kb, per_node=True)
    np.testing.assert_allclose(r.stretch_energy, e_s, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(r.bend_energy, e_b, rtol=1e-11, atol=1e-14)
    assert e_s.sum() > 0 and e_b.sum() > 0


@pytest.mark.parametrize("shape", ["sheet", "sphere"])
def test_internal_forces_have_zero_net_force_and_torque(shape, request, rng):
    x, topo = request.getfixturevalue(shape)
    state = random_state(x, topo, rng)
    for _ in range(3):
        y = x + rng.normal(scale=0.05, size=x.shape)
        f = elastic_forces(y, topo, state, 1000.0, 10000.0).forces
        scale = np.abs(f).max() * len(f)
        np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12 * scale)
        np.testing.assert_allclose(np.cross(y - y.mean(axis=0), f).sum(axis=0), 0.0, atol=1e-12 * scale)


def test_energy_is_invariant_under_rigid_motion(sphere, rng):
    x, topo = sphere
    state = random_state(x, topo, rng)
    y = x + rng.normal(scale=0.05, size=x.shape)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    e = elastic_energy(y, topo, state, 10.0, 10.0)
    assert elastic_energy(y @ q.T + [1.0, -2.0, 3.0], topo, state, 10.0, 10.0) == pytest.approx(e, rel=1e-10)


def test_uniform_stretch_matches_analytic_energy(sheet):
    """In-plane scaling by (1+eps): every A_k scales by (1+eps)^2, so (7.7) is known in closed form."""
    x, topo = sheet
    state = FiberState.at_rest(x, topo)
    eps, ks = 0.03, 50.0
    e_s, e_b = elastic_energy(x * (1 + eps), topo, state, ks, 10.0, per_node=True)
    c = topo.fibers[:, 1]
    m = np.maximum(topo.fiber_counts(), 1)
    a0 = np.pi / 4 * state.length_orig**2
    node_a0 = np.bincount(c, a0, topo.n_nodes) / m
    mean_sq = np.bincount(c, a0**2, topo.n_nodes) / m
    k = (1 + eps) ** 2 - 1
    np.testing.assert_allclose(e_s, ks / 2 * k**2 * (node_a0**2 + mean_sq), rtol=1e-12)
    np.testing.assert_allclose(e_b, 0.0, atol=1e-20)


def _sheet_energy_per_area(spacing, deform, ks, kb):
    """Energy per unit area of the inner part of a 1 x 1 jittered sheet under ``deform``."""
    n = round(1.0 / spacing) + 1
    x, topo = grid_sheet(n, n, spacing=1.0 / (n - 1), jitter=0.2, seed=1)
    state = FiberState.at_rest(x, topo)
    e_s, e_b = elastic_energy(deform(x), topo, state, ks, kb, per_node=True)
    inner = np.all((x[:, :2] > 0.25) & (x[:, :2] < 0.75), axis=1)
    # energy per node area: the inner nodes share 0.25 of the area
    return e_s[inner].sum() / 0.25, e_b[inner].sum() / 0.25


def test_energy_per_area_scales_with_the_node_spacing_squared():
    """The printed (7.7)/(7.11) store an energy per unit area that scales like h^2 for a given
    strain or curvature (the sampling dependence of thesis 7.6; see unmesh.shells.energy)."""
    stretch = lambda x: x * [1.02, 1.0, 1.0]  # noqa: E731
    radius = 2.0

    def bend(x):  # roll the sheet onto a cylinder of radius 2 about the y axis (isometric)
        phi = (x[:, 0] - 0.5) / radius
        return np.stack([radius * np.sin(phi) + 0.5, x[:, 1], radius * (np.cos(phi) - 1)], axis=1)

    ratio = (12 / 36) ** 2
    coarse = _sheet_energy_per_area(1 / 12, stretch, 100.0, 1.0)
    fine = _sheet_energy_per_area(1 / 36, stretch, 100.0, 1.0)
    assert fine[0] / coarse[0] == pytest.approx(ratio, rel=0.15)
    coarse = _sheet_energy_per_area(1 / 12, bend, 100.0, 1.0)
    fine = _sheet_energy_per_area(1 / 36, bend, 100.0, 1.0)
    assert fine[1] / coarse[1] == pytest.approx(ratio, rel=0.15)
    assert fine[0] < 0.01 * fine[1]     # rolling up is isometric: almost no membrane energy


def test_scaling_fibers_per_node_does_not_change_stiffness(sphere, rng):
    """(7.6)/(7.16) normalise by m_i: duplicating every fiber r times leaves energy and forces unchanged."""
    x, topo = sphere
    state = random_state(x, topo, rng)
    y = x + rng.normal(scale=0.04, size=x.shape)
    ref = elastic_forces(y, topo, state, 30.0, 20.0)
    for r in (2, 3):
        dup = ShellTopology.build(topo.n_nodes, topo.neighbor_offsets, topo.neighbors, topo.pairs,
                                  topo.pair_center, np.tile(topo.fibers, (r, 1)), topo.soft)
        order = np.argsort(np.tile(topo.fibers[:, 1], r), kind="stable")
        dstate = FiberState.concatenate([state] * r).take(order)
        out = elastic_forces(y, dup, dstate, 30.0, 20.0)
        assert out.energy == pytest.approx(ref.energy, rel=1e-12)
        np.testing.assert_allclose(out.forces, ref.forces, atol=1e-12 * np.abs(ref.forces).max())


def test_flat_sheet_fibers_have_zero_rest_angle(sheet):
    """Irregular in-plane (geodesic) bends do not count as curvature (7.9 asks for normal curvature)."""
    x, topo = sheet
    state = FiberState.at_rest(x, topo)
    np.testing.assert_allclose(state.angle_orig, 0.0, atol=1e-12)
    _, normals = umbrella_normals(x, topo)
    has = np.diff(topo.pair_offsets) > 0
    np.testing.assert_allclose(normals[has], np.tile([0.0, 0, 1], (has.sum(), 1)), atol=1e-12)


def test_sphere_curvature_is_positive_and_uniform(sphere):
    """Outward normals on a convex sphere: H > 0 (7.10), roughly equal at every node."""
    x, topo = sphere
    state = FiberState.at_rest(x, topo)
    assert np.all(state.angle_orig > 0)
    _, normals = umbrella_normals(x, topo)
    assert np.all(np.einsum("ij,ij->i", normals, x) > 0.95)
    c = topo.fibers[:, 1]
    h = np.bincount(c, state.angle_orig, topo.n_nodes) / np.maximum(topo.fiber_counts(), 1)
    assert h.std() / h.mean() < 0.2


def test_kernel_fiber_measures_match_reference(sphere, rng):
    from unmesh.shells import _fiber_kernels
    from unmesh.shells import fibers as fb

    x, topo = sphere
    y = x + rng.normal(scale=0.05, size=x.shape)
    f = topo.fibers
    n = rng.normal(size=(len(f), 3))
    lk, gk = np.empty(len(f)), np.empty((len(f), 3, 3))
    _fiber_kernels.fiber_length_batch(y, f, _fiber_kernels.sample_weights(4), lk, gk)
    lr, gr = fb.arc_length_gradient(y[f[:, 0]], y[f[:, 1]], y[f[:, 2]], 4)
    np.testing.assert_allclose(lk, lr, rtol=1e-13)
    np.testing.assert_allclose(gk, gr, atol=1e-13)
    soft = rng.uniform(0, 0.3, len(f))
    tk, tg, tn = np.empty(len(f)), np.empty((len(f), 3, 3)), np.empty((len(f), 3))
    _fiber_kernels.fiber_angle_batch(y, f, n, soft, tk, tg, tn)
    tr, tgr, tnr = fb.bending_angle_gradient(y[f[:, 0]], y[f[:, 1]], y[f[:, 2]], n, soft, fb.TANGENT_SOFTENING)
    np.testing.assert_allclose(tk, tr, atol=1e-13)
    np.testing.assert_allclose(tg, tgr, atol=1e-11)
    np.testing.assert_allclose(tn, tnr, atol=1e-11)


def test_parallel_force_kernel_matches_reference(sphere, rng, monkeypatch):
    """The multi-threaded path of force_chunks (one private buffer per chunk, no write races)
    gives the reference forces and energies, as the single-threaded path does."""
    import numba

    from unmesh import _threads as sim_threads

    x, topo = sphere
    state = random_state(x, topo, rng)
    y = x + rng.normal(scale=0.05, size=x.shape)
    f_ref, e_ref = elastic_forces_reference(y, topo, state, 25.0, 7.0)
    monkeypatch.setattr(sim_threads, "PARALLEL_MIN", 0)
    threads = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    try:
        r = elastic_forces(y, topo, state, 25.0, 7.0)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_allclose(r.forces, f_ref, atol=1e-10 * np.abs(f_ref).max())
    assert r.energy == pytest.approx(e_ref, rel=1e-12)
