"""Plasticity with creep and weakening of fibers (thesis 7.3.1, 7.3.3; eqs. 7.19-7.23, 7.25).

A fiber's rest state is ``l^0 = l_orig + l_plastic``, ``theta^0 = theta_orig +
theta_plastic`` (7.19). In every time step in which the deformation exceeds a yield
threshold, the plastic part creeps towards the current state::

    |l - l^0| > beta_s l^0      =>  l_plastic     += alpha_s (l - l^0) dt        (7.20, 7.22)
    |theta - theta^0| > beta_b  =>  theta_plastic += alpha_b (theta - theta^0) dt (7.21, 7.23)

The stretch threshold is read as a strain (relative to ``l^0``) so that it does not depend
on the model's units; the bending threshold is an angle in radians. Repeated plastic
bending weakens the fiber: its bending fracture threshold changes by
``Delta gamma_b = -chi gamma_b |Delta theta_plastic|`` (7.25).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh._validate import scalar
from unmesh.shells.energy import FiberState

__all__ = ["Plasticity"]


@dataclass(frozen=True)
class Plasticity:
    """Yield thresholds, creep rates and weakening.

    Parameters
    ----------
    creep_stretch, creep_bend : float
        ``alpha_s``, ``alpha_b`` (1/s): how fast the rest state follows (7.22, 7.23).
    yield_stretch : float
        ``beta_s``, strain threshold ``|l - l^0| / l^0`` (7.20).
    yield_bend : float
        ``beta_b``, angle threshold in radians (7.21).
    weakening : float
        ``chi`` of (7.25); 0 disables weakening.

    Example
    -------
    >>> p = Plasticity(creep_stretch=2.0, creep_bend=2.0, yield_stretch=0.2, yield_bend=0.2)
    >>> s = FiberState.uniform([1.0, 1.0], [0.0, 0.0])
    >>> p.update(s, np.array([1.5, 1.1]), np.array([0.0, 0.5]), dt=0.1)
    (1, 1)
    >>> s.length_plastic.round(3), s.angle_plastic.round(3)
    (array([0.1, 0. ]), array([0. , 0.1]))
    """

    creep_stretch: float = 0.0
    creep_bend: float = 0.0
    yield_stretch: float = np.inf
    yield_bend: float = np.inf
    weakening: float = 0.0

    def __post_init__(self) -> None:
        for name in ("creep_stretch", "creep_bend", "weakening"):
            object.__setattr__(self, name, scalar(getattr(self, name), name, 0.0))
        for name in ("yield_stretch", "yield_bend"):
            v = float(getattr(self, name))
            if not v >= 0:
                from unmesh.errors import InputError

                raise InputError(f"{name}: expected a number >= 0 (or inf), got {v}")
            object.__setattr__(self, name, v)

    @property
    def active(self) -> bool:
        """False when no fiber can ever yield."""
        return (self.creep_stretch > 0 and np.isfinite(self.yield_stretch)) or (
            self.creep_bend > 0 and np.isfinite(self.yield_bend))

    def update(self, state: FiberState, lengths: np.ndarray, angles: np.ndarray, dt: float) -> tuple[int, int]:
        """Apply one time step of (7.20)-(7.23) and (7.25) to ``state`` in place.

        Parameters
        ----------
        state : FiberState
            Updated in place (``length_plastic``, ``angle_plastic``, ``fracture_bend``).
        lengths, angles : ndarray (F,)
            Current ``l~`` and ``theta`` of every fiber.
        dt : float
            Time step.

        Returns
        -------
        (int, int)
            Number of fibers that yielded in stretching and in bending.
        """
        if not self.active:
            return 0, 0
        ns = nb = 0
        if self.creep_stretch > 0 and np.isfinite(self.yield_stretch):
            l0 = state.rest_length()
            dl = lengths - l0
            y = np.abs(dl) > self.yield_stretch * l0
            if y.any():
                state.length_plastic[y] += self.creep_stretch * dl[y] * dt
                ns = int(y.sum())
        if self.creep_bend > 0 and np.isfinite(self.yield_bend):
            dth = angles - state.rest_angle()
            y = np.abs(dth) > self.yield_bend
            if y.any():
                step = self.creep_bend * dth[y] * dt
                state.angle_plastic[y] += step
                if self.weakening > 0:
                    state.fracture_bend[y] *= np.maximum(0.0, 1.0 - self.weakening * np.abs(step))
                nb = int(y.sum())
        return ns, nb
