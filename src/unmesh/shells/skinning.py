"""Surface animation: the dense surfel cloud follows the simulation nodes (thesis 7.4, 7.26-7.30).

Every *passive point* ``p`` (each dense surfel, and each discontinuity surfel at a crack)
is bound to its nearest simulation nodes ``x_0 .. x_K`` in the rest state, sorted by
distance. With ``N`` the normal of the least-squares plane through them, each further
node ``x_i`` spans a local frame (7.26)::

    e1 = x_i - x_0,   e2 = N x e1 / |e1|,   e3 = e2 x e1 / |e1|

``p - x_0`` is stored in local coordinates ``y_k = (p - x_0).e_k / |e_k|^2`` (7.27), and
after deformation ``p'_i = x'_0 + sum_k y_k e'_k`` (7.28) is blended with weights
``w_i = w(|x_i - p| / |x_K - p|)`` (7.29, 7.30) where ``w(r) = ((1 - r) / r)^2`` has
``w(0) = inf`` and ``w(1) = 0`` (so ``x_K`` only sets the radius). Tangent axes are mapped
the same way as vectors (without ``x_0``), and the normal is their cross product, so
normals and axes rotate and stretch with the shell. Rigid motions are reproduced exactly.

With cracks, only nodes *visible* from ``p`` (7.3.2) are bound, so the two sides of a tear
separate cleanly; each crack also adds a pair of *discontinuity surfels* with opposite
normals on either side of the crack plane (for the edge clipping of 4.3; written with the
per-surfel attribute ``discontinuity = 1``).

Thin parts (beyond the thesis): where a part is about one node spacing thick (the tip of the
plastic blob's ear) the nearest nodes of a surfel by distance include nodes of the far face.
Bound to them, the surfel followed the far face's motion (a sunken, tilted splat: a dark fleck
on the ear; knobs under the ear bent on impact). Like the nodes a crack hides (7.3.2), nodes
whose rest normal makes more than 90° with the surfel's (:data:`FACING_MIN`) are not bound
(:func:`bind_points`, ``facing``), unless every candidate faces away.

Where the bound nodes have no plane (beyond the thesis): at a thin or sharply curved part (an
ear's base) the nearest nodes of a surfel can lie on both sides of it, spread in all three
directions. Their least-squares plane is then ill-defined (its normal turns with small motions
of the nodes) or crosses the surface, and frames built on it amplify small node motions into
large displacements of the surfel (a stretched splat that detached from the surface of a
dented plastic blob). Such surfels, found once at rest by :func:`frame_normals` (the two
smallest spreads differ by less than :data:`PLANE_FLATNESS`, or the plane normal is more than
60° from the sum of the node normals, :data:`PLANE_AGREEMENT`, or about 37° from the surfel's
own normal, :data:`PLANE_SURFACE_AGREEMENT`: a surfel on the rim of a thin part whose nodes lie
on its two faces, whose plane is the faces'), use the normalised sum of
their nodes' normals as ``N``, as points bound to fewer than 3 nodes do. A frame whose edge
``e1`` is within 30° of ``N`` (:data:`FRAME_MAX_COS`; a node across the thin part) spans
almost nothing across ``e1`` and gets no weight (:func:`usable_frames`). A frame that becomes so
in motion (a node across the rim of the ear rolls over onto ``N`` as the ear bends: 40° at rest,
10° on impact, a needle-like splat standing off the rim) fades out between 30° and 15° in the
deformed state (:func:`unmesh.shells._skinning_kernels.frame_fade`; weights of a blend only, so
rigid motions stay exact).

Splat radii (beyond the thesis): the deformed circle takes the longer deformed tangent axis,
but the blend of (7.28) is not continuous where ``x_0`` changes between neighbouring
surfels, and the node-level strain of a stretched shell varies strongly from node to node,
so pinholes opened along those seams (the inflated balloon of Fig. 7.10: neighbouring
surfels bound to different ``x_0`` were stretched by up to 2.2, those with the same
``x_0`` by up to 1.3). Each dense surfel therefore also keeps its :data:`COVER_NEIGHBORS`
nearest rest neighbours, and its radius grows with the largest stretch of those distances
(:func:`cover_radii_reference`). Neighbours that would need more than :data:`COVER_CAP` times
the axis radius count as torn apart, and so do neighbours whose rest normals differ by more
than 60° (the two sides of a thin part), and neighbours separated by a crack (the segment between their rest positions crosses a crack disc, 7.3.2)
or that share no bound node are ignored, so cracks stay open.
Under rigid motions the radii are those of the axes. (So are they under uniform shrinking;
under uniform stretching by ``s`` the axes of (7.26) stretch only along ``e1``, to about
0.89 ``s`` of the rest radius for ``s = 1.4``, and the neighbour distances set the radii.)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._threads import threads_for
from unmesh._validate import as_array, as_points
from unmesh.errors import InputError
from unmesh.shells import _skinning_kernels as _sk
from unmesh.shells.nodes import hide_blocked
from unmesh.shells.rebinding import Rebinding, _cover_pairs, _cover_pairs_reference, _Passive  # noqa: F401
from unmesh.surfels import SurfelCloud

__all__ = ["COVER_CAP", "COVER_NEIGHBORS", "DEFAULT_SKIN_NODES", "FACING_MIN", "FRAME_MAX_COS", "PLANE_AGREEMENT",
           "PLANE_FLATNESS", "PLANE_SURFACE_AGREEMENT", "SkinnedSurface",
           "bind_points", "cover_radii_reference", "deform_reference", "frame_normals", "skin_weight",
           "usable_frames"]

#: A binding has no plane when the smallest spread of its nodes (covariance eigenvalue) is more
#: than this fraction of the middle one (see the module notes and :func:`frame_normals`).
PLANE_FLATNESS = 0.5
#: ... or when its plane normal and the sum of its node normals make a larger angle (cosine).
PLANE_AGREEMENT = 0.5
#: ... or when its plane normal and the point's own rest normal make a larger angle (cosine, ~37°).
PLANE_SURFACE_AGREEMENT = 0.8
#: Nodes whose rest normal and the point's make a larger angle (cosine below this, 90°) lie on the
#: far side of a thin part and are not bound (:func:`bind_points`, ``facing``).
FACING_MIN = 0.0
#: A frame whose rest edge ``e1`` makes a smaller angle with ``N`` (cosine above this) is degenerate
#: (7.26: ``e2 = N x e1 / |e1|`` vanishes) and gets no weight (:func:`usable_frames`).
FRAME_MAX_COS = float(np.cos(np.radians(30.0)))
#: Nodes per passive point: x_0 and K further nodes (K - 1 weighted frames).
DEFAULT_SKIN_NODES = 6
#: Below this many passive points the skinning kernel runs on one thread (see unmesh._threads).
SKIN_PARALLEL_MIN = 4000
#: Rest neighbours per dense surfel whose stretch sets its splat radius (:func:`cover_radii_reference`).
COVER_NEIGHBORS = 6
#: Rest neighbours that moved apart so far that a splat would need more than this many times its
#: deformed-axis radius count as torn apart (before the balloon of Fig. 7.10 tears, seams need
#: up to 2.1, 99 % of them less than 1.6; in its opening the torn material needs far more).
COVER_CAP = 2.0
#: Rest neighbours whose normals make a larger angle (cosine below this) do not count: the two
#: sides of a thin part (an ear) are not neighbours on the surface.
COVER_FACING = 0.5


def skin_weight(r: np.ndarray) -> np.ndarray:
    """The blending weight ``w(r) = ((1 - r)/r)^2`` of (7.30): w(0) = inf, w(1) = 0.

    Example
    -------
    >>> skin_weight(np.array([0.5, 1.0]))
    array([1., 0.])
    """
    r = np.asarray(r, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(r < 1, ((1 - r) / np.maximum(r, 1e-12)) ** 2, 0.0)


def bind_points(points: Any, node_rest: Any, k: int = DEFAULT_SKIN_NODES, blocked: Any = None,
                tree: Any = None, candidates: tuple[np.ndarray, np.ndarray] | None = None,
                exclude: np.ndarray | None = None, facing: tuple[np.ndarray, np.ndarray] | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Bind points to their nearest (visible) nodes: indices (S, K+1) and frame weights (S, K).

    Parameters
    ----------
    points : array_like (S, 3)
        Rest positions of the passive points.
    node_rest : array_like (N, 3)
        Rest positions of the nodes.
    k : int
        Frame nodes per point (besides the nearest node ``x_0``).
    blocked : callable, optional
        ``blocked(p, q) -> bool (M,)`` crack visibility test; hidden nodes are skipped (a
        point that sees none of its ``3 (K + 1)`` nearest nodes follows the nearest one).
    tree : unmesh.spatial.KDTree, optional
        Tree over ``node_rest`` to reuse.
    candidates : (ndarray, ndarray), optional
        The distances and indices (S, c) of the ``c`` nearest nodes of every point, as
        ``tree.knn(points, c)`` gives them (``c = K + 1``, or ``3 (K + 1)`` with ``blocked`` or
        ``exclude``), when they are known already.
    exclude : ndarray (N,) bool, optional
        Nodes not to bind to (the crumbs of a torn shell: they carry no material); skipped
        like hidden ones.
    facing : (ndarray (S, 3), ndarray (N, 3)), optional
        Rest normals of the points and of the nodes: nodes whose normal makes more than 90°
        with the point's (``n_p . n_x < FACING_MIN``: the far side of a thin part) are
        skipped like hidden ones, unless every candidate faces away (module notes).

    Returns
    -------
    bind : ndarray (S, K + 1) int64
        ``x_0`` first, then frame nodes by distance; -1 where fewer nodes are visible.
    weights : ndarray (S, K)
        ``w(|x_i - p| / |x_last - p|)`` for the frame nodes, the last (radius) node 0.

    Example
    -------
    >>> nodes = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 0]])
    >>> b, w = bind_points([[0.1, 0.1, 0]], nodes, k=3)
    >>> b.tolist(), bool(w[0, 2] == 0)
    ([[0, 1, 2, 3]], True)
    """
    from unmesh.spatial import KDTree

    p = as_points(points, "points")
    x = as_points(node_rest, "node_rest")
    if int(k) != k or k < 1:
        raise InputError(f"skin_nodes: expected a positive integer, got {k!r}")
    want = int(min(k + 1, len(x)))
    filtered = blocked is not None or exclude is not None or facing is not None
    cand = int(min(3 * want, len(x))) if filtered else want
    if candidates is not None:
        dist, idx = candidates
        if idx.shape != (len(p), cand):
            raise InputError(f"candidates: expected ({len(p)}, {cand}) arrays, got {idx.shape}")
    else:
        dist, idx = (tree if tree is not None else KDTree(x)).knn(p, cand)
    keep = idx >= 0
    if exclude is not None:
        keep &= ~exclude[np.maximum(idx, 0)]
    if facing is not None and len(p):
        pn, xn = (as_array(a, what, (n, 3), np.float64) for a, what, n in
                  ((facing[0], "facing[0] (point normals)", len(p)), (facing[1], "facing[1] (node normals)", len(x))))
        faces = keep & (np.einsum("sa,sca->sc", pn, xn[np.maximum(idx, 0)]) >= FACING_MIN)
        keep = np.where(faces.any(axis=1)[:, None], faces, keep)   # no node on its side: all count
    if blocked is not None and len(p):
        hide_blocked(keep, p, x, idx, blocked, want)
    # a point hidden from every candidate (a sliver between two cracks) follows its nearest node
    lost = ~keep.any(axis=1) & (idx[:, 0] >= 0)
    keep[lost, 0] = True
    rank = np.cumsum(keep, axis=1)
    keep &= rank <= want
    bind = np.full((len(p), k + 1), -1, dtype=np.int64)
    dd = np.full((len(p), k + 1), np.inf)
    col = rank - 1
    r_, c_ = np.nonzero(keep)
    bind[r_, col[r_, c_]] = idx[r_, c_]
    dd[r_, col[r_, c_]] = dist[r_, c_]
    count = (bind >= 0).sum(axis=1)
    last = np.take_along_axis(dd, np.maximum(count - 1, 0)[:, None], axis=1)
    weights = np.zeros((len(p), k))
    frames = dd[:, 1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        weights = np.where(np.isfinite(frames), skin_weight(frames / np.maximum(last, 1e-300)), 0.0)
    # two visible nodes only: the single frame gets weight 1 (no radius node to spare)
    weights[count == 2, 0] = 1.0
    return bind, weights


def frame_normals(rest: np.ndarray, normals: np.ndarray, bind: np.ndarray, frame: np.ndarray | None = None,
                  points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The rest normal ``N`` of each binding's frames (7.26) and whether it is the node normals'.

    ``N`` is the least-squares plane normal through the bound nodes, oriented along the sum of
    their normals, except where the nodes have no plane (module notes): fewer than 3 nodes,
    an eigenvalue ratio ``lambda_0 / lambda_1 > PLANE_FLATNESS`` of their covariance, or
    ``|N . n_sum| < PLANE_AGREEMENT`` with ``n_sum`` the normalised sum of the node normals,
    or (with ``points``) ``|N . n_p| < PLANE_SURFACE_AGREEMENT`` with ``n_p`` the point's own
    rest normal (the plane is not the surface at the point: a rim surfel of a thin part whose
    nodes lie on its two faces); there ``N`` is the normalised sum of the ``frame`` normals, and the flag tells
    :func:`unmesh.shells._skinning_kernels.deform` to use the node normals it is given for the
    deformed frames too (so ``frame`` must be what it is given at rest).

    Parameters
    ----------
    rest : ndarray (N, 3) float64
        Node rest positions.
    normals : ndarray (N, 3) float64
        Node rest normals.
    bind : ndarray (S, K+1) int64
        Bound nodes (-1 unused).
    frame : ndarray (N, 3) float64, optional
        The node normals the deformation gets at rest (zero rows allowed); ``normals`` if omitted.
    points : ndarray (S, 3) float64, optional
        Rest normals of the bound points (unit); without them only the node tests apply.

    Returns
    -------
    plane : ndarray (S, 3) float64
        Unit normals.
    by_normals : ndarray (S,) uint8
        1 where ``plane`` is the node normals' sum.

    Example
    -------
    >>> x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.01]])
    >>> n = np.tile([0.0, 0, 1], (4, 1))
    >>> plane, flag = frame_normals(x, n, np.array([[0, 1, 2, 3]]))
    >>> flag.tolist(), bool(plane[0, 2] > 0.99)
    ([0], True)
    """
    plane = np.empty((len(bind), 3))
    flag = np.zeros(len(bind), dtype=np.uint8)
    if not len(bind):
        return plane, flag
    _sk.rest_plane_normals(rest, normals, bind, plane)
    valid = bind >= 0
    cnt = valid.sum(axis=1)
    x = np.where(valid[..., None], rest[np.maximum(bind, 0)], 0.0)
    mean = x.sum(axis=1) / np.maximum(cnt, 1)[:, None]
    d = np.where(valid[..., None], x - mean[:, None], 0.0)
    lam = np.linalg.eigvalsh(np.einsum("ska,skb->sab", d, d))

    def unit_sum(nrm: np.ndarray) -> np.ndarray:
        total = np.where(valid[..., None], nrm[np.maximum(bind, 0)], 0.0).sum(axis=1)
        length = np.linalg.norm(total, axis=1)
        return np.where(length[:, None] > 0, total / np.maximum(length, 1e-300)[:, None], [0.0, 0.0, 1.0])

    unit = unit_sum(normals)
    loose = (lam[:, 0] > PLANE_FLATNESS * lam[:, 1]) | \
        (np.abs(np.einsum("sk,sk->s", plane, unit)) < PLANE_AGREEMENT)
    if points is not None:
        loose |= np.abs(np.einsum("sk,sk->s", plane, points)) < PLANE_SURFACE_AGREEMENT
    flag[(cnt >= 3) & loose] = 1
    if frame is not None:
        unit = unit_sum(frame)
    plane[flag == 1] = unit[flag == 1]
    return plane, flag


def usable_frames(rest: np.ndarray, bind: np.ndarray, weights: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """``weights`` (S, K) with 0 for the degenerate frames: rest edge ``e1 = x_i - x_0`` within 30°
    of the frame normal ``plane`` (S, 3) (``|cos| > FRAME_MAX_COS``), where (7.26)'s ``e2`` and
    ``e3`` nearly vanish and local coordinates across ``e1`` blow up.

    Example
    -------
    >>> x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 1]])
    >>> usable_frames(x, np.array([[0, 1, 2]]), np.array([[1.0, 1.0]]), np.array([[0.0, 0, 1]])).tolist()
    [[1.0, 0.0]]
    """
    frames = bind[:, 1:]
    e = rest[np.maximum(frames, 0)] - rest[bind[:, :1]]
    length = np.linalg.norm(e, axis=2)
    cos = np.abs(np.einsum("ska,sa->sk", e, plane)) / np.maximum(length, 1e-300)
    return np.where((frames >= 0) & (cos > FRAME_MAX_COS), 0.0, weights)


def deform_reference(rest: np.ndarray, cur: np.ndarray, cur_normals: np.ndarray, rest_normals: np.ndarray,
                     bind: np.ndarray, weights: np.ndarray, points: np.ndarray,
                     axes: np.ndarray, by_normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy version of the skinning kernel (7.26-7.30), for tests (``by_normals`` (S,):
    the flags of :func:`frame_normals`, none set when omitted; frame weights scaled by the fade
    of the deformed frames, :func:`unmesh.shells._skinning_kernels.frame_fade`).

    Returns
    -------
    points : ndarray (S, 3)
    axes : ndarray (S, 2, 3)
    """
    out_p = np.empty_like(points)
    out_a = np.empty_like(axes)

    def plane(x, nrm, nodes, by_normals):
        nodes = nodes[nodes >= 0]
        o = nrm[nodes].sum(axis=0)
        if len(nodes) < 3 or by_normals:
            return o / np.linalg.norm(o)
        d = x[nodes] - x[nodes].mean(axis=0)
        _, vec = np.linalg.eigh(d.T @ d)
        v = vec[:, 0]
        return v if v @ o >= 0 else -v

    def frame(x, o, j, n):
        e1 = x[j] - x[o]
        ln = np.linalg.norm(e1)
        e2 = np.cross(n, e1) / ln
        e3 = np.cross(e2, e1) / ln
        return np.stack([e1, e2, e3])

    def fade(e1, n):
        c = abs(e1 @ n) / np.linalg.norm(e1)
        t = np.clip((_sk.FRAME_FADE_TO - c) / (_sk.FRAME_FADE_TO - _sk.FRAME_FADE_FROM), 0.0, 1.0)
        return _sk.FRAME_FADE_FLOOR + (1.0 - _sk.FRAME_FADE_FLOOR) * t

    for s in range(len(points)):
        o = bind[s, 0]
        flag = by_normals is not None and bool(by_normals[s])
        n_rest = plane(rest, rest_normals, bind[s], flag)
        n_cur = plane(cur, cur_normals, bind[s], flag)
        acc_p, acc_a, wsum = np.zeros(3), np.zeros((2, 3)), 0.0
        for i in range(weights.shape[1]):
            j, w = bind[s, i + 1], weights[s, i]
            if j < 0 or w <= 0:
                continue
            f, g = frame(rest, o, j, n_rest), frame(cur, o, j, n_cur)
            w = w * fade(g[0], n_cur)
            coord = lambda d, f=f: (f @ d) / np.einsum("ij,ij->i", f, f)  # noqa: E731
            acc_p += w * (coord(points[s] - rest[o]) @ g)
            acc_a += w * np.stack([coord(axes[s, 0]) @ g, coord(axes[s, 1]) @ g])
            wsum += w
        if wsum > 0:
            out_p[s] = cur[o] + acc_p / wsum
            out_a[s] = acc_a / wsum
        else:
            out_p[s] = cur[o] + points[s] - rest[o]
            out_a[s] = axes[s]
    return out_p, out_a


