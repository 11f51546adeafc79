"""Numba scalar kernels for use inside other numba kernels (SPH, MLS, shells).

Every function is ``@njit(cache=True)``, takes float64 scalars and returns a float64
scalar; none validates its input (validate at the public boundary). Each equals
the numpy function named in brackets (tested in ``tests/kernels``). ``r2`` means
the squared distance, ``r`` the distance, ``h`` the smoothing length / support
radius, ``sigma`` the Gaussian width.

MLS weights (unnormalised, ``w(0) = 1``; :mod:`unmesh.kernels.weights`)
    ``gaussian_w(r2, sigma)``                [gaussian]
    ``clipped_gaussian_w(r2, sigma, c)``     [clipped_gaussian; 0 for r >= c·σ]
    ``wendland_c2_w(r, h)``                  [wendland_c2]
    ``wendland_c2_dw(r, h)``                 [d/dr of wendland_c2]

SPH kernels (normalised; :mod:`unmesh.kernels.sph`), each in ``_2d`` and ``_3d``:
    ``poly6_{2d,3d}(r2, h)``                 value              [poly6]
    ``poly6_dw_{2d,3d}(r, h)``               w'(r)              [poly6_derivative]
    ``poly6_gradf_{2d,3d}(r2, h)``           w'(r)/r, so ∇W = gradf · x_ij   [poly6_gradient]
    ``poly6_d2w_{2d,3d}(r2, h)``             w''(r)             [poly6_second_derivative]
    ``poly6_lap_{2d,3d}(r2, h)``             w'' + (n−1) w'/r   [poly6_laplacian]
    ``spiky_{2d,3d}(r, h)``                  value              [spiky]
    ``spiky_dw_{2d,3d}(r, h)``               w'(r) (0 at r = 0) [spiky_derivative]
    ``spiky_gradf_{2d,3d}(r, h)``            w'(r)/r (0 at r = 0)            [spiky_gradient]
    ``spiky_d2w_{2d,3d}(r, h)``              w''(r)             [spiky_second_derivative]
    ``spiky_lap_{2d,3d}(r, h)``              w'' + (n−1) w'/r (w''(0) at r = 0) [spiky_laplacian]
    ``wendland_{2d,3d}(r, h)``, ``wendland_dw_{2d,3d}(r, h)``, ``wendland_gradf_{2d,3d}(r, h)``,
    ``wendland_lap_{2d,3d}(r, h)``           normalised Wendland C²  [WENDLAND_C2]

Example
-------
>>> import numpy as np
>>> from numba import njit
>>> from unmesh.kernels._kernels import poly6_3d
>>> @njit
... def density(r2s, h):
...     s = 0.0
...     for r2 in r2s:
...         s += poly6_3d(r2, h)
...     return s
>>> round(density(np.zeros(2), 1.0), 6)
3.133363
"""

from __future__ import annotations

import math

from numba import njit

# Normalisation constants (see unmesh.kernels.sph).
POLY6_2D = 4.0 / math.pi
POLY6_3D = 315.0 / (64.0 * math.pi)
SPIKY_2D = 10.0 / math.pi
SPIKY_3D = 15.0 / math.pi
WENDLAND_2D = 7.0 / math.pi
WENDLAND_3D = 21.0 / (2.0 * math.pi)

__all__ = [
    "clipped_gaussian_w",
    "gaussian_w",
    "poly6_2d",
    "poly6_3d",
    "poly6_d2w_2d",
    "poly6_d2w_3d",
    "poly6_dw_2d",
    "poly6_dw_3d",
    "poly6_gradf_2d",
    "poly6_gradf_3d",
    "poly6_lap_2d",
    "poly6_lap_3d",
    "spiky_2d",
    "spiky_3d",
    "spiky_d2w_2d",
    "spiky_d2w_3d",
    "spiky_dw_2d",
    "spiky_dw_3d",
    "spiky_gradf_2d",
    "spiky_gradf_3d",
    "spiky_lap_2d",
    "spiky_lap_3d",
    "wendland_2d",
    "wendland_3d",
    "wendland_c2_dw",
    "wendland_c2_w",
    "wendland_dw_2d",
    "wendland_dw_3d",
    "wendland_gradf_2d",
    "wendland_gradf_3d",
    "wendland_lap_2d",
    "wendland_lap_3d",
]

# -- MLS weights ------------------------------------------------------------------------


@njit(cache=True)
def gaussian_w(r2, sigma):
    """exp(-r²/σ²) (eq. 3.10)."""
    return math.exp(-r2 / (sigma * sigma))


