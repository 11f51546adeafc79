"""CSG trees: operators, the rewrite of difference/complement (4.3), flattening, patches."""

import numpy as np
import pytest

from unmesh import SurfelCloud
from unmesh.csg import Complement, Intersection, Patch, Union, flatten, normalize
from unmesh.csg.model import INTERSECTION, LEAF, UNION, patches
from unmesh.errors import InputError


def _p(name):
    return Patch(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]), name=name)


A, B, C, D = _p("A"), _p("B"), _p("C"), _p("D")


def test_operators_build_nodes():
    assert isinstance(A | B, Union) and isinstance(A & B, Intersection)
    assert isinstance(~A, Complement)
    d = A - B
    assert isinstance(d, Intersection) and isinstance(d.right, Complement) and d.right.child is B
    assert str(A - (B | C)) == "(A & ~(B | C))"


def test_normalize_pushes_inversions_to_leaves_thesis_example():
    # 4.3: A \ (B u C) = A n ~(B u C) = A n (~B n ~C)
    assert str(normalize(A - (B | C))) == "(A & (~B & ~C))"
    assert str(normalize(~~A)) == "A"
    assert str(normalize(~(A & (B | ~C)))) == "(~A | (~B & C))"


def _truth(tree, env):
    if isinstance(tree, Patch):
        return env[tree.name]
    if isinstance(tree, Complement):
        return not _truth(tree.child, env)
    a, b = _truth(tree.left, env), _truth(tree.right, env)
    return (a or b) if isinstance(tree, Union) else (a and b)


def test_normalize_preserves_set_semantics_on_all_assignments():
    trees = [A - (B | C), ~(A & B) | (C - ~D), ~((A | ~B) & ~(C - D)), (A - B) - (C - D)]
    for t in trees:
        n = normalize(t)
        for bits in range(16):
            env = {k: bool(bits >> i & 1) for i, k in enumerate("ABCD")}
            assert _truth(n, env) == _truth(t, env)


def test_flatten_post_order_and_subtree_ranges():
    f = flatten((A - B) | C)
    # post order: A, ~B, &, C, |
    assert f.op.tolist() == [LEAF, LEAF, INTERSECTION, LEAF, UNION]
    assert f.invert.tolist() == [0, 1, 0, 0, 0]
    assert f.parent.tolist() == [2, 2, 4, 4, -1]
    assert f.first.tolist() == [0, 1, 0, 3, 0]
    assert [p.name for p in f.leaves] == ["A", "B", "C"]
    assert f.table().shape == (5, 4) and f.table().dtype == np.int32


def test_patches_distinct_in_order():
    assert [p.name for p in patches((A | B) & (A - C))] == ["A", "B", "C"]


def test_halfspace_square_covers_its_extent():
    p = Patch.halfspace((1, 2, 3), (0, 0, 2), extent=2.0, spacing=0.5)
    c = p.cloud
    assert len(c) == 16
    assert np.allclose(c.normals, [0, 0, 1]) and np.allclose(c.positions[:, 2], 3)
    # every point of the square is within a radius of some centre (no holes)
    g = np.stack(np.meshgrid(np.linspace(0, 2, 41), np.linspace(1, 3, 41)), -1).reshape(-1, 2)
    d = np.linalg.norm(g[:, None, :] - c.positions[None, :, :2], axis=2).min(axis=1)
    assert d.max() < c.radii[0]
    one = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=1.0, spacing=5.0)
    assert len(one.cloud) == 1 and one.cloud.radii[0] >= np.sqrt(0.5)


def test_moved_composes_transforms():
    m = np.eye(4)
    m[:3, 3] = (1, 0, 0)
    p = A.moved(m).moved(m)
    assert np.allclose(p.world_cloud().positions, [[2, 0, 0]])
    assert np.allclose(A.world_cloud().positions, [[0, 0, 0]])


def test_bad_input():
    with pytest.raises(InputError, match="non-empty"):
        Patch(SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0)), name="e")
    with pytest.raises(InputError, match="right operand of \\|"):
        A | 3
    with pytest.raises(InputError, match="normal"):
        Patch.halfspace((0, 0, 0), (0, 0, 0), 1.0, 0.1)
    with pytest.raises(InputError, match="discontinuity"):
        Patch(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0], attributes={"discontinuity": [1]}))
