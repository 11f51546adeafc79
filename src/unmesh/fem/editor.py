"""A mutable overlay of a :class:`PolyMesh` for topology edits (cutting, sliver removal).

Edits touch a few elements of a possibly large mesh, so the editor reads faces and
elements lazily from the flat arrays and stores only what changed in
dictionaries. :meth:`MeshEditor.commit` builds the new mesh with vectorised
gathers plus the edited parts, and reports how node states and elements map.

Invariants kept by every edit: a face is shared by at most two elements (with
opposite signs), and every node on a face's boundary is one of its vertices (an
edge split inserts the new node into every face containing that edge).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from unmesh.errors import InputError
from unmesh.fem._kernels import node_faces
from unmesh.fem.mesh import PolyMesh

__all__ = ["EditResult", "MeshEditor"]


@dataclass(frozen=True, eq=False)
class EditResult:
    """A new mesh and how it relates to the old one.

    Attributes
    ----------
    mesh : PolyMesh
    node_weights : scipy.sparse.csr_array (n_new, n_old)
        New node state = node_weights @ old node state (edge interpolation, copies).
    element_parent : (E_new,) int64
        Old element each new element comes from.
    changed : (E_new,) bool
        Elements whose faces changed (their integration must be recomputed).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> from unmesh.fem.cutting import PlaneCut, apply_cuts
    >>> r = apply_cuts(hex_grid((1, 1, 1)), [PlaneCut((0.5, 0.5, 0.5), (1, 0, 0))])
    >>> r.node_weights.shape, r.changed.tolist()
    ((12, 8), [True, True])
    """

    mesh: PolyMesh
    node_weights: sp.csr_array
    element_parent: np.ndarray
    changed: np.ndarray


class MeshEditor:
    """Lazy, mutable view of a mesh (see the module docstring).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> ed = MeshEditor(hex_grid((1, 1, 1)))
    >>> m = ed.split_edge(0, 1, 0.5)
    >>> ed.commit().mesh.n_nodes
    9
    """

    def __init__(self, mesh: PolyMesh) -> None:
        self.base = mesh
        self.n_base_nodes = mesh.n_nodes
        self._pts = [mesh.points]
        self._new_pts: list[np.ndarray] = []
        self.n_nodes = mesh.n_nodes
        self.weights: dict[int, dict[int, float]] = {}
        self._faces: dict[int, list[int]] = {}
        self._refs: dict[int, list[tuple[int, int]]] = {}
        self._elems: dict[int, list[tuple[int, int]]] = {}
        self._parent: dict[int, int] = {}
        self.dead_faces: set[int] = set()
        self.dead_elems: set[int] = set()
        self.n_faces = mesh.n_faces
        self.n_elems = mesh.n_elements
        self.changed: set[int] = set()
        self._fe = mesh.face_elements()
        self._nf_off, self._nf_faces = node_faces(mesh.face_offsets, mesh.face_nodes, mesh.n_nodes)
        self._extra: dict[int, set[int]] = {}
        self._edge_cache: dict[tuple[int, int], int] = {}
        self._moved: dict[int, np.ndarray] = {}
        self._scale = mesh.node_scales()
        self.scale_override: dict[int, float] = {}

    # -- nodes ------------------------------------------------------------------------------
    def point(self, v: int) -> np.ndarray:
        """Rest position of node v."""
        moved = self._moved.get(v)
        if moved is not None:
            return moved
        if v < self.n_base_nodes:
            return self.base.points[v]
        return self._new_pts[v - self.n_base_nodes]

    def points_of(self, nodes: list[int]) -> np.ndarray:
        """Rest positions (k,3) of nodes."""
        return np.array([self.point(v) for v in nodes]) if nodes else np.zeros((0, 3))

    def node_weights(self, v: int) -> dict[int, float]:
        """Interpolation weights of node v in terms of the original nodes."""
        return self.weights.get(v, {v: 1.0}) if v >= self.n_base_nodes else {v: 1.0}

    def node_scale(self, v: int) -> float:
        """Snapping length scale of node v (:meth:`PolyMesh.node_scales`; new nodes interpolate it)."""
        got = self.scale_override.get(v)
        if got is not None:
            return got
        if v < self.n_base_nodes:
            return float(self._scale[v])
        return float(sum(w * self._scale[k] for k, w in self.weights[v].items()))

    def add_node(self, x: np.ndarray, weights: dict[int, float]) -> int:
        """Append a node at rest position x with state weights (over original nodes)."""
        v = self.n_nodes
        self.n_nodes += 1
        self._new_pts.append(np.asarray(x, dtype=np.float64).copy())
        self.weights[v] = weights
        return v

    def combine(self, nodes: list[int], coeffs: list[float]) -> dict[int, float]:
        """Weights of Σ c_k node_k."""
        out: dict[int, float] = {}
        for v, c in zip(nodes, coeffs, strict=True):
            if c == 0.0:
                continue
            for k, w in self.node_weights(v).items():
                out[k] = out.get(k, 0.0) + c * w
        return out

    # -- faces & elements ------------------------------------------------------------------
    def face(self, f: int) -> list[int]:
        """Node cycle of face f."""
        got = self._faces.get(f)
        if got is not None:
            return got
        fo = self.base.face_offsets
        return self.base.face_nodes[fo[f]:fo[f + 1]].tolist()

    def refs(self, f: int) -> list[tuple[int, int]]:
        """(element, sign) pairs referencing face f."""
        got = self._refs.get(f)
        if got is not None:
            return got
        out = []
        if self._fe[f, 0] >= 0:
            out.append((int(self._fe[f, 0]), 1))
        if self._fe[f, 1] >= 0:
            out.append((int(self._fe[f, 1]), -1))
        return out

    def elem(self, e: int) -> list[tuple[int, int]]:
        """(face, sign) pairs of element e."""
        got = self._elems.get(e)
        if got is not None:
            return got
        eo = self.base.elem_offsets
        return list(zip(self.base.elem_faces[eo[e]:eo[e + 1]].tolist(), self.base.elem_signs[eo[e]:eo[e + 1]].tolist(),
                        strict=True))

    def oriented(self, f: int, s: int) -> list[int]:
        """Face cycle oriented outward for the element using it with sign s."""
        c = self.face(f)
        return c if s > 0 else [c[0], *c[:0:-1]]

    def elem_nodes(self, e: int) -> list[int]:
        """Sorted unique nodes of element e."""
        return sorted({v for f, _ in self.elem(e) for v in self.face(f)})

    def parent(self, e: int) -> int:
        """Original element that element e descends from."""
        return self._parent.get(e, e)

    def set_face(self, f: int, nodes: list[int]) -> None:
        """Replace the node cycle of face f (marks its elements changed)."""
        for v in nodes:
            self._extra.setdefault(v, set()).add(f)
        self._faces[f] = list(nodes)
        for e, _ in self.refs(f):
            self.changed.add(e)

    def new_face(self, nodes: list[int], refs: list[tuple[int, int]]) -> int:
        """A new face with the given element references (elements are not updated)."""
        f = self.n_faces
        self.n_faces += 1
        self._faces[f] = list(nodes)
        self._refs[f] = list(refs)
        for v in nodes:
            self._extra.setdefault(v, set()).add(f)
        return f

    def set_refs(self, f: int, refs: list[tuple[int, int]]) -> None:
        """Replace the element references of face f."""
        self._refs[f] = list(refs)

    def set_elem(self, e: int, faces: list[tuple[int, int]]) -> None:
        """Replace the faces of element e (marks it changed)."""
        self._elems[e] = list(faces)
        self.changed.add(e)

    def new_elem(self, faces: list[tuple[int, int]], parent: int) -> int:
        """Append an element descending from ``parent``."""
        e = self.n_elems
        self.n_elems += 1
        self._elems[e] = list(faces)
        self._parent[e] = self.parent(parent)
        self.changed.add(e)
        return e

    def kill_face(self, f: int) -> None:
        """Remove face f (callers update the elements)."""
        self.dead_faces.add(f)

    def kill_elem(self, e: int) -> None:
        """Remove element e and drop its references from its faces."""
        for f, _ in self.elem(e):
            self.set_refs(f, [(a, s) for a, s in self.refs(f) if a != e])
        self.dead_elems.add(e)

    def faces_of_node(self, v: int) -> list[int]:
        """Live faces containing node v."""
        cand: set[int] = set()
        if v < self.n_base_nodes:
            cand.update(self._nf_faces[self._nf_off[v]:self._nf_off[v + 1]].tolist())
        cand |= self._extra.get(v, set())
        return [f for f in cand if f not in self.dead_faces and v in self.face(f)]

    def elems_of_node(self, v: int) -> set[int]:
        """Live elements containing node v."""
        return {e for f in self.faces_of_node(v) for e, _ in self.refs(f)}

    def faces_of_edge(self, a: int, b: int) -> list[int]:
        """Live faces having a and b as consecutive vertices."""
        out = []
        for f in self.faces_of_node(a):
            c = self.face(f)
            n = len(c)
            i = c.index(a)
            if c[(i + 1) % n] == b or c[(i - 1) % n] == b:
                out.append(f)
        return out

    # -- primitive edits ------------------------------------------------------------------
    def split_edge(self, a: int, b: int, t: float) -> int:
        """Insert a node at ``(1-t) x_a + t x_b`` into every face containing edge (a, b).

        The same edge split twice in one operation returns the same node.
        """
        key = (a, b) if a < b else (b, a)
        hit = self._edge_cache.get(key)
        if hit is not None:
            return hit
        if key[0] != a:
            a, b, t = b, a, 1.0 - t
        x = (1.0 - t) * self.point(a) + t * self.point(b)
        m = self.add_node(x, self.combine([a, b], [1.0 - t, t]))
        for f in self.faces_of_edge(a, b):
            c = self.face(f)
            n = len(c)
            i = c.index(a)
            if c[(i + 1) % n] == b:
                c2 = [*c[:i + 1], m, *c[i + 1:]]
            else:
                c2 = [*c[:i], m, *c[i:]]
            self.set_face(f, c2)
        self._edge_cache[key] = m
        return m

    def move_node(self, v: int, x: np.ndarray) -> None:
        """Move the rest position of node v (its elements are marked changed)."""
        if v < self.n_base_nodes:
            self._moved[v] = np.asarray(x, dtype=np.float64).copy()
        else:
            self._new_pts[v - self.n_base_nodes] = np.asarray(x, dtype=np.float64).copy()
        for e in self.elems_of_node(v):
            self.changed.add(e)

    def insert_on_edge(self, a: int, b: int, m: int) -> None:
        """Insert existing node m between a and b in every face containing edge (a, b)."""
        for f in self.faces_of_edge(a, b):
            c = self.face(f)
            if m in c:
                continue
            n = len(c)
            i = c.index(a)
            if c[(i + 1) % n] == b:
                c2 = [*c[:i + 1], m, *c[i + 1:]]
            else:
                c2 = [*c[:i], m, *c[i:]]
            self.set_face(f, c2)

    def merge_nodes(self, keep: int, drop: int) -> None:
        """Replace node ``drop`` by ``keep`` everywhere; faces left with < 3 nodes are removed."""
        for f in self.faces_of_node(drop):
            c = [keep if v == drop else v for v in self.face(f)]
            out = [v for i, v in enumerate(c) if v != c[i - 1]] if len(c) > 1 else c
            if len(out) < 3:
                for e, _s in self.refs(f):
                    self.set_elem(e, [(g, t) for g, t in self.elem(e) if g != f])
                self.kill_face(f)
            else:
                self.set_face(f, out)

    def reset_cache(self) -> None:
        """Forget edge splits (call between independent operations)."""
        self._edge_cache.clear()

    def split_face(self, f: int, piece_a: list[int], piece_b: list[int]) -> tuple[int, int]:
        """Replace face f by two pieces (same orientation) in every element using it."""
        refs = self.refs(f)
        self.set_face(f, piece_a)
        g = self.new_face(piece_b, refs)
        for e, s in refs:
            faces = self.elem(e)
            k = faces.index((f, s))
            self.set_elem(e, [*faces[:k + 1], (g, s), *faces[k + 1:]])
        return f, g

    def replace_face(self, f: int, pieces: list[list[int]]) -> list[int]:
        """Replace face f by several coplanar pieces in every element using it."""
        refs = self.refs(f)
        self.set_face(f, pieces[0])
        ids = [f] + [self.new_face(p, refs) for p in pieces[1:]]
        for e, s in refs:
            faces = self.elem(e)
            k = faces.index((f, s))
            self.set_elem(e, [*faces[:k], *[(g, s) for g in ids], *faces[k + 1:]])
        return ids

    # -- commit --------------------------------------------------------------------------------
    def commit(self, *, tolerance: float | None = None, abs_tolerance: float | None = None,
               check: bool = True) -> EditResult:
        """Build the edited mesh (unused nodes dropped, order kept) and the maps."""
        base = self.base
        tol = base.tolerance if tolerance is None else tolerance
        atol = base.abs_tolerance if abs_tolerance is None else abs_tolerance
        nf_base = base.n_faces
        touched_f = np.zeros(nf_base, bool)
        for f in list(self._faces) + list(self.dead_faces):
            if f < nf_base:
                touched_f[f] = True
        keep_f = np.flatnonzero(~touched_f)
        new_f = [f for f in self._faces if f not in self.dead_faces]
        fmap = np.full(self.n_faces, -1, np.int64)
        fmap[keep_f] = np.arange(len(keep_f))
        fmap[new_f] = len(keep_f) + np.arange(len(new_f))
        sizes = np.diff(base.face_offsets)[keep_f]
        idx = np.repeat(base.face_offsets[keep_f] - (np.cumsum(sizes) - sizes), sizes) + np.arange(sizes.sum())
        fn = [base.face_nodes[idx]] + [np.asarray(self._faces[f], np.int64) for f in new_f]
        fsz = np.r_[sizes, [len(self._faces[f]) for f in new_f]].astype(np.int64)
        face_nodes = np.concatenate(fn).astype(np.int64)
        face_offsets = np.r_[0, np.cumsum(fsz)].astype(np.int64)
        # elements: base order (edited in place, dead removed), new ones appended
        ne_base = base.n_elements
        edited = np.zeros(ne_base, bool)
        for e in self._elems:
            if e < ne_base:
                edited[e] = True
        dead = np.zeros(self.n_elems, bool)
        for e in self.dead_elems:
            dead[e] = True
        elem_ids = np.r_[np.flatnonzero(~dead[:ne_base]), [e for e in range(ne_base, self.n_elems) if not dead[e]]]
        elem_ids = elem_ids.astype(np.int64)
        eo = base.elem_offsets
        base_counts = np.diff(eo)
        counts = base_counts[np.minimum(elem_ids, ne_base - 1)] if ne_base else np.zeros(len(elem_ids), np.int64)
        for k in np.flatnonzero((elem_ids >= ne_base) | edited[np.minimum(elem_ids, ne_base - 1)]):
            counts[k] = len(self._elems[int(elem_ids[k])])
        ef = np.empty(counts.sum(), np.int64)
        es = np.empty(counts.sum(), np.int64)
        off = np.r_[0, np.cumsum(counts)].astype(np.int64)
        plain = np.flatnonzero((elem_ids < ne_base) & ~edited[np.minimum(elem_ids, ne_base - 1)])
        pe = elem_ids[plain]
        pc = base_counts[pe]
        within = np.arange(pc.sum()) - np.repeat(np.cumsum(pc) - pc, pc)
        dst = np.repeat(off[plain], pc) + within
        src = np.repeat(eo[pe], pc) + within
        ef[dst] = fmap[base.elem_faces[src]]
        es[dst] = base.elem_signs[src]
        for k in np.flatnonzero((elem_ids >= ne_base) | edited[np.minimum(elem_ids, ne_base - 1)]):
            faces = self._elems[int(elem_ids[k])]
            ef[off[k]:off[k + 1]] = [fmap[f] for f, _ in faces]
            es[off[k]:off[k + 1]] = [s for _, s in faces]
        if np.any(ef < 0):
            raise InputError("internal error: an element refers to a removed face")
        # nodes: drop unused ones, keep order
        allp = np.concatenate([base.points, np.array(self._new_pts).reshape(-1, 3)])
        for v, x in self._moved.items():
            allp[v] = x
        used = np.zeros(self.n_nodes, bool)
        used[face_nodes] = True
        nmap = np.cumsum(used) - 1
        points = allp[used]
        face_nodes = nmap[face_nodes]
        # node weights (new x old)
        rows, cols, vals = [], [], []
        kept_base = np.flatnonzero(used[:self.n_base_nodes])
        rows.append(nmap[kept_base])
        cols.append(kept_base)
        vals.append(np.ones(len(kept_base)))
        for v in range(self.n_base_nodes, self.n_nodes):
            if used[v]:
                w = self.weights[v]
                rows.append(np.full(len(w), nmap[v]))
                cols.append(np.fromiter(w.keys(), np.int64, len(w)))
                vals.append(np.fromiter(w.values(), np.float64, len(w)))
        W = sp.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(len(points), self.n_base_nodes))
        scale = W @ self._scale
        for v, h in self.scale_override.items():
            if used[v]:
                scale[nmap[v]] = h
        mesh = PolyMesh.from_arrays(points, face_nodes, face_offsets, ef, es, off, tolerance=tol, abs_tolerance=atol,
                                    check=False, node_scale=scale)
        pos = np.full(self.n_elems, -1, np.int64)
        pos[elem_ids] = np.arange(len(elem_ids))
        parent = elem_ids.copy()
        for e, p in self._parent.items():
            if pos[e] >= 0:
                parent[pos[e]] = p
        changed = np.zeros(len(elem_ids), bool)
        ch = np.fromiter(self.changed, np.int64, len(self.changed))
        ch = ch[pos[ch] >= 0] if len(ch) else ch
        changed[pos[ch]] = True
        # elements whose node set changed are all in `changed`; compaction keeps node order.
        # Unchanged elements keep their (validated) geometry, moved nodes mark theirs changed:
        # only the changed elements need the geometric checks.
        if check:
            mesh.check(elements=np.flatnonzero(changed))
        return EditResult(mesh, W, parent, changed)
