"""Integration (9.17–9.19), stiffness, assembly, masses (9.21), patch test, cantilever."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from unmesh.errors import InputError
from unmesh.fem import _fe_kernels as FK
from unmesh.fem import (
    constitutive_matrix,
    cut_by_plane,
    element_stiffness,
    hex_grid,
    integrate_elements,
    lumped_masses,
    solve_static,
    stiffness_matrix,
    tet_mesh,
    voronoi_foam,
)
from unmesh.fem.assembly import BlockPattern


def _skfem_tet_mesh(n: int, seed: int = 0):
    skfem = pytest.importorskip("skfem")
    m = skfem.MeshTet.init_tensor(*[np.linspace(0, 1, n + 1)] * 3)
    rng = np.random.default_rng(seed)
    p = m.p.copy()
    inner = np.all((p > 1e-9) & (p < 1 - 1e-9), axis=0)
    p[:, inner] += rng.uniform(-0.3, 0.3, size=(3, inner.sum())) / n  # irregular tets
    return skfem.MeshTet(p, m.t)


def test_tet_stiffness_equals_scikit_fem():
    skfem = pytest.importorskip("skfem")
    from skfem.models.elasticity import lame_parameters as lp
    from skfem.models.elasticity import linear_elasticity

    m = _skfem_tet_mesh(5)
    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP1()))
    assert basis.nodal_dofs[:, 1].tolist() == [3, 4, 5]  # interleaved like unmesh
    Ks = skfem.asm(linear_elasticity(*lp(1e3, 0.3)), basis).tocsr()
    K = stiffness_matrix(tet_mesh(m.p.T, m.t.T), 1e3, 0.3)
    assert abs(K - Ks).max() <= 1e-10 * abs(Ks).max()


def test_constitutive_matrix_matches_lame_kernel(rng):
    # K_e = Σ w Bᵀ C B with B of (9.14) in the strain order of (9.3) equals the Lamé kernel
    mesh = voronoi_foam(3, seed=4)
    integ = integrate_elements(mesh)
    ks = element_stiffness(integ, 7.0, 0.27)
    C = constitutive_matrix(7.0, 0.27)
    for e in range(mesh.n_elements):
        n = integ.node_offsets[e + 1] - integ.node_offsets[e]
        Ke = np.zeros((3 * n, 3 * n))
        for q in range(integ.sample_offsets[e], integ.sample_offsets[e + 1]):
            k = q - integ.sample_offsets[e]
            g = integ.grads[integ.grad_offsets[e] + k * n:integ.grad_offsets[e] + (k + 1) * n]
            B = np.zeros((6, 3 * n))
            B[0, 0::3], B[1, 1::3], B[2, 2::3] = g[:, 0], g[:, 1], g[:, 2]
            B[3, 0::3], B[3, 1::3] = g[:, 1], g[:, 0]  # γ_xy
            B[4, 0::3], B[4, 2::3] = g[:, 2], g[:, 0]  # γ_xz
            B[5, 1::3], B[5, 2::3] = g[:, 2], g[:, 1]  # γ_yz
            Ke += integ.weights[q] * B.T @ C @ B
        np.testing.assert_allclose(ks.matrix(e), Ke, atol=1e-12 * abs(Ke).max())


def test_weights_sum_to_volume_and_tets_use_one_sample():
    mesh = voronoi_foam(6, seed=9)
    integ = integrate_elements(mesh)
    sums = np.add.reduceat(integ.weights, integ.sample_offsets[:-1])
    np.testing.assert_allclose(sums, mesh.volumes(), rtol=1e-13)
    np.testing.assert_allclose(np.add.reduceat(integ.mu, integ.node_offsets[:-1]), 1.0, rtol=1e-13)
    tets = integrate_elements(tet_mesh(np.eye(4)[:, :3] + [[0, 0, 0]] * 4 + np.r_[[[0, 0, 0]], np.zeros((3, 3))],
                                       [[0, 1, 2, 3]]))
    assert tets.sample_offsets.tolist() == [0, 1]
    np.testing.assert_allclose(tets.mu, 0.25)


def test_integration_kernel_matches_python_reference():
    from unmesh.fem.mvc import mean_value_coordinates

    mesh = voronoi_foam(2, seed=1)
    integ = integrate_elements(mesh, correction=True)
    off, nodes = mesh.element_nodes()
    for e in range(mesh.n_elements):
        nd = nodes[off[e]:off[e + 1]]
        v = mesh.points[nd]
        toff, tris = mesh.element_triangles()
        t = np.searchsorted(nd, tris[toff[e]:toff[e + 1]])
        c = v.mean(axis=0)
        tv = np.einsum("ij,ij->i", v[t[:, 0]] - c, np.cross(v[t[:, 1]] - c, v[t[:, 2]] - c)) / 6
        V = tv.sum()
        mu = np.zeros(len(nd))
        for r in range(3):
            np.add.at(mu, t[:, r], tv / (3 * V))
        samples = np.r_[0.8 * v + 0.2 * c, 0.9 * v[t].mean(axis=1) + 0.1 * c]
        w = np.r_[V * mu / 2, tv / 2]
        _, g = mean_value_coordinates(v, t, samples)
        exact = np.zeros((len(nd), 3))
        cr = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]) / 6
        for r in range(3):
            np.add.at(exact, t[:, r], cr)
        g = g + (exact - np.einsum("q,qia->ia", w, g))[None] / V
        s0, s1 = integ.sample_offsets[e], integ.sample_offsets[e + 1]
        np.testing.assert_allclose(integ.weights[s0:s1], w, rtol=1e-12)
        np.testing.assert_allclose(integ.samples[s0:s1], samples, atol=1e-14)
        gk = integ.grads[integ.grad_offsets[e]:integ.grad_offsets[e + 1]].reshape(len(samples), len(nd), 3)
        np.testing.assert_allclose(gk, g, atol=1e-10 * abs(g).max())


def test_global_matrix_properties_and_scatter_kernel(rng):
    mesh = cut_by_plane(voronoi_foam(12, seed=3), (0.5, 0.5, 0.5), (1.0, 0.4, 0.2))
    K = stiffness_matrix(mesh, 100.0, 0.3)
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()
    # rigid modes are in the null space: translations and infinitesimal rotations
    x = mesh.points
    for mode in (np.tile([1.0, 0, 0], (len(x), 1)), np.c_[-x[:, 1], x[:, 0], np.zeros(len(x))]):
        assert abs(K @ mode.ravel()).max() <= 1e-10 * abs(K).max()
    # internal forces sum to zero for any displacement
    u = rng.normal(size=3 * len(x))
    f = (K @ u).reshape(-1, 3)
    assert abs(f.sum(axis=0)).max() <= 1e-10 * abs(f).max()
    w = np.linalg.eigvalsh(K.toarray())
    assert w[6] > 1e-8 * w[-1] and w[0] > -1e-9 * w[-1]  # PSD with exactly six zero modes
    # scatter kernel vs np.add.at
    ks = element_stiffness(mesh, 100.0, 0.3)
    pat = BlockPattern.build(ks.node_offsets, ks.nodes, mesh.n_nodes)
    ref = np.zeros((len(pat.indices), 9))
    np.add.at(ref, pat.block_map, ks.data.reshape(-1, 9))
    np.testing.assert_allclose(FK.scatter_blocks(pat.block_map, ks.data.reshape(-1, 9), len(pat.indices)), ref)


def test_lumped_masses_sum_to_mass():
    mesh = voronoi_foam(10, seed=5)
    m = lumped_masses(mesh, 2.5)
    assert m.sum() == pytest.approx(2.5, rel=1e-12)
    assert m.min() > 0


def _patch_error(mesh, correction: bool) -> float:
    rng = np.random.default_rng(1)
    A = rng.normal(size=(3, 3)) * 1e-2
    b = rng.normal(size=3) * 1e-2
    exact = mesh.points @ A.T + b
    bnd = np.unique(mesh.boundary_triangles())
    u = solve_static(mesh, 1e3, 0.3, bnd, np.zeros_like(exact), displacements=exact, correction=correction)
    return float(np.abs(u - exact).max() / np.abs(exact).max())


def test_patch_test_on_irregular_polyhedra():
    """Exact linear fields on Voronoi foams and randomly split cubes, only with the correction."""
    foam = voronoi_foam(40, seed=4)
    cube = hex_grid((2, 2, 2))
    rng = np.random.default_rng(3)
    for _ in range(6):
        cube = cut_by_plane(cube, rng.random(3), rng.normal(size=3))
    for mesh in (foam, cube):
        assert _patch_error(mesh, correction=True) < 1e-10
        assert _patch_error(mesh, correction=False) > 1e-4  # the printed quadrature alone fails it


def _cantilever(nx: int, ny: int, correction: bool = True) -> float:
    m = hex_grid((nx, ny, ny), size=(10, 1, 1))
    left = np.flatnonzero(np.isclose(m.points[:, 0], 0))
    right = np.flatnonzero(np.isclose(m.points[:, 0], 10))
    y, z = m.points[right, 1], m.points[right, 2]
    wy = np.where(np.isclose(y, 0) | np.isclose(y, 1), 0.5, 1.0)
    wz = np.where(np.isclose(z, 0) | np.isclose(z, 1), 0.5, 1.0)
    f = np.zeros((m.n_nodes, 3))
    f[right, 1] = -(wy * wz) / (wy * wz).sum()  # consistent end load, total 1
    u = solve_static(m, 1e3, 0.3, left, f, correction=correction)
    return float(-u[right, 1].mean())


def test_cantilever_converges_towards_euler_bernoulli():
    d = [_cantilever(n, n // 10) for n in (10, 20, 40)]
    assert d[0] < d[1] < d[2] < 4.0
    assert d[2] > 3.5


@pytest.mark.slow
def test_cantilever_within_four_percent():
    assert _cantilever(80, 8) == pytest.approx(4.0, rel=0.04)


def test_singular_static_system_is_reported():
    m = hex_grid((2, 1, 1))
    f = np.zeros((m.n_nodes, 3))
    f[0, 1] = 1
    with pytest.raises(InputError, match="singular"):
        solve_static(m, 1.0, 0.3, [], f)
    with pytest.raises(InputError, match="non-collinear"):
        solve_static(m, 1.0, 0.3, [0, 1], f)
    with pytest.raises(InputError, match="Poisson"):
        stiffness_matrix(m, 1.0, 0.5)


def test_static_solve_of_uniaxial_tension():
    m = hex_grid((4, 2, 2), size=(4, 1, 1))
    x = m.points
    # uniaxial stress σ_xx = s: u_x = s x / Y, u_y = -ν s y / Y, u_z = -ν s z / Y
    Y, nu, s = 10.0, 0.25, 0.5
    exact = np.c_[s * x[:, 0] / Y, -nu * s * x[:, 1] / Y, -nu * s * x[:, 2] / Y]
    left = np.flatnonzero(x[:, 0] == 0)
    right = np.isclose(x[:, 0], 4)
    K = stiffness_matrix(m, Y, nu)
    f = (K @ exact.ravel()).reshape(-1, 3)
    f[left] = 0
    assert abs(f[~right & (x[:, 0] > 0)]).max() < 1e-10  # interior equilibrium
    u = solve_static(m, Y, nu, left, f, displacements=exact)
    np.testing.assert_allclose(u, exact, atol=1e-12)
    assert isinstance(K, sp.csr_array)


def test_block_pattern_kernel_matches_numpy_reference():
    from unmesh.fem.cutting import PolygonCut, apply_cuts

    foam = voronoi_foam(12, seed=4)
    cut = apply_cuts(foam, [PolygonCut(np.array([[-1, 0.5, -1], [0.6, 0.5, -1], [0.6, 0.5, 2], [-1, 0.5, 2.0]]))]).mesh
    for mesh in (foam, cut, hex_grid((3, 2, 1))):
        off, nodes = mesh.element_nodes()
        fast = BlockPattern.build(off, nodes, mesh.n_nodes)
        ref = BlockPattern.build(off, nodes, mesh.n_nodes, fast=False)
        for name in ("indptr", "indices", "block_map", "diag", "inc_offsets", "inc_elements", "inc_local"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(ref, name), err_msg=name)
