"""Linear solvers of the implicit Euler step (9.1.4), chosen for these problem sizes.

All solve ``A v = b`` with ``A = c_m M + c_k K'`` (warped stiffness, 3×3 blocks)
and per-node constraints (fixed, or normal-constrained ground contact):

- ``"cg"``: filtered PCG with a block-Jacobi preconditioner, warm-started from the
  last velocity. No setup; fine for small or soft meshes, slow for stiff ones.
- ``"auto"`` (default): ``"cg"``; if a solve does not converge in 150 iterations the
  system is too stiff for it and the dynamics switch to ``"lu-pcg"`` for good.
- ``"lu-pcg"``: filtered PCG warm-started from the last velocity,
  preconditioned by a *lagged, warped* sparse LU factorisation: the unwarped
  matrix ``A₀ = c_m M + c_k K`` is factorised (SuperLU, minimum-degree ordering of
  A+Aᵀ) and reused for later steps as ``Q A₀⁻¹ Qᵀ`` with per-node rotations Q (so
  rigidly rotated parts are preconditioned exactly); it is refactorised after a
  topology change (cut), a change of the step size, or when a solve needed more
  than ``refactor_iterations`` iterations (large relative rotations). Keeping the
  old factorisation across a cut (block-Jacobi on new nodes) was measured to need
  80-200 iterations instead of about 8, which costs more than refactorising.
- ``"direct"``: exact sparse LU of the constrained system in every step.

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

from typing import Any

import numpy as np
import scipy.sparse as sp

from unmesh.errors import InputError
from unmesh.fem import _solve_kernels as SK

__all__ = ["SOLVERS", "LaggedLU", "direct_solve", "pcg"]

SOLVERS = ("auto", "lu-pcg", "cg", "direct")


def pcg(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, b: np.ndarray, x0: np.ndarray, kind: np.ndarray,
        normal: np.ndarray, precond: Any, tol: float, maxiter: int) -> tuple[np.ndarray, int, float]:
    """Filtered PCG (Baraff & Witkin 1998) with a Python preconditioner ``precond(r) -> z``.

    ``x0`` must satisfy the constraints. Returns (x, iterations, relative residual).

    Example
    -------
    >>> import numpy as np
    >>> eye = np.eye(3).ravel()[None]
    >>> x, its, res = pcg(np.array([0, 1]), np.array([0]), 2 * eye, np.ones((1, 3)), np.zeros((1, 3)),
    ...                   np.zeros(1, np.int64), np.array([0.0, 1.0, 0.0]), lambda r: r, 1e-12, 10)
    >>> x.tolist()
    [[0.5, 0.5, 0.5]]
    """
    x = x0.copy()
    r = b - SK.bsr_matvec(indptr, indices, blocks, x)
    SK.filter_inplace(r, kind, normal)
    fb = b.copy()
    SK.filter_inplace(fb, kind, normal)
    bn = float(np.sqrt(SK.dot(fb, fb))) or 1.0
    rn = float(np.sqrt(SK.dot(r, r)))
    if rn <= tol * bn:
        return x, 0, rn / bn
    z = precond(r)
    SK.filter_inplace(z, kind, normal)
    d = z.copy()
    delta = SK.dot(r, z)
    it = 0
    while it < maxiter:
        it += 1
        q = SK.bsr_matvec(indptr, indices, blocks, d)
        SK.filter_inplace(q, kind, normal)
        dq = SK.dot(d, q)
        if dq <= 0.0:
            break
        rn = SK.cg_update(x, r, d, q, delta / dq)
        if rn <= tol * bn:
            break
        z = precond(r)
        SK.filter_inplace(z, kind, normal)
        dnew = SK.dot(r, z)
        SK.cg_direction(z, d, dnew / delta)
        delta = dnew
    return x, it, rn / bn


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
    mat = sp.bsr_array((blocks.reshape(-1, 3, 3), indices, indptr), shape=(3 * n, 3 * n)).tocsr()
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


class LaggedLU:
    """The lagged, warped LU preconditioner of ``"lu-pcg"`` (see the module docstring).

    Example
    -------
    >>> LaggedLU().needs_factor((1.0, 1e-4))
    True
    """

    def __init__(self, refactor_iterations: int = 40) -> None:
        self.refactor_iterations = int(refactor_iterations)
        self.lu: Any = None
        self.coeffs: tuple[float, float] | None = None
        self.factorizations = 0
        self.last_iterations = 0

    def invalidate(self) -> None:
        """Drop the factorisation (e.g. after a change of material)."""
        self.lu = None

    def needs_factor(self, coeffs: tuple[float, float]) -> bool:
        """Whether to (re)factorise before the next solve."""
        return (self.lu is None or self.coeffs != coeffs or self.last_iterations > self.refactor_iterations)

    def factor(self, indptr: np.ndarray, indices: np.ndarray, blocks0: np.ndarray, coeffs: tuple[float, float]) -> None:
        """Factorise the unwarped matrix A₀ (3×3 blocks) with SuperLU."""
        from scipy.sparse.linalg import splu

        n = len(indptr) - 1
        A0 = sp.bsr_array((blocks0.reshape(-1, 3, 3), indices, indptr), shape=(3 * n, 3 * n)).tocsc()
        try:
            self.lu = splu(A0, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
        except RuntimeError as exc:
            raise InputError(f"the implicit system is singular ({exc}); check masses and materials") from None
        self.coeffs = coeffs
        self.factorizations += 1
        self.last_iterations = 0

    def preconditioner(self, node_rot: np.ndarray) -> Any:
        """``r -> Q A₀⁻¹ Qᵀ r`` for (n,3) residuals (Q: per-node rotations)."""
        lu = self.lu
        assert lu is not None

        def apply(r: np.ndarray) -> np.ndarray:
            rl = np.einsum("nji,nj->ni", node_rot, r)
            y = lu.solve(rl.ravel()).reshape(-1, 3)
            return np.einsum("nij,nj->ni", node_rot, y)

        return apply


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
    u, _, vt = np.linalg.svd(acc)
    q = u @ vt
    flip = np.linalg.det(q) < 0
    if flip.any():
        u[flip, :, 2] *= -1
        q[flip] = u[flip] @ vt[flip]
    return q
