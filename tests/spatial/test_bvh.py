"""TriangleBVH: closest points, winding numbers and ray hits against brute force over all triangles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.spatial import TriangleBVH
from unmesh.spatial.bvh import closest_point_reference, ray_hits_reference, winding_reference


def uv_sphere(n_lat: int = 12, n_lon: int = 24, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward UV sphere: poles plus ``n_lat - 1`` rings of ``n_lon`` vertices."""
    th = np.pi * np.arange(1, n_lat) / n_lat
    ph = 2 * np.pi * np.arange(n_lon) / n_lon
    ring = np.stack([np.outer(np.sin(th), np.cos(ph)), np.outer(np.sin(th), np.sin(ph)),
                     np.outer(np.cos(th), np.ones(n_lon))], -1).reshape(-1, 3)
    v = radius * np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]])
    south = len(v) - 1
    j = np.arange(n_lon)
    j1 = (j + 1) % n_lon
    faces = [np.stack([np.zeros(n_lon, np.int64), 1 + j, 1 + j1], 1)]
    for i in range(n_lat - 2):
        a, b = 1 + i * n_lon + j, 1 + (i + 1) * n_lon + j
        c, d = 1 + (i + 1) * n_lon + j1, 1 + i * n_lon + j1
        faces += [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    last = 1 + (n_lat - 2) * n_lon
    faces.append(np.stack([np.full(n_lon, south), last + j1, last + j], 1))
    return v, np.concatenate(faces).astype(np.int64)


def unit_cube() -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward cube [0, 1]^3 of 12 triangles (axis-aligned faces: flat boxes in the tree)."""
    v = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int64)
    return v, f


def random_soup(rng: np.random.Generator, n_vertices: int = 60, n_faces: int = 90) -> tuple[np.ndarray, np.ndarray]:
    """Random triangles (overlapping, of every size and orientation) in [-1, 1]^3."""
    v = rng.uniform(-1, 1, (n_vertices, 3))
    f = np.stack([rng.choice(n_vertices, 3, replace=False) for _ in range(n_faces)]).astype(np.int64)
    return v, f


def _signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6)


def _triangle_points(v, f, face, bary):
    tri = v[f[face]]  # (N, 3, 3)
    return np.einsum("nk,nki->ni", bary, tri)


def test_helpers_are_closed_and_outward():
    for v, f in (uv_sphere(), unit_cube()):
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        _, counts = np.unique(e, axis=0, return_counts=True)
        assert np.all(counts == 2)
        assert _signed_volume(v, f) > 0


@pytest.mark.parametrize("leaf_size", [1, 3, 8, 1000])
def test_closest_matches_brute_force(rng, leaf_size):
    v, f = random_soup(rng)
    bvh = TriangleBVH(v, f, leaf_size=leaf_size)
    x = rng.uniform(-1.5, 1.5, (300, 3))
    d, face, p, b = bvh.closest(x)
    d_ref, p_ref = closest_point_reference(x, v, f)
    np.testing.assert_allclose(d, d_ref, atol=1e-12)
    np.testing.assert_allclose(p, p_ref, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(x - p, axis=1), d, atol=1e-12)
    # the reported face holds the point: its own distance is the minimum
    own = np.array([closest_point_reference(x[i:i + 1], v, f[face[i]:face[i] + 1])[0][0] for i in range(len(x))])
    np.testing.assert_allclose(own, d, atol=1e-12)
    # barycentrics: non-negative, sum to one, reconstruct the point
    assert np.all(b >= -1e-12)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(_triangle_points(v, f, face, b), p, atol=1e-12)


def test_leaf_size_does_not_change_the_answers(rng):
    v, f = random_soup(rng, 40, 200)
    x = rng.uniform(-1.2, 1.2, (200, 3))
    ref = TriangleBVH(v, f, leaf_size=1).closest(x)
    for leaf in (2, 8, 500):
        got = TriangleBVH(v, f, leaf_size=leaf).closest(x)
        np.testing.assert_array_equal(got[0], ref[0])
        # the face may differ only where several triangles are exactly as near (shared vertices/edges)
        other = got[1] != ref[1]
        own = [closest_point_reference(x[i:i + 1], v, f[got[1][i]:got[1][i] + 1])[0][0] for i in np.flatnonzero(other)]
        np.testing.assert_allclose(own, ref[0][other], rtol=1e-14)


def test_closest_handles_degenerate_triangles():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [2, 0, 0], [3, 0, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 4], [5, 5, 5]])  # a collinear and a point-like triangle
    bvh = TriangleBVH(v, f)
    d, face, p, b = bvh.closest([[0.2, 0.2, 1.0], [3.0, 1.0, 0.0], [1.5, -1.0, 0.0]])
    np.testing.assert_allclose(d, [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(face, [0, 2, 1])
    np.testing.assert_allclose(b.sum(axis=1), 1.0)
    np.testing.assert_allclose(_triangle_points(v, f, face, b), p, atol=1e-15)


def test_winding_numbers_match_exact_sum(rng):
    v, f = uv_sphere()
    bvh = TriangleBVH(v, f)
    x = rng.uniform(-1.5, 1.5, (400, 3))
    w_ref = winding_reference(x, v, f)
    np.testing.assert_allclose(bvh.winding_number(x, beta=np.inf), w_ref, atol=1e-12)
    assert np.abs(bvh.winding_number(x) - w_ref).max() < 0.025
    sv, sf = random_soup(rng)  # open soups: any real value
    np.testing.assert_allclose(TriangleBVH(sv, sf).winding_number(x, beta=np.inf), winding_reference(x, sv, sf),
                               atol=1e-12)


def test_contains_on_closed_meshes(rng):
    v, f = uv_sphere()
    x = rng.uniform(-1.5, 1.5, (3000, 3))
    r = np.linalg.norm(x, axis=1)
    sure = (r < 0.9) | (r > 1.05)  # the UV sphere lies between radii cos(pi/12) and 1
    np.testing.assert_array_equal(TriangleBVH(v, f).contains(x)[sure], (r < 1)[sure])
    cv, cf = unit_cube()
    y = rng.uniform(-0.5, 1.5, (3000, 3))
    inside = np.all((y > 0) & (y < 1), axis=1)
    np.testing.assert_array_equal(TriangleBVH(cv, cf).contains(y), inside)


def _first_reference(o, d, v, f):
    t, u, w = ray_hits_reference(o, d, v, f)
    face = np.argmin(t, axis=1)  # lowest index among equal t
    tt = t[np.arange(len(o)), face]
    hit = np.isfinite(tt)
    bary = np.stack([1 - u - w, u, w], -1)[np.arange(len(o)), face]
    return np.where(hit, tt, np.inf), np.where(hit, face, -1), t, bary


@pytest.mark.parametrize("mesh", ["soup", "sphere", "cube"])
def test_first_ray_hits_match_brute_force(rng, mesh):
    v, f = {"soup": lambda: random_soup(rng), "sphere": uv_sphere, "cube": unit_cube}[mesh]()
    bvh = TriangleBVH(v, f, leaf_size=2)
    o = rng.uniform(-2, 2, (400, 3))
    d = rng.normal(size=(400, 3))
    d[:100] = np.rint(d[:100])  # axis-parallel and diagonal directions with zero components
    d[np.all(d == 0, axis=1)] = (0.0, 0.0, 1.0)
    if mesh == "cube":  # aim at the faces too, including exact axis-aligned rays
        d[100:200] = rng.uniform(0, 1, (100, 3)) - o[100:200]
        d[200:260] = np.eye(3)[rng.integers(0, 3, 60)] * rng.choice([-1.0, 1.0], (60, 1))
    t, face, b = bvh.ray_hits(o, d)
    t_ref, face_ref, t_all, b_ref = _first_reference(o, d, v, f)
    np.testing.assert_array_equal(np.isfinite(t), np.isfinite(t_ref))
    hit = np.isfinite(t)
    assert hit.sum() > 50
    np.testing.assert_allclose(t[hit], t_ref[hit], rtol=1e-12, atol=1e-12)
    # the same face unless another triangle is hit at the same t (shared edges)
    srt = np.sort(t_all[hit], axis=1)
    unique = (srt[:, 1] - srt[:, 0]) > 1e-9 * np.maximum(1.0, srt[:, 0])
    np.testing.assert_array_equal(face[hit][unique], face_ref[hit][unique])
    np.testing.assert_allclose(b[hit][unique], b_ref[hit][unique], atol=1e-12)
    assert np.all(face[~hit] == -1) and np.all(np.isnan(b[~hit]))


@pytest.mark.parametrize("mesh", ["soup", "sphere"])
def test_all_ray_hits_match_brute_force(rng, mesh):
    v, f = random_soup(rng) if mesh == "soup" else uv_sphere()
    bvh = TriangleBVH(v, f)
    o = rng.uniform(-2, 2, (300, 3))
    d = rng.normal(size=(300, 3))
    off, t, face, b = bvh.ray_hits(o, d, first=False)
    t_all, u, w = ray_hits_reference(o, d, v, f)
    np.testing.assert_array_equal(np.diff(off), np.isfinite(t_all).sum(axis=1))
    for i in range(len(o)):
        s = slice(off[i], off[i + 1])
        assert np.all(np.diff(t[s]) >= 0)
        np.testing.assert_array_equal(np.sort(face[s]), np.flatnonzero(np.isfinite(t_all[i])))
        np.testing.assert_allclose(t[s], t_all[i, face[s]], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(b[s, 1:], np.stack([u[i, face[s]], w[i, face[s]]], 1), atol=1e-12)
    # a ray from inside a closed sphere leaves it exactly once
    if mesh == "sphere":
        off2, *_ = bvh.ray_hits(rng.uniform(-0.5, 0.5, (50, 3)), rng.normal(size=(50, 3)), first=False)
        assert np.all(np.diff(off2) >= 1)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.floats(1e-3, 1e3))
def test_closest_invariants(seed, scale):
    rng = np.random.default_rng(seed)
    v, f = random_soup(rng, 30, 40)
    v *= scale
    x = rng.uniform(-2, 2, (50, 3)) * scale
    d, face, p, b = TriangleBVH(v, f).closest(x)
    used = np.unique(f)
    vd = np.linalg.norm(x[:, None] - v[used][None], axis=2)
    assert np.all(d <= vd.min(axis=1) * (1 + 1e-12))  # never farther than any vertex
    assert np.all(b >= -1e-12) and np.allclose(b.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(_triangle_points(v, f, face, b), p, atol=1e-12 * scale)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), radius=st.floats(0.1, 10.0), n_lat=st.integers(4, 10))
def test_winding_invariants_on_a_closed_sphere(seed, radius, n_lat):
    rng = np.random.default_rng(seed)
    v, f = uv_sphere(n_lat, 2 * n_lat, radius)
    inner = radius * np.cos(np.pi / n_lat) * np.cos(np.pi / (2 * n_lat))  # below every face's plane distance
    dirs = rng.normal(size=(40, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    inside = dirs * rng.uniform(0, 0.95, (40, 1)) * inner
    outside = dirs * rng.uniform(1.05, 5.0, (40, 1)) * radius
    bvh = TriangleBVH(v, f)
    np.testing.assert_allclose(bvh.winding_number(inside, beta=np.inf), 1.0, atol=1e-9)
    np.testing.assert_allclose(bvh.winding_number(outside, beta=np.inf), 0.0, atol=1e-9)
    assert bvh.contains(inside).all() and not bvh.contains(outside).any()


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_ray_hit_points_lie_on_their_triangles(seed):
    rng = np.random.default_rng(seed)
    v, f = random_soup(rng, 30, 40)
    o = rng.uniform(-2, 2, (60, 3))
    d = rng.uniform(-1, 1, (60, 3)) - o  # towards the soup
    bvh = TriangleBVH(v, f)
    t, face, b = bvh.ray_hits(o, d)
    hit = np.isfinite(t)
    x = o[hit] + t[hit, None] * d[hit]
    assert np.all(b[hit] >= -1e-12) and np.allclose(b[hit].sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(_triangle_points(v, f, face[hit], b[hit]), x, atol=1e-9)
    own = [closest_point_reference(x[i:i + 1], v, f[face[hit][i]:face[hit][i] + 1])[0][0] for i in range(len(x))]
    np.testing.assert_allclose(own, 0.0, atol=1e-9)
    # nothing is hit before the first hit
    off, t_all, _, _ = bvh.ray_hits(o, d, first=False)
    firsts = np.array([t_all[off[i]] if off[i + 1] > off[i] else np.inf for i in range(len(o))])
    np.testing.assert_array_equal(firsts, t)


def test_empty_tree_input_checks_and_immutability():
    empty = TriangleBVH(np.zeros((3, 3)), np.zeros((0, 3), np.int64))
    d, face, p, b = empty.closest([[0.0, 0.0, 0.0]])
    assert d[0] == np.inf and face[0] == -1 and np.isnan(p).all() and np.isnan(b).all()
    assert empty.winding_number([[0.0, 0.0, 0.0]])[0] == 0.0
    t, face, _ = empty.ray_hits([[0.0, 0, 0]], [[1.0, 0, 0]])
    assert t[0] == np.inf and face[0] == -1
    v, f = unit_cube()
    bvh = TriangleBVH(v, f)
    assert len(bvh) == 12 and "n_faces=12" in repr(bvh)
    with pytest.raises(InputError, match="faces"):
        TriangleBVH(v, f + 8)
    with pytest.raises(InputError, match="leaf_size"):
        TriangleBVH(v, f, leaf_size=0)
    with pytest.raises(InputError, match="directions"):
        bvh.ray_hits([[0.0, 0, 0]], [[0.0, 0, 0]])
    with pytest.raises(InputError, match="directions"):
        bvh.ray_hits([[0.0, 0, 0]], [[1.0, 0, 0], [0.0, 1, 0]])
    with pytest.raises(InputError, match="beta"):
        bvh.winding_number([[0.0, 0, 0]], beta=0.0)
    with pytest.raises(AttributeError):
        bvh.vertices = v
