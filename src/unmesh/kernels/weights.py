"""MLS weight functions (thesis section 3.1.5, eqs. 3.10–3.13).

These are the *unnormalised* weights used by moving-least-squares fits: only
ratios of weights matter there, so ``w(0) = 1``. For kernels that integrate to
one (SPH, density estimates) use :mod:`unmesh.kernels.sph`.

Corrections to the printed formulas (the stated properties win, see
``NOTES.md``):

* (3.11) the clipped Gaussian is cut off at ``d < c·σ`` (the print says ``c·σ²``,
  which is not even dimensionally consistent).
* (3.12) the Wendland function with C² continuity is ``(1 − d/r)⁴ (1 + 4 d/r)``.
  The printed ``(1 + d/r)`` has ``w'(0) = −3/r ≠ 0``: the weight would have a cone
  tip at the sample, i.e. it would be only C⁰ as a function of the position. The
  factor 4 makes ``w'(0) = 0`` and gives Wendland's ψ₃,₁, which is C² everywhere.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from unmesh.errors import InputError

__all__ = ["clipped_gaussian", "elliptical_distance", "elliptical_weight", "gaussian", "wendland_c2"]


def _distances(d: Any, name: str = "d") -> np.ndarray:
    """Non-negative finite float64 array (any shape) from a scalar or array."""
    try:
        arr = np.asarray(d, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number or an array of numbers, got {type(d).__name__}") from None
    if arr.size:
        bad = ~np.isfinite(arr)
        if bad.any():
            raise InputError(f"{name}: expected finite values, got {arr[bad].flat[0]}")
        if (arr < 0).any():
            raise InputError(f"{name}: expected distances >= 0, got {arr[arr < 0].flat[0]}")
    return arr


def _positive(value: Any, name: str) -> np.ndarray:
    """Positive finite float64 scalar or array (broadcast by the caller)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a positive number, got {value!r}") from None
    if arr.size == 0 or not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        shown = value if arr.ndim == 0 else f"an array with min {np.nanmin(arr) if arr.size else 'empty'}"
        raise InputError(f"{name}: expected a positive finite number, got {shown}")
    return arr


def _out(values: np.ndarray) -> np.ndarray | float:
    """Return numpy scalars for 0-d results, arrays otherwise."""
    return values[()] if values.ndim == 0 else values


def gaussian(d: Any, sigma: Any) -> np.ndarray | float:
    """Gaussian weight ``w_G(d) = exp(−d²/σ²)`` (eq. 3.10).

    Parameters
    ----------
    d : float or array_like of float, any shape
        Distances ``‖x_i − x‖ >= 0``.
    sigma : float or array_like broadcastable to ``d``
        Width σ > 0 (per sample if an array).

    Returns
    -------
    numpy.ndarray of float64 (shape of ``d`` broadcast with ``sigma``) or float
        Weights in (0, 1], ``w(0) = 1``; global support.

    Example
    -------
    >>> float(gaussian(1.0, 1.0))  # e^-1
    0.36787944117144233
    """
    dd = _distances(d)
    s = _positive(sigma, "sigma")
    return _out(np.exp(-(dd * dd) / (s * s)))


def clipped_gaussian(d: Any, sigma: Any, c: float = 3.0) -> np.ndarray | float:
    """Gaussian weight clipped to ``d < c·σ`` (eq. 3.11, cut-off read as c·σ, see module notes).

    Parameters
    ----------
    d : float or array_like of float
        Distances >= 0.
    sigma : float or array_like broadcastable to ``d``
        Width σ > 0.
    c : float, default 3
        Cut-off in units of σ (> 0). At ``c = 3`` the jump at the cut-off is
        ``e^-9 ≈ 1.2e-4`` of the peak weight.

    Returns
    -------
    numpy.ndarray of float64 or float
        ``exp(−d²/σ²)`` where ``d < c·σ``, else 0.

    Example
    -------
    >>> [round(float(w), 6) for w in clipped_gaussian([0.0, 2.9, 3.0], 1.0, c=3.0)]
    [1.0, 0.000223, 0.0]
    """
    dd = _distances(d)
    s = _positive(sigma, "sigma")
    cc = float(_positive(c, "c"))
    d2 = dd * dd
    lim = cc * s
    return _out(np.where(d2 < lim * lim, np.exp(-d2 / (s * s)), 0.0))


def wendland_c2(d: Any, r: Any) -> np.ndarray | float:
    """Wendland C² weight ``(1 − d/r)⁴ (1 + 4 d/r)`` for ``d < r``, else 0 (eq. 3.12, corrected).

    The thesis prints ``(1 + d/r)``; that function is not smooth at ``d = 0``
    (``w'(0) = −3/r``). The C² function it names is Wendland's ψ₃,₁ with the
    factor 4, which has ``w'(0) = 0`` and ``w(r) = w'(r) = w''(r) = 0``.

    Parameters
    ----------
    d : float or array_like of float
        Distances >= 0.
    r : float or array_like broadcastable to ``d``
        Support radius > 0.

    Returns
    -------
    numpy.ndarray of float64 or float
        Weights in [0, 1], ``w(0) = 1``.

    Example
    -------
    >>> float(wendland_c2(0.5, 1.0))  # 0.5**4 * 3
    0.1875
    """
    dd = _distances(d)
    rr = _positive(r, "r")
    u = dd / rr
    return _out(np.where(u < 1.0, (1.0 - u) ** 4 * (1.0 + 4.0 * u), 0.0))


