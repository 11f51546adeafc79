"""Normalised SPH kernels (Appendix C, 8.1.1): normalisation, moments, derivatives, support."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from unmesh.errors import InputError
from unmesh.kernels import (
    GAUSSIAN,
    KERNELS,
    POLY6,
    SPIKY,
    WENDLAND_C2,
    get_kernel,
    poly6,
    poly6_derivative,
    poly6_gradient,
    poly6_laplacian,
    poly6_second_derivative,
    spiky,
    spiky_derivative,
    spiky_gradient,
    spiky_laplacian,
    spiky_second_derivative,
)

ALL = sorted(KERNELS)
H = 0.7


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("dim", [2, 3])
def test_normalised_radial_quadrature(name, dim):
    """(8.1): int 2 pi r w dr = 1 (2D), int 4 pi r^2 w dr = 1 (3D)."""
    k = get_kernel(name)
    upper = H * (k.support if np.isfinite(k.support) else 12.0)
    area = (lambda r: 2 * np.pi * r) if dim == 2 else (lambda r: 4 * np.pi * r * r)
    total, _ = integrate.quad(lambda r: area(r) * float(k.value(r, H, dim)), 0, upper, epsabs=1e-13, epsrel=1e-12)
    assert total == pytest.approx(1.0, abs=1e-10)


@pytest.mark.parametrize("name", ALL)
def test_normalised_cartesian_grid_2d_and_zero_first_moment(name):
    """Independent of the radial formula: midpoint rule on a Cartesian grid (2D)."""
    k = get_kernel(name)
    half = H * (k.support if np.isfinite(k.support) else 7.0)
    n = 1200
    x = (np.arange(n) + 0.5) / n * 2 * half - half
    dx = 2 * half / n
    xx, yy = np.meshgrid(x, x + 0.3 * dx, indexing="ij")  # off-centre grid: moments not zero by construction
    w = k.value(np.hypot(xx, yy), H, dim=2)
    assert w.sum() * dx * dx == pytest.approx(1.0, abs=2e-4)
    # first moment about the kernel centre vanishes (up to the grid offset)
    assert abs((w * xx).sum() * dx * dx) < 1e-9
    assert abs((w * yy).sum() * dx * dx) < 1e-5 * H


@pytest.mark.parametrize("name", ALL)
def test_normalised_cartesian_grid_3d_and_zero_first_moment(name):
    k = get_kernel(name)
    half = H * (k.support if np.isfinite(k.support) else 6.0)
    n = 140
    x = (np.arange(n) + 0.5) / n * 2 * half - half
    dx = 2 * half / n
    xx, yy, zz = np.meshgrid(x, x, x, indexing="ij", sparse=True)
    w = k.value(np.sqrt(xx**2 + yy**2 + zz**2), H, dim=3)
    assert w.sum() * dx**3 == pytest.approx(1.0, abs=2e-3)
    for c in (xx, yy, zz):
        assert abs((w * c).sum() * dx**3) < 1e-12


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("dim", [2, 3])
def test_radial_derivatives_match_finite_differences(name, dim):
    k = get_kernel(name)
    r = np.linspace(0.02, 0.98, 49) * H
    e = 1e-6 * H
    fd1 = (np.asarray(k.value(r + e, H, dim)) - np.asarray(k.value(r - e, H, dim))) / (2 * e)
    np.testing.assert_allclose(k.derivative(r, H, dim), fd1, rtol=1e-6, atol=1e-6 * abs(fd1).max())
    e = 1e-4 * H
    fd2 = (np.asarray(k.value(r + e, H, dim)) - 2 * np.asarray(k.value(r, H, dim)) + np.asarray(k.value(r - e, H, dim))) / e**2
    np.testing.assert_allclose(k.second_derivative(r, H, dim), fd2, rtol=1e-5, atol=1e-5 * abs(fd2).max())
    np.testing.assert_allclose(np.asarray(k.derivative_over_r(r, H, dim)) * r, k.derivative(r, H, dim), rtol=1e-12)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("dim", [2, 3])
def test_gradient_and_laplacian_match_cartesian_finite_differences(name, dim, rng):
    """Gradient (8.8) and Laplacian w'' + (n-1)/r w' against FD of W(x) in Cartesian coordinates."""
    k = get_kernel(name)
    dirs = rng.normal(size=(200, dim))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    x = dirs * rng.uniform(0.05, 0.95, size=(200, 1)) * H
    W = lambda p: np.asarray(k.value(np.linalg.norm(p, axis=-1), H, dim))  # noqa: E731
    e = 1e-6 * H
    grad_fd = np.stack([(W(x + e * np.eye(dim)[a]) - W(x - e * np.eye(dim)[a])) / (2 * e) for a in range(dim)], axis=1)
    grad = k.gradient(x, H)
    np.testing.assert_allclose(grad, grad_fd, rtol=1e-5, atol=1e-6 * abs(grad_fd).max())
    e = 2e-4 * H
    lap_fd = sum((W(x + e * np.eye(dim)[a]) - 2 * W(x) + W(x - e * np.eye(dim)[a])) / e**2 for a in range(dim))
    lap = k.laplacian(np.linalg.norm(x, axis=1), H, dim)
    np.testing.assert_allclose(lap, lap_fd, rtol=1e-4, atol=1e-5 * abs(lap_fd).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_laplacian_is_not_the_printed_second_derivative(dim):
    """NOTES.md: the text's laplacian = w'' is wrong; the (n-1)/r w' term matters."""
    r = np.array([0.3, 0.5]) * H
    for k in (POLY6, SPIKY):
        assert not np.allclose(k.laplacian(r, H, dim), k.second_derivative(r, H, dim), rtol=1e-2)
    # divergence theorem: int_ball lap W = flux through the sphere = area * w'(R) (= 0 at R = h)
    area = (lambda s: 2 * np.pi * s) if dim == 2 else (lambda s: 4 * np.pi * s * s)
    for k in (POLY6, WENDLAND_C2):
        integrand = lambda s, k=k: area(s) * float(k.laplacian(s, H, dim))  # noqa: E731
        R = 0.6 * H
        vol, _ = integrate.quad(integrand, 0, R, epsabs=1e-12)
        assert vol == pytest.approx(area(R) * float(k.derivative(R, H, dim)), rel=1e-8)
        # the Laplacian of a compact kernel integrates to zero over its support
        tot, _ = integrate.quad(integrand, 0, H, epsabs=1e-12)
        assert abs(tot) < 1e-8 / H**2


def test_spiky_2d_constant_is_ten_over_pi_h2():
    """(C.10) prints 15/(pi h^2); only 10/(pi h^2) integrates to one and matches (C.11), (C.12)."""
    h = 1.7
    assert float(spiky(0.0, h, dim=2)) == pytest.approx(10 / (np.pi * h * h))
    assert float(spiky_derivative(0.5 * h, h, dim=2)) == pytest.approx(-30 / (np.pi * h**3) * 0.25)
    assert float(spiky_second_derivative(0.5 * h, h, dim=2)) == pytest.approx(60 / (np.pi * h**4) * 0.5)
    total, _ = integrate.quad(lambda r: 2 * np.pi * r * 15 / (np.pi * h * h) * (1 - r / h) ** 3, 0, h)
    assert total == pytest.approx(1.5)  # the printed constant would give 1.5


def test_appendix_c_closed_forms():
    h, d = 1.3, 0.4
    s = d * d / (h * h)
    assert float(poly6(d, h)) == pytest.approx(315 / (64 * np.pi * h**3) * (1 - s) ** 3)
    assert float(poly6_derivative(d, h)) == pytest.approx(-945 / (32 * np.pi * h**3) * d / h**2 * (1 - s) ** 2)
    assert float(poly6_second_derivative(d, h)) == pytest.approx(945 / (32 * np.pi * h**5) * (1 - s) * (5 * s - 1))
    assert float(poly6(d, h, 2)) == pytest.approx(4 / (np.pi * h**2) * (1 - s) ** 3)
    assert float(poly6_derivative(d, h, 2)) == pytest.approx(-24 / (np.pi * h**2) * d / h**2 * (1 - s) ** 2)
    assert float(poly6_second_derivative(d, h, 2)) == pytest.approx(24 / (np.pi * h**4) * (1 - s) * (5 * s - 1))
    u = d / h
    assert float(spiky(d, h)) == pytest.approx(15 / (np.pi * h**3) * (1 - u) ** 3)
    assert float(spiky_derivative(d, h)) == pytest.approx(-45 / (np.pi * h**4) * (1 - u) ** 2)
    assert float(spiky_second_derivative(d, h)) == pytest.approx(90 / (np.pi * h**5) * (1 - u))
    # laplacians in closed form
    assert float(poly6_laplacian(d, h, 3)) == pytest.approx(945 / (32 * np.pi * h**5) * (1 - s) * (7 * s - 3))
    assert float(spiky_laplacian(d, h, 3)) == pytest.approx(90 / (np.pi * h**5) * (1 - u) * (2 * u - 1) / u)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("dim", [2, 3])
def test_compact_support(name, dim):
    k = get_kernel(name)
    if not np.isfinite(k.support):
        assert float(k.value(5 * H, H, dim)) > 0
        return
    r = H * np.array([1.0, 1.0 + 1e-12, 1.5, 10.0])
    for f in (k.value, k.derivative, k.second_derivative, k.derivative_over_r, k.laplacian):
        np.testing.assert_array_equal(f(r, H, dim), 0.0)
    x = np.zeros((3, dim))
    x[:, 0] = r[1:]
    np.testing.assert_array_equal(k.gradient(x, H), 0.0)
    # values continuous at the support boundary
    assert abs(float(k.value(H * (1 - 1e-7), H, dim))) < 1e-12 / H**dim


def test_conventions_at_the_origin():
    zero3, zero2 = np.zeros((1, 3)), np.zeros(2)
    for k in KERNELS.values():
        np.testing.assert_array_equal(k.gradient(zero3, H), 0.0)
        np.testing.assert_array_equal(k.gradient(zero2, H), 0.0)
        assert float(k.derivative(0.0, H)) == 0.0
    # spiky Laplacian is singular at 0; the documented finite convention is w''(0)
    assert float(spiky_laplacian(0.0, H)) == pytest.approx(float(spiky_second_derivative(0.0, H)))
    # poly6 Laplacian at 0 is exact: -6 n C / h^(n+2)
    assert float(poly6_laplacian(0.0, H, 3)) == pytest.approx(-18 * 315 / (64 * np.pi) / H**5)
    assert float(poly6_laplacian(0.0, H, 2)) == pytest.approx(-12 * 4 / np.pi / H**4)


def test_gradient_antisymmetric_and_pointing_inwards(rng):
    xij = rng.normal(size=(30, 3)) * 0.3 * H
    for k in KERNELS.values():
        g = k.gradient(xij, H)
        np.testing.assert_allclose(k.gradient(-xij, H), -g)
        assert np.all(np.einsum("ij,ij->i", g, xij) <= 0)
    assert poly6_gradient(xij, H).shape == (30, 3)
    assert spiky_gradient(xij[:, :2], H).shape == (30, 2)


def test_gaussian_kernel_is_normal_distribution():
    # GAUSSIAN with h = sqrt(2) s is the normal density with standard deviation s
    s = 0.4
    x = np.linspace(0, 2, 9)
    np.testing.assert_allclose(GAUSSIAN.value(x, np.sqrt(2) * s, 2), np.exp(-(x**2) / (2 * s * s)) / (2 * np.pi * s * s))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: poly6(1.0, 1.0, dim=4), "dim: expected 2 or 3"),
        (lambda: poly6(1.0, 1.0, dim=True), "dim: expected 2 or 3"),
        (lambda: poly6(-1.0, 1.0), "r: expected distances >= 0"),
        (lambda: spiky(1.0, 0.0), "h: expected a positive"),
        (lambda: poly6_gradient([1.0, 2.0, 3.0, 4.0], 1.0), r"xij: expected shape \(\.\.\., 2\) or \(\.\.\., 3\)"),
        (lambda: spiky_gradient([[np.inf, 0.0]], 1.0), "xij: expected finite"),
        (lambda: get_kernel("cubic"), "kernel: expected one of"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(InputError, match=match):
        call()
