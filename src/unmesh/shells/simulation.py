"""The point-sampled thin shell as a :class:`unmesh.sim.Simulation` (thesis chapter 7).

:class:`ShellSimulation` chooses simulation nodes on a dense surfel cloud, builds fibers,
integrates (7.18) with velocity Verlet, applies plasticity and fracture after every step,
and animates the dense surface with local-frame skinning once per written frame. The
runner (:func:`unmesh.sim.run`) owns the time loop and files; see ``docs/shell_scene.md``
for the outputs.
"""

from __future__ import annotations

import collections
import math
import time as _time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError
from unmesh.shells import _step_kernels
from unmesh.shells.dynamics import Gravity, Handle, Pressure, Pull, damping_force
from unmesh.shells.energy import FiberState, umbrella_normals
from unmesh.shells.forces import ForceResult, elastic_forces
from unmesh.shells.fracture import CrackSet
from unmesh.shells.material import ShellMaterial
from unmesh.shells.nodes import DEFAULT_MIN_ANGLE, DEFAULT_NEIGHBORS, build_topology, select_nodes
from unmesh.shells.skinning import DEFAULT_SKIN_NODES, SkinnedSurface
from unmesh.shells.tearing import DEGENERATE_RATIO, Tearing, warm_up
from unmesh.shells.topology import ShellTopology, csr_entries
from unmesh.sim import Simulation
from unmesh.sim.checkpoint import expect_shapes
from unmesh.surfels import SurfelCloud

__all__ = ["ShellSimulation", "node_areas", "stable_time_step"]

#: Minimum number of simulation nodes.
MIN_NODES = 10
_NO_ANGLES = np.zeros(0)


def node_areas(cloud: SurfelCloud, owner: np.ndarray, n_nodes: int, total_area: float | None = None,
               k: int = 8) -> np.ndarray:
    """Surface area represented by each node: the area of the surfels whose nearest node it is.

    Parameters
    ----------
    cloud : SurfelCloud
        Dense surface.
    owner : ndarray (S,) int64
        Nearest node of each surfel.
    n_nodes : int
    total_area : float, optional
        Known surface area; shared in proportion to surfel counts. Without it, each surfel's
        area is estimated from the local sampling density, ``pi d_k^2 / (k + 1)`` with
        ``d_k`` the distance to its ``k``-th nearest surfel.
    k : int
        Neighbours of the density estimate.

    Returns
    -------
    ndarray (N,)

    Example
    -------
    >>> c = SurfelCloud(np.zeros((4, 3)) + np.arange(4)[:, None], np.tile([0, 0, 1.0], (4, 1)), radii=np.ones(4))
    >>> node_areas(c, np.array([0, 0, 1, 1]), 2, total_area=2.0)
    array([1., 1.])
    """
    if total_area is not None:
        per = np.full(len(cloud), float(total_area) / len(cloud))
    else:
        from unmesh.spatial import knn

        kk = int(min(k, len(cloud) - 1))
        d, _ = knn(cloud.positions, kk + 1)
        per = np.pi * d[:, kk] ** 2 / (kk + 1)
    return np.bincount(owner, per, n_nodes)


def _select(region: Any, rest: np.ndarray, what: str) -> np.ndarray:
    if callable(getattr(region, "contains", None)):
        mask = np.asarray(region.contains(rest), dtype=bool)
    else:
        idx = as_array(region, what, (None,), np.int64)
        mask = np.zeros(len(rest), dtype=bool)
        mask[idx] = True
    if not mask.any():
        raise InputError(f"{what}: the region contains no simulation node")
    return np.flatnonzero(mask)


