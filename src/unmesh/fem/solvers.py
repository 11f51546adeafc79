"""Linear solvers of the implicit Euler step (9.1.4), chosen for these problem sizes.

All solve ``A v = b`` with ``A = c_m M + c_k K'`` (warped stiffness, 3×3 blocks)
and per-node constraints (fixed, or normal-constrained ground contact):

- ``"cg"``: filtered PCG with a block-Jacobi preconditioner, warm-started from the
  last velocity. No setup; fine for small or soft meshes, slow for stiff ones.
- ``"auto"`` (default): ``"cg"``; if a solve does not converge in 150 iterations the
  system is too stiff for it and the dynamics switch to ``"lu-pcg"`` for good.
- ``"lu-pcg"``: filtered PCG warm-started from the last velocity, preconditioned by a
  *lagged, warped* sparse LU factorisation. The matrix ``A_f`` of the step it is made in
  (warped stiffness, the rotations of that step), with the constraints of the last step's
  contact set eliminated (``S A_f S + I - S``, S the constraint projection), is factorised
  (SuperLU in METIS nested-dissection order of the node graph, :func:`nested_dissection`,
  3×3 blocks kept together; SuperLU's own order when ``pymetis`` is missing; single
  precision after symmetric Jacobi scaling, :class:`unmesh.fem.factor.Factorization`)
  and reused for later steps as ``Q A_f⁻¹ Qᵀ`` with Q the best-fit rotation of each
  connected piece from the positions ``A_f`` was taken at to the current ones
  (:func:`unmesh.fem.rotations.piece_rotations`), so rigidly rotated pieces are
  preconditioned exactly (one rotation per piece: a per-node rotation would map the
  translations out of the near-null space of ``Q A_f Qᵀ``).

  It is refactorised after a change of the step size, when a cut separates a new piece,
  or when a solve needed more than ``refactor_iterations`` iterations; with cuts since the
  last factorisation, also when the touched part exceeds ``touched_fraction`` (10%) of the
  nodes or a solve needs more than 1.5 ``refactor_iterations``; and when the nodes whose
  constraint differs from the factorised one, with their ``LOCAL_RINGS`` layers, exceed
  ``touched_fraction``. A solve that has not converged after 200 iterations
  with a lagged factorisation is restarted with a fresh one
  (:data:`unmesh.fem.dynamics.LAGGED_ITERATIONS`). Refactorisations may run in a
  background thread (:meth:`LaggedLU.wants_background`, ``background=True``).

  A cut does not refactorise: the old factorisation is mapped to the new nodes through the
  cut's node weights W (new state = W old state), and a *local set* gets an exact solve of
  its block ``A_tt`` of the current (filtered) matrix: the nodes the cut touched (new,
  duplicated, re-integrated) plus ``TOUCHED_RINGS`` (1) layers, the constrained nodes plus
  ``CONSTRAINED_RINGS`` (1) layers, and the nodes whose constraint differs from the
  factorised one plus ``LOCAL_RINGS`` (3) layers. The two are combined as a symmetric
  multiplicative Schwarz preconditioner, ``z₁ = A_tt⁻¹ r_t``,
  ``z₂ = z₁ + Q W A_f⁻¹ Wᵀ Qᵀ (r - A z₁)``, ``z = z₂ + A_tt⁻¹ (r - A z₂)_t``.
- ``"direct"``: exact sparse LU of the constrained system in every step.

The measurements behind these choices, and the alternatives tried and rejected (AMG,
ILU, CHOLMOD, other orderings and thresholds), are in ``docs/performance.md``.

The rounds of the contact active-set iteration (:mod:`unmesh.fem.dynamics`) are solved
to a relative residual of 10⁻³ and the final active set is confirmed by a solve to
``cg_tol``; the local factorisation of a round is reused by later rounds with the same
active set, and the confirming solve of an unchanged set continues the PCG of the loose
one (:class:`PCG`) instead of restarting from its solution.

Example
-------
>>> from unmesh.fem import hex_grid
>>> from unmesh.fem.dynamics import Dynamics
>>> sim = Dynamics(hex_grid((4, 4, 4)), 1e3, 0.3, solver="lu-pcg")
>>> info = sim.step(0.01)
>>> info.iterations < 10
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from unmesh.errors import InputError
from unmesh.fem import _solve_kernels as SK
from unmesh.fem.factor import Factorization, Job, _local_factor, block_csr, nested_dissection
from unmesh.fem.krylov import PCG, pcg
from unmesh.fem.rotations import polar_rotations

__all__ = ["LOCAL_RINGS", "PCG", "SOLVERS", "LaggedLU", "block_csr", "direct_solve", "grow", "nested_dissection",
           "pcg"]

SOLVERS = ("auto", "lu-pcg", "cg", "direct")
#: Layers of neighbours added, for the local solve, around nodes whose constraint differs from the factorised one.
LOCAL_RINGS = 3
#: Layers of neighbours added around the other constrained nodes.
CONSTRAINED_RINGS = 1
#: Layers of neighbours added around the nodes touched by cuts.
TOUCHED_RINGS = 1
#: A background refactorisation starts when the touched (or mismatched) nodes exceed this share of ``touched_fraction``.
BACKGROUND_SHARE = 0.25
#: ... or when a solve needed more than this many iterations.
BACKGROUND_ITERATIONS = 15
#: Steps after its start at which a background factorisation is installed.
BACKGROUND_LEAD = 2
#: A single-precision factorisation whose solve of a random right-hand side leaves a larger relative
#: residual is redone in double precision (bunny benchmark: 4-5e-5 normally, 20-220 after slivers).
SINGLE_RESIDUAL = 1e-3


def grow(indptr: np.ndarray, indices: np.ndarray, mask: np.ndarray, rings: int, *, fast: bool = True) -> np.ndarray:
    """``mask`` (n,) bool grown by ``rings`` layers of neighbours in the (symmetric) block pattern.

    ``fast``: the numba kernel, which visits only the marked rows (the preconditioner grows
    masks of a few % of the nodes five times per setup); ``fast=False`` is the numpy reference.

    Example
    -------
    >>> import numpy as np
    >>> grow(np.array([0, 2, 5, 7]), np.array([0, 1, 0, 1, 2, 1, 2]), np.array([True, False, False]), 1).tolist()
    [True, True, False]
    """
    if fast:
        return SK.grow_mask(np.asarray(indptr, np.int64), np.asarray(indices, np.int64), np.asarray(mask, bool),
                            int(rings))
    out = np.asarray(mask, bool).copy()
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    for _ in range(rings):
        out[indices[out[rows]]] = True
    return out


def direct_solve(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, b: np.ndarray, x0: np.ndarray,
                 kind: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Exact solve of the constrained system by sparse LU on the free directions.

    Example
    -------
    >>> import numpy as np
    >>> eye = np.eye(3).ravel()[None]
    >>> direct_solve(np.array([0, 1]), np.array([0]), 4 * eye, np.ones((1, 3)), np.zeros((1, 3)),
    ...              np.zeros(1, np.int64), np.array([0.0, 1.0, 0.0])).tolist()
    [[0.25, 0.25, 0.25]]
    """
    from scipy.sparse.linalg import spsolve

    n = len(indptr) - 1
    mat = block_csr(indptr, indices, blocks)
    t1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    rows, cols, vals = [], [], []
    free = np.flatnonzero(kind == 0)
    for k in range(3):
        rows.append(3 * free + k)
        cols.append(np.arange(len(free)) * 3 + k)
        vals.append(np.ones(len(free)))
    col = 3 * len(free)
    cont = np.flatnonzero(kind == 2)
    for j, t in enumerate((t1, t2)):
        for k in range(3):
            rows.append(3 * cont + k)
            cols.append(col + np.arange(len(cont)) * 2 + j)
            vals.append(np.full(len(cont), t[k]))
    col += 2 * len(cont)
    P = sp.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, col))
    r = b.ravel() - mat @ x0.ravel()
    Ar = (P.T @ mat @ P).tocsc()
    y = spsolve(Ar, P.T @ r, permc_spec="MMD_AT_PLUS_A")
    return (x0.ravel() + P @ np.atleast_1d(y)).reshape(n, 3)


