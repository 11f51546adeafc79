"""Materials of the visco-elastic SPH model (thesis chapter 8, Appendix F.2).

A :class:`Material` bundles the fluid parameters (eqs. 8.15–8.19), the elastic
lattice parameters (section 8.2, eqs. 8.29–8.31, or Young's modulus and Poisson
ratio for the strain-based forces), fracture (docking rates, section 8.2.5),
heat conduction and the phase-transition rates (eqs. 8.34–8.36). A particle keeps
its material through phase changes: fluid particles ignore the elastic
parameters, solid particles use them.

Appendix F.2 uses ``Γ = 1``, ``ρ0 = 1`` (the defaults here) and, for the melting
bunny of Fig. 8.4, ``K = 200``, ``ξ = 0.1``, ``ζ = 0.01``, ``K_e = 39528``.

Example
-------
>>> jelly = Material("jelly", stiffness=200.0, xsph=0.1, negative_pressure=0.01, elastic_stiffness=39528.0)
>>> jelly.is_elastic, material_table([jelly]).shape
(True, (1, 28))
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from unmesh.errors import InputError

__all__ = ["Material", "material_table"]

# Column indices of the material table passed to the numba kernels.
RHO0, K, GAMMA, ZETA, VISC, XI, KE, GOAL, LMU, LLAM, DIFF = range(11)
DOCK_MAX, DOCK_GAIN, DOCK_LOSS, FRACTURE, MELT_RATE, MELT_T = range(11, 17)
FREEZE_RATE, FREEZE_T, FREEZE_NMIN, FREEZE_VMAX, FREEZE_FMAX = range(17, 22)
ALPHA, SOUND, DENSITY_DIFFUSION, DENSITY_PASSES = 22, 23, 24, 25
YIELD, CREEP = 26, 27
NCOL = 28


@dataclass(frozen=True)
class Material:
    """Parameters of one SPH material (symbols of chapter 8 in brackets).

    Parameters
    ----------
    name : str
    density : float
        Rest density ``ρ0`` (kg/m³ in SI; the thesis uses 1).
    stiffness : float
        Pressure stiffness ``K`` of eq. (8.15) (Pa); speed of sound ``√(ΓK/ρ0)``.
    gamma : float
        Exponent ``Γ`` of eq. (8.15).
    negative_pressure : float
        ``ζ`` of eq. (8.16): negative pressures are scaled by it (0 clamps them).
    viscosity : float
        Dynamic viscosity ``μ`` of eq. (8.18) (Pa·s).
    xsph : float
        XSPH factor ``ξ`` of eq. (8.19) in [0, 1].
    artificial_viscosity : float
        Monaghan's artificial viscosity ``α`` (dimensionless; acts only between
        approaching particles, ``Π_ij = −α c h (v_ij·x_ij)/(ρ̄ (r² + 0.01h²))``). The
        spiky pressure gradient (8.17) with poly6 densities (8.4) does not derive
        from a potential and pumps energy into compressed particle arrangements; a
        small ``α`` removes that without visible damping of the flow.
    elastic_stiffness : float
        ``K_e`` of eq. (8.31) (1/s²); 0 = no direct elastic forces.
    goal_deformation : float
        ``s`` of eq. (8.30) in [0, 1].
    young, poisson : float
        Young's modulus (Pa; 0 = no strain-based forces) and Poisson ratio of the
        linear-elastic stress (section 8.2.2).
    docking_rate : float
        Maximum docking rate ``λ_d`` of a lattice slot (1/s; ``inf`` = immediate).
    docking_gain, docking_loss : float
        ``Δλ_d^+`` and ``Δλ_d^-`` per second (1/s²) for occupied / empty slots.
    plastic_yield : float
        Yield strain ``β`` of the stored plastic deformation (``inf`` = none, the default: only
        the inherent plasticity of section 8.2.5). Each solid particle keeps a rest shape ``P``
        of its lattice (rest offsets ``P l``, ``det P = 1``); when the isochoric elastic stretch
        of its neighbourhood deviates from the identity by more than ``β`` (Frobenius norm), the
        rest shape creeps towards the current shape — the yield and creep rule of the thesis'
        shells (7.20–7.22) applied to the lattice, the "stored plastic strain" that section 8.2.5
        names as an addition to the inherent plasticity.
    plastic_creep : float
        Creep rate ``α`` (1/s) of that rule; ``α Δt ≥ 1`` (e.g. ``inf``) returns a yielding
        particle to the yield surface within one step (perfect plasticity).
    fracture_stretch : float
        Stress criterion (section 8.2.5, "modifies λ_d"): a docked neighbour stretched beyond
        ``(1 + fracture_stretch)`` times its lattice distance makes its slot lose ``Δλ_d^-`` per
        second, as if it were empty, and is released when the rate reaches 0 (at once when
        the docking gain is infinite).
    diffusivity : float
        Thermal diffusivity (m²/s) of the SPH heat conduction.
    melt_rate, melting_point : float
        ``λ_m^0`` (1/(s·K)) and ``T_m`` of eq. (8.35).
    freeze_rate, freezing_point : float
        ``λ_f^0`` (1/(s·K)) and ``T_f`` of eq. (8.36).
    freeze_min_neighbors : int
        ``n_min`` of eq. (8.36) (0: spontaneous freezing allowed).
    freeze_max_velocity : float
        ``v_max`` of ``c_v`` in eq. (8.36) (m/s).
    freeze_max_force : float
        ``F_max`` of ``c_F`` in eq. (8.36), as an acceleration (m/s²).
    density_diffusion : float
        ``δ`` in [0, 1] of the δ-SPH density filter of the fluid phase (Molteni & Colagrossi
        2009 with Antuono et al.'s 2010 correction, :mod:`unmesh.sph._diffusion_kernels`):
        the summation density (8.4) of a fluid particle moves the fraction ``δ`` of the way
        to the linearly corrected average of its fluid neighbours before the pressure
        (8.15) is taken from it. It removes the particle-scale pressure noise of a
        disordered arrangement (a resting column's pressure becomes linear in depth),
        conserves mass (``Σ m_i Δρ_i = 0``) and leaves a linear density field unchanged.
        0 (the default) disables it: the thesis' plain summation density. Solid particles
        are never filtered.
    density_passes : int
        Number of filter passes per force evaluation (each on the previous result); the
        particle-scale smoothing grows with it, and so does the cost (two neighbour loops
        per pass).

    Example
    -------
    >>> water = Material("water", stiffness=2000.0)
    >>> round(water.sound_speed, 2), water.is_elastic
    (44.72, False)
    """

    name: str = "material"
    density: float = 1.0
    stiffness: float = 200.0
    gamma: float = 1.0
    negative_pressure: float = 0.01
    viscosity: float = 0.0
    xsph: float = 0.0
    artificial_viscosity: float = 0.05
    elastic_stiffness: float = 0.0
    goal_deformation: float = 0.5
    young: float = 0.0
    poisson: float = 0.3
    docking_rate: float = math.inf
    docking_gain: float = math.inf
    docking_loss: float = 0.0
    fracture_stretch: float = math.inf
    diffusivity: float = 0.0
    melt_rate: float = 0.0
    melting_point: float = math.inf
    freeze_rate: float = 0.0
    freezing_point: float = -math.inf
    freeze_min_neighbors: int = 1
    freeze_max_velocity: float = math.inf
    freeze_max_force: float = math.inf
    density_diffusion: float = 0.0
    density_passes: int = 1
    plastic_yield: float = math.inf
    plastic_creep: float = math.inf

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "name":
                continue
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
                raise InputError(f"{self.name}.{f.name}: expected a number, got {value!r}")
        positive = ("density", "stiffness", "gamma")
        for key in positive:
            if not (getattr(self, key) > 0 and math.isfinite(getattr(self, key))):
                raise InputError(f"{self.name}.{key}: expected a positive finite number, got {getattr(self, key)}")
        nonneg = ("viscosity", "artificial_viscosity", "elastic_stiffness", "young", "docking_rate", "docking_gain", "docking_loss",
                  "fracture_stretch", "diffusivity", "melt_rate", "freeze_rate", "freeze_max_velocity",
                  "freeze_max_force", "plastic_yield", "plastic_creep")
        for key in nonneg:
            if not getattr(self, key) >= 0:
                raise InputError(f"{self.name}.{key}: expected a number >= 0, got {getattr(self, key)}")
        for key in ("negative_pressure", "xsph", "goal_deformation", "density_diffusion"):
            if not 0.0 <= getattr(self, key) <= 1.0:
                raise InputError(f"{self.name}.{key}: expected a number in [0, 1], got {getattr(self, key)}")
        if (isinstance(self.density_passes, float) and not self.density_passes.is_integer()) or self.density_passes < 1:
            raise InputError(f"{self.name}.density_passes: expected an integer >= 1, got {self.density_passes!r}")
        object.__setattr__(self, "density_passes", int(self.density_passes))
        if not -1.0 < self.poisson < 0.5:
            raise InputError(f"{self.name}.poisson: expected a Poisson ratio in (-1, 0.5), got {self.poisson}")
        for key in ("elastic_stiffness", "young", "viscosity", "diffusivity", "artificial_viscosity"):
            if not math.isfinite(getattr(self, key)):
                raise InputError(f"{self.name}.{key}: expected a finite number, got {getattr(self, key)}")

    @property
    def is_elastic(self) -> bool:
        """True when solid particles of this material feel lattice forces."""
        return self.elastic_stiffness > 0 or self.young > 0

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé parameters ``(μ, λ)`` of the strain-based forces."""
        nu = self.poisson
        return self.young / (2.0 * (1.0 + nu)), self.young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))

    @property
    def sound_speed(self) -> float:
        """``√(Γ K / ρ0)`` (m/s)."""
        return math.sqrt(self.gamma * self.stiffness / self.density)


