"""CSG scene files (``docs/csg_scene.md``): patches and a tree expression.

::

    [patches.top]
    file = "top.ply"                     # a surfel PLY, used as is (path relative to the scene file)
    [patches.ball]
    shape = { type = "sphere", radius = 0.6, center = [0.5, 0.5, 0.5] }
    spacing = 0.02                       # sampling of a built-in shape
    color = [0.8, 0.2, 0.2]              # optional: overrides the patch colour
    [patches.floor]
    halfspace = { point = [0, 0, 0], normal = [0, -1, 0], extent = 2.0 }
    spacing = 0.05
    [csg]
    tree = "(top & floor) - ball"        # patch names, | & - ~ with Python's precedence, parentheses

Optional per patch: ``translate``, ``rotate`` (degrees about x, y, z, about the patch's
centroid) placing it; ``move`` (per frame) and ``spin`` (degrees per frame) animate it
(dynamic CSG, with ``[animation] frames = N, fps = F``). Every error is a
:class:`~unmesh.errors.SceneError` naming the file and the key.

Example
-------
>>> import tempfile, pathlib
>>> f = pathlib.Path(tempfile.mkdtemp()) / "s.toml"
>>> _ = f.write_text('''
... [patches.a]
... halfspace = { point = [0, 0, 0], normal = [0, 0, 1], extent = 2.0 }
... spacing = 0.5
... [patches.b]
... shape = { type = "sphere", radius = 0.5 }
... spacing = 0.2
... [csg]
... tree = "a - ~~b"
... ''')
>>> str(load(f).model)
'(a & ~~~b)'
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.csg.model import Node, Patch
from unmesh.errors import SceneError
from unmesh.scene import load_scene
from unmesh.scene.shapes import placement_matrix
from unmesh.scene.table import Table

__all__ = ["CSGScene", "load", "parse_tree"]

_TOKEN = re.compile(r"\s*(?:([A-Za-z_][A-Za-z0-9_]*)|(.))")


def parse_tree(text: str, names: dict[str, Node], where: str = "tree") -> Node:
    """Parse a tree expression: names, ``| & - ~`` with Python's precedence (``~`` binds
    tightest, then ``-``, then ``&``, then ``|``), and parentheses.

    Raises ``ValueError`` with the 1-based column of the problem.

    Example
    -------
    >>> from unmesh import SurfelCloud
    >>> p = {k: Patch(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]), k) for k in "abc"}
    >>> str(parse_tree("a | b & c - a", p))
    '(a | (b & (c & ~a)))'
    """
    tokens: list[tuple[str, str, int]] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            break
        if m.group(1):
            tokens.append(("name", m.group(1), m.start(1) + 1))
        elif m.group(2):
            ch = m.group(2)
            if ch not in "|&-~()":
                raise ValueError(f"unexpected character {ch!r} at column {m.start(2) + 1}")
            tokens.append(("op", ch, m.start(2) + 1))
        pos = m.end()
    tokens.append(("end", "", len(text) + 1))
    i = 0

    def peek() -> tuple[str, str, int]:
        return tokens[i]

    def take() -> tuple[str, str, int]:
        nonlocal i
        i += 1
        return tokens[i - 1]

    def binary(sub: Any, op: str) -> Node:
        left = sub()
        while peek() == ("op", op, peek()[2]):
            take()
            right = sub()
            left = left | right if op == "|" else left & right if op == "&" else left - right
        return left

    def unary() -> Node:
        kind, val, col = take()
        if kind == "op" and val == "~":
            return ~unary()
        if kind == "op" and val == "(":
            node = expr()
            _, v2, c2 = take()
            if v2 != ")":
                raise ValueError(f"expected ')' at column {c2} (opened at column {col})")
            return node
        if kind == "name":
            if val not in names:
                raise ValueError(f"unknown patch {val!r} at column {col}; defined: {', '.join(sorted(names)) or 'none'}")
            return names[val]
        what = "end of the expression" if kind == "end" else f"{val!r}"
        raise ValueError(f"expected a patch name, '~' or '(' at column {col}, got {what}")

    def expr() -> Node:
        return binary(lambda: binary(lambda: binary(unary, "-"), "&"), "|")

    node = expr()
    kind, val, col = peek()
    if kind != "end":
        raise ValueError(f"unexpected {val!r} at column {col}")
    return node


@dataclass(frozen=True, eq=False)
class CSGScene:
    """A loaded CSG scene: the model, its patches by name, and the animation."""

    model: Node
    patches: dict[str, Patch]
    frames: int = 1
    fps: float = 30.0
    motion: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def at_frame(self, k: int) -> Node:
        """The model at animation frame ``k`` (patches moved by ``k`` times their per-frame
        ``move`` and ``spin``; partners and classes are recomputed when it is drawn)."""
        if not self.motion or k == 0:
            return self.model
        moved = {}
        for name, p in self.patches.items():
            if name in self.motion:
                move, spin = self.motion[name]
                c = p.world_cloud().positions.mean(axis=0)
                m = placement_matrix(c + k * move, k * spin) @ placement_matrix(-c)
                moved[id(p)] = p.moved(m)
        return _substitute(self.model, moved)


def _substitute(node: Node, moved: dict[int, Patch]) -> Node:
    from unmesh.csg.model import Complement, Intersection, Union

    if isinstance(node, Patch):
        return moved.get(id(node), node)
    if isinstance(node, Complement):
        return Complement(_substitute(node.child, moved))
    cls = Union if isinstance(node, Union) else Intersection
    return cls(_substitute(node.left, moved), _substitute(node.right, moved))  # type: ignore[attr-defined]


def _patch(name: str, t: Table) -> tuple[Patch, tuple[np.ndarray, np.ndarray] | None]:
    sources = [k for k in ("file", "shape", "halfspace") if k in t]
    if len(sources) != 1:
        raise t.error(None, f"expected exactly one of file, shape, halfspace, got {', '.join(sources) or 'none'}")
    color = t.vector("color", 3, default=None)
    if color is not None and (color.min() < 0 or color.max() > 1):
        raise t.error("color", f"expected RGB in [0, 1], got {color.tolist()}")
    src = sources[0]
    if src == "file":
        path = t.path("file")
        with t.guard("file"):
            patch = Patch.load(path, name)
        if color is not None:
            patch = Patch(patch.cloud.replace(colors=np.broadcast_to(color, patch.cloud.positions.shape)), name)
    elif src == "shape":
        shape = t.shape("shape")
        spacing = t.number("spacing", positive=True)
        with t.guard("shape"):
            patch = Patch(shape.surfels(spacing, color=color), name)
    else:
        h = t.table("halfspace")
        point = h.vector("point", 3)
        normal = h.vector("normal", 3)
        if not np.linalg.norm(normal) > 0:
            raise h.error("normal", "expected a non-zero vector")
        extent = h.number("extent", positive=True)
        spacing = t.number("spacing", positive=True)
        with h.guard(None):
            patch = Patch.halfspace(point, normal, extent, spacing, color=color, name=name)
    _check_orientation(t, src, patch)
    translate = t.vector("translate", 3, default=(0.0, 0.0, 0.0))
    rotate = t.vector("rotate", 3, default=(0.0, 0.0, 0.0))
    if np.any(translate != 0) or np.any(rotate != 0):
        c = patch.cloud.positions.mean(axis=0)
        patch = patch.moved(placement_matrix(c + translate, rotate) @ placement_matrix(-c))
    move = t.vector("move", 3, default=None)
    spin = t.vector("spin", 3, default=None)
    motion = None
    if move is not None or spin is not None:
        motion = (np.zeros(3) if move is None else move, np.zeros(3) if spin is None else spin)
    return patch, motion


def _check_orientation(t: Table, key: str, patch: Patch) -> None:
    """Closed patches must have outward normals: the mean of ``n . (x - centroid)`` is positive."""
    c = patch.cloud
    if key == "halfspace" or len(c) < 4:
        return
    ext = np.ptp(c.positions, axis=0)
    if np.sort(ext)[0] < 1e-6 * ext.max():  # a flat patch has no inside to check
        return
    d = c.positions - c.positions.mean(axis=0)
    if float(np.mean(np.einsum("ij,ij->i", d, c.normals))) < 0:
        raise t.error(key, "the patch's normals point inwards (expected outward normals; flip them, or use ~name "
                           "in the tree for the complement)")


def load(path: str | Path) -> CSGScene:
    """Load a CSG scene file (see the module notes and ``docs/csg_scene.md``)."""
    root = load_scene(path)
    specs = root.tables("patches", required=True)
    if not specs:
        raise root.error("patches", "expected at least one [patches.NAME] table")
    patches: dict[str, Patch] = {}
    motion: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, t in specs.items():
        patch, mot = _patch(name, t)
        patches[name] = patch
        if mot is not None:
            motion[name] = mot
    csg = root.table("csg")
    text = csg.string("tree")
    try:
        model = parse_tree(text, patches)
    except ValueError as exc:
        raise csg.error("tree", f"{exc} in {text!r}") from None
    frames, fps = 1, 30.0
    anim = root.table("animation", required=False)
    if anim is not None:
        frames = anim.integer("frames", minimum=1)
        fps = anim.number("fps", default=30.0, positive=True)
    elif motion:
        raise SceneError(f"{root.file.name}: patches move (move/spin) but there is no [animation] table with frames")
    root.finish()
    return CSGScene(model, patches, frames, fps, motion)
