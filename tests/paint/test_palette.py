"""The palette (chapter 5) in the engine's image (5.7): an inset equal to the palette's own render."""

import numpy as np
import pytest

from tests.paint.conftest import ROUND
from unmesh.errors import InputError
from unmesh.paint import Paint, PaintOptions, Palette, PaletteInset, Sample, Session
from unmesh.paint.palette import PALETTE_COLOR, palette_cloud
from unmesh.render import Camera
from unmesh.shapes import by_name

CAM = Camera((0.3, 1.2, 0.8), (0, 0, 0), width=200, height=150, fov=40)
GREEN = Paint("oil", (0.1, 0.7, 0.2), relief="none")


def test_inset_windows():
    assert PaletteInset().window(400, 300) == (300 - 8 - 72, 300 - 8, 8, 128)
    assert PaletteInset(corner="top-right", width=0.25).window(400, 300) == (8, 68, 292, 392)
    r0, r1, c0, c1 = PaletteInset(width=1.0, margin=0).window(100, 20)
    assert (r1 - r0, c1 - c0) == (20, 100)  # height capped at the image's
    for bad in ({"corner": "middle"}, {"width": 0.0}, {"width": 1.5}, {"margin": -1}, {"margin": 2.5}):
        with pytest.raises(InputError, match=r"inset\."):
            PaletteInset(**bad)


def test_palette_plane():
    c = palette_cloud(1.0, 0.5, 0.1)
    assert len(c) == 11 * 6 and np.allclose(c.normals, [0, 0, 1]) and np.allclose(c.colors, PALETTE_COLOR)
    with pytest.raises(InputError, match="spacing"):
        palette_cloud(spacing=0.0)


def test_palette_drawn_in_the_engine_image():
    s = Session(by_name("plane", size=1.0).surfels(0.04), PaintOptions(haptics=False))
    p = Palette(inset=PaletteInset(corner="top-right", width=0.4))
    plain = np.array(s.render(CAM, brush=False).color)
    # paint green on the palette: the palette session is painted like the object
    p.session.stroke([Sample(0.05 * i, (-0.3 + 0.1 * i, 0.0, 0.0), 0.8) for i in range(6)], brush=ROUND, paint=GREEN)
    with_palette = s.render(CAM, brush=False, palette=p).color
    r0, r1, c0, c1 = p.inset.window(CAM.width, CAM.height)
    own = p.render(c1 - c0, r1 - r0, brush=True).color
    np.testing.assert_array_equal(with_palette[r0:r1, c0:c1], own)  # the palette's own render
    assert (np.abs(own - GREEN.color).sum(axis=2) < 0.2).sum() > 20  # its green paint shows
    assert (np.abs(own - PALETTE_COLOR).sum(axis=2) < 0.02).mean() > 0.5  # on the off-white plane
    outside = np.ones(plain.shape[:2], bool)
    outside[r0:r1, c0:c1] = False
    np.testing.assert_array_equal(with_palette[outside], plain[outside])  # the object is unchanged
    # without the palette the object's pixels come back (the inset window is recomposed)
    np.testing.assert_array_equal(s.render(CAM, brush=False).color, plain)
    # the paint on the palette loads the brush
    rows, cols = np.nonzero(np.abs(p.render().albedo - GREEN.color).sum(axis=2) < 0.05)
    np.testing.assert_allclose(p.color_at(cols[0] + 0.5, rows[0] + 0.5), GREEN.color, atol=0.05)
    with pytest.raises(InputError, match="x, y"):
        p.color_at(-1, 0)
