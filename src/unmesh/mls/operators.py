"""MLS surface operators: projection (3.1–3.8), inside/outside test (3.9), ray casting (Alg. 3.1).

All three are vectorised over many query points or rays, run in numba (parallel
over queries) and work in chunks, so memory stays bounded for millions of queries.

Corrections to the printed text (the stated property wins, see ``NOTES.md``):

* (3.9) reads ``outside ⇔ (Ψ(x) − x)·N(Ψ(x)) > 0``; the sentence before it ("the
  normal at its projected position points in its direction") and any example
  (a point outside a sphere) need ``(x − Ψ(x))·N(Ψ(x)) > 0``, which is implemented.
* Algorithm 3.1 line 4 prints ``N·(x − q)/(N·d)``; the intersection of the ray
  ``x + t d`` with the plane ``N·(y − q) = 0`` is at ``t = N·(q − x)/(N·d)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, positive_scalar
from unmesh.errors import InputError
from unmesh.mls import _kernels as K
from unmesh.mls import _ray_kernels as RK
from unmesh.mls.surface import MLSSurface, as_surface
from unmesh.surfels import SurfelCloud

__all__ = ["inside", "interpolate", "intersect", "project"]

_CHUNK = 1 << 17


def _chunks(n: int, chunk_size: int, progress: bool, desc: str) -> Any:
    starts = range(0, n, chunk_size)
    if progress and n > chunk_size:
        from tqdm.auto import tqdm

        return tqdm(starts, desc=desc, unit="chunk", total=len(starts))
    return starts


def _chunk_size(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"chunk_size: expected a positive integer, got {value!r}")
    return int(value)


def _max_iter(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"max_iter: expected a positive integer, got {value!r}")
    return int(value)


def _sorted_chunks(surf: MLSSurface, x: np.ndarray, chunk_size: int, progress: bool, desc: str) -> Any:
    """Yield ``(start, end, order)`` per chunk; ``order`` sorts the chunk by cell (memory locality)."""
    q = len(x)
    for s in _chunks(q, chunk_size, progress, desc):
        e = min(q, s + chunk_size)
        yield s, e, np.argsort(surf._locality_keys(x[s:e]), kind="stable")


def _project_raw(surf: MLSSurface, x: np.ndarray, max_iter: int, tol: float, chunk_size: int,
                 progress: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = len(x)
    points = np.empty((q, 3))
    normals = np.empty((q, 3))
    status = np.empty(q, np.int64)
    args = surf._kernel_args()
    for s, e, order in _sorted_chunks(surf, x, chunk_size, progress, "MLS projection"):
        # process the chunk in grid-cell order, write back in input order
        p_c = np.empty((e - s, 3))
        n_c = np.empty((e - s, 3))
        st_c = np.empty(e - s, np.int64)
        K.project_kernel(np.ascontiguousarray(x[s:e][order]), *args, max_iter, tol, p_c, n_c, st_c)
        points[s:e][order] = p_c
        normals[s:e][order] = n_c
        status[s:e][order] = st_c
    return points, normals, status


def project(
    cloud: SurfelCloud | MLSSurface,
    x: Any,
    *,
    max_iter: int = 30,
    tol: float = 1e-7,
    return_converged: bool = False,
    chunk_size: int = _CHUNK,
    progress: bool = False,
    **options: Any,
) -> tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project points onto the MLS surface of a surfel cloud (eqs. 3.1–3.8).

    Each point x is projected orthogonally (Levin's constraint 3.2): starting at
    ``y = x`` the local fit at y — weighted mean q (3.6), plane normal (3.8 or 3.5)
    and, with ``degree=2``, a quadratic height field (3.3) — gives a foot point p and
    normal n, and ``y ← x − (n·(x − p)) n`` is repeated until y moves less than
    ``tol·σ``. The result lies on its own local fit and ``x − y`` is parallel to the
    normal there.

    Parameters
    ----------
    cloud : SurfelCloud or MLSSurface
        The samples, or a prepared surface (then give no surface options).
    x : array_like, shape (Q, 3) or (3,)
        Query points; they must lie within the kernel support (about
        ``cutoff·σ``, see :attr:`MLSSurface.support`) of the samples.
    max_iter : int, default 30
        Iteration limit; typically 3–6 iterations are needed.
    tol : float, default 1e-7
        Convergence tolerance relative to the local kernel width σ.
    return_converged : bool, default False
        Also return a (Q,) bool array, False where the iteration hit ``max_iter``
        (the last iterate is returned there) or where the result is NaN.
    chunk_size : int
        Queries per chunk (bounds temporary memory).
    progress : bool
        Show a progress bar over the chunks.
    **options
        Surface options of :class:`MLSSurface` (``sigma``, ``sigma_factor``,
        ``cutoff``, ``kernel``, ``normal``, ``degree``) when ``cloud`` is a cloud.

    Returns
    -------
    points : numpy.ndarray, shape (Q, 3), float64
        Projected points; NaN rows for queries no kernel reaches (and, rarely, when
        an iterate leaves the support or the sample normals there cancel out).
    normals : numpy.ndarray, shape (Q, 3), float64
        Unit surface normals at the projected points, oriented like the sample
        normals; NaN where the points are NaN.
    converged : numpy.ndarray, shape (Q,), bool
        Only with ``return_converged=True``.

    Raises
    ------
    unmesh.errors.InputError
        On bad arguments, or when not a single query lies within the support.

    Example
    -------
    >>> import numpy as np
    >>> from unmesh.surfels import SurfelCloud
    >>> g = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11)), -1).reshape(-1, 2) * 0.1
    >>> plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.1))
    >>> p, n = project(plane, [[0.03, 0.02, 0.2]])
    >>> p.round(6), n.round(6)
    (array([[0.03, 0.02, 0.  ]]), array([[0., 0., 1.]]))
    """
    surf = as_surface(cloud, **options)
    pts = as_points(x, "x")
    max_iter = _max_iter(max_iter)
    tol = positive_scalar(tol, "tol")
    chunk_size = _chunk_size(chunk_size)
    points, normals, status = _project_raw(surf, pts, max_iter, tol, chunk_size, progress)
    bad = np.isnan(points[:, 0])
    if len(pts) and bad.all():
        raise InputError(
            f"x: none of the {len(pts)} query points lies within the kernel support "
            f"({surf.support:.4g}) of the samples; move them closer to the surface or widen sigma"
        )
    if return_converged:
        return points, normals, status == K.CONVERGED
    return points, normals


