"""Support levels and adaptive neighbour gathering for clouds whose radii vary (thesis 3.1, 3.4).

The kernels search one cell grid per power-of-two band of the supports ``cutoff·σ_i``;
these tests check the bands, that the gathered candidates are exactly the samples a
brute force finds, that the candidates adapt to the local support (a few times the
true neighbour count, not the neighbours of the largest support), and that every
operator on varying-radius clouds equals the plain numpy reference.
"""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import mls
from unmesh.mls import MLSSurface
from unmesh.mls import _kernels as K
from unmesh.mls.surface import size_levels
from unmesh.surfels import SurfelCloud

from . import reference as ref
from . import samples as S


@pytest.fixture(scope="module")
def varying_cloud() -> SurfelCloud:
    """A unit sphere whose spacing and radii grow 5x from the south to the north pole (1814 samples)."""
    return S.varying_sphere_cloud(0.04, ratio=5.0)


@pytest.fixture(scope="module")
def outlier_cloud() -> SurfelCloud:
    """A uniform sphere (spacing 0.1) where 5 surfels have 6x the radius (like LDC samplings of meshes)."""
    c = S.sphere_cloud(0.1)
    r = c.radii.copy()
    r[[3, 400, 700, 1000, 1300]] *= 6.0
    return c.replace(radii=r)


def _queries(cloud: SurfelCloud, n: int, rng: np.random.Generator, scale: float = 1.5) -> np.ndarray:
    """Points near random samples, offset by up to ``scale`` local surfel radii in 3D."""
    idx = rng.choice(len(cloud), n, replace=False)
    off = rng.normal(size=(n, 3))
    off *= rng.uniform(0, scale, (n, 1)) * cloud.radii[idx, None] / np.linalg.norm(off, axis=1, keepdims=True)
    return cloud.positions[idx] + off


# -- levels ---------------------------------------------------------------------------------


def test_size_levels_bands_and_merging(rng):
    v = np.exp(rng.uniform(np.log(1e-3), 0.0, 5000))
    lev = size_levels(v, min_size=1)
    k = np.floor(np.log2(v.max() / v)).astype(int)
    np.testing.assert_array_equal(lev, np.unique(np.minimum(k, 7), return_inverse=True)[1])  # bands of 2x, capped
    # every value is at most its level's largest value and coarser levels hold larger values
    for lv in range(lev.max() + 1):
        assert v[lev == lv].min() > v[lev == lv + 1].max() if lv < lev.max() else True
    # sparse finer bands move into the next coarser one; the coarsest band always stays
    v2 = np.r_[np.full(10, 1.0), np.full(500, 0.3), np.full(20, 0.1)]
    assert np.bincount(size_levels(v2, min_size=64)).tolist() == [10, 520]
    assert size_levels(np.full(7, 0.2)).tolist() == [0] * 7


def test_levels_of_a_varying_cloud(varying_cloud, outlier_cloud):
    surf = MLSSurface(varying_cloud)
    grids = surf.level_grids
    assert len(grids) == 3 and sum(g.n_points for g in grids) == len(varying_cloud)
    supp = surf.cutoff * surf.sigmas[surf._order]
    start = 0
    for g in grids:  # cell edge >= largest support of the level + the gather margin
        assert g.cell_size >= supp[start:start + g.n_points].max() + surf._margin
        start += g.n_points
    assert "3 support level(s)" in repr(surf)
    assert len(MLSSurface(outlier_cloud).level_grids) == 2
    assert len(MLSSurface(S.sphere_cloud(0.1)).level_grids) == 1


# -- gathering ------------------------------------------------------------------------------


def _gather_all(surf: MLSSurface, centres: np.ndarray, margin: float) -> list[np.ndarray]:
    args = surf._kernel_args()
    out = []
    for c in centres:
        cand, cbuf, _ = K.work_buffers(len(surf.cloud) + 1)
        n = K.gather(np.ascontiguousarray(c), margin, args[0], *args[5:], np.empty((9, 2), np.int64), cand, cbuf)
        out.append(cand[:n].copy())
        np.testing.assert_array_equal(cbuf[:n], args[0][cand[:n], :9])
    return out


