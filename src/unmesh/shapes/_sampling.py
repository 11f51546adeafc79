"""Maximal Poisson-disk sampling of an implicit surface (used by the blob's surfels).

Curvature-adaptive at sharp convex caps (:func:`poisson_surface`); the shape operator of
the implicit's level set is :func:`principal_curvatures`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from unmesh._csr import csr_entries

__all__ = ["greedy_poisson_reference", "local_spacing", "poisson_surface", "principal_curvatures"]

#: Curvature-adaptive spacing: the local Poisson spacing is at most this many convex curvature
#: radii (``local_spacing``), so a cap sharper than the spacing gets several samples.
CURVATURE_SPACING = 1.0
#: The local spacing is never below this fraction of the nominal spacing.
MIN_SPACING_FRACTION = 0.25
#: Rounds of scattering fine candidates round themselves (reaches caps the candidate mesh cut short).
SCATTER_ROUNDS = 2
#: The local spacing grows at most this much per unit distance from a sharp cap (grading).
GRADING = 0.5


def greedy_poisson_reference(order: np.ndarray, offsets: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Plain Python reference of :func:`unmesh.shapes._kernels.greedy_poisson`."""
    n = len(offsets) - 1
    keep = np.zeros(n, bool)
    blocked = np.zeros(n, bool)
    for i in order:
        if blocked[i]:
            continue
        keep[i] = True
        blocked[indices[offsets[i]:offsets[i + 1]]] = True
    return keep


def principal_curvatures(implicit: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], points: np.ndarray,
                         normals: np.ndarray, eps: float) -> np.ndarray:
    """Principal curvatures (N,2), larger first, of the level set through each point (convex positive).

    The shape operator ``S_ab = t_a . dn/dt_b`` in a tangent frame ``(t_1, t_2)`` of the unit
    normal ``n`` is estimated by central differences of the implicit's unit gradient at
    ``x +- eps t_b`` (error O(eps^2)), symmetrised, and its eigenvalues returned: ``1/R`` twice
    on a sphere of radius R with outward normals, ``(1/r, 0)`` on a cylinder of radius r,
    negative where the surface bends away from its normal (concave).

    Parameters
    ----------
    implicit : callable
        ``implicit(x) -> (values (N,), unit gradients (N,3))``.
    points, normals : numpy.ndarray, shape (N, 3), float64
        Points (on the surface) and their unit normals.
    eps : float
        Difference step (a small fraction of the smallest curvature radius of interest).

    Returns
    -------
    numpy.ndarray, shape (N, 2), float64
        ``kappa_1 >= kappa_2``.
    """
    from unmesh.surfels.cloud import tangent_frame

    t1, t2 = tangent_frame(normals)
    s = np.empty((len(points), 2, 2))
    for b, tb in enumerate((t1, t2)):
        dn = (implicit(points + eps * tb)[1] - implicit(points - eps * tb)[1]) / (2.0 * eps)
        s[:, 0, b] = np.einsum("ij,ij->i", t1, dn)
        s[:, 1, b] = np.einsum("ij,ij->i", t2, dn)
    a, d, off = s[:, 0, 0], s[:, 1, 1], 0.5 * (s[:, 0, 1] + s[:, 1, 0])
    mean, dev = 0.5 * (a + d), np.sqrt(0.25 * (a - d) ** 2 + off**2)
    return np.stack([mean + dev, mean - dev], axis=1)


def local_spacing(curvatures: np.ndarray, spacing: float, factor: float = CURVATURE_SPACING,
                  floor: float = MIN_SPACING_FRACTION) -> np.ndarray:
    """Curvature-adaptive Poisson spacing (N,) at convex caps.

    ``spacing * clip(factor / (kappa_1 spacing), floor, 1)`` where both principal curvatures
    (N,2) are positive (a cap: an ear or toe tip), ``spacing`` elsewhere (flat, ridges,
    saddles, concave blends).
    """
    k = np.where(curvatures[:, 1] > 0.0, curvatures[:, 0], 0.0) * spacing
    frac = np.where(k > factor, factor / np.where(k > factor, k, 1.0), 1.0)
    return spacing * np.maximum(frac, floor)


def _sample_faces(rng: np.random.Generator, a: np.ndarray, b: np.ndarray, c: np.ndarray, weights: np.ndarray,
                  count: int) -> np.ndarray:
    """``count`` points (count,3) on the triangles (a, b, c), triangle chosen with probability ~ weights,
    and their triangles (count,)."""
    tri = rng.choice(len(a), size=count, p=weights / weights.sum())
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    return (1 - r1)[:, None] * a[tri] + (r1 * (1 - r2))[:, None] * b[tri] + (r1 * r2)[:, None] * c[tri], tri


