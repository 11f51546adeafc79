"""Fiber geometry: natural cubic splines through three nodes (thesis 7.2.1, Appendix B).

A fiber ``k`` is the natural cubic spline through an end node ``x1`` (t = 0), its centre
node ``x`` (t = 1/2) and a second end node ``x2`` (t = 1), stored as two cubic segments
``f1``, ``f2`` with local parameter ``s`` in [0, 1] (B.1, B.2). With ``q = x1 - 2x + x2``
the coefficients (B.3, derived in ``NOTES.md``) are::

    f1(s) = x1 + b1 s + d1 s^3,            b1 = (-5 x1 + 6 x - x2) / 4,  d1 = q / 4
    f2(s) = x + b2 s + c2 s^2 + d2 s^3,    b2 = (x2 - x1) / 2,  c2 = 3q/4,  d2 = -q/4

Both ends have zero second derivative and f1, f2 join with equal first and second
derivatives at the centre. Every derivative ``f_i'(s)`` is a weighted sum
``w1 x1 + w x + w2 x2`` of the three nodes with weights that sum to zero, which makes the
gradients below short.

Two quantities are measured on a fiber:

* the arc length ``l~`` (7.5, B.4): the sampled speeds of both segments. We sample at the
  midpoints ``s = (i + 1/2)/n`` instead of the printed ``i/n``: the result is then the same
  for a fiber and its reverse (``x1`` and ``x2`` swapped), so which of two duplicate fibers
  is kept (7.4) does not matter, and it is second-order accurate. Gradients as (B.5, B.6).
* the oriented tangent angle ``theta`` (7.10, B.9): the angle between the end tangents
  ``t0 = f1'(0)`` and ``t1 = f2'(1)``, negative when the fiber bends towards the surface
  normal ``N`` of its centre node. The printed (B.9), ``sign(-N.f''(1/2)) arccos(..)``, is
  discontinuous where ``N.f''`` changes sign while the fiber also bends inside the surface
  (geodesic bending, present in any irregular sampling), and its gradient (B.11, B.12) is
  singular at ``theta = 0``, i.e. for every straight fiber of a flat sheet. We therefore
  measure the angle inside the fiber's normal plane, which is what (7.9) asks for ("the
  normal curvature of the surface in its direction"): both end tangents are projected onto
  the plane spanned by ``tc`` and ``N`` (normal to ``a``) and the signed angle between the
  projections ``p0``, ``p1`` is taken::

      a = (N x tc) / |N x tc|,   tc = f2'(0) = b2,   p = t - (t.a) a
      theta = atan2(a . (p0 x p1), p0 . p1) = atan2(a . (t0 x t1), t0.t1 - (t0.a)(t1.a))

  For a fiber bending in its normal plane ``|theta|`` equals the arccos of (B.9) and, for
  moderate bends, its sign equals (B.9)'s (both tested); ``theta`` is smooth through zero,
  and its gradient with respect to the three nodes and to ``N`` is derived in
  :func:`bending_angle_gradient` and checked against central differences. For a circular arc
  the natural spline's end tangents turn by about 3/4 of the arc's turning angle; only
  changes of ``theta`` enter the energy, so this constant factor is absorbed in ``K_b``.

All functions take the fiber nodes as arrays of shape (F, 3) (or (3,) for one fiber) and
return per-fiber arrays; gradients have shape (F, 3, 3) with axis 1 the node (``x1``,
``x``, ``x2``) and axis 2 the coordinate. The numba versions used by the force kernels are
in :mod:`unmesh.shells._force_kernels`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_points
from unmesh.errors import InputError

__all__ = [
    "ARC_SAMPLES",
    "TANGENT_SOFTENING",
    "arc_length",
    "arc_length_gradient",
    "bending_angle",
    "bending_angle_gradient",
    "degenerate",
    "evaluate",
    "spline_coefficients",
    "tangents",
    "thesis_bending_angle",
]

#: Default number of speed samples per segment for the arc length (B.4).
ARC_SAMPLES = 4
#: Regularisation ``soft_x`` of the tangent angle used by the shell energy (see bending_angle_gradient).
TANGENT_SOFTENING = 0.05

#: d t0 / d(x1, x, x2), d t1 / d(...), d tc / d(...) (scalar weights; B.3).
_T0 = np.array([-1.25, 1.5, -0.25])
_T1 = np.array([0.25, -1.5, 1.25])
_TC = np.array([-0.5, 0.0, 0.5])


def _nodes(x1: Any, x: Any, x2: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = as_points(x1, "x1")
    b = as_points(x, "x", length=len(a))
    c = as_points(x2, "x2", length=len(a))
    return a, b, c


def _samples(samples: int) -> int:
    if int(samples) != samples or samples < 1:
        raise InputError(f"samples: expected a positive integer, got {samples!r}")
    return int(samples)


def spline_coefficients(x1: Any, x: Any, x2: Any) -> dict[str, np.ndarray]:
    """Coefficients of both segments of the natural cubic spline fiber (B.2, B.3).

    Parameters
    ----------
    x1, x, x2 : array_like, shape (F, 3) or (3,)
        First end node (t = 0), centre node (t = 1/2), second end node (t = 1).

    Returns
    -------
    dict of str to ndarray, each (F, 3) float64
        ``a1, b1, c1, d1`` of ``f1(s) = a1 + b1 s + c1 s^2 + d1 s^3`` and ``a2 .. d2`` of f2.

    Example
    -------
    >>> c = spline_coefficients([0, 0, 0], [1, 0, 0], [2, 0, 0])
    >>> c["b1"], c["d1"]
    (array([[1., 0., 0.]]), array([[0., 0., 0.]]))
    """
    p1, p, p2 = _nodes(x1, x, x2)
    q = p1 - 2.0 * p + p2
    return {
        "a1": p1.copy(), "b1": (-5.0 * p1 + 6.0 * p - p2) / 4.0, "c1": np.zeros_like(p), "d1": q / 4.0,
        "a2": p.copy(), "b2": (p2 - p1) / 2.0, "c2": 0.75 * q, "d2": -0.25 * q,
    }


def evaluate(x1: Any, x: Any, x2: Any, t: Any) -> np.ndarray:
    """Points ``f(t)`` of the fibers at global parameters ``t`` in [0, 1] (B.1).

    Parameters
    ----------
    x1, x, x2 : array_like, shape (F, 3)
        Fiber nodes.
    t : array_like, shape (T,)
        Global curve parameters.

    Returns
    -------
    ndarray, shape (F, T, 3)

    Example
    -------
    >>> evaluate([0, 0, 0], [1, 1, 0], [2, 0, 0], [0.0, 0.5, 1.0])[0]
    array([[0., 0., 0.],
           [1., 1., 0.],
           [2., 0., 0.]])
    """
    c = spline_coefficients(x1, x, x2)
    tt = np.atleast_1d(np.asarray(t, dtype=np.float64))
    first = tt < 0.5
    s = np.where(first, 2.0 * tt, 2.0 * tt - 1.0)[None, :, None]
    seg1 = c["a1"][:, None] + c["b1"][:, None] * s + c["d1"][:, None] * s**3
    seg2 = c["a2"][:, None] + c["b2"][:, None] * s + c["c2"][:, None] * s**2 + c["d2"][:, None] * s**3
    return np.where(first[None, :, None], seg1, seg2)


def _speed_weights(samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Weights (n, 3) of f1'(s_i) and f2'(s_i) on (x1, x, x2) at midpoint samples."""
    s = (np.arange(samples) + 0.5) / samples
    w1 = np.stack([-1.25 + 0.75 * s**2, 1.5 - 1.5 * s**2, -0.25 + 0.75 * s**2], axis=1)
    w2 = np.stack([-0.5 + 1.5 * s - 0.75 * s**2, -3.0 * s + 1.5 * s**2, 0.5 + 1.5 * s - 0.75 * s**2], axis=1)
    return w1, w2


