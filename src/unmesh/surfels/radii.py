"""Surfel radii that make the splats cover the surface (thesis section 3.3).

For splatting "the surfels have to be close enough that their reconstruction
kernels overlap. If this is not the case, holes appear in the surface"
(section 3.3, Figure 3.5). unmesh chooses each radius as the smallest one that
provably covers the surfel's own share of the surface in its tangent plane:

**Rule (restricted Voronoi radius).** The cell of surfel i is the set of points p
of its tangent plane that are closer (in 3-D) to x_i than to each of its ``k``
nearest neighbours x_j, i.e. the half-planes
``q'_j . (p - x_i) <= |x_j - x_i|^2 / 2`` with q'_j the tangential part of
``x_j - x_i`` (the 3-D Voronoi diagram restricted to the tangent plane). The
radius is the distance from x_i to the farthest vertex of that cell, times
``margin`` (default 1.05). The union of all discs then contains the union of all
cells, i.e. the whole sampled surface, so there are no holes; using the 3-D
distance makes the rule exact on curved surfaces (a neighbour at arc angle theta on
a circle of radius R bounds the cell at R tan(theta/2), beyond the arc midpoint)
and lets points of a nearby other sheet (whose offset is mostly along the normal)
constrain the cell only far away. Because using only k neighbours can only make
a cell larger, the radius is never smaller than the exact restricted Voronoi radius.

Neighbours facing away (``n_i . n_j <= 0.25``, i.e. more than about 75 degrees
apart: the other side of a thin part, or the other face at a sharp edge) are
ignored; when fewer than k of the k nearest neighbours are valid, the cell is
built from the valid ones among the ``4k`` nearest. Cells are computed inside a
disc of radius ``2 x`` the distance to the k-th nearest neighbour (the local
sample spacing; for LDC, Poisson-disk and even uniformly random samplings every
restricted Voronoi vertex lies well inside it). Where a cell reaches that disc
even with ``4k`` neighbours (an open boundary such as the bunny's holes, a sharp
edge seen from one face, or a feature thinner than the spacing), it is closed by
a disc of radius equal to the distance to the 4th nearest valid neighbour: the
splat reaches about one and a half sample spacings beyond the last sample
(enough to reach the corner of a face sampled on a square lattice). For strongly
non-uniform clouds this cap can leave small gaps where a dense region borders a
much sparser one.

**Outlier cells.** A cell computed from k neighbours is exact when its farthest vertex is
within half the k-th neighbour distance (a farther neighbour's bisector lies beyond it).
Typical cells reach about 0.55 of that distance; cells past ``RECHECK`` (0.75) times it are
recomputed from ``4k`` neighbours, so outliers are not left too large by a neighbour beyond
the k-th (recomputing every cell past 0.5 would cost about 3x the run time).

**Smooth surfaces** (``smooth=True``, e.g. the blob's exact surface: no creases). Only
neighbours facing away by more than 120 degrees (``n_i . n_j <= -0.5``, the other side of a
thin part) are ignored, so samples round a tip or rim sharper than the spacing (the blob's
ear tips) bound the cell. Cells that are still open or reach past the k-th neighbour are
recomputed with each neighbour's bound pulled in to at most its own tangential offset
(``REACH``): where the surface bends away faster than the spacing, the plain bisector of a
neighbour far below the tangent plane lies far out in the plane, off the surface. Meshes
with sharp edges keep the default: each face must be covered by its own splats.

**Bound.** Finally every radius (before ``margin``) is capped at ``MAX_FACTOR``
(1.25) times the distance to the k-th nearest neighbour of any orientation, the
local sample density. Without it, samples at thin features (the blob's ear tips,
where the other side's samples are ignored and the cell stays open up to the clip
disc) got splats up to 2x that distance, sticking out past the silhouette (LDC
radii up to 5.7x their mean). Where the sampling is dense enough the Voronoi radius
is well below the cap (median about 0.55 for LDC and Poisson-disk samplings), so
the cap only trims those outliers. A sampling with a known covering distance
(every surface point within ``D`` of a sample, e.g. LDC with ``D = sqrt(3) d``)
can also pass ``max_radius=D``: the nearest sample's disc then still contains
each surface point's tangential offset (at most its 3-D distance), so the
surface stays hole-free (``tests/surfels/test_radii_bound.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_points, positive_scalar
from unmesh.errors import InputError

__all__ = ["estimate_radii", "voronoi_radii_reference"]

#: Neighbours with ``n_i . n_j`` at or below this are ignored (other sheet, other face of an edge).
MIN_DOT = 0.25
#: The same for smooth surfaces (no creases): only the other side of a thin part is ignored.
MIN_DOT_SMOOTH = -0.5
#: Smooth surfaces: a neighbour bounds a wide cell at most this many times its tangential offset away.
REACH = 1.0
#: Inradius of the clip polygon in units of the k-th neighbour distance; a cell reaching it is open.
OPEN_CLIP = 2.0
#: Cells with a vertex past this multiple of the k-th neighbour distance are recomputed from 4k
#: neighbours (0.5 would make every cell exact; larger cells are rare outliers, typical ones ~0.55).
RECHECK = 0.75
#: Boundary cells are closed at this multiple of the 4th valid neighbour distance.
BOUNDARY_FACTOR = 1.0
#: Radii (before margin) are capped at this multiple of the k-th nearest neighbour distance.
MAX_FACTOR = 1.25


def estimate_radii(points: Any, normals: Any = None, k: int = 8, *, margin: float = 1.05,
                   max_radius: float | None = None, smooth: bool = False) -> np.ndarray:
    """Splat radii (N,) from the tangent-plane Voronoi rule of the module docstring.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Surfel centres.
    normals : array_like, shape (N, 3), optional
        Unit normals (oriented or not). Estimated by PCA when omitted
        (:func:`unmesh.surfels.estimate_normals`, unoriented is enough here).
    k : int
        Neighbours used for each cell (at least 3; cells that stay open are
        retried with ``4k``).
    margin : float
        Factor (>= 1) applied to the Voronoi radius for curvature.
    max_radius : float, optional
        Upper bound of every radius (after ``margin``): the sampling's covering
        distance when it is known (module docstring, "Bound").
    smooth : bool
        The sampled surface is smooth (no creases), so neighbours facing away are the
        surface bending round a tip or rim sharper than the spacing: cells that are open or
        reach past the k-th neighbour are also bounded by them (module docstring, "Smooth
        surfaces"). Leave False for meshes with sharp edges, whose faces must each be
        covered by their own splats.

    Returns
    -------
    numpy.ndarray, shape (N,), float64
        Positive radii. A single point gets radius 1.

    Example
    -------
    >>> g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2)
    >>> pts = np.c_[g, np.zeros(100)]
    >>> r = estimate_radii(pts, np.tile([0, 0, 1.0], (100, 1)), margin=1.0)
    >>> round(float(r[55]), 6)  # interior of a unit square grid: half the diagonal
    0.707107
    """
    return _estimate(points, normals, k, margin, max_radius, smooth)[0]


@dataclass(frozen=True)
class _RadiiState:
    """What :func:`_extend` needs to update the radii of :func:`_estimate` after points are added."""

    tree: Any  # KDTree of the points
    normals: np.ndarray  # (N,3) the normalised normals the radii were computed with
    reach: np.ndarray  # (N,) distance of the farthest neighbour each radius depends on
    k: int
    margin: float
    cap: float
    smooth: bool


def _estimate(points: Any, normals: Any, k: int, margin: float, max_radius: float | None,
              smooth: bool) -> tuple[np.ndarray, _RadiiState | None]:
    """:func:`estimate_radii` and, for oriented normals and more than ``4k + 1`` points, the state
    that :func:`_extend` updates (None otherwise)."""
    from unmesh.spatial import KDTree

    pts = as_points(points, "points")
    n = len(pts)
    kk = int(k)
    if kk != k or kk < 3:
        raise InputError(f"k: expected an integer >= 3, got {k!r}")
    m = positive_scalar(margin, "margin")
    if m < 1.0:
        raise InputError(f"margin: expected a factor >= 1, got {m}")
    cap = np.inf if max_radius is None else positive_scalar(max_radius, "max_radius")
    if n == 0:
        return np.zeros(0), None
    if n == 1:
        return np.ones(1), None
    oriented = normals is not None
    if normals is None:
        from unmesh.surfels.normals import pca_normals

        nrm = pca_normals(pts, k=max(kk, 8))
    else:
        nrm = as_points(normals, "normals", length=n)
        lengths = np.linalg.norm(nrm, axis=1)
        if not np.all(lengths > 1e-12):
            raise InputError("normals: expected non-zero vectors")
        nrm = np.ascontiguousarray(nrm / lengths[:, None])
    tree = KDTree(pts)
    radii, reach = _radii_rows(tree, nrm, None, kk, m, cap, oriented, smooth)
    if not oriented or n <= 4 * kk + 1:  # PCA normals depend on the neighbours; small clouds on n
        return radii, None
    return radii, _RadiiState(tree, nrm, reach, kk, m, cap, smooth)


def _extend(state: _RadiiState, radii: np.ndarray, points: Any, normals: Any) -> tuple[np.ndarray, _RadiiState]:
    """Radii (N+M,) of the cloud with ``points`` (M,3) and oriented ``normals`` (M,3) appended.

    Bitwise equal to :func:`estimate_radii` of the whole cloud (same parameters): the new points
    and the old ones with a new point within their reach are recomputed, the others keep their
    radius (their neighbour lists are unchanged: a new point never ties before an old one, as
    equal distances are ordered by index).
    """
    from unmesh.spatial import KDTree

    new = as_points(points, "points")
    nn = as_points(normals, "normals", length=len(new))
    lengths = np.linalg.norm(nn, axis=1)
    if not np.all(lengths > 1e-12):
        raise InputError("normals: expected non-zero vectors")
    n_old = len(state.tree.points)
    pts = np.concatenate([state.tree.points, new])
    nrm = np.ascontiguousarray(np.concatenate([state.normals, nn / lengths[:, None]]))
    tree = KDTree(pts)
    if len(new) == 0:
        return radii.copy(), _RadiiState(tree, nrm, state.reach.copy(), state.k, state.margin, state.cap,
                                          state.smooth)
    # old rows with a new point within their reach: a ball search around the new points, and a
    # nearest-new-point search for the few rows that reach farther than 4x the median
    cut = 4.0 * float(np.median(state.reach))
    off, ind = state.tree.radius_neighbors(new, cut)
    owner = np.repeat(np.arange(len(new)), np.diff(off))
    hit = np.linalg.norm(state.tree.points[ind] - new[owner], axis=1) <= state.reach[ind]
    far = np.flatnonzero(state.reach > cut)
    if len(far):
        near, _ = KDTree(new).knn(state.tree.points[far], 1)
        far = far[near[:, 0] <= state.reach[far]]
    rows = np.concatenate([np.union1d(ind[hit], far), np.arange(n_old, len(pts))])
    r_rows, reach_rows = _radii_rows(tree, nrm, rows, state.k, state.margin, state.cap, True, state.smooth)
    out = np.concatenate([radii, np.zeros(len(new))])
    reach = np.concatenate([state.reach, np.zeros(len(new))])
    out[rows] = r_rows
    reach[rows] = reach_rows
    return out, _RadiiState(tree, nrm, reach, state.k, state.margin, state.cap, state.smooth)


def _radii_rows(tree: Any, nrm: np.ndarray, rows: np.ndarray | None, kk: int, m: float, cap: float,
                oriented: bool, smooth: bool) -> tuple[np.ndarray, np.ndarray]:
    """The radii of :func:`estimate_radii` for the points ``rows`` of ``tree`` (None: all), and each
    one's reach: the distance of the farthest neighbour its radius depends on.

    A row's radius depends only on its nearest neighbours up to its reach (the ``k+1`` nearest, or
    the ``4k+1`` nearest where a cell was recomputed), so after points are added only the rows with
    a new point within their reach change (:func:`_extend`); every row is computed with the
    same arithmetic whatever ``rows`` is, so the radii are bitwise those of the whole cloud.
    """
    from unmesh.surfels._radii_kernels import voronoi_radii

    pts = tree.points
    n = len(pts)
    kq = min(kk + 1, n)
    everything = rows is None
    if everything:
        rows = np.arange(n)
        dist, idx = tree.knn(None, kq)
    else:
        dist, idx = tree.knn(pts[rows], kq)
    min_dot = MIN_DOT_SMOOTH if smooth else MIN_DOT
    valid = _valid(nrm, rows, dist, idx, oriented, min_dot)
    clip = OPEN_CLIP * _positive_scale(dist)  # the local sample spacing, whatever the normals
    if everything:
        radii, opened = voronoi_radii(pts, nrm, np.where(valid, idx, -1), clip, oriented, min_dot, 0.0)
    else:
        radii, opened = _subset_radii(pts, nrm, rows, np.where(valid, idx, -1), clip, oriented, min_dot)
    reach = dist[:, -1].copy()
    # Open cells, too few valid neighbours (another sheet was nearer), or cells that a neighbour
    # beyond the k-th may cut by much (a vertex past RECHECK times the k-th neighbour distance):
    # retry with 4k neighbours.
    kq2 = min(4 * kk + 1, n)
    redo = np.flatnonzero(opened | (valid.sum(axis=1) < min(kk, n - 1)) | (radii > RECHECK * dist[:, -1]))
    if len(redo) and kq2 > kq:
        dist2, idx2 = tree.knn(pts[rows[redo]], kq2)
        reach[redo] = dist2[:, -1]
        valid2 = _valid(nrm, rows[redo], dist2, idx2, oriented, min_dot)
        nb2 = np.where(valid2, idx2, -1)
        radii[redo], opened[redo] = _subset_radii(pts, nrm, rows[redo], nb2, clip[redo], oriented, min_dot)
    # Still open: a boundary or sharp edge. Close the cell at the 4th valid neighbour distance.
    still = np.flatnonzero(opened)
    if len(still):
        dist3, nbrs3 = tree.knn(pts[rows[still]], kq2)
        reach[still] = np.maximum(reach[still], dist3[:, -1])
        valid3 = _valid(nrm, rows[still], dist3, nbrs3, oriented, min_dot)
        close = np.minimum(BOUNDARY_FACTOR * _valid_scale(dist3, valid3, 4), clip[still])
        radii[still] = _subset_radii(pts, nrm, rows[still], np.where(valid3, nbrs3, -1), close, oriented,
                                     min_dot)[0]
    if smooth:  # cells open or reaching past the k-th neighbour: a bend sharper than the spacing
        wide = np.flatnonzero((radii > clip / OPEN_CLIP) | opened)
        if len(wide):
            dist4, nbrs4 = tree.knn(pts[rows[wide]], kq2)
            reach[wide] = np.maximum(reach[wide], dist4[:, -1])
            distinct = (nbrs4 >= 0) & (nbrs4 != rows[wide][:, None]) & (dist4 > 0)
            r_all, open_all = _subset_radii(pts, nrm, rows[wide], np.where(distinct, nbrs4, -1), clip[wide],
                                            oriented, min_dot, reach=REACH)
            radii[wide] = np.where(open_all, radii[wide], np.minimum(radii[wide], r_all))
    np.minimum(radii, MAX_FACTOR * clip / OPEN_CLIP, out=radii)  # bound by the local sample density
    radii *= m
    bad = ~(radii > 0)
    if bad.any():  # fully coincident points: fall back to the neighbour distance scale
        radii[bad] = clip[bad] / OPEN_CLIP
    return np.minimum(radii, cap), reach


def _positive_scale(dist: np.ndarray) -> np.ndarray:
    """Distance to the farthest finite neighbour, per row (> 0; 1 when all coincide)."""
    d = np.where(np.isfinite(dist), dist, 0.0).max(axis=1)
    return np.where(d > 0, d, 1.0)


def _subset_radii(pts: np.ndarray, nrm: np.ndarray, rows: np.ndarray, nbrs: np.ndarray, clip: np.ndarray,
                  oriented: bool, min_dot: float, reach: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Voronoi radii of the points ``rows`` with neighbour lists ``nbrs`` (indices into pts)."""
    from unmesh.surfels._radii_kernels import voronoi_radii

    # Put the subset first, followed by every point it references, and relabel.
    used = np.unique(np.concatenate([rows, nbrs[nbrs >= 0]]))
    local = np.full(len(pts), -1, np.int64)
    order = np.concatenate([rows, np.setdiff1d(used, rows)])
    local[order] = np.arange(len(order))
    sub_pts = np.ascontiguousarray(pts[order])
    sub_nrm = np.ascontiguousarray(nrm[order])
    nb = np.where(nbrs >= 0, local[np.maximum(nbrs, 0)], -1)
    full_nb = np.full((len(order), nb.shape[1]), -1, np.int64)
    full_nb[: len(rows)] = nb
    full_clip = np.ones(len(order))
    full_clip[: len(rows)] = clip
    r, o = voronoi_radii(sub_pts, sub_nrm, full_nb, full_clip, oriented,
                         min_dot, reach)
    return r[: len(rows)], o[: len(rows)]


