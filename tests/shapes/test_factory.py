"""The by_name factory and shape parameters."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.shapes import SHAPES, Blob, Shape, by_name, parameters


def test_every_name_builds_a_shape_with_the_protocol():
    assert set(SHAPES) == {"sphere", "box", "cylinder", "torus", "disc", "plane", "blob"}
    for name in SHAPES:
        s = by_name(name.upper())
        assert isinstance(s, Shape)
        assert s.bounds().shape == (2, 3)
        assert s.area() > 0
        assert name in repr(s).lower() or type(s).__name__.lower() == name


def test_parameters_are_passed():
    s = by_name("cylinder", radius=0.25, height=2.0, axis=[1, 0, 0], center=(0, 1, 0))
    assert s.radius == 0.25 and s.height == 2.0
    np.testing.assert_allclose(s.axis, [1, 0, 0])
    np.testing.assert_allclose(s.bounds(), [[-1, 0.75, -0.25], [1, 1.25, 0.25]], atol=1e-12)
    assert by_name("blob", scale=2.0).scale == 2.0
    assert parameters("torus") == {"center": (0.0, 0.0, 0.0), "major": 1.0, "minor": 0.35, "axis": None,
                                   "rotation": None}


def test_errors_list_names_and_parameters():
    with pytest.raises(InputError, match="blob, box, cylinder, disc, plane, sphere, torus"):
        by_name("bunny")
    with pytest.raises(InputError, match="unknown parameter radus; expected center, radius, rotation"):
        by_name("sphere", radus=1.0)
    with pytest.raises(InputError, match="sphere: radius: expected a positive number"):
        by_name("sphere", radius=-1)
    with pytest.raises(InputError, match="torus: minor"):
        by_name("torus", major=0.5, minor=0.6)
    with pytest.raises(InputError, match="axis or rotation"):
        by_name("cylinder", axis=(0, 0, 1), rotation=np.eye(3))
    with pytest.raises(InputError, match="size"):
        by_name("box", size=(1, -1, 1))
    with pytest.raises(InputError, match="rotation"):
        by_name("box", rotation=np.diag([1.0, 1.0, -1.0]))


def test_moved_scales_about_the_shape_centre():
    b = Blob(center=(1.0, 0.0, 0.0))
    big = b.moved(scale=2.0)
    np.testing.assert_allclose(big.center, b.center)
    np.testing.assert_allclose(big.volume(), 8 * b.volume())
    np.testing.assert_allclose(big.bounds() - big.center, 2 * (b.bounds() - b.center), rtol=1e-9)