def material_table(materials: list[Material]) -> np.ndarray:
    """Pack materials into the (n_materials, 28) float64 table of the numba kernels.

    Example
    -------
    >>> float(material_table([Material(density=2.0)])[0, RHO0])
    2.0
    """
    t = np.zeros((len(materials), NCOL))
    for i, mat in enumerate(materials):
        mu, lam = mat.lame
        t[i, [RHO0, K, GAMMA, ZETA, VISC, XI, KE, GOAL, LMU, LLAM, DIFF]] = (
            mat.density, mat.stiffness, mat.gamma, mat.negative_pressure, mat.viscosity, mat.xsph,
            mat.elastic_stiffness, mat.goal_deformation, mu, lam, mat.diffusivity)
        t[i, [DOCK_MAX, DOCK_GAIN, DOCK_LOSS, FRACTURE, MELT_RATE, MELT_T]] = (
            mat.docking_rate, mat.docking_gain, mat.docking_loss, mat.fracture_stretch, mat.melt_rate,
            mat.melting_point)
        t[i, [FREEZE_RATE, FREEZE_T, FREEZE_NMIN, FREEZE_VMAX, FREEZE_FMAX]] = (
            mat.freeze_rate, mat.freezing_point, mat.freeze_min_neighbors, mat.freeze_max_velocity,
            mat.freeze_max_force)
        t[i, ALPHA] = mat.artificial_viscosity
        t[i, SOUND] = mat.sound_speed
        t[i, DENSITY_DIFFUSION] = mat.density_diffusion
        t[i, DENSITY_PASSES] = mat.density_passes
        t[i, YIELD] = mat.plastic_yield
        t[i, CREEP] = mat.plastic_creep
    return t
