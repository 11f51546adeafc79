"""Elastic forces with an implicit rest state (thesis section 8.2) — reference math.

Plain numpy versions of every step of the per-particle lattice computation; the
fast numba versions in :mod:`unmesh.sph._elastic_kernels` are tested against them.
For a particle ``i`` with neighbours ``j`` (``r_ij = x_j − x_i``, weights
``W_ij = W(‖r_ij‖)``, poly6):

1. **Lattice assignment** (eq. 8.21, :func:`assign_slots`): each neighbour is
   mapped to the lattice point nearest to ``A_i^(t−1)⁻¹ r_ij``; when several
   neighbours claim the same lattice point only the closest keeps it.
2. **Shape matching** (eq. 8.23, :func:`shape_matching`):
   ``A_i = (Σ W r lᵀ)(Σ W l lᵀ)⁻¹`` and its rotation ``R_i = U Vᵀ`` (eq. 8.24,
   :func:`rotation_svd`, with ``det U = det V = +1`` so ``R_i`` is never a
   reflection; the last singular value carries the sign).
3. **Direct forces** (eqs. 8.29–8.31, :func:`goal_matrix`):
   ``g'_ij = U S Vᵀ l_ij`` with the volume-preserving scale
   ``S = (sΣ + (1−s)I) / det(sΣ + (1−s)I)^(1/n)`` and the pair force
   ``F_ij = K_e (m_i m_j/ρ0) W_ij (g'_ij − r_ij)``, ``+½F_ij`` on ``j`` and
   ``−½F_ij`` on ``i``. The thesis' ``F_ij = W_ij K_e (…)`` is scaled by
   ``m_i m_j/ρ0`` so that ``K_e`` is a rate (1/s²; the acceleration of a particle
   displaced by δ is about ``K_e δ``) independent of resolution, matching the
   magnitudes of Appendix F.2 (``K_e Δt² ≈ 1``).
4. **Strain forces** (section 8.2.2, :func:`displacement_gradient`): eq. (8.28)
   divides by ``Σ W (g·e_β)``, zero on a symmetric lattice (NOTES.md); we use the
   weighted least-squares gradient ``∇u = (Σ W (r−g) gᵀ)(Σ W g gᵀ)⁻¹`` with
   ``g = R l`` (eq. 8.25), which equals ``A Rᵀ − I`` — symmetric, rotation
   invariant, central differences on a regular lattice. With the linear stress
   ``σ = λ tr(ε) I + 2μ ε`` the elastic energy ``Σ V_i ½ ε:σ`` is the corotated
   linear energy, whose gradient gives the forces ``f_j = −V_i W_ij P_i M_i⁻¹ l_ij``,
   ``f_i = −Σ_j f_j`` with ``P = 2μ(A − R) + λ tr(RᵀA − I) R`` and
   ``M = Σ W l lᵀ``; they conserve linear and angular momentum by construction.
5. **Exact torque correction** (replaces eqs. 8.32–8.33, which do not cancel the
   torque, NOTES.md): the forces of neighbourhood ``i`` sum to zero but may carry a
   torque ``τ_i = Σ_k (x_k − x_i) × f_k``. Correction forces
   ``f^τ_k = w_k ω_i × (x_k − c_i)`` on the members ``k ∈ {i} ∪ N_i`` with
   ``w_k = m_k W_ik``, ``c_i = Σ w_k x_k / Σ w_k`` and ``ω_i = −I_i⁻¹ τ_i``,
   ``I_i = Σ w_k (‖y_k‖² I − y_k y_kᵀ)``, ``y_k = x_k − c_i``, add zero net force
   (``Σ w_k y_k = 0``) and exactly the torque ``−τ_i``. Total linear and angular
   momentum of the elastic forces are therefore conserved to round-off.
6. **Stored plastic deformation** (optional, :func:`plastic_flow`): a particle keeps a rest
   shape ``P`` of its lattice (``det P = 1``): its neighbours' rest offsets are ``P l``. The
   fit ``A`` of eq. (8.23) is unchanged (it maps lattice offsets to the current ones and is
   used for the assignment 8.21); the best fit to the rest offsets ``P l`` is the elastic part
   ``A_e = A P⁻¹``, which is decomposed (8.24) and gives the goals ``g' = U S Vᵀ P l``
   (8.29–8.30) and the strain forces (``M⁻¹`` becomes ``P⁻ᵀ M⁻¹``). Beyond the yield strain
   the rest shape creeps towards the current shape (the thesis' yield and creep rule for
   shells, eqs. 7.20–7.22, applied to the lattice; section 8.2.5 names stored plastic strain as
   an addition to the inherent plasticity).
7. **Few members** (not in the thesis): a neighbourhood of a freezing material with fewer than ``FIT_MEMBERS_PER_DIM * dim``
   members (3D: 6 of 12) fits a rotation only: its transformation and goal are ``R = U Vᵀ`` of the fit,
   ``g' = R l``, with no strain stress and no plastic flow. A few members on one side of a particle
   (surface ice) do not determine a stretch: their fit is squashed (singular values like 2.7, 1.7, 0.22),
   its next assignment rounds neighbours to wrong slots and its forces ring.

Example
-------
>>> import numpy as np
>>> from unmesh.sph.sampling import lattice_slots
>>> vecs, _, _ = lattice_slots(2, 2.0)
>>> l = 0.1 * vecs                       # lattice offsets, d = 0.1
>>> q = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])   # any rotation
>>> r = l @ q.T                           # undeformed, rotated lattice
>>> w = np.ones(len(l))
>>> fi, fj = neighbourhood_forces(np.zeros(3), r, l, w, 1.0, 1.0, np.ones(len(l)),
...                               ElasticParams(dim=2, stiffness=1e4))
>>> float(np.abs(fj).max()) < 1e-9
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array
from unmesh.errors import InputError
from unmesh.sph.sampling import nearest_lattice_point

__all__ = [
    "ElasticParams",
    "assign_slots",
    "displacement_gradient",
    "goal_matrix",
    "lame_parameters",
    "linear_stress",
    "neighbourhood_forces",
    "plastic_flow",
    "rotation_svd",
    "shape_matching",
    "torque_correction",
]

#: Singular values are clamped to at least this when forming goal positions (inverted lattices).
SIGMA_FLOOR = 0.05
#: Fewer members than ``FIT_MEMBERS_PER_DIM * dim``: only the rotation of the fit (item 7 of the module docstring).
FIT_MEMBERS_PER_DIM = 2


@dataclass(frozen=True)
class ElasticParams:
    """Parameters of the elastic lattice forces of one material.

    Parameters
    ----------
    dim : int
        2 or 3.
    stiffness : float
        ``K_e`` of the direct force estimate (eq. 8.31), in 1/s² (0 disables).
    goal_deformation : float
        ``s`` of eq. (8.30) in [0, 1]: 0 pulls to the rigid rest state, 1 to the
        fitted deformed lattice (volume preserved either way).
    mu, lam : float
        Lamé parameters of the strain-based forces (Pa; 0 disables), see
        :func:`lame_parameters`.
    rest_density : float
        ``ρ0`` (particle rest volume ``m/ρ0``).
    plastic_yield, plastic_creep : float
        Yield strain ``β`` and creep rate ``α`` (1/s) of the stored plastic deformation
        (:func:`plastic_flow`; ``β = inf``: none).
    few_member_rotation : bool
        Item 7 of the module docstring (materials that freeze, ``freeze_rate > 0``).

    Example
    -------
    >>> mu, lam = lame_parameters(1000.0, 0.3)
    >>> ElasticParams(dim=3, stiffness=1e5, mu=mu, lam=lam).goal_deformation
    0.5
    """

    dim: int
    stiffness: float = 0.0
    goal_deformation: float = 0.5
    mu: float = 0.0
    lam: float = 0.0
    rest_density: float = 1.0
    plastic_yield: float = float("inf")
    plastic_creep: float = float("inf")
    few_member_rotation: bool = False

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise InputError(f"dim: expected 2 or 3, got {self.dim!r}")
        if not 0.0 <= self.goal_deformation <= 1.0:
            raise InputError(f"goal_deformation: expected a number in [0, 1], got {self.goal_deformation}")
        for name in ("stiffness", "mu", "lam", "plastic_yield", "plastic_creep"):
            if not getattr(self, name) >= 0.0:
                raise InputError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        if not self.rest_density > 0.0:
            raise InputError(f"rest_density: expected a positive number, got {self.rest_density}")


def lame_parameters(young: float, poisson: float) -> tuple[float, float]:
    """Lamé parameters ``(μ, λ)`` from Young's modulus and Poisson ratio.

    ``μ = Y / (2(1+ν))``, ``λ = Yν / ((1+ν)(1−2ν))`` (3D; plane strain in 2D).

    Example
    -------
    >>> lame_parameters(2.5, 0.25)
    (1.0, 1.0)
    """
    if not young >= 0.0:
        raise InputError(f"young: expected a number >= 0, got {young}")
    if not -1.0 < poisson < 0.5:
        raise InputError(f"poisson: expected a Poisson ratio in (-1, 0.5), got {poisson}")
    return young / (2.0 * (1.0 + poisson)), young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))


def rotation_svd(a: Any, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SVD ``A = U diag(σ) Vᵀ`` with proper rotations ``U, V`` (eq. 8.24).

    In 2D only the upper-left 2×2 block is decomposed and the z row/column of
    ``U`` and ``V`` is the identity (``σ_z = 1``). If ``det A < 0`` the smallest
    singular value is negative, so ``R = U Vᵀ`` is always a rotation.

    Parameters
    ----------
    a : array_like, shape (3, 3)
    dim : int

    Returns
    -------
    u : ndarray (3, 3), sigma : ndarray (3,), v : ndarray (3, 3)

    Example
    -------
    >>> u, s, v = rotation_svd(np.diag([2.0, -1.0, 1.0]), 2)
    >>> np.round(s, 12).tolist(), round(float(np.linalg.det(u @ v.T)), 12)
    ([2.0, -1.0, 1.0], 1.0)
    """
    m = as_array(a, "a", (3, 3))
    n = 2 if dim == 2 else 3
    u = np.eye(3)
    v = np.eye(3)
    s = np.ones(3)
    uu, ss, vt = np.linalg.svd(m[:n, :n])
    vv = vt.T.copy()
    if np.linalg.det(uu) < 0:
        uu[:, -1] *= -1.0
        ss[-1] *= -1.0
    if np.linalg.det(vv) < 0:
        vv[:, -1] *= -1.0
        ss[-1] *= -1.0
    u[:n, :n] = uu
    v[:n, :n] = vv
    s[:n] = ss
    return u, s, v