def inside(
    cloud: SurfelCloud | MLSSurface,
    x: Any,
    *,
    max_iter: int = 30,
    tol: float = 1e-7,
    chunk_size: int = _CHUNK,
    progress: bool = False,
    **options: Any,
) -> np.ndarray:
    """Inside/outside test of the MLS surface (eq. 3.9, sign corrected).

    A point is outside when the surface normal at its projection points towards it:
    ``(x − Ψ(x))·N(Ψ(x)) > 0``. Points on the surface count as inside. The test is
    reliable near the surface (within the kernel support), as the thesis notes.
    Points that no kernel reaches are classified by their nearest sample j instead:
    outside when ``(x − x_j)·n_j > 0`` (exact for convex shapes, a good guess for
    points far from a closed surface).

    Parameters
    ----------
    cloud : SurfelCloud or MLSSurface
    x : array_like, shape (Q, 3) or (3,)
    max_iter, tol, chunk_size, progress, **options
        As for :func:`project`.

    Returns
    -------
    numpy.ndarray, shape (Q,), bool
        True inside.

    Example
    -------
    >>> import numpy as np
    >>> from unmesh.surfels import SurfelCloud
    >>> g = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11)), -1).reshape(-1, 2) * 0.1
    >>> plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.1))
    >>> inside(plane, [[0, 0, 0.05], [0, 0, -0.05], [0, 0, -5.0]]).tolist()
    [False, True, True]
    """
    surf = as_surface(cloud, **options)
    pts = as_points(x, "x")
    points, normals, _ = _project_raw(surf, pts, _max_iter(max_iter), positive_scalar(tol, "tol"),
                                      _chunk_size(chunk_size), progress)
    side = np.einsum("ij,ij->i", pts - points, normals)
    far = np.isnan(side)
    if far.any():
        from unmesh.spatial import knn

        _, idx = knn(surf.cloud.positions, 1, queries=pts[far])
        j = idx[:, 0]
        side[far] = np.einsum("ij,ij->i", pts[far] - surf.cloud.positions[j], surf.cloud.normals[j])
    return ~(side > 0)


