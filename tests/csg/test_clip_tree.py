"""Per-fragment clipping (Algorithm 4.2 with 4.3/4.4 and 4.9/4.10) and Appendix A's invariant."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import SurfelCloud
from unmesh.csg import Patch, flatten
from unmesh.csg.classify import on_surface_reference, same_plane_reference
from unmesh.csg.model import INTERSECTION, LEAF
from unmesh.render._splat_kernels import COPLANAR_EPS, keep_tree


def _tree(draw, nleaves):
    """A random CSG tree over patches 0..nleaves-1 with random complements."""
    leaves = [Patch(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]), name=f"P{i}") for i in range(nleaves)]
    nodes = [~p if draw(st.booleans()) else p for p in leaves]
    while len(nodes) > 1:
        i = draw(st.integers(0, len(nodes) - 2))
        a, b = nodes[i], nodes[i + 1]
        op = draw(st.sampled_from(["|", "&", "-"]))
        node = a | b if op == "|" else a & b if op == "&" else a - b
        nodes[i:i + 2] = [~node if draw(st.booleans()) else node]
    return nodes[0]


@st.composite
def fragments(draw, most=3, sheet=False, planes=False):
    nleaves = draw(st.integers(1, 6))
    flat = flatten(_tree(draw, nleaves))
    table = flat.table()
    L = len(flat.leaves)
    s_leaf = draw(st.integers(0, L - 1))
    rows = []
    for j in range(L):
        if j == s_leaf:
            continue
        base_n = np.array(draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3))) if sheet else None
        for _ in range(draw(st.integers(0, most))):
            c = draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3))
            n = draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3))
            if sheet:  # samples of one smooth patch: nearly parallel normals
                n = base_n + 0.05 * np.array(n)
            if np.linalg.norm(n) < 1e-3:
                n = [0, 0, 1.0]
            if planes and rows and rows[-1][6] == flat.leaf_node[j] and draw(st.booleans()):
                # on the plane of the previous partner of this leaf (a line of border surfels)
                prev = np.array(rows[-1][:6])
                t = np.array(c) - np.dot(np.array(c) - prev[:3], prev[3:]) * prev[3:]
                c, n = list(t), prev[3:]
            rows.append([*c, *(np.array(n) / np.linalg.norm(n)), flat.leaf_node[j]])
    partners = np.array(rows, dtype=np.float64).reshape(-1, 7)
    x = np.array(draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3)))
    offsets = np.array([0, len(partners)], dtype=np.int64)
    leaf = np.array([flat.leaf_node[s_leaf]], dtype=np.int32)
    return x, offsets, partners, table, leaf, flat


@settings(max_examples=150, deadline=None)
@given(fragments())
def test_kernel_matches_reference(case):
    x, offsets, partners, table, leaf, _ = case
    work = np.empty((len(table), 5))
    ref = on_surface_reference(x, 0, offsets, partners, table, leaf)
    assert keep_tree(0, x[0], x[1], x[2], offsets, partners, table, leaf, work) == ref


def _inside_values(flat, x, partners, own):
    """insideTree (three-valued) of every node for the fragment of leaf ``own``, from the
    partners (a fragment on a partner's plane is inside the lower leaf's patch, 4.5)."""
    table = flat.table()
    vals = {}
    for k in range(len(table)):
        if table[k, 0] == LEAF:
            mine = partners[partners[:, 6] == k]
            if len(mine) == 0:
                vals[k] = None
                continue
            d = ((mine[:, :3] - x) ** 2).sum(1)
            o = np.argsort(d, kind="stable")

            def clips(r, p):
                return float(np.dot(p - r[:3], r[3:6])) >= 0

            def clips_x(r):
                d = float(np.dot(x - r[:3], r[3:6]))
                if abs(d) <= COPLANAR_EPS * (1 + np.abs(x).sum()):
                    return own > r[6]
                return d >= 0

            a = mine[o[0]]
            c1 = clips_x(a)
            off = [r for r in mine[o[1:]] if not same_plane_reference(a, r)]  # s2 off s1's plane
            if not off:
                v = not c1
            else:
                b = off[0]
                c2 = clips_x(b)
                v = (not c1 or not c2) if (clips(a, b[:3]) and clips(b, a[:3])) else (not c1 and not c2)
            vals[k] = v != bool(table[k, 3])
        else:
            right = k - 1
            left = table[right, 2] - 1
            a, b = vals[left], vals[right]
            if a is None:
                vals[k] = b
            elif b is None:
                vals[k] = a
            else:
                vals[k] = (a and b) if table[k, 0] == INTERSECTION else (a or b)
    return vals


@settings(max_examples=150, deadline=None)
@given(fragments())
def test_appendix_a_invariant(case):
    """Algorithm A.1 (no early exit) keeps (A.3): on <=> x on the surface of the current node,
    where surface membership follows (A.1)/(A.2) and an unknown sibling leaves it unchanged;
    Algorithm 4.2 (early exit, the kernel) returns the same as A.1."""
    x, offsets, partners, table, leaf, flat = case
    vals = _inside_values(flat, x, partners, int(leaf[0]))

    def on_surface(k, start):
        """x in S_k, for x on the leaf ``start`` (and on no other leaf)."""
        if table[k, 0] == LEAF:
            return k == start
        right = k - 1
        left = table[right, 2] - 1
        sa, sb = on_surface(left, start), on_surface(right, start)
        ia, ib = vals[left], vals[right]
        out = False
        for s_self, i_other in ((sa, ib), (sb, ia)):
            if not s_self:
                continue
            if i_other is None:
                out = True
            elif table[k, 0] == INTERSECTION:
                out = out or i_other
            else:
                out = out or not i_other
        return out

    node = int(leaf[0])
    on = True
    assert on == on_surface(node, int(leaf[0]))
    while table[node, 1] >= 0:  # Algorithm A.1
        p = int(table[node, 1])
        right = p - 1
        sib = table[right, 2] - 1 if node == right else right
        v = vals[sib]
        if v is not None:
            on = on and (v if table[p, 0] == INTERSECTION else not v)
        node = p
        assert on == on_surface(node, int(leaf[0]))  # (A.3) after every iteration
    work = np.empty((len(table), 5))
    assert keep_tree(0, x[0], x[1], x[2], offsets, partners, table, leaf, work) == on


@settings(max_examples=150, deadline=None)
@given(fragments(), st.integers(0, 2**31 - 1))
def test_cached_short_circuit_traversal_equals_full_traversal(case, seed):
    """keep_tree_cached (short-circuited, results reused between neighbouring fragments, 4.2.3)
    gives exactly keep_tree's answer on a walk of nearby fragments (pixel-sized steps, some
    landing on partner planes and on ties between partners)."""
    _walk_cached(case, seed)


@settings(max_examples=150, deadline=None)
@given(fragments(most=1), st.integers(0, 2**31 - 1))
def test_cached_traversal_with_one_partner_per_leaf_equals_full_traversal(case, seed):
    """The same with at most one partner per leaf (keep_tree_cached's plane-per-leaf path)."""
    _walk_cached(case, seed)


@settings(max_examples=150, deadline=None)
@given(fragments(most=5, sheet=True), st.integers(0, 2**31 - 1))
def test_cached_traversal_with_sheets_of_partners_equals_full_traversal(case, seed):
    """The same with several partners of nearly one orientation per leaf (a sampled surface):
    all of a leaf's partners then often agree on the fragment, whichever two are closest."""
    _walk_cached(case, seed)


def _walk_cached(case, seed):
    from unmesh.render._splat_kernels import clip_work, keep_tree_cached, max_rows

    x, offsets, partners, table, leaf, _ = case
    full = np.empty((len(table), 5))
    work = clip_work(len(table), max_rows(offsets))
    rng = np.random.default_rng(seed)
    p = x.copy()
    for step in range(60):
        if step % 7 == 3 and len(partners):  # onto a partner's plane (coplanar tie band)
            r = partners[rng.integers(len(partners))]
            p = p - np.dot(p - r[:3], r[3:6]) * r[3:6]
        elif step % 11 == 5 and len(partners) > 1:  # equidistant from two partners
            a, b = partners[rng.choice(len(partners), 2, replace=False)]
            p = 0.5 * (a[:3] + b[:3])
        else:
            p = p + rng.normal(scale=10.0 ** rng.uniform(-4, -1), size=3)
        want = keep_tree(0, p[0], p[1], p[2], offsets, partners, table, leaf, full)
        assert keep_tree_cached(0, p[0], p[1], p[2], offsets, partners, table, leaf, work) == want


@settings(max_examples=150, deadline=None)
@given(fragments(planes=True))
def test_kernel_matches_reference_with_partners_on_one_plane(case):
    """keep_tree against the reference with lines of partners on one plane (s2 is the closest
    partner off s1's plane)."""
    x, offsets, partners, table, leaf, _ = case
    work = np.empty((len(table), 5))
    ref = on_surface_reference(x, 0, offsets, partners, table, leaf)
    assert keep_tree(0, x[0], x[1], x[2], offsets, partners, table, leaf, work) == ref


@settings(max_examples=150, deadline=None)
@given(fragments(most=5, planes=True), st.integers(0, 2**31 - 1))
def test_cached_traversal_with_partners_on_one_plane_equals_full_traversal(case, seed):
    """keep_tree_cached equals keep_tree with lines of partners on one plane (its margin keeps
    s1 the closest and s2 the closest off s1's plane)."""
    _walk_cached(case, seed)


def _corner_partners():
    """Partners of one leaf along two border lines meeting at a corner (Fig. 4.6, a surfel
    outside the painted square next to its corner): the line ``x = 0`` (normals +x) with
    surfels every 0.05 for ``y`` in [-1, -0.05], and the line ``y = 0`` (normals -y) for ``x``
    in [-1, -0.05]; the patch is the quadrant x < 0, y > 0."""
    t = -np.arange(1, 21) * 0.05
    a = np.stack([np.zeros_like(t), t, np.zeros_like(t)], axis=1)
    b = np.stack([t, np.zeros_like(t), np.zeros_like(t)], axis=1)
    rows = np.zeros((2 * len(t), 7))
    rows[:len(t), :3] = a
    rows[:len(t), 3] = 1.0
    rows[len(t):, :3] = b
    rows[len(t):, 4] = -1.0
    rows[:, 6] = 1.0
    return rows


def test_corner_of_two_border_lines_fig_4_6():
    """Fragments near the corner of two lines of partners: outside beyond either line. Before,
    the two closest partners of a fragment beside the line ``x = 0`` but beyond ``y = 0`` both
    came from the first line, and 4.4 reduced to its half-space, keeping the fragment."""
    from unmesh.render._splat_kernels import clip_work, keep_tree_cached, max_rows

    partners = _corner_partners()
    offsets = np.array([0, len(partners)], dtype=np.int64)
    table = np.array([[2, 2, 0, 0], [2, 2, 1, 0], [0, -1, 0, 0]], dtype=np.int32)  # surface & D
    leaf = np.array([0], dtype=np.int32)
    rng = np.random.default_rng(1)
    x = rng.uniform(-0.3, 0.3, (4000, 3))
    x[:, 2] *= 0.1
    exact = (x[:, 0] < 0) & (x[:, 1] > 0)
    full = np.empty((3, 5))
    work = clip_work(3, max_rows(offsets))
    got = np.array([keep_tree(0, *p, offsets, partners, table, leaf, full) for p in x])
    cached = np.array([keep_tree_cached(0, *p, offsets, partners, table, leaf, work) for p in x])
    ref = np.array([on_surface_reference(p, 0, offsets, partners, table, leaf) for p in x])
    # beside the line x = 0 (inside its half-space) but beyond y = 0
    near = (x[:, 0] < 0) & (x[:, 0] > -0.03) & (x[:, 1] < -0.02)
    assert near.sum() > 20
    assert not got[near].any()
    assert (got == exact).all() and (cached == got).all() and (ref == got).all()
    cloud = SurfelCloud(partners[:, :3], partners[:, 3:6], radii=np.full(len(partners), 0.05))
    from unmesh.csg import inside_patch
    assert (inside_patch(cloud, x) == exact).all()
