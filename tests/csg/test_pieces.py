"""Pieces of a patch (4.1.2): the union-find kernel against scipy's connected components."""

import numpy as np
import pytest

from unmesh.csg.frame import _pieces, pieces_reference
from unmesh.csg.model import Patch
from unmesh.surfels import SurfelCloud


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_piece_labels_equal_scipy_reference(seed):
    rng = np.random.default_rng(seed)
    leaves = [Patch.halfspace((0, 0, 0), (0, 0, 1), extent=2.0, spacing=0.1),
              Patch.halfspace((0, 0, 0), (1, 0, 0), extent=2.0, spacing=0.13)]
    pos = rng.uniform(-1, 1, (300, 3))
    leaves.append(Patch(SurfelCloud(pos, np.tile([0, 0, 1.0], (300, 1)), radii=rng.uniform(0.02, 0.15, 300))))
    sizes = [len(p.cloud) for p in leaves]
    for frac in (0.0, 0.1, 0.5):
        edge = rng.uniform(size=sum(sizes)) < frac
        edge[:40] = True  # a band cuts the first sheet
        got = _pieces(leaves, sizes, edge)
        ref = pieces_reference(leaves, sizes, edge)
        assert np.array_equal(got, ref)
        assert got.max() >= 2
