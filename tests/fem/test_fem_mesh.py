"""PolyMesh structure, validation, builders and face triangulation."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.fem import PolyMesh, convex_polyhedron, hex_grid, tet_mesh, voronoi_foam
from unmesh.fem import _kernels as K
from unmesh.fem._meshcheck import convexity_violation

CUBE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
CUBE_FACES = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]


def test_cells_round_trip_and_volume():
    m = PolyMesh(CUBE, [CUBE_FACES])
    assert m.cells == [CUBE_FACES]
    assert m.volume() == pytest.approx(1.0, abs=1e-14)
    assert m.n_nodes == 8 and m.n_elements == 1 and m.n_faces == 6


def test_shared_faces_are_stored_once():
    m = hex_grid((3, 2, 1))
    assert m.n_faces == 3 * 2 * 1 * 6 - (2 * 2 * 1 + 3 * 1 * 1 + 0)  # 6 per cell minus shared
    use = m.face_use()
    assert set(np.unique(use)) == {1, 2}
    again = PolyMesh(m.points, m.cells)
    assert again.n_faces == m.n_faces
    np.testing.assert_allclose(again.volumes(), m.volumes())


@pytest.mark.parametrize(("faces", "message"), [
    (CUBE_FACES[:5], "not closed"),
    ([CUBE_FACES[0][::-1], *CUBE_FACES[1:]], "orientation"),
    ([f[::-1] for f in CUBE_FACES], "inverted"),
])
def test_bad_elements_are_named(faces, message):
    with pytest.raises(InputError, match=rf"element 0: (.*{message}|is not closed)"):
        PolyMesh(CUBE, [faces])


def test_non_convex_element_is_rejected():
    pts = np.array(CUBE, float)
    pts[6] = [0.6, 0.6, 0.4]  # push a corner inside: faces become non-planar / element non-convex
    with pytest.raises(InputError, match=r"element 0: (is not convex|has a non-planar face)"):
        PolyMesh(pts, [CUBE_FACES])


def test_non_convex_face_is_rejected():
    # an L-shaped prism as one element
    L = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    pts = np.r_[np.c_[L, np.zeros(6)], np.c_[L, np.ones(6)]]
    bottom = [5, 4, 3, 2, 1, 0]
    top = [6, 7, 8, 9, 10, 11]
    sides = [[i, (i + 1) % 6, (i + 1) % 6 + 6, i + 6] for i in range(6)]
    with pytest.raises(InputError, match="element 0"):
        PolyMesh(pts, [[bottom, top, *sides]])


def test_face_shared_by_three_and_same_orientation():
    m = hex_grid((2, 1, 1))
    cells = m.cells
    shared = next(f for f in cells[0] if sorted(f) in [sorted(g) for g in cells[1]])
    with pytest.raises(InputError, match="same orientation"):
        PolyMesh(m.points, [cells[0], [shared if sorted(f) == sorted(shared) else f for f in cells[1]]])
    with pytest.raises(InputError, match="more than two"):
        PolyMesh(m.points, [cells[0], cells[1], cells[1]])


def test_builders_volumes():
    assert hex_grid((2, 3, 4), size=(2, 3, 4)).volume() == pytest.approx(24.0)
    foam = voronoi_foam(25, size=(1, 2, 1), seed=5)
    assert foam.n_elements == 25
    assert foam.volume() == pytest.approx(2.0, abs=1e-9)
    assert foam.element_nodes()[0][-1] > 4 * 25
    hull = convex_polyhedron(np.random.default_rng(0).normal(size=(40, 3)))
    assert hull.n_elements == 1
    from scipy.spatial import ConvexHull

    assert hull.volume() == pytest.approx(ConvexHull(hull.points).volume, rel=1e-12)


def test_tet_mesh_flips_negative_tets():
    m = tet_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], [[0, 2, 1, 3], [1, 2, 3, 4]])
    assert np.all(m.volumes() > 0)


def test_tetrahedralize_closed_surface():
    from unmesh.fem import tetrahedralize
    from unmesh.shapes import Sphere

    surf = Sphere(radius=1.0).mesh(0.35)
    m = tetrahedralize(surf)
    assert m.volume() == pytest.approx(abs(surf.volume()), rel=1e-9)
    assert np.all(m.element_is_tet())


def _reference_triangulation(pts: np.ndarray, ring: list[int], tol: float = 1e-9) -> list[tuple[int, int, int]]:
    """Plain Python reference of the greedy ear clipping in the triangulation kernel."""
    n = len(ring)
    nrm = np.zeros(3)
    for k in range(n):
        a, b = pts[ring[k]], pts[ring[(k + 1) % n]]
        nrm += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]), (a[0] - b[0]) * (a[1] + b[1])])
    nrm /= np.linalg.norm(nrm)

    def score(a, b, c):
        u, v, w = pts[b] - pts[a], pts[c] - pts[a], pts[c] - pts[b]
        return np.cross(u, v) @ nrm / (u @ u + v @ v + w @ w)

    ring = list(ring)
    out = []
    while len(ring) > 3:
        m = len(ring)
        strict = [score(ring[k - 1], ring[k], ring[(k + 1) % m]) > tol for k in range(m)]
        best, best_s = -1, -1.0
        for k in range(m):
            if not strict[k]:
                continue
            a, b, c = ring[k - 1], ring[k], ring[(k + 1) % m]
            sc = score(a, b, c)
            sa = score(ring[(k - 2) % m], a, c)
            sb = score(a, c, ring[(k + 2) % m])
            count = sum(strict) - 1 - strict[(k - 1) % m] - strict[(k + 1) % m] + (sa > tol) + (sb > tol)
            if count < 3:
                continue
            if m == 4:
                sc = min(sc, score(a, c, ring[(k + 2) % m]))
            if sc > best_s:
                best, best_s = k, sc
        best = max(best, 0)
        out.append((ring[best - 1], ring[best], ring[(best + 1) % m]))
        ring.pop(best)
    out.append(tuple(ring))
    return out


def test_triangulation_kernel_matches_reference_and_avoids_t_junction_slivers(rng):
    # a square with collinear (t-junction) nodes on every side
    pts = np.array([[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [1, 0.3, 0], [1, 1, 0], [0.4, 1, 0], [0, 1, 0], [0, 0.5, 0]], float)
    ring = list(range(8))
    tris = K.triangulate_faces(pts, np.array(ring), np.array([0, 8]), 1e-9)
    assert [tuple(t) for t in tris.tolist()] == _reference_triangulation(pts, ring)
    area = np.linalg.norm(np.cross(pts[tris[:, 1]] - pts[tris[:, 0]], pts[tris[:, 2]] - pts[tris[:, 0]]), axis=1) / 2
    assert area.min() > 0.05 and area.sum() == pytest.approx(1.0)
    # a triangle with midpoints on all sides: four proper triangles
    tri = np.array([[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [0.5, 0.5, 0], [0, 1, 0], [0, 0.5, 0]], float)
    t2 = K.triangulate_faces(tri, np.arange(6), np.array([0, 6]), 1e-9)
    a2 = np.linalg.norm(np.cross(tri[t2[:, 1]] - tri[t2[:, 0]], tri[t2[:, 2]] - tri[t2[:, 0]]), axis=1) / 2
    assert a2.min() == pytest.approx(0.125)
    # random convex polygons
    for _ in range(20):
        k = int(rng.integers(3, 12))
        ang = np.sort(rng.random(k)) * 2 * np.pi
        poly = np.c_[np.cos(ang), np.sin(ang), np.zeros(k)]
        t = K.triangulate_faces(poly, np.arange(k), np.array([0, k]), 1e-9)
        ref = np.array(_reference_triangulation(poly, list(range(k))))
        # same greedy choices up to ties: same worst triangle, same total area, all positive
        for tt in (t, ref):
            a = np.cross(poly[tt[:, 1]] - poly[tt[:, 0]], poly[tt[:, 2]] - poly[tt[:, 0]])[:, 2] / 2
            assert a.min() > 0
        amin = [np.cross(poly[x[:, 1]] - poly[x[:, 0]], poly[x[:, 2]] - poly[x[:, 0]])[:, 2].min() for x in (t, ref)]
        assert amin[0] == pytest.approx(amin[1], rel=1e-9)


def test_convexity_kernel_matches_numpy():
    m = voronoi_foam(8, seed=3)
    worst, _kind, _face = convexity_violation(m)
    cells = m.cells
    diam = m.diameters()
    ref = np.zeros(m.n_elements)
    for e, cell in enumerate(cells):
        nodes = sorted({v for f in cell for v in f})
        for f in cell:
            p = m.points[f]
            n = np.zeros(3)
            for i in range(len(f)):
                a, b = p[i], p[(i + 1) % len(f)]
                n += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]), (a[0] - b[0]) * (a[1] + b[1])])
            n /= np.linalg.norm(n)
            d = (m.points[nodes] - p.mean(axis=0)) @ n / diam[e]
            ref[e] = max(ref[e], d.max(), np.abs((p - p.mean(axis=0)) @ n).max() / diam[e])
    np.testing.assert_allclose(worst, ref, atol=1e-15)


def test_element_volume_kernel_matches_numpy():
    m = voronoi_foam(6, seed=1)
    off, tris = m.element_triangles()
    c = m.element_centers()
    e = np.repeat(np.arange(m.n_elements), np.diff(off))
    p = m.points
    ref = np.einsum("ij,ij->i", p[tris[:, 0]] - c[e], np.cross(p[tris[:, 1]] - c[e], p[tris[:, 2]] - c[e])) / 6
    np.testing.assert_allclose(K.element_tri_volumes(p, off, tris, c), ref, rtol=1e-13, atol=1e-16)


def test_surface_is_closed_and_outward():
    m = voronoi_foam(10, seed=2)
    s = m.surface()
    assert len(s.boundary_edges()) == 0
    assert s.volume() == pytest.approx(1.0, abs=1e-9)


def test_element_node_triangle_and_bound_kernels_match_the_numpy_references():
    from unmesh.fem.cutting import PlaneCut, apply_cuts

    for mesh in (voronoi_foam(12, seed=3), hex_grid((3, 2, 2))):
        cut = apply_cuts(mesh, [PlaneCut((0.41, 0.5, 0.5), (1.0, 0.2, 0.1))]).mesh
        for m in (mesh, cut):
            off, nodes = K.element_node_sets(m.elem_offsets, m.elem_faces, m.face_offsets, m.face_nodes, m.n_nodes)
            ref_off, ref_nodes = m._elem_nodes_reference()
            np.testing.assert_array_equal(off, ref_off)
            np.testing.assert_array_equal(nodes, ref_nodes)
            toff, tris = m.element_triangles()
            ref_toff, ref_tris = m._elem_tris_reference()
            np.testing.assert_array_equal(toff, ref_toff)
            np.testing.assert_array_equal(tris, ref_tris)
            some = np.array([m.n_elements - 1, 0, 2])
            soff, stris = m.triangles_of(some)
            np.testing.assert_array_equal(np.diff(soff), np.diff(toff)[some])
            np.testing.assert_array_equal(stris, np.concatenate([tris[toff[e]:toff[e + 1]] for e in some]))
            lo, hi = m.element_bounds()
            p = m.points[nodes]
            np.testing.assert_array_equal(lo, np.minimum.reduceat(p, off[:-1], axis=0))
            np.testing.assert_array_equal(hi, np.maximum.reduceat(p, off[:-1], axis=0))


def test_node_face_and_repeated_node_kernels_match_numpy_references():
    for m in (voronoi_foam(12, seed=6), hex_grid((2, 3, 2))):
        off, faces = K.node_faces(m.face_offsets, m.face_nodes, m.n_nodes)
        order = np.argsort(m.face_nodes, kind="stable")
        ref_faces = np.repeat(np.arange(m.n_faces), np.diff(m.face_offsets))[order]
        ref_off = np.searchsorted(m.face_nodes[order], np.arange(m.n_nodes + 1))
        np.testing.assert_array_equal(off, ref_off)
        np.testing.assert_array_equal(faces, ref_faces)
        assert K.repeated_face_node(m.face_offsets, m.face_nodes) == (-1, -1)
        fn = m.face_nodes.copy()
        f = 3
        fn[m.face_offsets[f] + 2] = fn[m.face_offsets[f]]
        assert K.repeated_face_node(m.face_offsets, fn) == (f, fn[m.face_offsets[f]])
