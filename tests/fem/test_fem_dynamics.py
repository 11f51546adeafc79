"""Horn rotations, stiffness warping, implicit Euler, contact, constraints, solvers."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from unmesh.errors import InputError
from unmesh.fem import _fe_kernels as FK
from unmesh.fem import _solve_kernels as SK
from unmesh.fem import convex_polyhedron, hex_grid, horn_rotations, voronoi_foam
from unmesh.fem.dynamics import Dynamics, Ground, Load, Prescribed
from unmesh.fem.rotations import horn_matrix, jacobi_eigh4


def test_jacobi_eigen_solver_matches_numpy(rng):
    for _ in range(50):
        a = rng.normal(size=(4, 4))
        a = a + a.T
        w, v = jacobi_eigh4(a)
        ref = np.linalg.eigvalsh(a)
        np.testing.assert_allclose(np.sort(w), ref, atol=1e-12 * abs(ref).max())
        np.testing.assert_allclose(a @ v, v * w, atol=1e-12 * abs(ref).max())


@pytest.mark.parametrize("shape", ["random", "flat", "flat_triangle_pair"])
def test_horn_recovers_exact_rotations_including_flat_elements(rng, shape):
    if shape == "random":
        X = rng.normal(size=(7, 3))
    elif shape == "flat":
        X = np.c_[rng.normal(size=(6, 2)), np.zeros(6)]
    else:
        X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)  # three points: a degenerate "element"
    for _ in range(20):
        R = Rotation.random(random_state=rng.integers(1 << 30)).as_matrix()
        x = X @ R.T + rng.normal(size=3)
        Rh = horn_rotations(X, x, [0, len(X)], np.arange(len(X)))[0]
        np.testing.assert_allclose(Rh, R, atol=1e-10)
        assert np.linalg.det(Rh) == pytest.approx(1.0)


def test_horn_matrix_eigenvector_is_the_least_squares_rotation(rng):
    X = rng.normal(size=(8, 3))
    x = X @ Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix().T + 0.01 * rng.normal(size=(8, 3))
    Xc, xc = X - X.mean(axis=0), x - x.mean(axis=0)
    _, v = np.linalg.eigh(horn_matrix(Xc.T @ xc))
    Rh = horn_rotations(X, x, [0, 8], np.arange(8))[0]
    q = v[:, -1]
    R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    np.testing.assert_allclose(Rh, R, atol=1e-10)
    u, _, vt = np.linalg.svd(Xc.T @ xc)  # Kabsch: R = V Uᵀ
    np.testing.assert_allclose(Rh, vt.T @ u.T, atol=1e-8)


def test_rigid_motion_gives_zero_warped_force(rng):
    mesh = voronoi_foam(12, seed=2)
    sim = Dynamics(mesh, 1e3, 0.3)
    for _ in range(3):
        R = Rotation.random(random_state=rng.integers(1 << 30)).as_matrix()
        sim.u = mesh.points @ R.T + rng.normal(size=3) * 5 - mesh.points
        f, energy = sim.elastic_forces()
        assert abs(f).max() < 1e-10 * 1e3 and energy < 1e-20
    # without warping a rotation does produce (spurious) forces
    lin = Dynamics(mesh, 1e3, 0.3, warping=False)
    lin.u = sim.u
    assert abs(lin.elastic_forces()[0]).max() > 1.0


def test_internal_forces_sum_to_zero(rng):
    sim = Dynamics(voronoi_foam(10, seed=7), 1e3, 0.3)
    sim.u = rng.normal(size=sim.u.shape) * 0.05
    f, _ = sim.elastic_forces()
    assert abs(f.sum(axis=0)).max() < 1e-11 * abs(f).max()


def test_warped_force_kernel_matches_numpy(rng):
    sim = Dynamics(voronoi_foam(5, seed=3), 50.0, 0.3)
    sim.u = rng.normal(size=sim.u.shape) * 0.1
    R = sim.rotations()
    f, energy = sim.elastic_forces(R)
    ref = np.zeros_like(f)
    eref = 0.0
    integ, ks = sim.integ, sim.kstiff
    for e in range(sim.mesh.n_elements):
        nd = integ.nodes[integ.node_offsets[e]:integ.node_offsets[e + 1]]
        d = sim.positions()[nd] @ R[e] - sim.mesh.points[nd]
        d -= d.mean(axis=0)
        Ke = ks.matrix(e)
        fe = -(Ke @ d.ravel()).reshape(-1, 3) @ R[e].T
        np.add.at(ref, nd, fe)
        eref += 0.5 * d.ravel() @ Ke @ d.ravel()
    np.testing.assert_allclose(f, ref, atol=1e-12 * abs(ref).max())
    assert energy == pytest.approx(eref, rel=1e-12)
    # rotated blocks vs einsum
    blocks = FK.rotated_blocks(integ.node_offsets, ks.offsets, ks.data, R)
    e_of_block = np.repeat(np.arange(len(R)), np.diff(integ.node_offsets) ** 2)
    ref_b = np.einsum("bij,bjk,blk->bil", R[e_of_block], ks.data.reshape(-1, 3, 3), R[e_of_block]).reshape(-1, 9)
    np.testing.assert_allclose(blocks, ref_b, atol=1e-12 * abs(ref_b).max())


def test_block_kernels_match_scipy(rng):
    sim = Dynamics(voronoi_foam(8, seed=1), 50.0, 0.3)
    p = sim.pattern
    blocks = rng.normal(size=(len(p.indices), 9))
    import scipy.sparse as sp

    A = sp.bsr_array((blocks.reshape(-1, 3, 3), p.indices, p.indptr), shape=(3 * p.n_nodes,) * 2)
    x = rng.normal(size=(p.n_nodes, 3))
    np.testing.assert_allclose(SK.bsr_matvec(p.indptr, p.indices, blocks, x).ravel(), A @ x.ravel(), atol=1e-12)


def _drop(solver: str, steps: int = 60) -> Dynamics:
    sim = Dynamics(hex_grid((2, 2, 2), origin=(0, 0.3, 0)), 50.0, 0.3, 1.0, ground=Ground(friction=0.5),
                   solver=solver, cg_tol=1e-10)
    for _ in range(steps):
        sim.step(0.005)
    return sim


def test_solvers_agree():
    a, b, c = (_drop(s, 80) for s in ("lu-pcg", "cg", "direct"))
    np.testing.assert_allclose(a.u, c.u, atol=1e-7)
    np.testing.assert_allclose(b.u, c.u, atol=1e-7)


def test_falling_element_bounces_and_settles():
    k = np.arange(6)
    top = np.c_[0.4 * np.cos(k * np.pi / 3), np.full(6, 0.25), 0.4 * np.sin(k * np.pi / 3)]
    bot = np.c_[0.45 * np.cos(k * np.pi / 3 + np.pi / 6), np.full(6, -0.25), 0.45 * np.sin(k * np.pi / 3 + np.pi / 6)]
    poly = convex_polyhedron(np.r_[top, bot] @ Rotation.from_euler("xyz", [25, 10, 15], degrees=True).as_matrix().T
                             + [0, 0.9, 0])
    assert poly.n_nodes == 12
    sim = Dynamics(poly, 50.0, 0.3, 1.0, ground=Ground(friction=0.5), rayleigh=(0.0, 0.01))
    m = sim.masses
    com, low, energy = [], [], []
    for _ in range(800):
        sim.step(0.004)
        x = sim.positions()
        com.append((m * x[:, 1]).sum() / m.sum())
        low.append(x[:, 1].min())
        energy.append(sim.kinetic_energy() + sim.elastic_energy())
    com, low = np.array(com), np.array(low)
    assert low.min() > -1e-9  # never below the ground
    first = int(np.argmax(low < 1e-9))
    bottom = first + int(np.argmin(com[first:first + 100]))
    assert com[bottom:bottom + 150].max() > com[bottom] + 0.05  # it bounces back up ...
    assert low[bottom:bottom + 150].max() > 1e-3  # ... and leaves the ground
    assert energy[-1] < 0.05 * max(energy)  # and comes to rest (damped)
    assert np.ptp(com[-100:]) < 0.02


def test_fixed_and_moving_nodes_and_loads():
    m = hex_grid((4, 1, 1), size=(4, 1, 1))
    left = np.flatnonzero(m.points[:, 0] == 0)
    right = np.flatnonzero(m.points[:, 0] == 4)
    sim = Dynamics(m, 1e3, 0.3, 1.0, gravity=(0, 0, 0), prescribed=[Prescribed(left), Prescribed(right, (0.1, 0, 0),
                                                                                                stop=0.5)],
                   rayleigh=(1.0, 0.01))
    for _ in range(50):
        sim.step(0.01)
    np.testing.assert_allclose(sim.u[right, 0], 0.05, atol=1e-12)  # moved with 0.1 for 0.5 s
    for _ in range(50):
        sim.step(0.01)
    assert abs(sim.u[left]).max() == 0
    assert sim.u[right, 0].max() < 0.04  # released: the stretched bar springs back
    sim2 = Dynamics(m, 1e3, 0.0, 1.0, gravity=(0, 0, 0), prescribed=[Prescribed(left)],
                    loads=[Load(right, (1.0, 0.0, 0.0))], rayleigh=(2.0, 0.0))
    for _ in range(300):
        sim2.step(0.05)
    # the damped motion settles at the static solution (about 4e-3 = F L / (Y A))
    from unmesh.fem import solve_static

    f = np.zeros((m.n_nodes, 3))
    f[right, 0] = 1.0 / len(right)
    static = solve_static(m, 1e3, 0.0, left, f)
    np.testing.assert_allclose(sim2.u, static, atol=2e-3 * abs(static).max())
    assert static[right, 0].mean() == pytest.approx(4e-3, rel=0.03)


def test_damping_dissipates_and_bad_arguments():
    m = hex_grid((2, 2, 2))
    with pytest.raises(InputError, match="solver"):
        Dynamics(m, 1.0, 0.3, solver="magic")
    with pytest.raises(InputError, match="density"):
        Dynamics(m, 1.0, 0.3, density=-1.0)
    sims = []
    for ray in ((0.0, 0.0), (0.0, 0.05)):
        s = Dynamics(m, 100.0, 0.3, gravity=(0, 0, 0), rayleigh=ray)
        s.v[:, 0] = m.points[:, 1] - 0.5  # shear motion
        for _ in range(20):
            s.step(0.01)
        sims.append(s.kinetic_energy() + s.elastic_energy())
    assert sims[1] < sims[0]


def test_reintegration_after_a_cut_equals_a_fresh_integration(rng):
    from unmesh.fem import element_stiffness, integrate_elements
    from unmesh.fem.cutting import PlaneCut, PolygonCut, apply_cuts

    mesh = voronoi_foam(12, seed=5)
    sim = Dynamics(mesh, 50.0, 0.3, 1.0, gravity=(0, 0, 0))
    sim.u = rng.normal(size=sim.u.shape) * 1e-3
    r = apply_cuts(mesh, [PlaneCut((0.5, 0.4, 0.5), (0.3, 1.0, 0.2)),
                          PolygonCut(np.array([[-1, 0.7, -1], [2, 0.7, -1], [2, 0.7, 0.5], [-1, 0.7, 0.5]]))])
    assert 0 < r.changed.sum() < r.mesh.n_elements
    sim.change_topology(r.mesh, r.node_weights, r.element_parent, r.changed)
    assert sim.flush() > 0
    fresh = integrate_elements(r.mesh)
    np.testing.assert_array_equal(sim.integ.nodes, fresh.nodes)
    np.testing.assert_allclose(sim.integ.volumes, fresh.volumes, rtol=1e-12)
    np.testing.assert_allclose(sim.integ.grads, fresh.grads, atol=1e-10 * abs(fresh.grads).max())
    ks = element_stiffness(fresh, 50.0, 0.3)
    np.testing.assert_allclose(sim.kstiff.data, ks.data, atol=1e-10 * abs(ks.data).max())
    assert sim.masses.sum() == pytest.approx(mesh.volume(), rel=1e-12)
    sim.step(0.01)  # and the dynamics run on the new mesh


def test_lu_pcg_keeps_its_factorisation_across_cuts_and_matches_the_direct_solver():
    """The lagged LU mapped through the cut's node weights plus the exact local solve on the
    touched and constrained nodes (multiplicative Schwarz) gives the direct solution."""
    from unmesh.fem.cutting import PlaneCut, apply_cuts

    mesh = hex_grid((3, 3, 3), origin=(0, 0.02, 0))
    sims = [Dynamics(mesh, 50.0, 0.3, 1.0, ground=Ground(friction=0.5), solver=s, cg_tol=1e-11)
            for s in ("lu-pcg", "direct")]
    sims[0].lagged.touched_fraction = 1.0  # a small mesh: keep the factorisation however much a cut touches
    sims[0].lagged.background = False  # (and start no refactorisation in the background either)
    cuts = [PlaneCut((0.5, 0.5, 0.5), (1.0, 0.3, 0.1)), PlaneCut((0.4, 0.5, 0.5), (0.2, 1.0, -0.3))]
    for k in range(12):
        if k in (4, 8):
            for sim in sims:
                r = apply_cuts(sim.mesh, [cuts[k // 4 - 1]])
                assert r.changed.any()
                sim.change_topology(r.mesh, r.node_weights, r.element_parent, r.changed)
        for sim in sims:
            sim.step(0.01)
        if k in (4, 8):
            lag = sims[0].lagged
            assert lag.factorizations == 1 and lag.touched is not None and lag.touched.any()
        np.testing.assert_allclose(sims[0].u, sims[1].u, atol=1e-9)
    assert sims[0].contact.any()
    assert sims[0].mesh.n_nodes > mesh.n_nodes


def test_schwarz_preconditioner_with_constraints_is_symmetric_positive(rng):
    from unmesh.fem.solvers import LaggedLU, node_rotations

    sim = Dynamics(voronoi_foam(10, seed=2), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    R = sim.rotations()
    K = FK.scatter_blocks(p.block_map, FK.rotated_blocks(sim.integ.node_offsets, sim.kstiff.offsets, sim.kstiff.data, R),
                          len(p.indices))
    A = SK.add_diagonal(K, p.diag, 1e-4, sim.masses, 1.0)
    lag = LaggedLU()
    lag.factor(p.indptr, p.indices, A, (1.0, 1e-4))
    lag.touched = rng.random(n) < 0.3
    kind = np.where(rng.random(n) < 0.1, 1, np.where(rng.random(n) < 0.2, 2, 0)).astype(np.int64)
    normal = np.array([0.0, 1.0, 0.0])
    Q = node_rotations(R, sim.integ.node_offsets, sim.integ.nodes, sim.integ.mu, n)
    prec = lag.preconditioner(Q, p.indptr, p.indices, A, kind, normal)
    x, y = rng.normal(size=(2, n, 3))
    for v in (x, y):
        SK.filter_inplace(v, kind, normal)
    assert np.vdot(prec(x), y) == pytest.approx(np.vdot(x, prec(y)), rel=1e-5)
    assert np.vdot(prec(x), x) > 0


@pytest.mark.parametrize("shape", [(), (3,), (3, 3)])
def test_gather_csr_kernel_matches_numpy(rng, shape):
    from unmesh.fem.integration import gather_csr

    lens = rng.integers(0, 7, 40)
    off = np.r_[0, np.cumsum(lens)]
    data = rng.normal(size=(off[-1], *shape))
    idx = rng.integers(0, 40, 60)
    fo, fd = gather_csr(off, data, idx)
    ro, rd = gather_csr(off, data, idx, fast=False)
    np.testing.assert_array_equal(fo, ro)
    np.testing.assert_array_equal(fd, rd)
    assert fd.shape == rd.shape


@pytest.mark.parametrize("shape", [(), (3,)])
def test_merge_csr_kernel_matches_numpy(rng, shape):
    from unmesh.fem.integration import merge_csr

    la, lb = rng.integers(0, 7, 30), rng.integers(0, 7, 20)
    oa, ob = np.r_[0, np.cumsum(la)], np.r_[0, np.cumsum(lb)]
    da, db = rng.normal(size=(oa[-1], *shape)), rng.normal(size=(ob[-1], *shape))
    from_b = rng.random(50) < 0.4
    idx = np.where(from_b, rng.integers(0, 20, 50), rng.integers(0, 30, 50))
    fo, fd = merge_csr(oa, da, ob, db, from_b, idx)
    ro, rd = merge_csr(oa, da, ob, db, from_b, idx, fast=False)
    np.testing.assert_array_equal(fo, ro)
    np.testing.assert_array_equal(fd, rd)
    i = int(np.flatnonzero(from_b)[0])
    np.testing.assert_array_equal(fd[fo[i]:fo[i + 1]], db[ob[idx[i]]:ob[idx[i] + 1]])
    buf = np.full((len(rd) + 5, *shape), np.nan)  # written into when long enough, ignored when too short
    for out, view in ((buf, True), (buf[:len(rd) - 1], False)):
        _, bd = merge_csr(oa, da, ob, db, from_b, idx, out=out)
        np.testing.assert_array_equal(bd, rd)
        assert np.shares_memory(bd, buf) == view


def test_piece_rotations_recover_rigid_rotations_of_each_piece(rng):
    from unmesh.fem.rotations import piece_rotations

    X = rng.normal(size=(30, 3))
    labels = np.repeat([0, 1, 2], 10)
    Rs = Rotation.random(2, random_state=3).as_matrix()
    x = X.copy()
    x[:10] = X[:10] @ Rs[0].T + [1.0, 2.0, 3.0]
    x[10:20] = X[10:20] @ Rs[1].T - 4.0
    w = rng.random(30) + 0.1
    w[20:] = 0.0  # no weight: identity
    Q = piece_rotations(X, x, w, labels, 3)
    np.testing.assert_allclose(Q[:2], Rs, atol=1e-12)
    np.testing.assert_array_equal(Q[2], np.eye(3))


def _spsolve_reference(sim, dt):
    """v⁺ of one implicit Euler step (9.1.4) by scipy's spsolve on the assembled system (no constraints)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    sim.flush()
    p, n = sim.pattern, sim.mesh.n_nodes
    R = sim.rotations()
    f, _ = sim.elastic_forces(R)
    K = FK.scatter_blocks(p.block_map, FK.rotated_blocks(sim.integ.node_offsets, sim.kstiff.offsets, sim.kstiff.data, R),
                          len(p.indices))
    K = sp.bsr_array((K.reshape(-1, 3, 3), p.indices, p.indptr), shape=(3 * n, 3 * n)).tocsr()
    A = sp.diags_array(np.repeat(sim.masses, 3)) + dt * dt * K
    b = (sim.masses[:, None] * sim.v + dt * (f + sim.external_forces())).ravel()
    used = np.repeat(sim._used, 3)
    v = np.zeros(3 * n)
    v[used] = spsolve(sp.csc_array(A[used][:, used]), b[used])
    return v.reshape(n, 3)


