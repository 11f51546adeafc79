"""Membrane and bending energy of a fiber-sampled shell and its exact gradient (thesis 7.2).

Plain numpy reference implementation; :mod:`unmesh.shells.forces` evaluates the same
quantities with numba kernels, and the tests compare the two. The reference
(:func:`elastic_energy`, :func:`elastic_forces_reference`) never calls the fast path: it
uses :mod:`unmesh.shells.fibers` only. :meth:`FiberState.at_rest` and
:meth:`FiberState.measure` measure with the force kernels' arithmetic (tables from
:mod:`unmesh.shells.arcs`), so a rest state has exactly zero force on the fast path too;
this module does not import :mod:`unmesh.shells.forces`, which imports it.

Definitions (per node ``i`` with fibers ``k``, ``m_i`` of them; fiber ``k`` centred at ``i``):

* fiber area ``A_k = pi/4 l~_k^2`` (7.5) and node area ``A_i = (1/m_i) sum_k A_k`` (7.6),
* membrane energy (7.7) with per-fiber stiffness scales ``sigma_k`` (7.3.4)::

      E_s,i = K_s/2 [ mean(sigma) (A_i - A_i^0)^2 + (1/m_i) sum_k sigma_k (A_k - A_k^0)^2 ]

* mean curvature ``H_i = sum_k beta_k theta_k / sum_k beta_k`` (7.9, weighted by the bending
  scales ``beta_k``) and bending energy (7.11)::

      E_b,i = K_b/2 A_i^0 mean(beta) (H_i - H_i^0)^2

These are the printed forms. With all scales 1 they are exactly (7.7) and (7.11); they only
depend on means over a node's fibers, so duplicating every fiber changes nothing (7.6:
"increasing the number of fibers per point does not increase material stiffness"). As the
thesis says (7.6, Discussion), the material depends on the sampling: with node spacing
``h`` (``A ~ h^2``, ``theta ~ kappa h``) the energy per unit area of a given strain or
curvature scales like ``h^2``, so ``K_s``, ``K_b`` describe a material only together with a
sampling density. A strain/curvature normalisation (``(A - A^0)/A^0`` integrated over
``A_i^0``, ``theta / l^0``) removes that, but changes what a given ``K_s``, ``K_b`` means (by factors ``1/A^0`` and
``1/l0^2``): on a unit sphere with 300 nodes the stable step for the F.1 values K_s = 1000,
K_b = 10000 falls from 1.74 ms to 1.11 ms, below 1.5x the F.1 step of 1 ms, so the F.1
parameters would no longer run at the F.1 time steps; it is therefore not used (see
``docs/shell_scene.md``, design notes). Rest values come from
the rest length and angle of each fiber, ``l^0 = l_orig + l_plastic``, ``theta^0 =
theta_orig + theta_plastic`` (7.19). The angles use the umbrella vector ``s_i`` of the centre node as
normal, regularised by ``topology.soft`` (:mod:`unmesh.shells.topology`). The forces are
``F = -grad E`` (7.12-7.17) including the dependence of ``s_i`` on the nodes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points
from unmesh.errors import InputError
from unmesh.shells import fibers as fb
from unmesh.shells.topology import ShellTopology

__all__ = ["FiberState", "elastic_energy", "elastic_forces_reference", "umbrella_normals"]

_FIELDS = ("length_orig", "angle_orig", "length_plastic", "angle_plastic", "stretch_scale", "bend_scale",
           "fracture_stretch", "fracture_bend")


@dataclass(frozen=True, eq=False)
class FiberState:
    """Per-fiber rest state and material, arrays of shape (F,) float64 aligned with ``topology.fibers``.

    The arrays are simulation state: plasticity (7.19-7.23) and weakening (7.25) update
    ``length_plastic``, ``angle_plastic`` and ``fracture_bend`` in place.

    Attributes
    ----------
    length_orig, angle_orig : ndarray (F,)
        Arc length ``l_orig`` and tangent angle ``theta_orig`` of the undeformed fiber.
    length_plastic, angle_plastic : ndarray (F,)
        Plastic parts (7.19).
    stretch_scale, bend_scale : ndarray (F,)
        Per-fiber factors on ``K_s`` and ``K_b`` (anisotropy / inhomogeneity, 7.3.4).
    fracture_stretch, fracture_bend : ndarray (F,)
        Fracture thresholds ``gamma_s`` (strain ``l/l^0 - 1``) and ``gamma_b`` (radians),
        ``inf`` when the fiber cannot break (7.24).

    Example
    -------
    >>> s = FiberState.uniform([1.0, 2.0], [0.0, 0.1])
    >>> s.rest_length()
    array([1., 2.])
    """

    length_orig: np.ndarray
    angle_orig: np.ndarray
    length_plastic: np.ndarray
    angle_plastic: np.ndarray
    stretch_scale: np.ndarray
    bend_scale: np.ndarray
    fracture_stretch: np.ndarray
    fracture_bend: np.ndarray

    def __post_init__(self) -> None:
        n = len(np.asarray(self.length_orig))
        for name in _FIELDS:
            finite = name not in ("fracture_stretch", "fracture_bend")
            arr = as_array(getattr(self, name), name, (None,), length=n, finite=finite)
            object.__setattr__(self, name, arr.copy())
        if np.any(self.length_orig <= 0):
            raise InputError("length_orig: expected positive fiber lengths (coincident nodes?)")
        if np.any(self.stretch_scale < 0) or np.any(self.bend_scale < 0):
            raise InputError("stretch_scale, bend_scale: expected non-negative stiffness factors")

    @classmethod
    def uniform(cls, length: Any, angle: Any, fracture_stretch: float = np.inf,
                fracture_bend: float = np.inf) -> FiberState:
        """Fibers with the given rest values, unit stiffness scales and no plastic part."""
        length = np.asarray(length, dtype=np.float64)
        zeros = np.zeros_like(length)
        return cls(length, angle, zeros, zeros, zeros + 1.0, zeros + 1.0, zeros + fracture_stretch,
                   zeros + fracture_bend)

    @classmethod
    def at_rest(cls, rest: Any, topology: ShellTopology, samples: int = fb.ARC_SAMPLES, **fields: Any) -> FiberState:
        """Rest lengths and angles measured on the node positions ``rest`` (N, 3).

        Measured with the same kernels as the forces, so the rest state has exactly zero
        energy and force. Extra keyword arrays (e.g. ``stretch_scale``) override the uniform defaults.
        """
        from unmesh.shells import _fiber_kernels
        from unmesh.shells.arcs import arc_gram

        x = as_points(rest, "rest", length=topology.n_nodes)
        f = topology.fibers
        s, normals = np.empty_like(x), np.empty_like(x)
        _fiber_kernels.umbrella(x, topology.pairs, topology.pair_offsets, s, normals)
        length, angle = np.empty(len(f)), np.empty(len(f))
        _fiber_kernels.fiber_measures(x, f, np.ascontiguousarray(s[f[:, 1]]), np.ascontiguousarray(topology.soft[f[:, 1]]),
                                arc_gram(samples), length, angle)
        state = cls.uniform(length, angle)
        return dataclasses.replace(state, **fields) if fields else state

    @staticmethod
    def measure(x: np.ndarray, topology: ShellTopology, samples: int = fb.ARC_SAMPLES,
                which: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths and tangent angles (principal branch) of the fibers ``which`` (default all)
        at node positions ``x``, with the force kernels' arithmetic."""
        from unmesh.shells import _fiber_kernels
        from unmesh.shells.arcs import arc_gram

        f = topology.fibers if which is None else np.ascontiguousarray(topology.fibers[which])
        s, normals = np.empty_like(x), np.empty_like(x)
        _fiber_kernels.umbrella(x, topology.pairs, topology.pair_offsets, s, normals)
        length, angle = np.empty(len(f)), np.empty(len(f))
        _fiber_kernels.fiber_measures(x, f, np.ascontiguousarray(s[f[:, 1]]), np.ascontiguousarray(topology.soft[f[:, 1]]),
                                arc_gram(samples), length, angle)
        return length, angle

    def __len__(self) -> int:
        return len(self.length_orig)

    def rest_length(self) -> np.ndarray:
        """``l^0 = l_orig + l_plastic`` (7.19), (F,)."""
        return self.length_orig + self.length_plastic

    def rest_angle(self) -> np.ndarray:
        """``theta^0 = theta_orig + theta_plastic`` (7.19), (F,)."""
        return self.angle_orig + self.angle_plastic

    @classmethod
    def _checked(cls, arrays: Any) -> FiberState:
        """A state from arrays taken from valid states (no validation; each array is new)."""
        state = object.__new__(cls)
        for name, arr in zip(_FIELDS, arrays, strict=True):
            object.__setattr__(state, name, np.ascontiguousarray(arr, dtype=np.float64))
        return state

    def take(self, index: Any) -> FiberState:
        """The fibers selected by ``index`` (mask or indices), as a new state."""
        return FiberState._checked(getattr(self, name)[index] for name in _FIELDS)

    @classmethod
    def concatenate(cls, states: list[FiberState]) -> FiberState:
        """Join states in order."""
        return cls._checked(np.concatenate([getattr(s, name) for s in states]) for name in _FIELDS)

    def as_dict(self) -> dict[str, np.ndarray]:
        """Arrays by field name (for checkpoints)."""
        return {name: getattr(self, name) for name in _FIELDS}


