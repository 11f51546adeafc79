import numpy as np
import pytest

from unmesh.surfels import SurfelCloud


def fibonacci_sphere(n: int, radius: float = 1.0) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return radius * np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]


@pytest.fixture(scope="session")
def sphere_cloud() -> SurfelCloud:
    """4000 surfels on the unit sphere, coloured by a smooth pattern."""
    p = fibonacci_sphere(4000)
    spacing = np.sqrt(4 * np.pi / 4000)
    col = 0.5 + 0.4 * np.c_[np.sin(3 * p[:, 0]), np.cos(2 * p[:, 1]), p[:, 2]]
    return SurfelCloud(p, p, radii=np.full(len(p), 0.7 * spacing), colors=col)


@pytest.fixture(scope="session")
def pattern_cloud() -> SurfelCloud:
    """8000 surfels on the unit sphere with a smooth colour pattern (the PSNR test's input)."""
    n = 8000
    p = fibonacci_sphere(n)
    spacing = np.sqrt(4 * np.pi / n)
    col = 0.5 + 0.4 * np.c_[np.sin(5 * p[:, 0]), np.cos(4 * p[:, 1]), np.sin(6 * p[:, 2])]
    return SurfelCloud(p, p, radii=np.full(n, 0.7 * spacing), colors=col)


@pytest.fixture(scope="session")
def converted(pattern_cloud):
    """The conversion of ``pattern_cloud`` at the default thresholds."""
    from unmesh.convert import convert_cloud

    return convert_cloud(pattern_cloud)
