"""Geometry discontinuity surfels (4.3): invisible surfels that clip their neighbours to clean
crack edges (the thin shells' crack surfels, 7.4)."""

import numpy as np

from unmesh import SurfelCloud
from unmesh.render import Camera, render
from unmesh.render.splat import ClipSurfels, discontinuity_clip, surfel_arrays


def _torn_sheet(h=0.05, gap=0.1, with_discs=True):
    """A plane z = 0 torn along x = 0: the right half moved by ``gap``; a pair of crack surfels
    (facing the gap, spanning the crack line and the surface normal) every ``h`` along y."""
    g = np.arange(-1 + h / 2, 1, h)
    x, y = np.meshgrid(g, g, indexing="ij")
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    pos[pos[:, 0] > 0, 0] += gap
    sheet = SurfelCloud(pos, np.tile([0, 0, 1.0], (len(pos), 1)), radii=np.full(len(pos), 0.75 * h),
                        colors=np.tile([0.2, 0.4, 0.9], (len(pos), 1)))
    if not with_discs:
        return sheet
    ys = np.arange(-1, 1 + h, h)
    dpos = np.concatenate([np.stack([np.zeros_like(ys), ys, np.zeros_like(ys)], 1),
                           np.stack([np.full_like(ys, gap), ys, np.zeros_like(ys)], 1)])
    dnrm = np.concatenate([np.tile([1.0, 0, 0], (len(ys), 1)), np.tile([-1.0, 0, 0], (len(ys), 1))])
    axes = np.tile([[[0, h, 0], [0, 0, h]]], (len(dpos), 1, 1))
    discs = SurfelCloud(dpos, dnrm, axes=axes, attributes={"discontinuity": np.ones(len(dpos))})
    return [sheet.replace(attributes={"discontinuity": np.zeros(len(sheet))}), discs]


def test_crack_surfels_cut_clean_edges():
    cam = Camera((0.05, 0, 3), (0.05, 0, 0), width=128, height=64, ortho=0.4)
    clean = render(_torn_sheet(), cam, shading="none")
    raw = render(_torn_sheet(with_discs=False), cam, shading="none")
    px = 0.4 / 64  # world units per pixel
    xs = 0.05 + (np.arange(128) + 0.5 - 64) * px  # world x of the pixel columns
    in_gap = (xs > px) & (xs < 0.1 - px)
    on_sheet = (xs < -px) | (xs > 0.1 + px)
    assert not clean.coverage[:, in_gap].any()  # the crack is open and clean
    assert clean.coverage[:, on_sheet].all()  # and nothing else is cut
    assert raw.coverage[:, in_gap].any()  # without crack surfels the splats bleed into it
    # straight edges: every row ends at the same column
    last = np.array([np.flatnonzero(r[: 64])[-1] for r in clean.coverage])
    assert np.ptp(last) == 0


def test_coplanar_discontinuity_surfels_do_not_clip():
    a = surfel_arrays(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]))
    flat = ClipSurfels([[0.2, 0, 0.0]], [[0, 0.3, 1.0]], [[[0.5, 0, 0], [0, 0.5, 0]]], [1])
    assert discontinuity_clip(a, flat) is None
    across = ClipSurfels([[0.2, 0, 0.0]], [[1.0, 0, 0]], [[[0, 0.5, 0], [0, 0, 0.5]]], [1])
    assert discontinuity_clip(a, across) is not None
    behind = ClipSurfels([[-0.2, 0, 0.0]], [[1.0, 0, 0]], [[[0, 0.5, 0], [0, 0, 0.5]]], [1])
    assert discontinuity_clip(a, behind) is None  # the surfel's centre is in front: the other side's surfel


def _painted_sheet(h=0.05, with_discs=True):
    """A plane z = 0, red for x < 0 and blue for x > 0 (the boundary between samples), with a
    pair of texture discontinuity surfels along x = 0 (facing either way)."""
    g = np.arange(-1 + h / 2, 1, h)
    x, y = np.meshgrid(g, g, indexing="ij")
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    col = np.where(pos[:, :1] < 0, [1.0, 0, 0], [0, 0, 1.0])
    sheet = SurfelCloud(pos, np.tile([0, 0, 1.0], (len(pos), 1)), radii=np.full(len(pos), 0.75 * h), colors=col,
                        attributes={"discontinuity": np.zeros(len(pos))})
    if not with_discs:
        return sheet
    ys = np.arange(-1, 1 + h, h)
    p = np.stack([np.zeros_like(ys), ys, np.zeros_like(ys)], 1)
    dpos = np.concatenate([p, p])
    dnrm = np.concatenate([np.tile([1.0, 0, 0], (len(ys), 1)), np.tile([-1.0, 0, 0], (len(ys), 1))])
    axes = np.tile([[[0, h, 0], [0, 0, h]]], (len(dpos), 1, 1))
    discs = SurfelCloud(dpos, dnrm, axes=axes, attributes={"discontinuity": np.full(len(dpos), 2)})
    return [sheet, discs]


def test_texture_discontinuity_surfels_clip_colour_only_fig_4_6():
    cam = Camera((0, 0, 3), (0, 0, 0), width=96, height=48, ortho=0.15)
    sharp = render(_painted_sheet(), cam, shading="none")
    soft = render(_painted_sheet(with_discs=False), cam, shading="none")
    # colour: a jump within one pixel column (blurred over several without the surfels)
    red = sharp.color[..., 0]
    mixed = ((red > 1e-9) & (red < 1 - 1e-9)).sum(axis=1)
    assert mixed.max() <= 1
    soft_mixed = ((soft.color[..., 0] > 1e-9) & (soft.color[..., 0] < 1 - 1e-9)).sum(axis=1)
    assert np.median(soft_mixed) >= 4
    # geometry blends across the texture edge as without the surfels
    np.testing.assert_array_equal(sharp.depth, soft.depth)
    np.testing.assert_array_equal(sharp.normal, soft.normal)
    assert sharp.coverage.all()