def poisson_surface(vertices: np.ndarray, faces: np.ndarray, spacing: float,
                    implicit: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                    density: float = 6.0, seed: int = 0, iterations: int = 10,
                    adaptive: bool = True) -> np.ndarray:
    """Blue-noise points (N,3) on the zero set of ``implicit``, about ``spacing`` apart.

    ``density`` candidates per ``spacing**2`` of area are drawn uniformly on the
    (fine) mesh ``vertices/faces``, projected onto the exact surface by Newton steps,
    and thinned greedily in a seeded random order with disk radius
    ``0.9 * spacing``: kept points are at least that far apart, and every candidate
    is within that distance of a kept point (a maximal Poisson-disk set).
    Deterministic for a given ``seed``.

    With ``adaptive`` (default) the spacing is refined at convex caps sharper than the
    spacing (the blob's ear tips, curvature radius ~0.007 at scale 1), where a lone sample
    would need a splat about twice the median radius to close the cap:

    - the local spacing ``s(x)`` of :func:`local_spacing` (``CURVATURE_SPACING`` = 1 curvature
      radius ``1/kappa_1`` where both principal curvatures are positive, at least
      ``MIN_SPACING_FRACTION`` of ``spacing``) is evaluated at the mesh vertices whose edges
      bend sharply and at the candidates on their faces, then graded,
      ``s(x) = min_v (s_v + GRADING |x - v|)``, so the refinement reaches up to 1.5 spacings
      round the apex. With neighbours at most ~1.8 s apart (a maximal Poisson-disk set),
      their normals differ by at most ~100 degrees round the cap, within the 120 degrees
      that :func:`unmesh.surfels.estimate_radii` (``smooth=True``) accepts as neighbours;
    - faces needing ``s < spacing`` get extra candidates (a second stream of the same seed)
      up to ``density`` per ``s**2``; the fine candidates are scattered in their tangent
      planes (``SCATTER_ROUNDS`` rounds, up to one spacing) and projected, which reaches a
      cap the candidate mesh cut short;
    - two candidates conflict when they are within ``0.9 (s_i + s_j) / 2``; the original
      candidates are visited first, in their uniform order.

    Where ``s = spacing`` the candidates, their order and the rule are those of the uniform
    sampling, so the samples away from sharp caps are the same points (on the blob only the
    ears change; figures in docs/performance.md, "Blob ear tips, stop 36").
    """
    from unmesh.shapes._kernels import greedy_poisson
    from unmesh.shapes._meshing import project_to_zero
    from unmesh.spatial import radius_neighbors

    rng = np.random.default_rng(seed)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    total = float(areas.sum())
    count = max(16, int(np.ceil(density * total / spacing**2)))
    pts, tri = _sample_faces(rng, a, b, c, areas, count)
    pts = project_to_zero(implicit, pts, spacing, iterations)
    radius = 0.9 * spacing
    order = rng.permutation(count).astype(np.int64)
    local = None
    if adaptive:
        pts, order, local = _refine_caps(implicit, pts, tri, order, vertices, faces, areas, spacing, density,
                                         seed, iterations)
    offsets, indices = radius_neighbors(pts, radius)
    if local is not None and (local < spacing).any():
        offsets, indices = _adaptive_conflicts(pts, local, spacing, offsets, indices)
    keep = greedy_poisson(order, offsets, indices)
    return np.ascontiguousarray(pts[keep])


