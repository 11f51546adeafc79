"""Static cell grid and its numba kernels against numpy references."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import unmesh.spatial
from unmesh.errors import InputError
from unmesh.spatial import _kernels as K
from unmesh.spatial import _pair_kernels as PK
from unmesh.spatial import build_cell_grid, cellgrid, hashgrid, kdtree, neighbors

from .reference import brute_radius, ref_cells, ref_compress, ref_knn_finish, ref_stencil_points, sq_dist_matrix


@pytest.mark.parametrize("dim", [2, 3])
def test_grid_layout(rng, dim):
    x = rng.random((3000, dim)) * [3.0, 1.0, 2.0][:dim]
    g = build_cell_grid(x, 0.2)
    assert g.dim == dim and g.n_points == 3000
    np.testing.assert_array_equal(g.points, x[g.order])
    np.testing.assert_array_equal(g.rank[g.order], np.arange(3000))
    _, keys = ref_cells(x, g.origin, g.inv_cell, g.dims)
    np.testing.assert_array_equal(K.compute_keys(x, g.origin, g.inv_cell, g.dims), keys)
    np.testing.assert_array_equal(g.order, np.argsort(keys, kind="stable"))
    ck, cs = ref_compress(keys[g.order])
    np.testing.assert_array_equal(g.cell_keys, ck)
    np.testing.assert_array_equal(g.cell_start, cs)
    # cell edge is the requested size (plus the round-off margin), cells hold their points
    assert g.cell_size == pytest.approx(0.2, rel=2e-6) and g.reach(0.2) == 1 and g.reach(0.3) == 2
    lo = np.floor((g.points - g.origin) * g.inv_cell)
    assert np.all(lo >= 0)
    if dim == 2:
        assert g.dims[0] == 1
    assert "CellGrid" in repr(g)


def test_counting_sort_and_argsort_paths(rng):
    # dense grid (counting sort) and sparse grid (argsort) give the same layout rules
    for x in (rng.random((500, 3)), np.concatenate([rng.random((500, 3)), [[1e4, 1e4, 1e4]]])):
        g = build_cell_grid(x, 0.05)
        _, keys = ref_cells(x, g.origin, g.inv_cell, g.dims)
        np.testing.assert_array_equal(g.order, np.argsort(keys, kind="stable"))
    keys = rng.integers(0, 50, 1000)
    np.testing.assert_array_equal(K.counting_sort(keys, 50), np.argsort(keys, kind="stable"))


def test_point_cell_clamps(rng):
    g = build_cell_grid(rng.random((100, 3)), 0.25)
    for p in ([-5.0, 0.5, 0.5], [0.5, 1e300, -1e300], [0.1, 0.2, 0.3]):
        p = np.array(p)
        ijk, key = ref_cells(p[None], g.origin, g.inv_cell, g.dims)
        got = K.point_cell(p, g.origin, g.inv_cell, g.dims)
        assert tuple(got) == tuple(ijk[0])
        assert K.cell_key(*got, g.dims) == key[0]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("reach", [1, 2])
def test_stencil_ranges_vs_reference(rng, dim, reach):
    x = np.concatenate([rng.random((400, dim)), rng.random((50, dim)) * 0.1])
    g = build_cell_grid(x, 0.15)
    out = np.empty(((2 * reach + 1) ** 2, 2), np.int64)
    for p in np.concatenate([x[:60], rng.random((30, dim)) * 2 - 0.5]):
        i, j, k = K.point_cell(p, g.origin, g.inv_cell, g.dims)
        n = K.stencil_ranges(i, j, k, reach, g.dims, g.cell_keys, g.cell_start, out)
        got = np.sort(np.concatenate([np.arange(a, b) for a, b in out[:n]]))
        np.testing.assert_array_equal(got, ref_stencil_points(i, j, k, reach, g.dims, g.cell_keys, g.cell_start))
        c = K.find_cell(K.cell_key(i, j, k, g.dims), g.cell_keys)
        s, e = K.cell_range(c, g.cell_start)
        if c >= 0:
            assert g.cell_keys[c] == K.cell_key(i, j, k, g.dims) and e > s
        else:
            assert s == e == 0


def test_sample_efficiency_vs_reference(rng):
    x = rng.random((2000, 3))
    g = build_cell_grid(x, 0.1)
    s = rng.random((40, 3))
    cand, hits = K.sample_efficiency(g.points, g.cell_keys, g.cell_start, g.origin, g.inv_cell, g.dims, 1, s, 0.1)
    out = np.empty((9, 2), np.int64)
    want_c = 0
    for p in s:
        i, j, k = K.point_cell(p, g.origin, g.inv_cell, g.dims)
        want_c += ref_stencil_points(i, j, k, 1, g.dims, g.cell_keys, g.cell_start).size
    assert K.stencil_ranges(0, 0, 0, 1, g.dims, g.cell_keys, g.cell_start, out) <= 9
    assert cand == want_c
    assert hits == int((sq_dist_matrix(x, s) <= 0.01).sum())


def test_knn_finish_and_gather_vs_reference(rng):
    x = np.round(rng.random((300, 3)) * 4) / 4  # many ties
    q = np.round(rng.random((50, 3)) * 4) / 4
    idx = rng.integers(0, 300, (50, 8))
    dist = np.empty((50, 8))
    want_d, want_i = ref_knn_finish(x, q, idx)
    K.knn_finish(x, q, idx, dist)
    np.testing.assert_array_equal(idx, want_i)
    np.testing.assert_array_equal(dist, want_d)
    np.testing.assert_array_equal(K.gather_rows(x, np.ascontiguousarray(idx[:, 0])), x[idx[:, 0]])


def test_pairs_within_vs_reference(rng):
    for dim in (2, 3):
        x = np.round(rng.random((300, dim)) * 4) / 4  # many distances exactly equal to the radius
        q = np.round(rng.random((50, dim)) * 4) / 4
        i = rng.integers(0, 300, 2000)
        j = rng.integers(0, 50, 2000)
        keep = np.empty(2000, np.bool_)
        K.pairs_within(x, i, q, j, 0.25, keep)
        np.testing.assert_array_equal(keep, kdtree._sq_dist(x, i, q, j) <= 0.25)
        assert 0 < keep.sum() < 2000 and (kdtree._sq_dist(x, i, q, j) == 0.25).any()


def test_empty_grid_and_errors():
    g = build_cell_grid(np.empty((0, 3)), 1.0)
    assert g.n_points == 0 and g.n_cells == 0 and g.cell_start.tolist() == [0]
    with pytest.raises(InputError, match="cell_size"):
        build_cell_grid(np.zeros((2, 3)), 0.0)
    with pytest.raises(InputError, match="points"):
        build_cell_grid(np.zeros((2, 4)), 1.0)
    with pytest.raises(InputError, match="overflows"):
        build_cell_grid([[-1e308, 0, 0], [1e308, 0, 0]], 1.0)


def test_huge_extent_enlarges_cells():
    x = np.array([[0.0, 0, 0], [1e12, 0, 0], [1e12 + 1e-3, 0, 0]])
    g = build_cell_grid(x, 1e-6)
    assert g.dims.max() <= cellgrid.MAX_CELLS_PER_AXIS
    assert g.cell_size > 1e-6


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 60),
    dim=st.sampled_from([2, 3]),
    h=st.sampled_from([0.1, 0.25, 0.5, 2.0]),
    data=st.data(),
)
def test_hypothesis_stencil_covers_radius(n, dim, h, data):
    pts = data.draw(st.lists(st.tuples(*[st.integers(-8, 8).map(lambda v: v / 8)] * dim), min_size=n, max_size=n))
    x = np.array(pts, float)
    g = build_cell_grid(x, h)
    out = np.empty((9, 2), np.int64)
    d2 = sq_dist_matrix(g.points, g.points)
    for a in range(n):
        i, j, k = K.point_cell(g.points[a], g.origin, g.inv_cell, g.dims)
        m = K.stencil_ranges(i, j, k, 1, g.dims, g.cell_keys, g.cell_start, out)
        found = np.zeros(n, bool)
        for s, e in out[:m]:
            found[s:e] = True
        assert np.all(found[d2[a] <= h * h])


@pytest.mark.parametrize("module", [unmesh.spatial, cellgrid, hashgrid, kdtree, neighbors])
def test_docstring_examples(module):
    result = doctest.testmod(module, extraglobs={"np": np}, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0 and result.attempted > 0


def _ref_pairs(x, r):
    want = sq_dist_matrix(x, x) <= r * r
    np.fill_diagonal(want, False)
    wi, wj = np.nonzero(np.triu(want))
    return want, np.stack([wi, wj], 1)


def _sorted_pairs(plo, phi):
    got = np.stack([plo, phi], 1).astype(np.int64)
    return got[np.lexsort((got[:, 1], got[:, 0]))]


@pytest.mark.parametrize("dim", [2, 3])
def test_half_stencil_pair_kernels_vs_reference(rng, dim):
    x = np.concatenate([rng.random((700, dim)), rng.random((100, dim)) * 0.05])
    r = 0.08
    g = build_cell_grid(x, r)
    base = (g.points, g.cell_keys, g.cell_start, g.dims, 1, r)
    cells = np.arange(g.n_cells)
    counts = PK.half_count(*base, cells)
    assert counts.shape == (g.n_cells,)
    coff = np.concatenate([[0], np.cumsum(counts)])
    plo = np.empty(coff[-1], np.int32)
    phi = np.empty(coff[-1], np.int32)
    PK.half_fill(g.points, g.order, *base[1:], cells, coff, plo, phi)
    # every pair once, as original indices lo < hi
    want, pairs = _ref_pairs(x, r)
    assert np.all(plo < phi)
    np.testing.assert_array_equal(_sorted_pairs(plo, phi), pairs)
    # the pairs of cell c are those whose lower sorted position lies in c
    cell_of = np.repeat(np.arange(g.n_cells), np.diff(g.cell_start))
    per_cell = np.zeros(g.n_cells, np.int64)
    np.add.at(per_cell, cell_of[np.minimum(g.rank[pairs[:, 0]], g.rank[pairs[:, 1]])], 1)
    np.testing.assert_array_equal(counts, per_cell)
    # a subset of cells
    sub = np.ascontiguousarray(cells[::3])  # the C layout of every caller: no test-only compile
    np.testing.assert_array_equal(PK.half_count(*base, sub), per_cell[sub])
    # rows from segments: counting sort + row sort give the brute-force CSR
    n = len(x)
    seg_start = np.array([0, coff[-1] // 2])
    seg_len = np.array([coff[-1] // 2, coff[-1] - coff[-1] // 2])
    for both in (False, True):
        for nparts in (1, 3):
            rc = PK.pair_row_counts(plo, phi, seg_start, seg_len, n, both, nparts)
            assert rc.shape == (nparts, n)
            rows = np.concatenate([plo, phi]) if both else plo.astype(np.int64)
            np.testing.assert_array_equal(rc.sum(0), np.bincount(rows, minlength=n))
            off, cursors = PK.row_cursors(rc, both)
            np.testing.assert_array_equal(np.diff(off), rc.sum(0) + both)
            want_cur = off[:-1] + both + np.concatenate([np.zeros((1, n), int), np.cumsum(rc, 0)[:-1]])
            np.testing.assert_array_equal(cursors, want_cur)
            cols = np.empty(off[-1], np.int32)
            if both:
                PK.write_self_loops(off, cols)
            PK.pair_row_scatter(plo, phi, seg_start, seg_len, cursors, both, cols)
            np.testing.assert_array_equal(cursors, off[1:][None, :] - np.cumsum(rc[::-1], 0)[::-1] + rc)
            sorted_cols = np.empty(off[-1], np.int64)
            PK.sort_rows(off, cols, sorted_cols)
            full = want | np.eye(n, dtype=bool) if both else np.triu(want)
            np.testing.assert_array_equal(sorted_cols, np.nonzero(full)[1])
            if not both:
                out = np.empty((off[-1], 2), np.int64)
                PK.sort_pair_rows(off, cols, out)
                np.testing.assert_array_equal(out, pairs)


@pytest.mark.parametrize("capacity", [0, 5, 40, 10**6])
def test_half_fill_chunks_vs_reference(rng, capacity):
    x = np.concatenate([rng.random((600, 3)), rng.random((200, 3)) * 0.03])
    r = 0.09
    g = build_cell_grid(x, r)
    chunk_cells = np.array([0, g.n_cells // 3, g.n_cells // 2, g.n_cells])
    chunk_base = np.arange(4) * capacity
    plo = np.zeros(chunk_base[-1], np.int32)
    phi = np.zeros(chunk_base[-1], np.int32)
    lengths, stops = PK.half_fill_chunks(g.points, g.order, g.cell_keys, g.cell_start, g.dims, 1, r, chunk_cells,
                                        chunk_base, plo, phi)
    per_cell = PK.half_count(g.points, g.cell_keys, g.cell_start, g.dims, 1, r, np.arange(g.n_cells))
    _, pairs = _ref_pairs(x, r)
    for t in range(3):
        # complete cells only, as many as fit
        done = per_cell[chunk_cells[t] : stops[t]].sum()
        assert lengths[t] == done <= capacity
        if stops[t] < chunk_cells[t + 1]:
            assert done + per_cell[stops[t]] > capacity
    got = np.concatenate([np.arange(b, b + ln) for b, ln in zip(chunk_base[:-1], lengths, strict=True)]).astype(int)
    sel = _sorted_pairs(plo[got], phi[got])
    # every written pair is a true pair, without repeats
    assert len(np.unique(sel, axis=0)) == len(sel)
    assert set(map(tuple, sel.tolist())) <= set(map(tuple, pairs.tolist()))


@pytest.mark.parametrize("slack", [0.0, 0.3, 1.25])
def test_self_pairs_estimate_fallback(rng, monkeypatch, slack):
    # clustered data makes the per-chunk estimate wrong; the exact fallback must fix it
    x = np.concatenate([rng.random((1500, 3)), rng.random((1500, 3)) * 0.02 + 0.5])
    r = 0.05
    monkeypatch.setattr(neighbors, "_CAPACITY_SLACK", slack)
    _, pairs = _ref_pairs(x, r)
    np.testing.assert_array_equal(neighbors.radius_pairs(x, r, method="grid"), pairs)
    off, ind = neighbors.radius_neighbors(x, r, method="grid")
    want_off, want_ind = brute_radius(x, r)
    np.testing.assert_array_equal(off, want_off)
    np.testing.assert_array_equal(ind, want_ind)


def test_sort_rows_vs_numpy(rng):
    off = np.concatenate([[0], np.cumsum(rng.integers(0, 120, 300))])
    cols = np.concatenate([rng.permutation(1000)[: off[i + 1] - off[i]] for i in range(300)]).astype(np.int32)
    want = np.concatenate([np.sort(cols[off[i] : off[i + 1]]) for i in range(300)])
    got = np.empty(len(cols), np.int64)
    PK.sort_rows(off, cols, got)
    np.testing.assert_array_equal(got, want)
    pairs = np.empty((len(cols), 2), np.int64)
    PK.sort_pair_rows(off, cols, pairs)
    np.testing.assert_array_equal(pairs[:, 1], want)
    np.testing.assert_array_equal(pairs[:, 0], np.repeat(np.arange(300), np.diff(off)))


@pytest.mark.parametrize("pairs_only", [False, True])
def test_cross_query_kernels_vs_reference(rng, pairs_only):
    x = rng.random((600, 3))
    q = np.concatenate([rng.random((200, 3)) * 1.5 - 0.25, x[:50]])
    r = 0.1
    g = build_cell_grid(x, r)
    qkeys = K.compute_keys(q, g.origin, g.inv_cell, g.dims)
    qorder = np.argsort(qkeys, kind="stable")
    gk, gs = K.compress_cells(qkeys[qorder])
    sq = K.gather_rows(q, qorder)
    args = (g.points, g.order, g.cell_keys, g.cell_start, g.dims, 1, sq, qorder, gk, gs, True, g.origin, g.upper,
            r, pairs_only)
    counts = K.radius_count(*args)
    hit = sq_dist_matrix(x, q) <= r * r
    if pairs_only:
        hit &= np.arange(600)[None, :] > np.arange(len(q))[:, None]
    np.testing.assert_array_equal(counts, hit.sum(1))
    off = np.concatenate([[0], np.cumsum(counts)])
    ind = np.empty(off[-1], np.int64)
    K.radius_fill(*args, off, ind)
    np.testing.assert_array_equal(ind, np.nonzero(hit)[1])


@pytest.mark.parametrize("dim", [2, 3])
def test_stencil_table_and_cell_of(rng, dim):
    x = rng.random((500, dim))
    g = build_cell_grid(x, 0.12)
    cell_of = np.repeat(np.arange(g.n_cells), np.diff(g.cell_start))
    np.testing.assert_array_equal(g.cell_of, cell_of)
    for radius, reach in ((None, 1), (0.2, 2)):
        table = g.stencil_table(radius)
        assert table.shape == (g.n_cells, (2 * reach + 1) ** 2, 2)
        for c in range(0, g.n_cells, 7):
            i, j, k = K.point_cell(g.points[g.cell_start[c]], g.origin, g.inv_cell, g.dims)
            got = np.sort(np.concatenate([np.arange(a, b) for a, b in table[c]]))
            np.testing.assert_array_equal(got, ref_stencil_points(i, j, k, reach, g.dims, g.cell_keys, g.cell_start))


@pytest.mark.parametrize("n", [1, 5, 63, 64, 65, 100, 1000, 4097])
def test_bounds_vs_numpy(rng, n):
    x = rng.normal(size=(n, 3)) + 100.0  # positive: stale memory would not pass unnoticed
    lo, hi = K.bounds(x)
    np.testing.assert_array_equal(lo, x.min(0))
    np.testing.assert_array_equal(hi, x.max(0))