def umbrella_normals(x: np.ndarray, topology: ShellTopology) -> tuple[np.ndarray, np.ndarray]:
    """Umbrella vectors ``s_i = sum (x_a - x_i) x (x_b - x_i)`` and unit normals ``s_i/|s_i|``.

    Parameters
    ----------
    x : ndarray (N, 3) float64
    topology : ShellTopology

    Returns
    -------
    s, normals : ndarray (N, 3) float64
        Nodes without pairs get zero vectors.

    Example
    -------
    >>> t = ShellTopology.build(3, [0, 2, 2, 2], [1, 2], [[1, 2]], [0], np.zeros((0, 3)))
    >>> umbrella_normals(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), t)[1][0]
    array([0., 0., 1.])
    """
    pr, pc = topology.pairs, topology.pair_center
    s = np.zeros_like(x)
    np.add.at(s, pc, np.cross(x[pr[:, 0]] - x[pc], x[pr[:, 1]] - x[pc]))
    norm = np.linalg.norm(s, axis=1)
    normals = np.where(norm[:, None] > 0, s / np.maximum(norm, 1e-300)[:, None], 0.0)
    return s, normals


def _node_terms(x: np.ndarray, topology: ShellTopology, state: FiberState, ks: float, kb: float,
                samples: int) -> dict[str, Any]:
    f = topology.fibers
    s, normals = umbrella_normals(x, topology)
    length, dlen = fb.arc_length_gradient(x[f[:, 0]], x[f[:, 1]], x[f[:, 2]], samples)
    theta, dtheta, dnormal = fb.bending_angle_gradient(x[f[:, 0]], x[f[:, 1]], x[f[:, 2]], s[f[:, 1]],
                                                       topology.soft[f[:, 1]], fb.TANGENT_SOFTENING)
    # the branch theta + 2 pi k nearest to the rest angle (as the kernels do without a reference)
    theta = theta + 2 * np.pi * np.floor((state.rest_angle() - theta) / (2 * np.pi) + 0.5)
    n = topology.n_nodes
    c = f[:, 1]
    m = np.bincount(c, minlength=n).astype(np.float64)
    msafe = np.maximum(m, 1.0)
    area = np.pi / 4 * length**2
    area0 = np.pi / 4 * state.rest_length() ** 2
    node_area = np.bincount(c, area, n) / msafe
    node_area0 = np.bincount(c, area0, n) / msafe
    sig = state.stretch_scale
    sig_mean = np.bincount(c, sig, n) / msafe
    bsum = np.bincount(c, state.bend_scale, n)
    bsafe = np.where(bsum > 0, bsum, 1.0)
    h = np.bincount(c, state.bend_scale * theta, n) / bsafe
    h0 = np.bincount(c, state.bend_scale * state.rest_angle(), n) / bsafe
    da = node_area - node_area0
    dak = area - area0
    e_s = 0.5 * ks * (sig_mean * da**2 + np.bincount(c, sig * dak**2, n) / msafe)
    e_b = 0.5 * kb * node_area0 * (bsum / msafe) * (h - h0) ** 2
    return dict(s=s, normals=normals, length=length, dlen=dlen, theta=theta, dtheta=dtheta, dnormal=dnormal,
                m=msafe, area=area, area0=area0, dak=dak, da=da, node_area=node_area, node_area0=node_area0,
                sig_mean=sig_mean, h=h, h0=h0, e_s=e_s, e_b=e_b)