@njit(cache=True)
def clipped_gaussian_w(r2, sigma, c):
    """exp(-r²/σ²) for r < c·σ, else 0 (eq. 3.11, cut-off c·σ)."""
    lim = c * sigma
    if r2 >= lim * lim:
        return 0.0
    return math.exp(-r2 / (sigma * sigma))


@njit(cache=True)
def wendland_c2_w(r, h):
    """(1 - r/h)^4 (1 + 4r/h) for r < h (eq. 3.12 corrected)."""
    u = r / h
    if u >= 1.0:
        return 0.0
    a = 1.0 - u
    return a * a * a * a * (1.0 + 4.0 * u)


@njit(cache=True)
def wendland_c2_dw(r, h):
    """d/dr of wendland_c2_w: -20 u (1-u)^3 / h."""
    u = r / h
    if u >= 1.0:
        return 0.0
    a = 1.0 - u
    return -20.0 * u * a * a * a / h


# -- poly6 (C.1-C.6), r2 = squared distance ------------------------------------------


@njit(cache=True)
def _poly6_f(r2, h):
    s = r2 / (h * h)
    if s >= 1.0:
        return 0.0
    a = 1.0 - s
    return a * a * a


@njit(cache=True)
def poly6_3d(r2, h):
    """315/(64π h³) (1 - r²/h²)³ (eq. C.1)."""
    return POLY6_3D / (h * h * h) * _poly6_f(r2, h)


@njit(cache=True)
def poly6_2d(r2, h):
    """4/(π h²) (1 - r²/h²)³ (eq. C.4)."""
    return POLY6_2D / (h * h) * _poly6_f(r2, h)


@njit(cache=True)
def _poly6_g(r2, h):
    """-6 (1 - r²/h²)² (= f'(u)/u)."""
    s = r2 / (h * h)
    if s >= 1.0:
        return 0.0
    a = 1.0 - s
    return -6.0 * a * a


@njit(cache=True)
def poly6_gradf_3d(r2, h):
    """w'(r)/r of poly6 in 3D."""
    return POLY6_3D / (h * h * h * h * h) * _poly6_g(r2, h)


@njit(cache=True)
def poly6_gradf_2d(r2, h):
    """w'(r)/r of poly6 in 2D."""
    return POLY6_2D / (h * h * h * h) * _poly6_g(r2, h)


@njit(cache=True)
def poly6_dw_3d(r, h):
    """w'(r) of poly6 in 3D (eq. C.2)."""
    return r * poly6_gradf_3d(r * r, h)


@njit(cache=True)
def poly6_dw_2d(r, h):
    """w'(r) of poly6 in 2D (eq. C.5)."""
    return r * poly6_gradf_2d(r * r, h)


@njit(cache=True)
def _poly6_d2f(r2, h):
    s = r2 / (h * h)
    if s >= 1.0:
        return 0.0
    return -6.0 * (1.0 - s) * (1.0 - 5.0 * s)


@njit(cache=True)
def poly6_d2w_3d(r2, h):
    """w''(r) of poly6 in 3D (eq. C.3)."""
    return POLY6_3D / (h * h * h * h * h) * _poly6_d2f(r2, h)


@njit(cache=True)
def poly6_d2w_2d(r2, h):
    """w''(r) of poly6 in 2D (eq. C.6)."""
    return POLY6_2D / (h * h * h * h) * _poly6_d2f(r2, h)


@njit(cache=True)
def poly6_lap_3d(r2, h):
    """Laplacian w'' + 2 w'/r of poly6 in 3D."""
    return POLY6_3D / (h * h * h * h * h) * (_poly6_d2f(r2, h) + 2.0 * _poly6_g(r2, h))


@njit(cache=True)
def poly6_lap_2d(r2, h):
    """Laplacian w'' + w'/r of poly6 in 2D."""
    return POLY6_2D / (h * h * h * h) * (_poly6_d2f(r2, h) + _poly6_g(r2, h))


# -- spiky (C.7-C.12), r = distance ---------------------------------------------------


@njit(cache=True)
def _spiky_f(r, h):
    u = r / h
    if u >= 1.0:
        return 0.0
    a = 1.0 - u
    return a * a * a


@njit(cache=True)
def spiky_3d(r, h):
    """15/(π h³) (1 - r/h)³ (eq. C.7)."""
    return SPIKY_3D / (h * h * h) * _spiky_f(r, h)


@njit(cache=True)
def spiky_2d(r, h):
    """10/(π h²) (1 - r/h)³ (eq. C.10 with the corrected constant)."""
    return SPIKY_2D / (h * h) * _spiky_f(r, h)


