"""Colormaps and legends."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import SurfelCloud, TriangleMesh
from unmesh.errors import InputError
from unmesh.render import COLORMAPS, colormap, draw_legend
from unmesh.render.colormap import attribute_values, map_colors, value_range


def test_viridis_endpoints_and_monotone_luminance():
    v = colormap("viridis")(np.linspace(0, 1, 50))
    assert np.allclose(v[0], [0.267, 0.004, 0.329], atol=2e-3)
    assert np.allclose(v[-1], [0.992, 0.906, 0.145], atol=2e-3)
    lum = v @ [0.2126, 0.7152, 0.0722]
    assert np.all(np.diff(lum) > 0)


def test_every_map_and_reverse_and_nan():
    for name in COLORMAPS:
        c = colormap(name)(np.array([0.0, 0.5, 1.0, np.nan]))
        assert c.shape == (4, 3) and np.all((c >= 0) & (c <= 1))
        assert np.allclose(c[3], 0.5)
    assert np.allclose(colormap("gray_r")(np.array([0.0])), 1.0)
    with pytest.raises(InputError):
        colormap("jet")


def test_attribute_values_and_ranges():
    c = SurfelCloud([[0, 0, 0], [1, 2, 3]], [[0, 0, 1]] * 2, radii=[0.1, 0.2], attributes={"v": np.array([[3.0, 4, 0], [0, 0, 1]])})
    assert attribute_values(c, "v").tolist() == [5.0, 1.0]
    assert attribute_values(c, "y").tolist() == [0.0, 2.0]
    assert attribute_values(c, "radius").tolist() == [0.1, 0.2]
    m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], attributes={"stress": [1.0, 2.0, 3.0]})
    assert attribute_values(m, "stress").tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(InputError, match="available: v, x, y, z, radius"):
        attribute_values(c, "nope")
    assert value_range([np.array([2.0, 2.0])]) == (1.0, 3.0)
    assert value_range([np.array([np.nan, 1.0, 5.0])]) == (1.0, 5.0)
    with pytest.raises(InputError):
        value_range([], (3, 1))
    assert np.allclose(map_colors(np.array([5.0]), 0, 10, "gray"), 0.5)


def test_legend_is_drawn_on_the_right_and_leaves_the_rest():
    img = np.ones((200, 300, 3))
    out = draw_legend(img, -1.0, 2.5, "viridis", label="pressure")
    changed = np.abs(out - img).sum(-1) > 1e-9
    cols = np.flatnonzero(changed.any(axis=0))
    assert cols.min() > 150 and cols.max() < 300
    assert out.shape == img.shape and np.all((out >= 0) & (out <= 1))
    tiny = draw_legend(np.ones((10, 10, 3)), 0, 1)
    assert np.array_equal(tiny, np.ones((10, 10, 3)))
