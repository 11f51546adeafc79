"""Factorisations of the implicit step: scaled single precision, background refactorisation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from unmesh.fem import _fe_kernels as FK
from unmesh.fem import _solve_kernels as SK
from unmesh.fem import hex_grid, voronoi_foam
from unmesh.fem.dynamics import Dynamics, Ground
from unmesh.fem.factor import Factorization, Job


def _stiff_system(rng, mass_span=0.0):
    """A foam's implicit matrix (3×3 blocks) whose lumped masses span ``mass_span`` decades (as after slivers)."""
    sim = Dynamics(voronoi_foam(12, seed=5), 2e3, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    masses = sim.masses * 10.0 ** (-mass_span * rng.random(n))
    A = SK.add_diagonal(K, p.diag, 0.04**2, masses, 1.0)
    kind = np.where(rng.random(n) < 0.1, 2, 0).astype(np.int64)
    return p, n, A, kind, np.array([0.0, 1.0, 0.0])


@pytest.mark.parametrize("perm", [False, True])
def test_single_precision_factorisation_solves_to_float32_accuracy(rng, perm):
    """Scaled to a unit diagonal, the float32 factors solve a system with masses over 5 decades
    to float32 round-off (relative residual ~1e-6), in either order."""
    from unmesh.fem.solvers import block_csr

    p, n, A, _, _ = _stiff_system(rng, mass_span=5.0)
    M = block_csr(p.indptr, p.indices, A)
    order = rng.permutation(3 * n) if perm else None
    x = rng.normal(size=3 * n)
    b = M @ x
    single = Factorization(M, order, single=True)
    double = Factorization(M, order)
    assert single.lu.L.dtype == np.float32 and double.lu.L.dtype == np.float64
    for lu, tol in ((single, 1e-4), (double, 1e-12)):
        y = lu.solve(b)
        assert y.dtype == np.float64
        assert np.linalg.norm(M @ y - b) < tol * np.linalg.norm(b)
    with pytest.raises(RuntimeError):
        Factorization(sp.csr_array(np.diag([1.0, -1.0])), None, single=True)


def test_single_precision_preconditioner_reaches_the_same_tolerance(rng):
    """PCG with the single-precision lagged LU meets the same criterion (relative residual
    ≤ 1e-10, far below float32's resolution) as with the double-precision one, in a few more
    iterations at most, on a matrix whose masses span 5 decades."""
    from unmesh.fem.solvers import LaggedLU, pcg

    p, n, A, kind, normal = _stiff_system(rng, mass_span=5.0)
    Q = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    b = rng.normal(size=(n, 3))
    out = {}
    for single in (False, True):
        lag = LaggedLU(single=single)
        lag.factor(p.indptr, p.indices, A, (1.0, 0.04**2), kind=kind, normal=normal)
        x, its, res = pcg(p.indptr, p.indices, A, b, np.zeros((n, 3)), kind, normal,
                          lag.preconditioner(Q, p.indptr, p.indices, A, kind, normal), 1e-10, 50)
        assert res <= 1e-10
        out[single] = (x, its)
    assert out[True][1] <= out[False][1] + 2
    np.testing.assert_allclose(out[True][0], out[False][0], atol=1e-8 * np.abs(out[False][0]).max())


def test_job_runs_in_a_thread_or_at_once_and_reraises():
    assert Job(np.add, 2, 3).result() == 5
    job = Job(np.add, 2, 3, threaded=False)
    assert job.done() and job.result() == 5
    for threaded in (True, False):
        job = Job(int, "x", threaded=threaded)
        with pytest.raises(ValueError):
            job.result()


def _cut_scene(threaded: bool, solver: str = "lu-pcg") -> tuple[Dynamics, int]:
    """Cuts on a grid resting on the ground, with a refactorisation in the background whenever none is pending."""
    from unmesh.fem.cutting import PlaneCut, apply_cuts

    sim = Dynamics(hex_grid((4, 3, 3), origin=(0, 0.02, 0)), 80.0, 0.3, 1.0, ground=Ground(friction=0.5),
                   solver=solver, cg_tol=1e-11)
    if solver == "lu-pcg":
        sim.lagged.touched_fraction = 1.0  # a small mesh: never refactorise in the foreground for a cut
        sim.lagged.threaded = threaded
        sim.lagged.background_iterations = 0  # start one whenever none is pending
    cuts = [PlaneCut((0.5, 0.5, 0.5), (1.0, 0.3, 0.1)), PlaneCut((0.4, 0.5, 0.5), (0.2, 1.0, -0.3)),
            PlaneCut((0.5, 0.6, 0.5), (0.1, 0.2, 1.0))]
    remapped = 0  # cuts while a background factorisation was pending
    for k in range(12):
        if k in (3, 4, 7):
            if solver == "lu-pcg":
                remapped += sim.lagged.pending is not None
            r = apply_cuts(sim.mesh, [cuts[(3, 4, 7).index(k)]])
            sim.change_topology(r.mesh, r.node_weights, r.element_parent, r.changed)
        sim.step(0.01)
    return sim, remapped


def test_background_refactorisation_is_deterministic_and_exact():
    """A factorisation made in a thread is installed at a fixed step (its remap across the cuts
    made meanwhile included): the same results, bit for bit, as computing it at once, and the
    solution of the direct solver."""
    threaded, remapped = _cut_scene(True)
    at_once, _ = _cut_scene(False)
    direct, _ = _cut_scene(False, solver="direct")
    lag = threaded.lagged
    assert lag.background_factorizations >= 3 and lag.factorizations > lag.background_factorizations
    assert remapped >= 1 and threaded.mesh.n_nodes > hex_grid((4, 3, 3)).n_nodes
    np.testing.assert_array_equal(threaded.u, at_once.u)
    np.testing.assert_array_equal(threaded.v, at_once.v)
    assert at_once.lagged.background_factorizations == lag.background_factorizations
    np.testing.assert_allclose(threaded.u, direct.u, atol=1e-9)


def test_background_refactorisation_policy():
    """It starts when the touched nodes pass ``background_share`` of ``touched_fraction`` (or the
    iterations pass ``background_iterations``), is installed ``lead`` steps later, and a
    foreground factorisation drops it."""
    from unmesh.fem.solvers import LaggedLU

    sim = Dynamics(hex_grid((3, 3, 3)), 50.0, 0.3, 1.0, gravity=(0, 0, 0))
    p, n = sim.pattern, sim.mesh.n_nodes
    A = SK.add_diagonal(FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices)), p.diag,
                        1e-3, sim.masses, 1.0)
    lag = LaggedLU(touched_fraction=0.4, background_share=0.5, background_iterations=20, threaded=False)
    coeffs = (1.0, 1e-3)
    lag.factor(p.indptr, p.indices, A, coeffs)
    assert not lag.wants_background(coeffs)
    lag.touched = np.arange(n) < 0.21 * n
    assert lag.wants_background(coeffs) and not lag.needs_factor(coeffs)
    lag.touched = None
    lag.last_iterations = 21
    assert lag.wants_background(coeffs) and not lag.wants_background((1.0, 2e-3))
    lag.start_background(p.indptr, p.indices, A, coeffs, step=5)
    assert not lag.wants_background(coeffs) and lag.factorizations == 2
    assert not lag.collect(5 + lag.lead - 1) and lag.collect(5 + lag.lead)
    assert lag.pending is None and lag.last_iterations == 0
    lag.start_background(p.indptr, p.indices, A, coeffs, step=9)
    lag.factor(p.indptr, p.indices, A, coeffs)
    assert lag.pending is None and not lag.collect(100)


