"""The vectorised face-stream parser against the checked list parser (same arrays, same refusals)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.errors import InputError
from unmesh.fem import cut_by_plane, hex_grid, voronoi_foam
from unmesh.fem.cellparse import parse_cells, parse_face_stream


def _flat(cells):
    faces = [f for c in cells for f in c]
    size = np.array([len(f) for f in faces], dtype=np.int64)
    nodes = np.array([v for f in faces for v in f], dtype=np.int64)
    return (nodes, np.concatenate([[0], np.cumsum(size)]),
            np.concatenate([[0], np.cumsum([len(c) for c in cells])]).astype(np.int64))


@functools.lru_cache
def _cut_cube(seed: int, cuts: int):
    rng = np.random.default_rng(seed)
    m = hex_grid((2, 2, 2))
    for _ in range(cuts):
        m = cut_by_plane(m, rng.random(3), rng.normal(size=3))
    return m


@pytest.mark.parametrize("mesh", [hex_grid((3, 2, 2)), voronoi_foam(20, seed=3), _cut_cube(1, 5)],
                         ids=["hexes", "voronoi", "cut-cube"])
def test_same_arrays_as_the_list_parser(mesh):
    cells = mesh.cells
    want = parse_cells(cells, mesh.n_nodes)
    got = parse_face_stream(*_flat(cells), mesh.n_nodes)
    for a, b in zip(got, want, strict=True):
        assert a.dtype == np.int64
        np.testing.assert_array_equal(a, b)


@settings(max_examples=25, deadline=None)
@given(st.randoms(use_true_random=False), st.integers(0, 4))
def test_any_element_order_and_face_rotation_agree(rnd, cuts):
    mesh = _cut_cube(7, cuts)
    cells = [list(c) for c in mesh.cells]
    rnd.shuffle(cells)
    cells = [[(f[r:] + f[:r]) for f in c for r in [rnd.randrange(len(f))]] for c in cells]
    for c in cells:
        rnd.shuffle(c)
    want = parse_cells(cells, mesh.n_nodes)
    got = parse_face_stream(*_flat(cells), mesh.n_nodes)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, b)


TET = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]


@pytest.mark.parametrize("cells, n", [
    ([TET, TET], 4),                                        # every face shared in the same orientation
    ([TET, [f[::-1] for f in TET], [f[::-1] for f in TET]], 4),  # a face shared three times
    ([TET[:3]], 4),                                          # three faces
    ([[[0, 2], *TET[1:]]], 4),                               # a face of two nodes
    ([TET], 3),                                              # node 3 out of range
    ([TET, [[0, 1, 2], [0, 3, 1], [2, 1, 3], [0, 3, 2]]], 4),   # a face in a different cyclic order
], ids=["same-orientation", "three-uses", "three-faces", "short-face", "range", "cyclic-order"])
def test_irregular_elements_are_left_to_the_list_parser(cells, n):
    assert parse_face_stream(*_flat(cells), n) is None
    with pytest.raises(InputError):
        parse_cells(cells, n)