def _valid(nrm: np.ndarray, rows: np.ndarray, dist: np.ndarray, idx: np.ndarray, oriented: bool,
           min_dot: float) -> np.ndarray:
    """Mask (Q,K) of neighbours that bound a cell: distinct, present, normals within ~75 degrees."""
    dn = np.einsum("qki,qi->qk", nrm[np.maximum(idx, 0)], nrm[rows])
    if not oriented:
        dn = np.abs(dn)
    return (idx >= 0) & (idx != rows[:, None]) & (dist > 0) & (dn > min_dot)


def _valid_scale(dist: np.ndarray, valid: np.ndarray, k: int) -> np.ndarray:
    """Distance to the k-th valid neighbour of each row (the farthest valid one if fewer;
    the farthest neighbour at all if none is valid; 1 if all coincide)."""
    dv = np.where(valid, dist, np.inf)
    dv.sort(axis=1)
    kth = dv[:, min(k, dv.shape[1]) - 1]
    farthest_valid = np.max(np.where(np.isfinite(dv), dv, 0.0), axis=1)
    scale = np.where(np.isfinite(kth), kth, farthest_valid)
    return np.where(scale > 0, scale, _positive_scale(dist))


def voronoi_radii_reference(points: np.ndarray, normals: np.ndarray, nbrs: np.ndarray, clip: np.ndarray,
                            oriented: bool, min_dot: float = MIN_DOT, sides: int = 16,
                            rows: Any = None, reach: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Numpy reference of :func:`unmesh.surfels._radii_kernels.voronoi_radii`.

    Independent formulation: the cell's vertices are all pairwise intersections
    of its bounding lines (bisectors and clip-polygon edges) that satisfy every
    constraint; the radius is the largest vertex norm. ``rows`` limits the
    computation to some points (the result keeps all N entries, zero elsewhere).
    """
    from unmesh.surfels.cloud import tangent_frame

    t1, t2 = tangent_frame(normals)
    out = np.zeros(len(points))
    opened = np.zeros(len(points), bool)
    ang = 2 * np.pi * np.arange(sides) / sides
    for i in range(len(points)) if rows is None else rows:
        lines_a = [np.array([np.cos(a), np.sin(a)]) for a in ang]
        lines_c = [clip[i]] * sides
        for j in nbrs[i]:
            if j < 0 or j == i:
                continue
            d = points[j] - points[i]
            dist = np.linalg.norm(d)
            if dist <= 1e-12 * clip[i]:
                continue
            dn = normals[i] @ normals[j]
            if (abs(dn) if not oriented else dn) <= min_dot:
                continue
            q = np.array([d @ t1[i], d @ t2[i]])
            if q @ q <= 1e-24 * dist * dist:
                continue
            lines_a.append(q)
            lines_c.append(min(0.5 * dist * dist, reach * (q @ q)) if reach > 0 else 0.5 * dist * dist)
        a = np.array(lines_a)
        c = np.array(lines_c)
        best = 0.0
        for p in range(len(a)):
            for q in range(p + 1, len(a)):
                m = np.array([a[p], a[q]])
                if abs(np.linalg.det(m)) < 1e-14 * (np.linalg.norm(a[p]) * np.linalg.norm(a[q])):
                    continue
                v = np.linalg.solve(m, [c[p], c[q]])
                if np.all(a @ v <= c + 1e-9 * np.maximum(1.0, np.abs(c))):
                    r = float(np.hypot(*v))
                    if r > best:
                        best = r
                    if np.any(a[:sides] @ v >= clip[i] * (1 - 1e-9)):
                        opened[i] = True
        out[i] = best
    return out, opened
