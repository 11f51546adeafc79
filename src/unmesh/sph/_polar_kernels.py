"""Small dense linear algebra of the lattice pass in registers (thesis eq. 8.24): 3×3 SVD, polar
decomposition, inverse and determinant.

Numpy references: :func:`unmesh.sph.elastic.rotation_svd` and :func:`numpy.linalg.svd`, which
the tests compare against. The helpers compile with explicit flags (:data:`PLAIN`): numba passes a
caller's ``fastmath`` and ``error_model`` on to callees that do not set them, so they compile the same
whoever calls them first (e.g. the SVD stays bit-identical to the shared Jacobi solver, and
the lanes of :func:`polar_lanes` to each other).

Example
-------
>>> import numpy as np
>>> u, s, v = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
>>> svd_rot(np.diag([2.0, 1.0, 0.5]), 3, u, s, v, np.empty((4, 3, 3)))
>>> s.tolist()
[2.0, 1.0, 0.5]
"""

from __future__ import annotations

import math

from numba import njit

from unmesh._linalg_kernels import jacobi_eigh
from unmesh.sph._kernels import PLAIN

#: Clamp of singular values when inverting A for the next assignment.
SIG_LO = 0.2
SIG_HI = 5.0


@njit(cache=True)
def sym_eig3(a, vec, val, b):
    """Eigen-decomposition of the symmetric 3×3 ``a`` by cyclic Jacobi (descending).

    Writes eigenvectors (columns of ``vec``, ``det = +1``) and eigenvalues ``val``;
    ``b`` (3, 3) is scratch.
    """
    for p in range(3):
        for q in range(3):
            b[p, q] = a[p, q]
    jacobi_eigh(b, vec)
    for k in range(3):
        val[k] = b[k, k]
    _sort_desc(vec, val)


@njit(**PLAIN)
def _sort_desc(vec, val):
    """Sort eigenvalues descending (columns of ``vec`` along) and make ``det vec = +1``."""
    for i in range(2):
        best = i
        for j in range(i + 1, 3):
            if val[j] > val[best]:
                best = j
        if best != i:
            tmp = val[i]
            val[i] = val[best]
            val[best] = tmp
            for k in range(3):
                tmp = vec[k, i]
                vec[k, i] = vec[k, best]
                vec[k, best] = tmp
    det = (vec[0, 0] * (vec[1, 1] * vec[2, 2] - vec[1, 2] * vec[2, 1])
           - vec[0, 1] * (vec[1, 0] * vec[2, 2] - vec[1, 2] * vec[2, 0])
           + vec[0, 2] * (vec[1, 0] * vec[2, 1] - vec[1, 1] * vec[2, 0]))
    if det < 0.0:
        for k in range(3):
            vec[k, 2] = -vec[k, 2]


@njit(cache=True)
def _orthonormal_to(u, col, ref):
    """Unit vector orthogonal to column ``ref`` of ``u`` written into column ``col``."""
    ax = 0
    if abs(u[1, ref]) < abs(u[ax, ref]):
        ax = 1
    if abs(u[2, ref]) < abs(u[ax, ref]):
        ax = 2
    d = u[ax, ref]
    n2 = 0.0
    for k in range(3):
        u[k, col] = (1.0 if k == ax else 0.0) - d * u[k, ref]
        n2 += u[k, col] * u[k, col]
    n = math.sqrt(n2)
    for k in range(3):
        u[k, col] /= n


@njit(**PLAIN)
def _rot2(c, s, a, b):
    """Plane rotation of the pair ``(a, b)``: ``(c a − s b, s a + c b)``."""
    return c * a - s * b, s * a + c * b


@njit(**PLAIN)
def _angle(bpp, bqq, apq):
    """Cosine and sine of the Jacobi rotation that annihilates ``apq`` (as :func:`jacobi_eigh`)."""
    theta = (bqq - bpp) / (2.0 * apq)
    t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
    if theta < 0.0:
        t = -t
    c = 1.0 / math.sqrt(t * t + 1.0)
    return c, t * c


