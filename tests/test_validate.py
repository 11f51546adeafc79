import numpy as np
import pytest

from unmesh._validate import as_array, as_indices, as_points, positive_scalar, scalar
from unmesh.errors import InputError


def test_as_points_converts_dtype_and_layout():
    pts = np.asfortranarray(np.arange(12, dtype=np.int32).reshape(4, 3))
    out = as_points(pts)
    assert out.dtype == np.float64 and out.flags.c_contiguous
    np.testing.assert_array_equal(out, pts)


def test_as_points_single_point_and_empty():
    assert as_points([1, 2, 3]).shape == (1, 3)
    assert as_points(np.zeros((0, 3))).shape == (0, 3)
    assert as_points([]).shape == (0, 3)


@pytest.mark.parametrize(
    "value, fragment",
    [
        (np.zeros((4, 2)), "expected shape (N, 3), got (4, 2)"),
        ([[0, 0, 0], [0, np.nan, 0]], "NaN or infinity at index 1"),
        ([[0, 0, np.inf]], "NaN or infinity at index 0"),
        ([["a", "b", "c"]], "expected numbers"),
        ([[0, 0], [0, 0, 0]], "points"),
    ],
)
def test_as_points_rejects(value, fragment):
    with pytest.raises(InputError, match="points") as info:
        as_points(value)
    assert fragment in str(info.value)


def test_as_array_length_and_wildcards():
    assert as_array(np.zeros((2, 2, 3)), "axes", (None, 2, 3), length=2).shape == (2, 2, 3)
    with pytest.raises(InputError, match="expected 3 rows"):
        as_array(np.zeros((2, 3)), "normals", (None, 3), length=3)


def test_as_indices_bounds_and_integrality():
    out = as_indices([[0, 1, 2]], "faces", (None, 3), upper=3)
    assert out.dtype == np.int64
    with pytest.raises(InputError, match=r"faces: expected indices in \[0, 3\), got \[0, 1, 3\] at index 0"):
        as_indices([[0, 1, 3]], "faces", (None, 3), upper=3)
    with pytest.raises(InputError, match="integer"):
        as_indices([[0.5, 1, 2]], "faces", (None, 3))
    np.testing.assert_array_equal(as_indices([[0.0, 1.0, 2.0]], "faces", (None, 3)), [[0, 1, 2]])


def test_scalars():
    assert scalar("2.5", "x") == 2.5
    assert positive_scalar(3, "radius") == 3.0
    for bad in (0, -1):
        with pytest.raises(InputError, match="radius: expected a positive number"):
            positive_scalar(bad, "radius")
    with pytest.raises(InputError, match="finite"):
        scalar(float("nan"), "x")
    with pytest.raises(InputError, match=">= 0"):
        scalar(-1, "x", minimum=0)
    with pytest.raises(InputError, match="expected a number"):
        scalar("abc", "x")
