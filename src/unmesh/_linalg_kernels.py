"""Small dense linear algebra shared by the numba kernels of every capability (bottom layer).

One implementation per algorithm, each tested against numpy (``tests/test_linalg_kernels.py``):

* :func:`jacobi_eigh` diagonalises a small symmetric matrix in place by cyclic Jacobi rotations
  (Golub & Van Loan, section 8.5): the polar decompositions of SPH shape matching (thesis 8.24,
  3×3) and Horn's absolute orientation for FEM stiffness warping (9.1.4, 4×4,
  :func:`jacobi_eigh4`). :func:`jacobi3` is the same rotations unrolled in scalars for 3×3
  (bit-identical, in registers); :func:`sym_eig3` sorts its result. Reference:
  ``numpy.linalg.eigh``.
* :func:`svd_rot`: 3×3 (and 2×2) SVD ``A = U diag(s) Vᵀ`` with rotations ``U``, ``V``, the polar
  decomposition ``A = (U Vᵀ)(V diag(s) Vᵀ)`` of SPH shape matching (8.24). Reference:
  ``numpy.linalg.svd``.
* :func:`inv3` (3×3 inverse and determinant), :func:`sym_adjugate` (symmetric 3×3 adjugate).
  Reference: ``numpy.linalg.inv``.
* :func:`smallest_eigenvector` (:func:`smallest_eigenvectors` for a stack): closed-form unit
  eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix, for normal estimation,
  MLS (3.5) and shell skinning (7.26); :func:`smallest_eigenvector_sel` is the same
  implementation evaluated for vectorised fast-math loops (polynomial :func:`atan2` and cos).
  Reference: ``numpy.linalg.eigh``.

Helpers called from kernels compiled with other flags set theirs explicitly (:data:`PLAIN`):
numba passes a caller's ``fastmath`` and ``error_model`` on to callees that do not set them, so
they compile the same whoever calls them first (e.g. :func:`svd_rot` stays bit-identical to
:func:`jacobi_eigh`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["FASTMATH", "PLAIN", "atan2", "inv3", "jacobi3", "jacobi_eigh", "jacobi_eigh4", "smallest_eigenvector",
           "smallest_eigenvector_sel", "smallest_eigenvectors", "smallest_eigenvectors_sel", "svd_rot", "sym_adjugate",
           "sym_eig3"]

#: Explicit compile flags of helpers shared by kernels with different flags (strict IEEE arithmetic).
PLAIN = {"cache": True, "fastmath": False, "error_model": "python"}

#: Fast-math flags of the vectorised loops (shells): FMA contraction, reciprocal and reassociation;
#: NaN/inf semantics kept.
FASTMATH = {"nsz", "arcp", "contract", "reassoc"}


@njit(cache=True)
def jacobi_eigh(b, vec, sweeps=30):  # pragma: no cover - numba
    """Diagonalise the symmetric (n, n) ``b`` in place; ``vec`` (n, n) receives the eigenvectors.

    On return ``b[k, k]`` are the eigenvalues (unsorted) and column ``k`` of ``vec`` the unit
    eigenvector of ``b[k, k]``. Stops when the off-diagonal mass is below ``1e-32`` of the
    diagonal's (or zero), after at most ``sweeps`` sweeps.

    Example
    -------
    >>> import numpy as np
    >>> b, v = np.diag([3.0, 1.0, 2.0]), np.empty((3, 3))
    >>> jacobi_eigh(b, v); sorted(np.diag(b).tolist())
    [1.0, 2.0, 3.0]
    """
    n = b.shape[0]
    for p in range(n):
        for q in range(n):
            vec[p, q] = 1.0 if p == q else 0.0
    for _sweep in range(sweeps):
        off = 0.0
        diag = 0.0
        for p in range(n):
            diag += b[p, p] * b[p, p]
            for q in range(p + 1, n):
                off += b[p, q] * b[p, q]
        if off <= 1e-32 * diag or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = b[p, q]
                if apq == 0.0:
                    continue
                theta = (b[q, q] - b[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):  # b = b J
                    bkp = b[k, p]
                    bkq = b[k, q]
                    b[k, p] = c * bkp - s * bkq
                    b[k, q] = s * bkp + c * bkq
                for k in range(n):  # b = J^T b
                    bpk = b[p, k]
                    bqk = b[q, k]
                    b[p, k] = c * bpk - s * bqk
                    b[q, k] = s * bpk + c * bqk
                for k in range(n):
                    vkp = vec[k, p]
                    vkq = vec[k, q]
                    vec[k, p] = c * vkp - s * vkq
                    vec[k, q] = s * vkp + c * vkq


@njit(cache=True)
def jacobi_eigh4(N):
    """Eigenvalues (4,) and eigenvectors (columns, 4×4) of a symmetric 4×4 matrix (cyclic Jacobi).

    Example
    -------
    >>> import numpy as np
    >>> w, v = jacobi_eigh4(np.diag([1.0, 4.0, 2.0, 3.0]))
    >>> sorted(w.tolist())
    [1.0, 2.0, 3.0, 4.0]
    """
    A = N.copy()
    V = np.empty((4, 4))
    jacobi_eigh(A, V)
    w = np.empty(4)
    for i in range(4):
        w[i] = A[i, i]
    return w, V


# -- 3×3 symmetric eigenproblem, SVD, inverse ------------------------------------------------


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
def inv3(m, out):
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


# -- polynomial atan2 (branch-free; the shell kernels' too) -------------------------------------


#: Coefficients of the rational approximation ``atan(t) = t + t z P(z)/Q(z)``, ``z = t^2``, on
#: ``|t| <= 0.66`` (Cephes ``atan``; leading coefficient of Q is 1), and the low part of pi/2.
_ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
           -1.228866684490136173410e2, -6.485021904942025371773e1)
_ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
           4.853903996359136964868e2, 1.945506571482613964425e2)
_PIO2_LO = 6.123233995736765886130e-17


@njit(cache=True, inline="always")
def atan2(y, x):
    """``atan2(y, x)`` within 2 ulp of the C library's, without a library call (no branches but
    selects; reference ``numpy.arctan2``, tested). ``atan2(0, 0) = 0``; the sign of a zero ``y``
    is not looked at (the results -pi and pi are the same angle)."""
    p0, p1, p2, p3, p4 = _ATAN_P
    q0, q1, q2, q3, q4 = _ATAN_Q
    ax = abs(x)
    ay = abs(y)
    mx = max(ax, ay)
    mn = min(ax, ay)
    big = mn > 0.66 * mx               # reduce atan(t) = pi/4 + atan((t - 1)/(t + 1)), t = mn/mx
    num = mn - mx if big else mn
    den = mn + mx if big else mx
    t = num / den if den > 0.0 else 0.0
    z = t * t
    p = (((p0 * z + p1) * z + p2) * z + p3) * z + p4
    q = ((((z + q0) * z + q1) * z + q2) * z + q3) * z + q4
    r = t + t * (z * p / q)
    r = r + (0.25 * math.pi + 0.5 * _PIO2_LO) if big else r
    r = (0.5 * math.pi + _PIO2_LO) - r if ay > ax else r
    r = math.pi - r if x < 0.0 else r
    return -r if y < 0.0 else r


@njit(cache=True)
def atan2_batch(y, x, out):
    """:func:`atan2` elementwise (for tests)."""
    for k in range(y.shape[0]):
        out[k] = atan2(y[k], x[k])


# -- smallest eigenvector (normals, MLS, skinning) --------------------------------------------


#: Taylor coefficients (-1)^k / (2k)! of cos, k = 0 .. 9 (exact to round-off on [0, pi/3]).
_COS = (1.0, -0.5, 1.0 / 24, -1.0 / 720, 1.0 / 40320, -1.0 / 3628800, 1.0 / 479001600, -1.0 / 87178291200,
        1.0 / 20922789888000, -1.0 / 6402373705728000)


@njit(cache=True, inline="always")
def _cos_small(y):
    """cos(y) for |y| <= pi/3 (Taylor polynomial to y^18)."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9 = _COS
    z = y * y
    return c0 + z * (c1 + z * (c2 + z * (c3 + z * (c4 + z * (c5 + z * (c6 + z * (c7 + z * (c8 + z * c9))))))))


