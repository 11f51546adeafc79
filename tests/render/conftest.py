"""Fixtures of the render tests: Fibonacci-sphere surfel clouds built directly (no sampler)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import SurfelCloud


def fibonacci_sphere(n: int, radius: float = 1.0, radius_factor: float = 0.9, color=(0.2, 0.6, 0.4),
                     center=(0.0, 0.0, 0.0)) -> SurfelCloud:
    """``n`` surfels on a sphere (golden-angle spiral), radii ``radius_factor`` times the spacing."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5**0.5) * i
    p = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    h = np.sqrt(4 * np.pi / n) * radius
    colors = np.tile(np.asarray(color, dtype=float), (n, 1))
    return SurfelCloud(p * radius + np.asarray(center), p, radii=np.full(n, radius_factor * h), colors=colors,
                       attributes={"height": p[:, 1] * radius})


@pytest.fixture(scope="session")
def sphere5k() -> SurfelCloud:
    return fibonacci_sphere(5000)


@pytest.fixture(scope="session")
def sphere20k() -> SurfelCloud:
    return fibonacci_sphere(20000)
