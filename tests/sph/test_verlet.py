"""Verlet neighbour lists of the fluid (``SPHConfig.neighbor_skin``): the candidates of the last cell scan
give the same neighbour lists, densities and pressures as a scan, and the scan repeats exactly when needed."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.sph import Material, SPHConfig, SPHObject, SPHSimulation, box_planes
from unmesh.sph import _kernels as K
from unmesh.sph.fluid import density_reference


def _cloud(dim: int, seed: int, d: float = 0.05, side: float = 0.4) -> np.ndarray:
    rng = np.random.default_rng(seed)
    k = int(side / d)
    ax = (np.arange(k) + 0.5) * d
    mesh = np.meshgrid(*([ax] * dim), indexing="ij")
    x = np.zeros((k**dim, 3))
    x[:, :dim] = np.stack([m.ravel() for m in mesh], axis=1)
    x[:, :dim] += 0.2 * d * rng.standard_normal((len(x), dim))
    return x


def _sim(dim: int, seed: int = 0, skin: float = 0.2, walls: bool = False) -> SPHSimulation:
    x = _cloud(dim, seed)
    planes = box_planes([-0.1, -0.1, -0.1], [0.5, 0.5, 0.5], dim) if walls else ()
    cfg = SPHConfig(dim=dim, spacing=0.05, dt=1e-3, neighbor_skin=skin, gravity=(0, -9.81, 0))
    return SPHSimulation(cfg, {"w": Material("w", stiffness=100.0, negative_pressure=0.3)}, [SPHObject("w", x, "w")],
                         planes=planes)


def _brute_neighbours(x: np.ndarray, h: float) -> list[np.ndarray]:
    """Indices ``b != a`` with ``r² < h²`` (the kernels' test, the same float operations), ascending."""
    d0 = x[:, None, 0] - x[None, :, 0]
    d1 = x[:, None, 1] - x[None, :, 1]
    d2 = x[:, None, 2] - x[None, :, 2]
    close = d0 * d0 + d1 * d1 + d2 * d2 < h * h
    np.fill_diagonal(close, False)
    return [np.flatnonzero(row) for row in close]


@pytest.mark.parametrize("dim", [2, 3])
def test_list_pass_equals_the_scan_bit_for_bit(dim):
    """Right after a scan (same positions, same order) the candidates give identical outputs."""
    sim = _sim(dim, walls=True)
    nbr, nnbr, rho, p = sim.nbr.copy(), sim.nnbr.copy(), sim.rho.copy(), sim.p.copy()
    assert sim.ncand.min() > sim.nnbr.min()  # the skin adds candidates beyond h
    sim._density(scan=False)
    assert np.array_equal(nnbr, sim.nnbr)
    assert np.array_equal(rho, sim.rho) and np.array_equal(p, sim.p)
    for a in range(len(nnbr)):
        assert np.array_equal(nbr[a, : nnbr[a]], sim.nbr[a, : nnbr[a]])


@pytest.mark.parametrize("dim", [2, 3])
def test_candidates_are_the_pairs_within_h_plus_skin(dim):
    """``cand`` holds every particle within ``h + skin`` (itself included, ascending): brute force."""
    sim = _sim(dim, seed=1)
    hs = sim.h + sim.skin
    ref = _brute_neighbours(sim.x, hs)
    for a in range(len(sim.x)):
        want = np.sort(np.append(ref[a], a))
        assert np.array_equal(sim.cand[a, : sim.ncand[a]], want)


@pytest.mark.parametrize("dim", [2, 3])
def test_moved_cloud_keeps_exact_neighbours_until_rescan(dim):
    """After several random moves (together less than half the skin per particle) the steps use the stored
    candidates (no scan, particle order kept) and still find exactly the neighbours within h (brute force)
    and the reference density (8.4); one more move beyond half the skin triggers a scan."""
    sim = _sim(dim, seed=2)
    rng = np.random.default_rng(3)
    scans = sim.neighbor_scans
    uid = sim.uid.copy()
    limit = 0.5 * sim.skin
    for _ in range(4):
        step = rng.standard_normal(sim.x.shape)
        step[:, dim:] = 0.0
        step *= (0.24 * limit / np.linalg.norm(step, axis=1))[:, None]  # 4 x 0.24 < 1: still valid
        sim.x += step
        sim._update()
        assert sim.neighbor_scans == scans and np.array_equal(sim.uid, uid)
        ref = _brute_neighbours(sim.x, sim.h)
        for a in range(len(sim.x)):
            assert np.array_equal(sim.nbr[a, : sim.nnbr[a]], ref[a])
        assert np.allclose(sim.rho, density_reference(sim.x, sim.m, sim.h, dim), rtol=1e-12)
    assert K.max_displacement(sim.x, sim._xref) < limit
    sim.x[7] = sim._xref[7] + np.array([1.01 * limit, 0.0, 0.0])  # beyond half the skin from the scan positions
    sim._update()
    assert sim.neighbor_scans == scans + 1


def test_rescan_threshold_is_half_the_skin():
    """The candidates stay valid up to (just below) half the skin of displacement and not beyond."""
    sim = _sim(3, seed=4)
    scans = sim.neighbor_scans
    a = 5
    x0 = sim._xref[a, 1]
    sim.x[a, 1] = x0 + 0.5 * sim.skin * (1.0 - 2e-6)
    assert sim._candidates_valid()
    sim.x[a, 1] = x0 + 0.5 * sim.skin * 1.000001
    assert not sim._candidates_valid()
    sim._update()
    assert sim.neighbor_scans == scans + 1 and sim._candidates_valid()


@pytest.mark.parametrize("dim", [2, 3])
def test_steps_with_verlet_lists_follow_the_scan_every_step(dim):
    """A falling, splashing cloud in a box: 40 steps with the skin equal 40 steps that scan every step up to the
    round-off of the summation order (the particles are re-sorted less often)."""
    runs = []
    for skin in (0.0, 0.3):
        sim = _sim(dim, seed=5, skin=skin, walls=True)
        for _ in range(40):
            sim.step()
            assert sim.check() is None
        runs.append((sim, sim.particles()))
    (a, pa), (b, pb) = runs
    assert b.neighbor_scans < 40 < a.neighbor_scans  # the skin saved scans
    scale = np.abs(pa.velocities).max()
    assert np.allclose(pa.positions, pb.positions, rtol=0, atol=1e-10)
    assert np.allclose(pa.velocities, pb.velocities, rtol=0, atol=1e-8 * scale)
    assert np.allclose(pa.densities, pb.densities, rtol=1e-10)


def _jelly(skin: float) -> SPHSimulation:
    """An elastic block (closest packing, slightly disturbed, spinning) dropped into a box with some fluid."""
    from unmesh.sph.sampling import closest_packing

    rng = np.random.default_rng(3)
    d = 0.05
    x = closest_packing([0.05, 0.03, 0.05], [0.3, 0.23, 0.3], d, 3) + 0.05 * d * rng.standard_normal((1, 3))
    x = x + 0.02 * d * rng.standard_normal(x.shape)
    w = closest_packing([0.05, 0.3, 0.05], [0.2, 0.4, 0.2], d, 3)
    cfg = SPHConfig(dim=3, spacing=d, dt=5e-4, neighbor_skin=skin, gravity=(0, -9.81, 0))
    mats = {"j": Material("j", elastic_stiffness=2e4, young=500.0, poisson=0.3, goal_deformation=0.5),
            "w": Material("w", stiffness=100.0, negative_pressure=0.3)}
    return SPHSimulation(cfg, mats, [SPHObject("j", x, "j", phase="solid", velocity=(0.0, -1.5, 0.0),
                                                      angular_velocity=(0.0, 0.0, 4.0)), SPHObject("w", w, "w")],
                         planes=box_planes([0.0, 0.0, 0.0], [0.4, 0.6, 0.4], 3, open_top=True))


def test_elastic_steps_with_verlet_lists_follow_the_scan_every_step():
    """Elastic solids use the lists too: on steps without a re-sort the lattice pass reads its previous
    state row for row (``_order`` the identity). A spinning jelly block hitting the floor beside some
    water: 60 steps with the skin equal 60 steps that scan every step up to the summation order's round-off."""
    runs = []
    for skin in (0.0, 0.3):
        sim = _jelly(skin)
        assert (sim.skin > 0) == (skin > 0)
        for _ in range(60):
            sim.step()
            assert sim.check() is None
        runs.append((sim, sim.particles()))
    (a, pa), (b, pb) = runs
    assert b.neighbor_scans < 60 < a.neighbor_scans and b.neighbor_scans > 1  # it re-sorted, and less often
    assert np.abs(a.a).max() > 1e3  # the floor's push was felt (the accelerations of impact)
    scale = np.abs(pa.velocities).max()
    assert np.allclose(pa.positions, pb.positions, rtol=0, atol=1e-9)
    assert np.allclose(pa.velocities, pb.velocities, rtol=0, atol=1e-7 * scale)
    # the lattice transformations of each particle (read through the sort order, or row for row)
    ia, ib = np.argsort(a.uid), np.argsort(b.uid)
    assert np.abs(a.amat[ia]).max() > 0.5 and np.abs(a.amat[ia] - b.amat[ib]).max() < 1e-10


def test_elastic_resume_with_verlet_lists_is_exact():
    """A checkpoint taken between two scans restores the candidates and the lattice state: the run
    continues bit for bit as without the interruption."""
    a = _jelly(0.3)
    for _ in range(25):
        a.step()
    state = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in a.state_dict().items()}
    assert "verlet_xref" in state
    b = _jelly(0.3)
    b.load_state_dict(state)
    for _ in range(25):
        a.step()
        b.step()
    pa, pb = a.particles(), b.particles()
    assert np.array_equal(pa.positions, pb.positions) and np.array_equal(pa.velocities, pb.velocities)


def test_skin_is_off_for_phase_change_scenes():
    x = _cloud(2, 0)
    sim = SPHSimulation(SPHConfig(dim=2, spacing=0.05, dt=1e-4),
                        {"j": Material("j", elastic_stiffness=1e4, melt_rate=1.0, melting_point=1.0)},
                        [SPHObject("j", x, "j", phase="solid")])
    assert sim.skin == 0.0 and sim.cand.shape[0] == 0


def test_negative_skin_is_refused():
    with pytest.raises(InputError, match="neighbor_skin: expected a number >= 0"):
        SPHConfig(dim=2, spacing=0.05, dt=1e-4, neighbor_skin=-0.1)