@njit(cache=True, inline="always")
def _smallest_eigenvector(a00, a01, a02, a11, a12, a22, fast):  # pragma: no cover - numba
    """The one implementation of :func:`smallest_eigenvector` (``fast`` False) and
    :func:`smallest_eigenvector_sel` (``fast`` True, a constant: the other path compiles away).

    Closed-form eigenvalues (trigonometric solution of the characteristic cubic) of the
    matrix scaled to unit max-norm, then the eigenvector as the largest cross product of two
    rows of ``A - l I``, chosen by selects (no branches). ``fast`` scales by the reciprocal
    and evaluates atan2 and cos as polynomials (within round-off) so a loop over matrices
    vectorises; otherwise the library functions and divisions.
    """
    s = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    if fast:
        inv_s0 = 1.0 / s
        inv_s = inv_s0 if s > 0.0 else 0.0
        a00 *= inv_s
        a01 *= inv_s
        a02 *= inv_s
        a11 *= inv_s
        a12 *= inv_s
        a22 *= inv_s
        m = (a00 + a11 + a22) * (1.0 / 3.0)
    else:
        if s != 0.0:            # s == 0: the matrix is zero already (and the result (0, 0, 1))
            a00 /= s
            a01 /= s
            a02 /= s
            a11 /= s
            a12 /= s
            a22 /= s
        m = (a00 + a11 + a22) / 3.0
    k00 = a00 - m
    k11 = a11 - m
    k22 = a22 - m
    if fast:
        p = (k00 * k00 + k11 * k11 + k22 * k22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) * (1.0 / 6.0)
    else:
        p = (k00 * k00 + k11 * k11 + k22 * k22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0
    q = 0.5 * (k00 * (k11 * k22 - a12 * a12) - a01 * (a01 * k22 - a12 * a02) + a02 * (a01 * a12 - k11 * a02))
    sp = math.sqrt(max(p, 0.0))
    if fast:
        phi = atan2(math.sqrt(max(p * p * p - q * q, 0.0)), q) * (1.0 / 3.0)
        lam = m - 2.0 * sp * _cos_small(math.pi / 3.0 - phi)          # cos(phi + 2 pi/3) = -cos(pi/3 - phi)
    else:
        phi = math.atan2(math.sqrt(max(p * p * p - q * q, 0.0)), q) / 3.0
        lam = m + 2.0 * sp * math.cos(phi + 2.0 * math.pi / 3.0)
    r0x, r0y, r0z = a00 - lam, a01, a02
    r1x, r1y, r1z = a01, a11 - lam, a12
    r2x, r2y, r2z = a02, a12, a22 - lam
    c0x = r0y * r1z - r0z * r1y
    c0y = r0z * r1x - r0x * r1z
    c0z = r0x * r1y - r0y * r1x
    c1x = r0y * r2z - r0z * r2y
    c1y = r0z * r2x - r0x * r2z
    c1z = r0x * r2y - r0y * r2x
    c2x = r1y * r2z - r1z * r2y
    c2y = r1z * r2x - r1x * r2z
    c2z = r1x * r2y - r1y * r2x
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    l0 = r0x * r0x + r0y * r0y + r0z * r0z
    l1 = r1x * r1x + r1y * r1y + r1z * r1z
    l2 = r2x * r2x + r2y * r2y + r2z * r2z
    lmax = max(l0, l1, l2)
    # |cross| <= 1e-6 |row|^2: the rows are parallel (a repeated smallest eigenvalue).
    tiny = 1e-12 * lmax * lmax + 1e-300
    pick0 = n0 >= n1 and n0 >= n2 and n0 > tiny
    pick1 = not pick0 and n1 >= n2 and n1 > tiny
    pick2 = not pick0 and not pick1 and n2 > tiny
    # rank <= 1: a vector orthogonal to the largest row of A - l I
    big0 = l0 >= l1 and l0 >= l2
    big1 = not big0 and l1 >= l2
    bx = r0x if big0 else (r1x if big1 else r2x)
    by = r0y if big0 else (r1y if big1 else r2y)
    bz = r0z if big0 else (r1z if big1 else r2z)
    bl = l0 if big0 else (l1 if big1 else l2)
    ax = abs(bx)
    ay = abs(by)
    az = abs(bz)
    ox = ax <= ay and ax <= az
    oy = not ox and ay <= az
    wx = 0.0 if ox else (bz if oy else -by)
    wy = -bz if ox else (0.0 if oy else bx)
    wz = by if ox else (-bx if oy else 0.0)
    flat = not (pick0 or pick1 or pick2)
    vx = c0x if pick0 else (c1x if pick1 else (c2x if pick2 else wx))
    vy = c0y if pick0 else (c1y if pick1 else (c2y if pick2 else wy))
    vz = c0z if pick0 else (c1z if pick1 else (c2z if pick2 else wz))
    none = s == 0.0 or (flat and bl <= 1e-30)
    vx = 0.0 if none else vx
    vy = 0.0 if none else vy
    vz = 1.0 if none else vz
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + vz * vz)
    return vx * inv, vy * inv, vz * inv


