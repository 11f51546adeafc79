"""The numba scalar kernels equal the numpy kernels."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from unmesh.kernels import POLY6, SPIKY, WENDLAND_C2, clipped_gaussian, gaussian, wendland_c2
from unmesh.kernels import _kernels as nk

H = 0.8
R = np.concatenate([[0.0], np.linspace(1e-3, 1.2, 301) * H, [H]])


@njit
def _apply(f, r, h, squared):
    out = np.empty(r.shape[0])
    for i in range(r.shape[0]):
        out[i] = f(r[i] * r[i], h) if squared else f(r[i], h)
    return out


def _run(f, squared):
    return _apply(f, R, H, squared)


CASES = [
    # numba function, takes r2?, numpy reference (r -> values)
    ("poly6_3d", True, lambda r: POLY6.value(r, H, 3)),
    ("poly6_2d", True, lambda r: POLY6.value(r, H, 2)),
    ("poly6_dw_3d", False, lambda r: POLY6.derivative(r, H, 3)),
    ("poly6_dw_2d", False, lambda r: POLY6.derivative(r, H, 2)),
    ("poly6_gradf_3d", True, lambda r: POLY6.derivative_over_r(r, H, 3)),
    ("poly6_gradf_2d", True, lambda r: POLY6.derivative_over_r(r, H, 2)),
    ("poly6_d2w_3d", True, lambda r: POLY6.second_derivative(r, H, 3)),
    ("poly6_d2w_2d", True, lambda r: POLY6.second_derivative(r, H, 2)),
    ("poly6_lap_3d", True, lambda r: POLY6.laplacian(r, H, 3)),
    ("poly6_lap_2d", True, lambda r: POLY6.laplacian(r, H, 2)),
    ("spiky_3d", False, lambda r: SPIKY.value(r, H, 3)),
    ("spiky_2d", False, lambda r: SPIKY.value(r, H, 2)),
    ("spiky_dw_3d", False, lambda r: SPIKY.derivative(r, H, 3)),
    ("spiky_dw_2d", False, lambda r: SPIKY.derivative(r, H, 2)),
    ("spiky_gradf_3d", False, lambda r: SPIKY.derivative_over_r(r, H, 3)),
    ("spiky_gradf_2d", False, lambda r: SPIKY.derivative_over_r(r, H, 2)),
    ("spiky_d2w_3d", False, lambda r: SPIKY.second_derivative(r, H, 3)),
    ("spiky_d2w_2d", False, lambda r: SPIKY.second_derivative(r, H, 2)),
    ("spiky_lap_3d", False, lambda r: SPIKY.laplacian(r, H, 3)),
    ("spiky_lap_2d", False, lambda r: SPIKY.laplacian(r, H, 2)),
    ("wendland_3d", False, lambda r: WENDLAND_C2.value(r, H, 3)),
    ("wendland_2d", False, lambda r: WENDLAND_C2.value(r, H, 2)),
    ("wendland_dw_3d", False, lambda r: WENDLAND_C2.derivative(r, H, 3)),
    ("wendland_dw_2d", False, lambda r: WENDLAND_C2.derivative(r, H, 2)),
    ("wendland_gradf_3d", False, lambda r: WENDLAND_C2.derivative_over_r(r, H, 3)),
    ("wendland_gradf_2d", False, lambda r: WENDLAND_C2.derivative_over_r(r, H, 2)),
    ("wendland_lap_3d", False, lambda r: WENDLAND_C2.laplacian(r, H, 3)),
    ("wendland_lap_2d", False, lambda r: WENDLAND_C2.laplacian(r, H, 2)),
    ("wendland_c2_w", False, lambda r: wendland_c2(r, H)),
    ("wendland_c2_dw", False, lambda r: WENDLAND_C2.derivative(r, H, 3) / WENDLAND_C2.norm[3] * H**3),
    ("gaussian_w", True, lambda r: gaussian(r, H)),
]


@pytest.mark.parametrize(("name", "squared", "ref"), CASES, ids=[c[0] for c in CASES])
def test_numba_equals_numpy(name, squared, ref):
    got = _run(getattr(nk, name), squared)
    want = np.asarray(ref(R), dtype=float)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * max(1.0, abs(want).max()))


def test_clipped_gaussian_numba():
    @njit
    def run(r, sigma, c):
        return np.array([nk.clipped_gaussian_w(x * x, sigma, c) for x in r])

    r = np.linspace(0, 4, 401) * 0.3
    np.testing.assert_allclose(run(r, 0.3, 3.0), clipped_gaussian(r, 0.3, 3.0), rtol=1e-12)


def test_every_documented_numba_kernel_is_tested():
    tested = {c[0] for c in CASES} | {"clipped_gaussian_w"}
    assert set(nk.__all__) == tested