@njit(cache=True)
def jacobi3(b00, b01, b02, b10, b11, b12, b20, b21, b22):
    """Cyclic Jacobi eigen-decomposition of a symmetric 3×3 matrix held in scalars.

    The same rotations, in the same order and with the same floating-point
    operations as :func:`unmesh._linalg_kernels.jacobi_eigh` (at most 30 sweeps, stop
    when the off-diagonal mass is below ``1e-32`` of the diagonal's), unrolled so the
    matrix stays in registers: the results are bit-identical.

    Returns
    -------
    tuple of 12 floats
        Eigenvalues ``l0, l1, l2`` (unsorted) and the eigenvector matrix ``V`` row by row
        (column ``k`` is the eigenvector of ``l_k``).

    Example
    -------
    >>> jacobi3(2.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 1.0)[:3]
    (2.0, 3.0, 1.0)
    """
    v00 = 1.0
    v01 = 0.0
    v02 = 0.0
    v10 = 0.0
    v11 = 1.0
    v12 = 0.0
    v20 = 0.0
    v21 = 0.0
    v22 = 1.0
    for _sweep in range(30):
        diag = b00 * b00 + b11 * b11 + b22 * b22
        off = b01 * b01 + b02 * b02 + b12 * b12
        if off <= 1e-32 * diag or off == 0.0:
            break
        if b01 != 0.0:  # (p, q) = (0, 1)
            c, s = _angle(b00, b11, b01)
            b00, b01 = _rot2(c, s, b00, b01)
            b10, b11 = _rot2(c, s, b10, b11)
            b20, b21 = _rot2(c, s, b20, b21)
            b00, b10 = _rot2(c, s, b00, b10)
            b01, b11 = _rot2(c, s, b01, b11)
            b02, b12 = _rot2(c, s, b02, b12)
            v00, v01 = _rot2(c, s, v00, v01)
            v10, v11 = _rot2(c, s, v10, v11)
            v20, v21 = _rot2(c, s, v20, v21)
        if b02 != 0.0:  # (0, 2)
            c, s = _angle(b00, b22, b02)
            b00, b02 = _rot2(c, s, b00, b02)
            b10, b12 = _rot2(c, s, b10, b12)
            b20, b22 = _rot2(c, s, b20, b22)
            b00, b20 = _rot2(c, s, b00, b20)
            b01, b21 = _rot2(c, s, b01, b21)
            b02, b22 = _rot2(c, s, b02, b22)
            v00, v02 = _rot2(c, s, v00, v02)
            v10, v12 = _rot2(c, s, v10, v12)
            v20, v22 = _rot2(c, s, v20, v22)
        if b12 != 0.0:  # (1, 2)
            c, s = _angle(b11, b22, b12)
            b01, b02 = _rot2(c, s, b01, b02)
            b11, b12 = _rot2(c, s, b11, b12)
            b21, b22 = _rot2(c, s, b21, b22)
            b10, b20 = _rot2(c, s, b10, b20)
            b11, b21 = _rot2(c, s, b11, b21)
            b12, b22 = _rot2(c, s, b12, b22)
            v01, v02 = _rot2(c, s, v01, v02)
            v11, v12 = _rot2(c, s, v11, v12)
            v21, v22 = _rot2(c, s, v21, v22)
    return b00, b11, b22, v00, v01, v02, v10, v11, v12, v20, v21, v22


