"""Numba kernels of the polyhedral mesh: face triangulation and element geometry.

Every kernel takes only arrays and scalars and has a numpy reference in
:mod:`unmesh.fem.mesh` or the tests.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh._csr_kernels import counting_sort_csr, csr_rows


@njit(cache=True)
def _newell(points, nodes, start, stop):
    nx = 0.0
    ny = 0.0
    nz = 0.0
    for k in range(start, stop):
        a = nodes[k]
        b = nodes[start + (k - start + 1) % (stop - start)]
        nx += (points[a, 1] - points[b, 1]) * (points[a, 2] + points[b, 2])
        ny += (points[a, 2] - points[b, 2]) * (points[a, 0] + points[b, 0])
        nz += (points[a, 0] - points[b, 0]) * (points[a, 1] + points[b, 1])
    return nx, ny, nz


@njit(cache=True)
def _ear_score(points, a, b, c, nx, ny, nz):
    """Signed quality of triangle (a, b, c) w.r.t. the face normal: 2A·n / Σ|e|²."""
    ux = points[b, 0] - points[a, 0]
    uy = points[b, 1] - points[a, 1]
    uz = points[b, 2] - points[a, 2]
    vx = points[c, 0] - points[a, 0]
    vy = points[c, 1] - points[a, 1]
    vz = points[c, 2] - points[a, 2]
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    wx = points[c, 0] - points[b, 0]
    wy = points[c, 1] - points[b, 1]
    wz = points[c, 2] - points[b, 2]
    s = ux * ux + uy * uy + uz * uz + vx * vx + vy * vy + vz * vz + wx * wx + wy * wy + wz * wz
    if s <= 0.0:
        return 0.0
    return (cx * nx + cy * ny + cz * nz) / s


@njit(cache=True, parallel=True)
def triangulate_faces(points, face_nodes, face_offsets, tol):
    """Triangulate convex (possibly t-junctioned) polygons by greedy ear clipping.

    Ears are clipped at strictly convex corners only (score > ``tol``), best
    quality first, never leaving a degenerate remainder, so collinear
    (t-junction) vertices never produce zero-area triangles. Triangle ``t`` of
    face ``f`` is row ``face_offsets[f] - 2 f + t``; orientation follows the face.
    """
    nf = face_offsets.shape[0] - 1
    ntri = face_offsets[nf] - 2 * nf
    tris = np.empty((ntri, 3), dtype=np.int64)
    for f in prange(nf):
        start = face_offsets[f]
        stop = face_offsets[f + 1]
        n = stop - start
        out = start - 2 * f
        nx, ny, nz = _newell(points, face_nodes, start, stop)
        nn = np.sqrt(nx * nx + ny * ny + nz * nz)
        if nn > 0.0:
            nx /= nn
            ny /= nn
            nz /= nn
        ring = np.empty(n, dtype=np.int64)
        for k in range(n):
            ring[k] = face_nodes[start + k]
        m = n
        t = 0
        strict = np.empty(n, dtype=np.bool_)
        while m > 3:
            nstrict = 0
            for k in range(m):
                strict[k] = _ear_score(points, ring[(k - 1) % m], ring[k], ring[(k + 1) % m], nx, ny, nz) > tol
                if strict[k]:
                    nstrict += 1
            best = -1
            best_score = -1.0
            for k in range(m):
                if not strict[k]:
                    continue
                a = ring[(k - 1) % m]
                b = ring[k]
                c = ring[(k + 1) % m]
                sc = _ear_score(points, a, b, c, nx, ny, nz)
                # the remainder must keep three strict corners (else it is degenerate)
                sa = _ear_score(points, ring[(k - 2) % m], a, c, nx, ny, nz)
                sb = _ear_score(points, a, c, ring[(k + 2) % m], nx, ny, nz)
                count = nstrict - 1 - int(strict[(k - 1) % m]) - int(strict[(k + 1) % m])
                count += int(sa > tol) + int(sb > tol)
                if count < 3:
                    continue
                if m == 4:
                    sc = min(sc, _ear_score(points, a, c, ring[(k + 2) % m], nx, ny, nz))
                if sc > best_score:
                    best_score = sc
                    best = k
            if best < 0:
                best = 0  # fully degenerate polygon: fall back to a fan (zero-area triangles)
            tris[out + t, 0] = ring[(best - 1) % m]
            tris[out + t, 1] = ring[best]
            tris[out + t, 2] = ring[(best + 1) % m]
            t += 1
            for k in range(best, m - 1):
                ring[k] = ring[k + 1]
            m -= 1
        tris[out + t, 0] = ring[0]
        tris[out + t, 1] = ring[1]
        tris[out + t, 2] = ring[2]
    return tris


@njit(cache=True, parallel=True)
def element_tri_volumes(points, elem_tri_ptr, elem_tris, centers):
    """Signed volume of the tetrahedron (triangle, element centre) per element triangle (9.17–9.18)."""
    ne = elem_tri_ptr.shape[0] - 1
    out = np.empty(elem_tris.shape[0])
    for e in prange(ne):
        cx = centers[e, 0]
        cy = centers[e, 1]
        cz = centers[e, 2]
        for t in range(elem_tri_ptr[e], elem_tri_ptr[e + 1]):
            a = elem_tris[t, 0]
            b = elem_tris[t, 1]
            c = elem_tris[t, 2]
            ax = points[a, 0] - cx
            ay = points[a, 1] - cy
            az = points[a, 2] - cz
            bx = points[b, 0] - cx
            by = points[b, 1] - cy
            bz = points[b, 2] - cz
            qx = points[c, 0] - cx
            qy = points[c, 1] - cy
            qz = points[c, 2] - cz
            out[t] = (ax * (by * qz - bz * qy) + ay * (bz * qx - bx * qz) + az * (bx * qy - by * qx)) / 6.0
    return out


@njit(cache=True)
def gather_rows(offsets, data, idx, new_offsets, out):
    """``out[new_offsets[i]:new_offsets[i+1]] = data[offsets[idx[i]]:offsets[idx[i]+1]]``.

    ``data`` and ``out`` are 2-D (rows, width) views; the numpy reference is
    :func:`unmesh.fem.integration.gather_csr` with ``fast=False``.
    """
    for i in range(idx.shape[0]):
        a = offsets[idx[i]]
        o = new_offsets[i]
        for r in range(offsets[idx[i] + 1] - a):
            for c in range(data.shape[1]):
                out[o + r, c] = data[a + r, c]


@njit(cache=True)
def element_node_sets(elem_offsets, elem_faces, face_offsets, face_nodes, n_nodes):
    """CSR ``(offsets, nodes)`` of each element's distinct nodes, ascending.

    One marker array, no global sort (the mesh is rebuilt after every cut). The numpy
    reference is :meth:`unmesh.fem.mesh.PolyMesh.element_nodes` with a global unique.
    """
    ne = elem_offsets.shape[0] - 1
    mark = np.full(n_nodes, -1, np.int64)
    offsets = np.zeros(ne + 1, np.int64)
    for e in range(ne):
        c = 0
        for k in range(elem_offsets[e], elem_offsets[e + 1]):
            f = elem_faces[k]
            for q in range(face_offsets[f], face_offsets[f + 1]):
                v = face_nodes[q]
                if mark[v] != e:
                    mark[v] = e
                    c += 1
        offsets[e + 1] = offsets[e] + c
    nodes = np.empty(offsets[ne], np.int64)
    mark[:] = -1
    for e in range(ne):
        p = offsets[e]
        for k in range(elem_offsets[e], elem_offsets[e + 1]):
            f = elem_faces[k]
            for q in range(face_offsets[f], face_offsets[f + 1]):
                v = face_nodes[q]
                if mark[v] != e:
                    mark[v] = e
                    nodes[p] = v
                    p += 1
        # insertion sort (a few nodes per element)
        for i in range(offsets[e] + 1, p):
            x = nodes[i]
            j = i - 1
            while j >= offsets[e] and nodes[j] > x:
                nodes[j + 1] = nodes[j]
                j -= 1
            nodes[j + 1] = x
    return offsets, nodes


@njit(cache=True)
def node_faces(face_offsets, face_nodes, n_nodes):
    """CSR ``(offsets (n+1,), faces)`` of the faces containing each node, ascending
    (:func:`unmesh._csr_kernels.counting_sort_csr` of the face node lists).

    The numpy reference is a stable argsort of ``face_nodes`` (in the tests).
    """
    order, off = counting_sort_csr(face_nodes, n_nodes)
    return off, csr_rows(face_offsets)[order]


@njit(cache=True)
def repeated_face_node(face_offsets, face_nodes):
    """First face (and the node) listing a node twice, or (-1, -1).

    The numpy reference is the lexsort in :func:`unmesh.fem._meshcheck.check_structure`.
    """
    for f in range(face_offsets.shape[0] - 1):
        for a in range(face_offsets[f], face_offsets[f + 1]):
            for b in range(a + 1, face_offsets[f + 1]):
                if face_nodes[a] == face_nodes[b]:
                    return f, face_nodes[a]
    return -1, -1


@njit(cache=True, parallel=True)
def element_triangles(elem_offsets, elem_faces, elem_signs, tri_offsets, tris, elements):
    """Outward triangles of the listed elements: CSR ``(offsets (k+1,), tris (T,3))``, global node ids.

    Element ``elements[i]`` gets the triangles of its faces in face order, reversed where
    its face sign is -1. The numpy reference is :meth:`unmesh.fem.mesh.PolyMesh._elem_tris_reference`.
    """
    k = elements.shape[0]
    counts = np.zeros(k, np.int64)
    for i in prange(k):
        e = elements[i]
        c = 0
        for j in range(elem_offsets[e], elem_offsets[e + 1]):
            f = elem_faces[j]
            c += tri_offsets[f + 1] - tri_offsets[f]
        counts[i] = c
    offsets = np.zeros(k + 1, np.int64)
    for i in range(k):
        offsets[i + 1] = offsets[i] + counts[i]
    out = np.empty((offsets[k], 3), np.int64)
    for i in prange(k):
        e = elements[i]
        p = offsets[i]
        for j in range(elem_offsets[e], elem_offsets[e + 1]):
            f = elem_faces[j]
            flip = elem_signs[j] < 0
            for t in range(tri_offsets[f], tri_offsets[f + 1]):
                out[p, 0] = tris[t, 2] if flip else tris[t, 0]
                out[p, 1] = tris[t, 1]
                out[p, 2] = tris[t, 0] if flip else tris[t, 2]
                p += 1
    return offsets, out


@njit(cache=True, parallel=True)
def element_bounds(points, node_off, nodes):
    """Bounding boxes ``(lo (E,3), hi (E,3))`` of the elements' nodes (numpy reference: ``minimum.reduceat``)."""
    ne = node_off.shape[0] - 1
    lo = np.empty((ne, 3))
    hi = np.empty((ne, 3))
    for e in prange(ne):
        for d in range(3):
            a = np.inf
            b = -np.inf
            for k in range(node_off[e], node_off[e + 1]):
                v = points[nodes[k], d]
                a = min(a, v)
                b = max(b, v)
            lo[e, d] = a
            hi[e, d] = b
    return lo, hi
