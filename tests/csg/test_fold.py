"""Per-surfel folded clip trees (unmesh.csg.fold): the same decision for every fragment, the same image."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import scenes
from unmesh.csg import prepare
from unmesh.csg.draw import front_facing
from unmesh.csg.fold import VARIABLE, fold_for_camera, fold_tree
from unmesh.csg.frame import select
from unmesh.csg.scene import load
from unmesh.render import Camera, ClipTree, SplatRenderer, scene_points
from unmesh.render._splat_kernels import keep_tree
from unmesh.render.splat import SurfelArrays
from unmesh.surfels import SurfelCloud

from .test_clip_tree import fragments


def _walk(tree, own, values):
    """Algorithm 4.2 with the kernel's three-valued logic over leaf ``values`` (K,) (-1 unknown)."""
    v = np.full(len(tree), -1)
    for k in range(len(tree)):
        if tree[k, 0] == 2:
            v[k] = values[k]
        else:
            a, b = v[tree[k - 1, 2] - 1], v[k - 1]
            v[k] = b if a < 0 else a if b < 0 else (min(a, b) if tree[k, 0] == 0 else max(a, b))
    node = own
    while tree[node, 1] >= 0:
        p = tree[node, 1]
        sib = tree[p - 1, 2] - 1 if node == p - 1 else p - 1
        if v[sib] >= 0 and not (v[sib] > 0 if tree[p, 0] == 0 else v[sib] == 0):
            return False
        node = p
    return True


@settings(max_examples=200, deadline=None)
@given(fragments(), st.integers(0, 2**31 - 1))
def test_folded_tree_walk_equals_full_walk(case, seed):
    """Constant leaves folded, every assignment of the variable ones: the same decision."""
    _, _, _, table, leaf, _ = case
    rng = np.random.default_rng(seed)
    own = int(leaf[0])
    is_leaf = table[:, 0] == 2
    state = np.where(is_leaf, rng.choice([-1, 0, 1, VARIABLE], len(table)), 0)
    state[own] = VARIABLE
    res = fold_tree(table, own, state)
    for _ in range(8):
        values = np.where(state == VARIABLE, rng.integers(0, 2, len(table)), state)
        full = _walk(table, own, values)
        if res is None:
            assert not full
        elif res == ():
            assert full
        else:
            rows, node_map = res
            assert own in node_map and set(node_map) <= set(np.flatnonzero(state == VARIABLE).tolist())
            sub = np.full(len(rows), -1)
            for old, new in node_map.items():
                sub[new] = values[old]
            assert _walk(rows, node_map[own], sub) == full
            # leaf order kept (the coplanar tie rule compares leaf numbers)
            olds = sorted(node_map)
            assert [node_map[o] for o in olds] == sorted(node_map.values())


@settings(max_examples=150, deadline=None)
@given(fragments(), st.integers(0, 2**31 - 1))
def test_folded_clip_tree_keeps_the_same_fragments(case, seed):
    """A random surfel disc with random partners: every fragment on the disc gets the full tree's decision."""
    _, offsets, partners, table, leaf, _ = case
    rng = np.random.default_rng(seed)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    c = rng.uniform(-1, 1, 3)
    r = float(rng.uniform(0.05, 1.0))
    arrays = SurfelArrays(c[None], n[None], np.array([r]), None, np.ones((1, 3)))
    clip = ClipTree(offsets, partners, table, leaf)
    cam = Camera(c + 3 * n, c, up=np.cross(n, [0.3, 0.5, 0.7]), width=256, height=256, ortho=1.2 * r)
    fa, fc = fold_for_camera(arrays, clip, cam)
    u = np.cross(n, rng.normal(size=3))
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    work = np.empty((len(table), 5))
    work2 = np.empty((len(fc.tree) if len(fa) else 1, 5))
    for _ in range(40):
        a, rho = rng.uniform(0, 2 * np.pi), r * np.sqrt(rng.uniform(0, 1))
        x = c + rho * (np.cos(a) * u + np.sin(a) * v)
        full = keep_tree(0, x[0], x[1], x[2], offsets, partners, table, leaf, work)
        if len(fa) == 0:
            assert not full
        elif fc.offsets[1] == 0:
            assert full
        else:
            assert keep_tree(0, x[0], x[1], x[2], fc.offsets, fc.partners, fc.tree, fc.leaf, work2) == full