@dataclass
class _Pending:
    """A factorisation running in the background, and the cuts since its matrix was taken."""

    job: Job
    due: int  # step at which it is installed (waiting for it if not done)
    coeffs: tuple[float, float]
    pieces: int | None
    kind: np.ndarray  # (n,) constraints factorised, on the current nodes
    normal: np.ndarray
    ref: np.ndarray | None = None  # (n,3) positions its matrix was taken at, on the current nodes
    weights: sp.csr_array | None = None  # current nodes -> its nodes (None: identity)
    touched: np.ndarray | None = None  # nodes changed by cuts since its matrix was taken


def _global_factor(indptr: np.ndarray, indices: np.ndarray, blocks0: np.ndarray, kind: np.ndarray,
                   normal: np.ndarray, single: bool) -> Factorization:
    """Factorisation of the filtered ``S A_f S + (I - S)`` in nested-dissection order (runs in a thread too)."""
    if kind.any():
        blocks0 = SK.filter_blocks(indptr, indices, blocks0, kind, normal)
    perm = nested_dissection(indptr, indices)

    def factorise(single: bool) -> Factorization:
        if perm is None:
            return Factorization(block_csr(indptr, indices, blocks0), None, single=single)
        return Factorization.from_blocks(indptr, indices, blocks0, perm, single=single)

    try:
        lu = factorise(single)
        if single and _solve_residual(indptr, indices, blocks0, lu) > SINGLE_RESIDUAL:
            lu = factorise(False)  # too ill-conditioned for single precision (module docstring)
        return lu
    except RuntimeError as exc:
        raise InputError(f"the implicit system is singular ({exc}); check masses and materials") from None


