"""Linear solvers of the implicit Euler step (9.1.4), chosen for these problem sizes.

All solve ``A v = b`` with ``A = c_m M + c_k K'`` (warped stiffness, 3×3 blocks)
and per-node constraints (fixed, or normal-constrained ground contact):

- ``"cg"``: filtered PCG with a block-Jacobi preconditioner, warm-started from the
  last velocity. No setup; fine for small or soft meshes, slow for stiff ones.
- ``"auto"`` (default): ``"cg"``; if a solve does not converge in 150 iterations the
  system is too stiff for it and the dynamics switch to ``"lu-pcg"`` for good.
- ``"lu-pcg"``: filtered PCG warm-started from the last velocity,
  preconditioned by a *lagged, warped* sparse LU factorisation: the matrix ``A_f`` of
  the step it is made in (warped stiffness, the rotations of that step), with the
  constraints of the last step's contact set eliminated (``S A_f S + I - S``, S the
  constraint projection; ground contact included, see below), is factorised (SuperLU in
  METIS nested-dissection order of the node graph, :func:`nested_dissection`, 3×3 blocks
  kept together; SuperLU's own minimum-degree order of A+Aᵀ when ``pymetis`` is missing;
  single precision after symmetric Jacobi scaling, :class:`unmesh.fem.factor.Factorization`)
  and reused for later steps as ``Q A_f⁻¹ Qᵀ`` with Q the best-fit rotation of each
  connected piece from the positions ``A_f`` was taken at to the current ones
  (:func:`unmesh.fem.rotations.piece_rotations`), so rigidly
  rotated pieces are preconditioned exactly. One rotation per piece, not per node:
  a node-to-node varying rotation maps the translations of the current configuration
  (eigenvalue ~ mass, 1/4800 of the stiffness scale on the bunny benchmark) outside the
  near-null space of ``Q A_f Qᵀ``; on the bunny-slicing benchmark node-averaged rotations
  needed 64-76 iterations where the piece rotation needs 23. (The unwarped rest matrix
  ``c_m M + c_k K`` rotated per piece from rest, factorised before, needed 10.0 iterations
  per frame on the bunny benchmark where the warped one needs 8.3: the head bends at the
  neck relative to the body, which one rotation per piece cannot follow.) It is refactorised after
  a change of the step size, when a cut separates a new piece (the remapped factorisation
  would still couple the pieces, which then rotate independently), or when a solve needed
  more than ``refactor_iterations`` iterations.
  A cut does not refactorise: the old factorisation is kept and mapped to the new
  nodes through the cut's node weights W (new state = W old state), and a *local set*
  gets an exact solve of its block ``A_tt`` of the current (filtered) matrix: the nodes
  the cut touched (new nodes, duplicated nodes, nodes of re-integrated elements,
  accumulated over the cuts since the last factorisation) plus ``TOUCHED_RINGS`` (1)
  layers of neighbours, the constrained nodes plus ``CONSTRAINED_RINGS`` (1) layers, and
  the nodes whose constraint differs from the factorised one plus ``LOCAL_RINGS`` (3)
  layers. The two are combined as a symmetric multiplicative Schwarz preconditioner,
  ``z₁ = A_tt⁻¹ r_t``, ``z₂ = z₁ + Q W A_f⁻¹ Wᵀ Qᵀ (r - A z₁)``, ``z = z₂ + A_tt⁻¹ (r - A z₂)_t``.
  (Keeping the old factorisation with only block-Jacobi on new nodes was measured
  to need 80-200 iterations instead of about 8-30; the local solve restores that.)
  A solve that has not converged after 200 iterations with a lagged factorisation is
  restarted with a fresh one (:data:`unmesh.fem.dynamics.LAGGED_ITERATIONS`).
  It refactorises when the touched part exceeds ``touched_fraction`` (10%) of the
  nodes or a solve needs more than 1.5 ``refactor_iterations``: on the bunny-slicing
  benchmark the iterations grow to 25-35 per solve as the touched part reaches 10-14%
  (measured with 20%: 1 LU instead of 2 in 12 frames, but 2.6-4.2 s instead of 1.2-2.8 s
  per cutting frame). It also refactorises when the nodes whose constraint differs from the
  factorised one, with their ``LOCAL_RINGS`` layers, exceed ``touched_fraction``: the
  constraints factorised are the last step's contact set (the free-fall prediction when
  there is none, which overestimates a first contact: 221 predicted, 64-131 in contact over
  the first frames of the bunny benchmark), and each node factorised in the wrong state
  widens the local set (the bunny benchmark solved 1137-2857 nodes locally for 85-690 of
  them; factorised with the contact set, the local set is the ~90 contacts and one ring).
- ``"direct"``: exact sparse LU of the constrained system in every step.

Measured on the bunny-slicing benchmark (49k DOFs, one thread, loaded machine; systems of
frames 1 and 10 solved to 10⁻⁶ from the warm start):

- the contact constraints, not the warping, cost most iterations: 11 and 14 iterations
  with the unconstrained factorisation and the contact nodes alone solved locally, 5 and 7
  with 3 rings of neighbours in the local set, 2-3 and 5 with the contacts factorised
  (still 2-3 and 5 with 1/8 of the contacts missing from the factorisation); the exact
  current matrix needs 1;
- METIS nested dissection: fill 14.0M (SuperLU's minimum degree: 16.1M), factorisation
  1.1-1.3 s instead of 2.4-2.8 s; a solve costs 30-40 ms with either;
- algebraic multigrid (``pyamg`` smoothed aggregation, rigid-body modes as near-null space,
  on the filtered matrix): setup 1.6-3.7 s per matrix, 100-140 ms per V-cycle (three times
  an LU solve), 6-165 iterations (137-165 after cuts with the default strength of
  connection, 7-11 with θ = 0.02); slower than the lagged LU in every configuration tried;
- incomplete LU (SuperLU ILUTP, drop 10⁻⁵..10⁻⁷): fill 8.2M-14.4M, no convergence in 300
  iterations until it is nearly the full factor; a scalar (trace) factorisation: factor
  0.12 s, but 21-59 iterations;
- CHOLMOD through ``cholespy`` (the only CHOLMOD wheel on PyPI; scikit-sparse has none):
  factorisation 4.1 s, solve 26 ms; hand-written numba triangular solves on SuperLU's
  factors (CSC or CSR, double or single precision): no faster than SuperLU's solve.
- single precision without scaling stalled PCG (lumped masses spanning 5 decades after
  slivers). Scaling does not cure every case: on the bunny meshed at 14,905 nodes, after 18
  cuts a sliver made the diagonal span 5·10¹⁰ and the float32 factors solved with a relative
  residual of 20-220 (PCG did not converge in 5,400 iterations, refactorised or not), so a
  factorisation whose solve of a fixed random vector leaves more than ``SINGLE_RESIDUAL``
  (10⁻³; 4-5·10⁻⁵ otherwise) is redone in double precision. Otherwise, after symmetric
  Jacobi scaling (unit diagonal) it needs the same CG iterations
  as double precision in every step of the 30-frame bunny run (24,138 nodes), factorises in
  1.2-1.55 s instead of 1.85-2.4 s CPU (fill 25.8M; half the memory, which matters on the
  benchmark's virtual machine, where first-touched memory costs up to 10 ms per MB) and
  solves in 24-33 ms instead of 34 ms; the run's solve time per frame went 0.90 → 0.71 s
  (load 1.5-1.6, one run each). The local (Schwarz) factorisations in single precision:
  same iterations, 2.21 → 2.01 s factorising and 0.97 → 0.85 s solving in 29 frames (main
  thread CPU): not worth an inexact local solve, they stay double;
- SuperLU's ``relax`` (8-128) and ``panel_size`` with the nested-dissection order: same fill
  (25.8M), solve 24-27 ms either way;
- the warped matrix of the factorisation step rotated per piece from its positions, instead
  of the rest matrix rotated from rest: 10.0 → 8.3 CG iterations per frame (30 frames);
- a background refactorisation (:meth:`LaggedLU.wants_background`): SuperLU releases the GIL
  (a Python loop in the main thread ran at 24% of its speed beside ``splu`` in a thread, at
  31% beside a BLAS product, load 2.7: the second core was busy with other work). Started at
  ``background_share`` 0.15 / 0.25 / 0.4 of ``touched_fraction``: 7.6 / 8.3 / 8.9 CG
  iterations per frame with 12 / 8 / 6 factorisations in 30 steps (none waited for: two
  steps of lead); 0.25 kept. Moving the foreground refactorisation of frame 1 (the auto
  switch factorised the free-fall prediction; 13.8% of the nodes mismatched) to the
  background as well, with doubled foreground limits, made frames 1-2 cost 1.30 + 1.53 s
  (a local set of 14% of the nodes) instead of 1.64 + 0.48 s: not kept. What the thread
  does holding the GIL holds up the main thread: scipy's SuperLU takes it for each
  allocation, ``pymetis`` for the whole ordering (160 ms: the main thread's Python loop
  ran at 11% of its speed; METIS is now called through ctypes, which releases it: 57%,
  :func:`nested_dissection`), scipy's conversions often (in the thread beside a busy main
  thread block→CSR took 0.38 s, 0.02 s alone, and ``A[p][:, p]`` 0.85 s, load 2.7):
  the permuted, scaled matrix is built by a kernel that releases
  the GIL (:meth:`unmesh.fem.factor.Factorization.from_blocks`), and the main thread's
  kernels release it. Reusing the last METIS order for the background refactorisation
  (new nodes placed after their parents through W) would spare the 160 ms, but after 20
  cuts (1,786 new nodes) it had fill 36.2M instead of 25.9M and solved in 45 instead of
  29 ms: not done. Predicting the first contact set from the nodes on the ground or taken
  below it by their velocity (563 on the bunny, instead of the free fall's 988) avoids the
  refactorisation of frame 1, but leaves 4.7% of the nodes mismatched (the contact rim
  changes) until a background factorisation is installed: frames 1-3 took 2.72 s CPU
  (load 3.4) instead of 1.84 s (an earlier run, load 2.8): not kept;
- the numba kernels on both cores for the bunny (:data:`unmesh.fem.dynamics.SERIAL_NODES`
  lowered below its node count), interleaved runs of 30 frames: wall 1.04 → 0.82 s per
  frame at load 2.9, 1.44 → 1.72 s at load 3.5-3.7 (the other engineers' jobs on the two
  cores); not adopted, as it depends on the load.

Per frame of the bunny-slicing benchmark (``benchmarks/bench_fem_slicing.py --bunny``, 12
frames; kernels on one thread as :data:`unmesh.fem.dynamics.SERIAL_NODES` sets them; the
machine shared, load average 2.8-3.1, the old and new code run one after the other):
37 → 16 CG iterations, 3.81 → 2.36 s CPU and 5.51 → 3.35 s wall per frame (cutting frames
4.08 → 2.59 s CPU); 3 LU factorisations either way (the setup step's, then a cut touching
more than 10% of the nodes and a cut separating the head).

The same benchmark at the thesis' node count (24,138 → 27,312 nodes, 30 frames), the code
before and after the single-precision, warped and background factorisations and the
kernels above, run one after the other on the shared machine (load 1.3-2.7): wall 1.37 →
1.28 s per frame (cut 0.11 → 0.18, re-integration 0.21 → 0.23, solve 1.03 → 0.86 s), CPU
1.31 → 1.25 s (main thread 0.97 s), 12 → 8 CG iterations, 3 → 8 factorisations (6 in the
background, none waited for); at 14,905 nodes: wall 0.95 → 0.86 s, CPU 0.90 → 1.06 s (main
thread 0.62 s), 10 → 8 iterations. A second pair at 24,138 nodes (load 1.0-2.9): wall
1.40 → 1.52 s, CPU 1.37 → 1.12 s (main thread 0.87 s); the new code at 14,905 nodes again:
wall 1.15 s, CPU 1.13 s (main thread 0.65 s; 14 factorisations, 12 in the background, some
redone in double precision after slivers). The background thread costs the main thread when the
machine is busy: with the other jobs on the two cores (load 1.7-3.2, interleaved runs of
the 30 frames) the background refactorisation took 1.27 and 1.24 s per frame, refactorising
in the foreground (``background=False``: 10.2 iterations, 3 factorisations) 1.19 and
1.03 s, though the main thread's CPU was 0.99 and 0.95 s against 1.15 and 1.00 s (in the
frames where a factorisation ran, cutting and re-integration took up to twice as long as in
the old code's run: SuperLU's allocations take the GIL, and the thread competes for a core).
Two more pairs at load 1.0-1.7: background 1.09 and 1.13 s (main thread 0.95 and 0.91 s),
foreground 1.07 and 1.09 s (main thread 1.04 and 1.06 s). So the background refactorisation
saves the main thread ~0.1 s per frame, which shows in the wall time only when the second
core is free; on this shared machine it never was, and the wall times were equal within the
noise (foreground faster in 4 of 5 pairs). It stays on (``background=True``), the goal being
a quiet machine; ``background=False`` spends less CPU in all (1.01-1.16 against 1.17-1.26 s).
Later, on the machine otherwise idle (load 0.6-1.7): the first two cuts took fresh memory for
the stiffness data (~6 ms per MB at first touch on the benchmark's virtual machine; now
reserved before the first step, :meth:`unmesh.fem.dynamics.Dynamics.reserve_topology_buffers`),
and each background start stopped the main thread for 90-140 ms (pymetis held the GIL for
the whole mesh's ordering; through ctypes, the step's first local ordering still queued
behind it on the METIS lock): METIS is called through ctypes, the background job starts
after the step's first local factorisation, and local orders are remembered
(:func:`unmesh.fem.factor._local_order`). Main thread per frame over the 30 frames, two
probe pairs: re-integration 114-119 → 73-77 ms, preconditioner set-up 72-76 → 50-52 ms;
wall per frame in five interleaved pairs 0.75 / 0.76 / 0.73 / 0.80 / 0.85 → 0.73 / 0.73 /
0.69 / 0.86 / 0.75 s (the machine's speed drifting by 25% within minutes: the same code ran
at 0.98 s earlier); 8 iterations and 8 factorisations either way, the displacements after
30 frames the same bit for bit. Tried without gain: METIS options (``nseps`` 3, ``ufactor``
100, ``niter`` 20, ``ccorder``: fill 25.5-25.8M against 25.8M, no pivoting either way, L and
U of equal size; solves within the noise), 1 or 2 BLAS threads for SuperLU's solve (28-40 ms
either way), ``background_share`` 0.15 (12 factorisations, 7.6 iterations: 0.93 / 0.88
against 0.93 / 0.86 s), ``background_iterations`` 10 (the same factorisations and
iterations: a refactorisation was pending, just installed or started for the touched nodes
anyway whenever it would have triggered), and
glibc's ``mallopt`` keeping freed memory (no mmap, no trim) against the first-touch cost
(no gain: the memory still grew, in the background thread's arena).

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
