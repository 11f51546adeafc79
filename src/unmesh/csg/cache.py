"""What a CSG frame can keep from one frame to the next (dynamic CSG, 4.2.1).

Patches move rigidly (or by similarity transforms) between frames, so everything intrinsic to
one patch is computed once per surfel cloud and reused while the patch moves: the k-d tree of
its surfel centres in the patch's own frame (insidePatch queries are mapped into that frame:
nearest surfels and the sides of their planes are invariant under similarity transforms) and
the pairs of its overlapping surfels (the pieces of 4.1.2). Patches are immutable (a moved
patch is a new :class:`~unmesh.csg.model.Patch`), so the insidePatch values of one patch's
surfel centres against another patch stay valid while neither moves: :func:`patch_memo` keeps
them, and a frame in which one patch moves only asks the pairs involving it. The caches hold
the clouds and patches weakly.

Example
-------
>>> from unmesh.csg.model import Patch
>>> p = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=1.0, spacing=0.5)
>>> local_tree(p.cloud) is local_tree(p.cloud)
True
>>> overlap_pairs(p.cloud).tolist()
[[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from unmesh.spatial import KDTree
from unmesh.surfels import SurfelCloud
from unmesh.surfels.cloud import similarity_scale

__all__ = ["local_points", "local_tree", "overlap_pairs", "patch_memo"]

_TREES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_PAIRS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_MEMO: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def patch_memo(target: Any, source: Any, rule: str) -> np.ndarray:
    """(n,) int8 insidePatch values (1 inside, 0 outside, -1 not asked yet) of the ``n`` surfel
    centres of patch ``source`` against patch ``target`` with ``rule``, filled in by the caller;
    one array per (target, source, rule) while both patches live.

    Example
    -------
    >>> from unmesh.csg.model import Patch
    >>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=1.0, spacing=0.5)
    >>> b = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=1.0, spacing=0.5)
    >>> m = patch_memo(a, b, "two")
    >>> m.tolist(), patch_memo(a, b, "two") is m, patch_memo(a, b, "closest") is m
    ([-1, -1, -1, -1], True, False)
    """
    per_target = _MEMO.get(target)
    if per_target is None:
        per_target = weakref.WeakKeyDictionary()
        _MEMO[target] = per_target
    per_source = per_target.get(source)
    if per_source is None:
        per_source = {}
        per_target[source] = per_source
    memo = per_source.get(rule)
    if memo is None:
        memo = np.full(len(source.cloud), -1, dtype=np.int8)
        per_source[rule] = memo
    return memo


#: Leaf size of the patch k-d trees: insidePatch asks many centres far from the patch (the
#: surfels of other patches), where larger leaves cost less (docs/performance.md, stop 34).
LEAF_SIZE = 64


def local_tree(cloud: SurfelCloud) -> KDTree:
    """The k-d tree of ``cloud.positions`` (leaves of :data:`LEAF_SIZE` points), built once per cloud."""
    tree = _TREES.get(cloud)
    if tree is None:
        tree = KDTree(cloud.positions, leafsize=LEAF_SIZE)
        _TREES[cloud] = tree
    return tree


def overlap_pairs(cloud: SurfelCloud) -> np.ndarray:
    """(P, 2) int64 pairs ``i < j`` of overlapping surfels of ``cloud`` (``|c_i - c_j| < r_i + r_j``),
    computed once per cloud (they do not change under similarity transforms)."""
    pairs = _PAIRS.get(cloud)
    if pairs is None:
        pos = cloud.positions
        r = np.asarray(cloud.radii, dtype=np.float64)
        if len(pos) < 2:
            pairs = np.zeros((0, 2), dtype=np.int64)
        else:
            pairs = local_tree(cloud).radius_pairs(2.0 * float(r.max()))
            d2 = ((pos[pairs[:, 0]] - pos[pairs[:, 1]]) ** 2).sum(axis=1)
            pairs = np.ascontiguousarray(pairs[d2 < (r[pairs[:, 0]] + r[pairs[:, 1]]) ** 2])
        _PAIRS[cloud] = pairs
    return pairs


def local_points(transform: Any, points: np.ndarray) -> np.ndarray | None:
    """``points`` (M,3) mapped into the frame of a patch with ``transform`` (4,4) or None, or
    None when the transform is not a similarity (the caller then works in world space)."""
    if transform is None:
        return points
    lin = transform[:3, :3]
    if similarity_scale(lin) is None:
        return None
    return np.ascontiguousarray((points - transform[:3, 3]) @ np.linalg.inv(lin).T)
