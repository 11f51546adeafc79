"""Element lists to the CSR face arrays of a :class:`~unmesh.fem.mesh.PolyMesh` (ch. 9).

Elements come as lists of faces (node cycles, counter-clockwise seen from outside the
element). A face shared by two elements appears in both with reversed orientation; it is
stored once, and the second element references it with sign ``-1``.

:func:`parse_cells` takes nested lists and checks every face with a message naming the
element and face; :func:`parse_face_stream` does the same for flat arrays (a VTK polyhedron
face stream) with numpy in O(F log F) and returns ``None`` when anything is irregular, so the
caller can rebuild the lists and let :func:`parse_cells` name the problem.

Example
-------
>>> faces = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]
>>> fn, fo, ef, es, eo = parse_cells([faces], 4)
>>> fo.tolist(), es.tolist()
([0, 3, 6, 9, 12], [1, 1, 1, 1])
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh.errors import InputError

__all__ = ["parse_cells", "parse_face_stream"]


def parse_cells(cells: Any, n_nodes: int) -> tuple[np.ndarray, ...]:
    """Nested lists of elements -> CSR arrays, identifying shared faces by their node sets.

    Parameters
    ----------
    cells : list of list of list of int
        Element ``e`` is a list of at least 4 faces, each a cycle of at least 3 node indices.
    n_nodes : int

    Returns
    -------
    face_nodes, face_offsets, elem_faces, elem_signs, elem_offsets : (K,), (F+1,), (U,), (U,), (E+1,) int64

    Raises
    ------
    InputError
        Naming the element and face: a short face, a node out of range, a face shared by more
        than two elements or twice with the same orientation.

    Example
    -------
    >>> parse_cells([[[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]], 4)[2].tolist()
    [0, 1, 2, 3]
    """
    if not isinstance(cells, list | tuple):
        raise InputError(f"cells: expected a list of elements (lists of faces), got {type(cells).__name__}")
    seen: dict[tuple[int, ...], tuple[int, list[int]]] = {}
    face_nodes: list[int] = []
    face_offsets = [0]
    elem_faces: list[int] = []
    elem_signs: list[int] = []
    elem_offsets = [0]
    uses: list[int] = []
    for e, cell in enumerate(cells):
        if not isinstance(cell, list | tuple) or len(cell) < 4:
            raise InputError(f"cells[{e}]: expected a list of at least 4 faces, got {cell!r}")
        for k, face in enumerate(cell):
            try:
                cyc = [int(v) for v in face]
            except (TypeError, ValueError):
                raise InputError(f"cells[{e}][{k}]: expected a list of node indices, got {face!r}") from None
            if len(cyc) < 3:
                raise InputError(f"element {e}: face {k} has {len(cyc)} nodes, expected at least 3")
            bad = [v for v in cyc if not 0 <= v < n_nodes]
            if bad:
                raise InputError(f"element {e}: face {k} refers to node {bad[0]}, expected indices in [0, {n_nodes})")
            key = tuple(sorted(cyc))
            hit = seen.get(key)
            if hit is None:
                fid = len(face_offsets) - 1
                seen[key] = (fid, cyc)
                face_nodes.extend(cyc)
                face_offsets.append(len(face_nodes))
                uses.append(1)
                elem_faces.append(fid)
                elem_signs.append(1)
                continue
            fid, ref = hit
            uses[fid] += 1
            if uses[fid] > 2:
                raise InputError(f"element {e}: face {k} {cyc} is shared by more than two elements")
            i = ref.index(cyc[0])
            rot = ref[i:] + ref[:i]
            rev = [rot[0], *rot[:0:-1]]
            if cyc == rev:
                sign = -1
            elif cyc == rot:
                raise InputError(f"element {e}: face {k} {cyc} has the same orientation as in the element sharing "
                                 "it; faces must be counter-clockwise seen from outside each element")
            else:
                raise InputError(f"element {e}: face {k} {cyc} has the nodes of another face in a different cyclic order")
            elem_faces.append(fid)
            elem_signs.append(sign)
        elem_offsets.append(len(elem_faces))
    i64 = np.int64
    return (np.array(face_nodes, i64), np.array(face_offsets, i64), np.array(elem_faces, i64),
            np.array(elem_signs, i64), np.array(elem_offsets, i64))


def parse_face_stream(nodes: np.ndarray, face_offsets: np.ndarray, cell_offsets: np.ndarray,
                      n_nodes: int) -> tuple[np.ndarray, ...] | None:
    """The CSR arrays of :func:`parse_cells` from flat arrays, vectorised.

    Parameters
    ----------
    nodes : (K,) int64
        The faces' node cycles, one after the other, elements in order.
    face_offsets : (F+1,) int64
        Face ``f`` is ``nodes[face_offsets[f]:face_offsets[f + 1]]``.
    cell_offsets : (E+1,) int64
        Element ``e`` has faces ``cell_offsets[e]`` to ``cell_offsets[e + 1] - 1``.
    n_nodes : int

    Returns
    -------
    tuple of int64 arrays or None
        Exactly what :func:`parse_cells` returns for the same elements, or ``None`` when an
        element has fewer than 4 faces, a face fewer than 3 nodes or a repeated node, a node is
        out of range, or a face is shared by more than two elements or not in reverse order.

    Example
    -------
    >>> fo = np.array([0, 3, 6, 9, 12]); co = np.array([0, 4])
    >>> parse_face_stream(np.array([0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2]), fo, co, 4)[0].tolist()
    [0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2]
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    fo = np.asarray(face_offsets, dtype=np.int64)
    co = np.asarray(cell_offsets, dtype=np.int64)
    n_faces = len(fo) - 1
    length = np.diff(fo)
    if n_faces == 0 or np.any(np.diff(co) < 4) or length.min() < 3:
        return None
    if nodes.min() < 0 or nodes.max() >= n_nodes:
        return None
    width = int(length.max())
    row = np.repeat(np.arange(n_faces), length)
    col = np.arange(len(nodes)) - fo[row]
    pad = np.full((n_faces, width), n_nodes, dtype=np.int64)
    pad[row, col] = nodes
    key = np.sort(pad, axis=1)
    if np.any((key[:, 1:] == key[:, :-1]) & (key[:, 1:] < n_nodes)):
        return None
    order = np.lexsort(key.T[::-1])
    ordered = key[order]
    new_group = np.concatenate([[True], np.any(ordered[1:] != ordered[:-1], axis=1)])
    inv = np.empty(n_faces, dtype=np.int64)
    inv[order] = np.cumsum(new_group) - 1
    count = np.bincount(inv)
    if count.max() > 2:
        return None
    first = np.full(len(count), n_faces, dtype=np.int64)
    np.minimum.at(first, inv, np.arange(n_faces))
    fid = np.empty(len(count), dtype=np.int64)
    fid[np.argsort(first)] = np.arange(len(count))
    elem_faces = fid[inv]
    owner = first[inv]
    second = np.flatnonzero(owner != np.arange(n_faces))
    # both uses rotated to start at their smallest node; the second must be the first reversed
    j = np.arange(width)
    start = np.argmin(pad, axis=1)
    def rotated(rows: np.ndarray, step: int) -> np.ndarray:
        n = length[rows, None]
        idx = (start[rows, None] + step * j) % n
        return np.where(j < n, pad[rows[:, None], idx], n_nodes)
    if np.any(rotated(second, -1) != rotated(owner[second], 1)):
        return None
    signs = np.ones(n_faces, dtype=np.int64)
    signs[second] = -1
    kept = np.flatnonzero(owner == np.arange(n_faces))
    kept_len = length[kept]
    out_off = np.concatenate([[0], np.cumsum(kept_len)])
    out_nodes = nodes[np.repeat(fo[kept], kept_len) + np.arange(out_off[-1]) - np.repeat(out_off[:-1], kept_len)]
    return out_nodes, out_off.astype(np.int64), elem_faces, signs, co.copy()
