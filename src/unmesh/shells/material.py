"""Shell material: stiffness, damping, density, plasticity, fracture, anisotropy (thesis 7.2-7.3, F.1).

All material properties live on the fibers (7.3.3), so anisotropic and inhomogeneous
materials (7.3.4) are per-fiber factors on ``K_s`` and ``K_b`` and on the fracture
thresholds, set from the fiber's rest direction and centre position:

* :class:`Anisotropy`: factor ``f_par cos^2(a) + f_perp sin^2(a)`` where ``a`` is the
  angle between the fiber's rest tangent and a material direction (fibers of a woven
  sheet, grain of wood);
* :class:`MaterialRegion`: factors for fibers whose centre lies inside a shape (a stiff
  patch, or a *weak point* with lowered fracture thresholds as in Figure 7.8).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, scalar
from unmesh.errors import InputError
from unmesh.shells.fibers import ARC_SAMPLES
from unmesh.shells.plasticity import Plasticity

__all__ = ["Anisotropy", "MaterialRegion", "ShellMaterial"]


def _nonneg(v: Any, name: str) -> float:
    return scalar(v, name, 0.0)


def _threshold(v: Any, name: str) -> float:
    x = float(v)
    if not x > 0:
        raise InputError(f"{name}: expected a positive threshold (or inf to disable), got {v!r}")
    return x


@dataclass(frozen=True)
class Anisotropy:
    """Direction-dependent stiffness factors (7.3.4).

    Example
    -------
    >>> a = Anisotropy((1, 0, 0), stretch=(2.0, 1.0))
    >>> a.factors(np.array([[1.0, 0, 0], [0, 1.0, 0]]))[0]
    array([2., 1.])
    """

    direction: Any = (1.0, 0.0, 0.0)
    stretch: Any = (1.0, 1.0)
    bend: Any = (1.0, 1.0)

    def __post_init__(self) -> None:
        d = as_array(self.direction, "anisotropy.direction", (3,))
        if not np.linalg.norm(d) > 0:
            raise InputError("anisotropy.direction: expected a non-zero vector")
        object.__setattr__(self, "direction", d / np.linalg.norm(d))
        for name in ("stretch", "bend"):
            v = as_array(getattr(self, name), f"anisotropy.{name}", (2,))
            if np.any(v < 0):
                raise InputError(f"anisotropy.{name}: expected non-negative [parallel, perpendicular] factors")
            object.__setattr__(self, name, v)

    def factors(self, tangents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stretch and bend factors (F,) for fiber rest tangents (F, 3)."""
        t = tangents / np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-300)
        c2 = (t @ self.direction) ** 2
        return (self.stretch[0] * c2 + self.stretch[1] * (1 - c2), self.bend[0] * c2 + self.bend[1] * (1 - c2))


@dataclass(frozen=True)
class MaterialRegion:
    """Factors for fibers centred inside ``region`` (anything with ``contains(points) -> bool``).

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> r = MaterialRegion(Sphere(radius=0.5), fracture=0.3)
    >>> r.fracture
    0.3
    """

    region: Any
    stretch: float = 1.0
    bend: float = 1.0
    fracture: float = 1.0

    def __post_init__(self) -> None:
        if not hasattr(self.region, "contains"):
            raise InputError("region: expected a shape with a contains(points) method")
        for name in ("stretch", "bend"):
            object.__setattr__(self, name, _nonneg(getattr(self, name), name))
        object.__setattr__(self, "fracture", _threshold(self.fracture, "fracture"))


@dataclass(frozen=True)
class ShellMaterial:
    """Everything Appendix F.1 lists per example, plus density and per-fiber variation.

    Parameters
    ----------
    ks, kb : float
        Stretching and bending stiffness ``K_s``, ``K_b`` (7.7, 7.11).
    damping : float
        ``D`` of (7.18), mass-proportional, 1/s.
    density : float
        Mass per unit area (node masses are lumped from their areas).
    plasticity : Plasticity
        Yield thresholds ``beta`` and creep rates ``alpha`` (7.19-7.23), weakening ``chi`` (7.25).
    fracture_stretch, fracture_bend : float
        ``gamma_s`` (strain) and ``gamma_b`` (radians) of (7.24); inf disables fracture.
    anisotropy : Anisotropy, optional
    regions : tuple of MaterialRegion
        Applied in order (factors multiply).
    arc_samples : int
        Arc-length samples per fiber segment (B.4).

    Example
    -------
    >>> m = ShellMaterial(ks=25, kb=25, damping=0.4)
    >>> m.fiber_material(np.array([[1, 0, 2]]), np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]))["stretch_scale"]
    array([1.])
    """

    ks: float
    kb: float
    damping: float = 0.0
    density: float = 1.0
    plasticity: Plasticity = field(default_factory=Plasticity)
    fracture_stretch: float = np.inf
    fracture_bend: float = np.inf
    anisotropy: Anisotropy | None = None
    regions: tuple[MaterialRegion, ...] = ()
    arc_samples: int = ARC_SAMPLES

    def __post_init__(self) -> None:
        for name in ("ks", "kb", "damping"):
            object.__setattr__(self, name, _nonneg(getattr(self, name), name))
        d = scalar(self.density, "density")
        if not d > 0:
            raise InputError(f"density: expected a positive mass per area, got {d}")
        object.__setattr__(self, "density", d)
        for name in ("fracture_stretch", "fracture_bend"):
            object.__setattr__(self, name, _threshold(getattr(self, name), name))
        if int(self.arc_samples) != self.arc_samples or self.arc_samples < 1:
            raise InputError(f"arc_samples: expected a positive integer, got {self.arc_samples!r}")
        object.__setattr__(self, "regions", tuple(self.regions))

    @property
    def fractures(self) -> bool:
        """True when fibers can break."""
        return bool(np.isfinite(self.fracture_stretch) or np.isfinite(self.fracture_bend))

    def fiber_material(self, fibers: np.ndarray, rest: np.ndarray) -> dict[str, np.ndarray]:
        """Per-fiber stiffness factors and fracture thresholds for fibers (F, 3) on rest nodes (N, 3)."""
        f = len(fibers)
        stretch = np.ones(f)
        bend = np.ones(f)
        frac = np.ones(f)
        if f and self.anisotropy is not None:
            s, b = self.anisotropy.factors(rest[fibers[:, 2]] - rest[fibers[:, 0]])
            stretch, bend = stretch * s, bend * b
        if f:
            centers = rest[fibers[:, 1]]
            for r in self.regions:
                inside = np.asarray(r.region.contains(centers), dtype=bool)
                stretch[inside] *= r.stretch
                bend[inside] *= r.bend
                frac[inside] *= r.fracture
        return {"stretch_scale": stretch, "bend_scale": bend, "fracture_stretch": self.fracture_stretch * frac,
                "fracture_bend": self.fracture_bend * frac}
