"""The band path of full updates (:mod:`unmesh.render._band_kernels`) against the tiled path
(itself tested against the numpy reference in test_splat.py): the same buffers bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import unmesh.render.splat as splat_module
from unmesh import SurfelCloud
from unmesh.render import Camera, SplatOptions, SplatRenderer
from unmesh.render._band_kernels import band_count, band_setup
from unmesh.render._splat_kernels import NPARAM, splat_setup
from unmesh.render.splat import BAND_SHIFT, surfel_arrays

from .conftest import fibonacci_sphere

BUFFERS = ("zvis", "sum_weight", "sum_color", "sum_normal", "sum_depth", "count")
CAMERAS = {
    "ortho": Camera((0.3, 0.2, 3), (0, 0, 0), width=70, height=53, ortho=1.6),
    "perspective": Camera((0.3, 0.2, 2.2), (0, 0, 0), width=70, height=53, fov=50),
    # the eye inside the cloud: surfels behind it, across the near plane and off screen
    "inside": Camera((0.1, 0.05, 0.2), (0, 0, -1), width=70, height=53, fov=80),
}


def mixed_cloud(seed: int, elliptical: bool) -> SurfelCloud:
    """A dense sphere (splats of a few pixels, many bands) and large random splats that span
    many bands or reach past the image."""
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


def buffers(cam, cloud, precision, bands, monkeypatch, opaque=None):
    monkeypatch.setattr(splat_module, "_USE_BANDS", bands)
    r = SplatRenderer(cam, SplatOptions(precision=precision, tile=16)).render(cloud, opaque=opaque)
    return {k: getattr(r, k).copy() for k in BUFFERS}


@pytest.mark.parametrize("camname", list(CAMERAS))
@pytest.mark.parametrize("elliptical", [False, True])
@pytest.mark.parametrize("precision", ["single", "double"])
def test_band_path_equals_tiled_path_bit_for_bit(camname, elliptical, precision, monkeypatch):
    cam = CAMERAS[camname]
    cloud = mixed_cloud(1, elliptical)
    tiled = buffers(cam, cloud, precision, False, monkeypatch)
    banded = buffers(cam, cloud, precision, True, monkeypatch)
    assert tiled["count"].sum() > 1000
    for key in BUFFERS:
        assert np.array_equal(tiled[key], banded[key]), key


def test_band_path_against_an_opaque_layer(monkeypatch):
    cam = CAMERAS["perspective"]
    cloud = mixed_cloud(2, False)
    from unmesh.render.shading import GBuffer
    opaque = GBuffer.empty(*cam.shape)
    opaque.depth[:, : cam.shape[1] // 2] = 2.0  # a wall in front of the left half
    tiled = buffers(cam, cloud, "double", False, monkeypatch, opaque)
    banded = buffers(cam, cloud, "double", True, monkeypatch, opaque)
    for key in BUFFERS:
        assert np.array_equal(tiled[key], banded[key]), key


@pytest.mark.parametrize("camname", list(CAMERAS))
def test_band_rows_cover_every_box_row_once(camname):
    """Brute force: each surfel's rows in band order are exactly the bands its pixel box meets,
    with the box clipped to the band, front-facing surfels first, then ascending."""
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
    view = (cam.rotation, cam.eye, f, cx, cy, ortho, near, w, h, 1.0, BAND_SHIFT)
    offsets, starts, total = band_count(a.positions, a.normals, a.radii, axes, True, *view, 3)
    rows = np.empty((total, NPARAM))
    items = np.empty(total, dtype=np.int32)
    band_setup(a.positions, a.normals, a.radii, axes, True, a.colors, *view, starts, rows, items)
    band = 1 << BAND_SHIFT
    for b in range(len(offsets) - 1):
        sel = items[offsets[b]:offsets[b + 1]]
        r = rows[offsets[b]:offsets[b + 1]]
        y0, y1 = b * band, min(h, (b + 1) * band) - 1
        meets = (box[:, 0] <= box[:, 1]) & (box[:, 2] <= np.minimum(box[:, 3], y1)) & (np.maximum(box[:, 2], y0) <= box[:, 3])
        # every surfel whose box meets the band is there (others only with empty clipped boxes)
        got = sel[(r[:, 19] <= r[:, 20]) & (r[:, 21] <= r[:, 22])]
        assert np.array_equal(np.sort(got), np.flatnonzero(meets))
        assert np.array_equal(sel, sel[np.lexsort((sel, group[sel]))])
        assert np.array_equal(r[:, :21], P[sel, :21], equal_nan=True)
        ok = (r[:, 21] <= r[:, 22])
        assert np.all(r[ok, 21] == np.maximum(box[sel[ok], 2], y0))
        assert np.all(r[ok, 22] == np.minimum(box[sel[ok], 3], y1))