def goal_matrix(u: np.ndarray, sigma: np.ndarray, v: np.ndarray, s: float, dim: int) -> np.ndarray:
    """``U S Vᵀ`` with the volume-preserving scale matrix ``S`` of eq. (8.30).

    ``S = (sΣ + (1−s)I) / det(sΣ + (1−s)I)^(1/n)``; singular values are clamped to
    at least :data:`SIGMA_FLOOR` first (an inverted lattice is pulled back).

    Example
    -------
    >>> g = goal_matrix(np.eye(3), np.array([2.0, 0.5, 1.0]), np.eye(3), 1.0, 2)
    >>> np.round(np.diag(g), 12).tolist()   # area preserved: 2 * 0.5 = 1
    [2.0, 0.5, 1.0]
    """
    n = 2 if dim == 2 else 3
    sig = np.maximum(np.asarray(sigma, dtype=np.float64)[:n], SIGMA_FLOOR)
    d = s * sig + (1.0 - s)
    d = d / np.prod(d) ** (1.0 / n)
    full = np.ones(3)
    full[:n] = d
    return u @ np.diag(full) @ v.T


def assign_slots(r: Any, a_inv: Any, slot_coords: np.ndarray, spacing: float, dim: int) -> np.ndarray:
    """Lattice assignment of eq. (8.21) with conflict resolution.

    Parameters
    ----------
    r : array_like, shape (K, 3)
        Offsets ``r_ij = x_j − x_i`` of the candidate neighbours.
    a_inv : array_like, shape (3, 3)
        Inverse of the previous lattice transformation ``A_i^(t−1)`` (maps world
        offsets to lattice-frame offsets in length units).
    slot_coords : ndarray, shape (Q, 3), int64
        Integer coordinates of the slots (:func:`unmesh.sph.sampling.lattice_slots`).
    spacing : float
        Lattice spacing ``d``.
    dim : int

    Returns
    -------
    ndarray, shape (K,), int64
        Slot index per neighbour, or -1 (no slot, or lost a conflict to a closer neighbour).

    Example
    -------
    >>> from unmesh.sph.sampling import lattice_slots
    >>> _, coords, _ = lattice_slots(2, 2.0)
    >>> assign_slots([[0.1, 0, 0], [0.11, 0, 0]], np.eye(3), coords, 0.1, 2).tolist()
    [5, -1]
    """
    rr = as_array(r, "r", (None, 3))
    y = rr @ as_array(a_inv, "a_inv", (3, 3)).T / spacing
    coords, d2 = nearest_lattice_point(y, dim)
    lookup = {tuple(c): q for q, c in enumerate(np.asarray(slot_coords).tolist())}
    slot = np.array([lookup.get(tuple(c), -1) for c in coords.tolist()], dtype=np.int64)
    best: dict[int, int] = {}
    for k, q in enumerate(slot.tolist()):
        if q < 0:
            continue
        if q not in best or d2[k] < d2[best[q]]:
            best[q] = k
    out = np.full(len(rr), -1, np.int64)
    for q, k in best.items():
        out[k] = q
    return out


