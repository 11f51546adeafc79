"""The paint model (thesis 5.6): mixing, bidirectional transfer, drying and diffusion.

- Mixing of two paint volumes: RGB by volume (5.11) or single-constant Kubelka-Munk (the
  option 5.6 names): reflectance ``R`` -> ``K/S = (1 - R)^2 / (2 R)``, mixed by volume, back by
  ``R = 1 + K/S - sqrt((K/S)^2 + 2 K/S)``.
- Transfer (5.9-5.11, with the corrected 5.11 of NOTES.md): both sides give up
  ``dV = (1 - exp(-tau p dt)) V`` and receive the other's; volume is conserved.
- Drying (5.12/5.13) with the drying function G (slightly brighter).
- Diffusion (5.15): pair exchange ``dV_ij = 1/2 (V_i - V_j) c_ij`` with
  ``c_ij = exp(-x_ij^T D^-1 x_ij / dt)`` (:func:`diffusion_coefficient`, which lists the
  properties NOTES.md asks for).

Example
-------
>>> import numpy as np
>>> c, v = mix(np.array([[1.0, 0, 0]]), np.array([1.0]), np.array([[0, 0, 1.0]]), np.array([1.0]))
>>> c.tolist(), v.tolist()
([[0.5, 0.0, 0.5]], [2.0])
"""

from __future__ import annotations

import numpy as np

__all__ = ["diffusion_coefficient", "diffusion_exchange", "dry", "drying_function", "mix", "transfer"]

_R_MIN = 1e-4


def _ks(c: np.ndarray) -> np.ndarray:
    r = np.clip(c, _R_MIN, 1.0)
    return (1.0 - r) ** 2 / (2.0 * r)


def _refl(ks: np.ndarray) -> np.ndarray:
    return np.clip(1.0 + ks - np.sqrt(ks * ks + 2.0 * ks), 0.0, 1.0)


def mix(c1: np.ndarray, v1: np.ndarray, c2: np.ndarray, v2: np.ndarray, km: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Colour and volume of ``v1`` of ``c1`` mixed with ``v2`` of ``c2`` (rows); where the total
    volume is zero the first colour is kept.

    Parameters
    ----------
    c1, c2 : (N, 3) float64
    v1, v2 : (N,) float64, >= 0
    km : bool
        Kubelka-Munk instead of RGB mixing.
    """
    v = v1 + v2
    safe = np.where(v > 0, v, 1.0)[:, None]
    if km:
        out = _refl((v1[:, None] * _ks(c1) + v2[:, None] * _ks(c2)) / safe)
    else:
        out = (v1[:, None] * c1 + v2[:, None] * c2) / safe
    return np.where((v > 0)[:, None], out, c1), v


def transfer(cs: np.ndarray, vs: np.ndarray, cb: np.ndarray, vb: np.ndarray, tau_sb: float, tau_bs: float,
             p: np.ndarray, dt: float, km: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bidirectional exchange between surface (s) and brush (b) pixels (5.9-5.11).

    ``dV_s = (1 - exp(-tau_sb p dt)) V_s`` leaves the surface, ``dV_b = (1 - exp(-tau_bs p dt)) V_b``
    leaves the brush; ``C_s' = ((V_s - dV_s) C_s + dV_b C_b) / (V_s - dV_s + dV_b)`` (5.11) and
    the same for the brush.

    Returns
    -------
    cs', vs', cb', vb' : new colours and volumes
    f_b : (N,) fraction of each surface pixel's new volume that came from the brush
    """
    ds = (1.0 - np.exp(-tau_sb * p * dt)) * vs
    db = (1.0 - np.exp(-tau_bs * p * dt)) * vb
    keep_s = vs - ds
    keep_b = vb - db
    cs2, vs2 = mix(cs, keep_s, cb, db, km)
    cb2, vb2 = mix(cb, keep_b, cs, ds, km)
    fb = np.where(vs2 > 0, db / np.where(vs2 > 0, vs2, 1.0), 0.0)
    return cs2, vs2, cb2, vb2, fb


def drying_function(c: np.ndarray) -> np.ndarray:
    """G of (5.13): dry paint is slightly brighter (reflectivity and shininess drop separately)."""
    return np.clip(c + 0.08 * (1.0 - c), 0.0, 1.0)


def dry(wet: np.ndarray, vw: np.ndarray, dryc: np.ndarray, vd: np.ndarray, kappa: np.ndarray, dt: float,
        km: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drying (5.12/5.13): ``dV = (1 - exp(-kappa dt)) V_w`` moves from wet to dry paint,
    ``C_d' = (V_d C_d + dV G(C_w)) / (V_d + dV)``.

    Returns
    -------
    vw', dry colour', vd'
    """
    dv = (1.0 - np.exp(-kappa * dt)) * vw
    c, v = mix(dryc, vd, drying_function(wet), dv, km)
    # where no dry paint existed yet, the dry colour becomes G(C_w) exactly
    return vw - dv, c, v


def diffusion_coefficient(xij: np.ndarray, D: np.ndarray, dt: float) -> np.ndarray:
    """Fraction ``c_ij`` of half the difference exchanged in ``dt`` (5.15 as NOTES.md asks).

    ``c_ij = exp(-x_ij^T D^-1 x_ij / dt)``: the thesis' ``exp(-1 / (D_ij dt))`` with the pair
    coefficient ``D_ij = (x_ij^T D^-1 x_ij)^-1`` of the diffusion tensor ``D``. It lies in [0, 1],
    grows with ``dt`` and with ``D``, decays exponentially with (squared, anisotropic) distance,
    and tends to 1 (equal volumes after the exchange) as ``dt -> infinity``.

    Parameters
    ----------
    xij : (P, 3) float64
        ``x_j - x_i``.
    D : (3, 3) float64 or (P, 3, 3)
        Diffusion tensor(s), symmetric positive semi-definite (area per second).
    dt : float

    Example
    -------
    >>> bool(diffusion_coefficient(np.array([[1.0, 0, 0]]), np.eye(3), 1.0)[0] == np.exp(-1.0))
    True
    """
    if dt <= 0:
        return np.zeros(len(xij))
    Dinv = np.linalg.pinv(D)
    if Dinv.ndim == 2:
        q = np.einsum("pi,ij,pj->p", xij, Dinv, xij)
    else:
        q = np.einsum("pi,pij,pj->p", xij, Dinv, xij)
    # directions D cannot diffuse along (pinv gives 0 there) exchange nothing
    if Dinv.ndim == 2:
        null = np.linalg.norm(xij - xij @ (D @ Dinv).T, axis=1) > 1e-12 * np.maximum(np.linalg.norm(xij, axis=1), 1e-300)
    else:
        null = np.zeros(len(xij), bool)
    c = np.exp(-q / dt)
    c[null] = 0.0
    return c


def diffusion_exchange(vi: np.ndarray, vj: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Volume moved from i to j by one pair exchange (5.15): ``dV_ij = 1/2 (V_i - V_j) c_ij``.

    Antisymmetric (conserves paint), from more to less, at most half the difference.

    Example
    -------
    >>> diffusion_exchange(np.array([3.0]), np.array([1.0]), np.array([1.0])).tolist()
    [1.0]
    """
    return 0.5 * (vi - vj) * c