def arc_length_gradient(x1: Any, x: Any, x2: Any, samples: int = ARC_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Approximate arc length and its gradient with respect to the three nodes (B.4-B.6).

    ``l~ = (1/n) sum_i (|f1'(s_i)| + |f2'(s_i)|)`` with ``s_i = (i + 1/2)/n``; the gradient
    with respect to node ``p`` is ``(1/n) sum_i w_p(s_i) f'(s_i) / |f'(s_i)|`` summed over
    both segments, where ``w_p`` are the spline weights of (B.6).

    Parameters
    ----------
    x1, x, x2 : array_like, shape (F, 3)
        Fiber nodes.
    samples : int
        Samples per segment ``n``.

    Returns
    -------
    length : ndarray, shape (F,)
    gradient : ndarray, shape (F, 3, 3)
        ``gradient[k, r]`` is d l~_k / d node r (r = 0: x1, 1: x, 2: x2).

    Example
    -------
    >>> l, g = arc_length_gradient([0, 0, 0], [1, 0, 0], [2, 0, 0])
    >>> float(l[0]), g[0, :, 0]
    (2.0, array([-1.,  0.,  1.]))
    """
    p = np.stack(_nodes(x1, x, x2), axis=1)  # (F, 3 nodes, 3)
    n = _samples(samples)
    length = np.zeros(len(p))
    grad = np.zeros_like(p)
    for w in _speed_weights(n):
        v = np.einsum("sr,frc->fsc", w, p)  # (F, n, 3) speeds
        speed = np.linalg.norm(v, axis=2)
        length += speed.sum(axis=1) / n
        unit = v / np.maximum(speed, 1e-300)[:, :, None]
        grad += np.einsum("sr,fsc->frc", w, unit) / n
    return length, grad


def arc_length(x1: Any, x: Any, x2: Any, samples: int = ARC_SAMPLES) -> np.ndarray:
    """Approximate arc length ``l~`` of each fiber (B.4), shape (F,).

    Example
    -------
    >>> float(arc_length([0, 0, 0], [1, 0, 0], [2, 0, 0])[0])
    2.0
    """
    return arc_length_gradient(x1, x, x2, samples)[0]


def tangents(x1: Any, x: Any, x2: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """End and centre tangents ``t0 = f1'(0)``, ``t1 = f2'(1)``, ``tc = f2'(0)``, each (F, 3).

    Example
    -------
    >>> t0, t1, tc = tangents([0, 0, 0], [1, 1, 0], [2, 0, 0])
    >>> t0, t1, tc
    (array([[1. , 1.5, 0. ]]), array([[ 1. , -1.5,  0. ]]), array([[1., 0., 0.]]))
    """
    p = np.stack(_nodes(x1, x, x2), axis=1)
    return (np.einsum("r,frc->fc", _T0, p), np.einsum("r,frc->fc", _T1, p), np.einsum("r,frc->fc", _TC, p))


def degenerate(x1: Any, x: Any, x2: Any, normal: Any, soft: Any = 0.0, ratio: float = 0.3) -> np.ndarray:
    """Fibers whose tangent angle is near its singularity: an end tangent, as the angle sees it, vanished.

    The tangent angle (7.10, :func:`bending_angle_gradient`) uses the end tangents projected
    onto the fiber's normal plane, ``p = t - (t.a) a`` with the (regularised) axis
    ``a = u / sqrt(|u|^2 + soft^2 |tc|^2)``, ``u = N x tc``. A centre node can slide along its
    fiber, or sideways inside the surface, without changing the arc length much; where it
    has lost its other fibers (next to a crack) nothing stops it, and the projected tangent
    ``p0`` or ``p1`` can shrink to zero and turn round while the full tangent stays long (its
    sideways, geodesic part is invisible to the angle). When ``p0 . p1 + e |tc|^2`` changes
    sign with ``a.(p0 x p1) = 0`` (a flat sheet), ``theta`` jumps by pi and its gradient is
    unbounded. A fiber is degenerate when ``min(|p0|, |p1|) < ratio |tc|``; for a fiber
    bending in its normal plane ``p = t`` (the plain end-tangent test).

    Parameters
    ----------
    x1, x, x2 : array_like, shape (F, 3)
        Fiber nodes.
    normal : array_like, shape (F, 3)
        Umbrella vector ``N`` of each fiber's centre node (as for :func:`bending_angle_gradient`).
    soft : float or array_like (F,)
        Axis regularisation of the angle (``topology.soft`` of the centre).
    ratio : float
        Shortest projected end tangent relative to ``|tc|``.

    Returns
    -------
    ndarray (F,) bool

    Example
    -------
    >>> n = [0.0, 0.0, 1.0]
    >>> bool(degenerate([-1, 0, 0], [0, 0, 0], [1, 0, 0], n)[0])      # straight, centred
    False
    >>> bool(degenerate([-1, 0, 0], [0.7, 0.5, 0], [1, 0, 0], n)[0])  # slid to one end and sideways
    True
    """
    p1, p, p2 = _nodes(x1, x, x2)
    nrm = as_points(normal, "normal", length=len(p1))
    sft = np.broadcast_to(np.asarray(soft, dtype=np.float64), (len(p1),))
    d1, d2 = p1 - p, p2 - p                             # from the edge vectors, as the force kernels
    t0, t1, tc = -1.25 * d1 - 0.25 * d2, 0.25 * d1 + 1.25 * d2, 0.5 * (d2 - d1)
    r2 = float(ratio) ** 2
    u = np.cross(nrm, tc)
    tt = np.einsum("ij,ij->i", tc, tc)
    rho = np.sqrt(np.einsum("ij,ij->i", u, u) + sft**2 * tt)
    a = u / np.where(rho > 0, rho, 1.0)[:, None]
    aa = np.einsum("ij,ij->i", a, a)
    # |t - (t.a) a|^2 = |t|^2 - (t.a)^2 (2 - |a|^2)
    q0 = np.einsum("ij,ij->i", t0, t0) - np.einsum("ij,ij->i", t0, a) ** 2 * (2.0 - aa)
    q1 = np.einsum("ij,ij->i", t1, t1) - np.einsum("ij,ij->i", t1, a) ** 2 * (2.0 - aa)
    # a is normal to tc, so p.tc = t.tc and |p| >= |t.tc| / |tc|: those fibers pass at once
    # (the kernel's shortcut; the same answer)
    along = (np.einsum("ij,ij->i", t0, tc) ** 2 >= r2 * tt * tt) & (np.einsum("ij,ij->i", t1, tc) ** 2 >= r2 * tt * tt)
    return ~along & (np.minimum(q0, q1) < r2 * tt)


def bending_angle_gradient(x1: Any, x: Any, x2: Any, normal: Any, soft: Any = 0.0,
                           soft_x: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oriented tangent angle ``theta`` (7.10) and its gradients.

    ``theta = atan2(Y, X + e |tc|^2)`` with ``Y = a.(t0 x t1)``, ``X = t0.t1 - (t0.a)(t1.a)``,
    ``e = soft_x`` and ``a = u / rho``, ``u = N x tc``, ``rho = sqrt(|u|^2 + c^2)``,
    ``c = soft |tc|``: the angle between the end tangents projected onto the fiber's
    normal plane (see the module docstring for why this replaces the printed B.9/B.11).
    With ``soft = soft_x = 0`` it is exactly that angle. ``soft > 0`` (in units of ``|N|``)
    bounds the gradient where ``N`` is tiny or parallel to ``tc`` (a collapsed or folded
    node neighbourhood), ``soft_x > 0`` where an end tangent almost vanishes (the centre
    node slid towards one end, which leaves the arc length unchanged); ``theta`` then
    fades to 0 instead of turning singular. Derivation, with ``X' = X + e |tc|^2`` and
    ``D = X'^2 + Y^2``::

        dtheta/dt0 = (X'/D) (t1 x a) - (Y/D) (t1 - (t1.a) a)
        dtheta/dt1 = (X'/D) (a x t0) - (Y/D) (t0 - (t0.a) a)
        dtheta/da  = (X'/D) (t0 x t1) + (Y/D) ((t1.a) t0 + (t0.a) t1)
        g_u = dtheta/da / rho - u (u . dtheta/da) / rho^3
        dtheta/dN  = tc x g_u
        dtheta/dtc = g_u x N - (u . dtheta/da) soft^2 tc / rho^3 - (Y/D) 2 e tc

    and the chain rule through ``t0 = (-5x1 + 6x - x2)/4``, ``t1 = (x1 - 6x + 5x2)/4``,
    ``tc = (x2 - x1)/2``. The three node gradients sum to zero (translation invariance) and
    ``sum_r x_r x dtheta/dx_r + N x dtheta/dN = 0`` (rotation invariance).

    Parameters
    ----------
    x1, x, x2 : array_like, shape (F, 3)
        Fiber nodes.
    normal : array_like, shape (F, 3)
        Surface normal ``N`` at each fiber's centre node (any length; with ``soft = 0``
        only its direction matters).
    soft : float or array_like (F,)
        Regularisation ``c / |tc|`` of the axis, >= 0.
    soft_x : float
        Regularisation ``e`` of the cosine part, >= 0.

    Returns
    -------
    theta : ndarray, shape (F,)
        Angle in (-pi, pi]; negative when the fiber bends towards ``N``.
    gradient : ndarray, shape (F, 3, 3)
        d theta / d (x1, x, x2).
    gradient_normal : ndarray, shape (F, 3)
        d theta / d N.

    Example
    -------
    >>> th, g, gn = bending_angle_gradient([0, 0, 0], [1, 1, 0], [2, 0, 0], [0, -1, 0])
    >>> round(float(th[0]), 6)   # f'' points along N: negative
    -1.965587
    >>> bool(np.abs(g.sum(axis=1)).max() < 1e-12)   # translation invariance
    True
    """
    p1, p, p2 = _nodes(x1, x, x2)
    nrm = as_points(normal, "normal", length=len(p1))
    sft = np.broadcast_to(np.asarray(soft, dtype=np.float64), (len(p1),))[:, None]
    if np.any(sft < 0) or not np.all(np.isfinite(sft)):
        raise InputError("soft: expected finite values >= 0")
    t0, t1, tc = tangents(p1, p, p2)
    u = np.cross(nrm, tc)
    rho = np.sqrt(np.einsum("ij,ij->i", u, u)[:, None] + sft**2 * np.einsum("ij,ij->i", tc, tc)[:, None])
    rho = np.maximum(rho, 1e-300)
    a = u / rho
    c01 = np.cross(t0, t1)
    a0 = np.einsum("ij,ij->i", t0, a)[:, None]
    a1 = np.einsum("ij,ij->i", t1, a)[:, None]
    X = np.einsum("ij,ij->i", t0, t1) - a0[:, 0] * a1[:, 0] + float(soft_x) * np.einsum("ij,ij->i", tc, tc)
    Y = np.einsum("ij,ij->i", a, c01)
    theta = np.arctan2(Y, X)
    D = np.maximum(X * X + Y * Y, 1e-300)
    gx, gy = (-Y / D)[:, None], (X / D)[:, None]
    g_t0 = gy * np.cross(t1, a) + gx * (t1 - a1 * a)
    g_t1 = gy * np.cross(a, t0) + gx * (t0 - a0 * a)
    g_a = gy * c01 - gx * (a1 * t0 + a0 * t1)
    ug = np.einsum("ij,ij->i", u, g_a)[:, None]
    g_u = g_a / rho - u * ug / rho**3
    g_n = np.cross(tc, g_u)
    g_tc = np.cross(g_u, nrm) - ug * sft**2 * tc / rho**3 + gx * 2.0 * float(soft_x) * tc
    grad = (_T0[None, :, None] * g_t0[:, None, :] + _T1[None, :, None] * g_t1[:, None, :]
            + _TC[None, :, None] * g_tc[:, None, :])
    return theta, grad, g_n


def bending_angle(x1: Any, x: Any, x2: Any, normal: Any, soft: Any = 0.0, soft_x: float = 0.0) -> np.ndarray:
    """Oriented tangent angle ``theta`` of each fiber (7.10), shape (F,).

    Example
    -------
    >>> round(float(bending_angle([0, 0, 0], [1, 1, 0], [2, 0, 0], [0, 1, 0])[0]), 6)
    1.965587
    """
    return bending_angle_gradient(x1, x, x2, normal, soft, soft_x)[0]


def thesis_bending_angle(x1: Any, x: Any, x2: Any, normal: Any) -> np.ndarray:
    """The printed definition (B.9): ``sign(-N . f''(1/2)) arccos(t0.t1 / (|t0||t1|))``.

    Kept as a reference: it agrees with :func:`bending_angle` for moderately bent fibers
    in their normal plane and is discontinuous otherwise (see the module docstring).

    Example
    -------
    >>> round(float(thesis_bending_angle([0, 0, 0], [1, 1, 0], [2, 0, 0], [0, 1, 0])[0]), 6)
    1.965587
    """
    p1, p, p2 = _nodes(x1, x, x2)
    nrm = as_points(normal, "normal", length=len(p1))
    t0, t1, _ = tangents(p1, p, p2)
    second = 1.5 * (p1 - 2.0 * p + p2)  # f2''(0) in the local parameter
    sign = np.sign(-np.einsum("ij,ij->i", nrm, second))
    cos = np.einsum("ij,ij->i", t0, t1) / (np.linalg.norm(t0, axis=1) * np.linalg.norm(t1, axis=1))
    return sign * np.arccos(np.clip(cos, -1.0, 1.0))