def _rotate_pieces(sim, rng, angles):
    """Move each connected piece rigidly (rotation about its centroid) plus a small deformation."""
    sim.flush()
    X = sim.mesh.points
    u = np.zeros_like(X)
    for k in range(sim.n_pieces):
        on = sim.piece == k
        c = X[on].mean(axis=0)
        R = Rotation.from_rotvec(angles[k % len(angles)] * np.array([0.3, 0.5, 1.0]) / np.linalg.norm([0.3, 0.5, 1.0]))
        u[on] = (X[on] - c) @ R.as_matrix().T + c + 0.1 * k - X[on]
    sim.u = u + 1e-3 * rng.normal(size=u.shape)
    sim.v = 0.1 * rng.normal(size=u.shape)


@pytest.mark.parametrize("solver", ["cg", "auto", "lu-pcg", "direct"])
def test_every_solver_matches_spsolve_on_a_cut_mesh_with_rotated_pieces(rng, solver):
    """Each solver path gives scipy's spsolve solution (to 1e-8 relative) after cuts, with
    pieces rotated far from the factorised configuration: a separating cut (refactorisation
    for "lu-pcg", rotation per piece) and then a slit that does not separate (the lagged
    factorisation mapped through the cut plus the local Schwarz solve)."""
    from unmesh.fem.cutting import PolygonCut, apply_cuts

    dt = 0.04
    sim = Dynamics(hex_grid((4, 2, 2)), 2e3, 0.3, 1.0, solver=solver, cg_tol=1e-11)
    sim.lagged.touched_fraction = 1.0  # a small mesh: keep the factorisation however much a cut touches
    sim.lagged.background = False  # (and start no refactorisation in the background either)
    sim.step(dt)
    separate = PolygonCut(np.array([[0.6, -1, -1], [0.6, 2, -1], [0.6, 2, 2], [0.6, -1, 2.0]]))
    slit = PolygonCut(np.array([[-1, 0.5, -1], [0.3, 0.5, -1], [0.3, 0.5, 2], [-1, 0.5, 2.0]]))
    for k, cut in enumerate((separate, slit)):
        r = apply_cuts(sim.mesh, [cut])
        assert r.changed.any()
        sim.change_topology(r.mesh, r.node_weights, r.element_parent, r.changed)
        _rotate_pieces(sim, rng, [1.2, -0.7])
        assert sim.n_solid_pieces == 2
        facts = sim.lagged.factorizations
        ref = _spsolve_reference(sim, dt)
        sim.step(dt)
        np.testing.assert_allclose(sim.v, ref, atol=1e-8 * abs(ref).max())
        if solver == "lu-pcg" and k == 1:  # the slit keeps the factorisation: lagged + Schwarz path
            assert sim.lagged.factorizations == facts and sim.lagged.touched.any()
    if solver == "auto":
        assert sim._stiff  # block-Jacobi gave up: the factorised path was exercised


