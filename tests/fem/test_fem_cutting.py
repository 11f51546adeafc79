"""Plane splits (9.3.1), progressive polygon cuts (9.3.2) and sliver removal (9.2)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.fem import (
    PolyMesh,
    cut_by_plane,
    cut_by_polygon,
    find_slivers,
    hex_grid,
    remove_slivers,
    split_element,
    tet_mesh,
    voronoi_foam,
)
from unmesh.fem._meshcheck import convexity_violation
from unmesh.fem.cutting import CutMissWarning, PlaneCut, PolygonCut, apply_cuts
from unmesh.fem.events import RandomSplits


def _valid(mesh: PolyMesh, volume: float, tol: float = 0.08) -> None:
    assert mesh.volume() == pytest.approx(volume, abs=1e-9)
    assert np.all(mesh.volumes() > 0)
    assert convexity_violation(mesh)[0].max() <= tol
    mesh.check()  # closed, oriented, convex within its tolerance
    assert len(mesh.surface().boundary_edges()) == 0


@pytest.mark.parametrize("seed", range(4))
def test_plane_cuts_conserve_volume_and_convexity(seed):
    rng = np.random.default_rng(seed)
    mesh = voronoi_foam(15, seed=seed) if seed % 2 else hex_grid((3, 2, 2))
    for _ in range(5):
        mesh = cut_by_plane(mesh, rng.random(3), rng.normal(size=3))
        _valid(mesh, 1.0)


def test_plane_split_creates_t_junctions_in_untouched_neighbours():
    m = hex_grid((2, 1, 1), size=(2, 1, 1))
    c = split_element(m, 0, (0.5, 0.37, 0.5), (0, 1, 0))
    assert c.n_elements == 3
    off, nodes = c.element_nodes()
    right = next(e for e in range(3) if c.points[nodes[off[e]:off[e + 1]], 0].min() > 0.9)
    assert off[right + 1] - off[right] == 10  # 8 corners + 2 t-junction nodes on the shared face
    _valid(c, 2.0, tol=1e-12)
    # the neighbour's shared face is split into two coplanar faces matching the halves exactly, and
    # its two faces containing the cut edges get the t-junction nodes
    assert sorted(len(f) for f in c.cells[right]) == [4, 4, 4, 4, 4, 5, 5]


def test_snapping_avoids_needles():
    m = hex_grid((2, 2, 2))
    with pytest.warns(CutMissWarning, match="misses"):  # snapped onto the grid plane: no element crosses it
        c = cut_by_plane(m, (0.5, 0.5005, 0.5), (0, 1, 0), snap=0.02)  # 0.1 % of an edge off a grid plane
    assert c.n_nodes == m.n_nodes and c.n_elements == m.n_elements  # snapped to the nodes: nothing split
    c2 = cut_by_plane(m, (0.5, 0.5005, 0.5), (0, 1, 0.3), snap=0.02)
    e = c2.edges()
    ln = np.linalg.norm(c2.points[e[:, 0]] - c2.points[e[:, 1]], axis=1)
    assert ln.min() > 0.02 * 0.5 * 0.99


def test_new_nodes_interpolate_linear_fields_exactly():
    m = voronoi_foam(8, seed=2)
    A = np.array([[0.1, 0.2, -0.3], [0.0, 0.5, 0.1], [0.2, -0.1, 0.4]])
    u = m.points @ A.T
    r = apply_cuts(m, [PlaneCut((0.4, 0.5, 0.6), (1.0, 2.0, 0.5))])
    np.testing.assert_allclose(r.node_weights @ u, r.mesh.points @ A.T, atol=1e-12)
    assert r.changed.sum() < r.mesh.n_elements  # not everything is re-integrated
    assert np.all(r.element_parent < m.n_elements)


def test_polygon_cut_separates_inside_and_keeps_connection_outside():
    m = hex_grid((2, 2, 2))
    half = np.array([[-1, 0.5, -1], [2, 0.5, -1], [2, 0.5, 0.5], [-1, 0.5, 0.5]])
    c = cut_by_polygon(m, half)
    assert c.n_nodes == 27 + 3  # the three grid nodes on z = 0 of the mid plane are duplicated
    _valid(c, 1.0, tol=1e-12)
    # the cut faces are now boundary faces: the surface gained the two sides of the crack
    area = c.surface().area()
    assert area == pytest.approx(6.0 + 2 * 0.5, abs=1e-12)
    # a full cut splits the mesh into two parts
    full = cut_by_polygon(m, np.array([[-1, 0.5, -1], [2, 0.5, -1], [2, 0.5, 2], [-1, 0.5, 2]]))
    from unmesh.fem.assembly import _components

    used = np.unique(full.element_nodes()[1])
    assert len(np.unique(_components(full)[used])) == 2


def test_progressive_cut_off_grid_and_pocket():
    m = hex_grid((2, 2, 2))
    quad = np.array([[-1, 0.37, -1], [2, 0.37, -1], [2, 0.37, 0.63], [-1, 0.37, 0.63]])
    c = cut_by_polygon(m, quad)
    _valid(c, 1.0)
    tri = np.array([[0.2, 0.33, 0.2], [0.4, 0.33, 0.2], [0.3, 0.33, 0.35]])  # inside one element: a pocket
    p = cut_by_polygon(m, tri)
    _valid(p, 1.0)
    assert p.surface().area() > 6.0  # the pocket opened: two new interior boundary sides
    assert p.surface().area() == pytest.approx(6.0 + 2 * 0.5 * 0.2 * 0.15, abs=1e-9)


def test_non_planar_cut_as_polygon_sequence():
    m = hex_grid((3, 3, 3))
    a = np.array([[-0.1, 0.6, -0.1], [1.1, 0.6, -0.1], [1.1, 0.5, 0.5], [-0.1, 0.5, 0.5]])
    b = np.array([[-0.1, 0.5, 0.5], [1.1, 0.5, 0.5], [1.1, 0.6, 1.1], [-0.1, 0.6, 1.1]])
    r = apply_cuts(m, [PolygonCut(a), PolygonCut(b)])
    _valid(r.mesh, 1.0)
    from unmesh.fem.assembly import _components

    used = np.unique(r.mesh.element_nodes()[1])
    assert len(np.unique(_components(r.mesh)[used])) == 2  # the two polygons together cut it through


def test_bad_cuts():
    m = hex_grid((2, 2, 2))
    with pytest.warns(CutMissWarning):
        out = cut_by_plane(m, (5, 5, 5), (0, 1, 0))
    assert out.n_elements == m.n_elements
    with pytest.warns(CutMissWarning):
        cut_by_polygon(m, np.array([[5, 5, 5], [6, 5, 5], [6, 5, 6]]))
    with pytest.raises(InputError, match="degenerate"):
        cut_by_polygon(m, np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2]]))
    with pytest.raises(InputError, match="coplanar"):
        cut_by_polygon(m, np.array([[0, 0.5, 0], [1, 0.5, 0], [1, 0.7, 1], [0, 0.5, 1]]))
    with pytest.raises(InputError, match="convex"):
        cut_by_polygon(m, np.array([[0, 0.5, 0], [1, 0.5, 0], [0.5, 0.5, 0.2], [0.5, 0.5, 1]]))
    with pytest.raises(InputError, match="normal"):
        cut_by_plane(m, (0, 0, 0), (0, 0, 0))


def test_random_planes_cube_like_figure_9_4():
    from unmesh.fem.cutting import Cutter

    c = Cutter(hex_grid((1, 1, 1)))
    RandomSplits(30, seed=4).apply(c)
    mesh = c.commit().mesh
    assert mesh.n_elements == 31
    _valid(mesh, 1.0)
    n = np.diff(mesh.element_nodes()[0])
    assert n.min() >= 4 and n.max() > 20  # irregular elements with many nodes (thesis: 8 to 32)


def test_tet_sliver_removal_creates_one_node():
    d = 0.02
    pts = np.array([[0, 0, d], [1, 0, -d], [1, 1, d], [0, 1, -d],
                    [0.7, 0.3, 0.8], [0.3, 0.7, 0.8], [0.7, 0.3, -0.8], [0.3, 0.7, -0.8]], float)
    m = tet_mesh(pts, [[0, 1, 2, 3], [0, 1, 2, 4], [0, 2, 3, 5], [0, 1, 3, 6], [1, 2, 3, 7]])
    assert find_slivers(m, 0.1).tolist() == [0]
    r = remove_slivers(m, 0.1)
    assert r.n_elements == 4 and r.n_nodes == m.n_nodes + 1
    assert np.diff(r.element_nodes()[0]).tolist() == [5, 5, 5, 5]
    r.check()


def test_slab_sliver_removal_keeps_volume():
    m = cut_by_plane(hex_grid((1, 1, 2), size=(1, 1, 2)), (0, 0, 1.004), (0, 0, 1), snap=0.0)
    assert find_slivers(m, 0.05).tolist() == [1]
    r = remove_slivers(m, 0.05)
    assert r.n_elements == 2
    assert r.volume() == pytest.approx(2.0, abs=1e-12)
