"""Batched polar decomposition of the lattice pass (thesis eq. 8.24) with the singular-value clamps.

:func:`polar_lanes` runs Newton's polar iteration on many 3×3 matrices at once and accepts a lane
only where the clamps :data:`SIG_LO`, :data:`SIG_HI` cannot act. The general small dense linear
algebra (3×3 SVD :func:`svd_rot`, Jacobi eigen-decompositions, inverse, adjugate) is the shared
:mod:`unmesh._linalg_kernels` (re-exported here for the lattice kernels). Numpy references:
:func:`unmesh.sph.elastic.rotation_svd` and :func:`numpy.linalg.svd`, which the tests compare against.

Example
-------
>>> import numpy as np
>>> u, s, v = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
>>> svd_rot(np.diag([2.0, 1.0, 0.5]), 3, u, s, v, np.empty((4, 3, 3)))
>>> s.tolist()
[2.0, 1.0, 0.5]
"""

from __future__ import annotations

from numba import njit

from unmesh._linalg_kernels import inv3 as _inv3  # noqa: F401 - re-exported for the lattice kernels
from unmesh._linalg_kernels import jacobi3, svd_rot, sym_adjugate, sym_eig3  # noqa: F401 - re-exported

#: Clamp of singular values when inverting A for the next assignment.
SIG_LO = 0.2
SIG_HI = 5.0


# -- polar decomposition -------------------------------------------------------------------


@njit(cache=True, fastmath=False, error_model="numpy")
def polar_lanes(a, rot, sym, fast, act):
    """Polar decompositions ``A = R S`` (3D, eq. 8.24) of ``L`` matrices at once, one per lane.

    Newton's iteration ``R ← (R + R⁻ᵀ)/2`` from ``R = A`` converges quadratically to the
    orthogonal polar factor (Higham 1986), a rotation when ``det A > 0``. A lane stops when a step
    changes no entry by more than 1e-8 (the iterate is then exact to rounding: the error squares),
    when ``det R ≤ 0`` or after 40 steps; its iterate is kept by a select, and the steps end when no
    lane is active. Each step is one loop over the lanes, so the divisions of different matrices
    overlap instead of waiting for each other. Then ``S = sym(Rᵀ A)``.

    The lattice pass needs only functions of ``S`` that reduce to matrix algebra when every
    singular value lies inside the clamps (``SIG_LO < σ < SIG_HI``, which also keeps the goal floor
    ``SIGMA_FLOOR`` inactive): ``U diag(f(σ)) Vᵀ = R f(S)`` for ``f(σ) = sσ + (1 − s)`` and
    ``V diag(1/σ) Uᵀ = S⁻¹ Rᵀ``, ``Σσ = tr S``. Gershgorin's discs of ``S`` bound its eigenvalues,
    so the check is rigorous. A lane is declined (use the SVD, :func:`svd_rot`) for ``det A ≤ 0``,
    when Newton's iteration does not converge or when a disc reaches a clamp.

    Parameters
    ----------
    a : ndarray, shape (9, L)
        The matrices, row-major entries: ``a[3 p + q, k] = A_k[p, q]``.
    rot, sym : ndarray, shape (9, L)
        Receive ``R`` and ``S`` of every lane (the same layout).
    fast : ndarray, shape (L,)
        Receives 1.0 where the lane is accepted, 0.0 where it is declined.
    act : ndarray, shape (L,)
        Scratch.

    Example
    -------
    >>> import numpy as np
    >>> a = np.zeros((9, 2)); a[[0, 4, 8], 0] = (1.1, 0.9, 1.0); a[[0, 4, 8], 1] = (1.0, 1.0, -1.0)
    >>> rot, sym, fast = np.empty((9, 2)), np.empty((9, 2)), np.empty(2)
    >>> polar_lanes(a, rot, sym, fast, np.empty(2)); fast.tolist(), sym[[0, 4, 8], 0].tolist()
    ([1.0, 0.0], [1.1, 0.9, 1.0])
    """
    lanes = a.shape[1]
    for k in range(lanes):
        for e in range(9):
            rot[e, k] = a[e, k]
        act[k] = 1.0
        fast[k] = 0.0
    for _it in range(40):
        nact = 0
        for k in range(lanes):
            r00, r01, r02 = rot[0, k], rot[1, k], rot[2, k]
            r10, r11, r12 = rot[3, k], rot[4, k], rot[5, k]
            r20, r21, r22 = rot[6, k], rot[7, k], rot[8, k]
            # cofactors: R⁻ᵀ = C / det R
            c00 = r11 * r22 - r12 * r21
            c01 = r12 * r20 - r10 * r22
            c02 = r10 * r21 - r11 * r20
            c10 = r02 * r21 - r01 * r22
            c11 = r00 * r22 - r02 * r20
            c12 = r01 * r20 - r00 * r21
            c20 = r01 * r12 - r02 * r11
            c21 = r02 * r10 - r00 * r12
            c22 = r00 * r11 - r01 * r10
            det = r00 * c00 + r01 * c01 + r02 * c02
            hinv = 0.5 / det
            n00 = 0.5 * r00 + hinv * c00
            n01 = 0.5 * r01 + hinv * c01
            n02 = 0.5 * r02 + hinv * c02
            n10 = 0.5 * r10 + hinv * c10
            n11 = 0.5 * r11 + hinv * c11
            n12 = 0.5 * r12 + hinv * c12
            n20 = 0.5 * r20 + hinv * c20
            n21 = 0.5 * r21 + hinv * c21
            n22 = 0.5 * r22 + hinv * c22
            diff = max(abs(n00 - r00), abs(n01 - r01), abs(n02 - r02), abs(n10 - r10), abs(n11 - r11),
                       abs(n12 - r12), abs(n20 - r20), abs(n21 - r21), abs(n22 - r22))
            step = (act[k] > 0.0) & (det > 0.0)
            rot[0, k] = n00 if step else r00
            rot[1, k] = n01 if step else r01
            rot[2, k] = n02 if step else r02
            rot[3, k] = n10 if step else r10
            rot[4, k] = n11 if step else r11
            rot[5, k] = n12 if step else r12
            rot[6, k] = n20 if step else r20
            rot[7, k] = n21 if step else r21
            rot[8, k] = n22 if step else r22
            done = step & (diff <= 1e-8)
            fast[k] = 1.0 if done else fast[k]
            go = step & ~done
            act[k] = 1.0 if go else 0.0
            nact += go
        if nact == 0:
            break
    # S = sym(Rᵀ A); accepted if Gershgorin's discs of S lie inside the clamps
    for k in range(lanes):
        for p in range(3):
            for q in range(3):
                sym[3 * p + q, k] = rot[p, k] * a[q, k] + rot[3 + p, k] * a[3 + q, k] + rot[6 + p, k] * a[6 + q, k]
        for p in range(3):
            for q in range(p + 1, 3):
                mean = 0.5 * (sym[3 * p + q, k] + sym[3 * q + p, k])
                sym[3 * p + q, k] = mean
                sym[3 * q + p, k] = mean
        inside = fast[k] > 0.0
        for p in range(3):
            rad = 0.0
            for q in range(3):
                if q != p:
                    rad += abs(sym[3 * p + q, k])
            d = sym[4 * p, k]
            inside = inside & (d - rad > SIG_LO * (1.0 + 1e-6)) & (d + rad < SIG_HI * (1.0 - 1e-6))
        fast[k] = 1.0 if inside else 0.0
