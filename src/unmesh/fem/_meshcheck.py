"""Validation of :class:`unmesh.fem.PolyMesh`: structure, closedness, orientation, convexity.

Every failure raises :class:`unmesh.errors.InputError` naming the element (and face).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from unmesh.errors import InputError
from unmesh.fem._kernels import repeated_face_node

__all__ = ["check_geometry", "check_structure", "convexity_violation"]


def check_structure(mesh: Any) -> None:
    """Cheap checks on the CSR arrays (offsets, index ranges, face sizes and sharing)."""
    n = mesh.n_nodes
    fo, fn, eo, ef, es = mesh.face_offsets, mesh.face_nodes, mesh.elem_offsets, mesh.elem_faces, mesh.elem_signs
    for name, off, total in (("face_offsets", fo, len(fn)), ("elem_offsets", eo, len(ef))):
        if len(off) < 1 or off[0] != 0 or off[-1] != total or np.any(np.diff(off) < 0):
            raise InputError(f"{name}: expected non-decreasing offsets from 0 to {total}")
    if len(es) != len(ef):
        raise InputError(f"elem_signs: expected {len(ef)} entries like elem_faces, got {len(es)}")
    if fn.size and (fn.min() < 0 or fn.max() >= n):
        bad = int(np.flatnonzero((fn < 0) | (fn >= n))[0])
        face = int(np.searchsorted(fo, bad, side="right") - 1)
        raise InputError(f"face {face}: node index {int(fn[bad])} out of range [0, {n})")
    if ef.size and (ef.min() < 0 or ef.max() >= len(fo) - 1):
        e = int(np.searchsorted(eo, int(np.flatnonzero((ef < 0) | (ef >= len(fo) - 1))[0]), side="right") - 1)
        raise InputError(f"element {e}: face index out of range [0, {len(fo) - 1})")
    if not np.all(np.abs(es) == 1):
        e = int(np.searchsorted(eo, int(np.flatnonzero(np.abs(es) != 1)[0]), side="right") - 1)
        raise InputError(f"element {e}: face signs must be +1 or -1")
    sizes = np.diff(fo)
    if np.any(sizes < 3):
        raise InputError(f"face {int(np.flatnonzero(sizes < 3)[0])}: has fewer than 3 nodes")
    counts = np.diff(eo)
    if np.any(counts < 4):
        raise InputError(f"element {int(np.flatnonzero(counts < 4)[0])}: has {int(counts.min())} faces, expected at least 4")
    # repeated nodes inside a face
    f, v = repeated_face_node(fo, fn)
    if f >= 0:
        raise InputError(f"face {int(f)}: node {int(v)} appears twice")
    use = np.bincount(ef, minlength=len(fo) - 1)
    if np.any(use == 0):
        raise InputError(f"face {int(np.flatnonzero(use == 0)[0])}: is not used by any element")
    if np.any(use > 2):
        f = int(np.flatnonzero(use > 2)[0])
        raise InputError(f"face {f}: is shared by {int(use[f])} elements, at most 2 allowed")
    ssum = np.bincount(ef, weights=es, minlength=len(fo) - 1)
    bad = (use == 2) & (ssum != 0)
    if bad.any():
        f = int(np.flatnonzero(bad)[0])
        elems = np.searchsorted(eo, np.flatnonzero(ef == f), side="right") - 1
        raise InputError(f"elements {elems.tolist()}: share face {f} with the same orientation (inconsistent orientation)")


def _half_edges(mesh: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    fo, fn = mesh.face_offsets, mesh.face_nodes
    nxt = np.arange(len(fn)) + 1
    nxt[fo[1:] - 1] = fo[:-1]
    sizes = np.diff(fo)[mesh.elem_faces]
    eid = np.repeat(np.repeat(np.arange(mesh.n_elements), np.diff(mesh.elem_offsets)), sizes)
    start = np.repeat(fo[mesh.elem_faces] - np.cumsum(np.r_[0, sizes[:-1]]), sizes) + np.arange(sizes.sum())
    a = fn[start]
    b = fn[nxt[start]]
    flip = np.repeat(mesh.elem_signs, sizes) < 0
    a, b = np.where(flip, b, a), np.where(flip, a, b)
    return eid, a, b


def check_geometry(mesh: Any, tolerance: float | None = None) -> None:
    """Closedness, orientation, positive volume and convexity of every element."""
    tol = mesh.tolerance if tolerance is None else tolerance
    if mesh.n_elements == 0:
        return
    eid, a, b = _half_edges(mesh)
    n1 = np.int64(mesh.n_nodes + 1)
    key = (eid * n1 + np.minimum(a, b)) * n1 + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    k = key[order]
    fwd = (a < b)[order]
    start = np.r_[True, k[1:] != k[:-1]]
    grp = np.cumsum(start) - 1
    cnt = np.bincount(grp)
    nf = np.bincount(grp, weights=fwd)
    bad = (cnt != 2) | (nf != 1)
    if bad.any():
        g = int(np.flatnonzero(bad)[0])
        i = order[np.flatnonzero(grp == g)[0]]
        e, u, v = int(eid[i]), int(min(a[i], b[i])), int(max(a[i], b[i]))
        if cnt[g] == 1:
            raise InputError(f"element {e}: is not closed: edge ({u}, {v}) belongs to only one of its faces")
        if cnt[g] == 2:
            raise InputError(f"element {e}: inconsistent face orientation at edge ({u}, {v}); faces must be "
                             "counter-clockwise seen from outside")
        raise InputError(f"element {e}: edge ({u}, {v}) is used by {int(cnt[g])} of its faces (not a closed manifold)")
    vols = mesh.volumes()
    diam = mesh.diameters()
    bad = ~(vols > 1e-12 * diam**3)
    if bad.any():
        e = int(np.flatnonzero(bad)[0])
        raise InputError(f"element {e}: is inverted or flat (volume {vols[e]:.3g}); faces must be counter-clockwise "
                         "seen from outside")
    worst, kind, face = convexity_violation(mesh)
    bad = (worst > tol) & (worst * diam > mesh.abs_tolerance)
    if bad.any():
        e = int(np.flatnonzero(bad)[0])
        what = ("is not convex: a node lies outside the plane of face", "has a non-planar face",
                "has a non-convex face")[int(kind[e])]
        f = int(mesh.elem_faces[mesh.elem_offsets[e] + face[e]])
        raise InputError(f"element {e}: {what} {f} (violation {worst[e]:.3g} of its size, tolerance {tol:.3g})")


def convexity_violation(mesh: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Worst relative convexity violation per element.

    Returns
    -------
    worst : (E,) float64
        Largest of: node distance outside a face plane, face non-planarity, and
        reflex turn in a face, each divided by the element diameter.
    kind : (E,) int64
        0 outside a face plane, 1 non-planar face, 2 non-convex face.
    face : (E,) int64
        Local face index of the worst violation.
    """
    off, nodes = mesh.element_nodes()
    return _convexity(mesh.points, mesh.face_nodes, mesh.face_offsets, mesh.elem_faces, mesh.elem_signs,
                      mesh.elem_offsets, off, nodes)


