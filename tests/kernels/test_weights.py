"""MLS weight functions (eqs. 3.10-3.13) against their definitions and stated properties."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.kernels import clipped_gaussian, elliptical_distance, elliptical_weight, gaussian, wendland_c2


def test_gaussian_values_and_broadcasting():
    d = np.linspace(0, 3, 7)
    np.testing.assert_allclose(gaussian(d, 1.5), np.exp(-(d**2) / 1.5**2))
    sig = np.array([0.5, 1.0, 2.0])
    out = gaussian(np.ones((4, 3)), sig)
    assert out.shape == (4, 3)
    np.testing.assert_allclose(out[0], np.exp(-1 / sig**2))
    assert float(gaussian(0.0, 0.1)) == 1.0


def test_clipped_gaussian_cutoff_is_c_sigma_not_c_sigma_squared():
    # NOTES.md (3.11): cut-off d < c*sigma. With sigma = 0.5, c = 3: c*sigma = 1.5 but c*sigma^2 = 0.75.
    sigma, c = 0.5, 3.0
    assert float(clipped_gaussian(1.4, sigma, c)) == pytest.approx(np.exp(-(1.4**2) / 0.25))
    assert float(clipped_gaussian(1.5, sigma, c)) == 0.0
    assert float(clipped_gaussian(1.6, sigma, c)) == 0.0
    d = np.linspace(0, 1.49, 50)
    np.testing.assert_allclose(clipped_gaussian(d, sigma, c), gaussian(d, sigma))
    # scaling invariance: the cut-off scales with sigma
    assert float(clipped_gaussian(2.9 * 7.0, 7.0, 3.0)) > 0.0


def test_wendland_c2_printed_form_is_not_smooth_but_corrected_is():
    r = 1.3
    d = np.linspace(0, r, 1001)
    w = wendland_c2(d, r)
    assert float(w[0]) == 1.0
    assert np.all(np.diff(w) <= 0)  # monotone, single maximum at 0
    # C2 at the sample: w'(0) = 0 (the printed (1 + d/r) has w'(0) = -3/r)
    eps = 1e-6
    assert abs((float(wendland_c2(eps, r)) - 1.0) / eps) < 1e-4
    printed = lambda x: (1 - x / r) ** 4 * (1 + x / r)  # noqa: E731
    assert (printed(eps) - 1.0) / eps == pytest.approx(-3.0 / r, rel=1e-4)
    # w, w', w'' vanish at the support radius (one-sided finite differences)
    h = 1e-4
    vals = np.array([float(wendland_c2(r - k * h, r)) for k in range(3)])
    assert vals[0] == 0.0
    assert abs(vals[1]) < 1e-12
    assert abs((vals[2] - 2 * vals[1] + vals[0]) / h**2) < 1e-5
    assert float(wendland_c2(r * 1.01, r)) == 0.0
    # second derivative is continuous in 3D as a function of position: w''(0) finite, matches FD of both sides
    x = np.array([-2e-3, -1e-3, 0.0, 1e-3, 2e-3])
    vals = wendland_c2(np.abs(x), r)
    left = (vals[0] - 2 * vals[1] + vals[2]) / 1e-6
    right = (vals[2] - 2 * vals[3] + vals[4]) / 1e-6
    assert left == pytest.approx(right, rel=1e-9)
    assert left == pytest.approx(-20 / r**2, rel=1e-2)


def test_elliptical_weight_reduces_to_radial_for_circles():
    rng = np.random.default_rng(1)
    s = 0.7
    t1 = np.array([s, 0, 0.0])
    t2 = np.array([0, s, 0.0])
    d = rng.normal(size=(100, 3))
    radial = np.linalg.norm(d[:, :2], axis=1) / s  # normal (z) component ignored
    np.testing.assert_allclose(elliptical_distance(d, t1, t2), radial)
    np.testing.assert_allclose(elliptical_weight(d, t1, t2), np.exp(-(radial**2)))
    np.testing.assert_allclose(elliptical_weight(d, t1, t2, "wendland_c2", r=2.0), wendland_c2(radial, 2.0))
    np.testing.assert_allclose(elliptical_weight(d, t1, t2, lambda rho: 1.0 / (1.0 + rho)), 1 / (1 + radial))


def test_elliptical_weight_unit_on_the_ellipse_and_per_sample_axes():
    # points on the ellipse spanned by (rotated) tangent axes have rho = 1
    rng = np.random.default_rng(2)
    n = 50
    a, b = rng.uniform(0.1, 2, n), rng.uniform(0.1, 2, n)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    t1 = a[:, None] * q[0]
    t2 = b[:, None] * q[1]
    phi = rng.uniform(0, 2 * np.pi, n)
    d = np.cos(phi)[:, None] * t1 + np.sin(phi)[:, None] * t2 + rng.normal(size=(n, 1)) * q[2]
    np.testing.assert_allclose(elliptical_distance(d, t1, t2), 1.0)
    np.testing.assert_allclose(elliptical_weight(d, t1, t2, "clipped_gaussian", sigma=0.5, c=1.99), 0.0)
    np.testing.assert_allclose(elliptical_weight(d, t1, t2, "clipped_gaussian", sigma=0.5, c=2.1), np.exp(-4.0))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: gaussian(-1.0, 1.0), "d: expected distances >= 0"),
        (lambda: gaussian([0.0, np.nan], 1.0), "d: expected finite"),
        (lambda: gaussian(1.0, 0.0), "sigma: expected a positive"),
        (lambda: gaussian(1.0, [1.0, -2.0]), "sigma: expected a positive"),
        (lambda: gaussian("x", 1.0), "d: expected a number"),
        (lambda: clipped_gaussian(1.0, 1.0, c=0), "c: expected a positive"),
        (lambda: wendland_c2(1.0, -1.0), "r: expected a positive"),
        (lambda: elliptical_distance([1.0, 2.0], [1, 0, 0], [0, 1, 0]), r"dvec: expected shape \(\.\.\., 3\)"),
        (lambda: elliptical_distance([1.0, 2.0, 3.0], [0, 0, 0], [0, 1, 0]), "non-zero tangent axes"),
        (lambda: elliptical_weight([1.0, 2.0, 3.0], [1, 0, 0], [0, 1, 0], kernel="box"), "kernel: expected one of"),
        (lambda: elliptical_weight([1.0, 2.0, 3.0], [1, 0, 0], [0, 1, 0], kernel="gaussian", r=2), "unexpected"),
    ],
)
def test_bad_inputs_raise_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()
