"""Shared fixtures for the thin-shell tests: small surfel clouds and simulations."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.surfels import SurfelCloud


class Box:
    """An axis-aligned box region (``contains``), for pinned / handle / pull regions."""

    def __init__(self, lo, hi):
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)

    def contains(self, x):
        return np.all((np.asarray(x) >= self.lo) & (np.asarray(x) <= self.hi), axis=1)


def fibonacci_cloud(n: int, radius: float = 1.0) -> SurfelCloud:
    """A sphere sampled with n Fibonacci points, outward normals."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    nrm = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)
    r = radius * np.sqrt(4 * np.pi / n) * 0.7
    return SurfelCloud(radius * nrm, nrm, radii=np.full(n, r))


def grid_cloud(nx: int, ny: int, spacing: float) -> SurfelCloud:
    """A regular sheet of surfels in the x-z plane (normal +y), centred at the origin."""
    gx, gz = np.meshgrid((np.arange(nx) - (nx - 1) / 2) * spacing, (np.arange(ny) - (ny - 1) / 2) * spacing,
                         indexing="ij")
    p = np.stack([gx.ravel(), np.zeros(nx * ny), gz.ravel()], axis=1)
    return SurfelCloud(p, np.tile([0.0, 1.0, 0.0], (len(p), 1)), radii=np.full(len(p), 0.75 * spacing))


def grid_nodes(nx: int, ny: int, step: int) -> np.ndarray:
    """Indices of every ``step``-th surfel in both directions of :func:`grid_cloud`."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    return np.flatnonzero(((i % step) == 0).ravel() & ((j % step) == 0).ravel())


def sphere_with_nodes(nodes: int = 300, dense: int = 2700, radius: float = 1.0) -> tuple[SurfelCloud, np.ndarray]:
    """A dense sphere cloud whose first ``nodes`` surfels are a Fibonacci node set."""
    return SurfelCloud.concatenate([fibonacci_cloud(nodes, radius), fibonacci_cloud(dense, radius)]), np.arange(nodes)


@pytest.fixture(scope="session")
def sphere_setup() -> tuple[SurfelCloud, np.ndarray]:
    return sphere_with_nodes()
