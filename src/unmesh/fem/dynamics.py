"""Dynamics (9.20, 9.1.4): stiffness warping, implicit Euler, damping, gravity, fixed and
moving nodes, ground contact, and deferred re-integration after topology changes.

Equations of motion ``M ü + D u̇ + K u = F`` (9.20) with lumped masses (9.21),
Rayleigh damping ``D = α M + β K'`` and warped stiffness: each element's rotation
R_e (Horn, :mod:`unmesh.fem.rotations`) rotates the current positions back to the
rest frame, so the elastic force is ``f = -Σ_e R_e K_e (R_eᵀ x_e - X_e)`` and a rigid
motion produces none. One linearised implicit Euler step solves

    ((1 + Δt α) M + (Δt β + Δt²) K') v⁺ = M v + Δt (f(x) + F),   x⁺ = x + Δt v⁺,

with ``K' = Σ R_e K_e R_eᵀ``, by PCG warm-started from the last velocity with a
lagged LU preconditioner rotated per connected piece (``solver="lu-pcg"``), block-Jacobi PCG
(``"cg"``) or a sparse LU factorisation per step (``"direct"``); see
:mod:`unmesh.fem.solvers`. Fixed and moving nodes and ground contact (an active set
of nodes whose normal velocity is prescribed so they land on the plane, released
when the contact force would pull) are constraints of that solve; when the active set
changes, the re-solve is warm-started from the previous solution (intermediate rounds to
a relative residual of ``CONTACT_TOL``, the final set confirmed to ``cg_tol``). A cut keeps the
factorised preconditioner (mapped through the cut's node weights, see
:mod:`unmesh.fem.solvers`).

Example
-------
>>> import numpy as np
>>> from unmesh.fem import hex_grid
>>> sim = Dynamics(hex_grid((2, 2, 2), origin=(0, 0.5, 0)), 50.0, 0.3, 1.0, ground=Ground())
>>> for _ in range(50):
...     _ = sim.step(0.01)
>>> bool(sim.positions()[:, 1].min() >= -1e-9)
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from unmesh._threads import serial_region, threads_for
from unmesh._validate import as_array, as_indices, positive_scalar, scalar
from unmesh.errors import InputError
from unmesh.fem import _fe_kernels as FK
from unmesh.fem import _solve_kernels as SK
from unmesh.fem.assembly import BlockPattern, ElementStiffness, element_stiffness, lame_parameters
from unmesh.fem.integration import ElementIntegration, IntegrationRule, integrate_elements, merge_csr
from unmesh.fem.mesh import PolyMesh
from unmesh.fem.rotations import _horn_all, piece_rotations
from unmesh.fem.solvers import PCG, SOLVERS, LaggedLU, direct_solve

__all__ = ["Dynamics", "Ground", "Load", "Prescribed", "kernel_threads"]

#: Meshes with fewer nodes than this run the numba kernels on one thread: parallel
#: regions on small arrays cost more in synchronisation than they save, and on a
#: shared (oversubscribed) machine they were measured up to 10x slower than serial.
SERIAL_NODES = 30000
#: Meshes with at least this many elements may run the heavy per-element kernels (Horn
#: rotations, warped forces and assembly) on all threads: :class:`unmesh._threads.threads_for`
#: times one thread against all now and then and keeps the faster (the second core helps when
#: it is free and hurts when other jobs keep it busy).
ELEMENT_PARALLEL_MIN = 4096
#: ... and the re-integration of at least this many changed elements (each costs ~0.25 ms).
CHANGED_PARALLEL_MIN = 64
#: Calls of a per-step kernel from one timing of both choices to the next.
TUNER_PERIOD = 25
#: ``solver="auto"``: block-Jacobi PCG iterations before switching to the factorised preconditioner.
AUTO_CG_ITERATIONS = 150
#: ``"lu-pcg"``: iterations with a lagged (or cut-remapped) factorisation before refactorising within the step.
LAGGED_ITERATIONS = 200
#: Relative residual of the intermediate solves of the contact active-set iteration.
CONTACT_TOL = 1e-3
#: Active-set rounds before the set is accepted (then confirmed by one accurate solve).
CONTACT_ROUNDS = 8


def kernel_threads(n_nodes: int) -> serial_region:
    """Use one numba thread for small problems inside the block.

    The heavy per-element kernels run inside it under :class:`unmesh._threads.threads_for`,
    which may still use the threads in effect outside (one, if the user set one).

    Example
    -------
    >>> with kernel_threads(10):
    ...     pass
    """
    return serial_region(n_nodes < SERIAL_NODES)


@dataclass(frozen=True)
class Ground:
    """A ground plane ``x·normal >= height`` with Coulomb-like friction.

    Example
    -------
    >>> Ground(height=0.0, friction=0.3).normal
    (0.0, 1.0, 0.0)
    """

    height: float = 0.0
    normal: tuple[float, float, float] = (0.0, 1.0, 0.0)
    friction: float = 0.5

    def unit_normal(self) -> np.ndarray:
        """The normal, normalised."""
        n = np.asarray(self.normal, dtype=np.float64)
        ln = np.linalg.norm(n)
        if not ln > 0:
            raise InputError(f"ground.normal: expected a non-zero vector, got {self.normal}")
        return n / ln


@dataclass(frozen=True)
class Prescribed:
    """Nodes moving with a prescribed velocity (zero: fixed) while ``start <= t < stop``.

    Example
    -------
    >>> Prescribed(np.array([0, 1])).velocity
    (0.0, 0.0, 0.0)
    """

    nodes: np.ndarray
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start: float = 0.0
    stop: float = float("inf")


@dataclass(frozen=True)
class Load:
    """A total force split evenly over a node group (e.g. an end load).

    Example
    -------
    >>> Load(np.array([3, 4]), (0.0, -1.0, 0.0)).force
    (0.0, -1.0, 0.0)
    """

    nodes: np.ndarray
    force: tuple[float, float, float]


@dataclass
class _Topology:
    """Pending topology change (applied at the end of the step)."""

    mesh: PolyMesh
    parent: np.ndarray  # new element -> element of the integrated mesh it came from (material)
    kept: np.ndarray  # new element -> integrated element with identical data, -1 if changed
    rots: np.ndarray | None = None  # rotations of the integrated elements in the state before the change
    u: np.ndarray | None = None  # displacements right after the change (the rotations hold while they do)


@dataclass
class StepInfo:
    """Diagnostics of one step."""

    solve_seconds: float = 0.0
    reintegration_seconds: float = 0.0
    iterations: int = 0
    contacts: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class Dynamics:
    """Implicit-Euler dynamics of a polyhedral mesh with stiffness warping.

    Parameters
    ----------
    mesh : PolyMesh
        Rest configuration.
    young, poisson, density : float or (E,) arrays
        Material per element (Y, ν, ρ).
    gravity : (3,) floats
    prescribed : list of Prescribed
        Fixed or moving node groups.
    ground : Ground, optional
    rayleigh : (alpha, beta)
        Rayleigh damping ``D = α M + β K'`` (default none, as in Appendix F.3).
    solver : {"auto", "lu-pcg", "cg", "direct"}
        Linear solver of the implicit step (:mod:`unmesh.fem.solvers`); ``"auto"``
        (default) uses block-Jacobi PCG and switches to ``"lu-pcg"`` for good when
        that does not converge within 150 iterations.
    warping : bool
        Stiffness warping (default True); False is plain linear elasticity.
    correction : bool
        Consistency correction of the element quadrature.
    cg_tol : float
        Relative residual of the PCG solve.
    rule : IntegrationRule or str, optional
        Element integration (:class:`~unmesh.fem.integration.IntegrationRule`; default the
        thesis rule (9.19)); the scene key ``simulation.integration``. After a cut the
        re-integrated elements get the same rule: under ``"incompatible"`` those that are
        still hexahedra get the incompatible-mode stiffness rebuilt from the cut mesh, the
        cut pieces (no longer hexahedra) the thesis rule; the unchanged cells keep theirs.

    Attributes
    ----------
    mesh, u (n,3) displacements, v (n,3) velocities, time, steps (steps taken).
    kstiff : ElementStiffness
        The element stiffness; after a cut its ``data`` is a view of a buffer that the
        cut after the next one overwrites (copy it to keep it).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> sim = Dynamics(hex_grid((2, 2, 2)), 100.0, 0.3, gravity=(0, -9.81, 0))
    >>> info = sim.step(0.01)
    >>> round(sim.time, 6), bool(sim.v[:, 1].mean() < 0)
    (0.01, True)
    """

    def __init__(self, mesh: PolyMesh, young: Any, poisson: Any, density: Any = 1.0, *,
                 gravity: Any = (0.0, -9.81, 0.0), prescribed: list[Prescribed] | None = None,
                 ground: Ground | None = None, loads: list[Load] | None = None, rayleigh: tuple[float, float] = (0.0, 0.0), solver: str = "auto",
                 warping: bool = True, correction: bool = True, cg_tol: float = 1e-6, cg_maxiter: int = 5000,
                 rule: IntegrationRule | str | None = None) -> None:
        if solver not in SOLVERS:
            raise InputError(f"solver: expected one of {', '.join(SOLVERS)}, got {solver!r}")
        ne = mesh.n_elements
        self.young = _expand(young, ne, "young")
        self.poisson = _expand(poisson, ne, "poisson")
        self.density = _expand(density, ne, "density")
        lame_parameters(self.young, self.poisson)
        if np.any(~(self.density > 0)):
            raise InputError("density: expected positive values")
        self.gravity = as_array(gravity, "gravity", (3,))
        self.ground = ground
        self.alpha = scalar(rayleigh[0], "rayleigh alpha", minimum=0.0)
        self.beta = scalar(rayleigh[1], "rayleigh beta", minimum=0.0)
        self.solver = solver
        self.warping = bool(warping)
        self.correction = bool(correction)
        self.rule = IntegrationRule.parse(rule)
        self.cg_tol = positive_scalar(cg_tol, "cg_tol")
        self.cg_maxiter = int(cg_maxiter)
        self.lagged = LaggedLU()
        self._stiff = False  # "auto": block-Jacobi PCG failed, use the factorised preconditioner
        self.mesh = mesh
        self.u = np.zeros((mesh.n_nodes, 3))
        self._forces_cache: tuple[Any, ...] | None = None
        self._rot_cache: tuple[Any, ...] | None = None
        self.v = np.zeros((mesh.n_nodes, 3))
        self.time = 0.0
        self.steps = 0  # steps taken (the schedule of background factorisations)
        self.groups: list[tuple[np.ndarray, Prescribed]] = []
        for p in prescribed or []:
            member = np.zeros(mesh.n_nodes, bool)
            member[as_indices(p.nodes, "prescribed nodes", (None,), upper=mesh.n_nodes)] = True
            self.groups.append((member, p))
        self.loads: list[tuple[np.ndarray, Load]] = []
        for ld in loads or []:
            member = np.zeros(mesh.n_nodes, bool)
            member[as_indices(ld.nodes, "load nodes", (None,), upper=mesh.n_nodes)] = True
            self.loads.append((member, ld))
        self.contact = np.zeros(mesh.n_nodes, bool)
        self._pending: _Topology | None = None
        self._kspare: np.ndarray | None = None  # buffer the stiffness data of the next topology change goes into
        self.last = StepInfo()
        t0 = time.perf_counter()
        self.integ = integrate_elements(mesh, self.correction, rule=self.rule)
        self._setup_element_data()
        self.last.reintegration_seconds = time.perf_counter() - t0

    # -- element data ----------------------------------------------------------------------
    def _setup_element_data(self, kstiff: ElementStiffness | None = None) -> None:
        integ = self.integ
        self.kstiff = kstiff if kstiff is not None else element_stiffness(integ, self.young, self.poisson,
                                                                          rule=self.rule, of_mesh=self.mesh)
        n = self.mesh.n_nodes
        per = np.repeat(integ.volumes * self.density, np.diff(integ.node_offsets)) * integ.mu
        self.masses = np.bincount(integ.nodes, weights=per, minlength=n)
        with threads_for(n, ELEMENT_PARALLEL_MIN, "fem.pattern", TUNER_PERIOD):
            self.pattern = BlockPattern.build(integ.node_offsets, integ.nodes, n)
        from scipy.sparse.csgraph import connected_components

        graph = sp.csr_array((np.ones(len(self.pattern.indices)), self.pattern.indices, self.pattern.indptr), shape=(n, n))
        self.n_pieces, self.piece = connected_components(graph, directed=False)
        # pieces with mass (orphan nodes left by a cut are components of their own)
        self.n_solid_pieces = int(np.count_nonzero(np.bincount(self.piece, weights=self.masses) > 0))
        self._used = np.zeros(n, bool)
        self._used[integ.nodes] = True

    # -- state ------------------------------------------------------------------------------
    def positions(self) -> np.ndarray:
        """Current node positions (n,3) = rest + displacement."""
        return self.mesh.points + self.u

    def rotations(self) -> np.ndarray:
        """Per-element rotations R_e (E,3,3) from Horn's method (identity without warping)."""
        if not self.warping:
            return np.broadcast_to(np.eye(3), (self.mesh.n_elements, 3, 3)).copy()
        with threads_for(self.mesh.n_elements, ELEMENT_PARALLEL_MIN, "fem.horn", TUNER_PERIOD):
            return _horn_all(self.mesh.points, self.positions(), self.integ.node_offsets, self.integ.nodes,
                             self.integ.mu)

    def elastic_forces(self, rots: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """Warped elastic forces (n,3) and the elastic energy Σ_e ½ dᵀ K_e d."""
        R = self.rotations() if rots is None else rots
        with threads_for(self.mesh.n_elements, ELEMENT_PARALLEL_MIN, "fem.forces", TUNER_PERIOD):
            fe, en = FK.warped_forces(self.mesh.points, self.positions(), self.integ.node_offsets, self.integ.nodes,
                                      self.kstiff.offsets, self.kstiff.data, R, self.mesh.n_nodes)
        f = np.zeros((self.mesh.n_nodes, 3))
        for k in range(3):
            f[:, k] = np.bincount(self.integ.nodes, weights=fe[:, k], minlength=self.mesh.n_nodes)
        return f, float(en.sum())

    def kinetic_energy(self) -> float:
        """½ Σ m_i |v_i|²."""
        return 0.5 * float((self.masses * (self.v**2).sum(axis=1)).sum())

    def elastic_energy(self) -> float:
        """Warped elastic energy Σ_e ½ (Rᵀx - X)ᵀ K_e (Rᵀx - X)."""
        return self._state_forces()[2]

    def _state_forces(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Rotations, elastic forces and elastic energy of the current state, computed once per state.

        A frame's record asks for the energy of the state the next step starts from; the
        step reuses the rotations and forces (about 6 % of a frame on the bunny-slicing
        benchmark). The state is identified by the objects it is made of (every change of
        ``u``, the mesh or the element data assigns new ones).
        """
        key = self._state_key()
        c = self._forces_cache
        if c is not None and _same(c[0], key):
            return c[1], c[2], c[3]
        R = self._cached_rotations()
        if R is None:
            R = self.rotations()
        f, en = self.elastic_forces(R)
        self._forces_cache = (key, R, f, en)
        return R, f, en

    def _state_key(self) -> tuple[Any, ...]:
        return (self.u, self.mesh, self.integ, self.kstiff, self.warping)

    def _cached_rotations(self) -> np.ndarray | None:
        """The rotations of the current state if already computed (by :meth:`_state_forces` or a re-integration)."""
        key = self._state_key()
        for c in (self._forces_cache, self._rot_cache):
            if c is not None and _same(c[0], key):
                return c[1]
        return None

    def potential_energy(self) -> float:
        """Gravitational potential -Σ m_i g·x_i."""
        return -float((self.masses * (self.positions() @ self.gravity)).sum())

    # -- constraints -----------------------------------------------------------------------
    def _prescribed(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        n = self.mesh.n_nodes
        mask = ~self._used.copy()  # orphan nodes are held
        vel = np.zeros((n, 3))
        for member, p in self.groups:
            if p.start <= t < p.stop:
                mask |= member
                vel[member] = p.velocity
        return mask, vel

    def external_forces(self) -> np.ndarray:
        """Gravity plus loads (n,3)."""
        f = self.masses[:, None] * self.gravity[None, :]
        for member, ld in self.loads:
            cnt = int(member.sum())
            if cnt:
                f[member] += np.asarray(ld.force, dtype=np.float64) / cnt
        return f

    # -- time step -----------------------------------------------------------------------------
    def step(self, dt: float) -> StepInfo:
        """Advance by ``dt`` (see :meth:`_step`)."""
        with kernel_threads(self.mesh.n_nodes):
            return self._step(dt)

    def _step(self, dt: float) -> StepInfo:
        """Advance by ``dt`` with one linearised implicit Euler step; returns timings.

        Pending topology changes (:meth:`change_topology`; all cuts of a step are
        committed together) are integrated once, before the solve (the deferred
        re-integration of 9.3.1).
        """
        dt = positive_scalar(dt, "dt")
        info = StepInfo()
        info.reintegration_seconds = self.flush()
        t0 = time.perf_counter()
        n = self.mesh.n_nodes
        x = self.positions()
        R, f_el, _ = self._state_forces()
        cm = 1.0 + dt * self.alpha
        ck = dt * self.beta + dt * dt
        pat = self.pattern
        integ, ks = self.integ, self.kstiff
        with threads_for(self.mesh.n_elements, ELEMENT_PARALLEL_MIN, "fem.assembly", TUNER_PERIOD) as tf:
            # one thread: the scatter over the elements; all: the row gather (same sums, same order)
            if tf.serial:
                A = FK.warped_global_blocks(integ.node_offsets, ks.offsets, ks.data, R, pat.block_map, len(pat.indices),
                                            ck)
            else:
                A = FK.warped_global_rows(integ.node_offsets, ks.offsets, ks.data, R, pat.inc_offsets,
                                          pat.inc_elements, pat.inc_local, pat.block_map, len(pat.indices), ck)
        SK.add_masses(A, self.pattern.diag, self.masses, cm)
        b = self.masses[:, None] * self.v + dt * (f_el + self.external_forces())
        fixed, vfix = self._prescribed(self.time)
        normal = self.ground.unit_normal() if self.ground is not None else np.array([0.0, 1.0, 0.0])
        active = self.contact & ~fixed if self.ground is not None else np.zeros(n, bool)
        mode = self.solver
        if mode == "auto":
            mode = "lu-pcg" if self._stiff else "cg"
        pinv = SK.block_jacobi(A, self.pattern.diag) if mode == "cg" else None
        # constraints for a factorisation made in this step: the active set of the last step or, without
        # one, the nodes a free fall would take below the ground (so a body that starts on the ground is
        # factorised in contact). The prediction overestimates a resting contact (bunny benchmark: 670
        # predicted, 87 in contact), and every node factorised in the wrong state widens the local set
        fall = active.copy()
        if self.ground is not None and not active.any():
            fall |= ~fixed & self._used & ((x + dt * (self.v + dt * self.gravity)) @ normal < self.ground.height)
        kind0 = np.where(fixed, 1, np.where(fall, 2, 0)).astype(np.int64)
        prec = self._lu_preconditioner(cm, ck, info, A, kind0, normal) if mode == "lu-pcg" else None
        vnew = self.v
        worst = 0
        # contact active-set rounds are solved to CONTACT_TOL; once the set is stable (or after
        # CONTACT_ROUNDS rounds) it is re-checked with a solve to cg_tol, so the accepted solution
        # meets the same criterion as solving every round to cg_tol
        tight = self.ground is None or mode == "direct" or self.cg_tol >= CONTACT_TOL
        rounds = 0
        resume = False  # the active set is confirmed: continue the loose solve's PCG to cg_tol
        solver: PCG | None = None
        solver_its = 0  # iterations of the current PCG over its runs
        while True:
            tol = self.cg_tol if tight else CONTACT_TOL
            rounds += 1
            kind = np.where(fixed, 1, np.where(active, 2, 0)).astype(np.int64)
            # warm start: the last velocity, then (contact set changed) the previous solution
            x0 = vnew.copy()
            x0[fixed] = vfix[fixed]
            if active.any():
                target = (self.ground.height - x[active] @ normal) / dt
                x0[active] += (target - x0[active] @ normal)[:, None] * normal
            if mode == "cg":
                limit = AUTO_CG_ITERATIONS if self.solver == "auto" else self.cg_maxiter
                vnew, its, res = SK.filtered_pcg(self.pattern.indptr, self.pattern.indices, A, pinv, b, x0, kind,
                                                normal, tol, limit)
                if self.solver == "auto" and res > tol:
                    # too stiff for block-Jacobi: switch to the factorised preconditioner for good
                    info.iterations += int(its)
                    self._stiff = True
                    mode = "lu-pcg"
                    prec = self._lu_preconditioner(cm, ck, info, A, kind0, normal)
            if mode == "lu-pcg":
                if not (resume and solver is not None):
                    solver = PCG(self.pattern.indptr, self.pattern.indices, A, b, x0, kind, normal, prec(kind, normal))
                    solver_its = 0
                vnew, its, res = solver.run(tol, min(self.cg_maxiter, LAGGED_ITERATIONS))
                solver_its += its
                if res > tol and self.lagged.factorizations and not info.extra.get("factorized"):
                    # the lagged preconditioner went bad: refactorise now and continue from there
                    info.iterations += int(its)
                    self.lagged.invalidate()
                    prec = self._lu_preconditioner(cm, ck, info, A, kind, normal)
                    solver = PCG(self.pattern.indptr, self.pattern.indices, A, b, x0, kind, normal, prec(kind, normal))
                    vnew, its, res = solver.run(tol, self.cg_maxiter)
                    solver_its = its
            elif mode == "direct":
                vnew, its = direct_solve(self.pattern.indptr, self.pattern.indices, A, b, x0, kind, normal), 1
            info.iterations += int(its)
            worst = max(worst, int(solver_its if mode == "lu-pcg" else its))
            resume = False
            if self.ground is None:
                break
            pred = (x + dt * vnew) @ normal - self.ground.height
            add = ~active & ~fixed & self._used & (pred < -1e-12 * max(1.0, abs(self.ground.height)))
            Av = SK.bsr_matvec(self.pattern.indptr, self.pattern.indices, A, vnew)
            lam = (Av - b) @ normal
            release = active & (lam < 0)
            if (not add.any() and not release.any()) or rounds >= CONTACT_ROUNDS:
                if tight or rounds > CONTACT_ROUNDS:
                    break
                tight = True  # confirm the active set with an accurate solve
                if not add.any() and not release.any():
                    resume = True
                    continue
            active = (active | add) & ~release
        if self.ground is not None and active.any():
            Av = SK.bsr_matvec(self.pattern.indptr, self.pattern.indices, A, vnew)
            lam = np.maximum((Av - b) @ normal, 0.0)
            vt = vnew[active] - np.outer(vnew[active] @ normal, normal)
            speed = np.linalg.norm(vt, axis=1)
            dv = np.minimum(speed, self.ground.friction * lam[active] / np.maximum(self.masses[active], 1e-300))
            scale = np.where(speed > 0, 1.0 - dv / np.where(speed > 0, speed, 1.0), 1.0)
            vnew[active] = np.outer(vnew[active] @ normal, normal) + vt * scale[:, None]
        self.contact = active
        self.lagged.last_iterations = worst
        info.contacts = int(active.sum())
        self.v = vnew
        self.u = self.u + dt * vnew
        self.time += dt
        self.steps += 1
        info.solve_seconds = time.perf_counter() - t0
        self.last = info
        return info

    def _lu_preconditioner(self, cm: float, ck: float, info: StepInfo, A: np.ndarray, kind0: np.ndarray,
                           normal: np.ndarray) -> Any:
        coeffs = (cm, ck)
        lag = self.lagged
        if lag.collect(self.steps):  # a background refactorisation due at this step
            info.extra["installed"] = True
        need = lag.needs_factor(coeffs, self.n_solid_pieces)
        start: list[Any] = []  # the background refactorisation, started once the first preconditioner is made
        if need or lag.wants_background(coeffs, self.n_solid_pieces):
            # the step's warped matrix with the last step's contact set is factorised, and rotated per
            # piece from the positions it was taken at (module docstring of solvers)
            ref = self.positions() if self.warping else None
            pat = self.pattern
            if need:
                lag.factor(pat.indptr, pat.indices, A, coeffs, self.n_solid_pieces, kind0, normal, ref)
                info.extra["factorized"] = True
            else:
                # after the first local factorisation of the step: its METIS ordering (a few ms) would
                # otherwise wait for the background thread's ordering of the whole mesh (~150 ms; METIS
                # calls are serialised, unmesh.fem.factor.nested_dissection). The preconditioner made
                # first does not depend on the pending factorisation
                start.append((pat.indptr, pat.indices, A, coeffs, self.steps, self.n_solid_pieces, kind0, normal,
                              ref))
        # one rotation per connected piece (not per node: a rotation varying from node to node
        # does not keep the translations in the near-null space, measured 3x the iterations)
        ref = self.mesh.points if lag.ref is None else lag.ref
        Q = piece_rotations(ref, self.positions(), self.masses, self.piece, self.n_pieces)[self.piece]
        pat = self.pattern
        made: dict[bytes, Any] = {}

        def prec(kind: np.ndarray, normal: np.ndarray) -> Any:
            # the contact rounds of a step often repeat an active set: reuse its local factorisation
            key = kind.tobytes()
            if key not in made:
                made[key] = self.lagged.preconditioner(Q, pat.indptr, pat.indices, A, kind, normal)
            if start:
                lag.start_background(*start.pop())
            return made[key]

        return prec

    # -- topology changes -------------------------------------------------------------------
    def reserve_topology_buffers(self) -> None:
        """Allocate (and touch) the buffers the stiffness data of the next topology changes go into.

        The merged stiffness data of a topology change (~100 MB on the bunny-slicing benchmark)
        is written into the buffer of the data two changes back (:meth:`_apply_pending`), 10 %
        longer than needed; the first two changes found none (no spare, then the setup's data,
        exactly as long as needed) and took fresh memory. On the benchmark's virtual machine
        memory the process had not used before cost ~6 ms per MB at its first touch (0.5 and
        0.7 s in the re-integration of the first two cutting frames). Called by a simulation
        with scripted cuts (:class:`unmesh.fem.simulation.FemSimulation`) before its first step;
        the data is unchanged, only moved.
        """
        ks = self.kstiff
        size = len(ks.data)
        cap = _capacity(size)
        base = _buffer(ks.data)
        if base is None or len(base) < cap:
            buf = np.empty(cap)
            buf[:size] = ks.data
            buf[size:] = 0.0
            self.kstiff = ElementStiffness(ks.node_offsets, ks.nodes, ks.offsets, buf[:size])
        if self._kspare is None or len(self._kspare) < cap:
            self._kspare = np.empty(cap)
            self._kspare.fill(0.0)

    def change_topology(self, mesh: PolyMesh, node_weights: sp.sparray, element_parent: np.ndarray,
                        changed: np.ndarray) -> None:
        """Switch to a new mesh after cutting; re-integration is deferred to the next :meth:`step`.

        Parameters
        ----------
        mesh : PolyMesh
            The new mesh (rest configuration).
        node_weights : sparse (n_new, n_old)
            New node state = weights @ old node state (interpolation on edges,
            copies for duplicated nodes).
        element_parent : (E_new,) int
            Old element each new element comes from (material, unchanged data).
        changed : (E_new,) bool
            Elements whose integration must be recomputed.
        """
        W = sp.csr_array(node_weights)
        if W.shape != (mesh.n_nodes, self.mesh.n_nodes):
            raise InputError(f"node_weights: expected shape {(mesh.n_nodes, self.mesh.n_nodes)}, got {W.shape}")
        W.sort_indices()
        parent = np.asarray(element_parent, dtype=np.int64)
        ch = np.asarray(changed, bool).copy()
        if self._pending is not None:  # compose with the change not integrated yet
            prev = self._pending
            ch |= prev.kept[parent] < 0
            kept = np.where(ch, -1, prev.kept[parent])
            parent = prev.parent[parent]
            rots = prev.rots
        else:
            kept = np.where(ch, -1, parent)
            # an unchanged element keeps its nodes' positions (copies), hence its rotation
            rots = self._cached_rotations()
        self.u = W @ self.u
        self.v = W @ self.v
        # keep the factorised preconditioner: mapped through W, exact solve on the touched nodes
        copy_rows = (np.diff(W.indptr) == 1) & (W.data[np.minimum(W.indptr[:-1], max(len(W.data) - 1, 0))] == 1.0)
        dup = np.bincount(W.indices[np.repeat(copy_rows, np.diff(W.indptr))], minlength=W.shape[1]) > 1
        touched = ~copy_rows | dup[W.indices[np.minimum(W.indptr[:-1], max(len(W.indices) - 1, 0))]]
        eoff, enodes = mesh.element_nodes()
        touched[enodes[np.repeat(ch, np.diff(eoff))]] = True
        self.lagged.remap(W, touched)
        # membership (fixed groups, contact) follows pure copies only
        nnz = np.diff(W.indptr)
        first = W.indices[np.minimum(W.indptr[:-1], max(len(W.indices) - 1, 0))]
        val = W.data[np.minimum(W.indptr[:-1], max(len(W.data) - 1, 0))]
        copy = (nnz == 1) & (val == 1.0)
        self.groups = [(m[first] & copy, p) for m, p in self.groups]
        self.loads = [(m[first] & copy, ld) for m, ld in self.loads]
        self.contact = self.contact[first] & copy
        self._pending = _Topology(mesh, parent, kept, rots, self.u)
        self.mesh = mesh
        self._used = np.zeros(mesh.n_nodes, bool)
        self._used[mesh.element_nodes()[1]] = True

    def _apply_pending(self) -> None:
        pend = self._pending
        self._pending = None
        assert pend is not None
        mesh = pend.mesh
        old_integ, old_k = self.integ, self.kstiff
        self.young = self.young[pend.parent]
        self.poisson = self.poisson[pend.parent]
        self.density = self.density[pend.parent]
        from_new = pend.kept < 0
        changed = np.flatnonzero(from_new)
        with threads_for(len(changed), CHANGED_PARALLEL_MIN, "fem.integrate", TUNER_PERIOD):
            new = integrate_elements(mesh, self.correction, elements=changed, rule=self.rule)
            ks_new = element_stiffness(new, self.young[changed], self.poisson[changed], rule=self.rule,
                                       of_mesh=mesh, elements=changed)
        # element i comes from the old data (row kept[i]) or the re-integrated data (its rank in `changed`)
        src = np.where(from_new, np.cumsum(from_new) - 1, pend.kept)
        noff, nodes = mesh.element_nodes()
        _, mu = merge_csr(old_integ.node_offsets, old_integ.mu, new.node_offsets, new.mu, from_new, src)
        soff, w = merge_csr(old_integ.sample_offsets, old_integ.weights, new.sample_offsets, new.weights, from_new, src)
        _, smp = merge_csr(old_integ.sample_offsets, old_integ.samples, new.sample_offsets, new.samples, from_new, src)
        goff, g = merge_csr(old_integ.grad_offsets, old_integ.grads, new.grad_offsets, new.grads, from_new, src)
        vols = np.where(from_new, new.volumes[np.where(from_new, src, 0)], old_integ.volumes[np.where(from_new, 0, src)])
        # unchanged elements keep their local node order; their node ids are the new mesh's
        self.integ = ElementIntegration(noff, nodes, vols, mu, soff, w, smp, goff, g, old_integ.corrected)
        # the stiffness data (~100 MB on the bunny benchmark) goes into the buffer of the data two changes
        # back, made 10 % longer than needed: a fresh array cost up to 1.7 s of first-touch page faults
        size = 9 * int(np.sum(np.diff(noff) ** 2))
        spare = self._kspare if self._kspare is not None and len(self._kspare) >= size else np.empty(_capacity(size))
        koff, kdata = merge_csr(old_k.offsets, old_k.data, ks_new.offsets, ks_new.data, from_new, src, out=spare)
        self._kspare = _buffer(old_k.data)
        self._setup_element_data(ElementStiffness(noff, nodes, koff, kdata))
        if pend.rots is not None and pend.u is self.u and self.warping:
            # Horn only for the re-integrated elements (bit-identical to a full pass: per element)
            R = np.empty((mesh.n_elements, 3, 3))
            R[~from_new] = pend.rots[pend.kept[~from_new]]
            R[from_new] = _horn_all(mesh.points, self.positions(), new.node_offsets, new.nodes, new.mu)
            self._rot_cache = (self._state_key(), R)

    def flush(self) -> float:
        """Apply a pending topology change now; returns the seconds spent re-integrating."""
        if self._pending is None:
            return 0.0
        t = time.perf_counter()
        self._apply_pending()
        return time.perf_counter() - t


def _capacity(size: int) -> int:
    """Length of a buffer for ``size`` stiffness values: 10 % more, for the growth of the next cuts."""
    return size + size // 10


def _buffer(a: np.ndarray) -> np.ndarray | None:
    """The 1-D float64 array whose memory ``a`` is (a view of), or None."""
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a if a.ndim == 1 and a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable else None


def _same(key: tuple[Any, ...], other: tuple[Any, ...]) -> bool:
    """Whether two state keys hold the same objects."""
    return len(key) == len(other) and all(a is b for a, b in zip(key, other, strict=True))


def _expand(value: Any, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    return as_array(arr, name, (n,)).copy()