@pytest.mark.parametrize("name", ["icosahedron", "spikes"])
@pytest.mark.parametrize("zoom", [1.0, 2.5])
def test_folded_frames_render_the_same_image(name, zoom):
    """Shipped scenes: the folded trees give bit-identical G-buffers with fewer partner rows."""
    fr = prepare(load(scenes.path(f"csg/{name}.toml")).model)
    pts = scene_points(SurfelCloud(fr.arrays.positions, fr.arrays.normals, radii=fr.arrays.radii))
    cam = Camera.fit(pts, 200, 200, fov=35).zoomed(zoom)
    arrays, clip = select(fr.arrays, fr.clip, front_facing(fr.arrays.positions, fr.arrays.normals, cam))
    fa, fc = fold_for_camera(arrays, clip, cam)
    assert len(fc.partners) < len(clip.partners)
    g1 = SplatRenderer(cam).render(arrays, clip=clip).gbuffer()
    g2 = SplatRenderer(cam).render(fa, clip=fc).gbuffer()
    for k in ("albedo", "normal", "depth", "coverage", "weight"):
        assert np.array_equal(getattr(g1, k), getattr(g2, k)), k


def test_surfels_beyond_the_tree_budget_keep_the_full_tree(monkeypatch):
    """With no room for folded trees, surfels still drop or go plain where they may, the others
    keep the full tree and all partners: the same image."""
    from unmesh.csg import fold

    monkeypatch.setattr(fold, "TREE_ROWS", 0)
    fr = prepare(load(scenes.path("csg/icosahedron.toml")).model)
    pts = scene_points(SurfelCloud(fr.arrays.positions, fr.arrays.normals, radii=fr.arrays.radii))
    cam = Camera.fit(pts, 160, 160, fov=35)
    arrays, clip = select(fr.arrays, fr.clip, front_facing(fr.arrays.positions, fr.arrays.normals, cam))
    fa, fc = fold_for_camera(arrays, clip, cam)
    assert len(fc.tree) <= 2 * len(clip.tree)
    g1 = SplatRenderer(cam).render(arrays, clip=clip).gbuffer()
    g2 = SplatRenderer(cam).render(fa, clip=fc).gbuffer()
    for k in ("albedo", "normal", "depth", "coverage", "weight"):
        assert np.array_equal(getattr(g1, k), getattr(g2, k)), k


@pytest.mark.parametrize("leaves", [5, 40])
def test_signature_groups_equal_numpy_unique_rows(leaves):
    """The packed-integer grouping of folding signatures (and its fallback for trees with too
    many leaves to pack) gives the groups of ``np.unique(axis=0)`` in the same order."""
    from unmesh.csg.fold import LEAF, _signatures

    rng = np.random.default_rng(leaves)
    k = 2 * leaves - 1
    tree = np.zeros((k, 4), dtype=np.int32)
    tree[rng.permutation(k)[:leaves], 0] = LEAF
    cols = np.flatnonzero(tree[:, 0] == LEAF)
    m = 500
    state = np.full((m, k), -1, dtype=np.int8)
    state[:, cols] = rng.integers(-1, 3, size=(m, leaves))
    state[rng.integers(0, m, 200)] = state[rng.integers(0, m, 200)]  # repeated signatures
    leaf = cols[rng.integers(0, leaves, m)].astype(np.int32)
    leaf[:100] = leaf[100:200]
    state[:100] = state[100:200]
    first, which = _signatures(tree, leaf, state)
    sig = np.concatenate([leaf[:, None].astype(np.int32), state.astype(np.int32)], axis=1)
    _, first_ref, which_ref = np.unique(sig, axis=0, return_index=True, return_inverse=True)
    assert np.array_equal(first, first_ref)
    assert np.array_equal(which, which_ref.reshape(-1))


def test_folding_cache_and_trusted_clip_tree_match_a_fresh_validated_fold(monkeypatch):
    """Folded trees reused from earlier frames give the same arrays as folding afresh, and the
    clip tree built without re-validation passes :class:`ClipTree`'s checks unchanged."""
    from unmesh.csg import fold

    fr = prepare(load(scenes.path("csg/spikes.toml")).model)
    pts = scene_points(SurfelCloud(fr.arrays.positions, fr.arrays.normals, radii=fr.arrays.radii))
    cam = Camera.fit(pts, 200, 200, fov=35)
    arrays, clip = select(fr.arrays, fr.clip, front_facing(fr.arrays.positions, fr.arrays.normals, cam))
    fa1, fc1 = fold_for_camera(arrays, clip, cam)  # fills the cache
    monkeypatch.setattr(fold, "_FOLDED", {})
    fa2, fc2 = fold_for_camera(arrays, clip, cam)
    checked = ClipTree(fc1.offsets, fc1.partners, fc1.tree, fc1.leaf)
    for a, b, c in zip((fc1.offsets, fc1.partners, fc1.tree, fc1.leaf), (fc2.offsets, fc2.partners, fc2.tree, fc2.leaf),
                       (checked.offsets, checked.partners, checked.tree, checked.leaf), strict=True):
        assert a.dtype == b.dtype == c.dtype and a.flags.c_contiguous
        assert np.array_equal(a, b) and np.array_equal(a, c)
    for k in ("positions", "normals", "radii", "colors"):
        assert np.array_equal(getattr(fa1, k), getattr(fa2, k))
