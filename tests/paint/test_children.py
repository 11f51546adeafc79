"""The father -> children lists of a paintable surface (linked lists in row arrays) against the
plain dict of lists they replaced, over random appends, deletes, undo and redo."""

from __future__ import annotations

import numpy as np

from unmesh import SurfelCloud
from unmesh.paint.surface import PaintSurface


class DictChildren:
    """The reference: father -> list of alive children, kept like the surface keeps its lists."""

    def __init__(self, father: np.ndarray, alive: np.ndarray) -> None:
        self.d: dict[int, list[int]] = {}
        for i in np.flatnonzero(alive & (father != np.arange(len(father)))):
            self.d.setdefault(int(father[i]), []).append(int(i))

    def append(self, rows, father):
        for i in rows:
            self.d.setdefault(int(father[i]), []).append(int(i))

    def delete(self, kids, father):
        for k in kids:
            lst = self.d.get(int(father[k]))
            if lst is not None and k in lst:
                lst.remove(k)
                if not lst:
                    del self.d[int(father[k])]

    def rows_of(self, s, fathers):
        rows = [fathers] + [np.asarray(self.d[f], np.int64) for f in fathers.tolist() if f in self.d]
        rows = np.unique(np.concatenate(rows))
        return rows[s.active[rows] & s.alive[rows]]


def _check(s: PaintSurface, ref: DictChildren) -> None:
    assert dict(s.children) == ref.d
    assert len(s.children) == len(ref.d) and bool(s.children) == bool(ref.d)
    for f in range(s.n_original):
        assert (f in s.children) == (f in ref.d)
    fathers = np.arange(0, s.n_original, 3)
    np.testing.assert_array_equal(s.rows_of(fathers), ref.rows_of(s, fathers))


def test_children_lists_equal_the_dict_reference():
    rng = np.random.default_rng(11)
    n0 = 40
    pts = np.c_[rng.random((n0, 2)), np.zeros(n0)]
    s = PaintSurface(SurfelCloud(pts, np.tile([0, 0, 1.0], (n0, 1)), radii=np.full(n0, 0.1)))
    ref = DictChildren(s.father, s.alive)
    cap0 = s.capacity
    s.begin_record()
    for _ in range(30):
        m = int(rng.integers(1, 25))
        fa = rng.integers(0, n0, m)
        new = {"pos": np.c_[rng.random((m, 2)), np.zeros(m)], "nrm": np.tile([0, 0, 1.0], (m, 1)),
               "rad": np.full(m, 0.05), "father": fa, "active": np.ones(m, bool), "alive": np.ones(m, bool)}
        rows = s.append(new)  # grows the row capacity past the initial RESERVE n0
        ref.append(rows, s.father)
        _check(s, ref)
        vis = s.visible_rows()
        gone = rng.choice(vis, size=min(len(vis), int(rng.integers(1, 15))), replace=False)
        gone = np.concatenate([gone, gone[:2]])  # repeated and original rows are allowed
        s.delete(gone)
        ref.delete(gone[gone >= n0].tolist(), s.father)
        _check(s, ref)
    assert s.capacity > cap0  # the appends grew the capacity on the way
    rec = s.end_record()
    red = s.revert(rec)
    _check(s, DictChildren(s.father, s.alive))
    assert not s.children
    s.reapply(red)
    _check(s, ref)