def _solve_residual(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, lu: Factorization) -> float:
    """Relative residual ``|A y - r| / |r|`` of ``y = lu.solve(r)`` for a fixed pseudo-random r (deterministic)."""
    n = len(indptr) - 1
    r = np.random.default_rng(20070101).standard_normal((n, 3))
    y = lu.solve(r.ravel()).reshape(n, 3)
    # the serial row kernel: this may run in the background thread beside the main thread's parallel kernels
    Ay = SK.bsr_matvec_rows(indptr, indices, blocks, y, np.arange(n))
    return float(np.linalg.norm(Ay - r) / np.linalg.norm(r))


def _remapped(W: sp.csr_array, touched: np.ndarray, weights: sp.csr_array | None, old_touched: np.ndarray | None,
              kind: np.ndarray | None, ref: np.ndarray | None) -> tuple[Any, ...]:
    """(weights, touched, kind, ref) of a factorisation carried across a cut with node weights W."""
    if old_touched is None:
        old_touched = np.zeros(W.shape[1], bool)
    new_touched = np.asarray(touched, bool) | ((W @ old_touched.astype(np.float64)) != 0)
    if kind is not None:
        # constraints of the factorisation on the new nodes (touched ones are solved locally anyway)
        kind = np.where(new_touched, 0, np.rint(W @ kind.astype(np.float64))).astype(np.int64)
    if ref is not None:
        ref = W @ ref
    return (W if weights is None else sp.csr_array(W @ weights)), new_touched, kind, ref