@njit(cache=True)
def _convexity_element(e, points, face_nodes, face_offsets, elem_faces, elem_signs, elem_offsets, node_off, nodes,
                       worst, kind, wface):
    """Worst convexity violation of element ``e`` (body of :func:`_convexity`)."""
    worst[e] = 0.0
    kind[e] = 0
    wface[e] = 0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for k in range(node_off[e], node_off[e + 1]):
        for d in range(3):
            lo[d] = min(lo[d], points[nodes[k], d])
            hi[d] = max(hi[d], points[nodes[k], d])
    diam = np.sqrt(((hi - lo) ** 2).sum())
    if diam <= 0.0:
        worst[e] = np.inf
        return
    for j in range(elem_offsets[e], elem_offsets[e + 1]):
        f = elem_faces[j]
        s = elem_signs[j]
        a0 = face_offsets[f]
        a1 = face_offsets[f + 1]
        m = a1 - a0
        nx = 0.0
        ny = 0.0
        nz = 0.0
        cx = 0.0
        cy = 0.0
        cz = 0.0
        for k in range(a0, a1):
            p = face_nodes[k]
            q = face_nodes[a0 + (k - a0 + 1) % m]
            nx += (points[p, 1] - points[q, 1]) * (points[p, 2] + points[q, 2])
            ny += (points[p, 2] - points[q, 2]) * (points[p, 0] + points[q, 0])
            nz += (points[p, 0] - points[q, 0]) * (points[p, 1] + points[q, 1])
            cx += points[p, 0]
            cy += points[p, 1]
            cz += points[p, 2]
        nn = np.sqrt(nx * nx + ny * ny + nz * nz)
        if nn <= 0.0:
            worst[e] = np.inf
            kind[e] = 1
            wface[e] = j - elem_offsets[e]
            continue
        nx *= s / nn
        ny *= s / nn
        nz *= s / nn
        cx /= m
        cy /= m
        cz /= m
        for k in range(node_off[e], node_off[e + 1]):
            p = nodes[k]
            d = ((points[p, 0] - cx) * nx + (points[p, 1] - cy) * ny + (points[p, 2] - cz) * nz) / diam
            if d > worst[e]:
                worst[e] = d
                kind[e] = 0
                wface[e] = j - elem_offsets[e]
        for k in range(a0, a1):
            p = face_nodes[k]
            d = abs((points[p, 0] - cx) * nx + (points[p, 1] - cy) * ny + (points[p, 2] - cz) * nz) / diam
            if d > worst[e]:
                worst[e] = d
                kind[e] = 1
                wface[e] = j - elem_offsets[e]
            # turn at p: (p - prev) x (next - p) . n must be >= 0
            pr = face_nodes[a0 + (k - a0 - 1) % m]
            nx2 = face_nodes[a0 + (k - a0 + 1) % m]
            ux = points[p, 0] - points[pr, 0]
            uy = points[p, 1] - points[pr, 1]
            uz = points[p, 2] - points[pr, 2]
            vx = points[nx2, 0] - points[p, 0]
            vy = points[nx2, 1] - points[p, 1]
            vz = points[nx2, 2] - points[p, 2]
            t = ((uy * vz - uz * vy) * nx + (uz * vx - ux * vz) * ny + (ux * vy - uy * vx) * nz) * s
            lu = np.sqrt(ux * ux + uy * uy + uz * uz)
            lv = np.sqrt(vx * vx + vy * vy + vz * vz)
            if lu > 0.0 and lv > 0.0:
                # distance of p from the chord prev-next, relative to the element size
                dd = -t / max(lu, lv) / diam
                if dd > worst[e]:
                    worst[e] = dd
                    kind[e] = 2
                    wface[e] = j - elem_offsets[e]


@njit(cache=True, parallel=True)
def _convexity(points, face_nodes, face_offsets, elem_faces, elem_signs, elem_offsets, node_off, nodes):
    ne = elem_offsets.shape[0] - 1
    # a thin prange loop over a serial body (no parfors; the body is typed once)
    worst = np.empty(ne)
    kind = np.empty(ne, dtype=np.int64)
    wface = np.empty(ne, dtype=np.int64)
    for e in prange(ne):
        _convexity_element(np.int64(e), points, face_nodes, face_offsets, elem_faces, elem_signs, elem_offsets,
                           node_off, nodes, worst, kind, wface)
    return worst, kind, wface
