"""Point-cloud simplification by hierarchical clustering (Pauly, Gross, Kobbelt 2002).

"Efficient simplification of point-sampled surfaces", section 4.2: the cloud is
split recursively by the plane through a cluster's centroid perpendicular to the
eigenvector of the largest eigenvalue of its covariance matrix, until every
cluster has at most ``max_size`` points and a surface variation
``sigma = l0 / (l0 + l1 + l2)`` (eigenvalues ascending) of at most
``max_variation``. Each cluster then becomes one surfel.

unmesh adds a ``target`` mode (exactly ``target`` clusters: the cluster with the
largest scatter along its principal axis -- largest covariance eigenvalue times
its point count -- is split first, so the clusters end up of similar size and
extent, e.g. for simulation nodes) and, when normals are
given, clusters whose normal cone is wider than 90 degrees count four times as
large and are split by the sign of ``n . e`` (e = dominant axis of the normals;
when that leaves at least 10 % of the points on each side), so that a cluster
does not straddle both sides of a thin part. Everything is deterministic.
"""

from __future__ import annotations

import heapq
from typing import TYPE_CHECKING, Any

import numpy as np

from unmesh._validate import as_indices, as_points, scalar
from unmesh.errors import InputError

if TYPE_CHECKING:
    from unmesh.surfels.cloud import SurfelCloud

__all__ = ["cluster", "cluster_reference", "representatives", "simplify"]


def _options(n: int, target: Any, max_size: Any, max_variation: Any) -> tuple[int, int, float]:
    if target is None and max_size is None and max_variation is None:
        raise InputError("cluster: give target, or max_size and/or max_variation")
    if target is not None:
        if max_size is not None or max_variation is not None:
            raise InputError("cluster: target gives an exact count; do not combine it with max_size or max_variation")
        t = int(target) if not isinstance(target, bool) else -1
        if t != target or t < 1:
            raise InputError(f"target: expected a positive integer, got {target!r}")
        if t > n:
            raise InputError(f"target: expected at most the number of points ({n}), got {t}")
        return t, 0, -1.0
    ms = 0
    if max_size is not None:
        ms = int(max_size) if not isinstance(max_size, bool) else -1
        if ms != max_size or ms < 1:
            raise InputError(f"max_size: expected a positive integer, got {max_size!r}")
    mv = -1.0
    if max_variation is not None:
        mv = scalar(max_variation, "max_variation", 0.0, 1.0 / 3.0)
    return 0, ms, mv


