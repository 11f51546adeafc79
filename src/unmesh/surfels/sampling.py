"""Sampling triangle meshes and raw points into surfel clouds (thesis sections 3.3 and 6).

LDC sampling (layered depth cube, Lischinski & Rappoport 1998; used for surfels by
Pfister et al. 2000 and in thesis chapter 6: "geometry [is] sampled by orthogonal
views, yielding a sampling with guaranteed maximum surfel distance"): three
orthogonal bundles of parallel rays on the world-aligned lattice
``((i + 1/2) d, (j + 1/2) d)`` shoot through the mesh along x, y and z, and every
ray-triangle intersection becomes a surfel. The three bundles are the edges of a
cubic lattice of spacing ``d``; a surface crossing a lattice cube crosses one of
its edges, so every surface point has a sample within the cube diagonal ``sqrt(3) d``
(for surfaces with features larger than ``d``).

The intersection test rasterises each triangle into the ray lattice with edge
functions evaluated in a canonical vertex order and a consistent tie rule (a
point exactly on an edge or vertex belongs to the triangle containing it after an
infinitesimal shift along ``(-eps, 1)`` in the projection plane), so a ray through
a shared edge or vertex of a closed mesh yields exactly one sample, never zero or two.
(On an open boundary, a ray exactly through a boundary edge may yield none: the tie
goes to the missing neighbour.)

**Caps sharper than the spacing.** Where the surface bends round a cap whose curvature radius
is below ``d`` (the blob's ear tips, a thin ellipsoid's ends), the lattice rays hit it only
sparsely: the neighbours of a sample there lie far below its tangent plane or face away, and the
radius rule (:mod:`unmesh.surfels.radii`) needs a disc up to ``sqrt(3) d`` that sticks out past
the silhouette (2.28x the median radius at the blob's ear apex in the paint examples' model).
``sample_mesh`` therefore refines, once, where a radius exceeds ``REFINE_RADIUS d`` (1.1 d;
the median is about 0.76 d) and the sample's ball (of that radius) holds a triangle smaller than
the spacing (bounding-sphere radius at most ``d / 2``) that no ray hit and whose normal is within
the radius rule's ~75 degrees both of the sample's and of a sample in the ball that is beyond
them: the surface passes through the orientations in between, a smooth bend that the mesh
resolves and the rays do not. A crease (box edge, cylinder rim) has no such orientation and a
mesh coarser than the rays has no such triangle; neither is refined. The triangles in the balls
of those samples are ray cast on the lattice of spacing ``d / 2`` (offset from the main one, so
no ray repeats), and a hit inside a ball is added when it lies at least ``REFINE_GAP d``
(``sqrt(2) / 4 d``, half the diagonal of a refinement lattice cell) from every sample and from
each hit added before it: the hits fill the gaps, they do not densify the cap. The radii are then
the radius rule's on the whole cloud (recomputed only where a new sample is within reach). The
lattice samples stay first, unchanged; adding samples keeps the covering distance.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from unmesh._validate import as_array, as_points, positive_scalar
from unmesh.errors import InputError

if TYPE_CHECKING:
    from unmesh.meshes import TriangleMesh
    from unmesh.surfels.cloud import SurfelCloud

__all__ = ["MAX_SAMPLES", "from_points", "ldc_reference", "ldc_samples", "sample_mesh"]

#: Refuse spacings that would create more samples than this (memory guard).
MAX_SAMPLES = 200_000_000
#: Triangles per kernel call (progress granularity).
_CHUNK = 1 << 16
#: Samples whose radius exceeds this multiple of the ray spacing are checked for an under-sampled bend.
REFINE_RADIUS = 1.1
#: Refinement rays at spacing d/2 keep only hits at least this many ``d`` from every sample (half the
#: diagonal of a refinement lattice cell, ``sqrt(2) / 4``): they fill the gaps, they do not densify.
REFINE_GAP = math.sqrt(2.0) / 4.0
#: The refinement check sizes every triangle when there are at most this many per candidate sample
#: (else only those near a candidate).
FEW_TRIANGLES = 50


def _expected_samples(mesh: TriangleMesh, d: float) -> float:
    cross = mesh._face_cross()
    return float(0.5 * np.abs(cross).sum() / (d * d))


def ldc_samples(vertices: np.ndarray, faces: np.ndarray, spacing: float,
                progress: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All ray-lattice hits: positions (H,3), face indices (H,) and barycentrics (H,3).

    Ordered by ray axis (x, y, z), then by face, then by lattice position.
    ``vertices`` (V,3) float64 and ``faces`` (F,3) int64 must be C-contiguous.
    """
    from unmesh.surfels._sampling_kernels import ldc_count, ldc_fill

    nf = len(faces)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=3 * nf, desc="LDC sampling", unit="tri", unit_scale=True, leave=False)
    pos, face, bary = [], [], []
    try:
        for axis in range(3):
            for f0 in range(0, nf, _CHUNK):
                f1 = min(nf, f0 + _CHUNK)
                counts = ldc_count(vertices, faces, f0, f1, axis, spacing)
                offsets = np.zeros(f1 - f0 + 1, np.int64)
                np.cumsum(counts, out=offsets[1:])
                p, f, b = ldc_fill(vertices, faces, f0, f1, axis, spacing, offsets)
                pos.append(p)
                face.append(f)
                bary.append(b)
                if bar is not None:
                    bar.update(f1 - f0)
    finally:
        if bar is not None:
            bar.close()
    if not pos:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3))
    return np.concatenate(pos), np.concatenate(face), np.concatenate(bary)


