import numpy as np
import pytest

from unmesh import Particles
from unmesh.errors import InputError


def test_particles_basics():
    p = Particles(np.zeros((3, 3)), radii=[1, 2, 3], attributes={"density": [1, 2, 3]})
    assert len(p) == 3
    s = p.subset([2])
    np.testing.assert_array_equal(s.radii, [3])
    np.testing.assert_array_equal(s.attributes["density"], [3])


def test_particles_validation():
    with pytest.raises(InputError, match=r"radii: expected positive values, got 0\.0 at index 1"):
        Particles(np.zeros((2, 3)), radii=[1, 0])
    with pytest.raises(InputError, match="attributes\\['d'\\]"):
        Particles(np.zeros((2, 3)), attributes={"d": [1]})
