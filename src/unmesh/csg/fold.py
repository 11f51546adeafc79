"""Per-surfel clip trees for one camera: the CSG tree folded where a surfel's classification is
constant over its splat (4.2.3, traversal work done per surfel instead of per fragment).

A partner whose plane does not cross an edge surfel's disc clips either every fragment of the
surfel or none. When all partners of one patch lie on the same side of the disc, insidePatch
(4.3/4.4) of that patch is the same for every fragment, whichever two partners are closest; a
patch without partners is *unknown* (4.9/4.10) everywhere. :func:`fold_for_camera` folds these
constants into the tree for every edge surfel (with the three-valued logic of the splat kernel)
and walks Algorithm 4.2 from the surfel's leaf once:

* a constant sibling that puts the surfel off the surface: the surfel is dropped;
* no variable sibling left: the surfel is splatted unclipped;
* otherwise the surfel gets a smaller tree (its leaf and the variable siblings, in the order of
  the walk, leaves numbered in their original order so that the coplanar tie rule of 4.5 is
  unchanged) and only the partners of its variable patches. Surfels with the same folded tree
  share it.

Every fragment gets the decision of the full tree, so the image is the same; the splat kernel
only evaluates fewer patches per fragment. Fragments lie on the disc unless the splat is small on
screen (the screen filter then adds fragments around it, 3.2): such surfels keep their full tree.

Example
-------
>>> from unmesh.csg.frame import prepare
>>> from unmesh.csg.model import Patch
>>> from unmesh.render import Camera
>>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=2.0, spacing=0.25)
>>> b = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=2.0, spacing=0.25)
>>> f = prepare(a & b)
>>> arrays, clip = fold_for_camera(f.arrays, f.clip, Camera((-3, 1, 3), (0, 0, 0), width=256, height=256))
>>> len(arrays) <= len(f.arrays), len(clip) == len(arrays)
(True, True)
"""

from __future__ import annotations

import numpy as np

from unmesh.render._splat_kernels import COPLANAR_EPS
from unmesh.render.camera import Camera
from unmesh.render.splat import ClipTree, SurfelArrays

__all__ = ["fold_for_camera", "fold_tree"]

#: Leaf states of a surfel: constant values 0 (outside) and 1 (inside, after inversion), -1
#: unknown (no partner in that patch), and :data:`VARIABLE` (depends on the fragment).
VARIABLE = 2

INTERSECTION, UNION, LEAF = 0, 1, 2

#: Rows of all folded trees together (at least twice the full tree's): surfels whose folded tree
#: does not fit keep the full one.
TREE_ROWS = 1024

#: Folded trees kept across calls (frames): (tree bytes, own leaf, state bytes) -> the result of
#: :func:`fold_tree` (read only). Cleared when it holds this many.
FOLD_CACHE = 4096
_FOLDED: dict = {}
_MISSING = object()


def _tri(op: int, a: int, b: int) -> int:
    if a < 0:
        return b
    if b < 0:
        return a
    return min(a, b) if op == INTERSECTION else max(a, b)


def _fold(tree: np.ndarray, k: int, state: np.ndarray):
    """Folded sub-tree of node ``k``: an int constant (0, 1, -1) or a nested tuple
    ``("leaf", node)`` / ``("op", op, left, right)`` that never evaluates to unknown."""
    if tree[k, 0] == LEAF:
        s = int(state[k])
        return ("leaf", k) if s == VARIABLE else s
    op = int(tree[k, 0])
    right = k - 1
    left = int(tree[right, 2]) - 1
    a = _fold(tree, left, state)
    b = _fold(tree, right, state)
    if isinstance(a, int) and isinstance(b, int):
        return _tri(op, a, b)
    if isinstance(a, int) or isinstance(b, int):
        c, x = (a, b) if isinstance(a, int) else (b, a)
        if c < 0:
            return x
        decided = 0 if op == INTERSECTION else 1
        return decided if c == decided else x
    return ("op", op, a, b)


