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
from unmesh.mls.surface import MLSSurface, as_surface
from unmesh.spatial._kernels import compute_keys
from unmesh.surfels import SurfelCloud

__all__ = ["inside", "intersect", "project"]

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


def _project_raw(surf: MLSSurface, x: np.ndarray, max_iter: int, tol: float, chunk_size: int,
                 progress: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = len(x)
    points = np.empty((q, 3))
    normals = np.empty((q, 3))
    status = np.empty(q, np.int64)
    args = surf._kernel_args()
    g = surf.grid
    for s in _chunks(q, chunk_size, progress, "MLS projection"):
        e = min(q, s + chunk_size)
        # process the chunk in grid-cell order (memory locality), write back in input order
        order = np.argsort(compute_keys(x[s:e], g.origin, g.inv_cell, g.dims), kind="stable")
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

    Per ray: rays are culled against the bounding box of the samples (padded by the
    kernel support); a start point near the surface is the nearest hit of the ray
    with the surfel discs (radius ``max(r_i, σ_i)``, found by a 3D-DDA walk through
    the cell grid); from there the ray is intersected with the local fit plane of
    the current point until the step is below ``tol·σ`` (Algorithm 3.1, lines 1–5).
    The hit is accepted when ``t > 0`` and ``‖q(x) − x‖ < eps2·σ`` (line 6: the
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
    o = np.ascontiguousarray(np.broadcast_to(o, (r, 3)))
    d = np.ascontiguousarray(np.broadcast_to(d, (r, 3)))
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
    gp, gn, gs, grho = surf._arrays
    ray_grid = surf.ray_grid()
    for s in _chunks(r, chunk_size, progress, "MLS ray casting"):
        e = min(r, s + chunk_size)
        K.intersect_kernel(o[s:e], d[s:e], tm[s:e], gp, gn, gs, grho, *surf._kernel_args()[3:], *ray_grid,
                           max_iter, tol, eps2, int(max_attempts), t[s:e], hit[s:e], nrm[s:e])
    if return_normals:
        return t, hit, nrm
    return t, hit
