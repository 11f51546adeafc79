"""CSG models of point-sampled patches (thesis 4.1, 4.3).

A model is a binary tree: the leaves are :class:`Patch` es (a :class:`~unmesh.SurfelCloud` of
one smooth surface with outward normals), the inner nodes :class:`Union` and
:class:`Intersection`; :class:`Complement` inverts a sub-tree. The operators ``a | b``,
``a & b``, ``a - b`` (``a & ~b``) and ``~a`` build trees from patches and nodes.

:func:`normalize` rewrites a tree into unions and intersections whose complements sit only at
the leaves (4.3, De Morgan: ``~(a | b) = ~a & ~b``, ``~~a = a``); :func:`flatten` numbers the
normalised tree in post order for the kernels (:class:`FlatTree`): the sub-tree of node ``k``
is the contiguous range ``first[k] .. k``.

Example
-------
>>> from unmesh.shapes import Sphere
>>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=2.0, spacing=0.5, name="floor")
>>> b = Patch(Sphere(radius=0.5).surfels(0.2), name="ball")
>>> str(normalize(~(a | b)))
'(~floor & ~ball)'
>>> flatten(a - b).op.tolist()
[2, 2, 0]
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError
from unmesh.surfels import SurfelCloud

__all__ = ["INTERSECTION", "LEAF", "UNION", "Binary", "Complement", "FlatTree", "Intersection", "Node", "Patch", "Union",
           "flatten", "normalize", "patches"]

#: Node operators of :class:`FlatTree`.
INTERSECTION, UNION, LEAF = 0, 1, 2


class Node:
    """Base of every CSG tree node: the operators ``| & - ~``."""

    def __or__(self, other: Node) -> Union:
        return Union(self, _node(other, "right operand of |"))

    def __and__(self, other: Node) -> Intersection:
        return Intersection(self, _node(other, "right operand of &"))

    def __sub__(self, other: Node) -> Intersection:
        return Intersection(self, Complement(_node(other, "right operand of -")))

    def __invert__(self) -> Complement:
        return Complement(self)

    @property
    def positions(self) -> np.ndarray:
        """Centres (N,3) of the surfels of every patch (for camera framing)."""
        return np.concatenate([p.world_cloud().positions for p in patches(self)])

    @property
    def radii(self) -> np.ndarray:
        """Radii (N,) of the surfels of every patch."""
        return np.concatenate([np.asarray(p.world_cloud().radii) for p in patches(self)])

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2,3) of the surfel centres of every patch."""
        pos = self.positions
        return np.stack([pos.min(axis=0), pos.max(axis=0)])


def _node(obj: Any, what: str) -> Node:
    if not isinstance(obj, Node):
        raise InputError(f"{what}: expected a Patch or a CSG node, got {type(obj).__name__}")
    return obj