@njit(cache=True)
def _spiky_df(r, h):
    u = r / h
    if u >= 1.0 or r <= 0.0:
        return 0.0
    a = 1.0 - u
    return -3.0 * a * a


@njit(cache=True)
def spiky_dw_3d(r, h):
    """w'(r) of spiky in 3D (eq. C.8); 0 at r = 0."""
    return SPIKY_3D / (h * h * h * h) * _spiky_df(r, h)


@njit(cache=True)
def spiky_dw_2d(r, h):
    """w'(r) of spiky in 2D (eq. C.11); 0 at r = 0."""
    return SPIKY_2D / (h * h * h) * _spiky_df(r, h)


@njit(cache=True)
def spiky_gradf_3d(r, h):
    """w'(r)/r of spiky in 3D; 0 at r = 0."""
    if r <= 0.0:
        return 0.0
    return spiky_dw_3d(r, h) / r


@njit(cache=True)
def spiky_gradf_2d(r, h):
    """w'(r)/r of spiky in 2D; 0 at r = 0."""
    if r <= 0.0:
        return 0.0
    return spiky_dw_2d(r, h) / r


@njit(cache=True)
def _spiky_d2f(r, h):
    u = r / h
    if u >= 1.0:
        return 0.0
    return 6.0 * (1.0 - u)


@njit(cache=True)
def spiky_d2w_3d(r, h):
    """w''(r) of spiky in 3D (eq. C.9)."""
    return SPIKY_3D / (h * h * h * h * h) * _spiky_d2f(r, h)


@njit(cache=True)
def spiky_d2w_2d(r, h):
    """w''(r) of spiky in 2D (eq. C.12)."""
    return SPIKY_2D / (h * h * h * h) * _spiky_d2f(r, h)


@njit(cache=True)
def spiky_lap_3d(r, h):
    """w'' + 2 w'/r of spiky in 3D (w''(0) at r = 0)."""
    return spiky_d2w_3d(r, h) + 2.0 * spiky_gradf_3d(r, h)


@njit(cache=True)
def spiky_lap_2d(r, h):
    """w'' + w'/r of spiky in 2D (w''(0) at r = 0)."""
    return spiky_d2w_2d(r, h) + spiky_gradf_2d(r, h)


# -- normalised Wendland C2 ---------------------------------------------------------------


@njit(cache=True)
def wendland_3d(r, h):
    """21/(2π h³) (1 - r/h)^4 (1 + 4r/h)."""
    return WENDLAND_3D / (h * h * h) * wendland_c2_w(r, h)


@njit(cache=True)
def wendland_2d(r, h):
    """7/(π h²) (1 - r/h)^4 (1 + 4r/h)."""
    return WENDLAND_2D / (h * h) * wendland_c2_w(r, h)


@njit(cache=True)
def _wendland_g(r, h):
    """f'(u)/u = -20 (1-u)^3."""
    u = r / h
    if u >= 1.0:
        return 0.0
    a = 1.0 - u
    return -20.0 * a * a * a


@njit(cache=True)
def wendland_gradf_3d(r, h):
    """w'(r)/r of the normalised Wendland C2 in 3D (exact at r = 0)."""
    return WENDLAND_3D / (h * h * h * h * h) * _wendland_g(r, h)


@njit(cache=True)
def wendland_gradf_2d(r, h):
    """w'(r)/r of the normalised Wendland C2 in 2D (exact at r = 0)."""
    return WENDLAND_2D / (h * h * h * h) * _wendland_g(r, h)


@njit(cache=True)
def wendland_dw_3d(r, h):
    """w'(r) of the normalised Wendland C2 in 3D."""
    return r * wendland_gradf_3d(r, h)


@njit(cache=True)
def wendland_dw_2d(r, h):
    """w'(r) of the normalised Wendland C2 in 2D."""
    return r * wendland_gradf_2d(r, h)


@njit(cache=True)
def _wendland_d2f(r, h):
    u = r / h
    if u >= 1.0:
        return 0.0
    a = 1.0 - u
    return -20.0 * a * a * (1.0 - 4.0 * u)


@njit(cache=True)
def wendland_lap_3d(r, h):
    """w'' + 2 w'/r of the normalised Wendland C2 in 3D."""
    return WENDLAND_3D / (h * h * h * h * h) * (_wendland_d2f(r, h) + 2.0 * _wendland_g(r, h))


@njit(cache=True)
def wendland_lap_2d(r, h):
    """w'' + w'/r of the normalised Wendland C2 in 2D."""
    return WENDLAND_2D / (h * h * h * h) * (_wendland_d2f(r, h) + _wendland_g(r, h))
