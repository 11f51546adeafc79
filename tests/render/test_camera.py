"""Camera and image conventions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.render import Camera


def test_point_on_axis_projects_to_image_centre_and_depth_is_camera_z():
    cam = Camera((1, 2, 7), (1, 2, 0), width=40, height=30, fov=50)
    row, col, depth = cam.project([[1.0, 2.0, 0.0], [1.0, 2.0, 3.0]])
    assert row.tolist() == [15.0, 15.0] and col.tolist() == [20.0, 20.0]
    assert depth.tolist() == [7.0, 4.0]


def test_rows_grow_down_columns_grow_right():
    cam = Camera((0, 0, 5), (0, 0, 0), width=100, height=80, ortho=2.0)
    row, col, _ = cam.project([[0.5, 0.5, 0.0], [-0.5, -0.5, 0.0]])
    # upper right quadrant: smaller row, larger column
    assert row[0] < 40 < row[1]
    assert col[0] > 50 > col[1]
    # ortho scale: H / ortho = 40 pixels per unit
    assert row[0] == pytest.approx(40 - 20) and col[0] == pytest.approx(50 + 20)


def test_pixel_centre_ray_hits_the_point_that_projects_to_it():
    for cam in (Camera((0.3, 1, 4), (0, 0, 0), width=17, height=11, fov=60),
                Camera((0.3, 1, 4), (0, 0, 0), width=17, height=11, ortho=3.0)):
        o, d = cam.rays()
        for r, c in [(0, 0), (10, 16), (5, 8), (3, 12)]:
            p = o[r, c] + 2.5 * d[r, c]
            row, col, depth = cam.project(p)
            assert row[0] == pytest.approx(r + 0.5) and col[0] == pytest.approx(c + 0.5)
            assert int(np.floor(row[0])) == r and int(np.floor(col[0])) == c
            assert depth[0] == pytest.approx(2.5 * d[r, c] @ cam.forward)


def test_top_left_pixel_sees_upper_left_of_scene():
    cam = Camera((0, 0, 5), (0, 0, 0), width=10, height=10, ortho=2.0)
    o, d = cam.rays()
    assert o[0, 0, 0] < 0 and o[0, 0, 1] > 0  # left and up
    assert np.allclose(o[0, 0, :2], [-0.9, 0.9])
    assert np.allclose(d, [0, 0, -1])


def test_perspective_vs_orthographic_scaling():
    persp = Camera((0, 0, 4), (0, 0, 0), width=64, height=64, fov=90)
    ortho = Camera((0, 0, 4), (0, 0, 0), width=64, height=64, ortho=4.0)
    pts = [[1.0, 0.0, 0.0], [1.0, 0.0, 2.0]]  # same x, nearer second point
    _, cp, _ = persp.project(pts)
    _, co, _ = ortho.project(pts)
    assert cp[1] > cp[0]  # perspective: nearer looks farther from the axis
    assert co[0] == co[1]  # orthographic: independent of depth
    # fov 90 at depth 4: half height 4 units over 32 pixels
    assert cp[0] == pytest.approx(32 + 32 * 1.0 / 4.0)


def test_default_up_and_parallel_up_fallback():
    cam = Camera((0, 5, 0), (0, 0, 0), width=8, height=8)
    assert np.isclose(np.linalg.norm(cam.true_up), 1.0)
    assert abs(cam.true_up @ cam.forward) < 1e-12
    cam2 = Camera((0, 0, 5), (0, 0, 0))
    assert np.allclose(cam2.true_up, [0, 1, 0]) and np.allclose(cam2.right, [1, 0, 0])


@pytest.mark.parametrize("kwargs", [dict(eye=(0, 0, 0), target=(0, 0, 0)), dict(eye=(0, 0, 1), target=(0, 0, 0), fov=30, ortho=2),
                                    dict(eye=(0, 0, 1), target=(0, 0, 0), width=0), dict(eye=(0, 0, 1), target=(0, 0, 0), fov=180),
                                    dict(eye=(0, 0, 1), target=(0, 0, 0), ortho=-1), dict(eye=(0, 0), target=(0, 0, 0))])
def test_bad_cameras_raise_input_error(kwargs):
    with pytest.raises(InputError):
        Camera(**kwargs)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=6, max_size=6), st.booleans(), st.integers(8, 300), st.integers(8, 300))
def test_framing_keeps_all_corners_in_view(vals, ortho, w, h):
    lo = np.minimum(vals[:3], vals[3:])
    hi = np.maximum(vals[:3], vals[3:]) + 1e-3
    cam = Camera.framing([lo, hi], w, h, ortho=ortho)
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    row, col, depth = cam.project(corners)
    assert np.all(depth > cam.near_distance)
    assert np.all((row >= -1e-6) & (row <= h + 1e-6) & (col >= -1e-6) & (col <= w + 1e-6))


def test_framing_flat_data_is_viewed_head_on():
    cam = Camera.framing([[0, 0, 0], [2, 1, 0]], 64, 32)
    assert np.allclose(cam.forward, [0, 0, -1])
    cam_y = Camera.framing([[0, 0, 0], [2, 0, 1]], 64, 32)
    assert np.allclose(cam_y.forward, [0, -1, 0])


def test_framing_empty_bounds_and_orbit_and_zoom():
    cam = Camera.framing([[np.inf] * 3, [-np.inf] * 3], 32, 32)
    assert np.all(np.isfinite(cam.eye))
    c = Camera((0, 0, 5), (0, 0, 0), width=32, height=32, fov=40)
    o = c.orbit(90)
    assert np.allclose(o.eye, [5, 0, 0]) and np.allclose(o.target, 0)
    z = c.zoomed(4)
    assert z.pixels_per_unit == pytest.approx(4 * c.pixels_per_unit)
    zo = Camera((0, 0, 5), (0, 0, 0), width=32, height=32, ortho=2.0).zoomed(8)
    assert zo.ortho == pytest.approx(0.25)


@pytest.mark.parametrize("ortho", [False, True])
def test_facing_rows_kernel_equals_facing_mask(ortho):
    from unmesh.render._kernels import facing_rows

    rng = np.random.default_rng(3)
    cam = Camera((0.5, 1.0, 3.0), (0, 0, 0), width=8, height=8, ortho=2.0 if ortho else None)
    pos = rng.normal(size=(500, 3))
    nrm = rng.normal(size=(500, 3))
    rows = np.sort(rng.choice(500, 300, replace=False)).astype(np.int64)
    got = facing_rows(rows, pos, nrm, np.asarray(cam.eye, float), np.asarray(cam.forward, float), ortho)
    assert np.array_equal(got, rows[cam.facing(pos[rows], nrm[rows])])