def cover_radii_reference(points: np.ndarray, nbr: np.ndarray, scale2: np.ndarray, radii: np.ndarray,
                          cap: float = COVER_CAP) -> np.ndarray:
    """Plain numpy version of the splat-radius kernel, for tests (see the module notes).

    Parameters
    ----------
    points : ndarray (S, 3)
        Deformed positions.
    nbr : ndarray (S, m) int64
        Rest neighbours.
    scale2 : ndarray (S, m)
        ``(rest radius / rest distance)^2`` per pair, 0 for pairs that do not count.
    radii : ndarray (S,)
        Deformed-axis radii.
    cap : float
        Pairs that would need more than ``cap radii`` count as torn apart.

    Returns
    -------
    ndarray (S,)
        ``max(radii, sqrt(scale2) |p_s - p_j|)`` over the pairs that need at most ``cap radii``.

    Example
    -------
    >>> p = np.array([[0.0, 0, 0], [2.0, 0, 0]])
    >>> cover_radii_reference(p, np.array([[1], [0]]), np.full((2, 1), 0.36), np.full(2, 0.6)).tolist()
    [1.2, 1.2]
    """
    need = np.sqrt(scale2) * np.linalg.norm(points[nbr] - points[:, None], axis=2)
    need = np.where(need <= cap * radii[:, None], need, 0.0)
    return np.maximum(radii, need.max(axis=1))