def intersect(
    cloud: SurfelCloud | MLSSurface,
    origins: Any,
    directions: Any,
    tmax: Any = np.inf,
    *,
    return_normals: bool = False,
    max_iter: int = 30,
    tol: float = 1e-7,
    eps2: float = 0.5,
    max_attempts: int = 32,
    chunk_size: int = _CHUNK,
    progress: bool = False,
    **options: Any,
) -> tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First intersection of rays ``o + t d`` (``0 < t <= tmax``) with the MLS surface (Algorithm 3.1).

    Per ray: a start point near the surface is the nearest hit of the ray with the
    surfel discs (radius ``max(r_i, σ_i)``, found by 3D-DDA walks with empty-space
    skipping through the ray grids of :meth:`MLSSurface.ray_grid`, one per
    power-of-two band of disc radii); from there the ray is intersected with the
    local fit plane of the current point until the step is below ``tol·σ``
    (Algorithm 3.1, lines 1–5); where these plane steps oscillate (they can fall into a
    2-cycle at creases and folds of scanned models, which left isolated unhit pixels),
    two iterates with steps of opposite sign bracket the surface and the iteration
    continues by regula falsi (Illinois) inside the bracket. The hit is accepted when ``t > 0`` and ``‖q(x) − x‖ < eps2·σ`` (line 6: the
    point is near its weighted mean, i.e. not on a plane extrapolated past the
    samples). Otherwise the search continues behind the failed start, at most
    ``max_attempts`` times. With the default ``degree=2`` the planes are the tangent
    planes of the quadratic fits, so hits lie on the same surface as
    :func:`project` returns.

    Parameters
    ----------
    cloud : SurfelCloud or MLSSurface
        Samples, or a prepared surface (build one once for repeated calls).
    origins : array_like, shape (R, 3) or (3,)
        Ray origins (a single origin is broadcast to all rays).
    directions : array_like, shape (R, 3) or (3,)
        Ray directions, non-zero; need not be unit length (t is in units of |d|).
    tmax : float or array_like (R,), default inf
        Largest accepted t per ray (> 0).
    return_normals : bool, default False
        Also return the unit surface normals at the hits (oriented like the sample
        normals, i.e. outwards for a consistently oriented closed surface).
    max_iter : int, default 30
        Iterations per start point.
    tol : float, default 1e-7
        Convergence tolerance on the step, relative to σ.
    eps2 : float, default 0.5
        Acceptance threshold ε₂ of Algorithm 3.1, relative to σ.
    max_attempts : int, default 32
        Start points tried per ray.
    chunk_size, progress, **options
        As for :func:`project`.

    Returns
    -------
    t : numpy.ndarray, shape (R,), float64
        Ray parameter of the first hit; ``inf`` where there is none.
    hit : numpy.ndarray, shape (R,), bool
    normals : numpy.ndarray, shape (R, 3), float64
        Only with ``return_normals=True``; NaN rows for misses.

    Example
    -------
    >>> import numpy as np
    >>> from unmesh.surfels import SurfelCloud
    >>> g = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11)), -1).reshape(-1, 2) * 0.1
    >>> plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.1))
    >>> t, hit = intersect(plane, [[0.1, 0.2, 1.0], [5.0, 0, 1]], [[0, 0, -1.0], [0, 0, -1]])
    >>> t.round(6).tolist(), hit.tolist()
    ([1.0, inf], [True, False])
    """
    surf = as_surface(cloud, **options)
    o = as_points(origins, "origins")
    d = as_points(directions, "directions")
    r = max(len(o), len(d))
    if len(o) not in (1, r) or len(d) not in (1, r):
        raise InputError(f"origins, directions: expected the same number of rays, got {len(o)} and {len(d)}")
    # writable C copies: a read-only view (broadcast_to) would compile a second kernel signature
    o = np.require(np.broadcast_to(o, (r, 3)), np.float64, ["C", "W"])
    d = np.require(np.broadcast_to(d, (r, 3)), np.float64, ["C", "W"])
    dl = np.linalg.norm(d, axis=1)
    if (dl <= 0).any():
        raise InputError(f"directions: expected non-zero vectors, got a zero vector at index {int(np.argmin(dl))}")
    tm = np.asarray(tmax, dtype=np.float64)
    if tm.ndim == 0:
        tm = np.full(r, float(tm))
    tm = as_array(tm, "tmax", (None,), finite=False, length=r)
    if np.isnan(tm).any() or (tm <= 0).any():
        raise InputError("tmax: expected positive values (inf allowed), got a NaN or a value <= 0")
    max_iter = _max_iter(max_iter)
    tol = positive_scalar(tol, "tol")
    eps2 = positive_scalar(eps2, "eps2")
    if isinstance(max_attempts, bool) or not isinstance(max_attempts, int | np.integer) or max_attempts < 1:
        raise InputError(f"max_attempts: expected a positive integer, got {max_attempts!r}")
    chunk_size = _chunk_size(chunk_size)
    t = np.empty(r)
    hit = np.empty(r, dtype=bool)
    nrm = np.empty((r, 3))
    args = surf._kernel_args()
    grho = surf._arrays[1]
    ray_grid = surf.ray_grid()
    for s in _chunks(r, chunk_size, progress, "MLS ray casting"):
        e = min(r, s + chunk_size)
        RK.intersect_kernel(o[s:e], d[s:e], tm[s:e], *args, grho, float(grho.max()), surf.support, *ray_grid,
                           max_iter, tol, eps2, int(max_attempts), t[s:e], hit[s:e], nrm[s:e])
    if return_normals:
        return t, hit, nrm
    return t, hit


def interpolate(
    surface: SurfelCloud | MLSSurface,
    points: Any,
    values: Any,
    *,
    chunk_size: int = _CHUNK,
    progress: bool = False,
    **options: Any,
) -> np.ndarray:
    """MLS-weighted interpolation of per-surfel attributes at arbitrary points (eqs. 3.6, 3.10–3.12).

    ``v(x) = Σ_i w_i(x) v_i / Σ_i w_i(x)`` with the weights ``w_i(x) = φ(‖x − x_i‖/σ_i)``
    of the surface's local fit (the weights of the weighted mean q, eq. 3.6: clipped
    Gaussian 3.10–3.11 or Wendland 3.12, support ``cutoff·σ_i``). Typical use: colours
    or any other attribute at points on the MLS surface (ray hits, projected points).
    Points that no kernel reaches take the value of their nearest surfel.

    Parameters
    ----------
    surface : SurfelCloud or MLSSurface
        The samples, or a prepared surface (then give no surface options).
    points : array_like, shape (M, 3) or (3,)
        Where to interpolate.
    values : array_like, shape (N,) or (N, k)
        One value (or row of k values) per surfel, in the cloud's order; converted to
        float64.
    chunk_size, progress, **options
        As for :func:`project`.

    Returns
    -------
    numpy.ndarray, shape (M,) or (M, k), float64
        The interpolated values (the shape of ``values`` with N replaced by M).

    Raises
    ------
    unmesh.errors.InputError
        On bad arguments, e.g. ``values`` without one row per surfel.

    Example
    -------
    >>> import numpy as np
    >>> from unmesh.surfels import SurfelCloud
    >>> c = SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]] * 2, radii=[0.5, 0.5])
    >>> interpolate(c, [[0.5, 0, 0], [0.1, 0, 0]], [[1.0, 0, 0], [0, 0, 1.0]]).round(3).tolist()
    [[0.5, 0.0, 0.5], [0.69, 0.0, 0.31]]
    >>> interpolate(c, [[9.0, 0, 0]], [10.0, 20.0]).tolist()  # out of reach: nearest surfel
    [20.0]
    """
    surf = as_surface(surface, **options)
    pts = as_points(points, "points")
    n = len(surf.cloud)
    try:
        vals = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"values: expected a numeric array of shape ({n},) or ({n}, k), got {exc}") from None
    if vals.ndim not in (1, 2) or len(vals) != n:
        raise InputError(f"values: expected shape ({n},) or ({n}, k) (one row per surfel), got {vals.shape}")
    flat = vals.ndim == 1
    table = np.ascontiguousarray(vals.reshape(n, -1)[surf._order])
    chunk_size = _chunk_size(chunk_size)
    m = len(pts)
    out = np.empty((m, table.shape[1]))
    found = np.empty(m, dtype=bool)
    args = surf._kernel_args()
    for s, e, order in _sorted_chunks(surf, pts, chunk_size, progress, "MLS interpolation"):
        o_c = np.empty((e - s, table.shape[1]))
        f_c = np.empty(e - s, dtype=bool)
        K.interpolate_kernel(np.ascontiguousarray(pts[s:e][order]), table, args[0], args[1], *args[4:], o_c, f_c)
        out[s:e][order] = o_c
        found[s:e][order] = f_c
    if not found.all():
        from unmesh.spatial import knn

        _, idx = knn(surf.cloud.positions, 1, queries=pts[~found])
        out[~found] = vals.reshape(n, -1)[idx[:, 0]]
    return out[:, 0] if flat else out