def _texture_lookup(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear texture colours (N,3) at uv (N,2).

    (0, 0) is the bottom-left corner, image row 0 the top. Coordinates outside
    [0, 1] repeat (wrap); the bilinear footprint is clamped at the image border, so
    texels of the opposite edge never bleed into an atlas.
    """
    h, w = texture.shape[:2]
    u = np.where((uv[:, 0] >= 0) & (uv[:, 0] <= 1), uv[:, 0], np.mod(uv[:, 0], 1.0))
    v = np.where((uv[:, 1] >= 0) & (uv[:, 1] <= 1), uv[:, 1], np.mod(uv[:, 1], 1.0))
    x = np.clip(u * w - 0.5, 0.0, w - 1.0)
    y = np.clip((1.0 - v) * h - 0.5, 0.0, h - 1.0)
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    top = texture[y0, x0] * (1 - fx) + texture[y0, x1] * fx
    bottom = texture[y1, x0] * (1 - fx) + texture[y1, x1] * fx
    return np.clip(top * (1 - fy) + bottom * fy, 0.0, 1.0)


def sample_mesh(mesh: TriangleMesh, spacing: float, *, progress: bool = False, k: int = 8,
                refine: bool = True) -> SurfelCloud:
    """LDC sampling of a triangle mesh into surfels (module docstring; thesis ch. 6).

    Parameters
    ----------
    mesh : TriangleMesh
        Any triangle mesh: open meshes (holes), unreferenced vertices and
        degenerate triangles are fine.
    spacing : float
        Ray spacing ``d``; every surface point has a sample within ``sqrt(3) d``.
    progress : bool
        Show a progress bar (tqdm) over the triangles.
    k : int
        Neighbours for the radius rule (:func:`unmesh.surfels.estimate_radii`).
    refine : bool
        Add samples at smooth bends sharper than the ray spacing (module docstring,
        "Caps sharper than the spacing"); ``False`` gives the plain LDC samples.

    Returns
    -------
    SurfelCloud
        One surfel per ray-triangle intersection, exactly on the triangle: the
        lattice rays first (in :func:`ldc_samples` order), then the hits of the
        refinement rays, if any.
        Normals: the triangle's unit normal, or the barycentric interpolation of
        the mesh's vertex normals (flipped where it disagrees with the triangle).
        Colours: interpolated vertex colours, else the bilinear texture colour at
        the interpolated uv, else the default grey. Radii: the tangent-plane
        Voronoi rule of :mod:`unmesh.surfels.radii` (neighbouring splats overlap
        so that they cover the surface), bounded by the covering distance
        ``sqrt(3) d`` (which alone already covers the surface).

    Raises
    ------
    unmesh.errors.InputError
        Non-positive spacing, or a spacing that would create more than
        ``MAX_SAMPLES`` samples (the message gives the estimate).

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> cloud = sample_mesh(Sphere().mesh(resolution=24), 0.1)
    >>> bool(np.abs(np.linalg.norm(cloud.positions, axis=1) - 1).max() < 0.02)
    True
    """
    from unmesh.meshes import TriangleMesh
    from unmesh.surfels.cloud import SurfelCloud
    from unmesh.surfels.radii import _estimate, _extend

    if not isinstance(mesh, TriangleMesh):
        raise InputError(f"mesh: expected a TriangleMesh, got {type(mesh).__name__}")
    d = positive_scalar(spacing, "spacing")
    expected = _expected_samples(mesh, d)
    if expected > MAX_SAMPLES:
        raise InputError(
            f"spacing: {d:.6g} would create about {expected:.3g} samples (limit {MAX_SAMPLES:.0e}); use a larger spacing"
        )
    pos, face, bary = ldc_samples(mesh.vertices, mesh.faces, d, progress)
    if len(pos) == 0:
        raise InputError(
            f"spacing: {d:.6g} is too coarse for this mesh (no ray hits a triangle; its size is "
            f"{(mesh.bounds()[1] - mesh.bounds()[0]).max():.6g}); use a smaller spacing"
        )
    fn = mesh.face_normals()
    nrm, colors = _attributes(mesh, fn, face, bary)
    radii, state = _estimate(pos, nrm, k, 1.05, np.sqrt(3.0) * d, False)
    if refine and state is not None:
        added = _refine_caps(mesh, fn, pos, face, nrm, radii, state.tree, d)
        if added is not None:
            p2, f2, b2 = added
            n2, c2 = _attributes(mesh, fn, f2, b2)
            radii, state = _extend(state, radii, p2, n2)
            pos = np.concatenate([pos, p2])
            nrm = np.concatenate([nrm, n2])
            colors = None if colors is None else np.concatenate([colors, c2])
    return SurfelCloud(pos, nrm, radii=radii, colors=colors)


def _attributes(mesh: TriangleMesh, fn: np.ndarray, face: np.ndarray,
                bary: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Normals (H,3) and colours (H,3) or None of hits on ``face`` (H,) at barycentrics ``bary`` (H,3)."""
    fv = mesh.faces[face]
    if mesh.vertex_normals is not None:
        nrm = np.einsum("nk,nki->ni", bary, mesh.vertex_normals[fv])
        length = np.linalg.norm(nrm, axis=1)
        ok = length > 1e-9
        nrm[ok] /= length[ok, None]
        nrm[~ok] = fn[face][~ok]
        flip = np.einsum("ij,ij->i", nrm, fn[face]) < 0
        nrm[flip] *= -1.0
    else:
        nrm = fn[face]
    colors = None
    if mesh.vertex_colors is not None:
        colors = np.clip(np.einsum("nk,nki->ni", bary, mesh.vertex_colors[fv]), 0.0, 1.0)
    elif mesh.texture is not None and mesh.uv is not None:
        uv = np.einsum("nk,nki->ni", bary, mesh.uv[fv])
        colors = _texture_lookup(mesh.texture, uv)
    return nrm, colors


def _ball_pairs(centres: np.ndarray, reach: np.ndarray, points: np.ndarray, slack: np.ndarray,
                rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (c, p) with ``|points[p] - centres[c]| <= reach[c] + slack[p]`` for ``p`` in ``rows``.

    ``centres`` (C,3), ``reach`` (C,), ``points`` (P,3), ``slack`` (P,); returns two int64 arrays,
    sorted by c. A grid of cells of the largest reach first drops the rows far from every centre.
    """
    from unmesh.spatial import KDTree

    if len(rows) == 0 or len(centres) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell = float(reach.max() + slack[rows].max())
    lo = np.floor(centres.min(axis=0) / cell) - 1
    dims = (np.floor(centres.max(axis=0) / cell) + 2 - lo).astype(np.int64)
    ijk = np.floor(points[rows] / cell) - lo
    ok = np.all((ijk >= 0) & (ijk < dims), axis=1)
    rows = rows[ok]
    keys = np.ravel_multi_index(ijk[ok].astype(np.int64).T, dims)
    ci = (np.floor(centres / cell) - lo).astype(np.int64)
    shifts = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), -1).reshape(-1, 3)
    around = np.unique(np.ravel_multi_index((ci[:, None, :] + shifts[None]).reshape(-1, 3).T, dims))
    rows = rows[np.isin(keys, around)]
    if len(rows) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    off, ind = KDTree(points[rows]).radius_neighbors(centres, cell)
    c = np.repeat(np.arange(len(centres)), np.diff(off))
    p = rows[ind]
    inside = np.linalg.norm(points[p] - centres[c], axis=1) <= reach[c] + slack[p]
    return c[inside], p[inside]


def _refine_caps(mesh: TriangleMesh, fn: np.ndarray, pos: np.ndarray, face: np.ndarray, nrm: np.ndarray,
                 radii: np.ndarray, tree: Any, d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Hits (positions, faces, barycentrics) of the rays at spacing ``d / 2`` that fill the gaps in
    the discs of the samples at under-sampled smooth bends (module docstring), or None.

    A sample is refined when its radius exceeds ``REFINE_RADIUS d`` and its ball (of that radius)
    holds a triangle smaller than the ray spacing (bounding sphere radius at most ``d / 2``) that no
    ray hit yet, whose normal is valid (``n . n' > MIN_DOT``) both for the sample and for a sample in
    the ball that is not valid for it: the surface bends through the orientations in between (a
    crease such as a box edge has none). The new hits are those inside the balls of the refined
    samples at least ``REFINE_GAP d`` from every sample and from each other (kept in ray order).
    ``tree`` is a KDTree of ``pos``.
    """
    from unmesh.surfels.radii import MIN_DOT

    cand = np.flatnonzero(radii > REFINE_RADIUS * d)
    if len(cand) == 0:
        return None
    rc = radii[cand]
    v, f = mesh.vertices, mesh.faces
    if len(f) <= FEW_TRIANGLES * len(cand):  # size every triangle
        tris = np.arange(len(f))
    else:  # the triangles with a vertex within reach + d of a candidate hold every small one of its ball
        near_v = np.zeros(len(v), bool)
        near_v[_ball_pairs(pos[cand], rc + d, v, np.zeros(len(v)), np.arange(len(v)))[1]] = True
        tris = np.flatnonzero(near_v[f].any(axis=1))
    corners = v[f[tris]]
    centre = np.zeros((len(f), 3))
    size = np.full(len(f), np.inf)
    centre[tris] = corners.mean(axis=1)
    size[tris] = np.sqrt(((corners - centre[tris][:, None, :]) ** 2).sum(axis=2).max(axis=1))
    small = tris[size[tris] <= 0.5 * d]
    hit = np.zeros(len(f), bool)
    hit[face] = True
    unhit = small[~hit[small]]
    if len(unhit) == 0:
        return None
    # unhit small triangles in each candidate's ball, valid for the candidate
    uc, ut = _ball_pairs(pos[cand], rc, centre, size, unhit)
    keep = np.einsum("ij,ij->i", fn[ut], nrm[cand[uc]]) > MIN_DOT
    uc, ut = uc[keep], ut[keep]
    if len(uc) == 0:
        return None
    # samples in each candidate's ball that are not valid for it
    off, ind = tree.radius_neighbors(pos[cand], float(rc.max()))
    sc = np.repeat(np.arange(len(cand)), np.diff(off))
    sj = ind
    keep = (np.linalg.norm(pos[sj] - pos[cand[sc]], axis=1) <= rc[sc]) & (
        np.einsum("ij,ij->i", nrm[sj], nrm[cand[sc]]) <= MIN_DOT)
    sc, sj = sc[keep], sj[keep]
    # every (triangle, sample) combination of a candidate: is the triangle valid for the sample too?
    start = np.searchsorted(sc, np.arange(len(cand) + 1))
    rep = np.diff(start)[uc]
    total = int(rep.sum())
    if total == 0:
        return None
    t_of = np.repeat(ut, rep)
    c_of = np.repeat(uc, rep)
    j_of = sj[start[c_of] + np.arange(total) - np.repeat(np.cumsum(rep) - rep, rep)]
    bend = np.zeros(len(cand), bool)
    bend[c_of[np.einsum("ij,ij->i", fn[t_of], nrm[j_of]) > MIN_DOT]] = True
    if not bend.any():
        return None
    b = np.flatnonzero(bend)
    sel = np.unique(_ball_pairs(pos[cand[b]], rc[b], centre, size, small)[1])  # the small triangles in the balls
    p2, f2, b2 = ldc_samples(mesh.vertices, np.ascontiguousarray(mesh.faces[sel]), 0.5 * d)
    inside = np.unique(_ball_pairs(pos[cand[b]], rc[b], p2, np.zeros(len(p2)), np.arange(len(p2)))[1])
    if len(inside):
        gap, _ = tree.knn(p2[inside], 1)
        inside = inside[gap[:, 0] >= REFINE_GAP * d]
    if len(inside) == 0:
        return None
    inside = inside[_greedy_apart(p2[inside], REFINE_GAP * d)]
    return p2[inside], sel[f2[inside]], b2[inside]


def _greedy_apart(points: np.ndarray, gap: float) -> np.ndarray:
    """Indices of the points (N,3) kept in order when each is dropped that lies closer than ``gap``
    to an earlier kept one (ascending int64)."""
    from unmesh.spatial import KDTree

    pairs = KDTree(points).radius_pairs(gap * (1.0 - 1e-12))  # i < j, lexicographic
    if len(pairs) == 0:
        return np.arange(len(points))
    start = np.searchsorted(pairs[:, 0], np.arange(len(points) + 1))
    dropped = np.zeros(len(points), bool)
    for i in np.unique(pairs[:, 0]):
        if not dropped[i]:
            dropped[pairs[start[i]:start[i + 1], 1]] = True
    return np.flatnonzero(~dropped)


def ldc_reference(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """Plain numpy reference of the LDC hits: positions (H,3), sorted lexicographically.

    Independent of the kernel: for every axis and every lattice ray it solves the
    ray-plane intersection of every triangle and keeps those whose barycentric
    coordinates are all non-negative (closed triangles). Rays through shared
    edges may therefore appear twice here; compare after removing duplicates.
    Meant for small meshes.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    out = []
    lo = v[np.unique(f)].min(axis=0)
    hi = v[np.unique(f)].max(axis=0)
    for axis in range(3):
        ua, va = (axis + 1) % 3, (axis + 2) % 3
        iu = np.arange(math.ceil(lo[ua] / spacing - 0.5), math.floor(hi[ua] / spacing - 0.5) + 1)
        iv = np.arange(math.ceil(lo[va] / spacing - 0.5), math.floor(hi[va] / spacing - 0.5) + 1)
        gu, gv = np.meshgrid((iu + 0.5) * spacing, (iv + 0.5) * spacing, indexing="ij")
        p = np.stack([gu.ravel(), gv.ravel()], 1)
        a, b, c = v[f[:, 0]][:, [ua, va]], v[f[:, 1]][:, [ua, va]], v[f[:, 2]][:, [ua, va]]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        ok = det != 0
        for t in np.flatnonzero(ok):
            rel = p - a[t]
            e1 = b[t] - a[t]
            e2 = c[t] - a[t]
            l1 = (rel[:, 0] * e2[1] - rel[:, 1] * e2[0]) / det[t]
            l2 = (e1[0] * rel[:, 1] - e1[1] * rel[:, 0]) / det[t]
            l0 = 1 - l1 - l2
            hit = (l0 >= -1e-12) & (l1 >= -1e-12) & (l2 >= -1e-12)
            if hit.any():
                w = l0[hit] * v[f[t, 0], axis] + l1[hit] * v[f[t, 1], axis] + l2[hit] * v[f[t, 2], axis]
                q = np.empty((hit.sum(), 3))
                q[:, axis] = w
                q[:, ua] = p[hit, 0]
                q[:, va] = p[hit, 1]
                out.append(q)
    if not out:
        return np.zeros((0, 3))
    allp = np.concatenate(out)
    return allp[np.lexsort(allp.T[::-1])]


def from_points(points: Any, normals: Any = None, radii: Any = None, colors: Any = None, k: int = 16) -> SurfelCloud:
    """A surfel cloud from raw points, estimating what is missing.

    Parameters
    ----------
    points : array_like, shape (N, 3)
    normals : array_like, shape (N, 3), optional
        Estimated with :func:`unmesh.surfels.estimate_normals` (k neighbours) when omitted.
    radii : array_like, shape (N,), optional
        Estimated with :func:`unmesh.surfels.estimate_radii` (covering splats) when omitted.
    colors : array_like, shape (N, 3), optional
        RGB in [0, 1] (or uint8).
    k : int
        Neighbourhood size for normal estimation.

    Returns
    -------
    SurfelCloud

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> c = from_points(Sphere().surfels(0.2).positions)
    >>> bool(np.all(np.einsum("ij,ij->i", c.normals, c.positions) > 0.99))
    True
    """
    from unmesh.surfels.cloud import SurfelCloud
    from unmesh.surfels.normals import estimate_normals
    from unmesh.surfels.radii import estimate_radii

    pts = as_points(points, "points")
    nrm = estimate_normals(pts, k) if normals is None else as_points(normals, "normals", length=len(pts))
    if radii is None:
        rad = estimate_radii(pts, nrm)
    else:
        rad = as_array(radii, "radii", (None,), length=len(pts))
    return SurfelCloud(pts, nrm, radii=rad, colors=colors)