def fold_tree(tree: np.ndarray, own: int, state: np.ndarray):
    """Fold the clip tree ``tree`` (K, 4) for a surfel of leaf node ``own`` whose leaf nodes have
    ``state`` (K,) (:data:`VARIABLE`, 0, 1 or -1; other rows ignored) and walk Algorithm 4.2.

    Returns ``None`` when the surfel is off the surface everywhere, ``()`` when it is on the
    surface everywhere, else ``(rows, node_map)``: the folded tree (M, 4) int32 in post order and
    a dict from the original leaf nodes kept (``own`` and the variable ones) to their new rows.

    Example
    -------
    >>> t = np.array([[2, 2, 0, 0], [2, 2, 1, 0], [0, -1, 0, 0]], dtype=np.int32)  # leaf0 & leaf1
    >>> fold_tree(t, 0, np.array([2, 0, 0])) is None, fold_tree(t, 0, np.array([2, 1, 0])), fold_tree(t, 0, np.array([2, -1, 0]))
    (True, (), ())
    >>> rows, m = fold_tree(t, 0, np.array([2, 2, 0]))
    >>> rows.tolist(), m
    ([[2, 2, 0, 0], [2, 2, 1, 0], [0, -1, 0, 0]], {0: 0, 1: 1})
    """
    chain = ("leaf", own)
    node = own
    while tree[node, 1] >= 0:
        p = int(tree[node, 1])
        right = p - 1
        sib_left = node == right
        sib = int(tree[right, 2]) - 1 if sib_left else right
        v = _fold(tree, sib, state)
        if isinstance(v, int):
            if v >= 0 and not (v > 0 if tree[p, 0] == INTERSECTION else v == 0):
                return None
        else:
            chain = ("op", int(tree[p, 0]), v, chain) if sib_left else ("op", int(tree[p, 0]), chain, v)
        node = p
    if chain[0] == "leaf":
        return ()
    rows: list[list[int]] = []
    node_map: dict[int, int] = {}

    def emit(x) -> tuple[int, int]:
        if x[0] == "leaf":
            rows.append([LEAF, -1, len(rows), int(tree[x[1], 3])])
            node_map[x[1]] = len(rows) - 1
            return len(rows) - 1, len(rows) - 1
        li, first = emit(x[2])
        ri, _ = emit(x[3])
        rows.append([x[1], -1, first, 0])
        rows[li][1] = rows[ri][1] = len(rows) - 1
        return len(rows) - 1, first

    emit(chain)
    return np.array(rows, dtype=np.int32), node_map


