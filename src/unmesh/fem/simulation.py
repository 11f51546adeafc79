"""The FEM simulation for :func:`unmesh.sim.run`: dynamics, scripted cuts, frame files.

Per frame ``k`` it writes ``frames/mesh_NNNNN.vtu`` (polyhedron cells, deformed points,
point data ``displacement`` and ``velocity``), rewrites ``mesh.pvd`` (the series, in OUTDIR)
and writes ``frames/surface_NNNNN.ply`` (the boundary triangles, deformed, for the
renderer); the runner records them in ``frames.json``. ``summary.json`` gets ``nodes_initial``, ``elements_initial`` and per
frame ``nodes``, ``elements``, ``volume`` (rest volume), ``kinetic_energy``,
``elastic_energy``, ``solve_seconds`` and ``reintegration_seconds`` (summed over
the steps of the frame), ``cg_iterations`` and ``contacts``.

Example
-------
>>> import tempfile
>>> from unmesh.fem import hex_grid
>>> from unmesh.fem.dynamics import Dynamics, Ground
>>> from unmesh.sim import RunSettings, run
>>> sim = FemSimulation(Dynamics(hex_grid((1, 1, 1), origin=(0, 0.2, 0)), 50, 0.3, ground=Ground()), dt=0.01)
>>> run(sim, tempfile.mkdtemp(), RunSettings(duration=0.1, fps=10), progress=False).status
'completed'
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.fem.cutting import CutMissWarning, Cutter
from unmesh.fem.dynamics import Dynamics
from unmesh.fem.events import CutEvent
from unmesh.fem.mesh import PolyMesh
from unmesh.fem.vtk_io import write_pvd, write_vtu
from unmesh.sim import Simulation
from unmesh.sim.checkpoint import expect_shapes

__all__ = ["CutSkippedWarning", "FemSimulation"]


class CutSkippedWarning(UserWarning):
    """The cuts of a time step were degenerate and skipped (the mesh is unchanged)."""


class FemSimulation(Simulation):
    """A :class:`Dynamics` plus scripted cuts, as an :class:`unmesh.sim.Simulation`.

    Parameters
    ----------
    dynamics : Dynamics
    dt : float
        Fixed time step.
    events : list of CutEvent
        Scripted cuts (rest coordinates).
    snap : float
        Snapping fraction of the cuts.
    sliver_threshold : float
        After each cutting step, changed elements flatter than this (thickness /
        diameter) are removed (9.2); 0 disables.

    Example
    -------
    See the module example.
    """

    name = "fem"

    def __init__(self, dynamics: Dynamics, dt: float, events: list[CutEvent] | None = None, *, snap: float = 0.02,
                 sliver_threshold: float = 0.0) -> None:
        self.dyn = dynamics
        self.dt = float(dt)
        self.events = list(events or [])
        self.snap = float(snap)
        self.sliver_threshold = float(sliver_threshold)
        self.time = dynamics.time
        self.nodes_initial = dynamics.mesh.n_nodes
        self.elements_initial = dynamics.mesh.n_elements
        self.frames: list[tuple[str, float]] = []
        self._acc = {"solve_seconds": 0.0, "reintegration_seconds": 0.0, "cut_seconds": 0.0, "cg_iterations": 0,
                     "slivers_removed": 0, "cuts_missed": 0, "cuts_skipped": 0}
        self._size = float(np.ptp(dynamics.mesh.points, axis=0).max())
        if self.events:
            dynamics.reserve_topology_buffers()

    # -- stepping --------------------------------------------------------------------------
    def _cut(self, t0: float, t1: float) -> None:
        ops = [op for ev in self.events for op in ev.operations(t0, t1)]
        if not ops:
            return
        from unmesh.fem.cutting import PlaneCut, PolygonCut

        tc = time.perf_counter()
        cutter = Cutter(self.dyn.mesh, self.snap)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", CutMissWarning)
                for op in ops:
                    if isinstance(op, PlaneCut):
                        cutter.plane(op.origin, op.normal, op.elements)
                    elif isinstance(op, PolygonCut):
                        cutter.polygon(op.polygon)
                    else:
                        op.apply(cutter)
            self._acc["cuts_missed"] += sum(issubclass(w.category, CutMissWarning) for w in caught)
            if not cutter.touched:
                return
            if self.sliver_threshold > 0:
                from unmesh.fem.slivers import remove_slivers_in

                self._acc["slivers_removed"] += remove_slivers_in(cutter, self.sliver_threshold)
            res = cutter.commit()
        except InputError as exc:
            # a degenerate cut must not corrupt the mesh: skip this step's cuts, keep running
            warnings.warn(f"t={t0:.4g} s: cuts of this step skipped: {exc}", CutSkippedWarning, stacklevel=2)
            self._acc["cuts_skipped"] += len(ops)
            return
        self.dyn.change_topology(res.mesh, res.node_weights, res.element_parent, res.changed)
        self._acc["cut_seconds"] += time.perf_counter() - tc

    def step(self) -> float:
        """Apply the cuts due in this step, then one implicit Euler step."""
        from unmesh.fem.dynamics import kernel_threads

        t0 = self.time
        with kernel_threads(self.dyn.mesh.n_nodes):
            self._cut(t0, t0 + self.dt)
        info = self.dyn.step(self.dt)
        self.time = self.dyn.time
        self._acc["solve_seconds"] += info.solve_seconds
        self._acc["reintegration_seconds"] += info.reintegration_seconds
        self._acc["cg_iterations"] += info.iterations
        return self.dt

    def check(self) -> str | None:
        """NaN or a runaway displacement stops the run."""
        d = self.dyn
        if not (np.all(np.isfinite(d.u)) and np.all(np.isfinite(d.v))):
            return "NaN in the displacements or velocities"
        if np.abs(d.u).max(initial=0.0) > 1e4 * self._size:
            return "displacements exploded (more than 10^4 object sizes)"
        return None

    # -- output ----------------------------------------------------------------------------
    def write_static(self, outdir: Path) -> list[str]:
        """``OUTDIR/mesh.pvd``, the ParaView series (empty until frame 0; :meth:`write_frame` extends it)."""
        write_pvd(Path(outdir) / "mesh.pvd", [f for f, _ in self.frames], [t for _, t in self.frames])
        return ["mesh.pvd"]

    def write_frame(self, outdir: Path, frame: int) -> list[str]:
        """``frames/mesh_NNNNN.vtu`` and ``frames/surface_NNNNN.ply``; rewrites ``mesh.pvd``.

        Returns the two frame files (relative to ``outdir``); ``mesh.pvd`` is a static file
        of the manifest (rewritten here, listing ``frames/mesh_*.vtu`` relative to itself).
        """
        from unmesh import io

        out = Path(outdir)
        d = self.dyn
        name = f"frames/mesh_{frame:05d}.vtu"
        surface = f"frames/surface_{frame:05d}.ply"
        write_vtu(out / name, d.mesh, d.u, point_data={"velocity": d.v})
        io.save(out / surface, d.mesh.surface(d.u))
        self.frames = [f for f in self.frames if f[0] != name] + [(name, float(self.time))]
        write_pvd(out / "mesh.pvd", [f for f, _ in self.frames], [t for _, t in self.frames])
        return [name, surface]

    def frame_record(self) -> dict[str, Any]:
        d = self.dyn
        rec = {"nodes": d.mesh.n_nodes, "elements": d.mesh.n_elements, "volume": d.mesh.volume(),
               "kinetic_energy": d.kinetic_energy(), "elastic_energy": d.elastic_energy(),
               "potential_energy": d.potential_energy(), "contacts": int(d.contact.sum()), **self._acc}
        self._acc = dict.fromkeys(self._acc, 0)
        self._acc["solve_seconds"] = 0.0
        self._acc["reintegration_seconds"] = 0.0
        self._acc["cut_seconds"] = 0.0
        return rec

    def summary_header(self) -> dict[str, Any]:
        d = self.dyn
        return {"nodes_initial": self.nodes_initial, "elements_initial": self.elements_initial, "dt": self.dt,
                "solver": d.solver, "warping": d.warping, "correction": d.correction}

    # -- checkpoints -------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        d = self.dyn
        m = d.mesh
        return {"time": self.time, "points": m.points, "face_nodes": m.face_nodes, "face_offsets": m.face_offsets,
                "elem_faces": m.elem_faces, "elem_signs": m.elem_signs, "elem_offsets": m.elem_offsets,
                "tolerance": m.tolerance, "abs_tolerance": m.abs_tolerance, "u": d.u, "v": d.v, "contact": d.contact,
                "groups": np.array([g for g, _ in d.groups]) if d.groups else np.zeros((0, m.n_nodes), bool),
                "loads": np.array([m for m, _ in d.loads]) if d.loads else np.zeros((0, m.n_nodes), bool),
                "young": d.young, "poisson": d.poisson, "density": d.density,
                "frame_files": [f for f, _ in self.frames], "frame_times": np.array([t for _, t in self.frames])}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        old = self.dyn
        pts = np.shape(state["points"])
        n = pts[0] if pts else 0  # cuts add nodes: the count is the checkpoint's own
        expect_shapes(state, {"points": (None, 3), "u": (n, 3), "v": (n, 3), "contact": (n,),
                              "groups": (len(old.groups), n), "loads": (len(old.loads), n)})
        mesh = PolyMesh.from_arrays(state["points"], state["face_nodes"], state["face_offsets"], state["elem_faces"],
                                    state["elem_signs"], state["elem_offsets"], tolerance=float(state["tolerance"]),
                                    abs_tolerance=float(state["abs_tolerance"]), check=False)
        groups = [(np.asarray(m, bool), p) for m, (_, p) in zip(state["groups"], old.groups, strict=True)]
        new = Dynamics(mesh, state["young"], state["poisson"], state["density"], gravity=old.gravity,
                       ground=old.ground, rayleigh=(old.alpha, old.beta), solver=old.solver, warping=old.warping,
                       correction=old.correction, cg_tol=old.cg_tol, cg_maxiter=old.cg_maxiter,
                       rule=old.rule)
        new.groups = groups
        new.loads = [(np.asarray(m, bool), ld) for m, (_, ld) in zip(state["loads"], old.loads, strict=True)]
        new.u = np.asarray(state["u"], dtype=np.float64).copy()
        new.v = np.asarray(state["v"], dtype=np.float64).copy()
        new.contact = np.asarray(state["contact"], bool).copy()
        new.time = float(state["time"])
        self.dyn = new
        self.time = new.time
        self.frames = list(zip([str(f) for f in state["frame_files"]], [float(t) for t in state["frame_times"]],
                               strict=True))