_CLOUD_FIELDS = ("positions", "normals", "radii", "axes", "colors", "attributes")


def _trusted_cloud(positions: np.ndarray, normals: np.ndarray, radii: np.ndarray, colors: np.ndarray,
                   attributes: dict[str, np.ndarray]) -> SurfelCloud:
    """A circular SurfelCloud from arrays that already hold its invariants, without the O(N) checks.

    The skinning kernel writes unit normals and positive radii, and the colours and
    attributes come from validated clouds; only the validation pass is skipped (it was
    a third of the skinning time).
    """
    import dataclasses

    if tuple(f.name for f in dataclasses.fields(SurfelCloud)) != _CLOUD_FIELDS:   # pragma: no cover - guard
        return SurfelCloud(positions, normals, radii=radii, colors=colors, attributes=attributes)
    cloud = object.__new__(SurfelCloud)
    for name, value in zip(_CLOUD_FIELDS, (positions, normals, radii, None, colors, attributes), strict=True):
        object.__setattr__(cloud, name, value)
    return cloud


class SkinnedSurface(Rebinding):
    """The dense surfel cloud of a shell, bound to its simulation nodes, plus crack surfels.

    Every passive point stores its nodes, frame weights (7.30) and local coordinates (7.27)
    once; :meth:`deform` then costs one frame construction per weighted frame (7.26, 7.28).

    Parameters
    ----------
    cloud : SurfelCloud
        Dense surface in the rest state.
    node_rest : ndarray (N, 3)
        Rest positions of the simulation nodes.
    node_normals : ndarray (N, 3)
        Rest normals of the nodes (orientation of the local planes).
    skin_nodes : int
        Frame nodes per point ``K``.
    frame_normals : ndarray (N, 3), optional
        The node normals :meth:`deform` gets at rest (a simulation's umbrella normals), for the
        frames of points whose nodes have no plane (:func:`frame_normals`); ``node_normals``
        if omitted.

    Example
    -------
    >>> from unmesh.shells.nodes import grid_sheet
    >>> x, _ = grid_sheet(4, 4)
    >>> cloud = SurfelCloud(x[:5] + [0.3, 0.2, 0], np.tile([0, 0, 1.0], (5, 1)), radii=np.full(5, 0.5))
    >>> surf = SkinnedSurface(cloud, x, np.tile([0, 0, 1.0], (16, 1)), skin_nodes=4)
    >>> moved = surf.deform(x + [0, 0, 2.0], np.tile([0, 0, 1.0], (16, 1)))
    >>> bool(np.allclose(moved.positions, cloud.positions + [0, 0, 2]))
    True
    """

    def __init__(self, cloud: SurfelCloud, node_rest: np.ndarray, node_normals: np.ndarray,
                 skin_nodes: int = DEFAULT_SKIN_NODES, frame_normals: np.ndarray | None = None) -> None:
        from unmesh.spatial import KDTree

        self.cloud = cloud
        self.node_rest = np.ascontiguousarray(node_rest, dtype=np.float64)
        self.node_normals = np.ascontiguousarray(node_normals, dtype=np.float64)
        self.frame_normals = None if frame_normals is None else np.ascontiguousarray(frame_normals, dtype=np.float64)
        self.k = int(skin_nodes)
        self.tree = KDTree(self.node_rest)
        axes = np.ascontiguousarray(cloud.tangent_axes())
        pts = np.ascontiguousarray(cloud.positions)
        cross = np.cross(axes[:, 0], axes[:, 1])
        orient = np.where(np.einsum("ij,ij->i", cross, cloud.normals) >= 0, 1.0, -1.0)
        nrm = np.ascontiguousarray(cloud.normals)
        bind, weights = bind_points(pts, self.node_rest, self.k, tree=self.tree, facing=(nrm, self.node_normals))
        plane, by_normals = self._frame_normals(bind, nrm)
        weights = usable_frames(self.node_rest, bind, weights, plane)
        self.dense = _Passive(self.k)
        self.dense.append(points=pts, normals=nrm, axes=axes, orient=orient, colors=cloud.colors, bind=bind, weights=weights,
                          plane=plane, by_normals=by_normals, coords=self._coords(bind, weights, plane, pts, axes),
                          reach=self._reaches(bind, pts))
        self.disc = _Passive(self.k)
        self.excluded = np.zeros(len(self.node_rest), dtype=bool)     # nodes not bound to (crumbs)
        # rest neighbours of the dense surfels and (rest radius / rest distance)^2, for the splat
        # radii (module notes); 0 for the surfel itself, pairs with no common bound node and
        # pairs facing apart (the two sides of a thin part)
        dist, self._cover_nbr = KDTree(pts).knn(pts, int(min(COVER_NEIGHBORS + 1, len(pts))))
        rest_r = np.linalg.norm(axes, axis=2).max(axis=1)
        with np.errstate(divide="ignore"):
            scale2 = np.where(dist > 0, (rest_r[:, None] / dist) ** 2, 0.0)
        facing = np.einsum("sk,sak->sa", nrm, nrm[self._cover_nbr]) >= COVER_FACING
        keep = _cover_pairs(bind, self._cover_nbr, np.arange(len(pts))) & facing
        self._cover_scale2 = np.where(keep, scale2, 0.0)
        self._reach = float(self.dense.view("reach").max()) if self.dense.n else 0.0
        from unmesh.shells.topology import csr_from_groups

        # surfels of the dense cloud grouped by their nearest node at rest (never changes)
        self._owned_offsets, self._owned = csr_from_groups(bind[:, 0].copy(), len(self.node_rest))

    # -- views (dense surfels first, then discontinuity surfels) --------------------------
    def _cat(self, name: str) -> np.ndarray:
        if self.disc.n == 0:
            return self.dense.view(name)
        return np.concatenate([self.dense.view(name), self.disc.view(name)])

    @property
    def points(self) -> np.ndarray:
        """Rest positions (S, 3) of all passive points."""
        return self._cat("points")

    @property
    def axes(self) -> np.ndarray:
        """Rest tangent axes (S, 2, 3)."""
        return self._cat("axes")

    @property
    def bind(self) -> np.ndarray:
        """Bound nodes (S, K + 1): x_0, then the frame nodes by distance (-1 unused)."""
        return self._cat("bind")

    @property
    def weights(self) -> np.ndarray:
        """Frame weights (S, K) of (7.30)."""
        return self._cat("weights")

    @property
    def by_normals(self) -> np.ndarray:
        """(S,) uint8: 1 where the frames use the node normals (:func:`frame_normals`)."""
        return self._cat("by_normals")

    @property
    def discontinuity(self) -> np.ndarray:
        """(S,) uint8: 1 for the discontinuity surfels of the cracks."""
        out = np.zeros(len(self), dtype=np.uint8)
        out[self.dense.n:] = 1
        return out

    def __len__(self) -> int:
        return self.dense.n + self.disc.n

    def _coords(self, bind: np.ndarray, weights: np.ndarray, plane: np.ndarray, points: np.ndarray,
                axes: np.ndarray) -> np.ndarray:
        out = np.empty((len(bind), self.k, _sk.COORDS))
        if len(bind):
            _sk.local_coordinates(self.node_rest, bind, weights, plane, np.ascontiguousarray(points),
                                  np.ascontiguousarray(axes), out)
        return out

    def _bind(self, pts: np.ndarray, normals: np.ndarray, blocked: Any,
              cand: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, ...]:
        """Binding of points (rest positions and surface normals) with visibility, without the
        excluded nodes and the nodes facing away: nodes, weights, frame normals and their flags
        (:func:`frame_normals`), and reaches."""
        if cand is None:
            cand = self.tree.knn(pts, int(min(3 * min(self.k + 1, len(self.node_rest)), len(self.node_rest))))
        b, w = bind_points(pts, self.node_rest, self.k, blocked=blocked, tree=self.tree, candidates=cand,
                           exclude=self.excluded, facing=(normals, self.node_normals))
        plane, by_normals = self._frame_normals(b, normals)
        return b, usable_frames(self.node_rest, b, w, plane), plane, by_normals, self._reaches(b, pts, cand[0])

    def _frame_normals(self, bind: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return frame_normals(self.node_rest, self.node_normals, bind, self.frame_normals, normals)

    def add_discontinuity(self, center: np.ndarray, normal: np.ndarray, radius: float, surface_normal: np.ndarray,
                          blocked: Any) -> None:
        """Add the two discontinuity surfels of one crack disc; see :meth:`add_discontinuities`."""
        self.add_discontinuities([center], [normal], [radius], [surface_normal], blocked)

    def add_discontinuities(self, centers: Any, normals: Any, radii: Any, surface_normals: Any, blocked: Any) -> None:
        """Add the two discontinuity surfels of each crack disc (rest coordinates), bound with visibility.

        They sit a tenth of the radius to either side of the crack plane; each faces away
        from its own side (towards the gap), spans the crack line and the surface normal,
        and takes the colour of a surfel of the nearest node.
        """
        pts, axes, facing, colors, surface = [], [], [], [], []
        for center, normal, radius, surface_normal in zip(centers, normals, radii, surface_normals, strict=True):
            n = np.asarray(normal, dtype=np.float64)
            n = n / np.linalg.norm(n)
            sn = np.asarray(surface_normal, dtype=np.float64)
            along = np.cross(sn, n)
            along /= np.linalg.norm(along)
            up = sn - (sn @ n) * n
            up /= np.linalg.norm(up)
            pts += [center + 0.1 * radius * n, center - 0.1 * radius * n]
            axes += [np.stack([radius * along, radius * up])] * 2
            facing += [-n, n]
            surface += [sn / np.linalg.norm(sn)] * 2
            _, node = self.tree.knn(np.asarray(center, dtype=np.float64)[None], 1)
            owned = self._owned[self._owned_offsets[node[0, 0]]:self._owned_offsets[node[0, 0] + 1]]
            colors += [self.dense.colors[owned[0]] if len(owned) else self.dense.colors[0]] * 2
        if not pts:
            return
        p, a = np.asarray(pts), np.asarray(axes)
        cross = np.cross(a[:, 0], a[:, 1])
        orient = np.where(np.einsum("ij,ij->i", cross, np.asarray(facing)) >= 0, 1.0, -1.0)
        sn = np.asarray(surface)
        b, w, plane, by_normals, reach = self._bind(p, sn, blocked)
        self.disc.append(points=p, normals=sn, axes=a, orient=orient, colors=np.asarray(colors), bind=b, weights=w, plane=plane,
                         by_normals=by_normals,
                         coords=self._coords(b, w, plane, p, a), reach=reach)
        self._reach = max(self._reach, float(reach.max()))

    def deform(self, node_positions: np.ndarray, node_normals: np.ndarray) -> SurfelCloud:
        """The deformed cloud for current node positions and (umbrella) normals.

        Returns
        -------
        SurfelCloud
            Circular surfels (radius = longer deformed tangent axis, enlarged where rest
            neighbours moved apart, see the module notes) with the per-surfel
            attribute ``discontinuity`` (uint8, 1 for crack surfels).
        """
        s = len(self)
        out_p = np.empty((s, 3))
        out_n = np.empty((s, 3))
        out_r = np.empty(s)
        cur = np.ascontiguousarray(node_positions, dtype=np.float64)
        nrm = np.ascontiguousarray(node_normals, dtype=np.float64)
        with threads_for(s, SKIN_PARALLEL_MIN, key="skinning"):
            for part, lo in ((self.dense, 0), (self.disc, self.dense.n)):
                if part.n:
                    hi = lo + part.n
                    _sk.deform(self.node_rest, cur, nrm, part.view("bind"), part.view("weights"), part.view("coords"),
                               part.view("points"), part.view("axes"), part.view("orient"), part.view("by_normals"), out_p[lo:hi],
                               out_n[lo:hi], out_r[lo:hi])
            if self.dense.n:
                n = self.dense.n
                _sk.cover_radii(out_p[:n], self._cover_nbr, self._cover_scale2, COVER_CAP, out_r[:n])
        return _trusted_cloud(out_p, out_n, out_r, *self._static_columns())

    def _static_columns(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Colours (S, 3) and the ``discontinuity`` flags (S,) of the deformed cloud.

        They change only when crack surfels are appended: both are kept in buffers that grow
        like the crack surfels' (the dense part is copied once), and each cloud gets views of
        their first S rows (later appends write only beyond them).
        """
        key = (self.dense.n, self.disc.n)
        st = getattr(self, "_static", None)
        if st is not None and st[0] == key:
            return st[1], st[2]
        s = len(self)
        if self.disc.n:
            dense, disc = self.dense.view("colors"), self.disc.view("colors")
            dtype = np.result_type(dense, disc)
            buf, flags, filled = getattr(self, "_static_buf", (None, None, 0))
            if (buf is None or len(buf) < s or buf.dtype != dtype or filled > s or filled < self.dense.n
                    or getattr(self, "_static_dense", None) != self.dense.n):
                cap = max(s, self.dense.n + 2 * self.disc.n, 16)
                buf = np.zeros((cap, *dense.shape[1:]), dtype=dtype)
                flags = np.zeros(cap, dtype=np.uint8)
                buf[:self.dense.n] = dense
                flags[self.dense.n:] = 1
                filled = self.dense.n
                self._static_dense = self.dense.n
            buf[filled:s] = disc[filled - self.dense.n:]
            self._static_buf = (buf, flags, s)
            colors, discontinuity = buf[:s], flags[:s]
        else:
            colors, discontinuity = self.dense.view("colors"), np.zeros(s, dtype=np.uint8)
        self._static = (key, colors, {"discontinuity": discontinuity})
        return colors, self._static[2]
