"""Fixtures of the FEM tests."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def poly_rng() -> np.random.Generator:
    return np.random.default_rng(2024)
