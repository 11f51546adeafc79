"""Shared test fixtures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

#: Classic test models shipped beside the repository (never needed by the package).
MODELS_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "models"


@pytest.fixture
def models_dir() -> Path:
    """Directory of the classic test models; skips the test when it is absent."""
    if not MODELS_DIR.is_dir():
        pytest.skip(f"test models not found at {MODELS_DIR}")
    return MODELS_DIR


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator (same numbers in every run)."""
    return np.random.default_rng(12345)
