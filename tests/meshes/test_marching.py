"""marching_cubes: closed, outward iso-surfaces with vertices exactly at the level."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh, marching_cubes


def _grid(spacing: float, extent: float = 1.6) -> tuple[np.ndarray, np.ndarray]:
    # shifted so that no grid node lies on the test spheres (a vertex at a node keeps scikit-image's
    # float32 position, as before marching cubes moved here)
    axis = np.arange(-extent, extent + 0.5 * spacing, spacing) + 0.0123
    x = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)
    return x, np.full(3, axis[0])


def _sdf(p: np.ndarray) -> np.ndarray:
    return np.linalg.norm(p, axis=-1) - 1.0


def trilinear(values: np.ndarray, origin: np.ndarray, spacing: float, pts: np.ndarray) -> np.ndarray:
    """The grid's trilinear interpolant at points (N,3) inside the grid."""
    u = (pts - origin) / spacing
    i = np.clip(np.floor(u).astype(np.int64), 0, np.array(values.shape) - 2)
    t = u - i
    out = np.zeros(len(pts))
    for corner in np.ndindex(2, 2, 2):
        c = np.array(corner)
        w = np.prod(np.where(c == 1, t, 1 - t), axis=1)
        out += w * values[i[:, 0] + c[0], i[:, 1] + c[1], i[:, 2] + c[2]]
    return out


def closed_and_oriented(mesh: TriangleMesh) -> bool:
    """Every directed edge once and its reverse once: closed, edge-manifold, consistently oriented."""
    f = mesh.faces
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    uniq, counts = np.unique(directed, axis=0, return_counts=True)
    if np.any(counts != 1):
        return False
    rev = {tuple(e) for e in directed[:, ::-1].tolist()}
    return all(tuple(e) in rev for e in uniq.tolist())


def euler_characteristic(mesh: TriangleMesh) -> int:
    f = mesh.faces
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    return len(np.unique(f)) - len(edges) + len(f)


@pytest.mark.parametrize("with_function", [True, False])
def test_sphere_is_closed_outward_and_at_the_level(with_function):
    x, origin = _grid(0.1)
    values = _sdf(x)
    mesh = marching_cubes(values, origin, 0.1, function=_sdf if with_function else None)
    assert closed_and_oriented(mesh) and euler_characteristic(mesh) == 2
    np.testing.assert_allclose(mesh.volume(), 4 / 3 * np.pi, rtol=0.02)
    if with_function:  # on the exact surface to round-off
        assert np.abs(_sdf(mesh.vertices)).max() < 1e-13
    else:  # on the level set of the grid's trilinear interpolant, and near the true surface
        assert np.abs(trilinear(values, origin, 0.1, mesh.vertices)).max() < 1e-13
        assert np.abs(_sdf(mesh.vertices)).max() < 0.01


def test_vertices_stay_on_their_grid_edges():
    from skimage.measure import marching_cubes as skimage_mc

    x, origin = _grid(0.2)
    values = _sdf(x)
    verts, faces, _, _ = skimage_mc(values, 0.0, allow_degenerate=False)
    mesh = marching_cubes(values, origin, 0.2, function=_sdf)
    np.testing.assert_array_equal(mesh.faces, faces)  # the same triangulation (outward)
    moved = mesh.vertices - (origin + 0.2 * verts.astype(np.float64))
    assert np.all(np.count_nonzero(np.abs(moved) > 1e-12, axis=1) <= 1)  # along one grid axis only
    assert np.abs(moved).max() < 0.2


def test_inside_above_and_level():
    x, origin = _grid(0.1)
    below = marching_cubes(_sdf(x), origin, 0.1, level=0.2, function=_sdf)
    above = marching_cubes(-_sdf(x), origin, 0.1, level=-0.2, inside="above", function=lambda p: -_sdf(p))
    np.testing.assert_allclose(np.linalg.norm(below.vertices, axis=1), 1.2, atol=1e-12)
    assert len(above.vertices) == len(below.vertices) and len(above.faces) == len(below.faces)

    def rows(v):
        return v[np.lexsort(np.round(v, 9).T[::-1])]

    np.testing.assert_allclose(rows(above.vertices), rows(below.vertices), atol=1e-12)
    assert closed_and_oriented(above) and above.volume() > 0 and below.volume() > 0
    np.testing.assert_allclose(above.volume(), 4 / 3 * np.pi * 1.2**3, rtol=0.02)


def test_empty_and_bad_input():
    x, origin = _grid(0.2)
    empty = marching_cubes(_sdf(x) + 10.0, origin, 0.2)
    assert len(empty.faces) == 0 and len(empty.vertices) == 0
    with pytest.raises(InputError, match="values"):
        marching_cubes(np.zeros((1, 4, 4)))
    with pytest.raises(InputError, match="values"):
        marching_cubes(np.zeros((4, 4)))
    with pytest.raises(InputError, match="inside"):
        marching_cubes(_sdf(x), origin, 0.2, inside="outside")
    with pytest.raises(InputError, match="spacing"):
        marching_cubes(_sdf(x), origin, 0.0)