def _refine_caps(implicit: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], pts: np.ndarray,
                 tri: np.ndarray, order: np.ndarray, vertices: np.ndarray, faces: np.ndarray, areas: np.ndarray, spacing: float,
                 density: float, seed: int, iterations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Extra candidates at sharp caps and the graded local spacing (N,) of all candidates.

    Returns the candidates (originals first, in their order, then the extra ones), the visiting
    order and the local spacing of every candidate (see :func:`poisson_surface`).
    """
    from unmesh.shapes._meshing import project_to_zero
    from unmesh.surfels.cloud import tangent_frame

    eps = 1e-3 * MIN_SPACING_FRACTION * spacing  # well below the finest curvature radius that matters

    def spacing_at(x: np.ndarray) -> np.ndarray:
        return local_spacing(principal_curvatures(implicit, x, implicit(x)[1], eps), spacing)

    # screen: normal curvature along each mesh edge, |n_i - n_j| / |x_i - x_j|; the principal
    # curvatures only where it exceeds a quarter of the refinement threshold at a face's vertex
    vn = implicit(vertices)[1]
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    k_edge = (np.linalg.norm(vn[edges[:, 0]] - vn[edges[:, 1]], axis=1)
              / np.maximum(np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1), 1e-300))
    curved = np.zeros(len(vertices), bool)
    curved[edges[k_edge * spacing > 0.25 * CURVATURE_SPACING].ravel()] = True
    sharp_faces = curved[faces].any(axis=1)
    kv = np.zeros((len(vertices), 2))
    kv[curved] = principal_curvatures(implicit, vertices[curved], vn[curved], eps)
    sv = local_spacing(kv, spacing)
    # candidates need their own curvature only on faces with a sharply curved vertex (the curvature
    # changes by far less than a factor 2 across a face of the candidate mesh)
    sharp = (sharp_faces & (kv[:, 0] * spacing > 0.5 * CURVATURE_SPACING)[faces].any(axis=1))[tri]
    local = np.full(len(pts), spacing)
    local[sharp] = spacing_at(pts[sharp])
    # sources of the sizing field: the vertices and candidates finer than the spacing
    fv, fp = sv < spacing, local < spacing
    src, s_src = np.concatenate([vertices[fv], pts[fp]]), np.concatenate([sv[fv], local[fp]])
    if not len(src):
        return pts, order, local
    # faces that need a finer spacing get extra candidates, up to ``density`` per s**2
    sf = _graded(vertices, sv, src, s_src, spacing)[faces].min(axis=1)
    extra_w = areas * ((spacing / sf) ** 2 - 1.0)
    if extra_w.max() > 0:
        fs = faces[extra_w > 0]
        a, b, c = vertices[fs[:, 0]], vertices[fs[:, 1]], vertices[fs[:, 2]]
        extra = int(np.ceil(density * float(extra_w.sum()) / spacing**2))
        more = _sample_faces(np.random.default_rng([seed, 1]), a, b, c, extra_w[extra_w > 0], extra)[0]
        more = project_to_zero(implicit, more, spacing, iterations)
        order = np.concatenate([order, len(pts) + np.random.default_rng([seed, 2]).permutation(extra)])
        pts = np.concatenate([pts, more])
        local = np.concatenate([local, spacing_at(more)])
    # the candidate mesh may cut a sharp cap short (a cell wider than the cap): scatter copies of
    # the fine candidates in their tangent planes (up to one spacing) and project them
    jit = np.random.default_rng([seed, 3])
    batch = np.arange(len(pts))
    for _ in range(SCATTER_ROUNDS):
        fine = batch[local[batch] < spacing]
        if not len(fine):
            break
        t1, t2 = tangent_frame(implicit(pts[fine])[1])
        rho = spacing * np.sqrt(jit.random(len(fine)))
        phi = 2.0 * np.pi * jit.random(len(fine))
        near = pts[fine] + (rho * np.cos(phi))[:, None] * t1 + (rho * np.sin(phi))[:, None] * t2
        near = project_to_zero(implicit, near, spacing, iterations)
        s_near = spacing_at(near)
        batch = len(pts) + np.arange(len(near))
        order = np.concatenate([order, batch[jit.permutation(len(near))]])
        pts = np.concatenate([pts, near])
        local = np.concatenate([local, s_near])
        src, s_src = np.concatenate([src, near[s_near < spacing]]), np.concatenate([s_src, s_near[s_near < spacing]])
    return pts, order, _graded(pts, local, src, s_src, spacing)


def _graded(pts: np.ndarray, local: np.ndarray, sources: np.ndarray, s_src: np.ndarray,
            spacing: float) -> np.ndarray:
    """``min(local, s_v + GRADING |x - v|)`` over the source points v with ``s_v < spacing``."""
    from unmesh.spatial import radius_neighbors

    fine = np.flatnonzero(s_src < spacing)
    if not len(fine):
        return local
    # no source lowers a point farther than reach = (spacing - s_min) / GRADING: query the points in
    # the sources' bounding box grown by reach (a sorted CSR row per point)
    reach = (spacing - s_src[fine].min()) / GRADING
    lo, hi = sources[fine].min(axis=0) - reach, sources[fine].max(axis=0) + reach
    box = np.flatnonzero(np.all((pts >= lo) & (pts <= hi), axis=1))
    off, ind = radius_neighbors(sources[fine], reach, queries=pts[box])
    nonempty = np.flatnonzero(np.diff(off))
    if not len(nonempty):
        return local
    rows = box[nonempty]
    src = fine[ind]
    cand = s_src[src] + GRADING * np.sqrt(((pts[np.repeat(rows, np.diff(off)[nonempty])] - sources[src]) ** 2).sum(-1))
    out = local.copy()
    out[rows] = np.minimum(local[rows], np.minimum.reduceat(cand, off[nonempty]))
    return out


def _adaptive_conflicts(pts: np.ndarray, local: np.ndarray, spacing: float, offsets: np.ndarray,
                        indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop the pairs of the (symmetric) CSR lists farther apart than ``0.9 (s_i + s_j) / 2``.

    Only the lists of the fine candidates (``s < spacing``) and of their neighbours are
    examined; every other pair keeps the uniform rule of the lists (radius ``0.9 spacing``).
    """
    fine = local < spacing
    f = np.flatnonzero(fine)
    rows = np.unique(np.concatenate([f, indices[csr_entries(offsets, f)[0]]]))  # fine candidates and their neighbours
    pos, r = csr_entries(offsets, rows)
    j = indices[pos]
    check = fine[r] | fine[j]
    pos, r, j = pos[check], r[check], j[check]
    lim = 0.9 * (0.5 * (local[r] + local[j]))
    drop = pos[((pts[r] - pts[j]) ** 2).sum(-1) > lim * lim]
    if not len(drop):
        return offsets, indices
    keep = np.ones(len(indices), bool)
    keep[drop] = False
    removed = np.zeros(len(offsets), np.int64)
    np.add.at(removed, 1 + np.searchsorted(offsets, drop, side="right") - 1, 1)
    return offsets - np.cumsum(removed), np.ascontiguousarray(indices[keep])
