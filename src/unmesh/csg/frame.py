"""One frame of a CSG model ready to splat: surfel classes, partners and the clip tree (4.1.2, 4.2).

:func:`prepare` evaluates a model for its current patch transforms:

1. the clipping partners of every surfel (4.2.1, :func:`unmesh.csg.partners.find_partners`);
2. the class of every surfel (4.1.2): Algorithm 4.2 at the surfel centre, with insidePatch of
   every patch the surfel does *not* intersect taken over the whole patch (4.4) and *unknown*
   for the patches it intersects (in Kleene logic: unknown may be either); a surfel whose
   centre is off the surface whatever the unknowns are is ``OUTSIDE`` (discarded), one with
   partners is an ``EDGE`` surfel (clipped per fragment: the
   conservative test, distance to another patch's surfel below the sum of radii), the rest
   are ``SURFACE`` surfels (splatted as usual);
3. the surfels to draw (normals flipped at complemented leaves, whose surface faces the other
   way) and a :class:`unmesh.render.ClipTree` with the partners of the edge surfels.

Surface and edge surfels go through one splatting pass, so they are merged before
normalisation (4.2.3) and blend across edges.

Example
-------
>>> from unmesh.csg.model import Patch
>>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=2.0, spacing=0.25)
>>> b = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=2.0, spacing=0.25)
>>> f = prepare(a & b)
>>> sorted(set(f.classes.tolist()))
[0, 1, 2]
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from unmesh.csg._piece_kernels import piece_labels
from unmesh.csg.cache import local_points, local_tree, overlap_pairs, patch_memo
from unmesh.csg.classify import inside_patch, maybe_on_surface, tree_values
from unmesh.csg.model import FlatTree, Node, flatten
from unmesh.csg.partners import find_partners
from unmesh.errors import InputError
from unmesh.render.splat import ClipTree, SurfelArrays
from unmesh.surfels import SurfelCloud
from unmesh.surfels.cloud import similarity_scale

__all__ = ["EDGE", "OUTSIDE", "SURFACE", "CSGFrame", "centre_classified", "concatenate_frames", "prepare", "select", "world_cloud"]

#: Surfel classes of 4.1.2.
SURFACE, EDGE, OUTSIDE = 0, 1, 2

#: Surfels to classify from which those already decided are dropped after each patch (for
#: fewer the tree evaluation costs more than the queries it saves).
_DECIDE_EARLY = 2048

#: Surfels asked against one patch from which insidePatch values of earlier frames are looked up
#: (:func:`unmesh.csg.cache.patch_memo`); fewer are asked directly.
_MEMO_FROM = 256

#: Surfels of one patch asked against another from which only representatives of their pieces
#: are asked (insidePatch of the other patch is constant over a piece of surfels that do not
#: meet it, as over the pieces of 4.1.2; pieces whose representatives disagree are asked whole).
_PIECES_FROM = 256

#: Frames of the models evaluated so far (held weakly), per (method, rule).
_FRAMES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class CSGFrame:
    """A model evaluated for one frame.

    Attributes
    ----------
    flat : FlatTree
    cloud : SurfelCloud
        Every surfel of every leaf (world space, outward normals), leaf by leaf.
    leaf : (N,) int64
        Leaf number of each surfel of :attr:`cloud`.
    classes : (N,) int8
        :data:`SURFACE`, :data:`EDGE` or :data:`OUTSIDE`.
    offsets, partners : CSR of the clipping partners of every surfel (indices into :attr:`cloud`).
    arrays : SurfelArrays
        The drawn (surface and edge) surfels.
    clip : ClipTree
        Their clipping partners and the tree.
    """

    flat: FlatTree
    cloud: SurfelCloud
    leaf: np.ndarray
    classes: np.ndarray
    offsets: np.ndarray
    partners: np.ndarray
    arrays: SurfelArrays
    clip: ClipTree

    @property
    def edge_surfels(self) -> int:
        """Number of edge surfels."""
        return int((self.classes == EDGE).sum())


def prepare(model: Node, method: str = "grid", rule: str = "two", reuse: bool = True) -> CSGFrame:
    """Evaluate ``model`` for its current transforms (see the module notes).

    Parameters
    ----------
    model : Node
    method : {"grid", "clipbuffer", "range"}
        Partner search (4.2.1).
    rule : {"two", "closest"}
        insidePatch for the surfel centres (4.4 or 4.3).
    reuse : bool
        Models are immutable (a moved patch is a new patch, so a new model): the frame of a
        model drawn before is returned again (a static scene seen from many cameras costs one
        evaluation). ``False`` always evaluates. Per-patch data (k-d trees, overlaps) is reused
        in any case (:mod:`unmesh.csg.cache`).
    """
    if not isinstance(model, Node):
        raise InputError(f"model: expected a CSG Patch or node, got {type(model).__name__}")
    if reuse:
        hit = _FRAMES.get(model, {}).get((method, rule))
        if hit is not None:
            return hit
    frame = _evaluate(model, method, rule)
    _FRAMES.setdefault(model, {})[(method, rule)] = frame
    return frame


def world_cloud(leaves: list) -> SurfelCloud:
    """The world clouds of the patches ``leaves`` concatenated (what
    ``SurfelCloud.concatenate([p.world_cloud() for p in leaves], attributes="none")`` gives).

    Circular patches under similarity transforms (every shipped scene) are written straight
    into preallocated arrays: positions ``p L^T + t``, normals ``n s L^-1`` (unit for a
    similarity ``L`` of scale ``s``, not normalised again), radii ``s r``; the result is
    :meth:`SurfelCloud.unchecked`. Other patches take the general path."""
    scales = []
    for p in leaves:
        if p.cloud.is_elliptical:
            scales = None
            break
        scales.append(1.0 if p.transform is None else similarity_scale(p.transform[:3, :3]))
    if len(leaves) == 1 or scales is None or any(s is None for s in scales):
        clouds = [p.world_cloud() for p in leaves]
        return SurfelCloud.concatenate(clouds, attributes="none") if len(clouds) > 1 else clouds[0]
    n = sum(len(p.cloud) for p in leaves)
    pos = np.empty((n, 3))
    nrm = np.empty((n, 3))
    radii = np.empty(n)
    colors = np.empty((n, 3))
    a = 0
    for p, scale in zip(leaves, scales, strict=True):
        c = p.cloud
        b = a + len(c)
        colors[a:b] = c.colors
        if p.transform is None:
            pos[a:b] = c.positions
            nrm[a:b] = c.normals
            radii[a:b] = c.radii
        else:
            lin = p.transform[:3, :3]
            np.matmul(c.positions, lin.T, out=pos[a:b])
            pos[a:b] += p.transform[:3, 3]
            np.matmul(c.normals, np.linalg.inv(lin) * scale, out=nrm[a:b])
            np.multiply(c.radii, scale, out=radii[a:b])
        a = b
    return SurfelCloud.unchecked(pos, nrm, radii, colors)


def _evaluate(model: Node, method: str, rule: str) -> CSGFrame:
    flat = flatten(model)
    cloud = world_cloud(flat.leaves)
    sizes = [len(p.cloud) for p in flat.leaves]
    leaf = np.repeat(np.arange(len(sizes)), sizes)
    radii = np.asarray(cloud.radii, dtype=np.float64)
    offsets, partners = find_partners(cloud.positions, radii, leaf, cloud.normals, method)
    n = len(cloud)
    # which leaves each surfel intersects
    rows = np.repeat(np.arange(n), np.diff(offsets))
    meets = np.zeros((len(sizes), n), dtype=bool)
    meets[leaf[partners], rows] = True
    has = np.diff(offsets) > 0
    # surfels between edges keep one class: classify the edge surfels and a few
    # representatives of every connected piece of the other surfels of a patch, exactly
    # (every member) where the representatives disagree
    comp = _pieces(flat.leaves, sizes, has)
    rep = _representatives(comp)
    on, raw = _classify(flat, sizes, cloud, leaf, meets, has | rep, rule)
    mixed = _disagreeing(comp, rep, on)
    if mixed.any():
        on2, _ = _classify(flat, sizes, cloud, leaf, meets, mixed, rule)
        on[mixed] = on2[mixed]
    members = (comp >= 0) & ~rep & ~mixed
    if members.any():
        first = np.full(comp.max() + 1, -1)
        first[comp[rep]] = np.flatnonzero(rep)
        on[members] = on[first[comp[members]]]
    classes = np.where(~on, OUTSIDE, np.where(has, EDGE, SURFACE)).astype(np.int8)
    keep = np.flatnonzero(classes != OUTSIDE)
    # drawn surfels
    flip = flat.invert[flat.leaf_node[leaf[keep]]].astype(bool)
    nrm = cloud.normals[keep].copy()
    nrm[flip] *= -1.0
    axes = None if cloud.axes is None else np.ascontiguousarray(cloud.tangent_axes()[keep])
    arrays = SurfelArrays(np.ascontiguousarray(cloud.positions[keep]), np.ascontiguousarray(nrm),
                          np.ascontiguousarray(radii[keep]), axes, np.ascontiguousarray(cloud.colors[keep]))
    clip = ClipTree(*_partner_rows(flat, cloud, leaf, radii, offsets, partners, keep, classes, raw), flat.table(),
                    flat.leaf_node[leaf[keep]])
    return CSGFrame(flat, cloud, leaf, classes, offsets, partners, arrays, clip)


def centre_classified(model: Node, rule: str = "two") -> SurfelCloud:
    """The conventional CSG result of Fig. 4.3 (a): the surfels whose *centre* lies on the
    result surface (Algorithm 4.2 with every patch classified as a whole, 4.4), normals flipped
    at complemented leaves, unclipped. Splatting them shows holes along the edges.

    Example
    -------
    >>> from unmesh.csg.model import Patch
    >>> a = Patch.halfspace((0, 0, 0), (0, 0, 1), extent=2.0, spacing=0.5)
    >>> b = Patch.halfspace((0, 0, 0), (1, 0, 0), extent=2.0, spacing=0.5)
    >>> len(centre_classified(a & b))
    16
    """
    flat = flatten(model)
    cloud = world_cloud(flat.leaves)
    sizes = [len(p.cloud) for p in flat.leaves]
    leaf = np.repeat(np.arange(len(sizes)), sizes)
    none = np.zeros((len(sizes), len(cloud)), dtype=bool)
    on, _ = _classify(flat, sizes, cloud, leaf, none, np.ones(len(cloud), dtype=bool), rule)
    flip = flat.invert[flat.leaf_node[leaf]].astype(bool)
    nrm = cloud.normals.copy()
    nrm[flip] *= -1.0
    return cloud.replace(normals=nrm).subset(on)


def _pieces(leaves: list, sizes: list[int], edge: np.ndarray) -> np.ndarray:
    """(N,) int64 label of the connected piece (overlapping discs of one patch, edge surfels
    removed) of every non-edge surfel; -1 for edge surfels. The overlaps of each patch are
    cached per cloud (:func:`unmesh.csg.cache.overlap_pairs`)."""
    comp = np.full(len(edge), -1, dtype=np.int64)
    base = 0
    start = 0
    for patch, n in zip(leaves, sizes, strict=True):
        ed = np.ascontiguousarray(edge[start:start + n])
        labels, count = piece_labels(n, overlap_pairs(patch.cloud), ed)
        comp[start:start + n] = np.where(labels >= 0, labels + base, -1)
        base += count
        start += n
    return comp


def pieces_reference(leaves: list, sizes: list[int], edge: np.ndarray) -> np.ndarray:
    """scipy reference of :func:`_pieces` (the same partition, pieces numbered per patch in the
    order of their lowest surfel)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    comp = np.full(len(edge), -1, dtype=np.int64)
    base = 0
    start = 0
    for patch, n in zip(leaves, sizes, strict=True):
        ed = edge[start:start + n]
        pairs = overlap_pairs(patch.cloud)
        pairs = pairs[~(ed[pairs[:, 0]] | ed[pairs[:, 1]])]
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        labels = labels[~ed]
        if len(labels):
            _, first, inv = np.unique(labels, return_index=True, return_inverse=True)
            rank = np.empty(len(first), dtype=np.int64)
            rank[np.argsort(first, kind="stable")] = np.arange(len(first))
            comp[start:start + n][~ed] = rank[inv] + base
            base += len(first)
        start += n
    return comp