class ShellSimulation(Tearing, Simulation):
    """A point-sampled thin shell (7.2-7.4) for :func:`unmesh.sim.run`.

    Parameters
    ----------
    cloud : SurfelCloud
        Dense input surface (rest state); every surfel is animated (7.4).
    material : ShellMaterial
    dt : float
        Time step (Appendix F.1).
    nodes : int, optional
        Number of simulation nodes chosen by clustering (7.2).
    node_indices : array_like of int, optional
        Or: the surfels to use as nodes.
    neighbors : int
        Neighbourhood size.
    min_angle : float
        Smallest fiber angle at its centre, degrees (7.4).
    skin_nodes : int
        Nodes per surfel for skinning (7.26-7.30).
    gravity : array_like (3,)
    velocity : array_like (3,)
        Initial velocity of every node.
    colliders : sequence
        :class:`~unmesh.shells.dynamics.PlaneCollider` / ``SphereCollider``.
    pinned : sequence
        Regions (shapes with ``contains``, or node index arrays) of fixed nodes.
    handles : sequence of dict
        ``{"region", "velocity", "start", "stop", "acceleration"}``: nodes moved kinematically.
    pulls : sequence of dict
        ``{"region", "force", "ramp", "start", "stop"}``: total forces on node groups.
    pressure : Pressure, optional
        Inflation pressure along the node normals.
    total_area : float, optional
        Known surface area (else estimated from the sampling density).
    max_cracks : int
        Most new cracks per time step.
    name : str
        Shown in progress bars and messages.

    Raises
    ------
    InputError
        Too few nodes, a disconnected or non-manifold input, nodes outside every fiber.
    """

    name = "shell"
    #: Take the one-kernel step (:mod:`unmesh.shells.stepping`); False: :meth:`step_plain`.
    fused = True

    def __init__(self, cloud: SurfelCloud, material: ShellMaterial, dt: float, *, nodes: int | None = None,
                 node_indices: Any = None, neighbors: int = DEFAULT_NEIGHBORS, min_angle: float = DEFAULT_MIN_ANGLE,
                 skin_nodes: int = DEFAULT_SKIN_NODES, gravity: Any = (0.0, -9.81, 0.0), velocity: Any = (0.0, 0.0, 0.0),
                 colliders: Sequence[Any] = (), pinned: Sequence[Any] = (), handles: Sequence[dict[str, Any]] = (),
                 pulls: Sequence[dict[str, Any]] = (), pressure: Pressure | None = None,
                 total_area: float | None = None, max_cracks: int = 8, name: str = "shell") -> None:
        if not isinstance(cloud, SurfelCloud):
            raise InputError(f"cloud: expected a SurfelCloud, got {type(cloud).__name__}")
        self.name = name
        self.material = material
        self.dt = positive_scalar(dt, "dt")
        if node_indices is None:
            if nodes is None:
                raise InputError("nodes: give the number of simulation nodes or node_indices")
            if int(nodes) != nodes or nodes < MIN_NODES:
                raise InputError(f"nodes: expected at least {MIN_NODES} simulation nodes, got {nodes!r}")
            node_indices = select_nodes(cloud, int(nodes))
        idx = as_array(node_indices, "node_indices", (None,), np.int64)
        if len(idx) < MIN_NODES:
            raise InputError(f"nodes: expected at least {MIN_NODES} simulation nodes, got {len(idx)}")
        if len(np.unique(idx)) != len(idx) or idx.min() < 0 or idx.max() >= len(cloud):
            raise InputError(f"node_indices: expected distinct surfel indices in [0, {len(cloud)})")
        self.node_indices = idx
        self.cloud = cloud
        self.rest = np.ascontiguousarray(cloud.positions[idx])
        self.rest_normals = np.ascontiguousarray(cloud.normals[idx])
        self.neighbors = int(neighbors)
        self.min_angle = float(min_angle)
        self.max_cracks = int(max_cracks)
        topo = build_topology(self.rest, self.rest_normals, self.neighbors, self.min_angle)
        # the umbrella normals at rest: checked against the input, and what deform() is given in
        # the rest state (the frames of bindings without a plane, skinning.frame_normals)
        self._skin_normals = umbrella_normals(self.rest, topo)[1]
        self._check_input(topo)
        self.topology = topo
        self.fibers = FiberState.at_rest(self.rest, topo, material.arc_samples,
                                         **material.fiber_material(topo.fibers, self.rest))
        self.fibers_initial = len(topo.fibers)
        self.surface = SkinnedSurface(cloud, self.rest, self.rest_normals, skin_nodes, self._skin_normals)
        owner = self.surface.bind[:, 0]
        self.area = node_areas(cloud, owner, len(idx), total_area)
        if np.any(self.area <= 0):
            # a node owning no surfel (possible only with given node_indices): borrow the mean
            self.area[self.area <= 0] = self.area[self.area > 0].mean()
        self.mass = material.density * self.area
        self.size = float(np.linalg.norm(self.rest.max(axis=0) - self.rest.min(axis=0)))
        self.colliders = tuple(colliders)
        self.gravity = Gravity(gravity)
        self.pressure = pressure
        self.fixed = np.zeros(len(idx), dtype=bool)
        for i, region in enumerate(pinned):
            self.fixed[_select(region, self.rest, f"pinned[{i}]")] = True
        self.handles = tuple(
            Handle(_select(h["region"], self.rest, f"handles[{i}]"), h.get("velocity", (0.0, 0.0, 0.0)),
                   float(h.get("start", 0.0)), float(h.get("stop", math.inf)), h.get("acceleration", (0.0, 0.0, 0.0)))
            for i, h in enumerate(handles))
        for h in self.handles:
            self.fixed[h.nodes] = True
        self.pulls = tuple(
            Pull(_select(p["region"], self.rest, f"pulls[{i}]"), p["force"], float(p.get("ramp", 0.0)),
                 float(p.get("start", 0.0)), float(p.get("stop", math.inf))) for i, p in enumerate(pulls))
        self.cracks = CrackSet()
        self._pending_cracks: list[int] = []   # cracks not yet bound into the skinned surface
        self.first_crack: float | None = None
        self.node_offsets = np.zeros((len(idx), 2))
        # crumbs: nodes a crack cut off from every fiber follow a visible node of a piece (-1: free)
        self.anchor = np.full(len(idx), -1, dtype=np.int64)
        self._reach = self._neighbor_reach()
        # state
        self.time = 0.0
        self.steps = 0
        self.x = self.rest.copy()
        self.v = np.zeros_like(self.x)
        self.v[:] = as_array(velocity, "velocity", (3,))
        self.v[self.fixed] = 0.0
        self._timers = {"force": 0.0, "fracture": 0.0, "surface": 0.0}
        self._energy_hist: collections.deque[float] = collections.deque(maxlen=40)
        self._energy_window = (0.0, 0.0)  # max energy of the previous / current block of 1000 steps
        self._energy_floor: float | None = None
        self._prev_angles: np.ndarray | None = None
        self._prev_topology: ShellTopology | None = None
        self._surface_cache: tuple[int, SurfelCloud] | None = None
        self.acc = self._accelerations()
        # load the kernel of check() now (from numba's cache: ~10 ms) rather than in the first frame
        no3 = np.zeros((0, 3))
        _step_kernels.check_stats(no3, no3.copy(), _NO_ANGLES, _NO_ANGLES, _NO_ANGLES, _NO_ANGLES, _NO_ANGLES)
        if material.fractures:
            warm_up()

    # -- set-up checks ------------------------------------------------------------
    def _check_input(self, topo: ShellTopology) -> None:
        n = topo.n_nodes
        on_fiber = np.diff(topo.fiber_incidence_offsets) > 0
        if not on_fiber.all():
            bad = np.flatnonzero(~on_fiber)
            raise InputError(
                f"input surface: {len(bad)} of {n} simulation nodes lie on no fiber (first at "
                f"{np.round(self.rest[bad[0]], 4).tolist()}); the surface is too coarsely sampled or not a surface "
                f"-- use more nodes or more neighbors (now {self.neighbors})")
        count, labels = topo.components()
        if count > 1:
            sizes = np.sort(np.bincount(labels))[::-1]
            raise InputError(
                f"input surface is disconnected: its fiber graph has {count} separate pieces (node counts "
                f"{sizes[:5].tolist()}{'...' if count > 5 else ''}); simulate pieces separately, or use more nodes "
                f"or neighbors if the surface is in one piece")
        nrm = self._skin_normals
        has = np.diff(topo.pair_offsets) > 0
        agree = np.einsum("ij,ij->i", nrm, self.rest_normals)
        bad = np.flatnonzero(has & (agree < 0.3))
        if len(bad) > max(2, n // 50):
            raise InputError(
                f"input surface: the node neighbourhoods of {len(bad)} nodes are not disc-like (first at "
                f"{np.round(self.rest[bad[0]], 4).tolist()}): the surface is non-manifold, inconsistently oriented, "
                "or thinner than the node spacing; use more nodes or fix the input")

    def _neighbor_reach(self, nodes: np.ndarray | None = None) -> float:
        """Longest rest distance from a node to a neighbour (of the listed ``nodes``, default all).

        After a rebuild only the rebuilt nodes' neighbourhoods can have grown (the others
        only lose neighbours), so ``max(reach, _neighbor_reach(rebuilt))`` equals
        ``max(reach, _neighbor_reach())``.
        """
        t = self.topology
        if nodes is None:
            nodes = np.arange(t.n_nodes)
        nodes = np.asarray(nodes, dtype=np.int64)
        pos, rows = csr_entries(t.neighbor_offsets, nodes)
        if not len(pos):
            return 0.0
        nbr = t.neighbors[pos]
        return float(np.linalg.norm(self.rest[nbr] - self.rest[rows], axis=1).max())

    # -- dynamics -----------------------------------------------------------------
    def _external(self, t: float, res: ForceResult) -> np.ndarray:
        f = self.gravity.force(t, self.x, self.v, self.mass, self.area, res.normals, self.first_crack)
        f += damping_force(self.v, self.mass, self.material.damping)
        if self.pressure is not None:
            # current node area: rest area times the local stretch of the umbrella fan
            stretch = self._fan_ratio(res)
            f += self.pressure.force(t, self.x, self.v, self.mass, self.area * stretch, res.normals, self.first_crack)
        for p in self.pulls:
            f += p.force(t, self.x, self.v, self.mass, self.area, res.normals, self.first_crack)
        return f

    def _fan0_of_topology(self) -> np.ndarray:
        """``|s_i|`` at rest of the current topology (cached per topology)."""
        if getattr(self, "_fan0_topo", None) is not self.topology:
            s0, _ = umbrella_normals(self.rest, self.topology)
            self._fan0 = np.linalg.norm(s0, axis=1)
            self._fan0_topo = self.topology
        return self._fan0

    def _fan_ratio(self, res: ForceResult) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.linalg.norm(res.umbrella, axis=1) / self._fan0_of_topology()
        return np.where(np.isfinite(r), r, 1.0)

    def _reference_angles(self) -> np.ndarray:
        """Angle branch reference of the next force pass: the last angles on this topology, else
        the angles carried over a topology change (once), else the rest angles."""
        last = getattr(self, "_last", None)
        if last is not None and getattr(self, "_last_topology", None) is self.topology:
            return last.angles
        if getattr(self, "_resume_angles", None) is not None and len(self._resume_angles) == len(self.topology.fibers):
            ref = self._resume_angles
            self._resume_angles = None
            return np.ascontiguousarray(ref, dtype=np.float64)
        return self.fibers.rest_angle()

    def _accelerations(self) -> np.ndarray:
        m = self.material
        ref = self._reference_angles()
        res = elastic_forces(self.x, self.topology, self.fibers, m.ks, m.kb, m.arc_samples, ref, self.node_offsets)
        self._x_force = self.x.copy()
        return self._acc_of(res)

    def _acc_of(self, res: ForceResult) -> np.ndarray:
        """Accelerations (7.18) from the elastic forces ``res`` at the current state (kept as the last pass)."""
        self._last = res
        self._last_topology = self.topology
        acc = (res.forces + self._external(self.time, res)) / self.mass[:, None]
        acc[self.fixed] = 0.0
        return acc

    def _kinematics(self, t: float) -> None:
        pinned = self.fixed.copy()
        for h in self.handles:
            pinned[h.nodes] = False
            self.x[h.nodes] = self.rest[h.nodes] + h.displacement(t)
            self.v[h.nodes] = h.current_velocity(t)
        self.x[pinned] = self.rest[pinned]
        self.v[pinned] = 0.0

    def step(self) -> float:
        """One velocity-Verlet step of (7.18), then plasticity (7.19-7.23) and fracture (7.24).

        Runs in one kernel call (:mod:`unmesh.shells.stepping`); :meth:`step_plain` is the
        same step with numpy and separate kernels (its reference, and the path taken for
        colliders the kernel does not know or when ``fused`` is False).
        """
        stepper = self._stepper()
        if stepper is None:
            return self.step_plain()
        t0 = _time.perf_counter()
        over, bad = stepper.step(self)
        self.steps += 1
        t1 = _time.perf_counter()
        self._timers["force"] += t1 - t0
        if over or bad:
            self._fracture_events(bad > 0)
            self._timers["fracture"] += _time.perf_counter() - t1
        return self.dt

    def _stepper(self) -> Any:
        """The one-kernel step for the current set-up (rebuilt when kinematic nodes or colliders change)."""
        if not self.fused:
            return None
        st = getattr(self, "_fused", None)
        if (st is None or st[0][0] is not self.handles or st[0][1] is not self.colliders
                or st[0][2] is not self.material or st[1] != self.fixed.tobytes()):
            from unmesh.shells.stepping import FusedStep

            fs = FusedStep(self, DEGENERATE_RATIO**2)
            st = self._fused = ((self.handles, self.colliders, self.material), self.fixed.tobytes(),
                                fs if fs.supported else None)
        return st[2]

    def step_plain(self) -> float:
        """:meth:`step` with numpy and separate kernels (the reference of the one-kernel step)."""
        t0 = _time.perf_counter()
        dt = self.dt
        self.v += 0.5 * dt * self.acc
        self.x += dt * self.v
        self.time += dt
        self._kinematics(self.time)
        self.acc = self._accelerations()
        self.v += 0.5 * dt * self.acc
        self._kinematics(self.time)
        for c in self.colliders:
            c.resolve(self.x, self.v)
        self._follow()
        self.material.plasticity.update(self.fibers, self._last.lengths, self._last.angles, dt)
        self.steps += 1
        t1 = _time.perf_counter()
        self._timers["force"] += t1 - t0
        if self.material.fractures:
            self._fracture()
            self._timers["fracture"] += _time.perf_counter() - t1
        return dt

    # -- diagnostics ----------------------------------------------------------------
    def kinetic_energy(self) -> float:
        """``sum m_i |v_i|^2 / 2``."""
        return float(0.5 * (self.mass * np.einsum("ij,ij->i", self.v, self.v)).sum())

    def elastic_energy(self) -> float:
        """``E_s + E_b`` of the current state."""
        return self._last.energy

    def check(self) -> str | None:
        """NaN, runaway energy, a fiber folding over in one step, or nodes jumping half the object."""
        angles = self._last.angles
        prev = self._prev_angles
        same = prev is not None and len(prev) == len(angles) and self._prev_topology is self.topology and len(angles)
        last = self._last
        finite, ke, vmax2, jumps, elastic = _step_kernels.check_stats(self.x, self.v, self.mass, angles,
                                                                      prev if same else _NO_ANGLES,
                                                                      last.stretch_energy, last.bend_energy)
        if not finite:
            return "NaN or infinity in the node positions or velocities"
        e = ke + elastic
        if not math.isfinite(e):
            return "non-finite energy"
        if self._energy_floor is None:
            self._energy_floor = float(self.mass.sum()) * (np.linalg.norm(self.gravity.g) + 1.0) * max(self.size,
                                                                                                      1e-12)
        floor = self._energy_floor
        hist = self._energy_hist
        hist.append(e)
        if len(hist) == hist.maxlen and e > 1e4 * max(hist[0], floor):
            return f"energy blew up from {hist[0]:.3g} to {e:.3g} within {len(hist)} steps"
        # slower runaways: more than 100x the largest energy of the last 1000 steps
        if self.steps % 1000 == 0:
            self._energy_window = (self._energy_window[1], 0.0)
        self._energy_window = (self._energy_window[0], max(self._energy_window[1], e))
        ref = max(self._energy_window[0], floor)
        if self._energy_window[0] > 0 and e > 100 * ref:
            return f"energy grew from at most {ref:.3g} to {e:.3g} within 2000 steps"
        # a few flips at crack edges are tolerated; many at once mean the state is breaking up
        if same and jumps > max(3, len(angles) // 500):
            return (f"{jumps} fibers folded over in one step (tangent angle jumps of more than "
                    "90 degrees): the deformation per step is too large for the node spacing")
        self._prev_angles = angles
        self._prev_topology = self.topology
        vmax = math.sqrt(vmax2)
        if vmax * self.dt > 0.5 * self.size:
            return f"nodes moved {vmax * self.dt:.3g} in one step, more than half the object size"
        return None

    def deformed_surface(self) -> SurfelCloud:
        """The dense surfel cloud of the current state (cached per step; timed as surface time)."""
        if self._surface_cache is None or self._surface_cache[0] != self.steps:
            t0 = _time.perf_counter()
            self._update_surface()
            t1 = _time.perf_counter()
            self._timers["fracture"] += t1 - t0
            cloud = self.surface.deform(self.x, self._last.normals)
            self._timers["surface"] += _time.perf_counter() - t1
            self._surface_cache = (self.steps, cloud)
        return self._surface_cache[1]

    def frame_record(self) -> dict[str, Any]:
        """Energies, momentum, fiber and crack counts, pieces and the time split (Table 7.1)."""
        self.deformed_surface()
        p = (self.mass[:, None] * self.v).sum(axis=0)
        ang = np.cross(self.x, self.mass[:, None] * self.v).sum(axis=0)
        rec = {
            "kinetic_energy": self.kinetic_energy(),
            "elastic_energy": self.elastic_energy(),
            "gravity_energy": self.gravity.potential(self.x, self.mass),
            "linear_momentum": p.tolist(),
            "angular_momentum": ang.tolist(),
            "fibers": len(self.topology.fibers),
            "cracks": len(self.cracks),
            "components": self.pieces()[0],
            "crumbs": int((self.anchor >= 0).sum()),
            "force_seconds": self._timers["force"],
            "fracture_seconds": self._timers["fracture"],
            "surface_seconds": self._timers["surface"],
        }
        if self.pressure is not None:
            rec["pressure"] = self.pressure.value(self.time, self.first_crack)
        self._timers = {"force": 0.0, "fracture": 0.0, "surface": 0.0}
        return rec

    def summary_header(self) -> dict[str, Any]:
        """Node, surfel and initial fiber counts and the main parameters."""
        m = self.material
        return {"nodes": len(self.rest), "surfels": len(self.cloud), "fibers_initial": self.fibers_initial,
                "dt": self.dt, "ks": m.ks, "kb": m.kb, "damping": m.damping, "mass": float(self.mass.sum())}

    # -- output ---------------------------------------------------------------------
    def write_frame(self, outdir: Path, frame: int) -> list[str]:
        """``frames/``: dense surfels; ``nodes/``: nodes with velocities; ``fibers/``: fiber data.

        Returns the three files written (relative to ``outdir``).
        """
        from unmesh import io
        from unmesh.io.atomic import atomic_path
        from unmesh.particles import Particles

        out = Path(outdir)
        name = f"frame_{frame:05d}"
        io.save(out / "frames" / f"{name}.ply", self.deformed_surface())
        n = self._last.normals
        nodes = Particles(self.x, attributes={
            "vx": self.v[:, 0], "vy": self.v[:, 1], "vz": self.v[:, 2], "normal": n,
            "mass": self.mass, "elastic_energy": self._last.stretch_energy + self._last.bend_energy})
        io.save(out / "nodes" / f"{name}.ply", nodes)
        (out / "fibers").mkdir(parents=True, exist_ok=True)
        with atomic_path(out / "fibers" / f"{name}.npz") as tmp, open(tmp, "wb") as fh:
            np.savez(fh, fibers=self.topology.fibers, length=self._last.lengths, angle=self._last.angles,
                     rest_length=self.fibers.rest_length(), rest_angle=self.fibers.rest_angle(),
                     crack_centers=self.cracks.centers, crack_normals=self.cracks.normals,
                     crack_radii=self.cracks.radii)
        return [f"frames/{name}.ply", f"nodes/{name}.ply", f"fibers/{name}.npz"]

    # -- checkpoints ----------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Node state, connectivity, fiber state and cracks (the skinning is rebuilt from the cracks)."""
        t = self.topology
        state: dict[str, Any] = {
            "time": self.time, "steps": self.steps, "x": self.x, "v": self.v, "acc": self.acc,
            "first_crack": math.nan if self.first_crack is None else self.first_crack,
            "neighbor_offsets": t.neighbor_offsets, "neighbors": t.neighbors, "pairs": t.pairs,
            "pair_center": t.pair_center, "fibers": t.fibers, "soft": t.soft, "node_offsets": self.node_offsets,
            "anchor": self.anchor,
        }
        state["angles"] = self._last.angles  # continuous (unwrapped) fiber angles
        state.update({f"fiber_{k}": v for k, v in self.fibers.as_dict().items()})
        state.update({f"crack_{k}": v for k, v in self.cracks.as_dict().items()})
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`; rebinds the surface to the restored cracks."""
        n = len(self.rest)
        expect_shapes(state, {"x": (n, 3), "v": (n, 3), "acc": (n, 3), "neighbor_offsets": (n + 1,)})
        self.time = float(state["time"])
        self.steps = int(state["steps"])
        self.x = np.ascontiguousarray(state["x"], dtype=np.float64)
        self.v = np.ascontiguousarray(state["v"], dtype=np.float64)
        self.node_offsets = np.array(state["node_offsets"], dtype=np.float64).reshape(-1, 2)
        self.anchor = np.array(state.get("anchor", np.full(len(self.rest), -1)), dtype=np.int64).reshape(-1)
        fc = float(state["first_crack"])
        self.first_crack = None if math.isnan(fc) else fc
        self.topology = ShellTopology.build(len(self.rest), state["neighbor_offsets"], state["neighbors"],
                                            state["pairs"], state["pair_center"], state["fibers"], state["soft"])
        names = ("length_orig", "angle_orig", "length_plastic", "angle_plastic", "stretch_scale", "bend_scale",
                 "fracture_stretch", "fracture_bend")
        self.fibers = FiberState(*(np.asarray(state[f"fiber_{k}"], dtype=np.float64) for k in names))
        self.cracks = CrackSet(*(np.asarray(state[f"crack_{k}"]) for k in ("centers", "normals", "radii", "nodes",
                                                                           "times")))
        self.cracks.centers = self.cracks.centers.reshape(-1, 3).astype(np.float64)
        self.cracks.normals = self.cracks.normals.reshape(-1, 3).astype(np.float64)
        self.cracks.nodes = self.cracks.nodes.astype(np.int64)
        self._reach = max(self._reach, self._neighbor_reach())
        self.surface = SkinnedSurface(self.cloud, self.rest, self.rest_normals, self.surface.k, self._skin_normals)
        self._pending_cracks = []
        self.surface.exclude_nodes(self.anchor >= 0, self.cracks.blocked)
        if len(self.cracks):
            self.surface.rebind_near(self.cracks.centers, float(self.cracks.radii.max()), self.cracks.blocked)
            self.surface.add_discontinuities(self.cracks.centers, self.cracks.normals, self.cracks.radii,
                                             self.rest_normals[self.cracks.nodes], self.cracks.blocked)
        self._surface_cache = None
        self._energy_hist.clear()
        self._energy_window = (0.0, 0.0)
        self._last = None
        self._resume_angles = np.asarray(state["angles"], dtype=np.float64)
        self._accelerations()  # fiber measures and normals of the restored state
        self._resume_angles = None
        # the stored accelerations include the damping of the half-step velocity they were made with
        self.acc = np.ascontiguousarray(state["acc"], dtype=np.float64)


def stable_time_step(sim: ShellSimulation, iterations: int = 40, seed: int = 0) -> float:
    """Estimate the largest stable velocity-Verlet step ``2 / omega_max`` at the current state.

    ``omega_max^2`` is the largest eigenvalue of ``M^-1 K`` (``K`` the elastic stiffness
    at the current positions), found by power iteration on central differences of the
    elastic forces. Damping and collisions are ignored.

    Parameters
    ----------
    sim : ShellSimulation
    iterations : int
        Power iterations.
    seed : int
        Seed of the start vector.

    Returns
    -------
    float
        Seconds; pick ``dt`` comfortably below it (e.g. 0.7 times).
    """
    m = sim.material
    rng = np.random.default_rng(seed)
    u = rng.normal(size=sim.x.shape)
    u[sim.fixed] = 0.0
    u /= np.linalg.norm(u)
    eps = 1e-7 * max(sim.size, 1e-12)
    lam = 0.0
    for _ in range(iterations):
        fp = elastic_forces(sim.x + eps * u, sim.topology, sim.fibers, m.ks, m.kb, m.arc_samples).forces
        fm = elastic_forces(sim.x - eps * u, sim.topology, sim.fibers, m.ks, m.kb, m.arc_samples).forces
        ku = -(fp - fm) / (2 * eps) / sim.mass[:, None]
        ku[sim.fixed] = 0.0
        lam = float(np.linalg.norm(ku))
        if not lam > 0:
            return math.inf
        u = ku / lam
    return 2.0 / math.sqrt(lam)
