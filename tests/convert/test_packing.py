"""Algorithm 6.1: patches land inside their pages, never overlap, and fill the pages."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.convert._packing_kernels import first_fit, pack_page
from unmesh.convert.atlas import patch_masks
from unmesh.convert.packing import (
    Placement,
    _profile_arrays,
    base_angles,
    fill_bound,
    first_fit_reference,
    pack,
    pack_page_reference,
)


def _random_patches(n, seed=0):
    rng = np.random.default_rng(seed)
    length = np.ones(n)
    apex = np.c_[rng.uniform(0.1, 0.9, n), rng.uniform(0.3, 0.85, n)]
    level = rng.integers(0, 6, n)
    s = 2.0**level
    w = (s + 2).astype(np.int64)
    h = (np.maximum(np.ceil(apex[:, 1] * s - 1e-9), 1) + 2).astype(np.int64)
    corners = np.zeros((n, 3, 2))
    corners[:, 1, 0] = s
    corners[:, 2] = apex * s[:, None]
    corners[:, :, 0] += 1
    corners[:, :, 1] = (h[:, None] - 1) - corners[:, :, 1]
    masks, _, _ = patch_masks(corners, w, h)
    return masks, base_angles(length, apex)


@pytest.mark.parametrize("best_fit", [0, 16])
def test_placements_are_disjoint_and_inside_the_pages(best_fit):
    masks, angles = _random_patches(1500)
    pl = pack(masks, angles, page_size=256, best_fit=best_fit)
    assert all(e & (e - 1) == 0 and e <= 256 for e in pl.pages)
    pages = [np.zeros((e, e), np.int64) for e in pl.pages]
    for i, m in enumerate(masks):
        mm = m[:, ::-1] if pl.flip_h[i] else m
        mm = mm[::-1] if pl.flip_v[i] else mm
        page = pages[pl.page[i]]
        y, x = pl.y[i], pl.x[i]
        assert x >= 0 and y >= 0 and y + mm.shape[0] <= page.shape[0] and x + mm.shape[1] <= page.shape[1]
        page[y:y + mm.shape[0], x:x + mm.shape[1]] += mm
    assert max(p.max() for p in pages) == 1  # no texel used twice
    used = sum(int(p.sum()) for p in pages)
    assert used == sum(int(m.sum()) for m in masks)
    fill = used / sum(e * e for e in pl.pages)
    assert np.isclose(fill, sum(f * e * e for f, e in zip(pl.fill, pl.pages, strict=True)) / sum(e * e for e in pl.pages))
    print(f"fill {fill:.3f}, pages {pl.pages}")
    assert fill > 0.84  # measured 0.87 (best_fit 0 and 16); the thesis reports 0.85-0.95


def _empty(n):
    return Placement(np.zeros(n, np.int64), np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros(n, bool),
                     np.zeros(n, bool), [], [])


@pytest.mark.parametrize("edge", [64, 128])
def test_kernel_is_algorithm_6_1_of_the_numpy_reference(edge):
    masks, angles = _random_patches(400, seed=3)
    items = np.argsort(-np.array([m.shape[0] for m in masks]), kind="stable").astype(np.int64)
    ref = _empty(len(masks))
    rest_ref = pack_page_reference(items.tolist(), masks, angles, edge, 0.05, ref, 0)
    got = _empty(len(masks))
    h, w, lft, rgt, off = _profile_arrays(masks)
    rest = pack_page(items, h, w, lft, rgt, off, angles[:, 0].copy(), angles[:, 1].copy(), edge, 0.05, 0,
                     got.page, got.x, got.y, got.flip_h, got.flip_v, 0)
    assert sorted(items[rest].tolist()) == sorted(rest_ref)
    for a in ("x", "y", "flip_h", "flip_v"):
        assert np.array_equal(getattr(got, a), getattr(ref, a)), a


def test_every_second_patch_of_a_row_is_mirrored_vertically():
    masks, angles = _random_patches(200, seed=2)
    pl = pack(masks, angles, page_size=512)
    assert 0.3 < pl.flip_v.mean() < 0.7


def _patches(levels, apex, offset=0.5):
    """Footprints of triangles with base 1 and the given apexes at the given levels (corners
    ``offset`` texels from the patch edges, as :func:`unmesh.convert.atlas.patch_corners`)."""
    s = 2.0**levels
    extra = round(2 * offset)
    w = (s + extra).astype(np.int64)
    h = (np.maximum(np.ceil(apex[:, 1] * s - 1e-9), 1) + extra).astype(np.int64)
    corners = np.zeros((len(levels), 3, 2))
    corners[:, 1, 0] = s
    corners[:, 2] = apex * s[:, None]
    corners[:, :, 0] += offset
    corners[:, :, 1] = (h[:, None] - offset) - corners[:, :, 1]
    masks, _, _ = patch_masks(corners, w, h)
    return masks, base_angles(np.ones(len(levels)), apex)


def _igea_like(n, seed):
    """Patches with the level histogram of Igea at 11,340 triangles (levels 0-7: 241, 4216, 5651,
    973, 131, 77, 34, 17) and apexes spread like its triangles' (x/L in 0.08-0.92, y/L in
    0.05-0.81 for 98 % of them), the longest edge as the base."""
    rng = np.random.default_rng(seed)
    hist = np.array([241, 4216, 5651, 973, 131, 77, 34, 17], float)
    levels = rng.choice(8, size=n, p=hist / hist.sum())
    apex = np.empty((0, 2))
    while len(apex) < n:
        a = np.c_[rng.uniform(0.08, 0.92, 2 * n), rng.uniform(0.05, 0.81, 2 * n)]
        ok = (a[:, 0] ** 2 + a[:, 1] ** 2 <= 1) & ((1 - a[:, 0]) ** 2 + a[:, 1] ** 2 <= 1)
        apex = np.vstack([apex, a[ok]])
    return _patches(levels, apex[:n])


def _check(masks, pl):
    """Brute force: every patch inside its page, no texel used twice; returns the used texels."""
    pages = [np.zeros((e, e), np.int64) for e in pl.pages]
    for i, m in enumerate(masks):
        mm = m[:, ::-1] if pl.flip_h[i] else m
        mm = mm[::-1] if pl.flip_v[i] else mm
        assert 0 <= pl.page[i] < len(pages)
        page = pages[pl.page[i]]
        y, x = pl.y[i], pl.x[i]
        assert x >= 0 and y >= 0 and y + mm.shape[0] <= page.shape[0] and x + mm.shape[1] <= page.shape[1]
        page[y:y + mm.shape[0], x:x + mm.shape[1]] += mm
    assert all(p.max(initial=0) <= 1 for p in pages)
    return sum(int(p.sum()) for p in pages)


def test_igea_like_patches_fill_at_least_90_percent():
    masks, angles = _igea_like(3000, seed=0)
    pl = pack(masks, angles)
    used = _check(masks, pl)
    fill = used / sum(e * e for e in pl.pages)
    print(f"fill {fill:.3f}, pages {pl.pages}, per page {np.round(pl.fill, 3).tolist()}")
    assert fill >= 0.90  # the goal of issue 20 (thesis: 0.85-0.95)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 120), st.sampled_from([16, 32, 64, 128]), st.booleans())
def test_packing_never_overlaps_and_stays_inside_the_pages(seed, n, page_size, holes):
    rng = np.random.default_rng(seed)
    top = int(np.log2(page_size)) - 1  # the largest patch must fit the largest page
    levels = rng.integers(0, top + 1, n)
    apex = np.c_[rng.uniform(0.0, 1.0, n), rng.uniform(0.01, 0.9, n)]
    masks, angles = _patches(levels, apex, offset=float(rng.choice([0.5, 1.0])))
    pl = pack(masks, angles, page_size=page_size, best_fit=int(rng.choice([0, 4])), holes=holes, slide=holes)
    assert all(e & (e - 1) == 0 and e <= page_size for e in pl.pages)
    assert _check(masks, pl) == sum(int(m.sum()) for m in masks)
    assert np.allclose(pl.fill, [sum(masks[i].sum() for i in np.flatnonzero(pl.page == k)) / e**2
                                 for k, e in enumerate(pl.pages)])


def test_first_fit_kernel_equals_the_numpy_reference():
    masks, _ = _random_patches(300, seed=5)
    rng = np.random.default_rng(1)
    grid = np.zeros((96, 96), bool)
    for _ in range(40):  # some used blocks
        y, x = rng.integers(0, 90, 2)
        grid[y:y + rng.integers(1, 12), x:x + rng.integers(1, 12)] = True
    items = np.argsort(-np.array([m.size for m in masks]), kind="stable").astype(np.int64)
    ref, got = _empty(len(masks)), _empty(len(masks))
    g_ref = grid.copy()
    rest_ref = first_fit_reference(items.tolist(), masks, g_ref, ref, 0)
    h, w, lft, rgt, off = _profile_arrays(masks)
    remaining = np.ones(len(items), bool)
    g = grid.copy()
    first_fit(items, remaining, 0, 96, h, w, lft, rgt, off, g, got.page, got.x, got.y, got.flip_h, got.flip_v, 0)
    assert sorted(items[remaining].tolist()) == sorted(rest_ref)
    assert 0 < len(rest_ref) < len(items)
    assert np.array_equal(g, g_ref)
    for a in ("x", "y", "flip_h", "flip_v"):
        assert np.array_equal(getattr(got, a), getattr(ref, a)), a


def test_fill_bound_is_above_every_packing_and_exact_for_page_sized_patches():
    masks, angles = _random_patches(300, seed=3)
    pl = pack(masks, angles, page_size=256)
    fill = _check(masks, pl) / sum(e * e for e in pl.pages)
    assert fill <= fill_bound(masks) + 1e-12
    # patches one texel wider than a 64 page need 128 pages (by area, three share one)
    wide = [np.ones((65, 65), bool)] * 3
    assert fill_bound(wide) == pytest.approx(3 * 65 * 65 / (128 * 128))
    assert fill_bound([*wide[:1], np.ones((10, 10), bool)]) == pytest.approx((65 * 65 + 100) / (128 * 128))
    # page-sized patches: one page each, nothing wasted
    assert fill_bound([np.ones((64, 64), bool)] * 5) == 1.0


def test_split_tail_packs_all_patches_into_a_smaller_atlas_or_keeps_the_chain():
    """The tail split (the smallest page as three of half the edge, the larger pages smallest
    first) is taken only when it places every patch, so the atlas never grows; it must place
    them disjointly inside their pages, pages listed largest first."""
    split = 0
    for seed in range(2, 6):  # the split is taken for seeds 3 (random) and 4 (Igea-like)
        for masks, angles in (_igea_like(1000, seed), _random_patches(300, seed)):
            chain = pack(masks, angles, split_tail=False)
            pl = pack(masks, angles)
            assert _check(masks, pl) == sum(int(m.sum()) for m in masks)
            assert sum(e * e for e in pl.pages) <= sum(e * e for e in chain.pages)
            assert np.allclose(pl.fill, [sum(masks[i].sum() for i in np.flatnonzero(pl.page == k)) / e**2
                                         for k, e in enumerate(pl.pages)])
            if sum(e * e for e in pl.pages) < sum(e * e for e in chain.pages):
                split += 1
                assert pl.pages == sorted(pl.pages, reverse=True)
                assert sorted(pl.pages) == sorted([*sorted(chain.pages)[1:], *[min(chain.pages) // 2] * 3])
    print(f"split taken in {split} of 8")
    assert split > 0
