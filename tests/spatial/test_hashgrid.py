"""Dynamic HashGrid against brute force after arbitrary update sequences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.spatial import HashGrid
from unmesh.spatial import _hash_kernels as H

from .reference import brute_radius


class Model:
    """Plain-Python model of the grid contents: id -> position."""

    def __init__(self, dim):
        self.pos = {}
        self.dim = dim

    def query(self, q, r):
        ids = np.array(sorted(self.pos), np.int64)
        pts = np.array([self.pos[i] for i in ids], float).reshape(-1, self.dim)
        off, ind = brute_radius(pts, r, q)
        return off, ids[ind] if len(ids) else ind


def assert_query(grid, model, q, r):
    off, ind = grid.query_radius(q, r)
    want = model.query(q, r)
    np.testing.assert_array_equal(off, want[0])
    np.testing.assert_array_equal(ind, want[1])


def ref_hash_index(i, j, k, s):
    """Eq. 3.17 in Python integers with int64 wrap-around."""
    def wrap(v):
        return (v + 2**63) % 2**64 - 2**63
    h = wrap(i * H.P1) ^ wrap(j * H.P2) ^ wrap(k * H.P3)
    return h % s


def test_hash_index_and_cell_reference():
    for i, j, k in [(0, 0, 0), (-1, 5, 7), (10**6, -(10**6), 3), (2**40, 2**41, -(2**42)), (H.CLAMP, -H.CLAMP, 1)]:
        assert H.hash_index(i, j, k, 1009) == ref_hash_index(i, j, k, 1009)
    rng = np.random.default_rng(0)
    p = rng.normal(size=(100, 3)) * 10
    for x in p:
        assert H.hash_cell_of(x, 1 / 0.7) == tuple(np.floor(x / 0.7).astype(int))
    assert H.hash_cell_of(np.array([1e300, -1e300]), 1.0) == (H.CLAMP, -H.CLAMP, 0)


@pytest.mark.parametrize("dim", [2, 3])
def test_matches_brute_force_after_updates(rng, dim):
    g = HashGrid(0.1, dim=dim)
    m = Model(dim)
    ids = rng.permutation(3000)[:2000]
    pts = rng.random((2000, dim))
    g.insert(ids, pts)
    m.pos.update(zip(ids.tolist(), pts, strict=True))
    q = rng.random((300, dim)) * 1.2 - 0.1
    for r in (0.03, 0.05, 0.1, 0.25, 3.0):
        assert_query(g, m, q, r)
    mv = ids[:700]
    newp = pts[:700] + rng.normal(scale=0.2, size=(700, dim))
    g.move(mv, newp)
    m.pos.update(zip(mv.tolist(), newp, strict=True))
    g.remove(ids[500:1200])
    for i in ids[500:1200].tolist():
        del m.pos[i]
    assert len(g) == len(m.pos)
    np.testing.assert_array_equal(g.ids, sorted(m.pos))
    assert_query(g, m, q, 0.1)
    np.testing.assert_array_equal(g.positions(ids[:5]), [m.pos[i] for i in ids[:5].tolist()])
    g.insert(ids[500:600], pts[500:600] + 5.0)
    m.pos.update(zip(ids[500:600].tolist(), pts[500:600] + 5.0, strict=True))
    assert_query(g, m, np.concatenate([q, q + 5.0]), 0.1)


def test_table_grows_and_cleans(rng):
    g = HashGrid(0.01)
    m = Model(3)
    for step in range(20):
        ids = np.arange(step * 200, step * 200 + 200)
        p = rng.random((200, 3)) * (1 + step)
        g.insert(ids, p)
        m.pos.update(zip(ids.tolist(), p, strict=True))
        if step % 3 == 0:
            g.remove(ids[::2])
            for i in ids[::2].tolist():
                del m.pos[i]
    assert g.n_cells > 0 and "HashGrid" in repr(g)
    assert_query(g, m, rng.random((200, 3)) * 10, 0.02)
    g.clear()
    assert len(g) == 0 and g.query_radius([[0, 0, 0]], 1.0)[0].tolist() == [0, 0]


def test_duplicates_huge_coordinates_and_empty():
    g = HashGrid(1.0)
    off, ind = g.query_radius(np.zeros((2, 3)), 1.0)
    assert off.tolist() == [0, 0, 0] and ind.size == 0
    g.insert([0, 1, 2, 3], [[0, 0, 0], [0, 0, 0], [1e200, 0, 0], [-1e200, 1e200, 0]])
    assert g.query_radius([[0, 0, 0]], 0.5)[1].tolist() == [0, 1]
    assert g.query_radius([[1e200, 0, 0]], 0.5)[1].tolist() == [2]
    assert g.query_radius([[1e200, 0, 0]], 1.0)[1].tolist() == [2]
    assert g.query_radius([[-1e200, 1e200, 0]], 0.3)[1].tolist() == [3]
    assert g.query_radius(np.empty((0, 3)), 0.5)[0].tolist() == [0]
    assert 2 in g and 7 not in g and "x" not in g


def test_errors():
    g = HashGrid(1.0)
    g.insert([0, 1], [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(InputError, match="already"):
        g.insert([1], [[0, 0, 0]])
    with pytest.raises(InputError, match="not in the grid"):
        g.remove([5])
    with pytest.raises(InputError, match="not in the grid"):
        g.move([0, 9], [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(InputError, match="unique"):
        g.insert([3, 3], [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(InputError, match="ids"):
        g.insert([-1], [[0, 0, 0]])
    with pytest.raises(InputError, match="points"):
        g.insert([4, 5], [[0, 0, 0]])
    with pytest.raises(InputError, match="points"):
        g.insert([4], [[0, 0]])
    with pytest.raises(InputError, match="radius"):
        g.query_radius([[0, 0, 0]], -1)
    with pytest.raises(InputError, match="cell_size"):
        HashGrid(0.0)
    with pytest.raises(InputError, match="dim"):
        HashGrid(1.0, dim=4)


coord = st.integers(-8, 8).map(lambda v: v * 0.125)


@settings(max_examples=50, deadline=None)
@given(
    dim=st.sampled_from([2, 3]),
    cell=st.sampled_from([0.125, 0.25, 0.5]),
    ops=st.lists(
        st.tuples(st.sampled_from(["insert", "remove", "move", "query"]), st.lists(st.integers(0, 25), max_size=8, unique=True)),
        max_size=25,
    ),
    data=st.data(),
)
def test_hypothesis_update_sequences(dim, cell, ops, data):
    g = HashGrid(cell, dim=dim)
    m = Model(dim)
    point = st.tuples(*[coord] * dim)
    for op, ids in ops:
        if op == "insert":
            ids = [i for i in ids if i not in m.pos]
            p = np.array(data.draw(st.lists(point, min_size=len(ids), max_size=len(ids))), float).reshape(-1, dim)
            g.insert(ids, p)
            m.pos.update(zip(ids, p, strict=True))
        elif op == "remove":
            ids = [i for i in ids if i in m.pos]
            g.remove(ids)
            for i in ids:
                del m.pos[i]
        elif op == "move":
            ids = [i for i in ids if i in m.pos]
            p = np.array(data.draw(st.lists(point, min_size=len(ids), max_size=len(ids))), float).reshape(-1, dim)
            g.move(ids, p)
            m.pos.update(zip(ids, p, strict=True))
        else:
            q = np.array(data.draw(st.lists(point, min_size=1, max_size=4)), float)
            r = data.draw(st.sampled_from([0.0625, 0.125, 0.25, 0.4, 1.0]))
            assert_query(g, m, q, r)
    assert len(g) == len(m.pos)
    q = np.array(data.draw(st.lists(point, min_size=1, max_size=4)), float)
    for r in (cell, cell / 2, cell / 3, 2 * cell):
        assert_query(g, m, q, r)


def test_query_cells_vs_numpy(rng):
    q = rng.normal(size=(200, 3)) * 5
    inv = 1 / 0.3
    np.testing.assert_array_equal(H.query_cells(q, inv, False), np.floor(q * inv).astype(np.int64))
    half = H.query_cells(q, inv, True)
    np.testing.assert_array_equal(half, np.floor(2 * (q * inv)).astype(np.int64))
    np.testing.assert_array_equal(half >> 1, np.floor(q * inv).astype(np.int64))
    q2 = q[:, :2].copy()
    want = np.concatenate([np.floor(q2 * inv), np.zeros((200, 1))], 1).astype(np.int64)
    np.testing.assert_array_equal(H.query_cells(q2, inv, False), want)


def test_query_box_reference():
    # 27-cell box around a cell; 8-cell box towards the query's half of the cell
    lo, hi = H._query_box(np.array([4, -3, 7]), 1, False, 3)
    assert lo.tolist() == [3, -4, 6] and hi.tolist() == [5, -2, 8]
    lo, hi = H._query_box(np.array([8, 9, -3]), 1, True, 3)  # half-cells: even -> lower side
    assert lo.tolist() == [3, 4, -2] and hi.tolist() == [4, 5, -1]
    lo, hi = H._query_box(np.array([8, 9, 0]), 1, True, 2)
    assert lo.tolist() == [3, 4, 0] and hi.tolist() == [4, 5, 0]
    lo, hi = H._query_box(np.array([2**40, 0, 0]), 1, False, 3)  # far from the origin: one more ring
    assert lo.tolist() == [2**40 - 2, -2, -2]
