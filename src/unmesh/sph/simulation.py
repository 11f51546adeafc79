"""The SPH simulation: state, time step, diagnostics and output (thesis chapter 8).

:class:`SPHSimulation` implements :class:`unmesh.sim.Simulation`; the runner
(:func:`unmesh.sim.run`) owns the time loop, frames, ``summary.json``,
checkpoints and instability handling.

One step (velocity Verlet in kick-drift-kick form, one force evaluation):

1. ``v ← v + ½Δt a``; ``x ← x + Δt (v + Δv_XSPH)`` (XSPH, eq. 8.19, moves the
   particles with smoothed velocities); walls push back particles that crossed them.
2. Particles are re-sorted by grid cell (``unmesh.spatial`` cell grid of edge ``h/2``), unless the
   Verlet candidates of the last cell scan still cover every neighbourhood (``SPHConfig.neighbor_skin``).
3. Density pass: neighbour lists (by a cell scan or from the candidates), density (8.4), pressure
   (8.15–8.16).
4. Lattice pass (if any solid): assignment (8.21), docking, shape matching
   (8.23–8.24), goal positions (8.29–8.30), strain stress, exact torque correction.
5. Force pass: pressure (8.17), viscosity (8.18), elastic forces, collisions
   (8.37), walls, gravity, heat conduction.
6. ``v ← v + ½Δt a``; temperatures; heat sources; melting and freezing (8.34–8.36).

Example
-------
>>> import numpy as np
>>> from unmesh.sph import SPHSimulation, SPHConfig, SPHObject, Material, box_planes
>>> from unmesh.sph.sampling import closest_packing
>>> cfg = SPHConfig(dim=2, spacing=0.05, dt=1e-3, gravity=(0, -9.81, 0))
>>> water = SPHObject("water", closest_packing([0, 0, 0], [0.3, 0.3, 0], 0.05, 2), material="water")
>>> sim = SPHSimulation(cfg, {"water": Material("water", stiffness=500.0, xsph=0.1)}, [water],
...                     planes=box_planes([0, 0, 0], [1, 1, 0], 2))
>>> dt = sim.step()
>>> sim.particles().phase_counts()
{'fluid': 36, 'solid': 0}
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unmesh._threads import serial_if_small
from unmesh._validate import as_array, as_points
from unmesh.errors import InputError
from unmesh.sim import Simulation
from unmesh.sph import _diffusion_kernels as DK
from unmesh.sph import _elastic_kernels as EK
from unmesh.sph import _kernels as K
from unmesh.sph import _phase_kernels as PK
from unmesh.sph import _slot_kernels as SK
from unmesh.sph import materials as MT
from unmesh.sph.boundary import (
    BoundaryParticles,
    Plane,
    corner_moment_tables,
    corner_pairs,
    corner_tables,
    wall_friction_tables,
    wall_moment_tables,
    wall_tables,
)
from unmesh.sph.elastic import rotation_svd
from unmesh.sph.front import surge_front
from unmesh.sph.materials import Material, material_table
from unmesh.sph.phase import HeatSource
from unmesh.sph.sampling import LATTICES, gradient_moment, lattice_basis, lattice_frame, lattice_points, lattice_slots
from unmesh.sph.state import FLUID, SOLID, ParticleState

__all__ = ["SPHConfig", "SPHObject", "SPHSimulation"]

#: Below this many particles the kernels run on one thread (thread start-up costs more than it saves;
#: :func:`unmesh._threads.serial_if_small`).
PARALLEL_MIN = 2000

_PARTICLE_ARRAYS = ("x", "v", "a", "xsph", "m", "rho", "p", "temp", "dtemp", "phase", "obj", "mat", "uid", "fixed",
                    "rho_t")
_ELASTIC_ARRAYS = ("amat", "ainv", "occ", "docked", "lam", "pmat")
#: Per-particle arrays that every step recomputes after the re-sort (not re-sorted in a step).
_RECOMPUTED = ("a", "xsph", "rho", "p", "dtemp")
#: Lattice state that the lattice pass reads in the previous order and writes in the new one (not re-sorted in a step).
_RESORTED_BY_LATTICE = ("amat", "ainv", "occ", "docked", "pmat")


@dataclass(frozen=True)
class SPHConfig:
    """Simulation-wide settings.

    Parameters
    ----------
    dim : int
        2 or 3.
    spacing : float
        Particle spacing ``d`` (nearest-neighbour distance of the closest packing).
    dt : float
        Time step (the maximum step when ``cfl`` is set).
    smoothing : float
        ``h / d``; Appendix F.2: ``h`` is twice the particle radius ``d``, so 2.
    cfl : float or None
        If set, the step is ``min(dt, cfl·h/(c + v_max), ...)`` (see
        :meth:`SPHSimulation.stable_dt`); else ``dt`` is fixed.
    gravity : array_like (3,)
    seed : int
        Seed of the random processes (melting, freezing, docking).
    wall_pressure : float
        Scale of the wall pressure term (1: Akinci et al. 2012).
    neighbor_capacity : int
        Initial capacity of the neighbour lists (grown automatically).
    gradient_correction : bool
        Scale the pair kernel gradients by ``1 / gradient_moment`` so that the
        pressure gradient (8.17) is exact on the rest lattice (with ``h = 2d`` the
        spiky gradient underestimates it by 13 % in 2D and 5 % in 3D). A constant
        factor keeps the forces symmetric and momentum-conserving.
    tensile_correction : float
        ε of Monaghan's (2000) tensile correction (artificial pressure), applied to pairs closer
        than ``d/2`` only: a pair with negative pressure is also pushed apart by
        ``ε (|p_i⁻|/ρ_i² + |p_j⁻|/ρ_j²) ((W(r)/W(d/2))⁴ − 1)₊ ∇W`` (poly6 ``W``), which is 0 from
        ``r = d/2`` on (a fluid at rest is unaffected), outweighs the tension's pull from
        ``r ≈ 0.42 d`` inwards and is 37 times it at ``r = 0`` (``ε = 4``, ``h = 2d``), so tension
        cannot pull particles onto each other (the pairing of tensile instability). It also carries a
        background ``B c_i²/ρ_i + B c_j²/ρ_j`` (background pressure ``B Γ K``,
        :data:`unmesh.sph._kernels.TENSILE_BACKGROUND`), so that pairs at ``p ≈ 0`` (thin films) are
        kept apart too. 0 switches it off.
    contact_damping : float
        Damping ratio ζ in [0, 1] of the contacts of solids (0: off, elastic contacts): a pair of
        particles of different objects closer than ``d`` gets a dashpot ``2ζ√k_c`` on its normal
        relative velocity, ``k_c = 2 CONTACT min(K_e,i, K_e,j) m_j/ρ0 W`` the stiffness of its contact
        spring (8.37); a solid particle closer than ``d`` to a wall plane is damped by
        ``2ζ√(CONTACT K_e)`` times its velocity (restitution and friction). Dice come to rest.
    lattice : {"closest", "cubic"}
        The lattice the objects are sampled on (:mod:`unmesh.sph.sampling`): it sets the
        particle mass (density exactly ``ρ0`` on that lattice, eq. 8.4) and the gradient
        correction. ``"cubic"`` (the simple cubic grid, 26 neighbours at rest instead of 42)
        is for fluids only: solid objects and freezing materials need the closest packing
        (lattice shape matching, section 8.2).
    neighbor_skin : float
        Skin ``s`` of the Verlet neighbour lists, in units of ``h`` (0: off). The cell scan then reaches
        ``h + s h`` and stores those candidates; the following steps test only them (exactly, ``r < h``)
        and skip the re-sort, until some particle has moved more than ``s h/2`` since the scan: the
        neighbour lists, densities and forces are those of a scan every step, up to the summation order
        of the particles between re-sorts (round-off). Elastic solids too (the lattice pass then reads its
        previous state row for row); scenes with phase changes scan every step.

    Example
    -------
    >>> SPHConfig(dim=3, spacing=0.01, dt=1e-4).h
    0.02
    """

    dim: int
    spacing: float
    dt: float
    smoothing: float = 2.0
    cfl: float | None = None
    gravity: Any = (0.0, -9.81, 0.0)
    seed: int = 0
    wall_pressure: float = 2.0
    neighbor_capacity: int = 0
    gradient_correction: bool = True
    lattice: str = "closest"
    tensile_correction: float = 4.0
    contact_damping: float = 0.0
    neighbor_skin: float = 0.2

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise InputError(f"dim: expected 2 or 3, got {self.dim!r}")
        if self.lattice not in LATTICES:
            raise InputError(f"lattice: expected one of {', '.join(map(repr, LATTICES))}, got {self.lattice!r}")
        for key in ("spacing", "dt", "smoothing", "wall_pressure"):
            v = getattr(self, key)
            if not (isinstance(v, int | float) and v > 0 and math.isfinite(v)):
                raise InputError(f"{key}: expected a positive number, got {v!r}")
        if not (isinstance(self.tensile_correction, int | float) and 0 <= self.tensile_correction < math.inf):
            raise InputError(f"tensile_correction: expected a number >= 0, got {self.tensile_correction!r}")
        if not (isinstance(self.neighbor_skin, int | float) and 0 <= self.neighbor_skin < math.inf):
            raise InputError(f"neighbor_skin: expected a number >= 0, got {self.neighbor_skin!r}")
        if not (isinstance(self.contact_damping, int | float) and 0 <= self.contact_damping <= 1):
            raise InputError(f"contact_damping: expected a number in [0, 1], got {self.contact_damping!r}")
        if self.smoothing <= 1.0:
            raise InputError(f"smoothing: expected h/d > 1, got {self.smoothing}")
        if self.cfl is not None and not 0 < self.cfl <= 1:
            raise InputError(f"cfl: expected a number in (0, 1], got {self.cfl}")
        g = as_array(self.gravity, "gravity", (3,))
        if self.dim == 2 and g[2] != 0:
            raise InputError(f"gravity: expected z = 0 in 2D, got {g.tolist()}")
        object.__setattr__(self, "gravity", g)

    @property
    def h(self) -> float:
        """Support radius ``h = smoothing · d``."""
        return self.smoothing * self.spacing


@dataclass(frozen=True, eq=False)
class SPHObject:
    """One object: particles of one material with initial conditions.

    Parameters
    ----------
    name : str
    positions : array_like, shape (N, 3)
        Particle positions (normally a closest packing, :mod:`unmesh.sph.sampling`).
    material : str
        Key into the simulation's materials.
    velocity : array_like (3,)
    angular_velocity : array_like (3,)
        Rigid rotation about the object's centroid (rad/s).
    temperature : float
    phase : str
        ``"fluid"`` or ``"solid"``.
    fixed : bool
        Kinematic object: its particles never move (a rod).
    anchor : shape or None
        Particles inside this shape (``contains``) never move: the object is clamped
        there (a cantilever fixed to a wall).
    surface : TriangleMesh or None
        Surface mesh skinned to the particles (eq. 8.38) and written per frame.

    Example
    -------
    >>> from unmesh.sph.sampling import closest_packing
    >>> cube = SPHObject("cube", closest_packing([0, 0, 0], [0.1, 0.1, 0], 0.01, 2), "rubber", phase="solid")
    >>> len(cube.positions)
    110
    """

    name: str
    positions: Any
    material: str
    velocity: Any = (0.0, 0.0, 0.0)
    angular_velocity: Any = (0.0, 0.0, 0.0)
    temperature: float = 0.0
    phase: str = "fluid"
    fixed: bool = False
    anchor: Any = None
    surface: Any = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "positions", as_points(self.positions, f"{self.name}.positions"))
        object.__setattr__(self, "velocity", as_array(self.velocity, f"{self.name}.velocity", (3,)))
        object.__setattr__(self, "angular_velocity", as_array(self.angular_velocity, f"{self.name}.angular_velocity", (3,)))
        if self.phase not in ("fluid", "solid"):
            raise InputError(f"{self.name}.phase: expected 'fluid' or 'solid', got {self.phase!r}")


@dataclass
class _Timers:
    steps: int = 0
    extra: dict[str, float] = field(default_factory=dict)


class SPHSimulation(Simulation):
    """Weakly compressible SPH with elastic lattice forces, phase changes and fracture.

    Parameters
    ----------
    config : SPHConfig
    materials : mapping of str to Material
    objects : sequence of SPHObject
    planes : sequence of Plane
        Analytic walls.
    boundary : BoundaryParticles or None
        Static boundary particles (Akinci et al. 2012).
    boundary_shapes : sequence of (shape, inside)
        Shapes of the boundary particles, used to push back particles that crossed
        them (``inside=True``: particles are kept inside the shape, a container).
    heat_sources : sequence of HeatSource
    surfaces : {"none", "fluid", "all"}
        Marching-cubes density surface written per frame (3D).
    surface_resolution : float
        Grid spacing of the density surface in units of ``d``.
    name : str
        Shown in the progress bar.

    Example
    -------
    >>> from unmesh.sph.sampling import closest_packing
    >>> cfg = SPHConfig(dim=2, spacing=0.02, dt=1e-3, cfl=0.3)
    >>> cube = SPHObject("cube", closest_packing([0, 0.1, 0], [0.2, 0.3, 0], 0.02, 2), "rubber", phase="solid")
    >>> sim = SPHSimulation(cfg, {"rubber": Material("rubber", elastic_stiffness=1e6)}, [cube],
    ...                     planes=[Plane((0, 0, 0), (0, 1, 0))])
    >>> while sim.time < 0.05:
    ...     _ = sim.step()
    >>> sim.check() is None, sim.particles().phase_counts()
    (True, {'fluid': 0, 'solid': 110})
    """

    def __init__(self, config: SPHConfig, materials: Mapping[str, Material], objects: Sequence[SPHObject],
                 planes: Sequence[Plane] = (), boundary: BoundaryParticles | None = None,
                 boundary_shapes: Sequence[tuple[Any, bool]] = (), heat_sources: Sequence[HeatSource] = (),
                 surfaces: str = "none", surface_resolution: float = 0.5, name: str = "sph") -> None:
        self.name = name
        self.config = config
        self.dim = config.dim
        self.h = config.h
        self.spacing = config.spacing
        if not objects or all(len(o.positions) == 0 for o in objects):
            raise InputError("the scene has no particles: add at least one object with a non-empty shape")
        self.material_names = list(materials)
        self.materials = [materials[k] for k in self.material_names]
        self.mats = material_table(self.materials)
        self.objects = list(objects)
        self.planes = list(planes)
        self.plane_p = np.ascontiguousarray(np.array([p.point for p in planes]).reshape(-1, 3))
        self.plane_n = np.ascontiguousarray(np.array([p.normal for p in planes]).reshape(-1, 3))
        self.wall_rho, self.wall_grad = wall_tables(self.h, self.dim)
        self.corners = corner_pairs(self.planes)
        self.plane_noslip = np.array([p.no_slip for p in self.planes], np.uint8)
        self.wall_visc = wall_friction_tables(self.h, self.dim) if self.plane_noslip.any() else np.zeros((2, 2))
        self.wall_mom = wall_moment_tables(self.h, self.dim) if len(self.planes) else np.zeros((2, 2))
        if len(self.corners):
            self.corner_rho, self.corner_grad = corner_tables(self.h, self.dim)
            self.corner_mom = corner_moment_tables(self.h, self.dim)
        else:
            self.corner_rho = self.corner_grad = np.zeros((2, 2))
            self.corner_mom = np.zeros((3, 2, 2))
        self.boundary = boundary if boundary is not None else BoundaryParticles(np.zeros((0, 3)), np.zeros(0))
        self.boundary_shapes = list(boundary_shapes)
        self.heat_sources = list(heat_sources)
        if surfaces not in ("none", "fluid", "all"):
            raise InputError(f"surfaces: expected 'none', 'fluid' or 'all', got {surfaces!r}")
        if surfaces != "none" and self.dim != 3:
            raise InputError("surfaces: density surfaces (marching cubes) need dimension 3")
        self.surfaces = surfaces
        self.surface_resolution = float(surface_resolution)
        # lattice of the elastic model
        self.slot_vecs, self.slot_coords, self.slot_table = lattice_slots(self.dim, config.smoothing)
        self.bmat = lattice_basis(self.dim)
        self.tmat = SK.d3_transform(self.bmat) if self.dim == 3 else np.eye(3)
        self.frame = lattice_frame(self.dim)
        # neighbours of a particle on the rest lattice: the tension's share by count (_kernels.tension_scale)
        self.full_neighbors = float(len(lattice_points(self.dim, config.smoothing, config.lattice)))
        if config.gradient_correction:
            self.grad_scale = 1.0 / gradient_moment(self.dim, config.smoothing, config.lattice)
        else:
            self.grad_scale = 1.0
        self.elastic = any(m.is_elastic for m in self.materials)
        if config.lattice != "closest":
            self._check_fluid_lattice()
        self.phase_changes = any(m.melt_rate > 0 or m.freeze_rate > 0 for m in self.materials)
        # Verlet lists (SPHConfig.neighbor_skin): fluids and elastic solids; phase changes scan every step
        self.skin = 0.0 if self.phase_changes else float(config.neighbor_skin) * self.h
        self._identity: np.ndarray | None = None  # the lattice pass's order on steps without a re-sort
        self.neighbor_scans = 0  # cell scans (re-sorts) so far; the other steps used the stored candidates
        self._build_particles()
        self._present = np.unique(self.mat)  # materials present (fixed: particles never change material)
        self._build_boundary_grid()
        self.time = 0.0
        self.steps = 0
        self.dt_last = config.dt
        self._problem: str | None = None
        self._diag = (0.0, 0.0, 0.0, 0.0, 0)
        self._skins = self._bind_skins()
        with serial_if_small(len(self.x), PARALLEL_MIN):
            self._update(prime=True)
            self._diag = K.diagnostics(self.x, self.v, self.a, self.m, self.rho, self.mat, self.mats)
        self._v_limit = self._speed_limit()

    # -- construction -----------------------------------------------------------------
    def _check_fluid_lattice(self) -> None:
        """A non-closest sampling lattice holds fluids only (no solids, no freezing)."""
        lat = self.config.lattice
        for o in self.objects:
            if o.phase == "solid":
                raise InputError(f"object {o.name!r} is solid but lattice = {lat!r}: solids need the closest packing "
                                 "(lattice shape matching, section 8.2); use lattice = 'closest'")
        used = {o.material for o in self.objects}
        for name, mat in zip(self.material_names, self.materials, strict=True):
            if name in used and mat.freeze_rate > 0:
                raise InputError(f"material {name!r} freezes but lattice = {lat!r}: solids need the closest packing "
                                 "(lattice shape matching, section 8.2); use lattice = 'closest'")

    def _lattice_mass(self, rho0: float) -> float:
        """Particle mass giving density ``ρ0`` on the perfect sampling lattice (eq. 8.4)."""
        from unmesh.kernels import poly6

        r = np.linalg.norm(lattice_points(self.dim, self.config.smoothing, self.config.lattice), axis=1) * self.spacing
        total = float(poly6(0.0, self.h, self.dim)) + float(np.sum(poly6(r, self.h, self.dim)))
        return rho0 / total

    def _build_particles(self) -> None:
        xs, vs, ms, ts, ph, ob, mt, fx = [], [], [], [], [], [], [], []
        for k, o in enumerate(self.objects):
            if o.material not in self.material_names:
                raise InputError(f"object {o.name!r}: unknown material {o.material!r}; defined: {', '.join(self.material_names)}")
            n = len(o.positions)
            if n == 0:
                raise InputError(f"object {o.name!r} has no particles (shape smaller than the spacing"
                                 + (", or not crossing the plane z = 0 of a 2D scene)" if self.dim == 2 else ")"))
            pos = o.positions.copy()
            if self.dim == 2:
                if np.any(pos[:, 2] != 0):
                    raise InputError(f"object {o.name!r}: 2D particles need z = 0")
            centroid = pos.mean(axis=0)
            vel = o.velocity[None, :] + np.cross(o.angular_velocity[None, :], pos - centroid)
            if o.fixed:
                vel[:] = 0.0
            if self.dim == 2:
                vel[:, 2] = 0.0
            mi = self.material_names.index(o.material)
            xs.append(pos)
            vs.append(vel)
            ms.append(np.full(n, self._lattice_mass(self.materials[mi].density)))
            ts.append(np.full(n, float(o.temperature)))
            ph.append(np.full(n, SOLID if o.phase == "solid" else FLUID, np.int8))
            ob.append(np.full(n, k, np.int32))
            mt.append(np.full(n, mi, np.int32))
            fixed = np.full(n, 1 if o.fixed else 0, np.uint8)
            if o.anchor is not None:
                fixed[np.asarray(o.anchor.contains(pos), dtype=bool)] = 1
            fx.append(fixed)
        self.x = np.ascontiguousarray(np.concatenate(xs))
        n = len(self.x)
        self.v = np.ascontiguousarray(np.concatenate(vs))
        self.a = np.zeros((n, 3))
        self.xsph = np.zeros((n, 3))
        self.m = np.concatenate(ms)
        self.rho = np.zeros(n)
        self.p = np.zeros(n)
        self.temp = np.concatenate(ts)
        self.dtemp = np.zeros(n)
        self.phase = np.concatenate(ph)
        self.obj = np.concatenate(ob)
        self.mat = np.concatenate(mt)
        self.uid = np.arange(n, dtype=np.int64)
        self.fixed = np.concatenate(fx)
        # tension reference density of the solids (K.solid_pressure): ρ0, and the density a particle froze at
        self.rho_t = np.ascontiguousarray(self.mats[self.mat, MT.RHO0])
        self._check_layout()
        q = len(self.slot_vecs)
        self.amat = np.ascontiguousarray(np.repeat(self.frame[None], n, axis=0))
        self.ainv = np.ascontiguousarray(np.repeat(self.frame.T[None], n, axis=0))
        self.occ = np.full((n, q), -1, np.int32) if self.elastic else np.full((n, 0), -1, np.int32)
        self.docked = np.zeros(self.occ.shape, np.uint8)
        # docking rates: only a finite docking gain needs them (lattice_update)
        rates = q if self.elastic and np.any(np.isfinite(self.mats[:, MT.DOCK_GAIN])) else 0
        self.lam = np.repeat(self.mats[self.mat, MT.DOCK_MAX][:, None], rates, axis=1)
        # stored plastic deformation (rest shape P of each lattice, identity): only a finite yield strain needs it
        plastic = self.elastic and np.any(np.isfinite(self.mats[:, MT.YIELD]))
        self.pmat = np.ascontiguousarray(np.repeat(np.eye(3)[None], n if plastic else 0, axis=0))
        cap = self.config.neighbor_capacity or (24 if self.dim == 2 else 64)
        self.nbr = np.zeros((n, cap + 1), np.int32)  # + the scratch column of the branch-free fill
        self.nnbr = np.zeros(n, np.int64)
        self.bnbr = np.zeros((n, 32 if len(self.boundary) else 1), np.int32)
        self.nbnbr = np.zeros(n, np.int64)
        # Verlet candidates within h + skin (K.density_pass) and the positions they were found at
        ccap = int(1.2 * (1.0 + self.config.neighbor_skin) ** self.dim * cap) + 8
        self.cand = np.zeros((n, ccap + 1) if self.skin > 0.0 else (0, 1), np.int32)
        self.ncand = np.zeros(n if self.skin > 0.0 else 0, np.int64)
        self._xref: np.ndarray | None = None
        self._scratch = None
        self._rows: dict[str, np.ndarray] | None = None  # packed per-particle rows of the density and force passes
        self._spare: dict[str, np.ndarray] = {}  # re-sort buffers, reused every step

    def _check_layout(self) -> None:
        """Report overlapping objects and particles that start outside the boundaries."""
        from unmesh.spatial import radius_pairs

        pairs = radius_pairs(self.x[:, : self.dim], 0.5 * self.spacing)
        if len(pairs):
            bad = pairs[self.obj[pairs[:, 0]] != self.obj[pairs[:, 1]]]
            if len(bad):
                a, b = self.objects[self.obj[bad[0, 0]]].name, self.objects[self.obj[bad[0, 1]]].name
                raise InputError(f"objects {a!r} and {b!r} overlap ({len(bad)} particle pairs closer than half the "
                                 f"spacing, e.g. at {np.round(self.x[bad[0, 0]], 6).tolist()}); move them apart")
        for plane in self.planes:
            dist = plane.distance(self.x)
            out = dist < 0
            if np.any(out):
                k = int(np.flatnonzero(out)[0])
                raise InputError(f"{int(out.sum())} particles of object {self.objects[self.obj[k]].name!r} start outside "
                                 f"the wall through {plane.point.tolist()} with normal {plane.normal.tolist()} "
                                 f"(e.g. at {np.round(self.x[k], 6).tolist()})")
        for shape, inside in self.boundary_shapes:
            vals = np.asarray(shape.implicit(self.x)[0])
            out = vals > 0 if inside else vals < 0
            if np.any(out):
                k = int(np.flatnonzero(out)[0])
                where = "outside the container" if inside else "inside the obstacle"
                raise InputError(f"{int(out.sum())} particles of object {self.objects[self.obj[k]].name!r} start {where} "
                                 f"{shape!r} (e.g. at {np.round(self.x[k], 6).tolist()})")

    def _build_boundary_grid(self) -> None:
        from unmesh.spatial import build_cell_grid

        if len(self.boundary):
            g = build_cell_grid(self.boundary.positions, self.h)
            self.bx = np.ascontiguousarray(g.points)
            self.bvol = np.ascontiguousarray(self.boundary.volumes[g.order])
            self.bnoslip = np.ascontiguousarray(self.boundary.no_slip[g.order])
            self.bgrid = (g.origin, g.inv_cell, g.dims, g.cell_keys, g.cell_start)
        else:
            self.bx = np.zeros((0, 3))
            self.bvol = np.zeros(0)
            self.bnoslip = np.zeros(0, np.uint8)
            self.bgrid = (np.zeros(3), 1.0, np.ones(3, np.int64), np.zeros(0, np.int64), np.zeros(1, np.int64))

    # -- the step ---------------------------------------------------------------------
    def _arrays(self) -> list[str]:
        return list(_PARTICLE_ARRAYS) + (list(_ELASTIC_ARRAYS) if self.elastic else [])

    def _sort(self, full: bool = True) -> None:
        """Re-sort the per-particle arrays by grid cell (``self.grid``).

        ``full=False`` (the step) leaves out the arrays that the density and force passes
        overwrite before anything reads them (:data:`_RECOMPUTED`) and the lattice state that
        the lattice pass re-sorts as it reads it (:data:`_RESORTED_BY_LATTICE`, through
        ``self._order``).
        """
        from unmesh.spatial import build_cell_grid

        g = build_cell_grid(self.x, K.CELL_FRACTION * self.h)
        order = g.order
        spare = self._spare
        self._order = np.ascontiguousarray(order, dtype=np.int64)
        for name in self._arrays():
            if not full and (name in _RECOMPUTED or name in _RESORTED_BY_LATTICE):
                continue
            if name == "x":
                self.x = np.ascontiguousarray(g.points)
                continue
            src = np.ascontiguousarray(getattr(self, name))
            dst = spare.get(name)
            if (dst is None or dst.shape != src.shape or dst.dtype != src.dtype or dst is src
                    or any(dst is buf for buf in (self._scratch or {}).values())):
                dst = np.empty_like(src)
            if len(src) and src.itemsize:
                a = src.reshape(len(src), -1).view(np.uint8)
                b = dst.reshape(len(dst), -1).view(np.uint8)
                if a.shape[1] % 8 == 0:
                    a = a.view(np.uint64)
                    b = b.view(np.uint64)
                K.permute_rows(a, order, b)
            setattr(self, name, dst)
            spare[name] = src  # the previous array becomes the next step's buffer
        self.grid = g

    def _ensure_scratch(self) -> None:
        n = len(self.x)
        if self._scratch is None or self._scratch["fown"].shape[0] != n:
            self._scratch = {
                "amat_out": np.zeros((n, 3, 3)), "ainv_out": np.zeros((n, 3, 3)),
                "occ_out": np.empty_like(self.occ), "docked_out": np.empty_like(self.docked),
                # the goal matrices only for freezing (phase_pass)
                "gmat": np.zeros((n if self.phase_changes else 0, 3, 3)),
                "fown": np.zeros((n, 3)), "valid": np.zeros(n, np.uint8),
                "fel": np.zeros((n, 3)), "pmat_out": np.zeros(self.pmat.shape),
            }

    def _density(self, scan: bool = True) -> None:
        """Neighbour lists, density and pressure: by a cell scan of the current (sorted) grid, or, with
        ``scan=False``, from the Verlet candidates of the last scan (valid while no particle has moved more
        than half the skin since, :meth:`_update`)."""
        if not scan:
            self._density_from_candidates()
            return
        g = self.grid
        bo, binv, bd, bk, bs = self.bgrid
        self._dense = dense = K.cell_starts(g, getattr(self, "_dense", None))
        n = len(self.x)
        if self._rows is None or self._rows["xm"].shape[0] != n:
            self._rows = {"xm": np.empty((n, 4)), "pk": np.empty((n, K.PK_COLS)), "dgrad": np.empty((n, 3)),
                          "drho": np.empty(n)}
        self.neighbor_scans += 1
        while True:
            K.density_pass(self.x, self.m, self.mat, self.mats, self.h, self.dim, g.origin, g.inv_cell, g.dims,
                           g.cell_keys, g.cell_start, dense, self._rows["xm"], self.nbr, self.nnbr, self.bx, self.bvol,
                           bo, binv, bd, bk, bs, self.bnbr, self.nbnbr, self.plane_p, self.plane_n, self.wall_rho,
                           self.corners, self.corner_rho, self.rho, self.p, self.phase, self.full_neighbors,
                           self.rho_t, self.h + self.skin, self.cand, self.ncand)
            if self._lists_fit():
                break
        if self.skin > 0.0:
            if self._xref is None or self._xref.shape != self.x.shape:
                self._xref = np.empty_like(self.x)
            self._xref[:] = self.x
        self._diffuse()
        self._partner_tension()

    def _density_from_candidates(self) -> None:
        bo, binv, bd, bk, bs = self.bgrid
        while True:
            K.density_list_pass(self.x, self.m, self.mat, self.mats, self.h, self.dim, self.cand, self.ncand,
                                self._rows["xm"], self.nbr, self.nnbr, self.bx, self.bvol, bo, binv, bd, bk, bs,
                                self.bnbr, self.nbnbr, self.plane_p, self.plane_n, self.wall_rho, self.corners,
                                self.corner_rho, self.rho, self.p, self.phase, self.full_neighbors, self.rho_t)
            if self._lists_fit():
                break
        self._diffuse()
        self._partner_tension()

    def _partner_tension(self) -> None:
        """The tension's share by count over the tension partners only (:func:`unmesh.sph._kernels.partner_pressure`),
        when particles of different objects, one of them solid, may meet."""
        if len(self.objects) > 1 and np.any(self.phase == SOLID):
            K.partner_pressure(self.rho, self.p, self.phase, self.obj, self.mat, self.mats, self.nbr, self.nnbr,
                               self.full_neighbors, self.rho_t)

    def _lists_fit(self) -> bool:
        """True when the last density pass's neighbour and candidate lists held every entry (their
        true counts ``nnbr``, ``nbnbr``, ``ncand``); otherwise they are grown for a repeat of the pass."""
        n = len(self.x)
        need = int(self.nnbr.max()) if len(self.nnbr) else 0
        bneed = int(self.nbnbr.max()) if len(self.nbnbr) else 0
        cneed = int(self.ncand.max()) if len(self.ncand) else 0
        if need <= self.nbr.shape[1] - 1 and bneed <= self.bnbr.shape[1] and cneed <= self.cand.shape[1] - 1:
            return True
        self.nbr = np.zeros((n, max(need + 9, self.nbr.shape[1])), np.int32)
        self.bnbr = np.zeros((n, max(bneed + 8, self.bnbr.shape[1])), np.int32)
        if cneed > self.cand.shape[1] - 1:
            self.cand = np.zeros((n, cneed + 17), np.int32)
        return False

    def _restore_candidates(self, xref: Any) -> bool:
        """Rebuild the Verlet candidates of a checkpoint from the positions of its last cell scan ``xref``
        (the particles are still in that scan's order), then the density at the current positions: the
        run continues exactly as without the interruption. False (nothing done) if ``xref`` does not fit."""
        from unmesh.spatial import build_cell_grid

        xref = np.ascontiguousarray(np.asarray(xref, dtype=np.float64))
        if xref.shape != self.x.shape:
            return False
        g = build_cell_grid(xref, K.CELL_FRACTION * self.h)
        if not np.array_equal(g.order, np.arange(len(xref))):  # not in scan order: scan afresh
            return False
        x_now = self.x
        self.x, self.grid = xref, g
        self._density()
        self.x = x_now
        self._density(scan=False)
        return True

    def _candidates_valid(self) -> bool:
        """True when the stored Verlet candidates still hold every pair closer than ``h``: no particle has
        moved more than half the skin since the scan (two particles then came at most one skin closer)."""
        if self.skin <= 0.0 or self._xref is None or self._xref.shape != self.x.shape:
            return False
        return bool(K.max_displacement(self.x, self._xref) <= 0.5 * self.skin * (1.0 - 1e-6))

    def _diffuse(self) -> None:
        if np.any(self.mats[:, MT.DENSITY_DIFFUSION] > 0):  # δ-SPH density filter of the fluids
            DK.density_diffusion_pass(self.x, self.m, self.rho, self.p, self.phase, self.mat, self.mats, self.nbr,
                                      self.nnbr, self.h, self.dim, self._rows["dgrad"], self._rows["drho"],
                                      self.full_neighbors)

    def _update(self, prime: bool = False, rescan: bool = False) -> None:
        """Sort, density, lattice and force passes at the current positions.

        With Verlet lists (``self.skin > 0``) the sort and the cell scan run only when the stored
        candidates no longer cover the neighbourhoods (or ``prime`` / ``rescan``).
        """
        scan = prime or rescan or not self._candidates_valid()
        if scan:
            self._sort(full=False)
        elif self.elastic:  # no re-sort: the lattice pass reads its previous state row for row
            if self._identity is None or len(self._identity) != len(self.x):
                self._identity = np.arange(len(self.x), dtype=np.int64)
            self._order = self._identity
        self._density(scan)
        self._ensure_scratch()
        s = self._scratch
        if self.elastic:
            EK.lattice_update(self.x, self.m, self.phase, self.obj, self.mat, self.uid, self.mats, self.nbr, self.nnbr,
                              self.h, self.dim, self.spacing, self.slot_vecs, self.tmat, self.slot_table,
                              self._order, self.amat, self.ainv, self.occ, self.docked, self.lam, self.config.seed,
                              self.steps, self.dt_last, 1 if prime else 0, s["amat_out"], s["ainv_out"], s["occ_out"],
                              s["docked_out"], s["gmat"], s["fown"], s["valid"], s["fel"], self.pmat, s["pmat_out"])
        K.force_pass(self.x, self.v, self.m, self.rho, self.p, self.temp, self.phase, self.obj, self.mat, self.uid,
                     self.mats, self.h, self.dim, self.config.gravity, self.nbr, self.nnbr, self.bx, self.bvol,
                     self.bnbr, self.nbnbr, self.plane_p, self.plane_n, self.wall_grad, self.corners,
                     self.corner_grad, self.config.wall_pressure, self.plane_noslip, self.wall_visc, self.wall_mom,
                     self.corner_mom, self.bnoslip,
                     self.grad_scale, self.config.tensile_correction, self.config.contact_damping, self.spacing, self.elastic, s["fel"], s["fown"], self._rows["pk"], self.a, self.xsph, self.dtemp,
                     self.full_neighbors)
        if self.elastic:
            # the new lattice state (in the new order) becomes the previous one of the next step
            self.amat, s["amat_out"] = s["amat_out"], self.amat
            self.ainv, s["ainv_out"] = s["ainv_out"], self.ainv
            self.occ, s["occ_out"] = s["occ_out"], self.occ
            self.docked, s["docked_out"] = s["docked_out"], self.docked
            self.pmat, s["pmat_out"] = s["pmat_out"], self.pmat

    def max_sound_speed(self) -> float:
        """Largest wave speed of the materials present: ``√(ΓK/ρ0)``, elastic ``√((λ+2μ)/ρ0)``."""
        c = 0.0
        for k in self._present:
            mat = self.materials[int(k)]
            mu, lam = mat.lame
            c = max(c, mat.sound_speed, math.sqrt(max(lam + 2 * mu, 0.0) / mat.density))
        return c

    def stability_limit(self) -> tuple[float, str]:
        """Estimated largest stable time step of velocity Verlet for the current state, and its cause.

        Measured limits of this discretisation (h = 2d): acoustic ``1.2 h/(c + v_max)``,
        elastic ``1.2/√K_e`` (solids present), viscous ``0.028 h²ρ0/μ``, thermal
        ``0.1 h²/α``.
        """
        _ke, vmax, _amax, _err, _bad = self._diag
        c = self.max_sound_speed()
        limits = [(1.2 * self.h / (c + vmax) if c + vmax > 0 else math.inf,
                   f"speed of sound {c:.3g} m/s, h = {self.h:.4g} m")]
        present = [self.materials[int(k)] for k in self._present]
        ke = max((m.elastic_stiffness for m in present), default=0.0)
        if ke > 0 and np.any(self.phase == SOLID):
            limits.append((1.2 / math.sqrt(ke), f"elastic stiffness K_e = {ke:.4g}/s²"))
        for mat in present:
            if mat.viscosity > 0:
                limits.append((0.028 * self.h * self.h * mat.density / mat.viscosity,
                               f"viscosity {mat.viscosity:.4g} Pa·s of {mat.name!r}"))
            if mat.diffusivity > 0:
                limits.append((0.1 * self.h * self.h / mat.diffusivity,
                               f"thermal diffusivity {mat.diffusivity:.4g} m²/s of {mat.name!r}"))
        return min(limits)

    def stable_dt(self, cfl: float = 0.25) -> float:
        """The CFL-limited step: ``cfl`` times :meth:`stability_limit`, and ``≤ cfl·√(h/a_max)``."""
        dt = cfl * self.stability_limit()[0]
        amax = self._diag[2]
        if amax > 0:
            dt = min(dt, cfl * math.sqrt(self.h / amax))
        return dt

    def step(self) -> float:
        """Advance one time step (kick-drift-kick velocity Verlet); returns Δt."""
        with serial_if_small(len(self.x), PARALLEL_MIN):
            return self._step()

    def _step(self) -> float:
        dt = self.config.dt
        if self.config.cfl is not None:
            dt = min(dt, self.stable_dt(self.config.cfl))
        self.dt_last = dt
        if K.kick_drift(self.x, self.v, self.a, self.xsph, 0.5 * dt, dt, self.fixed, self.plane_p, self.plane_n, 0.0):
            self._problem = "NaN or infinite particle positions"
            self.time += dt
            self.steps += 1
            return dt
        self._push_out_of_shapes()
        self._update()
        # second half kick; the diagnostics need nothing that heat sources and phase changes alter
        self._diag = K.kick_diagnostics(self.x, self.v, self.a, 0.5 * dt, self.fixed, self.m, self.rho, self.mat,
                                        self.mats)
        self._heat(dt)
        self.steps += 1
        if self.phase_changes:
            self._phase_transitions(dt)
        self.time += dt
        return dt

    def _push_out_of_shapes(self) -> None:
        """Move particles that crossed a boundary shape back to its surface."""
        if not self.boundary_shapes:
            return
        near = np.flatnonzero(self.nbnbr > 0)
        if len(near) == 0:
            return
        for shape, inside in self.boundary_shapes:
            vals, normals = shape.implicit(self.x[near])
            vals = np.asarray(vals)
            bad = vals > 0 if inside else vals < 0
            if not np.any(bad):
                continue
            idx = near[bad]
            nrm = np.asarray(normals)[bad]
            if self.dim == 2:
                nrm[:, 2] = 0.0
            self.x[idx] -= vals[bad, None] * nrm
            vn = np.einsum("ij,ij->i", self.v[idx], nrm)
            wrong = vn > 0 if inside else vn < 0
            self.v[idx[wrong]] -= vn[wrong, None] * nrm[wrong]

    def _heat(self, dt: float) -> None:
        if np.any(self.mats[:, MT.DIFF] > 0):
            self.temp += dt * self.dtemp
        for src in self.heat_sources:
            mask = src.mask(self.x)
            if np.any(mask):
                PK.heat_relax(self.temp, mask, float(src.temperature), float(-math.expm1(-src.rate * dt)))

    def _phase_transitions(self, dt: float) -> None:
        n = len(self.x)
        new_phase = np.empty(n, np.int8)
        donor = np.empty(n, np.int64)
        rates = np.empty(n)
        s = self._scratch
        occ = self.occ if self.elastic else np.full((n, len(self.slot_vecs)), -1, np.int32)
        PK.phase_pass(self.x, self.v, self.m, self.phase, self.obj, self.mat, self.uid, self.temp, self.mats,
                      self.nbr, self.nnbr, self.h, self.dim, self.spacing, self.slot_vecs, self.tmat,
                      self.slot_table, self.ainv, s["gmat"], occ, s["valid"], self.config.seed, self.steps, dt,
                      new_phase, donor, rates)
        changed = np.flatnonzero(new_phase != self.phase)
        if len(changed) == 0:
            return
        frozen = changed[new_phase[changed] == SOLID]
        if len(frozen) > 1:
            # two particles that freeze in the same step into one lattice site (closer than the site's
            # reach, 0.75 d): only the one with the smaller id freezes (else the same defect as freezing
            # into an occupied site, phase_pass)
            from unmesh.spatial import radius_pairs

            pairs = radius_pairs(self.x[frozen, : self.dim], 0.75 * self.spacing)
            if len(pairs):
                a, b = frozen[pairs[:, 0]], frozen[pairs[:, 1]]
                later = np.unique(np.where(self.uid[a] > self.uid[b], a, b))
                new_phase[later] = FLUID
                donor[later] = -1
                changed = np.flatnonzero(new_phase != self.phase)
                frozen = changed[new_phase[changed] == SOLID]
        has = frozen[donor[frozen] >= 0]
        self.obj[has] = self.obj[donor[has]]
        # a particle that melts or thaws returns to the first object of its material (a slime particle
        # that froze onto the rod and thaws is slime again, and collides with the rod and its ice)
        thawed = changed[new_phase[changed] == FLUID]
        home = np.array([next((k for k, o in enumerate(self.objects) if o.material == name), -1)
                         for name in self.material_names], np.int32)
        back = thawed[home[self.mat[thawed]] >= 0]
        self.obj[back] = home[self.mat[back]]
        # a new solid's rest state is the state it froze in: its tension is measured from the density its own
        # object gives it now (K.solid_pressure; a surface particle's summation density is the kernel's empty
        # support, not a stretched solid, and the fluid around it only repels it, 8.37); a thawed one is back to ρ0
        self.rho_t[thawed] = self.mats[self.mat[thawed], MT.RHO0]
        self.rho_t[frozen] = np.minimum(self.mats[self.mat[frozen], MT.RHO0], self._own_density(frozen))
        if self.elastic:
            self.amat[frozen] = self.frame
            self.ainv[frozen] = self.frame.T
            # the donor's frame (the rotation of its transformation, 8.24), not its stretch: a few-member
            # fit of surface ice may be squashed, and a particle that froze onto it would keep the squash
            for i in has:
                u, _, v = rotation_svd(self.amat[donor[i]], self.dim)
                self.amat[i] = u @ v.T
                self.ainv[i] = v @ u.T
            if len(self.pmat):
                self.pmat[changed] = np.eye(3)  # a new solid has its lattice's rest shape
            self.occ[changed] = -1
            self.docked[changed] = 0
            if self.lam.shape[1]:
                self.lam[changed] = self.mats[self.mat[changed], MT.DOCK_MAX][:, None]
        self.phase[changed] = new_phase[changed]

    def _own_density(self, idx: np.ndarray) -> np.ndarray:
        """Summation density (8.4) of particles ``idx`` over their own object's particles (self included), (len(idx),)."""
        from unmesh.kernels import poly6

        out = np.empty(len(idx))
        cap = self.nbr.shape[1] - 1
        for k, i in enumerate(idx):
            nb = self.nbr[i, : min(int(self.nnbr[i]), cap)]
            nb = nb[self.obj[nb] == self.obj[i]]
            r = np.linalg.norm(self.x[nb] - self.x[i], axis=1)
            out[k] = self.m[i] * float(poly6(0.0, self.h, self.dim)) + float(np.sum(self.m[nb] * poly6(r, self.h, self.dim)))
        return out

    def _bind_skins(self) -> dict[str, Any]:
        from unmesh.sph.surface import Skin

        skins: dict[str, Any] = {}
        for k, o in enumerate(self.objects):
            if o.surface is None:
                continue
            sel = np.flatnonzero(self.obj == k)
            vol = self.m[sel] / self.mats[self.mat[sel], MT.RHO0]
            a_rest = np.repeat(self.frame[None], len(sel), axis=0)
            name = o.name if o.name not in skins else f"{o.name}{k}"
            skins[name] = Skin.bind(o.surface, self.x[sel], self.uid[sel], vol, a_rest, self.h)
        return skins

    def skins(self) -> dict[str, Any]:
        """Skinned surface meshes by object name (:class:`unmesh.sph.surface.Skin`)."""
        return self._skins

    # -- runner interface -------------------------------------------------------------
    def _speed_limit(self) -> float:
        lo = self.x.min(axis=0)
        hi = self.x.max(axis=0)
        extent = float(np.max(hi - lo)) + 4 * self.h
        g = float(np.linalg.norm(self.config.gravity))
        v0 = float(np.max(np.linalg.norm(self.v, axis=1))) if len(self.v) else 0.0
        return 10.0 * (self.max_sound_speed() + math.sqrt(2.0 * g * extent) + v0) + 1e-9

    def check(self) -> str | None:
        """None when sane; else why the run must stop (NaN, speed blow-up, Δt too large)."""
        if self._problem:
            return self._problem
        _ke, vmax, _amax, _err, bad = self._diag
        if bad:
            return f"NaN or infinite velocities or positions in {bad} particles"
        if self.steps >= 1 and self.config.cfl is None:
            limit, cause = self.stability_limit()
            if self.dt_last > limit:
                return (f"time step {self.dt_last:.4g} s is too large for the stiffness: the stability limit is "
                        f"about {limit:.3g} s ({cause}); lower simulation.dt or set simulation.cfl")
        if vmax > self._v_limit:
            return (f"particle speed {vmax:.4g} m/s exceeds the plausible maximum {self._v_limit:.4g} m/s "
                    "(energy blow-up)")
        return None

    def particles(self) -> ParticleState:
        """The current particles in id order (a copy)."""
        o = np.argsort(self.uid, kind="stable")
        return ParticleState(self.dim, self.x[o], self.v[o], self.m[o], self.rho[o], self.p[o], self.temp[o],
                             self.phase[o], self.obj[o])

    def lattice_transforms(self) -> np.ndarray:
        """Current lattice transformations ``A_i`` (N, 3, 3) in id order (eq. 8.23)."""
        return self.amat[np.argsort(self.uid, kind="stable")] if self.elastic else np.repeat(self.frame[None], len(self.x), 0)

    def summary_header(self) -> dict[str, Any]:
        """``dimension`` and ``particles`` (simulated, non-boundary) for ``summary.json``."""
        return {"dimension": self.dim, "particles": len(self.x), "boundary_particles": len(self.boundary),
                "objects": [o.name for o in self.objects], "h": self.h, "spacing": self.spacing}

    def frame_record(self) -> dict[str, Any]:
        """Mass, momenta, kinetic energy, max density error, phase counts, surge front (see the scene docs).

        ``surge_front`` is the largest x of a particle with a neighbour within 1.5 spacings
        (:func:`unmesh.sph.front.surge_front`: the dam break's front, Martin & Moyce 1952).

        ``max_density_error`` is the largest compression ``max(ρ/ρ0 − 1, 0)``: the density
        deficit of particles at a free surface (an incomplete kernel sum) is not counted.
        """
        mv = self.m[:, None] * self.v
        fluid_only = self.phase == FLUID
        err = np.maximum(self.rho / self.mats[self.mat, MT.RHO0] - 1.0, 0.0)  # compression error
        return {
            "mass": float(self.m.sum()),
            "linear_momentum": mv.sum(axis=0).tolist(),
            "angular_momentum": np.cross(self.x, mv).sum(axis=0).tolist(),
            "kinetic_energy": float(0.5 * np.sum(self.m * np.einsum("ij,ij->i", self.v, self.v))),
            "max_density_error": float(err.max()),
            "max_fluid_density_error": float(err[fluid_only].max()) if np.any(fluid_only) else 0.0,
            "phase_counts": {"fluid": int(np.count_nonzero(fluid_only)), "solid": int(np.count_nonzero(~fluid_only))},
            "dt": float(self.dt_last),
            "surge_front": surge_front(self.x, self.spacing),
        }

    def write_static(self, outdir: Path) -> list[str]:
        """``OUTDIR/boundary.ply``: the boundary particles (with their volumes); returns the files written."""
        from unmesh import io
        from unmesh.particles import Particles

        if not len(self.boundary):
            return []
        io.save(Path(outdir) / "boundary.ply", Particles(self.boundary.positions, attributes={"volume": self.boundary.volumes}))
        return ["boundary.ply"]

    def write_frame(self, outdir: Path, frame: int) -> list[str]:
        """``frames/frame_NNNNN.ply`` (and ``surfaces/*_NNNNN.ply`` when enabled); returns the files written."""
        from unmesh import io

        out = Path(outdir)
        name = f"frame_{frame:05d}"
        io.save(out / "frames" / f"{name}.ply", self.particles().to_particles())
        files = [f"frames/{name}.ply"]
        if self.surfaces != "none" or any(o.surface is not None for o in self.objects):
            files.extend(f"surfaces/{f}" for f in self.write_surfaces(out / "surfaces", frame))
        return files

    def write_surfaces(self, outdir: Path, frame: int) -> list[str]:
        """Write ``fluid_NNNNN.ply`` (marching cubes) and ``<object>_NNNNN.ply`` (skinned meshes).

        Returns the names of the files written (relative to ``outdir``).

        Called by :meth:`write_frame` when the scene asks for surfaces (``[output] surface`` /
        ``skin``), e.g. ``sim.write_surfaces(outdir / "surfaces", 3)``; the meshes come from
        :func:`unmesh.sph.surface.fluid_surface` and :meth:`unmesh.sph.surface.Skin.deform`.
        """
        from unmesh import io
        from unmesh.sph.surface import fluid_surface

        outdir = Path(outdir)
        state = self.particles()
        written: list[str] = []
        if self.surfaces != "none":
            sel = state.phases == FLUID if self.surfaces == "fluid" else np.ones(len(state), bool)
            rho0 = float(np.average(self.mats[:, 0]))
            mesh = fluid_surface(state.positions[sel], state.masses[sel], rho0, self.h,
                                 step=self.surface_resolution * self.spacing)
            written.append(f"fluid_{frame:05d}.ply")
            io.save(outdir / written[-1], mesh)
        skins = self.skins()
        if skins:
            amat = self.lattice_transforms()
            active = (state.phases == SOLID).astype(np.float64)
            for name, skin in skins.items():
                written.append(f"{name}_{frame:05d}.ply")
                io.save(outdir / written[-1], skin.deform(state.positions, amat, active))
        return written

    def state_dict(self) -> dict[str, Any]:
        """Every array and counter needed to continue the run exactly."""
        state: dict[str, Any] = {name: getattr(self, name) for name in self._arrays()}
        state.update(time=float(self.time), steps=int(self.steps), dt_last=float(self.dt_last), n=len(self.x))
        if self.skin > 0.0 and self._xref is not None:
            state["verlet_xref"] = self._xref  # positions of the last cell scan (the candidates are rebuilt from them)
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (from a checkpoint)."""
        if int(state["n"]) != len(self.x):
            raise InputError(f"checkpoint has {int(state['n'])} particles but the scene has {len(self.x)}; "
                             "it belongs to a different scene")
        state = dict(state)
        if "rho_t" not in state and "mat" in state:  # checkpoints before stop 37: every solid measured from ρ0
            state["rho_t"] = self.mats[np.asarray(state["mat"], np.int64), MT.RHO0]
        for name in self._arrays():
            if name not in state:
                raise InputError(f"checkpoint lacks {name!r}; it belongs to a different scene")
            setattr(self, name, np.ascontiguousarray(np.asarray(state[name]).astype(getattr(self, name).dtype)))
        self._present = np.unique(self.mat)
        self.time = float(state["time"])
        self.steps = int(state["steps"])
        self.dt_last = float(state["dt_last"])
        self._problem = None
        # neighbour lists for diagnostics and surfaces at the restored positions
        with serial_if_small(len(self.x), PARALLEL_MIN):
            xref = state.get("verlet_xref")
            if not (self.skin > 0.0 and xref is not None and self._restore_candidates(xref)):
                self._sort()
                self._density()
            self._ensure_scratch()
            self._diag = K.diagnostics(self.x, self.v, self.a, self.m, self.rho, self.mat, self.mats)