@njit(**PLAIN)
def svd_rot(a, dim, u, s, v, work):
    """``A = U diag(s) Vᵀ`` with ``det U = det V = +1`` (last ``s`` signed), eq. (8.24).

    2D decomposes the upper 2×2 block (closed form via the polar angle); the z
    row/column of ``U``, ``V`` is the identity and ``s[2] = 1``. 3D diagonalises
    ``AᵀA`` by Jacobi rotations. ``work`` (4, 3, 3) is scratch.
    """
    if dim == 2:
        theta = math.atan2(a[1, 0] - a[0, 1], a[0, 0] + a[1, 1])
        c = math.cos(theta)
        sn = math.sin(theta)
        # symmetric S = R^T A
        p = c * a[0, 0] + sn * a[1, 0]
        q = c * a[0, 1] + sn * a[1, 1]
        r = -sn * a[0, 1] + c * a[1, 1]
        phi = 0.5 * math.atan2(2.0 * q, p - r)
        cp = math.cos(phi)
        sp = math.sin(phi)
        mean = 0.5 * (p + r)
        rad = math.sqrt(0.25 * (p - r) * (p - r) + q * q)
        s[0] = mean + rad
        s[1] = mean - rad
        s[2] = 1.0
        for i in range(3):
            for j in range(3):
                u[i, j] = 0.0
                v[i, j] = 0.0
        v[0, 0] = cp
        v[1, 0] = sp
        v[0, 1] = -sp
        v[1, 1] = cp
        v[2, 2] = 1.0
        # U = R V
        u[0, 0] = c * cp - sn * sp
        u[1, 0] = sn * cp + c * sp
        u[0, 1] = -c * sp - sn * cp
        u[1, 1] = -sn * sp + c * cp
        u[2, 2] = 1.0
        return
    ata = work[0]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += a[k, i] * a[k, j]
            ata[i, j] = acc
    lam = work[1, 0]
    (lam[0], lam[1], lam[2], v[0, 0], v[0, 1], v[0, 2], v[1, 0], v[1, 1], v[1, 2], v[2, 0], v[2, 1],
     v[2, 2]) = jacobi3(ata[0, 0], ata[0, 1], ata[0, 2], ata[1, 0], ata[1, 1], ata[1, 2], ata[2, 0], ata[2, 1],
                        ata[2, 2])
    _sort_desc(v, lam)
    av = work[3]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += a[i, k] * v[k, j]
            av[i, j] = acc
    n0 = math.sqrt(av[0, 0] ** 2 + av[1, 0] ** 2 + av[2, 0] ** 2)
    if n0 > 1e-300:
        for k in range(3):
            u[k, 0] = av[k, 0] / n0
    else:
        for k in range(3):
            u[k, 0] = v[k, 0]
    d = u[0, 0] * av[0, 1] + u[1, 0] * av[1, 1] + u[2, 0] * av[2, 1]
    t0 = av[0, 1] - d * u[0, 0]
    t1 = av[1, 1] - d * u[1, 0]
    t2 = av[2, 1] - d * u[2, 0]
    n1 = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if n1 > 1e-12 * max(n0, 1e-300):
        u[0, 1] = t0 / n1
        u[1, 1] = t1 / n1
        u[2, 1] = t2 / n1
    else:
        _orthonormal_to(u, 1, 0)
    u[0, 2] = u[1, 0] * u[2, 1] - u[2, 0] * u[1, 1]
    u[1, 2] = u[2, 0] * u[0, 1] - u[0, 0] * u[2, 1]
    u[2, 2] = u[0, 0] * u[1, 1] - u[1, 0] * u[0, 1]
    for j in range(3):
        s[j] = u[0, j] * av[0, j] + u[1, j] * av[1, j] + u[2, j] * av[2, j]


@njit(**PLAIN)
def _inv3(m, out):
    """Inverse of a 3×3 matrix; returns the determinant (0 leaves ``out`` unchanged)."""
    c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
    c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
    c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
    det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
    if det == 0.0:
        return 0.0
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[1, 0] = c01 * inv
    out[2, 0] = c02 * inv
    out[0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) * inv
    out[1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) * inv
    out[2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) * inv
    out[0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) * inv
    out[1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) * inv
    out[2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) * inv
    return det


@njit(cache=True, inline="always")
def sym_adjugate(s00, s01, s02, s11, s12, s22):
    """Adjugate (cofactor matrix) and determinant of the symmetric 3×3 matrix with the given upper
    triangle: ``(c00, c01, c02, c11, c12, c22, det)``; ``S⁻¹ = adj(S) / det``. Scalars in and out
    (inlined: stays in registers, vectorises in a loop over matrices).

    Example
    -------
    >>> sym_adjugate(2.0, 0.0, 0.0, 4.0, 0.0, 1.0)
    (4.0, 0.0, 0.0, 2.0, 0.0, 8.0, 8.0)
    """
    c00 = s11 * s22 - s12 * s12
    c01 = s12 * s02 - s01 * s22
    c02 = s01 * s12 - s11 * s02
    c11 = s00 * s22 - s02 * s02
    c12 = s01 * s02 - s00 * s12
    c22 = s00 * s11 - s01 * s01
    return c00, c01, c02, c11, c12, c22, s00 * c00 + s01 * c01 + s02 * c02


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