def _labels_from_ranges(n: int, perm: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Labels (N,) numbered by each cluster's smallest point index."""
    raw = np.empty(n, np.int64)
    for c, (s, e) in enumerate(zip(starts, ends, strict=True)):
        raw[perm[s:e]] = c
    first = np.full(len(starts), n, np.int64)
    np.minimum.at(first, raw, np.arange(n))
    rank = np.empty(len(starts), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(starts))
    return rank[raw]


def cluster(points: Any, normals: Any = None, *, target: int | None = None, max_size: int | None = None,
            max_variation: float | None = None) -> np.ndarray:
    """Hierarchical clustering of a point cloud (Pauly et al. 2002, section 4.2).

    Parameters
    ----------
    points : array_like, shape (N, 3)
    normals : array_like, shape (N, 3), optional
        When given, clusters whose normals spread over more than 90 degrees are
        split by normal direction (with 4x priority in ``target`` mode).
    target : int, optional
        Exact number of clusters (1 <= target <= N); the cluster with the largest
        scatter (largest covariance eigenvalue x point count) is split first.
    max_size : int, optional
        Split clusters with more points than this.
    max_variation : float, optional
        Split clusters whose surface variation ``l0 / (l0 + l1 + l2)`` exceeds this
        (in [0, 1/3]).

    Returns
    -------
    numpy.ndarray, shape (N,), int64
        Cluster label of every point, ``0 .. K-1``, numbered in the order of each
        cluster's smallest point index. Deterministic.

    Raises
    ------
    unmesh.errors.InputError
        No criterion, ``target`` combined with a criterion, or ``target > N``.

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> pts = Sphere().surfels(0.1).positions
    >>> labels = cluster(pts, target=50)
    >>> int(labels.max()) + 1, int(np.bincount(labels).min()) > 0
    (50, True)
    """
    from unmesh.surfels._cluster_kernels import cluster_split

    pts = as_points(points, "points")
    n = len(pts)
    if n == 0:
        raise InputError("points: expected at least one point, got none")
    t, ms, mv = _options(n, target, max_size, max_variation)
    use_normals = normals is not None
    nrm = as_points(normals, "normals", length=n) if use_normals else np.zeros((1, 3))
    perm, starts, ends = cluster_split(pts, nrm, use_normals, t, ms, mv)
    return _labels_from_ranges(n, perm, starts, ends)


def representatives(points: Any, labels: Any) -> np.ndarray:
    """Index (K,) of the original point closest to each cluster's centroid (lowest index on ties).

    Parameters
    ----------
    points : array_like, shape (N, 3)
    labels : array_like, shape (N,)
        Cluster labels ``0 .. K-1`` (every label used), e.g. from :func:`cluster`.

    Returns
    -------
    numpy.ndarray, shape (K,), int64
        ``rep[c]`` is a point of cluster ``c``.

    Example
    -------
    >>> pts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [10, 0, 0]])
    >>> representatives(pts, [0, 0, 0, 1]).tolist()
    [1, 3]
    """
    pts = as_points(points, "points")
    lab = as_indices(labels, "labels", (None,), length=len(pts))
    if len(lab) == 0:
        return np.zeros(0, np.int64)
    if lab.min() < 0:
        raise InputError("labels: expected non-negative cluster labels")
    k = int(lab.max()) + 1
    counts = np.bincount(lab, minlength=k)
    if np.any(counts == 0):
        raise InputError(f"labels: expected every label 0..{k - 1} to be used; label {int(np.argmin(counts))} is empty")
    cent = np.zeros((k, 3))
    np.add.at(cent, lab, pts)
    cent /= counts[:, None]
    d2 = ((pts - cent[lab]) ** 2).sum(axis=1)
    order = np.lexsort((np.arange(len(pts)), d2, lab))  # by label, then distance, then index
    first = np.searchsorted(lab[order], np.arange(k))
    return order[first].astype(np.int64)


def simplify(cloud: SurfelCloud, target: int | None = None, *, max_size: int | None = None,
             max_variation: float | None = None, return_labels: bool = False) -> Any:
    """One surfel per cluster of :func:`cluster` (Pauly et al. 2002).

    Each cluster becomes a surfel at its centroid with the normalised mean normal
    (the PCA normal oriented like the mean when the normals cancel out), the mean
    colour, and the radius that covers every member splat in the new tangent
    plane: ``max_i (|P (x_i - c)| + r_i)`` (P = projection onto the plane).
    Floating-point attributes are averaged; other attributes are taken from the
    cluster's representative (:func:`representatives`).

    Parameters
    ----------
    cloud : SurfelCloud
    target : int, optional
        Exact number of surfels in the result.
    max_size, max_variation : optional
        Pauly's split criteria instead of ``target`` (see :func:`cluster`).
    return_labels : bool
        Also return the labels (N,) of the input surfels.

    Returns
    -------
    SurfelCloud or (SurfelCloud, numpy.ndarray)

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> small = simplify(Sphere().surfels(0.1), target=100)
    >>> len(small)
    100
    """
    from unmesh.surfels.cloud import SurfelCloud

    if not isinstance(cloud, SurfelCloud):
        raise InputError(f"cloud: expected a SurfelCloud, got {type(cloud).__name__}")
    labels = cluster(cloud.positions, cloud.normals, target=target, max_size=max_size, max_variation=max_variation)
    k = int(labels.max()) + 1
    counts = np.bincount(labels, minlength=k).astype(np.float64)
    pos = np.zeros((k, 3))
    np.add.at(pos, labels, cloud.positions)
    pos /= counts[:, None]
    nsum = np.zeros((k, 3))
    np.add.at(nsum, labels, cloud.normals)
    length = np.linalg.norm(nsum, axis=1)
    nrm = np.empty((k, 3))
    ok = length > 1e-9 * counts
    nrm[ok] = nsum[ok] / length[ok, None]
    for c in np.flatnonzero(~ok):  # normals cancel: use the PCA normal
        sel = cloud.positions[labels == c] - pos[c]
        _, vec = np.linalg.eigh(sel.T @ sel)
        nrm[c] = vec[:, 0]
    col = np.zeros((k, 3))
    np.add.at(col, labels, cloud.colors)
    col = np.clip(col / counts[:, None], 0.0, 1.0)
    rel = cloud.positions - pos[labels]
    tang = rel - np.einsum("ij,ij->i", rel, nrm[labels])[:, None] * nrm[labels]
    reach = np.linalg.norm(tang, axis=1) + cloud.radii
    radii = np.zeros(k)
    np.maximum.at(radii, labels, reach)
    reps = representatives(cloud.positions, labels)
    attrs: dict[str, np.ndarray] = {}
    for name, arr in cloud.attributes.items():
        if np.issubdtype(arr.dtype, np.floating):
            acc = np.zeros((k, *arr.shape[1:]))
            np.add.at(acc, labels, arr)
            attrs[name] = acc / counts.reshape((k,) + (1,) * (arr.ndim - 1))
        else:
            attrs[name] = arr[reps]
    out = SurfelCloud(pos, nrm, radii=radii, colors=col, attributes=attrs)
    return (out, labels) if return_labels else out


def cluster_reference(points: np.ndarray, normals: np.ndarray | None, target: int = 0, max_size: int = 0,
                      max_variation: float = -1.0) -> np.ndarray:
    """Pure Python/numpy reference of :func:`cluster` (same rules, heapq, recursion)."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)

    def canonical(axis: np.ndarray) -> np.ndarray:
        return axis if axis[np.argmax(np.abs(axis))] >= 0 else -axis

    def stats(idx: np.ndarray) -> tuple[float, np.ndarray, float, np.ndarray, bool]:
        c = pts[idx].mean(axis=0)
        d = pts[idx] - c
        w, v = np.linalg.eigh(d.T @ d / len(idx))
        tot = w.sum()
        axis = v[:, 2]
        spread = False
        if normals is not None:
            m = normals[idx].sum(axis=0)
            lm = np.linalg.norm(m)
            spread = bool(lm <= 0 or np.any(normals[idx] @ (m / max(lm, 1e-300)) < 0))
            if spread:
                axis = np.linalg.eigh(normals[idx].T @ normals[idx])[1][:, 2]
        return max(w[2], 0.0), canonical(axis), (w[0] / tot if tot > 0 else 0.0), c, spread

    def split(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from unmesh.surfels._cluster_kernels import MIN_NORMAL_SHARE

        _, axis, _, c, spread = stats(idx)
        side = (normals[idx] @ axis <= 0) if spread else ((pts[idx] - c) @ axis <= 0)
        if spread and min(side.sum(), (~side).sum()) < MIN_NORMAL_SHARE * len(idx):
            c = pts[idx].mean(axis=0)
            d = pts[idx] - c
            axis = canonical(np.linalg.eigh(d.T @ d / len(idx))[1][:, 2])
            side = d @ axis <= 0
        if side.all() or not side.any():
            o = np.argsort(pts[idx] @ axis, kind="mergesort")
            return idx[o[: len(idx) // 2]], idx[o[len(idx) // 2:]]
        return idx[side], idx[~side]

    clusters: list[np.ndarray] = [np.arange(n)]
    if target > 0:
        from unmesh.surfels._cluster_kernels import SPREAD_WEIGHT

        def key(idx: np.ndarray) -> float:
            if len(idx) < 2:
                return -1.0
            lam, _, _, _, sp = stats(idx)
            return lam * len(idx) * (SPREAD_WEIGHT if sp else 1.0)

        heap = [(-key(clusters[0]), 0)]
        while len(clusters) < target and heap:
            _, cid = heapq.heappop(heap)
            a, b = split(clusters[cid])
            clusters[cid] = a
            clusters.append(b)
            for k in (cid, len(clusters) - 1):
                heapq.heappush(heap, (-key(clusters[k]), k))
    else:
        stack = [0]
        while stack:
            cid = stack.pop()
            idx = clusters[cid]
            if len(idx) < 2:
                continue
            _, _, var, _, sp = stats(idx)
            if not ((max_size > 0 and len(idx) > max_size) or (max_variation >= 0 and var > max_variation) or sp):
                continue
            a, b = split(idx)
            clusters[cid] = a
            clusters.append(b)
            stack.extend([cid, len(clusters) - 1])
    raw = np.empty(n, np.int64)
    for c, idx in enumerate(clusters):
        raw[idx] = c
    first = np.array([idx.min() for idx in clusters])
    rank = np.empty(len(clusters), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(clusters))
    return rank[raw]
