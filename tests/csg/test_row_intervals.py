"""Clipped splatting's row intervals (one clip-tree evaluation per interval of constant leaf
values along a pixel row) against the per-fragment evaluation, pixel for pixel."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh import scenes
from unmesh.csg import prepare
from unmesh.csg.draw import front_facing
from unmesh.csg.fold import fold_for_camera
from unmesh.csg.frame import select
from unmesh.csg.model import flatten
from unmesh.csg.scene import load
from unmesh.render import Camera, ClipTree, SplatOptions, SplatRenderer, scene_points, splat
from unmesh.render._splat_kernels import _rows_begin, clip_work, max_rows
from unmesh.render.splat import SurfelArrays
from unmesh.surfels import SurfelCloud

from .test_clip_tree import _tree

GBUFFER = ("albedo", "normal", "depth", "coverage", "weight")


def _both_paths(monkeypatch, cam, arrays, clip, options=None):
    """G-buffers with the row intervals (the default) and with every fragment evaluated on its
    own (``clip_mode[0] = 1`` with a clip tree)."""
    g_rows = SplatRenderer(cam, options).render(arrays, clip=clip).gbuffer()
    with monkeypatch.context() as m:
        m.setattr(splat, "_NO_MODE", np.ones(1, dtype=np.int8))
        g_each = SplatRenderer(cam, options).render(arrays, clip=clip).gbuffer()
    return g_rows, g_each


def _assert_same(g1, g2):
    for k in GBUFFER:
        assert np.array_equal(getattr(g1, k), getattr(g2, k)), k


@pytest.mark.parametrize("name", ["icosahedron", "sampled_cube", "carved_cube"])
@pytest.mark.parametrize("zoom", [1.0, 2.5])
@pytest.mark.parametrize("ortho", [False, True])
def test_shipped_scenes_row_intervals_equal_per_fragment_evaluation(monkeypatch, name, zoom, ortho):
    """Figs. 4.10 and 4.7 (and the carved cube): identical G-buffers with the tree folded for
    the camera and not, perspective and orthographic."""
    fr = prepare(load(scenes.path(f"csg/{name}.toml")).model)
    pts = scene_points(SurfelCloud(fr.arrays.positions, fr.arrays.normals, radii=fr.arrays.radii))
    cam = (Camera.fit(pts, 160, 160, ortho=True) if ortho else Camera.fit(pts, 160, 160, fov=35)).zoomed(zoom)
    arrays, clip = select(fr.arrays, fr.clip, front_facing(fr.arrays.positions, fr.arrays.normals, cam))
    fa, fc = fold_for_camera(arrays, clip, cam)
    for a, c in ((arrays, clip), (fa, fc)):
        g1, g2 = _both_paths(monkeypatch, cam, a, c)
        assert g1.coverage.any()
        _assert_same(g1, g2)


def test_row_intervals_apply_to_the_faces_of_fig_4_10():
    """Every edge surfel of the icosahedron (one surfel per face) takes the row path."""
    fr = prepare(load(scenes.path("csg/icosahedron.toml")).model)
    pts = scene_points(SurfelCloud(fr.arrays.positions, fr.arrays.normals, radii=fr.arrays.radii))
    cam = Camera.fit(pts, 160, 160, fov=35)
    f, cx, cy, ortho, near = cam.kernel_params()
    c = fr.clip
    work = clip_work(len(c.tree), max_rows(c.offsets))
    mode = np.zeros(1, dtype=np.int8)
    edge = np.flatnonzero(np.diff(c.offsets) > 0)
    assert len(edge) == 20
    for s in edge:
        z = float(cam.to_camera(fr.arrays.positions[s:s + 1])[0, 2])
        ok, tmin = _rows_begin(s, 0, 159, 0, 159, z - 1.0, z + 1.0, 1.0, ortho, near, 1.0 / f, cx, cy, cam.eye,
                               cam.rotation, c.offsets, c.partners, mode, c.tree, work)
        assert ok and tmin > 0.0


@st.composite
def planar_scenes(draw):
    """Random CSG trees of 2-6 patches of one large disc each (every leaf has one partner:
    a half-space), some partners on the surfel's own plane (coplanar patches, 4.5), some
    planes through the eye or containing the view rows, and a random camera."""
    nleaves = draw(st.integers(2, 6))
    flat = flatten(_tree(draw, nleaves))
    table = flat.table()
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    ortho = draw(st.booleans())
    eye = rng.normal(size=3)
    eye *= 3.0 / np.linalg.norm(eye)
    up = rng.normal(size=3)
    if ortho:
        cam = Camera(eye, (0, 0, 0), width=40, height=32, up=up, ortho=float(rng.uniform(0.6, 1.6)))
    else:
        cam = Camera(eye, (0, 0, 0), width=40, height=32, up=up, fov=float(rng.uniform(20, 60)))
    pos = rng.uniform(-0.4, 0.4, size=(nleaves, 3))
    nrm = rng.normal(size=(nleaves, 3))
    for i in range(nleaves):
        kind = draw(st.integers(0, 5))
        if kind == 1 and i > 0:  # on the plane of an earlier surfel (coplanar patches)
            j = int(rng.integers(i))
            pos[i] = pos[j] + np.cross(nrm[j], rng.normal(size=3)) * 0.1
            nrm[i] = nrm[j] * (1 if draw(st.booleans()) else -1)
        elif kind == 2:  # a plane through the eye
            nrm[i] = np.cross(pos[i] - cam.eye, rng.normal(size=3))
        elif kind == 3:  # a plane containing the camera's x axis (parallel to the pixel rows)
            nrm[i] = np.cross(cam.rotation[0], rng.normal(size=3))
        elif kind == 4 and i > 0:  # through an earlier surfel's centre
            pos[i] = pos[int(rng.integers(i))]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    radii = rng.uniform(0.3, 1.2, size=nleaves)
    leaf = np.array([flat.leaf_node[i] for i in range(nleaves)], dtype=np.int32)
    rows, offsets = [], [0]
    for i in range(nleaves):
        for j in range(nleaves):
            if j != i and np.linalg.norm(pos[i] - pos[j]) < radii[i] + radii[j]:
                rows.append([*pos[j], *nrm[j], leaf[j]])
        offsets.append(len(rows))
    clip = ClipTree(offsets, np.array(rows, dtype=np.float64).reshape(-1, 7), table, leaf)
    colors = rng.uniform(size=(nleaves, 3))
    arrays = SurfelArrays(pos, nrm, radii, None, colors)
    return cam, arrays, clip, SplatOptions(precision=draw(st.sampled_from(["single", "double"])))


@settings(max_examples=60, deadline=None)
@given(planar_scenes())
def test_random_planar_configurations_row_intervals_equal_per_fragment_evaluation(case):
    """Random half-space trees and cameras, both precisions: identical G-buffers from both
    paths."""
    cam, arrays, clip, options = case
    mp = pytest.MonkeyPatch()
    try:
        g1, g2 = _both_paths(mp, cam, arrays, clip, options)
    finally:
        mp.undo()
    _assert_same(g1, g2)
