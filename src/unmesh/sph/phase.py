"""Phase transitions and heat (thesis section 8.2.4).

Solids and fluids differ only in whether a particle feels elastic lattice
forces, so melting and freezing just flip its phase. Both are Poisson processes:
a particle changes phase within a step with probability ``ω = 1 − e^(−λΔt)``
(eq. 8.34), with the melting rate ``λ_m = max(0, λ_m^0 (T − T_m))`` (8.35) and the
freezing rate of eq. (8.36) (see :func:`freezing_rate`). Random numbers come from
the scene seed through a counter-based generator (:mod:`unmesh.sph._rng`), so runs
are reproducible and resumable.

Temperature is conducted between particles by SPH heat conduction (in the force
pass) and driven by :class:`HeatSource` regions (a heated floor, a cooled rod):
particles within ``distance`` of the source's shape relax towards its temperature
at ``rate`` (``T ← T + (T_s − T)(1 − e^(−rate Δt))``).

Example
-------
>>> import numpy as np
>>> freezing_rate(1.0, -5.0, 0.0, n_solid=4, n_min=1, dv=0.0, v_max=1.0, force=0.0, f_max=1.0)
20.0
>>> transition_probability(np.array([0.0, np.log(2.0)]), 1.0).tolist()
[0.0, 0.5]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh.errors import InputError

__all__ = ["HeatSource", "freezing_rate", "melting_rate", "transition_probability"]


def transition_probability(rate: Any, dt: float) -> np.ndarray:
    """Eq. (8.34): probability ``1 − e^(−λΔt)`` of a transition within one step.

    Example
    -------
    >>> float(transition_probability(np.array([np.inf]), 0.1)[0])
    1.0
    """
    return -np.expm1(-np.asarray(rate, dtype=np.float64) * dt)


def melting_rate(lam0: float, temperature: Any, melting_point: float) -> np.ndarray:
    """Eq. (8.35): ``λ_m = max(0, λ_m^0 (T − T_m))`` (numpy reference).

    Example
    -------
    >>> melting_rate(2.0, np.array([0.0, 5.0]), 1.0).tolist()
    [0.0, 8.0]
    """
    return np.maximum(0.0, lam0 * (np.asarray(temperature, dtype=np.float64) - melting_point))


def freezing_rate(lam0: float, temperature: float, freezing_point: float, n_solid: int, n_min: int,
                  dv: float, v_max: float, force: float, f_max: float) -> float:
    """Eq. (8.36) for one particle (numpy reference of the numba kernel).

    ``λ_f = max(0, λ_f^0 (T_f − T)(n_s − n_min + 1) min(1, c_v) min(1, c_F))`` for
    ``n_s ≥ n_min`` (else 0), ``c_v = v_max / ‖v_i − v̄‖``, ``c_F = F_max / ‖ΣF‖``.
    The printed factor ``(n_s − n_min)`` vanishes for ``n_min = 0`` and no solid
    neighbours, contradicting the stated property that ``n_min = 0`` allows
    spontaneous freezing; ``+1`` restores it. Zero denominators of ``c_v`` and
    ``c_F`` mean no reduction (NOTES.md).

    Parameters
    ----------
    lam0 : float
        ``λ_f^0`` (1/(s·K)).
    temperature, freezing_point : float
        ``T`` and ``T_f``.
    n_solid, n_min : int
        Number of solid neighbours and the minimum required.
    dv : float
        ``‖v_i − v̄‖``, speed relative to the solid neighbours' mean velocity.
    v_max : float
    force : float
        ``‖Σ_j F_ij‖ / m_i`` of the hypothetical lattice forces (acceleration).
    f_max : float

    Returns
    -------
    float

    Example
    -------
    >>> freezing_rate(1.0, -2.0, 0.0, n_solid=3, n_min=1, dv=0.0, v_max=0.5, force=0.0, f_max=10.0)
    6.0
    """
    if lam0 <= 0.0 or temperature >= freezing_point or n_solid < n_min:
        return 0.0
    cv = 1.0 if dv <= v_max else v_max / dv
    cf = 1.0 if force <= f_max else f_max / force
    return max(0.0, lam0 * (freezing_point - temperature) * (n_solid - n_min + 1) * cv * cf)


@dataclass(frozen=True)
class HeatSource:
    """A region that heats or cools the particles near it.

    Parameters
    ----------
    shape : unmesh.shapes shape
        Region; particles with ``shape.implicit(x) <= distance`` are affected.
    temperature : float
        Temperature ``T_s`` the particles relax to.
    rate : float
        Relaxation rate (1/s, > 0).
    distance : float
        Reach outside the shape (≥ 0).
    name : str

    Example
    -------
    >>> from unmesh.shapes import Box
    >>> floor = HeatSource(Box(center=(0, -0.05, 0), size=(1, 0.1, 1)), temperature=80.0, rate=5.0, distance=0.02)
    >>> floor.mask(np.array([[0.0, 0.01, 0.0], [0.0, 0.5, 0.0]])).tolist()
    [True, False]
    """

    shape: Any
    temperature: float
    rate: float
    distance: float = 0.0
    name: str = "heat source"

    def __post_init__(self) -> None:
        if not (self.rate > 0 and math.isfinite(self.rate)):
            raise InputError(f"{self.name}.rate: expected a positive finite number, got {self.rate}")
        if not self.distance >= 0:
            raise InputError(f"{self.name}.distance: expected a number >= 0, got {self.distance}")
        if not math.isfinite(self.temperature):
            raise InputError(f"{self.name}.temperature: expected a finite number, got {self.temperature}")

    def mask(self, positions: np.ndarray) -> np.ndarray:
        """Which particles (N,) the source reaches (bounding box pre-test, then the implicit)."""
        b = np.asarray(self.shape.bounds(), dtype=np.float64)
        lo = b[0] - self.distance
        hi = b[1] + self.distance
        near = np.all((positions >= lo - 1e-12) & (positions <= hi + 1e-12), axis=1)
        out = np.zeros(len(positions), dtype=bool)
        idx = np.flatnonzero(near)
        if len(idx):
            vals = np.asarray(self.shape.implicit(positions[idx])[0])
            out[idx] = vals <= self.distance
        return out