@pytest.mark.parametrize("which", ["varying", "outlier"])
def test_gather_equals_brute_force(which, varying_cloud, outlier_cloud, rng):
    cloud = varying_cloud if which == "varying" else outlier_cloud
    surf = MLSSurface(cloud)
    x = np.r_[_queries(cloud, 300, rng, 3.0), rng.uniform(-3, 3, (20, 3))]
    pos = cloud.positions[surf._order]
    supp = surf.cutoff * surf.sigmas[surf._order]
    for margin in (0.0, surf._margin):
        for c, got in zip(x, _gather_all(surf, x, margin), strict=True):
            d2 = ((pos - c) ** 2).sum(1)
            want = np.flatnonzero(d2 < ((supp + margin) * K._SLACK) ** 2)
            np.testing.assert_array_equal(got, want)  # same samples, ascending
            assert np.all(np.isin(np.flatnonzero(d2 < supp**2), got))  # every kernel reaching c


def test_candidates_adapt_to_the_local_support(varying_cloud, rng):
    """Candidates are a small multiple of the true neighbours, not all samples within the largest support."""
    surf = MLSSurface(varying_cloud)
    x = _queries(varying_cloud, 400, rng, 0.5)
    pos, supp = varying_cloud.positions, surf.cutoff * surf.sigmas
    ncand = np.array([len(c) for c in _gather_all(surf, x, surf._margin)])
    d2 = ((x[:, None, :] - pos[None]) ** 2).sum(-1)
    nbrs = (d2 < supp**2).sum(1)
    global_support = (d2 < surf.support**2).sum(1)
    assert np.all(ncand >= nbrs)
    assert np.mean(ncand / nbrs) < 2.0
    south = x[:, 2] < -0.5
    assert np.mean(global_support[south] / nbrs[south]) > 10  # what a single global support would scan


def test_refresh_regathers_into_larger_buffers(varying_cloud, rng):
    """Buffers smaller than, or exactly as long as, the candidate list are replaced by larger ones."""
    surf = MLSSurface(varying_cloud)
    args = surf._kernel_args()
    c = _queries(varying_cloud, 1, rng)[0]
    (want,) = _gather_all(surf, c[None], surf._margin)
    for size in (1, len(want) - 1, len(want), len(want) + 1):
        meta = np.zeros(2, np.int64)
        cand, cbuf, nbuf = K.refresh(c, surf._margin, args[0], *args[5:], np.empty((9, 2), np.int64),
                                     *K.work_buffers(size), np.empty(3), meta)
        assert meta.tolist() == [len(want), 1] and len(cand) > len(want) and len(cbuf) == len(nbuf) == len(cand)
        np.testing.assert_array_equal(cand[:len(want)], want)
        np.testing.assert_array_equal(cbuf[:len(want)], args[0][want, :9])


def test_candidate_buffer_grows_when_it_overflows(rng):
    """A support covering the whole cloud (> 1024 candidates per fit) gives the reference results."""
    surf = MLSSurface(S.sphere_cloud(0.1), sigma=0.6)
    assert len(surf.cloud) > K._CAP
    x = _queries(surf.cloud, 15, rng, 2.0)
    p, n = mls.project(surf, x)
    pr, nr = ref.project(surf, x)
    np.testing.assert_allclose(p, pr, atol=1e-9)
    np.testing.assert_allclose(n, nr, atol=1e-9)


# -- operators on varying-radius clouds against the numpy reference -------------------------


@pytest.mark.parametrize("options", [{}, {"degree": 1}, {"normal": "covariance"}, {"kernel": "wendland"}])
def test_project_equals_reference_with_varying_radii(options, varying_cloud, rng):
    surf = MLSSurface(varying_cloud, **options)
    x = _queries(varying_cloud, 40, rng, 2.0)
    p, n = mls.project(surf, x)
    pr, nr = ref.project(surf, x)
    np.testing.assert_allclose(p, pr, atol=1e-9)
    np.testing.assert_allclose(n, nr, atol=1e-9)


def test_project_and_inside_with_outliers_equal_reference(outlier_cloud, rng):
    surf = MLSSurface(outlier_cloud)
    x = np.r_[_queries(outlier_cloud, 40, rng, 2.0), outlier_cloud.positions[[3, 400]] * 1.01]
    p, n = mls.project(surf, x)
    pr, nr = ref.project(surf, x)
    np.testing.assert_allclose(p, pr, atol=1e-9)
    np.testing.assert_allclose(n, nr, atol=1e-9)
    np.testing.assert_array_equal(mls.inside(surf, x), ref.inside(surf, x))


def test_projection_accuracy_with_varying_radii(varying_cloud, rng):
    """The adaptive search changes nothing about the surface: projections stay on the sphere."""
    surf = MLSSurface(varying_cloud)
    pts, _ = S.sphere_surface_points(4000, rng)
    x = pts * (1 + rng.uniform(-0.03, 0.03, (len(pts), 1)))
    p, n, conv = mls.project(surf, x, return_converged=True)
    assert conv.all()
    sigma = surf.sigmas.max()
    assert np.abs(S.sphere_distance(p)).max() < 0.05 * sigma**2  # the quadratic step removes the sigma^2/2 bias
    assert S.angle_deg(n, S.sphere_normal(p)).max() < 1.0