@dataclass(frozen=True, eq=False)
class Patch(Node):
    """A leaf of a CSG tree: one smooth surface as surfels with outward normals (4.1).

    Parameters
    ----------
    cloud : SurfelCloud
        The samples (discontinuity surfels are not allowed in a patch).
    name : str, optional
        Shown by ``str(tree)`` and used by scene files.
    transform : array_like (4, 4), optional
        Rigid or similarity transform applied to ``cloud`` (dynamic CSG: a patch moves between
        frames without resampling, see :meth:`moved`).

    Example
    -------
    >>> p = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=1.0, spacing=0.25, name="wall")
    >>> len(p.world_cloud()), p.world_cloud().normals[0].tolist()
    (16, [1.0, 0.0, 0.0])
    """

    cloud: SurfelCloud
    name: str | None = None
    transform: Any = None

    def __post_init__(self) -> None:
        if not isinstance(self.cloud, SurfelCloud):
            raise InputError(f"cloud: expected a SurfelCloud, got {type(self.cloud).__name__}")
        label = f"patch {self.name!r}" if self.name else "cloud"
        if len(self.cloud) == 0:
            raise InputError(f"{label}: expected a non-empty SurfelCloud, got 0 surfels")
        if (self.cloud.surfel_kinds() != 0).any():
            raise InputError(f"{label}: expected surface samples only, got discontinuity surfels")
        if self.name is not None and not isinstance(self.name, str):
            raise InputError(f"name: expected a string, got {type(self.name).__name__}")
        if self.transform is not None:
            m = as_array(self.transform, "transform", (4, 4))
            object.__setattr__(self, "transform", m)

    def __str__(self) -> str:
        return self.name or f"patch{id(self) % 10000}"

    def world_cloud(self) -> SurfelCloud:
        """The surfels with :attr:`transform` applied."""
        return self.cloud if self.transform is None else self.cloud.transformed(self.transform)

    def moved(self, matrix: Any) -> Patch:
        """This patch with ``matrix`` (4,4) applied after its current transform."""
        m = as_array(matrix, "matrix", (4, 4))
        total = m if self.transform is None else m @ self.transform
        return Patch(self.cloud, self.name, total)

    @classmethod
    def halfspace(cls, point: Any, normal: Any, extent: float, spacing: float, color: Any = None,
                  name: str | None = None) -> Patch:
        """A half-space bounded by a square of surfels (4.3).

        Parameters
        ----------
        point : (3,) a point of the bounding plane, centre of the square.
        normal : (3,) outward normal (the half-space is ``(x - point) . normal <= 0``).
        extent : float
            Edge length of the square.
        spacing : float
            Sample spacing; ``spacing >= extent`` gives one surfel covering the square.
        color : (3,), optional
        """
        p = as_array(point, "point", (3,))
        n = as_array(normal, "normal", (3,))
        ln = float(np.linalg.norm(n))
        if not ln > 1e-12:
            raise InputError("normal: expected a non-zero vector, got length 0")
        n = n / ln
        ext = positive_scalar(extent, "extent")
        h = positive_scalar(spacing, "spacing")
        k = max(1, int(np.ceil(ext / h - 1e-9)))
        step = ext / k
        helper = np.eye(3)[int(np.argmin(np.abs(n)))]
        t1 = np.cross(n, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        g = (np.arange(k) + 0.5) * step - 0.5 * ext
        u, v = np.meshgrid(g, g, indexing="ij")
        pos = p + u.reshape(-1, 1) * t1 + v.reshape(-1, 1) * t2
        radius = step * np.sqrt(0.5) * 1.05  # the cell's circumradius (+5 %): no holes
        colors = None if color is None else np.broadcast_to(as_array(color, "color", (3,)), pos.shape)
        cloud = SurfelCloud(pos, np.broadcast_to(n, pos.shape), radii=np.full(len(pos), radius), colors=colors)
        return cls(cloud, name)

    @classmethod
    def from_shape(cls, shape: Any, spacing: float, color: Any = None, name: str | None = None) -> Patch:
        """A built-in shape of :mod:`unmesh.shapes` sampled at ``spacing``."""
        if not callable(getattr(shape, "surfels", None)):
            raise InputError(f"shape: expected a shape of unmesh.shapes, got {type(shape).__name__}")
        return cls(shape.surfels(spacing, color=color), name)

    @classmethod
    def load(cls, path: str | Path, name: str | None = None) -> Patch:
        """A surfel PLY file, used as is."""
        from unmesh.io import load

        cloud = load(path)
        if not isinstance(cloud, SurfelCloud):
            raise InputError(f"path: expected a surfel PLY, got {type(cloud).__name__} from {path}")
        return cls(cloud, name or Path(path).stem)


@dataclass(frozen=True, eq=False)
class Complement(Node):
    """``~child``: the outside of ``child`` (4.3)."""

    child: Node

    def __post_init__(self) -> None:
        _node(self.child, "child")

    def __str__(self) -> str:
        return f"~{self.child}"


@dataclass(frozen=True, eq=False)
class Binary(Node):
    """Base of the binary nodes :class:`Union` and :class:`Intersection`: two operands and the
    operator symbol ``SYMBOL`` of ``str(node)``."""

    left: Node
    right: Node

    SYMBOL: ClassVar[str] = "?"

    def __post_init__(self) -> None:
        _node(self.left, "left")
        _node(self.right, "right")

    def __str__(self) -> str:
        return f"({self.left} {self.SYMBOL} {self.right})"


@dataclass(frozen=True, eq=False)
class Union(Binary):
    """``left | right`` (4.2, 4.7)."""

    SYMBOL: ClassVar[str] = "|"


@dataclass(frozen=True, eq=False)
class Intersection(Binary):
    """``left & right`` (4.1, 4.8)."""

    SYMBOL: ClassVar[str] = "&"


def normalize(tree: Node, invert: bool = False) -> Node:
    """Push complements to the leaves (4.3): only :class:`Union`, :class:`Intersection`,
    :class:`Patch` and ``Complement(Patch)`` remain."""
    tree = _node(tree, "tree")
    if isinstance(tree, Patch):
        return Complement(tree) if invert else tree
    if isinstance(tree, Complement):
        return normalize(tree.child, not invert)
    if not isinstance(tree, Union | Intersection):
        raise InputError(f"tree: unknown node {type(tree).__name__}")
    op = {Union: Intersection, Intersection: Union}[type(tree)] if invert else type(tree)
    return op(normalize(tree.left, invert), normalize(tree.right, invert))


def patches(tree: Node) -> list[Patch]:
    """The distinct patches of ``tree`` in left-to-right order."""
    out: list[Patch] = []
    seen: set[int] = set()
    stack = [_node(tree, "tree")]
    while stack:
        t = stack.pop()
        if isinstance(t, Patch):
            if id(t) not in seen:
                seen.add(id(t))
                out.append(t)
        elif isinstance(t, Complement):
            stack.append(t.child)
        elif isinstance(t, Binary):
            stack.extend((t.right, t.left))
    return out


@dataclass(frozen=True, eq=False)
class FlatTree:
    """A normalised tree numbered in post order (the arrays the kernels read).

    Attributes
    ----------
    op : (K,) int8
        :data:`INTERSECTION`, :data:`UNION` or :data:`LEAF`.
    parent : (K,) int32
        Parent node, -1 at the root (the last node).
    first : (K,) int32
        First node of the sub-tree of each node (the sub-tree is ``first[k] .. k``).
    invert : (K,) int8
        1 at complemented leaves.
    leaves : list of Patch
        ``leaves[j]`` is the patch of the j-th leaf; ``leaf_node[j]`` its node.
    leaf_node : (L,) int32
    """

    op: np.ndarray
    parent: np.ndarray
    first: np.ndarray
    invert: np.ndarray
    leaves: list[Patch] = field(default_factory=list)
    leaf_node: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

    def __len__(self) -> int:
        return len(self.op)

    def table(self) -> np.ndarray:
        """(K, 4) int32 rows ``(op, parent, first, invert)``:
        the ``tree`` argument of :class:`unmesh.render.ClipTree`."""
        return np.ascontiguousarray(np.stack([self.op, self.parent, self.first, self.invert], axis=1), dtype=np.int32)


def flatten(tree: Node) -> FlatTree:
    """Normalise ``tree`` and number it in post order (see :class:`FlatTree`).

    A patch used at several leaves appears once per leaf (each leaf is its own surface).
    """
    norm = normalize(tree)
    op: list[int] = []
    parent: list[int] = []
    first: list[int] = []
    invert: list[int] = []
    leaves: list[Patch] = []
    leaf_node: list[int] = []

    def visit(t: Node) -> int:
        if isinstance(t, Patch | Complement):
            k = len(op)
            patch = t.child if isinstance(t, Complement) else t
            op.append(LEAF)
            parent.append(-1)
            first.append(k)
            invert.append(1 if isinstance(t, Complement) else 0)
            leaves.append(patch)  # type: ignore[arg-type]
            leaf_node.append(k)
            return k
        start = len(op)
        a = visit(t.left)  # type: ignore[attr-defined]
        b = visit(t.right)  # type: ignore[attr-defined]
        k = len(op)
        op.append(UNION if isinstance(t, Union) else INTERSECTION)
        parent.append(-1)
        first.append(start)
        invert.append(0)
        parent[a] = k
        parent[b] = k
        return k

    visit(norm)
    return FlatTree(np.asarray(op, np.int8), np.asarray(parent, np.int32), np.asarray(first, np.int32),
                    np.asarray(invert, np.int8), leaves, np.asarray(leaf_node, np.int32))
