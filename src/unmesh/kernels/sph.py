"""Normalised radial kernels for SPH (thesis section 8.1.1 and Appendix C).

Every kernel here is written ``W_h(x) = w_h(‖x‖) = (C_n / hⁿ) f(‖x‖/h)`` in
``n = 2`` or ``3`` dimensions and integrates to one over ℝⁿ (eq. 8.1). Each comes
with its radial derivatives ``w'``, ``w''``, its gradient vector (eq. 8.8)

    ∇W_h(x_ij) = x_ij / ‖x_ij‖ · w'(‖x_ij‖),   x_ij = x_i − x_j (gradient w.r.t. x_i),

and its Laplacian. The thesis writes ``∇²W = w''`` (section 8.1.3); for a radial
function in n dimensions the Laplacian is ``w'' + (n − 1)/r · w'`` (NOTES.md), which
is what :meth:`RadialKernel.laplacian` returns.

Kernels
-------
``poly6``
    ``(1 − r²/h²)³`` (eqs. C.1–C.6), ``C₃ = 315/(64π)``, ``C₂ = 4/π``. Smooth; used
    for densities and interpolation.
``spiky``
    ``(1 − r/h)³`` (eqs. C.7–C.12), ``C₃ = 15/π``, ``C₂ = 10/π``. The print of (C.10)
    has ``15/(πh²)``; the kernel integrates to one only with ``10/(πh²)``, which (C.11)
    and (C.12) already use. Its gradient does not vanish at ``r → 0`` (no clumping
    under pressure forces).
``wendland_c2``
    ``(1 − r/h)⁴ (1 + 4r/h)`` (eq. 3.12, corrected), ``C₃ = 21/(2π)``, ``C₂ = 7/π``.
    The normalised version of the MLS weight :func:`unmesh.kernels.wendland_c2`.
``gaussian``
    ``exp(−r²/h²)`` (eq. 3.10 with σ = h), ``Cₙ = π^(−n/2)``; global support.

Appendix C defines no viscosity kernel, so none is provided.

Conventions at ``r = 0``: the gradient is the zero vector. ``w'(0) = 0`` for every
kernel, as in the thesis (C.2, C.8 are defined for ``0 < d < h``); for ``spiky`` this
is a convention (the one-sided limit is ``−3 C/hⁿ⁺¹``). The spiky Laplacian is
singular at ``r = 0`` (``(n−1) w'/r → −∞``); there the finite value ``w''(0)`` is
returned, i.e. the ``w'/r`` term is taken as zero, so a self-term ``j = i`` in a sum
like (8.12) stays finite (it multiplies ``f_i − f_i = 0``).

Example
-------
>>> from unmesh.kernels import poly6, spiky_gradient
>>> round(float(poly6(0.0, 1.0, dim=3)), 6)  # 315 / (64 π)
1.566681
>>> spiky_gradient([[0.5, 0.0, 0.0]], 1.0)  # -45/pi * 0.25 along +x
array([[-3.58098622,  0.        ,  0.        ]])
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.kernels.weights import _distances, _out, _positive

__all__ = [
    "GAUSSIAN",
    "KERNELS",
    "POLY6",
    "SPIKY",
    "WENDLAND_C2",
    "RadialKernel",
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
]

_Shape = Callable[[np.ndarray], np.ndarray]


def _dim(dim: Any) -> int:
    if isinstance(dim, bool) or dim not in (2, 3):
        raise InputError(f"dim: expected 2 or 3, got {dim!r}")
    return int(dim)


@dataclass(frozen=True)
class RadialKernel:
    """A normalised radial kernel ``W_h(x) = (C_n/hⁿ) f(‖x‖/h)``.

    Parameters
    ----------
    name : str
        Short name (``"poly6"``, ``"spiky"``, ...).
    f, df, d2f : callable
        Shape function of ``u = r/h`` (vectorised, valid inside the support) and its
        first and second derivatives.
    df_over_u : callable
        ``f'(u)/u``, written so that it is exact (poly6, Wendland, Gaussian) or
        defined as 0 (spiky) at ``u = 0``.
    norm : dict {2: C₂, 3: C₃}
        Normalisation constants so that the kernel integrates to one.
    support : float
        Support radius in units of h (``inf`` for the Gaussian).
    equations : str
        Thesis equations the kernel implements.

    Example
    -------
    >>> k = get_kernel("spiky")
    >>> round(float(k.value(0.0, 2.0, dim=2)), 6)  # 10 / (π h²)
    0.795775
    """

    name: str
    f: _Shape
    df: _Shape
    d2f: _Shape
    df_over_u: _Shape
    norm: dict[int, float]
    support: float
    equations: str

    def _eval(self, shape: _Shape, r: Any, h: Any, dim: Any, power: int) -> np.ndarray | float:
        n = _dim(dim)
        rr = _distances(r, "r")
        hh = _positive(h, "h")
        u = rr / hh
        inside = u < self.support
        uu = np.where(inside, u, 0.0)
        vals = np.where(inside, shape(uu), 0.0) * (self.norm[n] / hh ** (n + power))
        return _out(np.asarray(vals, dtype=np.float64))

    def value(self, r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
        """Kernel value ``w_h(r)`` (float64, shape of ``r``); see the module docstring.

        Example
        -------
        >>> float(POLY6.value(1.0, 1.0))
        0.0
        """
        return self._eval(self.f, r, h, dim, 0)

    def derivative(self, r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
        """Radial derivative ``w_h'(r)`` (0 at r = 0 and outside the support).

        Example
        -------
        >>> round(float(SPIKY.derivative(0.5, 1.0)), 6)  # -45/π · 0.25
        -3.580986
        """
        out = self._eval(self.df, r, h, dim, 1)
        rr = _distances(r, "r")
        return _out(np.where(np.broadcast_to(rr, np.shape(out)) > 0, out, 0.0))

    def second_derivative(self, r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
        """Second radial derivative ``w_h''(r)``.

        Example
        -------
        >>> round(float(SPIKY.second_derivative(0.0, 1.0)), 6)  # 90/π
        28.64789
        """
        return self._eval(self.d2f, r, h, dim, 2)

    def derivative_over_r(self, r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
        """``w_h'(r)/r``, the factor with ``∇W(x_ij) = (w'/r) x_ij``; exact at r = 0 where finite.

        Example
        -------
        >>> round(float(POLY6.derivative_over_r(0.0, 1.0)), 6)  # -6 · 315/(64π)
        -9.400089
        """
        return self._eval(self.df_over_u, r, h, dim, 2)

    def gradient(self, xij: Any, h: Any) -> np.ndarray:
        """Gradient vectors ``∇W_h(x_ij) = x_ij w'(r)/r`` (eq. 8.8); dimension from the last axis.

        Parameters
        ----------
        xij : array_like, shape (..., 2) or (..., 3)
            Offsets ``x_i − x_j``.
        h : float or array_like broadcastable to ``xij[..., 0]``
            Smoothing length > 0.

        Returns
        -------
        numpy.ndarray of float64, shape of ``xij``
            Zero at ``x_ij = 0`` and outside the support.

        Example
        -------
        >>> POLY6.gradient([[0.0, 0.0, 0.0]], 1.0)
        array([[0., 0., 0.]])
        """
        x = np.asarray(xij, dtype=np.float64)
        if x.ndim == 0 or x.shape[-1] not in (2, 3):
            raise InputError(f"xij: expected shape (..., 2) or (..., 3), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise InputError("xij: expected finite values, got NaN or infinity")
        r = np.sqrt(np.einsum("...i,...i->...", x, x))
        fac = np.asarray(self.derivative_over_r(r, h, dim=x.shape[-1]))
        fac = np.where(r > 0, fac, 0.0)
        return np.ascontiguousarray(fac[..., None] * x + 0.0)  # + 0.0 turns -0.0 into 0.0

    def laplacian(self, r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
        """Laplacian ``∇²W_h = w'' + (n − 1)/r · w'`` in ``dim`` dimensions (not the printed ``w''``).

        Example
        -------
        >>> round(float(POLY6.laplacian(0.0, 1.0, dim=3)), 6)  # -18 · 315/(64π)
        -28.200266
        """
        n = _dim(dim)
        return _out(np.asarray(self.second_derivative(r, h, n)) + (n - 1) * np.asarray(self.derivative_over_r(r, h, n)))


# -- shape functions -------------------------------------------------------------------


def _spiky_df_over_u(u: np.ndarray) -> np.ndarray:
    safe = np.where(u > 0, u, 1.0)
    return np.where(u > 0, -3.0 * (1.0 - u) ** 2 / safe, 0.0)


POLY6 = RadialKernel(
    name="poly6",
    f=lambda u: (1.0 - u * u) ** 3,
    df=lambda u: -6.0 * u * (1.0 - u * u) ** 2,
    d2f=lambda u: -6.0 * (1.0 - u * u) * (1.0 - 5.0 * u * u),
    df_over_u=lambda u: -6.0 * (1.0 - u * u) ** 2,
    norm={2: 4.0 / np.pi, 3: 315.0 / (64.0 * np.pi)},
    support=1.0,
    equations="C.1-C.6",
)
SPIKY = RadialKernel(
    name="spiky",
    f=lambda u: (1.0 - u) ** 3,
    df=lambda u: -3.0 * (1.0 - u) ** 2,
    d2f=lambda u: 6.0 * (1.0 - u),
    df_over_u=_spiky_df_over_u,
    norm={2: 10.0 / np.pi, 3: 15.0 / np.pi},
    support=1.0,
    equations="C.7-C.12 (C.10 normalised by 10/(pi h^2))",
)
WENDLAND_C2 = RadialKernel(
    name="wendland_c2",
    f=lambda u: (1.0 - u) ** 4 * (1.0 + 4.0 * u),
    df=lambda u: -20.0 * u * (1.0 - u) ** 3,
    d2f=lambda u: -20.0 * (1.0 - u) ** 2 * (1.0 - 4.0 * u),
    df_over_u=lambda u: -20.0 * (1.0 - u) ** 3,
    norm={2: 7.0 / np.pi, 3: 21.0 / (2.0 * np.pi)},
    support=1.0,
    equations="3.12 (with 1 + 4 r/h)",
)
GAUSSIAN = RadialKernel(
    name="gaussian",
    f=lambda u: np.exp(-u * u),
    df=lambda u: -2.0 * u * np.exp(-u * u),
    d2f=lambda u: (4.0 * u * u - 2.0) * np.exp(-u * u),
    df_over_u=lambda u: -2.0 * np.exp(-u * u),
    norm={2: 1.0 / np.pi, 3: np.pi ** -1.5},
    support=np.inf,
    equations="3.10 (sigma = h), normalised",
)

#: All normalised kernels by name.
KERNELS: dict[str, RadialKernel] = {k.name: k for k in (POLY6, SPIKY, WENDLAND_C2, GAUSSIAN)}


def get_kernel(name: str) -> RadialKernel:
    """The normalised kernel called ``name`` (one of :data:`KERNELS`).

    Example
    -------
    >>> get_kernel("poly6").support
    1.0
    """
    try:
        return KERNELS[name]
    except (KeyError, TypeError):
        raise InputError(f"kernel: expected one of {sorted(KERNELS)}, got {name!r}") from None


# -- function API for the Appendix C kernels ----------------------------------------------


def poly6(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Poly6 kernel ``w_h(r)`` (eq. C.1 in 3D, C.4 in 2D).

    Parameters
    ----------
    r : float or array_like
        Distances >= 0.
    h : float or array_like broadcastable to ``r``
        Smoothing length (support radius) > 0.
    dim : {2, 3}
        Space dimension.

    Returns
    -------
    numpy.ndarray of float64 (shape of ``r``) or float

    Example
    -------
    >>> round(float(poly6(0.0, 1.0, dim=2)), 6)  # 4/π
    1.27324
    """
    return POLY6.value(r, h, dim)


