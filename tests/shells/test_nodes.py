"""Node selection, neighbourhoods, umbrella pairs and fiber creation (7.2, 7.4)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shells.conftest import grid_cloud
from unmesh.errors import InputError
from unmesh.shells.nodes import create_fibers, grid_sheet, node_neighborhoods, select_nodes, umbrella_pairs


def test_most_opposite_neighbour_on_a_regular_grid():
    """(7.4) on a square grid with the 8 nearest neighbours: 4 straight fibers per interior node."""
    x, topo = grid_sheet(7, 7, neighbors=8)
    centre = 3 * 7 + 3
    f = topo.fibers[topo.fiber_offsets[centre]:topo.fiber_offsets[centre + 1]]
    assert len(f) == 4
    d = x[f[:, 2]] - x[f[:, 0]]
    np.testing.assert_allclose(np.abs(np.cross(x[f[:, 1]] - x[f[:, 0]], d)), 0.0, atol=1e-12)   # straight
    directions = {tuple(np.round(v / np.linalg.norm(v), 6)) for v in np.abs(d)}
    assert len(directions) == 3   # horizontal, vertical, and the two diagonals (same |direction|)
    # duplicates removed: every (min, centre, max) triple once
    assert len(np.unique(topo.fibers, axis=0)) == len(topo.fibers)
    assert np.all(topo.fibers[:, 0] < topo.fibers[:, 2])


def test_heuristic_formula_7_4():
    """j' = argmin (x_j' - x_j).(x_j - x_i): the farthest neighbour on the opposite side."""
    x = np.array([[0.0, 0, 0], [1, 0, 0], [-1, 0.3, 0], [-1.5, -0.2, 0], [0, 1, 0]])
    fib = create_fibers(x, [0, 4], [1, 2, 3, 4], nodes=[0], min_angle=90.0, max_end_angle=90.0)
    assert [1, 0, 3] in fib.tolist()


@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_fiber_partner_kernel_matches_numpy(jitter):
    """The kernel's most-opposite partners give the fibers of the numpy reference, entry for entry
    (regular grids have exact ties in the argmin; subsets of centres as in a crack rebuild)."""
    x, topo = grid_sheet(9, 8, jitter=jitter, seed=3)
    x = x + np.array([0.0, 0.0, 0.05]) * np.sin(x[:, :1] * 1.3)
    for min_angle in (30.0, 60.0, 90.0):
        a = create_fibers(x, topo.neighbor_offsets, topo.neighbors, min_angle)
        b = create_fibers(x, topo.neighbor_offsets, topo.neighbors, min_angle, reference=True)
        np.testing.assert_array_equal(a, b)
    rows = np.array([3, 10, 11, 40, 71])
    off, nbr = node_neighborhoods(x, 12, nodes=rows)
    np.testing.assert_array_equal(create_fibers(x, off, nbr, nodes=rows),
                                  create_fibers(x, off, nbr, nodes=rows, reference=True))


def test_open_boundary_gets_no_folded_fibers():
    x, topo = grid_sheet(6, 6)
    f = topo.fibers
    a, b = x[f[:, 0]] - x[f[:, 1]], x[f[:, 2]] - x[f[:, 1]]
    cos = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    assert cos.max() <= np.cos(np.radians(120)) + 1e-9
    assert np.all(np.diff(topo.fiber_incidence_offsets) > 0)   # every node lies on a fiber


def test_umbrella_pairs_are_counter_clockwise():
    x, topo = grid_sheet(5, 5)
    pr, pc = topo.pairs, topo.pair_center
    c = np.cross(x[pr[:, 0]] - x[pc], x[pr[:, 1]] - x[pc])
    assert np.all(c[:, 2] > 0)
    interior = 2 * 5 + 2
    # closed fan over the 8 distinct directions of the 12 neighbours (collinear ones share an angle)
    assert np.diff(topo.pair_offsets)[interior] == 8


def test_neighborhoods_are_nearest_first_and_respect_blocking():
    x = np.array([[i * 1.0, 0, 0] for i in range(6)])
    off, nbr = node_neighborhoods(x, k=2)
    assert nbr[off[2]:off[3]].tolist() == [1, 3]
    off, nbr = node_neighborhoods(x, k=2, blocked=lambda p, q: (p[:, 0] < 2.5) != (q[:, 0] < 2.5))
    assert nbr[off[2]:off[3]].tolist() == [1, 0]
    with pytest.raises(InputError, match="neighbors"):
        node_neighborhoods(x, k=1)


def test_select_nodes_uses_clustering():
    cloud = grid_cloud(40, 40, 0.025)
    idx = select_nodes(cloud, 100)
    assert len(idx) == 100 and len(np.unique(idx)) == 100
    from unmesh.spatial import knn

    d, _ = knn(cloud.positions[idx], 2)
    assert d[:, 1].min() > 0.4 * np.median(d[:, 1])   # well spread, no clumps
    with pytest.raises(InputError, match="nodes"):
        select_nodes(cloud, 2)
    with pytest.raises(InputError, match="fewer nodes"):
        select_nodes(cloud, 5000)


def test_umbrella_pairs_skip_open_sides():
    x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0]])
    pr, _pc = umbrella_pairs(x, np.tile([0.0, 0, 1], (4, 1)), [0, 3, 3, 3, 3], [1, 2, 3])
    assert pr.tolist() == [[1, 2], [2, 3]]   # the 180 degree gap from -x back to +x is open


def test_kept_candidate_lists_give_the_same_neighbourhoods():
    """NodeCandidates keeps each node's kd-tree candidates: the same visible neighbourhoods,
    also for nodes asked again and on a grid (equal distances)."""
    from unmesh.shells import CrackSet
    from unmesh.shells.nodes import NodeCandidates, node_neighborhoods
    from unmesh.spatial import KDTree

    x, _ = grid_sheet(15, 12)
    cracks = CrackSet()
    cracks.add([6.5, 5.5, 0.0], [1.0, 0.2, 0.0], 2.0, 0, 0.0)
    cache = NodeCandidates(x, KDTree(x))
    for rows in (np.arange(0, 180, 3), np.arange(40, 120), np.arange(len(x))):
        a = node_neighborhoods(x, 12, cracks.blocked, nodes=rows, tree=KDTree(x))
        b = node_neighborhoods(x, 12, cracks.blocked, nodes=rows, tree=cache)
        for u, v in zip(a, b, strict=True):
            np.testing.assert_array_equal(u, v)