def _representatives(comp: np.ndarray, per: int = 4) -> np.ndarray:
    """(N,) bool: up to ``per`` surfels of every piece, spread over its members."""
    rep = np.zeros(len(comp), dtype=bool)
    idx = np.flatnonzero(comp >= 0)
    if len(idx) == 0:
        return rep
    order = idx[np.argsort(comp[idx], kind="stable")]
    labels = comp[order]
    starts = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
    sizes = np.diff(np.r_[starts, len(order)])
    for q in range(per):
        rep[order[starts + (q * sizes) // per]] = True
    return rep


def _disagreeing(comp: np.ndarray, rep: np.ndarray, on: np.ndarray) -> np.ndarray:
    """(N,) bool: the members of pieces whose representatives were classified differently."""
    if not rep.any():
        return np.zeros(len(comp), dtype=bool)
    m = comp.max() + 1
    n_on = np.bincount(comp[rep], weights=on[rep].astype(float), minlength=m)
    n_all = np.bincount(comp[rep], minlength=m)
    bad = (n_on > 0) & (n_on < n_all)
    return (comp >= 0) & bad[np.maximum(comp, 0)] & ~rep


def _classify(flat: FlatTree, sizes: list[int], cloud: SurfelCloud, leaf: np.ndarray, meets: np.ndarray,
              which: np.ndarray, rule: str) -> tuple[np.ndarray, np.ndarray]:
    """Centre classification of the surfels ``which`` of the world cloud ``cloud`` (the patches'
    surfels in leaf order, ``sizes`` of them each): (N,) on-surface flags (Kleene logic,
    unknown for the patches a surfel intersects) and the raw insidePatch values (L, N) int8
    (-1 where not asked).

    Patches are asked one after the other, and a surfel whose centre is already off the
    surface whatever the patches not asked yet say is not asked again (Kleene logic is
    monotone: more known values never turn *off* into *on* or *unknown*). Values of earlier
    frames are reused for pairs of patches that did not move (:func:`unmesh.csg.cache.patch_memo`)."""
    n = len(cloud)
    idx = np.flatnonzero(which)
    lw = leaf[idx]
    values = np.full((len(sizes), len(idx)), -1, dtype=np.int8)
    raw = np.full((len(sizes), n), -1, dtype=np.int8)
    open_ = np.ones(len(idx), dtype=bool)
    starts = np.concatenate([[0], np.cumsum(sizes)])
    for j in range(len(sizes)):
        ask = open_ & (lw != j) & ~meets[j, idx]
        if not ask.any():
            continue
        patch = flat.leaves[j]
        sel = idx[ask]
        v = np.empty(len(sel), dtype=bool)
        # values of patches that did not move since an earlier frame are reused (cache.patch_memo)
        todo = []
        pieced = []  # surfels of one patch valued by pieces (cf. _pieces): (rows, labels, representatives, memo, local)
        li = leaf[sel]
        if len(sel) < _MEMO_FROM:  # few points: asking costs less than looking them up
            todo.append((np.arange(len(sel)), None, None))
            li = li[:0]
        for i in np.unique(li):
            m = np.flatnonzero(li == i)
            memo = patch_memo(patch, flat.leaves[i], rule)
            local = sel[m] - starts[i]
            known = memo[local]
            v[m] = known > 0
            miss = known < 0
            if miss.any() and miss.sum() >= _PIECES_FROM:  # the pieces of these surfels: ask a few of each
                lab = _asked_pieces(flat.leaves[i].cloud, local[miss])
                rep = _representatives(lab)
                todo.append((m[miss][rep], memo, local[miss][rep]))
                pieced.append((m[miss], lab, rep, memo, local[miss]))
            elif miss.any():
                todo.append((m[miss], memo, local[miss]))
        if todo:
            _ask(patch, cloud, sel, rule, v, todo)
        for m, lab, rep, memo, local in pieced:
            on_rep = np.zeros(len(m), dtype=bool)
            on_rep[rep] = v[m[rep]]
            mixed = _disagreeing(lab, rep, on_rep)
            first = np.full(lab.max() + 1, -1)
            first[lab[rep]] = np.flatnonzero(rep)
            same = ~rep & ~mixed
            v[m[same]] = v[m[first[lab[same]]]]
            if mixed.any():
                _ask(patch, cloud, sel, rule, v, [(m[mixed], memo, local[mixed])])
        raw[j, sel] = v
        values[j, ask] = v != bool(flat.invert[flat.leaf_node[j]])
        if len(idx) >= _DECIDE_EARLY:
            open_ &= _maybe_on(flat, values, lw) != 0
    on = np.ones(n, dtype=bool)
    on[idx] = _maybe_on(flat, values, lw) != 0
    return on, raw


def _ask(patch, cloud: SurfelCloud, sel: np.ndarray, rule: str, v: np.ndarray, todo: list) -> None:
    """insidePatch of ``patch`` at the centres ``cloud.positions[sel[rows]]``
    of every ``(rows, memo, local)`` of ``todo`` into ``v[rows]`` (and ``memo[local]``)."""
    rows = np.concatenate([t[0] for t in todo])
    pts = cloud.positions[sel[rows]]
    x = local_points(patch.transform, pts)
    if x is None:  # not a similarity: in world space
        w = inside_patch(patch.world_cloud(), pts, rule)
    else:
        w = inside_patch(patch.cloud, x, rule, tree=local_tree(patch.cloud))
    v[rows] = w
    at = 0
    for m, memo, local in todo:
        if memo is not None:
            memo[local] = w[at:at + len(m)]
        at += len(m)


def _asked_pieces(source: SurfelCloud, local: np.ndarray) -> np.ndarray:
    """Labels (M,) int64 of the connected pieces (overlapping discs, :func:`_pieces`) that the
    surfels ``local`` (M,) of the patch cloud ``source`` form among themselves."""
    out = np.ones(len(source), dtype=bool)
    out[local] = False
    labels, _ = piece_labels(len(source), overlap_pairs(source), out)
    return labels[local]


def _maybe_on(flat: FlatTree, values: np.ndarray, lw: np.ndarray) -> np.ndarray:
    """Algorithm 4.2 at surfel centres of leaves ``lw`` (M,) with leaf values (L, M) in Kleene
    logic: a surfel is discarded only when its centre is off the surface whatever the patches
    it intersects (unknown) say (the neutral unknown of 4.9/4.10 could discard surfels that are
    partly on the surface). (M,) int8: 0 off, 1 on, -1 depends on unknowns."""
    vals = tree_values(flat, values, logic="kleene")
    on = np.ones(len(lw), dtype=np.int8)
    for j in range(len(flat.leaves)):
        sl = np.flatnonzero(lw == j)
        if len(sl):
            on[sl] = maybe_on_surface(flat, vals[:, sl], j)
    return on


def _partner_rows(flat: FlatTree, cloud: SurfelCloud, leaf: np.ndarray, radii: np.ndarray, offsets: np.ndarray,
                  partners: np.ndarray, keep: np.ndarray, classes: np.ndarray,
                  raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR offsets and rows ``(c, n, node)`` of the partners of the drawn surfels.

    An edge surfel also gets one constant row for every other patch it does not intersect: a
    plane ``100 r`` away that classifies the whole surfel as its centre was classified against
    that patch (inside or outside). Algorithm 4.4 would return *unknown* there, and (4.9)/(4.10)
    treat unknown as neutral, which is wrong when the surfel lies wholly outside an operand of an
    intersection inside a union, e.g. a fragment of ``c`` in ``(a & ~b) | c`` that meets only
    ``b`` and lies outside ``a``: it must stay, while ``unknown & ~[x inside b]`` could drop it.
    The constant rows make the patch's known value count instead.
    """
    nl = len(flat.leaves)
    edge = classes[keep] == EDGE
    const = np.zeros((len(keep), nl), dtype=bool)
    const[edge] = raw[:, keep[edge]].T >= 0
    counts = np.diff(offsets)[keep] + const.sum(axis=1)
    koff = np.zeros(len(keep) + 1, dtype=np.int64)
    np.cumsum(counts, out=koff[1:])
    rows = np.empty((koff[-1], 7))
    nreal = np.diff(offsets)[keep]
    real = partners[np.repeat(offsets[keep] - np.cumsum(nreal) + nreal, nreal) + np.arange(nreal.sum())]
    dst_real = np.repeat(koff[:-1], nreal) + (np.arange(len(real)) - np.repeat(np.cumsum(nreal) - nreal, nreal))
    rows[dst_real, :3] = cloud.positions[real]
    rows[dst_real, 3:6] = cloud.normals[real]
    rows[dst_real, 6] = flat.leaf_node[leaf[real]]
    si, lj = np.nonzero(const)
    rank = np.arange(len(si)) - np.repeat(np.cumsum(const.sum(1)) - const.sum(1), const.sum(1))
    dst = koff[si] + nreal[si] + rank
    s = keep[si]
    nrm = cloud.normals[s]
    # inside: the plane lies 100 r in front of the surfel; outside: 100 r behind it
    sign = np.where(raw[lj, s] > 0, 1.0, -1.0)
    rows[dst, :3] = cloud.positions[s] + (sign * 100.0 * radii[s])[:, None] * nrm
    rows[dst, 3:6] = nrm
    rows[dst, 6] = flat.leaf_node[lj]
    return koff, rows


def concatenate_frames(frames: list[CSGFrame]) -> tuple[SurfelArrays, ClipTree]:
    """The drawn surfels and clip trees of several frames as one splat input (node numbers of
    later trees shifted; each tree keeps its own root)."""
    if len(frames) == 1:
        return frames[0].arrays, frames[0].clip
    shift = 0
    trees, leaves, prows, offs = [], [], [], []
    base = 0
    for f in frames:
        t = f.clip.tree.copy()
        t[:, 1] = np.where(t[:, 1] >= 0, t[:, 1] + shift, -1)
        t[:, 2] += shift
        trees.append(t)
        leaves.append(f.clip.leaf + shift)
        p = f.clip.partners.copy()
        p[:, 6] += shift
        prows.append(p)
        offs.append(f.clip.offsets[:-1] + base)
        base += len(p)
        shift += len(t)
    offsets = np.concatenate([*offs, np.array([base])])
    a = [f.arrays for f in frames]
    axes = None
    if any(x.axes is not None for x in a):
        axes = np.concatenate([x.axes if x.axes is not None else _circle_axes(x) for x in a])
    arrays = SurfelArrays(*(np.ascontiguousarray(np.concatenate([getattr(x, k) for x in a]))
                            for k in ("positions", "normals", "radii")), axes,
                          np.ascontiguousarray(np.concatenate([x.colors for x in a])))
    return arrays, ClipTree(offsets, np.concatenate(prows), np.concatenate(trees), np.concatenate(leaves))


def _circle_axes(a: SurfelArrays) -> np.ndarray:
    return SurfelCloud(a.positions, a.normals, radii=a.radii).tangent_axes()


def select(arrays: SurfelArrays, clip: ClipTree, mask: np.ndarray) -> tuple[SurfelArrays, ClipTree]:
    """The drawn surfels where ``mask`` (N,) bool is true, with their partners."""
    idx = np.flatnonzero(mask)
    counts = np.diff(clip.offsets)[idx]
    off = np.zeros(len(idx) + 1, dtype=np.int64)
    np.cumsum(counts, out=off[1:])
    starts = np.repeat(clip.offsets[idx] - off[:-1], counts)
    rows = starts + np.arange(off[-1])
    sub = SurfelArrays(*(np.ascontiguousarray(getattr(arrays, k)[idx]) for k in ("positions", "normals", "radii")),
                       None if arrays.axes is None else np.ascontiguousarray(arrays.axes[idx]),
                       np.ascontiguousarray(arrays.colors[idx]))
    return sub, ClipTree(off, clip.partners[rows], clip.tree, clip.leaf[idx])