@pytest.mark.parametrize("which", ["varying", "outlier"])
def test_intersect_equals_reference_with_varying_radii(which, varying_cloud, outlier_cloud, rng):
    cloud = varying_cloud if which == "varying" else outlier_cloud
    surf = MLSSurface(cloud)
    n = 60
    o = rng.normal(size=(n, 3))
    o *= 2.5 / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.uniform(-1.2, 1.2, (n, 3)) - o
    t, hit = mls.intersect(surf, o, d)
    tr, hr = ref.intersect(surf, o, d)
    np.testing.assert_array_equal(hit, hr)
    np.testing.assert_allclose(t[hit], tr[hit], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(hit, np.isfinite(S.ray_sphere(o, d)))
    # coarse samplings (sigma up to 0.26); the wide kernels of the outliers bend the surface near them
    np.testing.assert_allclose(t[hit], S.ray_sphere(o, d)[hit], atol=0.01 if which == "varying" else 0.03)


def test_raycast_of_a_varying_sphere_hits_where_the_sphere_is(varying_cloud):
    """Rays on a grid through both the dense and the coarse half agree with the exact sphere."""
    u = np.linspace(-1.2, 1.2, 61)
    uu, vv = np.meshgrid(u, u)
    for axis in (0, 2):  # looking along x (both halves side by side) and down z (the coarse pole)
        o = np.zeros((uu.size, 3))
        o[:, axis] = 3.0
        rest = [k for k in range(3) if k != axis]
        o[:, rest[0]], o[:, rest[1]] = uu.ravel(), vv.ravel()
        d = np.zeros_like(o)
        d[:, axis] = -1.0
        t, hit, nrm = mls.intersect(varying_cloud, o, d, return_normals=True)
        exact = S.ray_sphere(o, d)
        r = np.hypot(o[:, rest[0]], o[:, rest[1]])
        inner, outer = r < 0.97, r > 1.03
        assert hit[inner].all() and not hit[outer].any()
        assert np.abs(t[inner] - exact[inner]).max() < 0.01
        p = o[hit] + t[hit, None] * d[hit]
        assert S.angle_deg(nrm[hit], S.sphere_normal(p)).max() < 2.0


def test_packed_weights_equal_the_kernel_module(rng):
    """The division-free weights of the fits equal unmesh.kernels' clipped Gaussian (3.11) and Wendland (3.12)."""
    from numba import njit

    from unmesh.kernels._kernels import clipped_gaussian_w, wendland_c2_w

    @njit
    def both(d2, s, cutoff, kernel):
        h = cutoff * s
        inv = 1.0 / (s * s) if kernel == 0 else 1.0 / h
        ref = clipped_gaussian_w(d2, s, cutoff) if kernel == 0 else wendland_c2_w(np.sqrt(d2), h)
        return K._wrow(d2, h * h, inv, kernel), ref

    s = rng.uniform(0.01, 1.0, 2000)
    d2 = (rng.uniform(0, 3.5, 2000) * s) ** 2
    d2[:10] = (3.0 * s[:10]) ** 2  # exactly at the cut-off: both zero
    for kernel in (0, 1):
        got = np.array([both(a, b, 3.0, kernel) for a, b in zip(d2, s, strict=True)])
        np.testing.assert_allclose(got[:, 0], got[:, 1], rtol=1e-14, atol=1e-16)  # weights <= 1
        np.testing.assert_array_equal(got[:, 0] > 0, got[:, 1] > 0)


# -- the remaining numba helpers against numpy ------------------------------------------------


@pytest.mark.parametrize("which", ["varying", "outlier"])
def test_first_disc_equals_brute_force(which, varying_cloud, outlier_cloud, rng):
    """The ray-grid DDA walks (all levels, empty-space skipping) find the nearest disc hit in [tlo, thi]."""
    from unmesh.mls import _ray_kernels as RK

    cloud = varying_cloud if which == "varying" else outlier_cloud
    surf = MLSSurface(cloud)
    gpack, grho = surf._arrays
    grid = surf.ray_grid()
    n = 300
    o = rng.normal(size=(n, 3))
    o *= rng.uniform(0.5, 3.0, (n, 1)) / np.linalg.norm(o, axis=1, keepdims=True)  # some start inside
    d = rng.uniform(-1.0, 1.0, (n, 3)) - o * rng.uniform(0, 1, (n, 1))
    tlo = rng.uniform(-0.3, 1.0, n)
    thi = tlo + rng.uniform(0.1, 4.0, n)
    pos, nrm = gpack[:, :3], gpack[:, 3:6]
    best = np.empty(2)
    for i in range(n):
        den = nrm @ d[i]
        with np.errstate(divide="ignore", invalid="ignore"):
            th = np.einsum("ij,ij->i", nrm, pos - o[i]) / den
        e = o[i] + th[:, None] * d[i] - pos
        ok = (den != 0) & (th >= tlo[i]) & (th <= thi[i]) & (np.einsum("ij,ij->i", e, e) <= grho**2)
        found = RK.first_disc(o[i], d[i], tlo[i], thi[i], gpack, grho, *grid, best)
        assert found == ok.any()
        if found:
            assert best[0] == pytest.approx(th[ok].min(), abs=1e-12)
            j = int(best[1])
            assert ok[j] and th[j] == pytest.approx(th[ok].min(), abs=1e-12)


def test_solve_spd_and_smallest_eigenvector_equal_numpy(rng):
    for _ in range(200):
        m = rng.normal(size=(6, 6))
        a = m @ m.T + 0.1 * np.eye(6)
        b = rng.normal(size=6)
        work, x = np.triu(a).copy(), b.copy()  # only the upper triangle is read
        assert K.solve_spd(work, x, 6)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-9)
        c = rng.normal(size=(3, 3))
        c = c @ c.T
        v = np.array(K.smallest_eigenvector(c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2]))
        w, vec = np.linalg.eigh(c)
        if w[1] - w[0] > 1e-6 * w[2]:
            assert abs(v @ vec[:, 0]) == pytest.approx(1.0, abs=1e-8)
    singular = np.zeros((6, 6))
    singular[0, 0] = 1.0
    assert not K.solve_spd(singular, np.ones(6), 6)  # rank-deficient fits are reported
    for n in np.r_[rng.normal(size=(100, 3)), [[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0]]]:
        n = n / np.linalg.norm(n)
        t1, t2 = (np.array(t) for t in K.tangent_frame(*n))
        frame = np.stack([t1, t2, n])
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)  # orthonormal
        np.testing.assert_allclose(np.cross(t1, t2), n, atol=1e-12)  # right-handed