class LaggedLU:
    """The lagged, warped LU preconditioner of ``"lu-pcg"`` (see the module docstring).

    ``single``: factorise the Jacobi-scaled matrix in single precision
    (:class:`unmesh.fem.factor.Factorization`). ``background``: refactorise in a thread
    before the factorisation is due (:meth:`wants_background`, :meth:`start_background`),
    installed ``lead`` steps later; ``threaded=False`` computes it at once instead (same
    results: the step it is installed at does not depend on the thread's timing).

    Example
    -------
    >>> LaggedLU().needs_factor((1.0, 1e-4))
    True
    """

    def __init__(self, refactor_iterations: int = 40, touched_fraction: float = 0.1, rings: int = LOCAL_RINGS,
                 touched_rings: int = TOUCHED_RINGS, constrained_rings: int = CONSTRAINED_RINGS, *,
                 single: bool = True, background: bool = True, threaded: bool = True,
                 background_share: float = BACKGROUND_SHARE, background_iterations: int = BACKGROUND_ITERATIONS,
                 lead: int = BACKGROUND_LEAD) -> None:
        self.refactor_iterations = int(refactor_iterations)
        self.rings = int(rings)
        self.constrained_rings = int(constrained_rings)
        self.touched_rings = int(touched_rings)
        self.touched_fraction = float(touched_fraction)
        self.single = bool(single)
        self.background = bool(background)
        self.threaded = bool(threaded)
        self.background_share = float(background_share)
        self.background_iterations = int(background_iterations)
        self.lead = int(lead)
        self.lu: Factorization | None = None
        self.coeffs: tuple[float, float] | None = None
        self.factorizations = 0  # all factorisations made, in the foreground or the background
        self.background_factorizations = 0
        self.waited = 0.0  # seconds spent waiting for background factorisations
        self.last_iterations = 0
        self.weights: sp.csr_array | None = None  # current nodes -> factorised nodes (None: identity)
        self.touched: np.ndarray | None = None  # (n,) bool, nodes changed by cuts since the factorisation
        self.remaps = 0
        self.pieces: int | None = None  # connected pieces of the mesh at the factorisation
        self.kind: np.ndarray | None = None  # (n,) constraints factorised, on the current nodes
        self.ref: np.ndarray | None = None  # (n,3) positions the factorised matrix was taken at (None: rest)
        self.pending: _Pending | None = None
        self._local_cache: tuple[Any, bytes, Any] | None = None  # (matrix, node set, local factor) of the cut region
        self.normal = np.array([0.0, 1.0, 0.0])
        self.mismatch = 0.0  # share of the nodes solved locally because their constraint differs from the factorised one

    @property
    def perm(self) -> np.ndarray | None:
        """DOF order of the factorisation (None: SuperLU's own)."""
        return None if self.lu is None else self.lu.perm

    def invalidate(self) -> None:
        """Drop the factorisation and a pending one (e.g. after a change of material)."""
        self.lu = None
        self.weights = None
        self.touched = None
        self.kind = None
        self.pending = None

    def needs_factor(self, coeffs: tuple[float, float], pieces: int | None = None) -> bool:
        """Whether to (re)factorise before the next solve.

        ``pieces`` (the number of connected pieces of the mesh) triggers a refactorisation
        when it differs from the count at the last factorisation: a cut-remapped
        factorisation still couples the pieces a cut has just separated, which then rotate
        independently (measured: 300 iterations per step on the bunny-slicing benchmark).
        """
        if pieces is not None and self.pieces is not None and pieces != self.pieces:
            return True
        if self.mismatch > self.touched_fraction:
            # the factorised constraints were a poor guess (the fall prediction of a first contact):
            # the nodes solved locally for them alone exceed the share allowed to the cuts
            return True
        limit = self.refactor_iterations
        if self.touched is not None:
            # the Schwarz preconditioner converges a little slower than a fresh factorisation
            limit = 3 * limit // 2
            if self.touched.mean() > self.touched_fraction:
                return True
        return self.lu is None or self.coeffs != coeffs or self.last_iterations > limit

    def wants_background(self, coeffs: tuple[float, float], pieces: int | None = None) -> bool:
        """Whether to start a background refactorisation (call when :meth:`needs_factor` is False).

        When the cut-touched nodes or the nodes of mismatched constraints exceed
        ``background_share`` of ``touched_fraction``, or the last solve needed more than
        ``background_iterations`` iterations, and no refactorisation is pending.
        """
        if not self.background or self.pending is not None or self.lu is None or self.coeffs != coeffs:
            return False
        if pieces is not None and self.pieces is not None and pieces != self.pieces:
            return False
        share = self.background_share * self.touched_fraction
        touched = 0.0 if self.touched is None else float(self.touched.mean())
        return touched > share or self.mismatch > share or self.last_iterations > self.background_iterations

    def start_background(self, indptr: np.ndarray, indices: np.ndarray, blocks0: np.ndarray,
                         coeffs: tuple[float, float], step: int, pieces: int | None = None,
                         kind: np.ndarray | None = None, normal: np.ndarray | None = None,
                         ref: np.ndarray | None = None) -> None:
        """Start factorising A_f (as :meth:`factor`) in a thread; it is installed at step ``step + lead``.

        The arrays must not be changed afterwards (the dynamics make new ones every step).
        """
        n = len(indptr) - 1
        kind0 = np.zeros(n, np.int64) if kind is None else np.ascontiguousarray(kind, dtype=np.int64).copy()
        nrm = np.array([0.0, 1.0, 0.0]) if normal is None else np.ascontiguousarray(normal, dtype=np.float64).copy()
        job = Job(_global_factor, indptr, indices, blocks0, kind0, nrm, self.single, threaded=self.threaded)
        self.pending = _Pending(job, step + self.lead, coeffs, pieces, kind0, nrm, ref)
        self.factorizations += 1
        self.background_factorizations += 1

    def collect(self, step: int) -> bool:
        """Install the pending factorisation if it is due at ``step`` (waits for it); whether it was."""
        pend = self.pending
        if pend is None or step < pend.due:
            return False
        t = time.perf_counter()
        lu = pend.job.result()
        self.waited += time.perf_counter() - t
        self._install(lu, pend.coeffs, pend.pieces, pend.kind, pend.normal, pend.ref)
        self.weights, self.touched = pend.weights, pend.touched
        return True

    def _install(self, lu: Factorization, coeffs: tuple[float, float], pieces: int | None, kind: np.ndarray,
                 normal: np.ndarray, ref: np.ndarray | None) -> None:
        self.lu = lu
        self.ref = ref
        self.coeffs = coeffs
        self.pieces = pieces
        self.kind = kind
        self.normal = normal
        self.mismatch = 0.0
        self.last_iterations = 0
        self.weights = None
        self.touched = None
        self.pending = None

    def remap(self, node_weights: sp.sparray, touched: np.ndarray) -> None:
        """Keep the factorisation (and a pending one) across a topology change (see the module docstring).

        Parameters
        ----------
        node_weights : sparse (n_new, n_old)
            New node state = weights @ old node state.
        touched : (n_new,) bool
            Nodes of the new mesh whose neighbourhood changed (new, duplicated, or in a
            re-integrated element).
        """
        W = sp.csr_array(node_weights)
        pend = self.pending
        if pend is not None:
            pend.weights, pend.touched, pend.kind, pend.ref = _remapped(W, touched, pend.weights, pend.touched,
                                                                        pend.kind, pend.ref)
        if self.lu is None:
            return
        self.weights, self.touched, self.kind, self.ref = _remapped(W, touched, self.weights, self.touched, self.kind,
                                                                    self.ref)
        self.remaps += 1

    def factor(self, indptr: np.ndarray, indices: np.ndarray, blocks0: np.ndarray, coeffs: tuple[float, float],
               pieces: int | None = None, kind: np.ndarray | None = None, normal: np.ndarray | None = None,
               ref: np.ndarray | None = None) -> None:
        """Factorise the matrix A_f (3×3 blocks) with SuperLU now (``pieces``: see :meth:`needs_factor`).

        ``ref`` (n,3): the positions A_f was taken at (its warping), from which the
        preconditioner rotates each piece; None: A_f is unwarped (the rest positions).

        With ``kind`` (n,) (1 fixed, 2 normal ``normal`` prescribed, 0 free) the filtered
        matrix ``S A_f S + (I - S)`` of these constraints is factorised (module docstring).
        A pending background factorisation is dropped.
        """
        n = len(indptr) - 1
        kind0 = np.zeros(n, np.int64) if kind is None else np.ascontiguousarray(kind, dtype=np.int64)
        nrm = np.array([0.0, 1.0, 0.0]) if normal is None else np.ascontiguousarray(normal, dtype=np.float64)
        self._install(_global_factor(indptr, indices, blocks0, kind0, nrm, self.single), coeffs, pieces, kind0, nrm,
                      ref)
        self.factorizations += 1

    def preconditioner(self, node_rot: np.ndarray, indptr: np.ndarray | None = None, indices: np.ndarray | None = None,
                       blocks: np.ndarray | None = None, kind: np.ndarray | None = None,
                       normal: np.ndarray | None = None) -> Any:
        """The preconditioner ``r -> z`` for (n,3) residuals of the filtered system.

        Without a cut since the factorisation and without constrained nodes it is
        ``Q A_f⁻¹ Qᵀ r`` (``node_rot`` (n,3,3): Q per node; the dynamics pass the rotation
        of each node's piece). Otherwise it is the symmetric
        multiplicative Schwarz combination (module docstring) of that with an exact
        solve on the local set: the nodes touched by cuts since the factorisation plus
        the constrained nodes (``kind`` 1 fixed, 2 normal ``normal`` prescribed), whose
        block is the filtered ``S A_tt S + (I - S)`` (S: the constraint projection), so
        the constraints, which the factorisation does not know, are solved exactly
        near them. That needs the current matrix (``indptr, indices, blocks``, 3×3 blocks).
        """
        lu = self.lu
        assert lu is not None
        W = self.weights
        WT = sp.csr_array(W.T) if W is not None else None

        def old(r: np.ndarray) -> np.ndarray:
            rl = np.einsum("nji,nj->ni", node_rot, r)
            if WT is not None:
                rl = WT @ rl
            y = lu.solve(rl.ravel()).reshape(-1, 3)
            if W is not None:
                y = W @ y
            return np.einsum("nij,nj->ni", node_rot, y)

        if indptr is None or indices is None or blocks is None:
            return old
        n = len(indptr) - 1
        t_mask = np.zeros(n, bool) if self.touched is None else self.touched.copy()
        if self.touched is not None and self.touched_rings:
            t_mask |= grow(indptr, indices, self.touched, self.touched_rings)
        c_mask = np.zeros(n, bool)
        if kind is not None and np.any(kind != 0):
            c_mask |= grow(indptr, indices, kind != 0, self.constrained_rings)
        if kind is not None and self.kind is not None and len(self.kind) == len(kind):
            changed = (kind != self.kind) | ((kind == 2) & (self.normal @ (normal if normal is not None else self.normal)
                                                            < 1.0 - 1e-12))
            if changed.any():
                wrong = grow(indptr, indices, changed, self.rings)
                self.mismatch = float(wrong.mean())
                c_mask |= wrong
            else:
                self.mismatch = 0.0
        if not (t_mask.any() or c_mask.any()):
            return old
        nrm = np.array([0.0, 1.0, 0.0]) if normal is None else np.asarray(normal, np.float64)
        kf = np.zeros(n, np.int64) if kind is None else np.ascontiguousarray(kind, dtype=np.int64)
        if t_mask.any() and c_mask.any() and not (grow(indptr, indices, c_mask, 1) & t_mask).any():
            # the cut region and the constrained region do not touch: A_tt is block diagonal, and
            # the cut block (unconstrained) is the same in every contact round of the step
            key = np.flatnonzero(t_mask).tobytes()
            cached = self._local_cache
            if cached is not None and cached[0] is blocks and cached[1] == key:
                t_part = cached[2]
            else:
                t_part = _local_factor(indptr, indices, blocks, np.flatnonzero(t_mask), kf, nrm)
                self._local_cache = (blocks, key, t_part)
            parts = [t_part, _local_factor(indptr, indices, blocks, np.flatnonzero(c_mask), kf, nrm)]
        else:
            parts = [_local_factor(indptr, indices, blocks, np.flatnonzero(t_mask | c_mask), kf, nrm)]

        def loc(r: np.ndarray) -> np.ndarray:
            z = np.zeros_like(r)
            for nodes, local in parts:
                z[nodes] = local.solve(r[nodes].ravel()).reshape(-1, 3)
            SK.filter_inplace(z, kf, nrm)
            return z

        # the local corrections live on the local set: A z₁ is needed only on its neighbourhood,
        # and the second local solve reads the residual only on the local set
        local_nodes = np.flatnonzero(t_mask | c_mask)
        near = np.flatnonzero(grow(indptr, indices, t_mask | c_mask, 1))

        def apply_schwarz(r: np.ndarray) -> np.ndarray:
            r = r.copy()
            SK.filter_inplace(r, kf, nrm)
            z = loc(r)
            q = r.copy()
            q[near] -= SK.bsr_matvec_rows(indptr, indices, blocks, z, near)
            SK.filter_inplace(q, kf, nrm)
            y = old(q)
            SK.filter_inplace(y, kf, nrm)
            z += y
            q = np.zeros_like(r)
            q[local_nodes] = r[local_nodes] - SK.bsr_matvec_rows(indptr, indices, blocks, z, local_nodes)
            SK.filter_inplace(q, kf, nrm)
            z += loc(q)
            return z

        return apply_schwarz


def node_rotations(rots: np.ndarray, node_offsets: np.ndarray, nodes: np.ndarray, weights: np.ndarray,
                   n_nodes: int) -> np.ndarray:
    """Per-node rotations: weighted average of incident element rotations, made orthogonal (polar)."""
    e = np.repeat(np.arange(len(rots)), np.diff(node_offsets))
    acc = np.zeros((n_nodes, 9))
    flat = rots.reshape(-1, 9)[e] * weights[:, None]
    for k in range(9):
        acc[:, k] = np.bincount(nodes, weights=flat[:, k], minlength=n_nodes)
    acc = acc.reshape(n_nodes, 3, 3)
    empty = np.abs(acc).sum(axis=(1, 2)) == 0
    acc[empty] = np.eye(3)
    return polar_rotations(acc)
