"""Kernel functions: MLS weights (thesis 3.1.5) and SPH kernels (8.1.1, Appendix C).

Two families:

* **MLS weights** (:mod:`unmesh.kernels.weights`), unnormalised with ``w(0) = 1``:
  :func:`gaussian` (3.10), :func:`clipped_gaussian` (3.11, cut-off ``c·σ``),
  :func:`wendland_c2` (3.12, with the C² factor ``1 + 4d/r``), and
  :func:`elliptical_weight` / :func:`elliptical_distance` (3.13).
* **Normalised kernels** (:mod:`unmesh.kernels.sph`), integrating to one in 2D or
  3D (8.1): ``poly6`` (C.1–C.6), ``spiky`` (C.7–C.12, 2D constant ``10/(πh²)``),
  and normalised ``wendland_c2`` and ``gaussian`` versions of the MLS weights for
  simulations. Functions ``poly6``, ``poly6_derivative``, ``poly6_second_derivative``,
  ``poly6_gradient``, ``poly6_laplacian`` and the same for ``spiky``; every kernel is
  also a :class:`RadialKernel` object (``POLY6``, ``SPIKY``, ``WENDLAND_C2``,
  ``GAUSSIAN``, :func:`get_kernel`) with ``value``, ``derivative``,
  ``second_derivative``, ``derivative_over_r``, ``gradient`` and ``laplacian``.
  Laplacians are ``w'' + (n−1)/r · w'`` (not the printed ``w''``).

Numba scalar versions for use inside other numba kernels live in
:mod:`unmesh.kernels._kernels` (squared distance ``r2`` for poly6, distance ``r``
otherwise; all ``@njit(cache=True)``):

* MLS weights: ``gaussian_w(r2, sigma)``, ``clipped_gaussian_w(r2, sigma, c)``,
  ``wendland_c2_w(r, h)``, ``wendland_c2_dw(r, h)``.
* poly6: ``poly6_2d/3d(r2, h)``, ``poly6_dw_2d/3d(r, h)``, ``poly6_gradf_2d/3d(r2, h)``
  (``w'/r``, so ``∇W = gradf · x_ij``), ``poly6_d2w_2d/3d(r2, h)``, ``poly6_lap_2d/3d(r2, h)``.
* spiky: ``spiky_2d/3d(r, h)``, ``spiky_dw_2d/3d(r, h)``, ``spiky_gradf_2d/3d(r, h)``,
  ``spiky_d2w_2d/3d(r, h)``, ``spiky_lap_2d/3d(r, h)``.
* normalised Wendland C²: ``wendland_2d/3d(r, h)``, ``wendland_dw_2d/3d(r, h)``,
  ``wendland_gradf_2d/3d(r, h)``, ``wendland_lap_2d/3d(r, h)``.

Example
-------
>>> import numpy as np
>>> from unmesh import kernels
>>> float(kernels.wendland_c2(0.0, 1.0))
1.0
>>> g = kernels.spiky_gradient(np.array([[0.1, 0.0, 0.0]]), h=0.5)
>>> bool(g[0, 0] < 0)  # points from j towards i, kernel decreasing
True
"""

from unmesh.kernels.sph import (
    GAUSSIAN,
    KERNELS,
    POLY6,
    SPIKY,
    WENDLAND_C2,
    RadialKernel,
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
from unmesh.kernels.weights import clipped_gaussian, elliptical_distance, elliptical_weight, gaussian, wendland_c2

__all__ = [
    "GAUSSIAN",
    "KERNELS",
    "POLY6",
    "SPIKY",
    "WENDLAND_C2",
    "RadialKernel",
    "clipped_gaussian",
    "elliptical_distance",
    "elliptical_weight",
    "gaussian",
    "get_kernel",
    "poly6",
    "poly6_derivative",
    "poly6_gradient",
    "poly6_laplacian",
    "poly6_second_derivative",
    "spiky",
    "spiky_derivative",
    "spiky_gradient",
    "spiky_laplacian",
    "spiky_second_derivative",
    "wendland_c2",
]