def test_sub_blocks_equals_scipy_submatrix(rng):
    import scipy.sparse as sp

    from unmesh.fem.factor import _sub_blocks

    sim = Dynamics(voronoi_foam(10, seed=2), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    B = rng.normal(size=(len(p.indices), 9))
    A = sp.bsr_array((B.reshape(-1, 3, 3), p.indices, p.indptr), shape=(3 * n, 3 * n)).tocsr()
    t = np.flatnonzero(rng.random(n) < 0.3)
    d = (3 * t[:, None] + np.arange(3)).ravel()
    np.testing.assert_array_equal(_sub_blocks(p.indptr, p.indices, B, t).toarray(), A[d][:, d].toarray())
    from unmesh.fem.factor import _sub_block_array

    for got, ref in zip(_sub_block_array(p.indptr, p.indices, B, t),
                        _sub_block_array(p.indptr, p.indices, B, t, fast=False), strict=True):
        np.testing.assert_array_equal(got, ref)


def _filtered_blocks_reference(indptr, indices, blocks, kind, normal):
    n = len(indptr) - 1
    P = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    P[kind == 1] = 0.0
    P[kind == 2] -= np.outer(normal, normal)
    rows = np.repeat(np.arange(n), np.diff(indptr))
    out = P[rows] @ blocks.reshape(-1, 3, 3) @ P[indices]
    d = rows == indices
    out[d] += np.eye(3) - P[rows[d]]
    return out.reshape(-1, 9)


def test_filter_blocks_kernel_matches_the_projected_matrix(rng):
    sim = Dynamics(voronoi_foam(10, seed=4), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    A = SK.add_diagonal(K, p.diag, 1e-3, sim.masses, 1.0)
    kind = rng.integers(0, 3, n).astype(np.int64)
    normal = np.array([0.3, 0.9, -0.1]) / np.linalg.norm([0.3, 0.9, -0.1])
    got = SK.filter_blocks(p.indptr, p.indices, A, kind, normal)
    np.testing.assert_allclose(got, _filtered_blocks_reference(p.indptr, p.indices, A, kind, normal), atol=1e-12)


@pytest.mark.parametrize("metis", [True, False])
def test_lagged_lu_with_factorised_constraints_is_exact_for_them(rng, monkeypatch, metis):
    """Nested-dissection (or SuperLU's own) order, constraints factorised: the unrotated
    preconditioner is the exact inverse of the filtered matrix, so PCG takes one iteration."""
    import unmesh.fem.solvers as SV
    from unmesh.fem.solvers import LaggedLU, grow, pcg

    if not metis:
        monkeypatch.setattr(SV, "nested_dissection", lambda indptr, indices: None)
    sim = Dynamics(voronoi_foam(12, seed=5), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    A = SK.add_diagonal(K, p.diag, 1e-3, sim.masses, 1.0)
    kind = np.where(rng.random(n) < 0.1, 1, np.where(rng.random(n) < 0.2, 2, 0)).astype(np.int64)
    normal = np.array([0.0, 1.0, 0.0])
    lag = LaggedLU()
    lag.factor(p.indptr, p.indices, A, (1.0, 1e-3), kind=kind, normal=normal)
    assert (lag.perm is not None) == (metis and SV.nested_dissection(p.indptr, p.indices) is not None)
    b = rng.normal(size=(n, 3))
    Q = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    _, its, res = pcg(p.indptr, p.indices, A, b, np.zeros((n, 3)), kind, normal,
                      lag.preconditioner(Q, p.indptr, p.indices, A, kind, normal), 1e-10, 50)
    assert its <= 2 and res < 1e-10
    assert grow(p.indptr, p.indices, kind != 0, 1).sum() > (kind != 0).sum()


def test_fused_warped_assembly_and_its_row_gather_match_rotated_blocks_scattered(rng):
    sim = Dynamics(voronoi_foam(10, seed=7), 50.0, 0.3, 1.0)
    p = sim.pattern
    R = Rotation.random(sim.mesh.n_elements, random_state=3).as_matrix()
    ref = FK.scatter_blocks(p.block_map, FK.rotated_blocks(sim.integ.node_offsets, sim.kstiff.offsets, sim.kstiff.data, R),
                            len(p.indices))
    got = FK.warped_global_blocks(sim.integ.node_offsets, sim.kstiff.offsets, sim.kstiff.data, R, p.block_map,
                                  len(p.indices), 0.25)
    threads = numba.get_num_threads()
    try:
        for count in sorted({1, min(2, numba.config.NUMBA_NUM_THREADS)}):
            numba.set_num_threads(count)
            rows = FK.warped_global_rows(sim.integ.node_offsets, sim.kstiff.offsets, sim.kstiff.data, R,
                                         p.inc_offsets, p.inc_elements, p.inc_local, p.block_map, len(p.indices), 0.25)
            np.testing.assert_array_equal(rows, got)  # the row gather: the scatter's sums in the same order
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_allclose(got, 0.25 * ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    SK.add_masses(got, p.diag, sim.masses, 2.0)
    np.testing.assert_allclose(got, SK.add_diagonal(ref, p.diag, 0.25, sim.masses, 2.0), rtol=1e-12,
                               atol=1e-12 * np.abs(ref).max())


def test_row_subset_matvec_matches_the_full_product(rng):
    sim = Dynamics(voronoi_foam(10, seed=8), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    x = rng.normal(size=(n, 3))
    rows = np.flatnonzero(rng.random(n) < 0.3)
    np.testing.assert_allclose(SK.bsr_matvec_rows(p.indptr, p.indices, K, x, rows),
                               SK.bsr_matvec(p.indptr, p.indices, K, x)[rows], rtol=1e-12, atol=1e-12 * np.abs(K).max())



@pytest.mark.parametrize("nd_nodes", [1, 10**9])
def test_local_factorisation_solves_the_filtered_block_in_either_order(rng, monkeypatch, nd_nodes):
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    import unmesh.fem.factor as SV

    monkeypatch.setattr(SV, "LOCAL_ND_NODES", nd_nodes)
    sim = Dynamics(voronoi_foam(12, seed=10), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    A = SK.add_diagonal(K, p.diag, 1e-3, sim.masses, 1.0)
    kind = np.where(rng.random(n) < 0.1, 1, np.where(rng.random(n) < 0.2, 2, 0)).astype(np.int64)
    normal = np.array([0.0, 1.0, 0.0])
    nodes = np.flatnonzero(rng.random(n) < 0.5)
    _, lu = SV._local_factor(p.indptr, p.indices, A, nodes, kind, normal)
    assert (lu.perm is not None) == (nd_nodes == 1 and SV.nested_dissection(p.indptr, p.indices) is not None)
    ref = _filtered_blocks_reference(p.indptr, p.indices, A, kind, normal)
    full = sp.bsr_array((ref.reshape(-1, 3, 3), p.indices, p.indptr), shape=(3 * n, 3 * n)).tocsr()
    dof = (3 * nodes[:, None] + np.arange(3)).ravel()
    r = rng.normal(size=3 * len(nodes))
    np.testing.assert_allclose(lu.solve(r), spsolve(sp.csc_array(full[dof][:, dof]), r), rtol=1e-8, atol=1e-10)


def _foam_system(rng, seed=5):
    sim = Dynamics(voronoi_foam(12, seed=seed), 50.0, 0.3, 1.0)
    p, n = sim.pattern, sim.mesh.n_nodes
    K = FK.scatter_blocks(p.block_map, sim.kstiff.data.reshape(-1, 9), len(p.indices))
    A = SK.add_diagonal(K, p.diag, 1e-3, sim.masses, 1.0)
    kind = np.where(rng.random(n) < 0.1, 1, np.where(rng.random(n) < 0.2, 2, 0)).astype(np.int64)
    return p, n, A, kind, np.array([0.0, 1.0, 0.0])


def test_resumed_pcg_is_the_same_sequence_as_one_solve(rng):
    """A loose solve continued to a tight tolerance (or a solve stopped by maxiter and
    continued) does exactly the iterations of one solve: same iterate, same count."""
    from unmesh.fem.krylov import PCG, pcg

    p, n, A, kind, normal = _foam_system(rng)
    pinv = SK.block_jacobi(A, p.diag)

    def jacobi(r):
        return np.einsum("nij,nj->ni", pinv, r)

    b = rng.normal(size=(n, 3))
    x0 = np.zeros((n, 3))
    ref, its, res = pcg(p.indptr, p.indices, A, b, x0, kind, normal, jacobi, 1e-10, 500)
    assert res <= 1e-10 and its > 5
    cg = PCG(p.indptr, p.indices, A, b, x0, kind, normal, jacobi)
    _, its1, res1 = cg.run(1e-3, 500)
    _, its2, _ = cg.run(1e-3, 500)  # already converged to this tolerance
    x, its3, res3 = cg.run(1e-10, 500)
    assert res1 <= 1e-3 and its2 == 0 and its1 + its3 == its and res3 == res
    np.testing.assert_array_equal(x, ref)
    cg = PCG(p.indptr, p.indices, A, b, x0, kind, normal, jacobi)
    _, its1, res1 = cg.run(1e-10, 3)
    x, its3, _ = cg.run(1e-10, 500)
    assert its1 == 3 and res1 > 1e-10 and its1 + its3 == its
    np.testing.assert_array_equal(x, ref)


def test_lagged_lu_refactorises_when_many_nodes_differ_from_the_factorised_constraints(rng):
    """Nodes whose constraint differs from the factorised one are solved locally with
    LOCAL_RINGS layers; when those exceed ``touched_fraction`` of the mesh, refactorise."""
    from unmesh.fem.solvers import LaggedLU

    p, n, A, kind, normal = _foam_system(rng)
    Q = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    lag = LaggedLU()
    lag.factor(p.indptr, p.indices, A, (1.0, 1e-3), kind=kind, normal=normal)
    lag.preconditioner(Q, p.indptr, p.indices, A, kind, normal)
    assert lag.mismatch == 0.0 and not lag.needs_factor((1.0, 1e-3))
    one = kind.copy()
    one[np.flatnonzero(kind == 2)[0]] = 0
    lag.rings = 0  # a small mesh: three rings around any node cover it
    lag.preconditioner(Q, p.indptr, p.indices, A, one, normal)
    assert lag.mismatch == 1 / n and not lag.needs_factor((1.0, 1e-3))
    lag.preconditioner(Q, p.indptr, p.indices, A, np.zeros(n, np.int64), normal)
    assert lag.mismatch > 0.1 and lag.needs_factor((1.0, 1e-3))
    lag.factor(p.indptr, p.indices, A, (1.0, 1e-3), kind=np.zeros(n, np.int64), normal=normal)
    assert lag.mismatch == 0.0 and not lag.needs_factor((1.0, 1e-3))


@pytest.mark.parametrize("twice", [False, True])
def test_rotations_carried_across_a_cut_equal_a_fresh_horn_pass(twice):
    """After a cut the unchanged elements keep their rotations and only the re-integrated
    ones get a Horn pass; that must be exactly what a full pass over the new mesh gives."""
    from unmesh.fem.cutting import PlaneCut, apply_cuts

    sim = Dynamics(hex_grid((3, 3, 3), origin=(0, 0.02, 0)), 50.0, 0.3, 1.0, ground=Ground(), solver="lu-pcg")
    for _ in range(3):
        sim.step(0.02)
    sim.elastic_energy()  # the frame record: rotations of this state computed
    cuts = [PlaneCut((0.5, 0.5, 0.5), (1.0, 0.3, 0.1)), PlaneCut((0.4, 0.5, 0.5), (0.2, 1.0, -0.3))]
    for cut in cuts[: 2 if twice else 1]:
        r = apply_cuts(sim.mesh, [cut])
        sim.change_topology(r.mesh, r.node_weights, r.element_parent, r.changed)
    sim.flush()
    carried = sim._cached_rotations()
    assert carried is not None
    np.testing.assert_array_equal(carried, sim.rotations())
    sim.u = sim.u + 1e-3  # a new state: nothing carried over
    assert sim._cached_rotations() is None


def test_steps_with_cuts_are_the_same_on_one_and_on_two_threads(monkeypatch):
    """The per-element kernels (Horn, forces, assembly, integration, stiffness, pattern, matvec) give
    the same results on any number of threads, so the tuner's choice does not change the simulation."""
    from unmesh import _threads as sim_threads
    from unmesh.fem import dynamics, krylov
    from unmesh.fem.events import BladeEvent
    from unmesh.fem.simulation import FemSimulation

    for name in ("ELEMENT_PARALLEL_MIN", "CHANGED_PARALLEL_MIN", "SERIAL_NODES"):
        monkeypatch.setattr(dynamics, name, 0)
    monkeypatch.setattr(krylov, "MATVEC_PARALLEL_MIN", 0)
    path = np.array([[[0.45, 1.2, -0.1], [0.45, 1.2, 1.1]], [[0.55, -0.2, -0.1], [0.55, -0.2, 1.1]]])

    def run(count: int) -> list[np.ndarray]:
        monkeypatch.setattr(sim_threads, "_TUNERS", {})  # probe from the start: both choices are taken
        numba.set_num_threads(count)
        dyn = Dynamics(hex_grid((5, 4, 3), size=(1.0, 1.0, 1.0), origin=(0, 0.02, 0)), 2e3, 0.3, 1.0,
                       ground=Ground(), solver="lu-pcg")
        sim = FemSimulation(dyn, 0.02, [BladeEvent(0.0, 0.16, path)])
        for _ in range(10):
            sim.step()
        assert dyn.mesh.n_elements > 60  # the blade cut
        return [dyn.u, dyn.v, dyn.mesh.points, dyn.elastic_forces()[0]]

    threads = numba.get_num_threads()
    try:
        one = run(1)
        two = run(min(2, numba.config.NUMBA_NUM_THREADS))
    finally:
        numba.set_num_threads(threads)
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a, b)


def test_reserved_topology_buffers_change_nothing():
    """The stiffness buffers reserved for cuts (touched before the first step) give the same steps."""
    from unmesh.fem.events import BladeEvent
    from unmesh.fem.simulation import FemSimulation

    path = np.array([[[0.45, 1.2, -0.1], [0.45, 1.2, 1.1]], [[0.55, -0.2, -0.1], [0.55, -0.2, 1.1]]])

    def run(reserve: bool) -> list[np.ndarray]:
        dyn = Dynamics(hex_grid((5, 4, 3), size=(1.0, 1.0, 1.0), origin=(0, 0.02, 0)), 2e3, 0.3, 1.0,
                       ground=Ground(), solver="lu-pcg")
        if not reserve:
            dyn.reserve_topology_buffers = lambda: None
        sim = FemSimulation(dyn, 0.02, [BladeEvent(0.0, 0.16, path)])
        assert (dyn._kspare is not None) == reserve
        for _ in range(10):
            sim.step()
        assert dyn.mesh.n_elements > 60  # the blade cut
        return [dyn.u, dyn.v, dyn.kstiff.data]

    for a, b in zip(run(True), run(False), strict=True):
        np.testing.assert_array_equal(a, b)