def _signatures(tree: np.ndarray, leaf: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Groups of equal folding signatures ``(leaf[i], state[i])``: ``first`` (G,) the first
    surfel of each group and ``which`` (M,) the group of each, the groups in lexicographic order
    of the signatures (what ``np.unique(..., axis=0)`` gives). Only leaf columns of ``state``
    vary (other nodes have no partners: -1); when they fit, each signature is packed into one
    int64 (2 bits per leaf state, order kept) and the unique is one of integers."""
    cols = np.flatnonzero(tree[:, 0] == LEAF)
    bits = 2 * len(cols)
    if bits + len(tree).bit_length() <= 62:
        weights = np.left_shift(np.int64(1), 2 * np.arange(len(cols) - 1, -1, -1, dtype=np.int64))
        key = (state[:, cols].astype(np.int64) + 1) @ weights + (leaf.astype(np.int64) << bits)
        _, first, which = np.unique(key, return_index=True, return_inverse=True)
    else:
        sig = np.concatenate([leaf[:, None].astype(np.int32), state.astype(np.int32)], axis=1)
        _, first, which = np.unique(sig, axis=0, return_index=True, return_inverse=True)
    return first, which.reshape(-1)


def _foldable(arrays: SurfelArrays, camera: Camera, filter_radius: float) -> np.ndarray:
    """(N,) bool: surfels whose every fragment lies on their disc (the screen filter's disc
    around the projected centre is well inside the projected splat)."""
    f, _, _, ortho, near = camera.kernel_params()
    r = arrays.radii
    if ortho:
        cos = np.abs(arrays.normals @ camera.rotation[2])
        minor = f * r * cos
        ok = np.ones(len(r), dtype=bool)
    else:
        d = arrays.positions - camera.eye
        dist = np.linalg.norm(d, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", d, arrays.normals)) / np.maximum(dist, 1e-300)
        minor = f * r * cos / (dist + r)
        ok = (d @ camera.rotation[2]) > near + r
    return ok & (0.99 * minor >= 2.0 * filter_radius + 2.0)


def fold_for_camera(arrays: SurfelArrays, clip: ClipTree, camera: Camera,
                    filter_radius: float = 1.0) -> tuple[SurfelArrays, ClipTree]:
    """The drawn surfels and clip tree of a CSG frame with the tree folded per surfel (see the
    module notes): the same image from :class:`unmesh.render.SplatRenderer` with ``camera`` and
    a screen filter of ``filter_radius`` pixels, with less work per fragment.

    Parameters
    ----------
    arrays : SurfelArrays
        (N,) drawn surfels (circular or elliptical; the largest semi-axis bounds the disc).
    clip : ClipTree
        Their clipping partners and tree (:func:`unmesh.csg.frame.prepare`).
    camera : Camera
    filter_radius : float
        ``SplatOptions.filter_radius`` of the renderer.

    Returns
    -------
    arrays, clip : the surfels still drawn and their (concatenated, per-surfel) clip trees.
    """
    n = len(arrays)
    counts = np.diff(clip.offsets)
    edge = counts > 0
    if not edge.any():
        return arrays, clip
    radii = arrays.radii if arrays.axes is None else np.linalg.norm(arrays.axes, axis=2).max(axis=1)
    sub = SurfelArrays(arrays.positions, arrays.normals, radii, None, arrays.colors)
    cand = edge & _foldable(sub, camera, filter_radius)
    if not cand.any():
        return arrays, clip
    tree = clip.tree
    K = len(tree)
    P = clip.partners
    owner = np.repeat(np.arange(n), counts)
    c = arrays.positions[owner]
    nrm = arrays.normals[owner]
    r = radii[owner] * (1.0 + 1e-6)
    d = np.einsum("ij,ij->i", c - P[:, :3], P[:, 3:6])
    reach = r * np.sqrt(np.clip(1.0 - np.einsum("ij,ij->i", nrm, P[:, 3:6]) ** 2, 0.0, 1.0))
    tol = 2.0 * COPLANAR_EPS * (1.0 + np.abs(c).sum(axis=1) + 3.0 * r) + 1e-12
    cross = np.abs(d) <= reach + tol
    clips = d >= 0.0
    node = P[:, 6].astype(np.int64)
    key = owner * K + node
    n_rows = np.bincount(key, minlength=n * K).reshape(n, K)
    n_cross = np.bincount(key, weights=cross, minlength=n * K).reshape(n, K)
    n_clip = np.bincount(key, weights=clips, minlength=n * K).reshape(n, K)
    inv = tree[:, 3].astype(bool)
    const = np.where(n_clip == 0, 1, 0) ^ inv[None, :]  # no partner clips: inside
    state = np.where(n_rows == 0, -1, np.where((n_cross > 0) | ((n_clip > 0) & (n_clip < n_rows)), VARIABLE, const))
    state = state.astype(np.int8)
    idx = np.flatnonzero(cand)
    first, which = _signatures(tree, clip.leaf[idx], state[idx])
    tree_key = tree.tobytes()
    trees = [tree]
    shift = K
    # per unique signature: None (drop), () (plain), (shift, node_map), or "full" (the tree rows
    # are spent: the kernel clears per-node scratch of the whole tree whenever the surfel
    # changes, so the concatenated trees stay small; the most common signatures go first)
    folded: list = [None] * len(first)
    full = np.zeros(len(first), dtype=bool)
    for q in np.argsort(-np.bincount(which, minlength=len(first)), kind="stable"):
        s = idx[first[q]]
        own = int(clip.leaf[s])
        key = (tree_key, own, state[s].tobytes())
        res = _FOLDED.get(key, _MISSING)
        if res is _MISSING:
            if len(_FOLDED) >= FOLD_CACHE:
                _FOLDED.clear()
            res = _FOLDED[key] = fold_tree(tree, own, state[s])
        if res is None or res == ():
            folded[q] = res
        elif shift + len(res[0]) > max(TREE_ROWS, 2 * K):
            full[q] = True
            folded[q] = "full"
        else:
            rows, node_map = res
            rows = rows.copy()
            rows[:, 1] = np.where(rows[:, 1] >= 0, rows[:, 1] + shift, -1)
            rows[:, 2] += shift
            trees.append(rows)
            folded[q] = (shift, node_map)
            shift += len(rows)
    keep = np.ones(n, dtype=bool)
    new_leaf = clip.leaf.astype(np.int64).copy()
    remap = np.full((len(folded), K), -1, dtype=np.int64)  # old leaf node -> new row, per signature
    drop_sig = np.zeros(len(folded), dtype=bool)
    for q, res in enumerate(folded):
        if res is None:
            drop_sig[q] = True
        elif res != () and res != "full":
            sh, node_map = res
            for old, new in node_map.items():
                remap[q, old] = new + sh
    keep[idx[drop_sig[which]]] = False
    sig_of = np.full(n, -1, dtype=np.int64)
    sig_of[idx] = which
    sig_of[idx[full[which]]] = -1  # unfolded: the full tree and all partners
    row_sig = sig_of[owner]
    folded_row = row_sig >= 0
    mapped = remap[np.maximum(row_sig, 0), node]
    new_node = np.where(folded_row, mapped, node)
    row_keep = keep[owner] & (~folded_row | (mapped >= 0))
    # folded surfels with a tree: their own leaf in it (plain ones keep the full tree's leaf)
    own_new = remap[which, clip.leaf[idx]]
    new_leaf[idx[own_new >= 0]] = own_new[own_new >= 0]
    rows = P[row_keep].copy()
    rows[:, 6] = new_node[row_keep]
    kept = np.flatnonzero(keep)
    per = np.bincount(owner[row_keep], minlength=n)[kept]
    offsets = np.zeros(len(kept) + 1, dtype=np.int64)
    np.cumsum(per, out=offsets[1:])
    out = SurfelArrays(*(np.ascontiguousarray(getattr(arrays, k)[kept]) for k in ("positions", "normals", "radii")),
                       None if arrays.axes is None else np.ascontiguousarray(arrays.axes[kept]),
                       np.ascontiguousarray(arrays.colors[kept]))
    # built here from the validated ``clip`` (leaf nodes of the concatenated trees, int32 rows):
    # no re-validation every frame
    return out, ClipTree.trusted(offsets, rows, np.ascontiguousarray(np.concatenate(trees), dtype=np.int32),
                                 new_leaf[kept].astype(np.int32))
