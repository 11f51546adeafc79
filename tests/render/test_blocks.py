"""The block path of full updates (:mod:`unmesh.render._block_kernels`) against the tiled path
(itself tested against the numpy reference in test_splat.py): the same buffers bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import unmesh.render.splat as splat_module
from unmesh import SurfelCloud
from unmesh.render import Camera, SplatOptions, SplatRenderer
from unmesh.render._block_kernels import block_count, block_setup
from unmesh.render._splat_kernels import NPARAM, splat_setup
from unmesh.render.splat import BLOCK_SHIFT, surfel_arrays

from .conftest import fibonacci_sphere

BUFFERS = ("zvis", "sum_weight", "sum_color", "sum_normal", "sum_depth", "count")
CAMERAS = {
    "ortho": Camera((0.3, 0.2, 3), (0, 0, 0), width=70, height=53, ortho=1.6),
    "perspective": Camera((0.3, 0.2, 2.2), (0, 0, 0), width=70, height=53, fov=50),
    # the eye inside the cloud: surfels behind it, across the near plane and off screen
    "inside": Camera((0.1, 0.05, 0.2), (0, 0, -1), width=70, height=53, fov=80),
}


def mixed_cloud(seed: int, elliptical: bool) -> SurfelCloud:
    """A dense sphere (splats of a few pixels, many blocks) and large random splats that span
    many blocks or reach past the image."""
    rng = np.random.default_rng(seed)
    s = fibonacci_sphere(3000, radius_factor=1.3)
    n = 40
    pos = np.concatenate([s.positions, rng.normal(size=(n, 3)) * 0.8])
    nrm = np.concatenate([s.normals, rng.normal(size=(n, 3))])
    col = np.concatenate([s.colors, rng.random((n, 3))])
    if elliptical:
        axes = np.concatenate([s.tangent_axes(), rng.normal(size=(n, 2, 3)) * rng.uniform(0.02, 0.5, (n, 2, 1))])
        return SurfelCloud(pos, nrm, axes=axes, colors=col)
    return SurfelCloud(pos, nrm, radii=np.concatenate([s.radii, rng.uniform(0.02, 0.6, n)]), colors=col)


def buffers(cam, cloud, precision, blocks, monkeypatch, opaque=None):
    monkeypatch.setattr(splat_module, "_USE_BLOCKS", blocks)
    r = SplatRenderer(cam, SplatOptions(precision=precision, tile=16)).render(cloud, opaque=opaque)
    return {k: getattr(r, k).copy() for k in BUFFERS}


@pytest.mark.parametrize("camname", list(CAMERAS))
@pytest.mark.parametrize("elliptical", [False, True])
@pytest.mark.parametrize("precision", ["single", "double"])
def test_block_path_equals_tiled_path_bit_for_bit(camname, elliptical, precision, monkeypatch):
    cam = CAMERAS[camname]
    cloud = mixed_cloud(1, elliptical)
    tiled = buffers(cam, cloud, precision, False, monkeypatch)
    blocked = buffers(cam, cloud, precision, True, monkeypatch)
    assert tiled["count"].sum() > 1000
    for key in BUFFERS:
        assert np.array_equal(tiled[key], blocked[key]), key


def test_block_path_against_an_opaque_layer(monkeypatch):
    cam = CAMERAS["perspective"]
    cloud = mixed_cloud(2, False)
    from unmesh.render.shading import GBuffer
    opaque = GBuffer.empty(*cam.shape)
    opaque.depth[:, : cam.shape[1] // 2] = 2.0  # a wall in front of the left half
    tiled = buffers(cam, cloud, "double", False, monkeypatch, opaque)
    blocked = buffers(cam, cloud, "double", True, monkeypatch, opaque)
    for key in BUFFERS:
        assert np.array_equal(tiled[key], blocked[key]), key


@pytest.mark.parametrize("camname", list(CAMERAS))
def test_block_rows_cover_every_box_once(camname):
    """Brute force: the rows of each block are exactly the surfels whose pixel box meets it,
    with the box clipped to the block, front-facing surfels first, then ascending."""
    cam = CAMERAS[camname]
    a = surfel_arrays(mixed_cloud(3, True))
    axes = a.axes
    f, cx, cy, ortho, near = cam.kernel_params()
    h, w = cam.shape
    n = len(a)
    P = np.empty((n, NPARAM))
    box = np.empty((n, 4), dtype=np.int32)
    group = np.empty(n, dtype=np.int8)
    splat_setup(a.positions, a.normals, a.radii, axes, True, a.colors, cam.rotation, cam.eye, f, cx, cy, ortho, near,
                w, h, 1.0, P, box, group)
    view = (cam.rotation, cam.eye, f, cx, cy, ortho, near, w, h, 1.0, *BLOCK_SHIFT)
    offsets, starts, total = block_count(a.positions, a.normals, a.radii, axes, True, *view, 3)
    rows = np.empty((total, NPARAM))
    items = np.empty(total, dtype=np.int32)
    block_setup(a.positions, a.normals, a.radii, axes, True, a.colors, *view, starts, rows, items)
    eh, ew = 1 << BLOCK_SHIFT[0], 1 << BLOCK_SHIFT[1]
    ntx = (w + ew - 1) // ew
    assert len(offsets) == ntx * ((h + eh - 1) // eh) + 1
    for t in range(len(offsets) - 1):
        sel = items[offsets[t]:offsets[t + 1]]
        r = rows[offsets[t]:offsets[t + 1]]
        y0, x0 = (t // ntx) * eh, (t % ntx) * ew
        y1, x1 = min(h, y0 + eh) - 1, min(w, x0 + ew) - 1
        lo = np.maximum(box, [x0, x0, y0, y0])
        hi = np.minimum(box, [x1, x1, y1, y1])
        meets = (lo[:, 0] <= hi[:, 1]) & (lo[:, 2] <= hi[:, 3])
        # every surfel whose box meets the block is there (others only with empty clipped boxes)
        got = sel[(r[:, 19] <= r[:, 20]) & (r[:, 21] <= r[:, 22])]
        assert np.array_equal(np.sort(got), np.flatnonzero(meets))
        assert np.array_equal(sel, sel[np.lexsort((sel, group[sel]))])
        assert np.array_equal(r[:, :19], P[sel, :19], equal_nan=True)
        assert np.array_equal(r[:, 23], P[sel, 23])
        ok = (r[:, 19] <= r[:, 20]) & (r[:, 21] <= r[:, 22])
        assert np.array_equal(r[ok, 19:23], np.stack([lo[sel[ok], 0], hi[sel[ok], 1], lo[sel[ok], 2], hi[sel[ok], 3]], 1))