def test_bracketed_ray_iteration_equals_reference_on_noisy_normals(rng):
    """With noisy sample normals the plane steps of Algorithm 3.1 overshoot and change sign, so the
    regula-falsi branch of the ray iteration runs; the kernel still equals the reference and hits
    where the sphere is."""
    c = S.sphere_cloud(0.1)
    n = c.normals + rng.normal(0, 0.3, c.normals.shape)
    surf = MLSSurface(c.replace(normals=n / np.linalg.norm(n, axis=1, keepdims=True)))
    m = 150
    o = rng.normal(size=(m, 3))
    o *= 3 / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.uniform(-0.8, 0.8, (m, 3)) - o
    t, hit = mls.intersect(surf, o, d)
    ref.BRACKET_STEPS[0] = 0
    tr, hr = ref.intersect(surf, o, d)
    assert ref.BRACKET_STEPS[0] > 20
    np.testing.assert_array_equal(hit, hr)
    np.testing.assert_allclose(t[hit], tr[hit], rtol=0, atol=1e-9)
    exact = S.ray_sphere(o, d)
    np.testing.assert_array_equal(hit, np.isfinite(exact))
    assert np.abs(t[hit] - exact[hit]).max() < 2e-3


@pytest.mark.parametrize("shape", ["sphere", "torus"])
def test_uniform_accuracy_is_unchanged_by_the_levels(shape, sphere_surface, torus_surface, rng):
    """The accuracy measured before the support levels (sphere ~1e-7, torus ~1e-6, normals < 0.05 deg)."""
    if shape == "sphere":
        surf, (pts, _), dist, normal, lim = sphere_surface, S.sphere_surface_points(5000, rng), S.sphere_distance, \
            S.sphere_normal, 3e-7
    else:
        surf, (pts, _), dist, normal, lim = torus_surface, S.torus_surface_points(5000, rng), S.torus_distance, \
            S.torus_normal, 3e-6
    assert len(surf.level_grids) == 1
    off = rng.normal(size=pts.shape)
    off *= rng.uniform(0, 3 * S.H, (len(pts), 1)) / np.linalg.norm(off, axis=1, keepdims=True)
    p, n = mls.project(surf, pts + off)
    assert np.abs(dist(p)).max() < lim
    assert S.angle_deg(n, normal(p)).max() < 0.05
