"""Shared MLS fixtures: a unit sphere and a torus (R=1, r=0.35) sampled with spacing 0.02."""

from __future__ import annotations

import pytest

from unmesh.mls import MLSSurface

from . import samples as S
from .samples import H


@pytest.fixture(scope="session")
def sphere_surface() -> MLSSurface:
    return MLSSurface(S.sphere_cloud(H))


@pytest.fixture(scope="session")
def torus_surface() -> MLSSurface:
    return MLSSurface(S.torus_cloud(H))


@pytest.fixture(scope="session")
def small_sphere_surface() -> MLSSurface:
    """A coarse sphere (spacing 0.1, 1451 samples) for reference comparisons."""
    return MLSSurface(S.sphere_cloud(0.1))

