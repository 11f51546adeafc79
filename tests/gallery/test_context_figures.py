"""The drawing context of the simulation examples (issue 23, items 9 and 10): floors and walls
from the scene files, blades at the right place, FEM pieces coloured by piece."""

import numpy as np
import pytest

from unmesh.gallery.examples.fem import _blade_polygons, _blades, piece_colored_surface, pieces
from unmesh.gallery.examples.sph import _context
from unmesh.gallery.figures import floor_under, nice_step
from unmesh.render import Box, Floor, Polygon


@pytest.mark.parametrize("length, lines, step", [(1.3, 8, 0.2), (10.0, 5, 2.0), (0.07, 8, 0.01), (48.0, 8, 5.0)])
def test_nice_step(length, lines, step):
    assert nice_step(length, lines) == pytest.approx(step)


def test_floor_under_is_centred_below_the_points():
    pts = np.array([[1.0, 0.5, 2.0], [3.0, 1.5, 4.0]])
    f = floor_under(pts, height=0.25)
    assert isinstance(f, Floor)
    assert f.point.tolist() == [2.0, 0.25, 3.0]
    assert f.extent == pytest.approx(12.0)


def test_sph_context_of_the_3d_tank_and_the_2d_walls():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([0.8, 0.5, 0.2])
    objs, keep = _context("dam_break", 3, lo, hi)
    floors = [o for o in objs if isinstance(o, Floor)]
    walls = [o for o in objs if isinstance(o, Polygon)]
    assert len(floors) == 1 and floors[0].point[1] == 0.0
    assert len(walls) == 4 and all(w.opacity < 1 for w in walls)
    # the walls stand on the tank's rectangle [0, 1.25] x [0, 0.2]
    corners = np.concatenate([w.vertices for w in walls])
    assert np.allclose(corners[:, [0, 2]].min(axis=0), [0, 0]) and np.allclose(corners[:, [0, 2]].max(axis=0), [1.25, 0.2])
    assert len(keep) == 4
    objs, keep = _context("fracture_2d", 2, np.array([0.0, 0.4, 0]), np.array([0.5, 0.6, 0]))
    boxes = [o for o in objs if isinstance(o, Box)]
    assert len(boxes) == 3 and all(b.opacity == 1 for b in boxes)
    assert min(b.hi[1] for b in boxes) == 0.0  # the floor's top is y = 0
    assert all(b.hi[2] <= 0.0 for b in boxes)  # behind the particles' plane z = 0
    objs, _ = _context("elastic_cube_2d", 2, np.array([-0.1, 0.3, 0]), np.array([0.1, 0.5, 0]))
    assert len(objs) == 1 and objs[0].hi[1] == 0.0


def test_blades_are_drawn_while_they_cut_at_their_edge():
    blades = _blades("progressive_slicing")
    assert len(blades) == 2
    b = blades[0]
    t = 0.5 * (b.start + b.stop)
    (poly,) = _blade_polygons(blades, t, 0.01)
    edge = b.blade(t)
    assert np.allclose(poly.vertices[:2], edge)
    assert _blade_polygons(blades, 1.1, 0.01) == []  # between the two sweeps
    assert len(_blade_polygons(blades, b.stop + 0.015, 0.01)) == 1  # shown just after the stop


def test_pieces_colour_separated_parts_and_number_them_left_to_right():
    from unmesh.fem import PolyMesh, hex_grid

    m = hex_grid((3, 1, 1))
    assert pieces(m).tolist() == [0, 0, 0]
    cells = m.cells
    # detach the middle element: its nodes are copied (as a cut does), reversed element order
    mid = sorted({n for face in cells[1] for n in face})
    new = {n: m.n_nodes + k for k, n in enumerate(mid)}
    points = np.concatenate([m.points, m.points[mid]])
    detached = [[new[n] for n in face] for face in cells[1]]
    split = PolyMesh(points, [cells[2], detached, cells[0]], tolerance=1e-6)
    label = pieces(split)
    # elements 2 and 0 still share the nodes of... nothing: three pieces, ordered by x
    assert label.tolist() == [2, 1, 0]
    surf = piece_colored_surface(split, np.zeros((split.n_nodes, 3)))
    assert len(np.unique(surf.vertex_colors, axis=0)) == 3


def test_the_hanging_sheet_clamp_is_drawn_where_the_scene_pins_it():
    from unmesh.gallery.examples.shells import _clamps

    (clamp,) = _clamps("hanging_sheet")
    assert np.allclose(0.5 * (clamp.lo + clamp.hi), [-0.5, 1.0, 0.0])
    assert np.allclose(clamp.hi - clamp.lo, [0.2, 0.02, 1.2])
    assert _clamps("elastic_drop") == ()