def poly6_derivative(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Radial derivative ``w_h'(r)`` of poly6 (eqs. C.2, C.5).

    Example
    -------
    >>> round(float(poly6_derivative(0.5, 1.0)), 6)  # -945/(32π) · 0.5 · 0.75²
    -2.643775
    """
    return POLY6.derivative(r, h, dim)


def poly6_second_derivative(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Second radial derivative ``w_h''(r)`` of poly6 (eqs. C.3, C.6).

    Example
    -------
    >>> round(float(poly6_second_derivative(0.0, 1.0)), 6)  # -945/(32π)
    -9.400089
    """
    return POLY6.second_derivative(r, h, dim)


def poly6_gradient(xij: Any, h: Any) -> np.ndarray:
    """Gradient ``∇W_h(x_ij)`` of poly6 (eq. 8.8); 2D or 3D from ``xij.shape[-1]``.

    Parameters
    ----------
    xij : array_like, shape (..., 2) or (..., 3)
        Offsets ``x_i − x_j``.
    h : float
        Smoothing length > 0.

    Returns
    -------
    numpy.ndarray of float64, shape of ``xij``

    Example
    -------
    >>> poly6_gradient([0.5, 0.0], 1.0).round(6)  # -24/π · 0.5 · 0.75² along +x
    array([-2.148592,  0.      ])
    """
    return POLY6.gradient(xij, h)


def poly6_laplacian(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Laplacian ``w'' + (n−1) w'/r`` of poly6 in ``dim`` dimensions.

    Example
    -------
    >>> round(float(poly6_laplacian(1.0, 1.0)), 6)
    0.0
    """
    return POLY6.laplacian(r, h, dim)


def spiky(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Spiky kernel ``ŵ_h(r)`` (eq. C.7 in 3D, C.10 in 2D with ``10/(πh²)``).

    Parameters
    ----------
    r : float or array_like
        Distances >= 0.
    h : float or array_like broadcastable to ``r``
        Smoothing length > 0.
    dim : {2, 3}

    Returns
    -------
    numpy.ndarray of float64 or float

    Example
    -------
    >>> round(float(spiky(0.0, 1.0, dim=3)), 6)  # 15/π
    4.774648
    """
    return SPIKY.value(r, h, dim)


def spiky_derivative(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Radial derivative ``ŵ_h'(r)`` of spiky (eqs. C.8, C.11); 0 at r = 0 by convention.

    Example
    -------
    >>> round(float(spiky_derivative(0.5, 1.0, dim=2)), 6)  # -30/π · 0.25
    -2.387324
    """
    return SPIKY.derivative(r, h, dim)


def spiky_second_derivative(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Second radial derivative ``ŵ_h''(r)`` of spiky (eqs. C.9, C.12).

    Example
    -------
    >>> round(float(spiky_second_derivative(0.0, 1.0, dim=2)), 6)  # 60/π
    19.098593
    """
    return SPIKY.second_derivative(r, h, dim)


def spiky_gradient(xij: Any, h: Any) -> np.ndarray:
    """Gradient ``∇Ŵ_h(x_ij)`` of spiky (eq. 8.8); zero vector at ``x_ij = 0``.

    Example
    -------
    >>> spiky_gradient([0.0, 0.5, 0.0], 1.0).round(6)
    array([ 0.      , -3.580986,  0.      ])
    """
    return SPIKY.gradient(xij, h)


def spiky_laplacian(r: Any, h: Any, dim: int = 3) -> np.ndarray | float:
    """Laplacian ``w'' + (n−1) w'/r`` of spiky; ``w''(0)`` at r = 0 (see module docstring).

    Example
    -------
    >>> round(float(spiky_laplacian(0.5, 1.0)), 6)  # 90/π·0.5 + 2·(−45/π·0.25)/0.5
    0.0
    """
    return SPIKY.laplacian(r, h, dim)
