"""One shell time step in one kernel call (thesis 7.2.2, 7.3): the fast path of ``ShellSimulation.step``.

:class:`FusedStep` gathers, once, everything of a :class:`~unmesh.shells.ShellSimulation`
that does not change from step to step (masses, kinematic nodes, colliders, plasticity
parameters, the topology's offsets and scratch buffers) and then runs each step with
:func:`unmesh.shells._step_kernels.shell_step`: velocity Verlet (7.18), elastic forces
(7.16), external forces, kinematic nodes, colliders, crumbs, plasticity (7.19-7.23, 7.25)
and the fracture test (7.24). Only what depends on time is evaluated in Python per step
(handle offsets, the pressure value, pulls). The result is that of
:meth:`ShellSimulation.step_plain` up to round-off (``tests/shells/test_step_kernel.py``);
the rare fracture events themselves are handled by the simulation in Python.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh._threads import threads_for
from unmesh.shells import _step_kernels
from unmesh.shells.dynamics import PlaneCollider, SphereCollider
from unmesh.shells.forces import FORCE_CHUNKS, ForceResult, arc_gram

__all__ = ["FusedStep"]


def _colliders(colliders: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """Collider kinds and parameters for the kernel; None when one is of another type."""
    kinds = np.zeros(len(colliders), dtype=np.int64)
    data = np.zeros((len(colliders), 8))
    for k, c in enumerate(colliders):
        if type(c) is PlaneCollider:
            kinds[k] = _step_kernels.PLANE
            data[k, :3], data[k, 3:6] = c.point, c.normal
        elif type(c) is SphereCollider:
            kinds[k] = _step_kernels.SPHERE
            data[k, :3], data[k, 3] = c.center, c.radius
        else:
            return None
        data[k, 6], data[k, 7] = c.restitution, c.friction
    return kinds, data


class FusedStep:
    """Per-simulation constants of the one-kernel step, and the step itself.

    Parameters
    ----------
    sim : ShellSimulation
    degenerate : float
        Squared end/centre tangent ratio of a degenerate fiber (with fracture; see
        ``ShellSimulation._drop_degenerate``).

    Attributes
    ----------
    supported : bool
        False when the simulation has a collider the kernel does not know (then
        ``ShellSimulation.step`` takes the plain path).
    """

    def __init__(self, sim: Any, degenerate: float) -> None:
        self.degenerate = float(degenerate)
        n = len(sim.rest)
        cols = _colliders(sim.colliders)
        self.supported = cols is not None
        self.col_type, self.col_data = cols if cols is not None else (np.zeros(0, np.int64), np.zeros((0, 8)))
        # -2 free, -1 pinned at rest, h moved by handle h (the last handle listing a node wins)
        kin = np.full(n, -2, dtype=np.int64)
        kin[sim.fixed] = -1
        for h, handle in enumerate(sim.handles):
            kin[handle.nodes] = h
        self.kin_handle = kin
        self.hdisp = np.zeros((max(len(sim.handles), 1), 3))
        self.hvel = np.zeros_like(self.hdisp)
        p = sim.material.plasticity
        flags = (1 if p.creep_stretch > 0 and math.isfinite(p.yield_stretch) else 0) | (
            2 if p.creep_bend > 0 and math.isfinite(p.yield_bend) else 0)
        self.plastic = np.array([p.creep_stretch, p.creep_bend, p.yield_stretch, p.yield_bend, p.weakening, flags],
                                dtype=np.float64)
        self.gram = arc_gram(int(sim.material.arc_samples))
        self.fractures = sim.material.fractures
        self.buf = np.empty((FORCE_CHUNKS, n, 3))
        self.x_force = np.empty((n, 3))     # positions of the last force pass
        self.no_extra = np.zeros((0, 3))
        self._topology: Any = None

    def _derive(self, sim: Any) -> None:
        """Offsets, counts and (for pressure) rest fan sizes of the current topology."""
        t = sim.topology
        self._topology = t
        self.pstart = t.pair_offsets[:-1]
        self.pcount = np.diff(t.pair_offsets)
        self.fstart = t.fiber_offsets[:-1]
        self.fcount = np.diff(t.fiber_offsets)
        self.cap = int(self.fcount.max()) if len(self.fcount) else 0
        self.fan0 = sim._fan0_of_topology() if sim.pressure is not None else np.zeros(0)

    def step(self, sim: Any) -> tuple[int, int]:
        """Advance ``sim`` by one step in place; returns (fibers over a threshold, degenerate fibers)."""
        if sim.topology is not self._topology:
            self._derive(sim)
        t = sim.time + sim.dt
        for h, handle in enumerate(sim.handles):
            self.hdisp[h] = handle.displacement(t)
            self.hvel[h] = handle.current_velocity(t)
        pressure = sim.pressure.value(t, sim.first_crack) if sim.pressure is not None else 0.0
        extra = self.no_extra
        if sim.pulls:
            extra = np.zeros_like(sim.x)
            for p in sim.pulls:
                extra += p.force(t, sim.x, sim.v, sim.mass, sim.area, None, sim.first_crack)
        ref = sim._reference_angles()
        topo, st = sim.topology, sim.fibers
        n, nf = len(sim.x), len(topo.fibers)
        forces, s, normals = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
        lengths, angles = np.empty(nf), np.empty(nf)
        node, es, eb = np.empty((n, 4)), np.empty(n), np.empty(n)
        m = sim.material
        fractures = self.fractures
        crumbs, anchors = sim._crumbs
        with threads_for(nf, key="step"):
            over, bad, _ = _step_kernels.shell_step(
                FORCE_CHUNKS, sim.dt, sim.x, sim.v, sim.acc, sim.rest, sim.mass, sim.area, self.kin_handle,
                self.hdisp, self.hvel, topo.pairs, self.pstart, self.pcount, topo.soft, topo.fibers, self.fstart,
                self.fcount, self.cap, st.length_orig, st.length_plastic, st.angle_orig, st.angle_plastic,
                st.stretch_scale, st.bend_scale, st.fracture_stretch, st.fracture_bend, m.ks, m.kb, self.gram, ref,
                sim.node_offsets, sim.gravity.g, m.damping, pressure, self.fan0, extra, self.col_type,
                self.col_data, crumbs, anchors, self.plastic, self.degenerate if fractures else 0.0,
                fractures, self.buf, forces, lengths, angles, s, normals, node, es, eb, self.x_force)
        sim.time = t
        sim._x_force = self.x_force
        sim._last = ForceResult(forces, es, eb, lengths, angles, normals, s, node)
        sim._last_topology = topo
        return int(over), int(bad)