def elastic_energy(x: Any, topology: ShellTopology, state: FiberState, ks: float, kb: float,
                   samples: int = fb.ARC_SAMPLES, per_node: bool = False) -> Any:
    """Total elastic energy ``E_s + E_b`` (7.7, 7.11).

    Parameters
    ----------
    x : array_like (N, 3)
        Node positions.
    topology : ShellTopology
    state : FiberState
        Rest state aligned with ``topology.fibers``.
    ks, kb : float
        Stretching and bending stiffness ``K_s``, ``K_b``.
    samples : int
        Arc-length samples per segment (B.4).
    per_node : bool
        Return the per-node arrays ``(E_s (N,), E_b (N,))`` instead of the total.

    Returns
    -------
    float or (ndarray, ndarray)

    Example
    -------
    >>> from unmesh.shells.nodes import grid_sheet
    >>> x, topo = grid_sheet(4, 4)
    >>> state = FiberState.at_rest(x, topo)
    >>> elastic_energy(x, topo, state, 10.0, 1.0) < 1e-20   # the rest state
    True
    """
    xx = as_points(x, "x", length=topology.n_nodes)
    t = _node_terms(xx, topology, state, ks, kb, samples)
    if per_node:
        return t["e_s"], t["e_b"]
    return float(t["e_s"].sum() + t["e_b"].sum())