def elliptical_distance(dvec: Any, t1: Any, t2: Any) -> np.ndarray:
    """The argument of the elliptical weight (eq. 3.13).

    ``ρ = sqrt((t1·d)²/‖t1‖⁴ + (t2·d)²/‖t2‖⁴)``: the offset ``d`` measured in units of
    the tangent-axis lengths, so ``ρ = 1`` on the ellipse spanned by ``t1, t2``. The
    component of ``d`` along the normal does not count.

    Parameters
    ----------
    dvec : array_like, shape (..., 3)
        Offsets ``d = x_i − x``.
    t1, t2 : array_like, shape (..., 3), broadcastable to ``dvec``
        Tangent axes of the sample (their lengths are the semi-axes, > 0).

    Returns
    -------
    numpy.ndarray of float64, shape (...)

    Example
    -------
    >>> float(elliptical_distance([2.0, 0.5, 7.0], [2.0, 0, 0], [0, 0.5, 0]))  # sqrt(1 + 1)
    1.4142135623730951
    """
    d = np.asarray(dvec, dtype=np.float64)
    a = np.asarray(t1, dtype=np.float64)
    b = np.asarray(t2, dtype=np.float64)
    for name, arr in (("dvec", d), ("t1", a), ("t2", b)):
        if arr.ndim == 0 or arr.shape[-1] != 3:
            raise InputError(f"{name}: expected shape (..., 3), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name}: expected finite values, got NaN or infinity")
    la = np.einsum("...i,...i->...", a, a)
    lb = np.einsum("...i,...i->...", b, b)
    if not (np.all(la > 0) and np.all(lb > 0)):
        raise InputError("t1, t2: expected non-zero tangent axes, got a zero vector")
    pa = np.einsum("...i,...i->...", a, d)
    pb = np.einsum("...i,...i->...", b, d)
    return np.sqrt(pa * pa / (la * la) + pb * pb / (lb * lb))


_RADIAL: dict[str, Callable[..., Any]] = {
    "gaussian": gaussian,
    "clipped_gaussian": clipped_gaussian,
    "wendland_c2": wendland_c2,
}


def elliptical_weight(
    dvec: Any, t1: Any, t2: Any, kernel: str | Callable[[np.ndarray], Any] = "gaussian", **params: float
) -> np.ndarray | float:
    """Elliptical weight ``w_E(d) = w(ρ)`` with ρ the elliptical distance (eq. 3.13).

    Parameters
    ----------
    dvec : array_like, shape (..., 3)
        Offsets ``d = x_i − x``.
    t1, t2 : array_like, shape (..., 3)
        Tangent axes of the sample; their lengths are the kernel size along them.
    kernel : {"gaussian", "clipped_gaussian", "wendland_c2"} or callable
        The radially symmetric weight ``w``, evaluated at the dimensionless ρ. Named
        kernels take their parameters from ``params`` with defaults ``sigma=1``
        (Gaussians, ``c=3`` for the clipped one) and ``r=1`` (Wendland, i.e. the
        support is exactly the ellipse). A callable gets the array ρ.
    **params : float
        Parameters of a named kernel.

    Returns
    -------
    numpy.ndarray of float64, shape (...), or float

    Example
    -------
    >>> float(elliptical_weight([0.5, 0.0, 0.0], [0.5, 0, 0], [0, 2.0, 0], kernel="wendland_c2"))
    0.0
    >>> float(elliptical_weight([0.0, 1.0, 0.0], [0.5, 0, 0], [0, 2.0, 0], kernel="wendland_c2"))
    0.1875
    """
    rho = elliptical_distance(dvec, t1, t2)
    if callable(kernel):
        return _out(np.asarray(kernel(rho), dtype=np.float64))
    if kernel not in _RADIAL:
        raise InputError(f"kernel: expected one of {sorted(_RADIAL)} or a callable, got {kernel!r}")
    if kernel == "wendland_c2":
        allowed = {"r"}
        args = {"r": params.get("r", 1.0)}
    else:
        allowed = {"sigma", "c"} if kernel == "clipped_gaussian" else {"sigma"}
        args = {"sigma": params.get("sigma", 1.0)}
        if kernel == "clipped_gaussian":
            args["c"] = params.get("c", 3.0)
    extra = set(params) - allowed
    if extra:
        raise InputError(f"params: kernel {kernel!r} takes {sorted(allowed)}, got unexpected {sorted(extra)}")
    return _RADIAL[kernel](rho, **args)
