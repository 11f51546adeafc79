"""MLS-weighted interpolation of per-surfel attributes (eqs. 3.6, 3.10-3.12)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import mls
from unmesh.errors import InputError
from unmesh.mls import MLSSurface
from unmesh.surfels import SurfelCloud

from . import reference as ref
from . import samples as S


@pytest.fixture(scope="module")
def varying_cloud() -> SurfelCloud:
    return S.varying_sphere_cloud(0.04, ratio=5.0)


def _points(cloud, n, rng, scale=2.0):
    idx = rng.choice(len(cloud), n, replace=False)
    return cloud.positions[idx] + rng.normal(0, 1, (n, 3)) * scale * cloud.radii[idx, None] / 3


@pytest.mark.parametrize("kernel", ["gaussian", "wendland"])
def test_interpolate_equals_reference(kernel, varying_cloud, rng):
    surf = MLSSurface(varying_cloud, kernel=kernel)
    x = np.r_[_points(varying_cloud, 300, rng), [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]]  # the last two: no kernel
    vals = rng.normal(size=(len(varying_cloud), 4))
    got = mls.interpolate(surf, x, vals)
    want = ref.interpolate(surf, x, vals)
    assert got.shape == (len(x), 4)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_weights_are_the_projection_weights(varying_cloud, rng):
    """Interpolating the positions gives the weighted mean q of the local fit (3.6)."""
    surf = MLSSurface(varying_cloud)
    x = _points(varying_cloud, 50, rng)
    q = mls.interpolate(surf, x, varying_cloud.positions)
    for xx, qq in zip(x[:10], q[:10], strict=True):
        np.testing.assert_allclose(qq, ref.local_fit(surf, xx)[2], atol=1e-12)


def test_partition_of_unity_and_bounds(varying_cloud, rng):
    x = _points(varying_cloud, 500, rng)
    np.testing.assert_allclose(mls.interpolate(varying_cloud, x, np.ones(len(varying_cloud))), 1.0, rtol=1e-14)
    v = rng.uniform(0.2, 0.7, len(varying_cloud))
    got = mls.interpolate(varying_cloud, x, v)
    assert got.shape == (500,)
    assert got.min() >= 0.2 and got.max() <= 0.7  # a convex combination


def test_smooth_field_converges(rng):
    """A smooth field sampled on finer spheres is reproduced with an error that falls like sigma^2."""
    errs = []
    for h in (0.08, 0.04, 0.02):
        c = S.sphere_cloud(h)
        f = np.sin(2 * c.positions[:, 0]) + c.positions[:, 2] ** 2
        pts, _ = S.sphere_surface_points(2000, np.random.default_rng(1))
        exact = np.sin(2 * pts[:, 0]) + pts[:, 2] ** 2
        errs.append(np.abs(mls.interpolate(c, pts, f) - exact).max())
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(rates > 1.7), (errs, rates)


def test_out_of_reach_points_take_the_nearest_surfel():
    c = SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]] * 2, radii=[0.1, 0.1])
    v = np.array([[1.0, 2.0], [3.0, 4.0]])
    got = mls.interpolate(c, [[-5.0, 0, 0], [0.9, 3.0, 0], [0.5, 0, 0]], v)
    np.testing.assert_array_equal(got[:2], [[1.0, 2.0], [3.0, 4.0]])
    np.testing.assert_allclose(got[2], [2.0, 3.0])  # midway, equal weights (both kernels cut at 0.6 > 0.5)


def test_chunks_options_and_shapes(varying_cloud, rng):
    x = _points(varying_cloud, 200, rng)
    v = rng.normal(size=(len(varying_cloud), 3))
    a = mls.interpolate(varying_cloud, x, v)
    np.testing.assert_array_equal(a, mls.interpolate(varying_cloud, x, v, chunk_size=7))
    np.testing.assert_array_equal(a, mls.interpolate(MLSSurface(varying_cloud), x, v))
    np.testing.assert_array_equal(a[5], mls.interpolate(varying_cloud, x[5], v)[0])
    w = mls.interpolate(varying_cloud, x, v, kernel="wendland")
    assert np.abs(w - a).max() > 1e-6  # the option reaches the weights
    assert mls.interpolate(varying_cloud, np.empty((0, 3)), v).shape == (0, 3)
    ints = mls.interpolate(varying_cloud, x, np.arange(len(varying_cloud)))
    assert ints.dtype == np.float64


@pytest.mark.parametrize(
    ("values", "match"),
    [
        (np.zeros(3), r"values: expected shape \(1814,\) or \(1814, k\)"),
        (np.zeros((1814, 2, 2)), r"values: expected shape"),
        ([["a"]] * 1814, "values: expected a numeric array"),
    ],
)
def test_bad_values(values, match, varying_cloud):
    with pytest.raises(InputError, match=match):
        mls.interpolate(varying_cloud, [[0, 0, 1.0]], values)


def test_bad_points_and_options(varying_cloud):
    v = np.zeros(len(varying_cloud))
    with pytest.raises(InputError, match="points: expected finite"):
        mls.interpolate(varying_cloud, [[0, 0, np.nan]], v)
    with pytest.raises(InputError, match="unknown MLS option"):
        mls.interpolate(varying_cloud, [[0, 0, 1.0]], v, smoothing=2)