@pytest.mark.parametrize("rings", [0, 1, 3])
def test_grow_kernel_matches_numpy(rng, rings):
    from unmesh.fem.solvers import grow

    sim = Dynamics(voronoi_foam(10, seed=3), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    mask = rng.random(n) < 0.05
    got = grow(p.indptr, p.indices, mask, rings)
    np.testing.assert_array_equal(got, grow(p.indptr, p.indices, mask, rings, fast=False))
    assert got.sum() >= mask.sum() and (rings == 0) == (got.sum() == mask.sum())


@pytest.mark.parametrize("scaled", [False, True])
def test_permuted_scalar_csr_kernel_matches_scipy(rng, scaled):
    """The GIL-free kernel builds scipy's ``A[p][:, p]`` (of the scaled matrix), rows sorted."""
    from unmesh.fem.solvers import block_csr

    p, n, A, _, _ = _stiff_system(rng, mass_span=2.0)
    perm = rng.permutation(n)
    data = np.empty(9 * len(p.indices))
    ptr, idx, scale = SK.permuted_scalar_csr(p.indptr, p.indices, A, perm, scaled, data)
    M = block_csr(p.indptr, p.indices, A)
    d = 1.0 / np.sqrt(M.diagonal()) if scaled else np.ones(3 * n)
    np.testing.assert_array_equal(scale, d)
    dof = (3 * perm[:, None] + np.arange(3)).ravel()
    ref = (sp.diags_array(d) @ M @ sp.diags_array(d)).tocsr()[dof][:, dof]
    got = sp.csr_array((data, idx, ptr), shape=M.shape)
    assert got.has_sorted_indices
    np.testing.assert_allclose(got.toarray(), ref.toarray(), rtol=1e-14, atol=1e-14 * abs(ref.data).max())


@pytest.mark.parametrize("single", [False, True])
def test_factorisation_from_blocks_equals_the_scalar_one(rng, single):
    from unmesh.fem.solvers import block_csr

    p, n, A, _, _ = _stiff_system(rng, mass_span=5.0)
    perm = rng.permutation(n)
    dof = (3 * perm[:, None] + np.arange(3)).ravel()
    a = Factorization.from_blocks(p.indptr, p.indices, A, perm, single=single)
    b = Factorization(block_csr(p.indptr, p.indices, A), dof, single=single)
    assert a.nnz == b.nnz and a.lu.L.dtype == b.lu.L.dtype
    r = rng.normal(size=3 * n)
    np.testing.assert_allclose(a.solve(r), b.solve(r), rtol=1e-4 if single else 1e-10,
                               atol=(1e-4 if single else 1e-10) * np.abs(b.solve(r)).max())
    with pytest.raises(RuntimeError):
        Factorization.from_blocks(p.indptr, p.indices, -A, perm, single=True)


def test_ill_conditioned_systems_fall_back_to_double_precision(rng):
    """Masses 10⁶ times too small for the stiffness (a sliver's nodes): the float32 factors of
    the scaled matrix are garbage (relative residual ~1), so the lagged LU is made in double
    precision and PCG converges at once; a well-conditioned system keeps float32."""
    from unmesh.fem.solvers import SINGLE_RESIDUAL, LaggedLU, _solve_residual, block_csr, pcg

    sim = Dynamics(voronoi_foam(12, seed=5), 2e3, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    Q = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    kind, normal = np.zeros(n, np.int64), np.array([0.0, 1.0, 0.0])
    for scale, dtype in ((1.0, np.float32), (1e-6, np.float64)):
        A = SK.add_diagonal(K, p.diag, 0.04**2, sim.masses * scale, 1.0)
        assert (_solve_residual(p.indptr, p.indices, A, Factorization(block_csr(p.indptr, p.indices, A), None,
                                                                      single=True)) > SINGLE_RESIDUAL) == (scale < 1)
        lag = LaggedLU()
        lag.factor(p.indptr, p.indices, A, (1.0, 0.04**2), kind=kind, normal=normal)
        assert lag.lu.lu.L.dtype == dtype
        _, its, res = pcg(p.indptr, p.indices, A, rng.normal(size=(n, 3)), np.zeros((n, 3)), kind, normal,
                          lag.preconditioner(Q), 1e-8, 50)
        assert res <= 1e-8 and its <= 4


def test_nested_dissection_through_ctypes_equals_pymetis():
    """METIS_NodeND called through ctypes (GIL released) gives pymetis' order, bit for bit."""
    pytest.importorskip("pymetis")
    from unmesh.fem.factor import _metis_node_nd, nested_dissection

    sim = Dynamics(voronoi_foam(12, seed=5), 2e3, 0.3, 1.0)
    p = sim.pattern
    fast = nested_dissection(p.indptr, p.indices)
    ref = nested_dissection(p.indptr, p.indices, fast=False)
    assert _metis_node_nd() is not None  # pymetis' build: 64-bit idx_t
    np.testing.assert_array_equal(fast, ref)
    assert sorted(fast.tolist()) == list(range(len(p.indptr) - 1))


def test_local_orders_are_remembered(monkeypatch):
    """A local set's pattern seen before gets its METIS order again without calling METIS."""
    pytest.importorskip("pymetis")
    import unmesh.fem.factor as FA

    sim = Dynamics(voronoi_foam(12, seed=5), 2e3, 0.3, 1.0)
    p = sim.pattern
    monkeypatch.setattr(FA, "_LOCAL_ORDERS", type(FA._LOCAL_ORDERS)())
    first = FA._local_order(p.indptr, p.indices)
    np.testing.assert_array_equal(first, FA.nested_dissection(p.indptr, p.indices))

    def fail(*args, **kwargs):
        raise AssertionError("METIS called for a remembered pattern")

    monkeypatch.setattr(FA, "nested_dissection", fail)
    np.testing.assert_array_equal(FA._local_order(p.indptr, p.indices), first)