def elastic_forces_reference(x: Any, topology: ShellTopology, state: FiberState, ks: float, kb: float,
                             samples: int = fb.ARC_SAMPLES) -> tuple[np.ndarray, float]:
    """Elastic forces ``-grad E`` (7.12-7.17), numpy reference of :func:`unmesh.shells.forces.elastic_forces`.

    Per fiber ``k`` centred at node ``j`` (7.16, generalised to per-fiber scales)::

        dE/dA_k     = K_s/m_j [ mean(sigma) (A_j - A_j^0) + sigma_k (A_k - A_k^0) ]
        dE/dtheta_k = K_b A_j^0 beta_k / m_j (H_j - H_j^0)

    with ``grad A_k = pi/2 l~_k grad l~_k`` (7.17); ``dE/dN_j = sum_k dE/dtheta_k
    dtheta_k/dN_j`` is passed on through the umbrella normal.

    Returns
    -------
    forces : ndarray (N, 3)
    energy : float

    Example
    -------
    >>> from unmesh.shells.nodes import grid_sheet
    >>> x, topo = grid_sheet(4, 4)
    >>> state = FiberState.at_rest(x, topo)
    >>> f, e = elastic_forces_reference(x * 1.1, topo, state, 10.0, 1.0)
    >>> bool(np.allclose(f.sum(axis=0), 0.0))
    True
    """
    xx = as_points(x, "x", length=topology.n_nodes)
    t = _node_terms(xx, topology, state, ks, kb, samples)
    f = topology.fibers
    c = f[:, 1]
    m = t["m"][c]
    de_da = ks / m * (t["sig_mean"][c] * t["da"][c] + state.stretch_scale * t["dak"])
    de_dl = de_da * np.pi / 2 * t["length"]
    de_dth = kb * t["node_area0"][c] * state.bend_scale / m * (t["h"][c] - t["h0"][c])
    grad = np.zeros_like(xx)
    per_fiber = de_dl[:, None, None] * t["dlen"] + de_dth[:, None, None] * t["dtheta"]
    for r in range(3):
        np.add.at(grad, f[:, r], per_fiber[:, r])
    # through the umbrella vector s_j (the angle's normal)
    g_s = np.zeros_like(xx)
    np.add.at(g_s, c, de_dth[:, None] * t["dnormal"])
    pr, pc = topology.pairs, topology.pair_center
    ea, eb = xx[pr[:, 0]] - xx[pc], xx[pr[:, 1]] - xx[pc]
    ga, gb = np.cross(eb, g_s[pc]), np.cross(g_s[pc], ea)
    np.add.at(grad, pr[:, 0], ga)
    np.add.at(grad, pr[:, 1], gb)
    np.add.at(grad, pc, -(ga + gb))
    return -grad, float(t["e_s"].sum() + t["e_b"].sum())
