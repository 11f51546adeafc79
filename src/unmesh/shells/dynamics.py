"""Dynamics of the shell nodes (thesis 7.2.2, eq. 7.18): integrator, colliders, external forces.

The governing equation ``M X'' + D X' = F_int + F_ext`` (7.18) is integrated with velocity
Verlet. ``M`` is the lumped (diagonal) node mass; the damping term is read as
mass-proportional, ``F_damp,i = -D m_i v_i`` with ``D`` in 1/s, so a given ``D`` damps the
same whatever the node count (the thesis leaves the mass scale open; with unit node masses
both readings agree).

External forces (all :class:`ExternalForce`):

* :class:`Gravity` ``m_i g``;
* :class:`Pressure` ``p(t) a_i N_i`` along the node normals (an inflated balloon), with the
  node area ``a_i`` following the local stretch; ``p(t)`` may ramp up and drops
  exponentially after the first crack (the air escapes);
* :class:`Pull` a total force on a group of nodes (tearing), optionally ramped.

Colliders (:class:`PlaneCollider`, :class:`SphereCollider`) push penetrating nodes back to
the surface and apply restitution and Coulomb friction to their velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar, scalar
from unmesh.errors import InputError

__all__ = [
    "ExternalForce",
    "Gravity",
    "Handle",
    "PlaneCollider",
    "Pressure",
    "Pull",
    "SphereCollider",
    "damping_force",
]


def damping_force(velocity: np.ndarray, mass: np.ndarray, damping: float) -> np.ndarray:
    """Mass-proportional damping ``-D m_i v_i`` (7.18), (N, 3).

    Example
    -------
    >>> damping_force(np.array([[1.0, 0, 0]]), np.array([2.0]), 0.5)
    array([[-1., -0., -0.]])
    """
    return -damping * mass[:, None] * velocity


def _unit(v: Any, name: str) -> np.ndarray:
    arr = as_array(v, name, (3,))
    n = np.linalg.norm(arr)
    if not n > 0:
        raise InputError(f"{name}: expected a non-zero vector, got {arr.tolist()}")
    return arr / n


def _friction(v: np.ndarray, normal: np.ndarray, hit: np.ndarray, restitution: float, friction: float) -> None:
    """In place: reflect the inward normal velocity of ``hit`` rows, Coulomb friction on the rest."""
    if not hit.any():
        return
    vh = v[hit]
    nh = normal[hit] if normal.ndim == 2 else normal[None, :]
    vn = np.einsum("ij,ij->i", vh, nh) if normal.ndim == 2 else vh @ normal
    inward = vn < 0
    vt = vh - vn[:, None] * nh
    dvn = np.where(inward, -(1.0 + restitution) * vn, 0.0)
    tn = np.linalg.norm(vt, axis=1)
    keep = np.where(tn > 0, np.maximum(0.0, 1.0 - friction * dvn / np.maximum(tn, 1e-300)), 1.0)
    new_vn = np.where(inward, -restitution * vn, vn)
    v[hit] = vt * keep[:, None] + new_vn[:, None] * nh


@dataclass(frozen=True)
class PlaneCollider:
    """The half-space ``(x - point) . normal >= 0`` is free; nodes below are pushed back.

    Parameters
    ----------
    point, normal : array_like (3,)
    restitution : float
        Fraction of the normal velocity kept (0 = inelastic, 1 = elastic).
    friction : float
        Coulomb friction coefficient.

    Example
    -------
    >>> floor = PlaneCollider((0, 0, 0), (0, 1, 0), restitution=0.0)
    >>> x, v = np.array([[0.0, -0.1, 0]]), np.array([[1.0, -2, 0]])
    >>> floor.resolve(x, v); x, v
    (array([[0., 0., 0.]]), array([[0., 0., 0.]]))
    """

    point: Any = (0.0, 0.0, 0.0)
    normal: Any = (0.0, 1.0, 0.0)
    restitution: float = 0.0
    friction: float = 0.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", as_array(self.point, "point", (3,)))
        object.__setattr__(self, "normal", _unit(self.normal, "normal"))
        object.__setattr__(self, "restitution", scalar(self.restitution, "restitution", 0.0, 1.0))
        object.__setattr__(self, "friction", scalar(self.friction, "friction", 0.0))

    def resolve(self, x: np.ndarray, v: np.ndarray) -> None:
        """Project penetrating rows of ``x`` (N, 3) onto the plane and update ``v`` in place."""
        d = (x - self.point) @ self.normal
        hit = d < 0
        if hit.any():
            x[hit] -= d[hit, None] * self.normal
            _friction(v, self.normal, hit, self.restitution, self.friction)


@dataclass(frozen=True)
class SphereCollider:
    """A solid ball; nodes inside are pushed to its surface.

    Example
    -------
    >>> ball = SphereCollider((0, 0, 0), 1.0)
    >>> x, v = np.array([[0.0, 0.5, 0]]), np.zeros((1, 3))
    >>> ball.resolve(x, v); x
    array([[0., 1., 0.]])
    """

    center: Any = (0.0, 0.0, 0.0)
    radius: float = 1.0
    restitution: float = 0.0
    friction: float = 0.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", as_array(self.center, "center", (3,)))
        object.__setattr__(self, "radius", positive_scalar(self.radius, "radius"))
        object.__setattr__(self, "restitution", scalar(self.restitution, "restitution", 0.0, 1.0))
        object.__setattr__(self, "friction", scalar(self.friction, "friction", 0.0))

    def resolve(self, x: np.ndarray, v: np.ndarray) -> None:
        """Project rows of ``x`` inside the ball onto its surface and update ``v`` in place."""
        r = x - self.center
        d = np.linalg.norm(r, axis=1)
        hit = d < self.radius
        if hit.any():
            n = np.zeros_like(r)
            n[hit] = r[hit] / np.maximum(d[hit], 1e-300)[:, None]
            n[hit & (d == 0)] = (0.0, 1.0, 0.0)
            x[hit] = self.center + self.radius * n[hit]
            _friction(v, n, hit, self.restitution, self.friction)


@dataclass(frozen=True)
class ExternalForce:
    """Base class: ``force(sim_state) -> (N, 3)``."""

    def force(self, time: float, x: np.ndarray, v: np.ndarray, mass: np.ndarray, area: np.ndarray,
              normals: np.ndarray, first_crack: float | None) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class Gravity(ExternalForce):
    """``m_i g``.

    Example
    -------
    >>> Gravity((0, -10, 0)).force(0.0, np.zeros((1, 3)), None, np.array([2.0]), None, None, None)
    array([[  0., -20.,   0.]])
    """

    g: Any = (0.0, -9.81, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "g", as_array(self.g, "gravity", (3,)))

    def force(self, time, x, v, mass, area, normals, first_crack):
        return mass[:, None] * self.g[None, :]

    def potential(self, x: np.ndarray, mass: np.ndarray) -> float:
        """Gravitational potential energy ``-sum m_i g . x_i``."""
        return float(-(mass * (x @ self.g)).sum())


@dataclass(frozen=True)
class Pressure(ExternalForce):
    """Inflation pressure along node normals: ``p(t) a_i N_i``.

    ``p(t) = min(pressure + rate t, maximum)``; once the shell has cracked (time
    ``t_c``), ``p`` is multiplied by ``exp(-(t - t_c) / release)`` (``release = inf``
    keeps it). ``a_i`` is the current node area (rest area times the local stretch).

    Example
    -------
    >>> p = Pressure(pressure=2.0)
    >>> p.value(1.0, None)
    2.0
    """

    pressure: float = 0.0
    rate: float = 0.0
    maximum: float = math.inf
    release: float = math.inf

    def __post_init__(self) -> None:
        object.__setattr__(self, "pressure", scalar(self.pressure, "pressure"))
        object.__setattr__(self, "rate", scalar(self.rate, "rate"))
        if not self.maximum > -math.inf:
            raise InputError(f"maximum: expected a number, got {self.maximum}")
        if not self.release > 0:
            raise InputError(f"release: expected a positive time, got {self.release}")

    def value(self, time: float, first_crack: float | None) -> float:
        """Pressure at ``time``."""
        p = min(self.pressure + self.rate * time, self.maximum)
        if first_crack is not None and math.isfinite(self.release):
            p *= math.exp(-max(time - first_crack, 0.0) / self.release)
        return p

    def force(self, time, x, v, mass, area, normals, first_crack):
        return self.value(time, first_crack) * area[:, None] * normals


@dataclass(frozen=True)
class Pull(ExternalForce):
    """A total force on the nodes ``nodes``, shared in proportion to their masses.

    Active for ``start <= t < stop``, ramped linearly from 0 over ``ramp`` seconds.

    Example
    -------
    >>> f = Pull(nodes=[0], total=(1.0, 0, 0)).force(0.0, np.zeros((2, 3)), None, np.ones(2), None, None, None)
    >>> f
    array([[1., 0., 0.],
           [0., 0., 0.]])
    """

    nodes: Any = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    total: Any = (0.0, 0.0, 0.0)
    ramp: float = 0.0
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", as_array(self.nodes, "nodes", (None,), np.int64))
        object.__setattr__(self, "total", as_array(self.total, "force", (3,)))
        object.__setattr__(self, "ramp", scalar(self.ramp, "ramp", 0.0))

    def scale(self, time: float) -> float:
        """Activation factor in [0, 1] at ``time``."""
        if time < self.start or time >= self.stop:
            return 0.0
        return 1.0 if self.ramp <= 0 else min(1.0, (time - self.start) / self.ramp)

    def force(self, time, x, v, mass, area, normals, first_crack):
        out = np.zeros_like(x)
        k = self.scale(time)
        if k > 0 and len(self.nodes):
            w = mass[self.nodes] / mass[self.nodes].sum()
            out[self.nodes] = k * w[:, None] * self.total[None, :]
        return out


@dataclass(frozen=True)
class Handle:
    """Nodes moved kinematically during ``[start, stop)`` with velocity ``velocity + acceleration
    * (t - start)``; fixed otherwise.

    Example
    -------
    >>> h = Handle(nodes=[0], velocity=(1.0, 0, 0), stop=2.0)
    >>> h.displacement(3.0)
    array([2., 0., 0.])
    >>> Handle(nodes=[0], velocity=(1.0, 0, 0), acceleration=(2.0, 0, 0)).displacement(1.0)
    array([2., 0., 0.])
    """

    nodes: Any = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    velocity: Any = (0.0, 0.0, 0.0)
    start: float = 0.0
    stop: float = math.inf
    acceleration: Any = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", as_array(self.nodes, "nodes", (None,), np.int64))
        object.__setattr__(self, "velocity", as_array(self.velocity, "velocity", (3,)))
        object.__setattr__(self, "acceleration", as_array(self.acceleration, "acceleration", (3,)))

    def displacement(self, time: float) -> np.ndarray:
        """Displacement from the rest position at ``time``, (3,)."""
        active = min(max(time, self.start), self.stop) - self.start
        return self.velocity * active + 0.5 * self.acceleration * active**2

    def current_velocity(self, time: float) -> np.ndarray:
        """Velocity at ``time``, (3,)."""
        if not self.start <= time < self.stop:
            return np.zeros(3)
        return self.velocity + self.acceleration * (time - self.start)