@njit(cache=True)
def smallest_eigenvector(a00, a01, a02, a11, a12, a22):  # pragma: no cover - numba
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (upper triangle).

    Closed-form eigenvalues (trigonometric solution of the characteristic cubic) of the
    matrix scaled to unit max-norm, then the eigenvector as the largest cross product of two
    rows of ``A - l I``. Where that eigenspace is more than one-dimensional any unit vector in
    it is returned; the zero matrix gives ``(0, 0, 1)``. Shared by normal estimation, MLS
    (3.5) and shell skinning (7.26). Reference: ``numpy.linalg.eigh``.

    Example
    -------
    >>> smallest_eigenvector(2.0, 0.0, 0.0, 3.0, 0.0, 1.0)
    (0.0, 0.0, 1.0)
    """
    return _smallest_eigenvector(a00, a01, a02, a11, a12, a22, False)


@njit(cache=True, fastmath=FASTMATH, error_model="numpy", inline="always")
def smallest_eigenvector_sel(a00, a01, a02, a11, a12, a22):  # pragma: no cover - numba
    """:func:`smallest_eigenvector` vectorisable: reciprocal scaling, polynomial atan2 and cos
    (within round-off), for the fast-math loops of shell skinning (inlined into them)."""
    return _smallest_eigenvector(a00, a01, a02, a11, a12, a22, True)


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def smallest_eigenvectors_sel(cov, out):  # pragma: no cover - numba
    """:func:`smallest_eigenvector_sel` of every symmetric matrix (S, 3, 3) into ``out`` (S, 3) (for tests)."""
    for k in range(cov.shape[0]):
        c = cov[k]
        out[k, 0], out[k, 1], out[k, 2] = smallest_eigenvector_sel(c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2])


@njit(cache=True, parallel=True)
def smallest_eigenvectors(cov):  # pragma: no cover - numba
    """Unit eigenvector (N,3) of the smallest eigenvalue of each symmetric 3x3 matrix (N,3,3)
    (:func:`smallest_eigenvector` per matrix). Reference: ``numpy.linalg.eigh``.
    """
    n = cov.shape[0]
    out = np.empty((n, 3))
    for i in prange(n):
        c = cov[i]
        vx, vy, vz = smallest_eigenvector(c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2])
        out[i, 0] = vx
        out[i, 1] = vy
        out[i, 2] = vz
    return out
