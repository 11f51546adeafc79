"""Inside/outside classification for CSG trees of surfel patches (thesis 4.1.1, 4.2.2).

* ``insidePatch`` over a whole patch: the closest surfel (4.3) or the two closest surfels with
  the concave/convex rule (4.4), vectorised through :class:`unmesh.spatial.KDTree`;
* ``insideTree`` (Algorithm 4.3): (4.7)/(4.8) over the tree, here over whole patches, so every
  value is known (:func:`inside`);
* Algorithm 4.2 with the three-valued logic of 4.9/4.10 (-1 unknown) as a plain numpy/Python
  reference (:func:`on_surface_reference`) of the splat kernel
  :func:`unmesh.render._splat_kernels.keep_tree`.

Example
-------
>>> from unmesh.csg.model import Patch
>>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=4.0, spacing=0.5)
>>> b = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=4.0, spacing=0.5)
>>> inside(a & b, [[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5]]).tolist()
[True, False, False]
>>> inside(a - b, [[0.5, 0, -0.5]]).tolist()
[True]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_points
from unmesh.csg.model import INTERSECTION, LEAF, FlatTree, Node, flatten
from unmesh.errors import InputError
from unmesh.render._splat_kernels import COPLANAR_EPS, SAME_PLANE_TOL
from unmesh.spatial import KDTree
from unmesh.surfels import SurfelCloud

__all__ = ["RULES", "inside", "inside_patch", "kleene_and", "kleene_or", "maybe_on_surface", "on_surface_reference",
           "same_plane_reference", "tree_values", "tri_and", "tri_or", "walk_up"]

#: Patch classification rules: the closest surfel (4.3) or the two closest (4.4).
RULES = ("closest", "two")


def inside_patch(cloud: SurfelCloud, points: Any, rule: str = "two", tree: KDTree | None = None) -> np.ndarray:
    """Whether ``points`` (M,3) are inside the patch ``cloud`` (outward normals): (M,) bool.

    ``rule="closest"``: (4.3), behind the closest surfel's plane. ``rule="two"``: (4.4), the
    closest surfel ``s1`` and the closest ``s2`` not on one plane with it (two surfels of one
    plane say no more than one; see :func:`unmesh.render._splat_kernels.same_plane`); when they
    are concave (each clips the other's centre) the point is inside if either does not clip
    it, otherwise only if neither clips it; without such an ``s2``, (4.3).

    Example
    -------
    >>> c = SurfelCloud([[0, 0, 0.0], [1, 0, 0]], [[0, 0, 1], [1, 0, 0]], radii=[1.0, 1.0])
    >>> inside_patch(c, [[0.5, 0, -0.1], [0.5, 0, 0.1]]).tolist()
    [True, False]
    """
    if rule not in RULES:
        raise InputError(f"rule: expected one of {', '.join(RULES)}, got {rule!r}")
    x = as_points(points, "points")
    if len(x) == 0:
        return np.zeros(0, dtype=bool)
    tree = tree if tree is not None else KDTree(cloud.positions)
    k = 1 if rule == "closest" or len(cloud) < 2 else 2
    _, idx = tree.knn(x, k)
    c, n = cloud.positions, cloud.normals
    i1 = idx[:, 0]
    clips1 = np.einsum("ij,ij->i", x - c[i1], n[i1]) >= 0.0
    if k == 1:
        return ~clips1
    i2 = _second_surfel(c, n, x, idx, tree)
    two = i2 >= 0
    i2 = np.where(two, i2, i1)
    clips2 = np.einsum("ij,ij->i", x - c[i2], n[i2]) >= 0.0
    concave = (np.einsum("ij,ij->i", c[i2] - c[i1], n[i1]) >= 0.0) & (np.einsum("ij,ij->i", c[i1] - c[i2], n[i2]) >= 0.0)
    return np.where(two, np.where(concave, ~clips1 | ~clips2, ~clips1 & ~clips2), ~clips1)


def _same_plane(c: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`unmesh.render._splat_kernels.same_plane` of surfels ``a`` and ``b`` (index arrays)."""
    t2 = SAME_PLANE_TOL * SAME_PLANE_TOL
    d = c[b] - c[a]
    dd = np.einsum("ij,ij->i", d, d)
    ea = np.einsum("ij,ij->i", d, n[a])
    eb = np.einsum("ij,ij->i", d, n[b])
    return (np.einsum("ij,ij->i", n[a], n[b]) >= 1.0 - 0.5 * t2) & (ea * ea <= t2 * dd) & (eb * eb <= t2 * dd)


def _second_surfel(c: np.ndarray, n: np.ndarray, x: np.ndarray, idx: np.ndarray, tree: KDTree) -> np.ndarray:
    """For each point, the closest surfel not on one plane with its closest ``idx[:, 0]`` (from
    the two nearest ``idx``, asking more neighbours where those are on one plane): (M,) int64,
    -1 where every surfel is on that plane."""
    i1 = idx[:, 0]
    out = np.where(_same_plane(c, n, i1, idx[:, 1]), -1, idx[:, 1]).astype(np.int64)
    rows = np.flatnonzero(out < 0)
    k = 2
    while len(rows) and k < len(c):
        k = min(4 * k, len(c))
        _, more = tree.knn(x[rows], k)
        found = np.full(len(rows), -1, dtype=np.int64)
        for col in range(k - 1, 0, -1):  # the nearest one off the plane wins
            j = more[:, col]
            ok = (j != i1[rows]) & ~_same_plane(c, n, i1[rows], j)
            found = np.where(ok, j, found)
        out[rows] = found
        rows = rows[found < 0]
    return out


def tri_and(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Three-valued conjunction (4.10) of int8 arrays (1 true, 0 false, -1 unknown)."""
    return np.where(a < 0, b, np.where(b < 0, a, np.minimum(a, b))).astype(np.int8)


def tri_or(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Three-valued disjunction (4.9) of int8 arrays (1 true, 0 false, -1 unknown)."""
    return np.where(a < 0, b, np.where(b < 0, a, np.maximum(a, b))).astype(np.int8)


def kleene_and(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Kleene's conjunction (unknown = either): false if either is false, unknown unless both are known."""
    return np.where((a == 0) | (b == 0), 0, np.where((a > 0) & (b > 0), 1, -1)).astype(np.int8)


def kleene_or(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Kleene's disjunction (unknown = either)."""
    return np.where((a > 0) | (b > 0), 1, np.where((a == 0) & (b == 0), 0, -1)).astype(np.int8)


def tree_values(flat: FlatTree, leaf_values: np.ndarray, logic: str = "thesis") -> np.ndarray:
    """insideTree (Algorithm 4.3) for every node: (K, M) int8 from leaf values (L, M) int8
    (already inverted at complemented leaves), with (4.7)/(4.8) in three-valued logic:
    ``"thesis"`` (4.9/4.10, unknown is neutral) or ``"kleene"`` (unknown is either value)."""
    both = (tri_and, tri_or) if logic == "thesis" else (kleene_and, kleene_or)
    leaf_values = np.asarray(leaf_values, dtype=np.int8)
    m = leaf_values.shape[1]
    vals = np.empty((len(flat), m), dtype=np.int8)
    j = 0
    for k in range(len(flat)):
        if flat.op[k] == LEAF:
            vals[k] = leaf_values[j]
            j += 1
        else:
            right = k - 1
            left = flat.first[right] - 1
            vals[k] = both[0 if flat.op[k] == INTERSECTION else 1](vals[left], vals[right])
    return vals


def walk_up(flat: FlatTree, vals: np.ndarray, leaf: int) -> np.ndarray:
    """Algorithm 4.2 from leaf number ``leaf`` with insideTree values ``vals`` (K, M): (M,) bool."""
    node = int(flat.leaf_node[leaf])
    on = np.ones(vals.shape[1], dtype=bool)
    while flat.parent[node] >= 0:
        p = int(flat.parent[node])
        right = p - 1
        sib = flat.first[right] - 1 if node == right else right
        v = vals[sib]
        known = v >= 0
        if flat.op[p] == INTERSECTION:
            on &= ~known | (v > 0)
        else:
            on &= ~known | (v == 0)
        node = p
    return on


def maybe_on_surface(flat: FlatTree, vals: np.ndarray, leaf: int) -> np.ndarray:
    """Algorithm 4.2 in Kleene logic from leaf number ``leaf`` with values ``vals`` (K, M) of
    :func:`tree_values` (``logic="kleene"``): (M,) int8, 0 where the point is off the surface
    whatever the unknown leaves are, 1 where it is on it, -1 where that depends on them."""
    node = int(flat.leaf_node[leaf])
    on = np.ones(vals.shape[1], dtype=np.int8)
    while flat.parent[node] >= 0:
        p = int(flat.parent[node])
        right = p - 1
        sib = flat.first[right] - 1 if node == right else right
        v = vals[sib]
        term = v if flat.op[p] == INTERSECTION else np.where(v < 0, -1, 1 - v).astype(np.int8)
        on = kleene_and(on, term)
        node = p
    return on


def inside(model: Node | FlatTree, points: Any, rule: str = "two") -> np.ndarray:
    """Whether ``points`` (M,3) are inside the CSG ``model``: (M,) bool (Algorithm 4.3 over
    whole patches with insidePatch (4.3)/(4.4); complemented leaves invert it, 4.3).

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> from unmesh.csg.model import Patch
    >>> a = Patch(Sphere(radius=1.0).surfels(0.1))
    >>> b = Patch(Sphere(radius=0.5).surfels(0.1))
    >>> inside(a - b, [[0, 0, 0], [0.75, 0, 0], [1.2, 0, 0]]).tolist()
    [False, True, False]
    """
    flat = model if isinstance(model, FlatTree) else flatten(model)
    x = as_points(points, "points")
    leaf_values = np.empty((len(flat.leaves), len(x)), dtype=np.int8)
    for j, patch in enumerate(flat.leaves):
        v = inside_patch(patch.world_cloud(), x, rule)
        leaf_values[j] = v != bool(flat.invert[flat.leaf_node[j]])
    return tree_values(flat, leaf_values)[-1] > 0


def same_plane_reference(a: np.ndarray, b: np.ndarray, tol: float = SAME_PLANE_TOL) -> bool:
    """Plain-Python :func:`unmesh.render._splat_kernels.same_plane` of two partner rows
    ``(cx, cy, cz, nx, ny, nz, ...)``: parallel normals and each centre on the other's plane."""
    t2 = tol * tol
    if float(a[3]) * float(b[3]) + float(a[4]) * float(b[4]) + float(a[5]) * float(b[5]) < 1.0 - 0.5 * t2:
        return False
    dx, dy, dz = float(b[0]) - float(a[0]), float(b[1]) - float(a[1]), float(b[2]) - float(a[2])
    dd = dx * dx + dy * dy + dz * dz
    ea = dx * float(a[3]) + dy * float(a[4]) + dz * float(a[5])
    eb = dx * float(b[3]) + dy * float(b[4]) + dz * float(b[5])
    return ea * ea <= t2 * dd and eb * eb <= t2 * dd


def on_surface_reference(x: Any, s: int, offsets: np.ndarray, partners: np.ndarray, tree: np.ndarray,
                         leaf: np.ndarray) -> bool:
    """Plain-Python Algorithm 4.2 (with 4.3, 4.4, 4.9, 4.10) for a fragment of surfel ``s`` at
    ``x``: the reference of :func:`unmesh.render._splat_kernels.keep_tree` (same arguments as
    :class:`unmesh.render.ClipTree`)."""
    x = np.asarray(x, dtype=np.float64)
    rows = partners[offsets[s]:offsets[s + 1]]
    k_nodes = len(tree)
    vals = np.full(k_nodes, -1, dtype=np.int64)

    def clips(row: np.ndarray, p: np.ndarray) -> bool:
        return float(np.dot(p - row[:3], row[3:6])) >= 0.0

    own = int(leaf[s])

    def clips_x(row: np.ndarray) -> bool:  # with the tie-break of coplanar patches (4.5)
        d = (x[0] - row[0]) * row[3] + (x[1] - row[1]) * row[4] + (x[2] - row[2]) * row[5]
        if abs(d) <= COPLANAR_EPS * (1.0 + abs(x[0]) + abs(x[1]) + abs(x[2])):
            return own > row[6]
        return d >= 0.0

    for k in range(k_nodes):
        op = tree[k, 0]
        if op == LEAF:
            mine = rows[rows[:, 6] == k]
            if len(mine) == 0:
                continue
            d = ((mine[:, :3] - x) ** 2).sum(axis=1)
            order = np.argsort(d, kind="stable")
            a = mine[order[0]]
            c1 = clips_x(a)
            off = [r for r in mine[order[1:]] if not same_plane_reference(a, r)]
            if not off:
                ins = not c1
            else:
                b = off[0]
                c2 = clips_x(b)
                ins = (not c1 or not c2) if (clips(a, b[:3]) and clips(b, a[:3])) else (not c1 and not c2)
            vals[k] = int(ins != bool(tree[k, 3]))
        else:
            right = k - 1
            left = tree[right, 2] - 1
            a, b = vals[left], vals[right]
            if a < 0:
                vals[k] = b
            elif b < 0:
                vals[k] = a
            else:
                vals[k] = min(a, b) if op == INTERSECTION else max(a, b)
    node = int(leaf[s])
    while tree[node, 1] >= 0:
        p = int(tree[node, 1])
        right = p - 1
        sib = tree[right, 2] - 1 if node == right else right
        v = vals[sib]
        if v >= 0 and not ((v > 0) if tree[p, 0] == INTERSECTION else (v == 0)):
            return False
        node = p
    return True
