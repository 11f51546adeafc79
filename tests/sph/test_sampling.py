"""Closest-packing lattices (8.20), slots, the nearest-lattice-point search (8.21) and the cubic fluid grid."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.kernels import poly6, spiky_derivative
from unmesh.shapes import Box, Sphere
from unmesh.sph import Material, SPHConfig, SPHObject, SPHSimulation
from unmesh.sph import _slot_kernels as SK
from unmesh.sph.sampling import (
    closest_packing,
    cubic_grid,
    gradient_moment,
    lattice_basis,
    lattice_points,
    lattice_slots,
    nearest_lattice_point,
    plane_spacings,
    sample_shape,
)


@pytest.mark.parametrize("dim, coordination", [(2, 6), (3, 12)])
def test_closest_packing_spacing_and_coordination(dim, coordination):
    d = 0.1
    p = closest_packing([0, 0, 0], [1, 1, 1], d, dim)
    dist = np.linalg.norm(p[:, None] - p[None], axis=2) + 10 * np.eye(len(p))
    assert np.isclose(dist.min(), d)
    centre = np.argmin(np.linalg.norm(p - p.mean(axis=0), axis=1))
    assert np.sum(np.isclose(dist[centre], d)) == coordination
    if dim == 2:
        assert np.all(p[:, 2] == 0.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_packing_fills_volume(dim):
    """Particles per volume equal the closest-packing density (1/(√3/2 d²) in 2D, √2/d³ in 3D)."""
    d = 0.05
    p = closest_packing([0, 0, 0], [1, 1, 1], d, dim)
    density = 1.0 / (np.sqrt(0.75) * d * d) if dim == 2 else np.sqrt(2.0) / d**3
    assert abs(len(p) / density - 1.0) < 0.03


def test_ccp_basis_eq_8_20():
    b = lattice_basis(3)
    assert np.allclose(np.linalg.norm(b, axis=0), 1.0)
    assert np.allclose(b.T @ b, [[1, 0.5, 0.5], [0.5, 1, 0.5], [0.5, 0.5, 1]])


@pytest.mark.parametrize("dim, count", [(2, 12), (3, 42)])
def test_slots_within_support(dim, count):
    vecs, coords, table = lattice_slots(dim, 2.0)
    assert len(vecs) == count
    assert np.allclose(coords @ lattice_basis(dim).T, vecs)
    half = table.shape[0] // 2
    for q, c in enumerate(coords):
        assert table[c[0] + half, c[1] + half, c[2] + half] == q


@pytest.mark.parametrize("dim", [2, 3])
def test_nearest_point_fast_matches_brute_force(dim):
    """Closed-form rounding (hexagonal split / D3) equals a brute-force search over lattice points."""
    rng = np.random.default_rng(0)
    y = rng.uniform(-2.6, 2.6, (8000, 3))
    if dim == 2:
        y[:, 2] = 0.0
    _vecs, coords, table = lattice_slots(dim, 2.0)
    tmat = SK.d3_transform(lattice_basis(dim)) if dim == 3 else np.eye(3)
    q, d2 = SK.nearest_slots(y, tmat, table, dim)
    # brute force over a big patch of lattice points
    rng_i = np.arange(-6, 7)
    if dim == 2:
        ii, jj = np.meshgrid(rng_i, rng_i, indexing="ij")
        cc = np.stack([ii.ravel(), jj.ravel(), 0 * ii.ravel()], axis=1)
    else:
        ii, jj, kk = np.meshgrid(rng_i, rng_i, rng_i, indexing="ij")
        cc = np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1)
    pts = cc @ lattice_basis(dim).T
    best = np.argmin(((y[:, None, :] - pts[None]) ** 2).sum(-1), axis=1)
    ref_d2 = ((y - pts[best]) ** 2).sum(-1)
    assert np.allclose(d2, ref_d2, atol=1e-12)
    lookup = {tuple(c): k for k, c in enumerate(coords.tolist())}
    ref_q = np.array([lookup.get(tuple(c), -1) for c in cc[best].tolist()])
    assert np.array_equal(q, ref_q)
    _c_np, d2_np = nearest_lattice_point(y[:500], dim)
    assert np.allclose(d2_np, ref_d2[:500], atol=1e-12)
    if dim == 3:  # the branch-free rounding of the lattice pass, from D3 coordinates z = T y
        z = y @ tmat.T
        qd, d2d = zip(*(SK._nearest_d3(a, b, c, table) for a, b, c in z), strict=True)
        assert np.array_equal(np.array(qd), q) and np.allclose(d2d, d2, rtol=1e-12, atol=1e-14)


def test_d3_rounding_gives_the_lattice_offset_of_its_point():
    """The lattice pass takes the lattice offset of the nearest point from the rounding's D3 coordinates
    k (d T⁻¹ k, no table): it equals the slot's vector wherever the point is a slot."""
    rng = np.random.default_rng(4)
    vecs, _coords, table = lattice_slots(3, 2.0)
    tmat = SK.d3_transform(lattice_basis(3))
    tinv = np.linalg.inv(tmat)
    size = table.shape[0]
    y = np.vstack([vecs, vecs + 0.2 * rng.uniform(-1.0, 1.0, vecs.shape), rng.uniform(-2.6, 2.6, (4000, 3))])
    q, _d2 = SK.nearest_slots(y, tmat, table, 3)
    assert (q >= 0).sum() > len(vecs)
    for yy, qq in zip(y, q, strict=True):
        idx, _best, *k = SK._d3_round_k(*(tmat @ yy), float(size // 2), float(size))
        if qq >= 0:
            assert idx >= 0 and np.abs(tinv @ np.array(k) - vecs[qq]).max() < 1e-14


def test_plane_spacings_and_box_margins():
    assert np.allclose(plane_spacings(2)[:2], [0.5, np.sqrt(0.75)])
    assert np.allclose(plane_spacings(3), [0.5, np.sqrt(2 / 3), np.sqrt(1 / 12)])
    d = 0.1
    p = closest_packing([0, 0, 0], [1, 1, 1], d, 3)
    margins = 0.5 * d * plane_spacings(3)
    assert np.allclose(p.min(axis=0), margins)


def test_sample_shape_inside_and_2d_cross_section():
    pts = sample_shape(Sphere(radius=0.5), 0.1, 3)
    assert np.all(np.linalg.norm(pts, axis=1) <= 0.5 + 1e-12)
    assert abs(len(pts) * 0.1**3 / np.sqrt(2) / (4 / 3 * np.pi * 0.125) - 1) < 0.1
    flat = sample_shape(Box(size=(2.0, 2.0, 1.0)), 0.1, 2)
    assert np.all(flat[:, 2] == 0.0) and abs(len(flat) * np.sqrt(0.75) * 0.01 / 4.0 - 1) < 0.05


def test_gradient_moment_lattice_values():
    assert abs(gradient_moment(2, 2.0) - 0.872) < 1e-3
    assert abs(gradient_moment(3, 2.0) - 0.949) < 1e-3
    assert gradient_moment(3, 3.0) > gradient_moment(3, 2.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_cubic_grid_fills_box_with_half_spacing_margins(dim):
    """The cubic grid holds volume/d^n particles, at spacing d, starting d/2 inside every face."""
    d = 0.05
    p = cubic_grid([0, 0, 0], [0.5, 0.3, 0.2], d, dim)
    assert len(p) == (10 * 6 * 4 if dim == 3 else 10 * 6)
    assert np.allclose(p.min(axis=0)[:dim], 0.5 * d) and np.allclose(p.max(axis=0)[:dim], np.array([0.5, 0.3, 0.2])[:dim] - 0.5 * d)
    dist = np.linalg.norm(p[:, None] - p[None], axis=2) + 10 * np.eye(len(p))
    assert np.isclose(dist.min(), d)
    centre = np.argmin(np.linalg.norm(p - p.mean(axis=0), axis=1))
    assert np.sum(np.isclose(dist[centre], d)) == 2 * dim
    if dim == 2:
        assert np.all(p[:, 2] == 0.0)
    box = Box(center=(0.25, 0.15, 0.1 if dim == 3 else 0.0), size=(0.5, 0.3, 0.2))
    assert np.array_equal(sample_shape(box, d, dim, lattice="cubic"), p)


@pytest.mark.parametrize("dim, count", [(2, 8), (3, 26)])
def test_cubic_lattice_points_and_gradient_moment(dim, count):
    """26 (3D) / 8 (2D) grid neighbours strictly within h = 2d; the moment by direct summation."""
    vecs = lattice_points(dim, 2.0, "cubic")
    assert len(vecs) == count and np.all(np.abs(vecs - np.round(vecs)) == 0)
    r = np.linalg.norm(vecs, axis=1)
    assert np.all((r > 0) & (r < 2.0))
    vol = 1.0 / (float(poly6(0.0, 2.0, dim)) + float(np.sum(poly6(r, 2.0, dim))))
    ref = -vol * np.sum(np.asarray(spiky_derivative(r, 2.0, dim)) * r) / dim
    assert np.isclose(gradient_moment(dim, 2.0, "cubic"), ref, rtol=1e-12)
    assert abs(gradient_moment(dim, 2.0, "cubic") - (0.874 if dim == 2 else 0.947)) < 1e-3


@pytest.mark.parametrize("dim", [2, 3])
def test_cubic_lattice_mass_gives_rest_density(dim):
    """With lattice = "cubic" the particle mass makes the density of the perfect grid exactly rho0 (8.4)."""
    d = 0.05
    x = cubic_grid([0, 0, 0], [0.5, 0.5, 0.5], d, dim)
    sim = SPHSimulation(SPHConfig(dim=dim, spacing=d, dt=1e-4, lattice="cubic"), {"w": Material("w", density=1000.0)},
                        [SPHObject("w", x, "w")])
    st = sim.particles()
    centre = np.argmin(np.linalg.norm(st.positions - st.positions.mean(axis=0), axis=1))
    assert np.isclose(st.densities[centre], 1000.0, rtol=1e-12)
    r = np.linalg.norm(lattice_points(dim, 2.0, "cubic"), axis=1)
    assert np.isclose(st.masses[0], 1000.0 * d**dim / (float(poly6(0.0, 2.0, dim)) + float(np.sum(poly6(r, 2.0, dim)))),
                      rtol=1e-12)


def test_cubic_lattice_is_for_fluids_only():
    """Solids and freezing materials need the closest packing (lattice shape matching)."""
    from unmesh.errors import InputError

    x = cubic_grid([0, 0, 0], [0.2, 0.2, 0], 0.05, 2)
    cfg = SPHConfig(dim=2, spacing=0.05, dt=1e-4, lattice="cubic")
    with pytest.raises(InputError, match="closest packing"):
        SPHSimulation(cfg, {"j": Material("j", elastic_stiffness=1e4)}, [SPHObject("j", x, "j", phase="solid")])
    with pytest.raises(InputError, match="closest packing"):
        SPHSimulation(cfg, {"w": Material("w", freeze_rate=1.0)}, [SPHObject("w", x, "w")])
    with pytest.raises(InputError, match="lattice"):
        SPHConfig(dim=2, spacing=0.05, dt=1e-4, lattice="hexagonal")
