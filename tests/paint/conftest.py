import numpy as np
import pytest

from unmesh.paint import Brush, Paint, PaintOptions, Sample, Session
from unmesh.shapes import by_name


@pytest.fixture(scope="module")
def plane_cloud():
    return by_name("plane", size=1.0).surfels(0.04)


def line(n=8, z=0.0, pressure=0.8, x0=-0.2, x1=0.2, t0=0.0):
    """Samples along x on the y=0 plane (its normal is +y)."""
    return [Sample(t0 + 0.05 * i, (x0 + (x1 - x0) * i / max(n - 1, 1), 0.0, z), pressure) for i in range(n)]


@pytest.fixture
def session(plane_cloud):
    return Session(plane_cloud, PaintOptions(haptics=False))


RED = Paint("oil", (0.9, 0.1, 0.1))
BLUE = Paint("watercolor", (0.1, 0.2, 0.9))
ROUND = Brush("round", 0.04)
__all__ = ["BLUE", "RED", "ROUND", "line", "np"]