def shape_matching(r: Any, l: Any, w: Any, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Best-fit lattice transformation of eq. (8.23).

    Parameters
    ----------
    r : array_like, shape (K, 3)
        Neighbour offsets ``r_ij``.
    l : array_like, shape (K, 3)
        Assigned lattice offsets ``l_ij`` (lattice frame, length units).
    w : array_like, shape (K,)
        Weights ``W_ij``.
    dim : int

    Returns
    -------
    a : ndarray (3, 3)
        ``A = (Σ W r lᵀ)(Σ W l lᵀ)⁻¹`` (z block identity in 2D).
    m : ndarray (3, 3)
        ``M = Σ W l lᵀ`` (z block identity in 2D).

    Example
    -------
    >>> l = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    >>> a, _ = shape_matching(2 * l, l, np.ones(4), 2)
    >>> np.round(a, 12).tolist()
    [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]
    """
    rr = as_array(r, "r", (None, 3))
    ll = as_array(l, "l", (None, 3), length=len(rr))
    ww = as_array(w, "w", (None,), length=len(rr))
    n = 2 if dim == 2 else 3
    m = _lattice_moment(ll, ww, n)
    return _shape_matrix(rr, ll, ww, n, m), m


def _lattice_moment(l: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """``M = Σ W l lᵀ`` of eq. (8.23) over the first ``n`` coordinates (the rest of the 3×3 identity)."""
    m = np.eye(3)
    m[:n, :n] = (w[:, None, None] * l[:, :n, None] * l[:, None, :n]).sum(axis=0)
    return m


def _shape_matrix(r: np.ndarray, l: np.ndarray, w: np.ndarray, n: int, m: np.ndarray) -> np.ndarray:
    """``A = (Σ W r lᵀ) M⁻¹`` of eq. (8.23) for the moment ``m`` (:func:`_lattice_moment`)."""
    b = np.eye(3)
    b[:n, :n] = (w[:, None, None] * r[:, :n, None] * l[:, None, :n]).sum(axis=0)
    return b @ np.linalg.inv(m)


def displacement_gradient(r: Any, g: Any, w: Any, dim: int) -> np.ndarray:
    """Weighted least-squares displacement gradient (replaces eq. 8.28, NOTES.md).

    ``∇u = (Σ_j W_ij (r_ij − g_ij) g_ijᵀ)(Σ_j W_ij g_ij g_ijᵀ)⁻¹`` — central
    differences on a regular lattice; equals ``A Rᵀ − I`` for ``g = R l``.

    Example
    -------
    >>> g = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    >>> r = g @ np.array([[1.1, 0, 0], [0, 1, 0], [0, 0, 1]]).T
    >>> np.round(displacement_gradient(r, g, np.ones(4), 2)[:2, :2], 12).tolist()
    [[0.1, 0.0], [0.0, 0.0]]
    """
    rr = as_array(r, "r", (None, 3))
    gg = as_array(g, "g", (None, 3), length=len(rr))
    ww = as_array(w, "w", (None,), length=len(rr))
    n = 2 if dim == 2 else 3
    out = np.zeros((3, 3))
    lhs = ((ww[:, None] * (rr - gg))[:, :n, None] * gg[:, None, :n]).sum(axis=0)
    rhs = ((ww[:, None] * gg)[:, :n, None] * gg[:, None, :n]).sum(axis=0)
    out[:n, :n] = lhs @ np.linalg.inv(rhs)
    return out


def linear_stress(grad_u: Any, mu: float, lam: float, dim: int) -> np.ndarray:
    """Cauchy strain (8.26) and linear-elastic stress ``σ = λ tr(ε) I + 2μ ε``.

    Example
    -------
    >>> float(linear_stress(np.diag([0.1, 0.0, 0.0]), 1.0, 0.0, 3)[0, 0])
    0.2
    """
    gu = as_array(grad_u, "grad_u", (3, 3))
    n = 2 if dim == 2 else 3
    eps = 0.5 * (gu + gu.T)
    eps[n:, :] = 0.0
    eps[:, n:] = 0.0
    sig = 2.0 * mu * eps
    sig[np.arange(n), np.arange(n)] += lam * np.trace(eps)
    return sig


def torque_correction(x: np.ndarray, f: np.ndarray, w: np.ndarray, dim: int) -> np.ndarray:
    """Correction forces that remove the torque of ``f`` about the members' centroid.

    Parameters
    ----------
    x : ndarray, shape (K, 3)
        Member positions (the centre particle and its neighbours).
    f : ndarray, shape (K, 3)
        Forces on the members (summing to zero).
    w : ndarray, shape (K,)
        Positive distribution weights ``w_k = m_k W_ik``.
    dim : int

    Returns
    -------
    ndarray, shape (K, 3)
        ``w_k ω × (x_k − c)`` with ``ω = −I⁻¹ τ``: zero net force, torque ``−τ``.

    Example
    -------
    >>> x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> f = np.array([[0.0, 0, 0], [0, 1, 0], [0, -1, 0]])
    >>> fc = torque_correction(x, f, np.ones(3), 2)
    >>> t = np.cross(x, f + fc).sum(axis=0)
    >>> bool(np.allclose(t, 0) and np.allclose((f + fc).sum(axis=0), 0))
    True
    """
    c = (w[:, None] * x).sum(axis=0) / w.sum()
    y = x - c
    tau = np.cross(y, f).sum(axis=0)
    if dim == 2:
        izz = float(np.sum(w * (y[:, 0] ** 2 + y[:, 1] ** 2)))
        omega = np.array([0.0, 0.0, -tau[2] / izz])
    else:
        inertia = np.einsum("k,kab->ab", w, np.einsum("ki,ki->k", y, y)[:, None, None] * np.eye(3)
                            - y[:, :, None] * y[:, None, :])
        omega = -np.linalg.solve(inertia, tau)
    return w[:, None] * np.cross(omega[None, :], y)


def plastic_flow(a: Any, p: Any, params: ElasticParams, dt: float) -> np.ndarray:
    """One step of the stored plastic deformation ``P`` (module docstring, item 6).

    With the elastic part ``A_e = A P⁻¹ = U Σ Vᵀ``, its isochoric right stretch
    ``Ŷ = V Σ Vᵀ / det(Σ)^(1/n)`` and ``ε = ‖Ŷ − I‖_F``: if ``ε > β`` (yield),
    ``P ← (I + c (Ŷ − I)) P`` with ``c = min(1, α Δt)(1 − β/ε)`` (the rule 7.20–7.22 of the
    thesis; ``c = 1 − β/ε`` returns the stretch to about the yield surface), normalised to ``det P = 1``.

    Parameters
    ----------
    a : array_like, shape (3, 3)
        Fitted lattice transformation ``A`` of eq. (8.23).
    p : array_like, shape (3, 3)
        Current plastic deformation (z row and column identity in 2D).
    params : ElasticParams
    dt : float

    Returns
    -------
    ndarray, shape (3, 3)

    Example
    -------
    >>> par = ElasticParams(dim=2, stiffness=1.0, plastic_yield=0.1)
    >>> p = plastic_flow(np.diag([1.5, 1 / 1.5, 1.0]), np.eye(3), par, 1e-3)   # sheared far beyond yield
    >>> e = np.diag([1.5, 1 / 1.5, 1.0]) @ np.linalg.inv(p) - np.eye(3)
    >>> round(float(np.linalg.norm(e[:2, :2])), 2), round(float(np.linalg.det(p)), 12)
    (0.1, 1.0)
    """
    aa = as_array(a, "a", (3, 3))
    pp = as_array(p, "p", (3, 3))
    n = 2 if params.dim == 2 else 3
    _, sig, v = rotation_svd(aa @ np.linalg.inv(pp), params.dim)
    sig = np.maximum(sig, SIGMA_FLOOR)
    y = v @ np.diag(sig) @ v.T
    y[:n, :n] /= np.prod(sig[:n]) ** (1.0 / n)
    dev = y[:n, :n] - np.eye(n)
    eps = float(np.linalg.norm(dev))
    if not eps > params.plastic_yield:
        return pp.copy()
    c = min(1.0, params.plastic_creep * dt) * (1.0 - params.plastic_yield / eps)
    out = pp.copy()
    out[:n, :] = (np.eye(n) + c * dev) @ pp[:n, :]
    out[:n, :n] /= np.linalg.det(out[:n, :n]) ** (1.0 / n)
    return out


def neighbourhood_forces(xi: Any, r: Any, l: Any, w: Any, w_self: float, mi: float, mj: Any,
                         params: ElasticParams, plastic: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Forces that the neighbourhood of particle ``i`` exerts on its members.

    Direct forces (8.29–8.31) plus strain forces (section 8.2.2) plus the exact
    torque correction (module docstring). Only assigned (docked) neighbours are passed.

    Parameters
    ----------
    xi : array_like, shape (3,)
        Position of the centre particle.
    r : array_like, shape (K, 3)
        Offsets ``r_ij`` of the assigned neighbours.
    l : array_like, shape (K, 3)
        Their lattice offsets (lattice frame, length units).
    w : array_like, shape (K,)
        Kernel weights ``W_ij``.
    w_self : float
        ``W(0)`` (weight of the centre in the torque correction).
    mi : float
        Mass of the centre particle.
    mj : array_like, shape (K,)
        Neighbour masses.
    params : ElasticParams
    plastic : array_like, shape (3, 3), optional
        Stored plastic deformation ``P`` (rest offsets ``P l``, item 6 of the module docstring).

    Returns
    -------
    fi : ndarray (3,)
        Force on the centre particle.
    fj : ndarray (K, 3)
        Forces on the neighbours. ``fi + Σ fj = 0`` and the torque vanishes.
        All zero when the assigned lattice offsets do not span the space.

    Example
    -------
    >>> from unmesh.sph.sampling import lattice_slots
    >>> l = 0.1 * lattice_slots(2, 2.0)[0]
    >>> r = 1.05 * l                                   # stretched by 5 %
    >>> fi, fj = neighbourhood_forces(np.zeros(3), r, l, np.ones(len(l)), 1.0, 1.0, np.ones(len(l)),
    ...                               ElasticParams(dim=2, stiffness=1e4))
    >>> bool(np.all(np.einsum("ij,ij->i", fj, r) < 0)), bool(np.allclose(fi + fj.sum(axis=0), 0))
    (True, True)
    """
    x0 = as_array(xi, "xi", (3,))
    rr = as_array(r, "r", (None, 3))
    ll = as_array(l, "l", (None, 3), length=len(rr))
    ww = as_array(w, "w", (None,), length=len(rr))
    mm = as_array(mj, "mj", (None,), length=len(rr))
    dim = params.dim
    n = 2 if dim == 2 else 3
    fj = np.zeros_like(rr)
    if len(rr) < n:
        return np.zeros(3), fj
    m = _lattice_moment(ll, ww, n)
    scale = np.trace(m[:n, :n]) / n
    if not np.linalg.det(m[:n, :n]) > 1e-6 * scale**n:  # e.g. a flat neighbourhood in 3D: no A exists
        return np.zeros(3), fj
    a = _shape_matrix(rr, ll, ww, n, m)
    pl = np.eye(3) if plastic is None else as_array(plastic, "plastic", (3, 3))
    if params.few_member_rotation and len(rr) < FIT_MEMBERS_PER_DIM * n:  # too few members for a stretch: the rotation alone (item 7)
        u, sig, v = rotation_svd(a, dim)
        a = u @ v.T
        pl = np.eye(3)
    pinv = np.linalg.inv(pl)
    a = a @ pinv                                  # the elastic part A_e = A P⁻¹
    u, sig, v = rotation_svd(a, dim)
    rot = u @ v.T
    if params.stiffness > 0.0:
        g = goal_matrix(u, sig, v, params.goal_deformation, dim) @ pl
        pair = params.stiffness * (mi * mm / params.rest_density)[:, None] * ww[:, None] * (ll @ g.T - rr)
        fj += 0.5 * pair
    if params.mu > 0.0 or params.lam > 0.0:
        p = 2.0 * params.mu * (a - rot) + params.lam * (np.trace((rot.T @ a)[:n, :n]) - n) * rot
        p[n:, :] = 0.0
        p[:, n:] = 0.0
        b = (mi / params.rest_density) * p @ pinv.T @ np.linalg.inv(m)
        b[n:, :] = 0.0
        fj -= ww[:, None] * (ll @ b.T)
    fi = -fj.sum(axis=0)
    xs = np.vstack([x0[None, :], x0[None, :] + rr])
    fs = np.vstack([fi[None, :], fj])
    ws = np.concatenate([[mi * w_self], mm * ww])
    fs = fs + torque_correction(xs, fs, ws, dim)
    return fs[0], fs[1:]

