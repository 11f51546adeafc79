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


#: Test folders in the order their work is handed out, the longest first (seconds in the cold CI
#: run of 2026-12-04 at d195f08: sph 321, shells 225, fem 150, paint 102, csg 66, surfels 64,
#: spatial 63, render 54, mls 32, kernels 25, convert 25, batch 20, shapes 20); the others follow
#: in collection order.
_LONGEST_FIRST = ("sph", "shells", "fem", "paint", "csg", "surfels", "spatial", "render", "mls", "kernels", "convert",
                  "batch", "shapes")


def _folder(nodeid: str) -> str:
    """``tests/<folder>`` of a test in a capability folder, else its file."""
    parts = nodeid.split("::", 1)[0].split("/")
    return "/".join(parts[:2] if len(parts) > 2 else parts)


def pytest_collection_modifyitems(config, items):
    """Longest folders first (a stable sort: the order inside a folder is kept)."""
    rank = {f"tests/{name}": k for k, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(_folder(item.nodeid), len(rank)))


def pytest_xdist_make_scheduler(config, log):
    """With ``--dist loadfile`` (the default of this project), hand out whole capability folders:
    the numba kernels of a capability then compile in one worker only, not in both at once
    (a cold run compiled SPH's lattice pass, about a minute, twice in parallel)."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ByFolder(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _folder(nodeid)

    config.option.loadscopereorder = False     # keep the longest-first order of the collection
    return ByFolder(config, log)
