"""Filtered preconditioned conjugate gradients of the implicit step (9.1.4), resumable.

The filtered PCG of Baraff & Witkin (1998) solves ``A v = b`` (3×3 blocks) with per-node
constraints (kind 0 free, 1 fixed, 2 the component along ``normal`` prescribed): the
initial guess satisfies them and the filter keeps every update in the free subspace.
The preconditioner is a Python callable (the lagged LU and Schwarz combination of
:mod:`unmesh.fem.solvers`); the kernels are in :mod:`unmesh.fem._solve_kernels`.

Example
-------
>>> import numpy as np
>>> eye = np.eye(3).ravel()[None]
>>> pcg(np.array([0, 1]), np.array([0]), 4 * eye, np.ones((1, 3)), np.zeros((1, 3)),
...     np.zeros(1, np.int64), np.array([0.0, 1.0, 0.0]), lambda r: r, 1e-12, 10)[0].tolist()
[[0.25, 0.25, 0.25]]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._threads import threads_for
from unmesh.fem import _solve_kernels as SK

__all__ = ["PCG", "pcg"]

#: Systems of at least this many nodes may run the matrix-vector product on all threads
#: (:class:`unmesh._threads.threads_for` keeps the faster choice).
MATVEC_PARALLEL_MIN = 4096


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
    return PCG(indptr, indices, blocks, b, x0, kind, normal, precond).run(tol, maxiter)


class PCG:
    """Filtered PCG that can be resumed to a tighter tolerance (see :func:`pcg`).

    The contact rounds of a step (:mod:`unmesh.fem.dynamics`) solve to a loose tolerance
    and confirm the final active set to ``cg_tol``: when the set did not change, the
    confirming solve continues the same Krylov sequence instead of restarting from the
    loose solution (a restart costs a preconditioner application and the search
    directions built so far).

    Example
    -------
    >>> import numpy as np
    >>> eye = np.eye(3).ravel()[None]
    >>> cg = PCG(np.array([0, 1]), np.array([0]), 2 * eye, np.ones((1, 3)), np.zeros((1, 3)),
    ...          np.zeros(1, np.int64), np.array([0.0, 1.0, 0.0]), lambda r: r)
    >>> cg.run(1e-3, 10)[1], cg.run(1e-12, 10)[1]
    (1, 0)
    """

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, b: np.ndarray, x0: np.ndarray,
                 kind: np.ndarray, normal: np.ndarray, precond: Any) -> None:
        self.mat = (indptr, indices, blocks)
        self.kind, self.normal, self.precond = kind, normal, precond
        self.x = x0.copy()
        self.r = b - SK.bsr_matvec(indptr, indices, blocks, self.x)
        SK.filter_inplace(self.r, kind, normal)
        fb = b.copy()
        SK.filter_inplace(fb, kind, normal)
        self.bn = float(np.sqrt(SK.dot(fb, fb))) or 1.0
        self.rn = float(np.sqrt(SK.dot(self.r, self.r)))
        self.d: np.ndarray | None = None  # search direction (None: not started)
        self.delta = 0.0
        self.current = False  # d is up to date with r
        self.broken = False  # dᵀ A d <= 0: cannot continue

    def _direction(self) -> None:
        """Precondition the current residual and update the search direction."""
        z = self.precond(self.r)
        SK.filter_inplace(z, self.kind, self.normal)
        dnew = SK.dot(self.r, z)
        if self.d is None:
            self.d = z.copy()
        else:
            SK.cg_direction(z, self.d, dnew / self.delta)
        self.delta = dnew
        self.current = True

    def run(self, tol: float, maxiter: int) -> tuple[np.ndarray, int, float]:
        """Iterate until the relative residual is at most ``tol`` (or ``maxiter`` iterations of this call).

        Returns (a copy of x, iterations of this call, relative residual).
        """
        it = 0
        if self.rn <= tol * self.bn or self.broken:
            return self.x.copy(), it, self.rn / self.bn
        indptr, indices, blocks = self.mat
        if not self.current:
            self._direction()
        while it < maxiter:
            it += 1
            with threads_for(len(indptr) - 1, MATVEC_PARALLEL_MIN, "fem.matvec"):
                q = SK.bsr_matvec(indptr, indices, blocks, self.d)
            SK.filter_inplace(q, self.kind, self.normal)
            dq = SK.dot(self.d, q)
            if dq <= 0.0:
                self.broken = True
                break
            self.rn = SK.cg_update(self.x, self.r, self.d, q, self.delta / dq)
            self.current = False
            if self.rn <= tol * self.bn:
                break
            self._direction()
        return self.x.copy(), it, self.rn / self.bn
