"""Clipping partners (4.2.1): clip buffer (Algorithm 4.1) and range queries vs brute force."""

import numpy as np
import pytest

from unmesh.csg import find_partners
from unmesh.csg.partners import METHODS, partners_brute_force


def _cloud(rng, n, npatch):
    pos = rng.uniform(-1, 1, (n, 3))
    pos[: n // 4, 2] *= 1e-3  # a flat layer: many surfels seen edge-on in some projections
    nrm = rng.normal(size=(n, 3))
    nrm[: n // 8] = [1.0, 0, 0]  # edge-on along x and y
    nrm[n // 8: n // 4] = [0, 1.0, 0]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    radii = np.exp(rng.uniform(np.log(0.01), np.log(0.3), n))
    radii[:3] = 0.9  # a few huge surfels (one surfel per face)
    return pos, nrm, radii, rng.integers(0, npatch, n)


def _discs_intersect(pos, nrm, radii):
    """(N, N) bool: the discs (centre, unit normal, radius) truly intersect (brute force)."""
    n = len(pos)
    i, j = np.triu_indices(n, 1)
    u = np.cross(nrm[i], nrm[j])
    uu = (u * u).sum(1)
    hit = np.zeros(len(i), bool)
    par = uu < 1e-18
    # parallel planes: coplanar and closer than the sum of radii
    d = pos[j] - pos[i]
    hit[par] = (np.abs((d[par] * nrm[i][par]).sum(1)) < 1e-12) & ((d[par] ** 2).sum(1) < (radii[i] + radii[j])[par] ** 2)
    q = ~par
    d1 = (nrm[i][q] * pos[i][q]).sum(1)
    d2 = (nrm[j][q] * pos[j][q]).sum(1)
    uq = u[q]
    p = (d1[:, None] * np.cross(nrm[j][q], uq) + d2[:, None] * np.cross(uq, nrm[i][q])) / uu[q][:, None]
    uh = uq / np.sqrt(uu[q])[:, None]
    lo, hi = [], []
    ok = np.ones(q.sum(), bool)
    for c, r in ((pos[i][q], radii[i][q]), (pos[j][q], radii[j][q])):
        w = c - p
        t = (w * uh).sum(1)
        h2 = (w * w).sum(1) - t * t
        ok &= h2 < r * r
        half = np.sqrt(np.clip(r * r - h2, 0, None))
        lo.append(t - half)
        hi.append(t + half)
    hit[q] = ok & (np.maximum(lo[0], lo[1]) < np.minimum(hi[0], hi[1]))
    out = np.zeros((n, n), bool)
    out[i, j] = hit
    return out | out.T


def _pairs(off, idx):
    return set(zip(np.repeat(np.arange(len(off) - 1), np.diff(off)).tolist(), idx.tolist(), strict=True))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_range_partners_equal_brute_force(seed):
    rng = np.random.default_rng(seed)
    pos, nrm, radii, patch = _cloud(rng, 700, 4)
    ref = partners_brute_force(pos, radii, patch)
    off, idx = find_partners(pos, radii, patch, nrm, method="range")
    assert np.array_equal(off, ref[0]) and np.array_equal(idx, ref[1])


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_partners_contain_every_truly_intersecting_pair(method, seed):
    rng = np.random.default_rng(seed)
    pos, nrm, radii, patch = _cloud(rng, 700, 4)
    truth = _discs_intersect(pos, nrm, radii) & (patch[:, None] != patch[None, :])
    true_pairs = set(zip(*map(np.ndarray.tolist, np.nonzero(truth)), strict=True))
    assert len(true_pairs) > 500
    found = _pairs(*find_partners(pos, radii, patch, nrm, method=method))
    assert true_pairs <= found
    assert found <= _pairs(*partners_brute_force(pos, radii, patch))  # the 4.2.1 estimate holds


def test_no_partners_within_one_patch_and_symmetry():
    rng = np.random.default_rng(5)
    pos, nrm, radii, patch = _cloud(rng, 300, 2)
    off, idx = find_partners(pos, radii, patch, nrm)
    rows = np.repeat(np.arange(len(pos)), np.diff(off))
    assert np.all(patch[rows] != patch[idx])
    pairs = set(zip(rows.tolist(), idx.tolist(), strict=True))
    assert all((j, i) in pairs for i, j in pairs)


def test_clip_buffer_without_normals_uses_bounding_spheres():
    """Without normals every surfel covers its bounding sphere's box: the 4.2.1 estimate exactly."""
    rng = np.random.default_rng(3)
    pos, _, radii, patch = _cloud(rng, 300, 3)
    ref = partners_brute_force(pos, radii, patch)
    off, idx = find_partners(pos, radii, patch)
    assert np.array_equal(off, ref[0]) and np.array_equal(idx, ref[1])


@pytest.mark.parametrize("seed", [0, 1])
def test_clip_buffer_kernel_equals_numpy_reference(seed):
    """The numba clip buffer returns exactly the pairs of the estimate that share a cell."""
    from unmesh.csg.partners import clip_buffer_reference

    rng = np.random.default_rng(seed)
    pos, nrm, radii, patch = _cloud(rng, 600, 3)
    ref = clip_buffer_reference(pos, radii, patch, nrm)
    off, idx = find_partners(pos, radii, patch, nrm, method="clipbuffer")
    assert len(ref[1]) > 500
    assert np.array_equal(off, ref[0]) and np.array_equal(idx, ref[1])


@pytest.mark.parametrize("seed", [0, 1])
def test_grid_kernel_equals_numpy_reference(seed):
    """The 3D clip grid returns exactly the pairs of the estimate whose disc boxes overlap."""
    from unmesh.csg.partners import grid_reference

    rng = np.random.default_rng(seed)
    pos, nrm, radii, patch = _cloud(rng, 600, 3)
    ref = grid_reference(pos, radii, patch, nrm)
    off, idx = find_partners(pos, radii, patch, nrm, method="grid")
    assert len(ref[1]) > 500
    assert np.array_equal(off, ref[0]) and np.array_equal(idx, ref[1])


def test_grid_result_does_not_depend_on_the_cell_size():
    """Coarsened grids (huge surfels, few cells) give the same pairs as fine ones."""
    from unmesh.csg._kernels import disc_boxes, grid_boxes, grid_csr

    rng = np.random.default_rng(7)
    pos, nrm, radii, patch = _cloud(rng, 400, 3)
    lo = pos.min(axis=0) - 1.0
    out = []
    for cell in (0.05, 0.3, 5.0):
        dims = (np.ptp(pos, axis=0) + 2.0) // cell + 1
        half, _, _ = disc_boxes(pos, radii, nrm)
        box, _ = grid_boxes(pos, half, lo, cell, dims.astype(np.int64))
        out.append(grid_csr(pos, radii, np.sort(patch).astype(np.int64), half, box, dims.astype(np.int64), 3))
    for off, idx in out[1:]:
        assert np.array_equal(off, out[0][0]) and np.array_equal(idx, out[0][1])


def test_grid_with_surfels_ordered_by_patch_equals_reference():
    """The kernel's own path (surfels already ordered by patch, as in every CSG frame)."""
    from unmesh.csg.partners import grid_reference

    rng = np.random.default_rng(11)
    pos, nrm, radii, patch = _cloud(rng, 600, 4)
    patch = np.sort(patch)
    ref = grid_reference(pos, radii, patch, nrm)
    off, idx = find_partners(pos, radii, patch, nrm, method="grid")
    assert len(ref[1]) > 300
    assert np.array_equal(off, ref[0]) and np.array_equal(idx, ref[1])
