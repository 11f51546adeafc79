"""EWA surface splatting with partial updates (thesis 3.2, 3.2.1, 5.7).

A :class:`SplatRenderer` owns the buffers of one view: the visibility buffer of the extended
depth test and the *unnormalised* sums ``sum w``, ``sum w c``, ``sum w n``, ``sum w z`` with a
fragment count per pixel. :meth:`SplatRenderer.render` is a full update (visibility pass, then
accumulation); :meth:`SplatRenderer.splat` and :meth:`SplatRenderer.unsplat` add or subtract the
very same per-fragment contributions against the stored visibility buffer, so after any sequence
of updates the normalised image equals a full re-render of the final surfel set wherever that
re-render's visibility buffer is the same (5.7: "the partial update does not change the depth
buffer"). Sums are float64 and a pixel whose fragment count returns to zero is reset exactly.

Fragments (see :mod:`unmesh.render._splat_kernels`): the pixel ray meets the surfel plane at
``(u, v)`` in semi-axis units (perspective correct, any surfel orientation), the screen-space
low-pass filter of EWA splatting (Zwicker et al. 2001) is approximated by the union with a disc
of radius ``filter_radius`` pixels around the projected centre (Botsch et al. 2005; for surfels
seen edge-on an ellipse reaching ``filter_radius`` across their outline and up to one pixel
along it, see :mod:`unmesh.render._splat_kernels`), and the
clipped Gaussian ``w = exp(-kappa rho^2)``, ``rho < 1``, is the reconstruction kernel. The depth
tolerance of the extended depth test is ``eps_s = depth_tolerance * r_s`` per surfel (3.2.1).

Clipping (chapter 4) is done per fragment in the one fragment loop: :class:`ClipPlanes`
(per-surfel planes) or :class:`ClipTree` (clipping partners and a CSG tree, Algorithm 4.2; built
by :mod:`unmesh.csg`). :class:`ClipSurfels`, the discontinuity surfels of the drawn clouds (4.3,
see :mod:`unmesh.surfels.cloud`), are invisible: the geometry ones become a :class:`ClipTree`
(:func:`discontinuity_clip`) that cuts the surface surfels crossing them to a clean edge (the
crack surfels of the thin shells); texture discontinuity surfels clip the colour only, by a
second pass of :func:`unmesh.render.render` (see :mod:`unmesh.render.pipeline`).

Example
-------
>>> import numpy as np
>>> from unmesh import SurfelCloud
>>> from unmesh.render import Camera
>>> cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5])
>>> r = SplatRenderer(Camera((0, 0, 3), (0, 0, 0), width=32, height=32, ortho=2.0))
>>> g = r.render(cloud).gbuffer()
>>> bool(g.coverage[16, 16]), int(g.coverage.sum()) > 100
(True, True)
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_indices, scalar
from unmesh.errors import InputError
from unmesh.render._kernels import SERIAL_BELOW, serial_if_small, tile_order
from unmesh.render._splat_kernels import NPARAM, splat_resolve, splat_setup_bin, splat_tiles
from unmesh.render.camera import Camera
from unmesh.render.shading import GBuffer, RenderResult, shade
from unmesh.render.shading import _window as _check_window
from unmesh.spatial import KDTree
from unmesh.surfels import SurfelCloud
from unmesh.surfels.cloud import GEOMETRY_DISCONTINUITY, SURFACE, TEXTURE_DISCONTINUITY

__all__ = ["DISCONTINUITY_MIN_ANGLE", "FILTER_RADIUS", "ClipPlanes", "ClipSurfels", "ClipTree", "SplatOptions", "SplatRenderer", "SurfelArrays", "discontinuity_clip", "surfel_arrays"]

#: Default radius (pixels) of the screen-space filter: just above sqrt(2)/2 (0.7071), the smallest
#: disc that always contains a pixel centre (the fragment test ``rho < 1`` is strict), so every
#: surfel still reaches a pixel; the particle splatter uses the same bound.
FILTER_RADIUS = 0.71
#: Per-thread work arrays of :meth:`SplatRenderer._run` (surfel parameters, boxes, groups) and of
#: ``render()``'s spent renderers (visibility buffer; the sums of :func:`_thread_sums`), shared
#: by all renderers of a thread, so that repeated ``render()`` calls neither allocate nor page
#: in ~190 MB per 10^6 surfels and 1024x1024 pixels. Each thread has its own (the studio renders
#: from a worker thread); memory: one set per thread, the largest sizes met (the sums: the last
#: image shape), freed with the thread.
_SCRATCH = threading.local()
#: The buffers of a :class:`SplatRenderer`, allocated by its first :meth:`~SplatRenderer.clear`.
_BUFFERS = frozenset({"_opaque", "zvis", "sum_weight", "sum_color", "sum_normal", "sum_depth", "count", "_dirty",
                      "_stale"})
#: Placeholder of the clip mode when splatting with a :class:`ClipTree` (without one the tree
#: arguments of the kernels are None, which compiles the plain kernels without the tree code).
_NO_MODE = np.zeros(1, dtype=np.int8)


def _thread_sums(h: int, w: int, tile: int) -> tuple[np.ndarray, ...]:
    """This thread's sums for ``render()``'s spent renderers (see :data:`_SCRATCH`):
    ``sum_weight, sum_color, sum_normal, sum_depth, count`` of shape (h, w) and their per-tile
    ``dirty`` flags (:func:`~unmesh.render._splat_kernels.splat_tiles`), kept between calls
    with their contents, so a full update needs to overwrite only its tiles. One set per thread:
    a call with another image shape or tile edge drops it and allocates zeroed arrays."""
    key = (h, w, tile)
    sums = getattr(_SCRATCH, "sums", None)
    if sums is None or sums[0] != key:
        _SCRATCH.sums = None  # the old set is freed before the new one is allocated
        ntiles = ((w + tile - 1) // tile) * ((h + tile - 1) // tile)
        sums = _SCRATCH.sums = (key, np.zeros((h, w)), np.zeros((h, w, 3)), np.zeros((h, w, 3)), np.zeros((h, w)),
                                np.zeros((h, w), dtype=np.int32), np.zeros(ntiles, dtype=np.uint8))
    return sums[1:]


@dataclass(frozen=True)
class SplatOptions:
    """Parameters of EWA splatting.

    Parameters
    ----------
    kappa : float
        Reconstruction kernel ``w = exp(-kappa rho^2)`` for ``rho < 1`` (``rho`` in units of the
        surfel semi-axes); the Gaussian is clipped at the surfel rim, where it is ``exp(-kappa)``.
    filter_radius : float
        Radius (pixels) of the screen-space low-pass filter; >= sqrt(2)/2 guarantees that every
        surfel reaches at least one pixel centre (no aliasing holes when minified). 0 disables it.
        The default is that bound (:data:`FILTER_RADIUS`, 0.71): a wider disc spreads the splats
        of an outline further past it (docs/performance.md, "Igea view 3: the splatter's screen
        filter at outlines, stop 35"). Surfels seen edge-on reach up to one pixel along their
        outline whatever the radius (``_splat_kernels.EDGE_FILTER_REACH``).
    depth_tolerance : float
        ``eps_z`` of the extended depth test as a multiple of each surfel's radius (3.2.1).
    tile : int
        Screen tile edge (pixels) for binning and parallel accumulation.
    precision : {"single", "double"}
        Storage of the per-surfel parameters. ``"single"`` (float32) halves the memory traffic;
        fragment arithmetic and accumulation are float64 in both cases.
    cull_backfaces : bool
        Skip surfels whose normal faces away from the camera (``render()`` only). For closed,
        consistently oriented surfaces: the far side's splats otherwise poke out past thin
        silhouettes (the blob's ear tips), drawn dark by the two-sided shading. Leave False
        for open sheets seen from both sides.

    Example
    -------
    >>> SplatOptions(filter_radius=0.0).filter_radius
    0.0
    """

    kappa: float = 2.0
    filter_radius: float = FILTER_RADIUS
    depth_tolerance: float = 1.0
    tile: int = 32
    precision: str = "single"
    cull_backfaces: bool = False

    def __post_init__(self) -> None:
        if self.precision not in ("single", "double"):
            raise InputError(f"precision: expected 'single' or 'double', got {self.precision!r}")
        object.__setattr__(self, "kappa", scalar(self.kappa, "kappa", 0.0))
        object.__setattr__(self, "filter_radius", scalar(self.filter_radius, "filter_radius", 0.0))
        object.__setattr__(self, "depth_tolerance", scalar(self.depth_tolerance, "depth_tolerance", 0.0))
        tile = int(self.tile)
        if tile != self.tile or tile < 4 or tile > 1024:
            raise InputError(f"tile: expected an integer in [4, 1024], got {self.tile!r}")
        object.__setattr__(self, "tile", tile)
        object.__setattr__(self, "cull_backfaces", bool(self.cull_backfaces))


@dataclass(frozen=True)
class ClipPlanes:
    """Per-surfel clip planes for clipped splatting (chapter 4, 4.2.2).

    Surfel ``i`` owns ``planes[offsets[i]:offsets[i+1]]``, rows ``(nx, ny, nz, d)``; plane ``j``
    keeps the fragments at ``x`` with ``n.x + d <= 0``. ``mode[i] = 0`` keeps fragments kept by
    all of the surfel's planes (convex edge/corner), ``1`` by any of them (concave).

    Example
    -------
    >>> c = ClipPlanes([0, 1, 1], [[1.0, 0, 0, 0]])  # surfel 0: keep x <= 0; surfel 1: no planes
    >>> c.mode.tolist()
    [0, 0]
    """

    offsets: Any
    planes: Any
    mode: Any = None

    def __post_init__(self) -> None:
        planes = as_array(self.planes, "planes", (None, 4))
        offsets = as_indices(self.offsets, "offsets", (None,), upper=len(planes) + 1)
        if len(offsets) < 1 or offsets[0] != 0 or offsets[-1] != len(planes) or np.any(np.diff(offsets) < 0):
            raise InputError("offsets: expected a non-decreasing array from 0 to len(planes)")
        n = len(offsets) - 1
        mode = np.zeros(n, dtype=np.int8) if self.mode is None else np.ascontiguousarray(self.mode, dtype=np.int8)
        if mode.shape != (n,):
            raise InputError(f"mode: expected shape ({n},), got {mode.shape}")
        object.__setattr__(self, "planes", planes)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "mode", mode)

    def __len__(self) -> int:
        return len(self.offsets) - 1


@dataclass(frozen=True)
class ClipTree:
    """Per-fragment CSG clipping of surfels by their clipping partners (chapter 4, 4.2.2).

    Surfel ``i`` owns the partners ``partners[offsets[i]:offsets[i+1]]``, rows
    ``(cx, cy, cz, nx, ny, nz, node)``: centre and (un-inverted, outward) normal of a surfel of
    another patch that intersects surfel ``i``, and the tree leaf of that patch. ``tree`` is the
    CSG tree in post order, rows ``(op, parent, first, invert)`` (op 0 intersection, 1 union,
    2 leaf; ``first`` the first node of the sub-tree; ``invert`` 1 at complemented leaves);
    ``leaf[i]`` is the leaf of surfel ``i``'s patch. A fragment is kept when Algorithm 4.2 says
    it lies on the surface of the root (three-valued logic, 4.9/4.10). Surfels without partners
    (surface surfels) are splatted unclipped. Built by :mod:`unmesh.csg`.

    Example
    -------
    >>> # two surfels, leaves 0 and 1 of "leaf0 & leaf1"; surfel 0 is clipped by surfel 1's plane x = 0
    >>> t = ClipTree([0, 1, 1], [[0, 0, 0, 1, 0, 0, 1]], [[2, 2, 0, 0], [2, 2, 1, 0], [0, -1, 0, 0]], [0, 1])
    >>> len(t), t.tree.shape
    (2, (3, 4))
    """

    offsets: Any
    partners: Any
    tree: Any
    leaf: Any

    def __post_init__(self) -> None:
        partners = as_array(self.partners, "partners", (None, 7))
        offsets = as_indices(self.offsets, "offsets", (None,), upper=len(partners) + 1)
        if len(offsets) < 1 or offsets[0] != 0 or offsets[-1] != len(partners) or np.any(np.diff(offsets) < 0):
            raise InputError("offsets: expected a non-decreasing array from 0 to len(partners)")
        tree = np.ascontiguousarray(self.tree, dtype=np.int32)
        if tree.ndim != 2 or tree.shape[1] != 4 or len(tree) == 0:
            raise InputError(f"tree: expected shape (K, 4) with K >= 1, got {tree.shape}")
        k = len(tree)
        leaf = np.ascontiguousarray(self.leaf, dtype=np.int32)
        if leaf.shape != (len(offsets) - 1,):
            raise InputError(f"leaf: expected shape ({len(offsets) - 1},), got {leaf.shape}")
        if len(leaf) and (leaf.min() < 0 or leaf.max() >= k or np.any(tree[leaf, 0] != 2)):
            raise InputError("leaf: expected the indices of leaf nodes of tree")
        nodes = partners[:, 6]
        if len(nodes) and (nodes.min() < 0 or nodes.max() >= k or np.any(tree[nodes.astype(np.int64), 0] != 2)):
            raise InputError("partners: expected column 6 to hold leaf nodes of tree")
        object.__setattr__(self, "partners", partners)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "tree", tree)
        object.__setattr__(self, "leaf", leaf)

    @classmethod
    def trusted(cls, offsets: np.ndarray, partners: np.ndarray, tree: np.ndarray, leaf: np.ndarray) -> ClipTree:
        """A clip tree from arrays already in the validated form (offsets (N+1,) int64 from 0 to
        P, partners (P, 7) float64 C-contiguous with leaf nodes in column 6, tree (K, 4) int32
        C-contiguous, leaf (N,) int32 leaf nodes), without re-checking them: for arrays built
        by the library itself from a validated tree (the per-camera folding of
        :mod:`unmesh.csg`, every frame). Other callers construct :class:`ClipTree` normally."""
        self = object.__new__(cls)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "partners", partners)
        object.__setattr__(self, "tree", tree)
        object.__setattr__(self, "leaf", leaf)
        return self

    def __len__(self) -> int:
        return len(self.offsets) - 1


#: A discontinuity surfel clips a surface surfel only when their planes meet at more than this
#: angle (degrees): discontinuity surfels cut across the surface; nearly coplanar ones would
#: make the front/back test (4.3) unreliable (4.5).
DISCONTINUITY_MIN_ANGLE = 45.0


def discontinuity_clip(arrays: SurfelArrays, clip_surfels: ClipSurfels, kind: int = GEOMETRY_DISCONTINUITY
                       ) -> ClipTree | None:
    """Clipping of surface surfels by discontinuity surfels (4.3) as a :class:`ClipTree`.

    The tree is ``surface & D``, with ``D`` the discontinuity surfels of ``kind``: a surface
    surfel ``s`` gets as partners the discontinuity surfels ``d`` that intersect it
    (``|c_s - c_d| < r_s + r_d``), meet its plane at more than
    :data:`DISCONTINUITY_MIN_ANGLE` and have ``s``'s centre behind them (each side of a crack
    is clipped by the surfel facing away from it, 7.4); its fragments in front of them are
    discarded by the two-surfel rule (4.4), leaving a clean edge. None when no surfel is clipped.

    Example
    -------
    >>> a = surfel_arrays(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]))
    >>> d = ClipSurfels([[0.5, 0, 0]], [[1.0, 0, 0]], [[[0, 0.5, 0], [0, 0, 0.5]]], [1])
    >>> t = discontinuity_clip(a, d)
    >>> t.offsets.tolist(), t.partners[0, :6].tolist()
    ([0, 1], [0.5, 0.0, 0.0, 1.0, 0.0, 0.0])
    """
    sel = np.flatnonzero(clip_surfels.kind == kind)
    n = len(arrays)
    if len(sel) == 0 or n == 0:
        return None
    dc = clip_surfels.positions[sel]
    dn = clip_surfels.normals[sel]
    dr = np.linalg.norm(clip_surfels.axes[sel], axis=2).max(axis=1)
    off, idx = KDTree(dc).radius_neighbors(arrays.positions, float(arrays.radii.max() + dr.max()))
    rows = np.repeat(np.arange(n), np.diff(off))
    d = arrays.positions[rows] - dc[idx]
    cos = np.abs(np.einsum("ij,ij->i", arrays.normals[rows], dn[idx]))
    keep = ((d * d).sum(axis=1) < (arrays.radii[rows] + dr[idx]) ** 2) & \
        (cos < np.cos(np.radians(DISCONTINUITY_MIN_ANGLE))) & (np.einsum("ij,ij->i", d, dn[idx]) < 0.0)
    rows, idx = rows[keep], idx[keep]
    if len(rows) == 0:
        return None
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=offsets[1:])
    partners = np.empty((len(rows), 7))
    partners[:, :3] = dc[idx]
    partners[:, 3:6] = dn[idx]
    partners[:, 6] = 1.0
    tree = np.array([[2, 2, 0, 0], [2, 2, 1, 0], [0, -1, 0, 0]], dtype=np.int32)
    return ClipTree(offsets, partners, tree, np.zeros(n, dtype=np.int32))


@dataclass(frozen=True, eq=False)
class ClipSurfels:
    """Discontinuity surfels that clip the splats around them (chapter 4, 4.3).

    Geometry discontinuity surfels (kind 1) clip their neighbours to a clean edge
    (:func:`discontinuity_clip`); texture discontinuity surfels (kind 2) clip only their colour
    (:func:`unmesh.render.render` splats a second pass clipped by them and takes its albedo).
    Neither is drawn. This is the clip information the renderer passes to :meth:`SplatRenderer.render`.

    Parameters
    ----------
    positions, normals : array_like, shape (K, 3)
    axes : array_like, shape (K, 2, 3)
        Tangent axes (semi-axis lengths) of the clipping discs.
    kind : array_like of int, shape (K,)
        :data:`~unmesh.surfels.cloud.GEOMETRY_DISCONTINUITY` (1) or
        :data:`~unmesh.surfels.cloud.TEXTURE_DISCONTINUITY` (2).

    Example
    -------
    >>> c = SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]] * 2, radii=[1.0, 1.0], attributes={"discontinuity": [0, 2]})
    >>> ClipSurfels.from_clouds([c]).kind.tolist()
    [2]
    """

    positions: Any
    normals: Any
    axes: Any
    kind: Any

    def __post_init__(self) -> None:
        pos = as_array(self.positions, "positions", (None, 3))
        n = len(pos)
        nrm = as_array(self.normals, "normals", (None, 3), length=n)
        axes = as_array(self.axes, "axes", (None, 2, 3), length=n)
        kind = np.ascontiguousarray(self.kind, dtype=np.int8)
        if kind.shape != (n,):
            raise InputError(f"kind: expected shape ({n},), got {kind.shape}")
        bad = (kind != GEOMETRY_DISCONTINUITY) & (kind != TEXTURE_DISCONTINUITY)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"kind: expected {GEOMETRY_DISCONTINUITY} or {TEXTURE_DISCONTINUITY}, got {kind[i]} at index {i}")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "normals", nrm)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "kind", kind)

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @classmethod
    def from_clouds(cls, clouds: SurfelCloud | Sequence[SurfelCloud]) -> ClipSurfels:
        """The discontinuity surfels of ``clouds`` (see :meth:`SurfelCloud.surfel_kinds`); their
        surface samples are ignored."""
        items = [clouds] if isinstance(clouds, SurfelCloud) else list(clouds)
        for i, c in enumerate(items):
            if not isinstance(c, SurfelCloud):
                raise InputError(f"clouds[{i}]: expected a SurfelCloud, got {type(c).__name__}")
        parts = []
        for c in items:
            kinds = c.surfel_kinds()
            mask = kinds != SURFACE
            if mask.any():
                parts.append((c.positions[mask], c.normals[mask], c.tangent_axes()[mask], kinds[mask]))
        if not parts:
            return cls(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2, 3)), np.zeros(0, dtype=np.int8))
        return cls(*(np.concatenate([p[k] for p in parts]) for k in range(4)))


@dataclass(frozen=True)
class SurfelArrays:
    """The arrays splatting reads.

    Attributes
    ----------
    positions, normals, colors : (N, 3) float64
    radii : (N,) float64
        Largest semi-axis.
    axes : (N, 2, 3) float64 or None
        Tangent axes of elliptical surfels; None when all are circular.
    """

    positions: np.ndarray
    normals: np.ndarray
    radii: np.ndarray
    axes: np.ndarray | None
    colors: np.ndarray

    def __len__(self) -> int:
        return int(self.positions.shape[0])


def surfel_arrays(clouds: SurfelCloud | Sequence[SurfelCloud], colors: Any = None) -> SurfelArrays:
    """Concatenate clouds into :class:`SurfelArrays`; ``colors`` (N,3) overrides the clouds' colours.

    Example
    -------
    >>> a = surfel_arrays(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]))
    >>> a.radii, a.axes is None
    (array([1.]), True)
    """
    items = [clouds] if isinstance(clouds, SurfelCloud) else list(clouds)
    for i, c in enumerate(items):
        if not isinstance(c, SurfelCloud):
            raise InputError(f"clouds[{i}]: expected a SurfelCloud, got {type(c).__name__}")
    items = [c for c in items if len(c)]
    if not items:
        z = np.zeros((0, 3))
        return SurfelArrays(z, z.copy(), np.zeros(0), None, z.copy())

    def cat(arrays: list[np.ndarray]) -> np.ndarray:
        return arrays[0] if len(arrays) == 1 else np.ascontiguousarray(np.concatenate(arrays))

    pos = cat([c.positions for c in items])
    nrm = cat([c.normals for c in items])
    radii = cat([np.asarray(c.radii) for c in items])
    axes = cat([c.tangent_axes() for c in items]) if any(c.is_elliptical for c in items) else None
    if colors is None:
        col = cat([np.asarray(c.colors) for c in items])
    else:
        col = as_array(colors, "colors", (None, 3), length=len(pos))
    return SurfelArrays(pos, nrm, radii, axes, col)


class SplatRenderer:
    """EWA splatting into persistent buffers, with partial updates (5.7).

    Parameters
    ----------
    camera : Camera
    options : SplatOptions, optional

    Attributes
    ----------
    zvis : (H, W) float64
        Visibility buffer ``min(z_f + eps_s)`` (initialised from the opaque depth).
    sum_weight, sum_depth : (H, W) float64
    sum_color, sum_normal : (H, W, 3) float64
        Unnormalised accumulation: weight, and colour, camera-space normal and depth times weight.
    count : (H, W) int32
        Number of accumulated fragments.
    clip_surfels : ClipSurfels or None
        The discontinuity surfels given to the last :meth:`render` (4.3); the hook of clipped
        splatting (chapter 4), which does not change the image yet.

    Example
    -------
    >>> import numpy as np
    >>> cloud = SurfelCloud([[0, 0, 0], [0.2, 0, 0]], [[0, 0, 1]] * 2, radii=[0.5, 0.5])
    >>> r = SplatRenderer(Camera((0, 0, 3), (0, 0, 0), width=16, height=16, ortho=2.0)).render(cloud)
    >>> before = r.gbuffer().albedo.copy()
    >>> _ = r.unsplat(cloud.subset([1])).splat(cloud.subset([1]))
    >>> bool(np.allclose(r.gbuffer().albedo, before))
    True
    """

    def __init__(self, camera: Camera, options: SplatOptions | None = None) -> None:
        if not isinstance(camera, Camera):
            raise InputError(f"camera: expected a Camera, got {type(camera).__name__}")
        self.camera = camera
        self.options = options if options is not None else SplatOptions()
        if not isinstance(self.options, SplatOptions):
            raise InputError(f"options: expected SplatOptions, got {type(self.options).__name__}")
        self.param_dtype = np.float32 if self.options.precision == "single" else np.float64
        self.clip_surfels: ClipSurfels | None = None
        self._adopt_opaque = False  # set by _render_in_place: clear() takes the opaque layer without a copy
        # the buffers are allocated on first use (__getattr__): render() replaces them anyway,
        # and _render_in_place takes this thread's work buffers instead

    def __getattr__(self, name: str) -> Any:
        # only called for attributes not set yet: the buffers of a new renderer, allocated as the
        # constructor's clear() did, and buffers assigned since (e.g. a shared zvis) kept
        if name in _BUFFERS and "camera" in self.__dict__:
            given = {k: v for k, v in self.__dict__.items() if k in _BUFFERS}
            self.clear()
            self.__dict__.update(given)
            return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    # -- buffers -------------------------------------------------------------------------
    def clear(self, opaque: GBuffer | None = None) -> SplatRenderer:
        """Empty the buffers. ``opaque`` (meshes, particles) occludes splats and shows where none are."""
        self._reset(opaque)
        if self._stale:
            self._zero_sums()
        return self

    def _reset(self, opaque: GBuffer | None) -> None:
        """:meth:`clear` without zeroing reused sums: they are only marked stale (``_stale``),
        and the next full update overwrites them tile by tile (:func:`splat_tiles` with the
        per-tile ``_dirty`` flags), which spares ``render()`` a serial pass over 68 MB of sums
        per 1024x1024 frame. Whoever calls this must end with a full update or
        :meth:`_zero_sums` (see :meth:`render`)."""
        h, w = self.camera.shape
        self._opaque = GBuffer.empty(h, w) if opaque is None else opaque if self._adopt_opaque else opaque.copy()
        if self._opaque.depth.shape != (h, w):
            raise InputError(f"opaque: expected buffers of shape {(h, w)}, got {self._opaque.depth.shape}")
        tile = self.options.tile
        ntiles = ((w + tile - 1) // tile) * ((h + tile - 1) // tile)
        if self._adopt_opaque:  # a spent renderer of render(): this thread's reused buffers (no page faults)
            self.zvis = self._scratch("zvis", (h, w), np.float64)
            np.copyto(self.zvis, self._opaque.depth)
            (self.sum_weight, self.sum_color, self.sum_normal, self.sum_depth, self.count,
             self._dirty) = _thread_sums(h, w, tile)
            self._stale = True
            return
        self.zvis = self._opaque.depth.copy()
        count, dirty = self.__dict__.get("count"), self.__dict__.get("_dirty")  # (no __getattr__)
        if count is not None and dirty is not None and count.shape == (h, w) and len(dirty) == ntiles:
            self._stale = True
            return
        self.sum_weight = np.zeros((h, w))
        self.sum_color = np.zeros((h, w, 3))
        self.sum_normal = np.zeros((h, w, 3))
        self.sum_depth = np.zeros((h, w))
        self.count = np.zeros((h, w), dtype=np.int32)
        self._dirty = np.zeros(ntiles, dtype=np.uint8)
        self._stale = False

    def _zero_sums(self) -> None:
        """Zero the sums (after :meth:`_reset` when no full update followed)."""
        for arr in (self.sum_weight, self.sum_color, self.sum_normal, self.sum_depth, self.count, self._dirty):
            arr.fill(0)
        self._stale = False

    # -- updates -------------------------------------------------------------------------
    def render(self, clouds: SurfelCloud | Sequence[SurfelCloud] | SurfelArrays, opaque: GBuffer | None = None,
               clip: ClipPlanes | ClipTree | None = None, clip_surfels: ClipSurfels | None = None) -> SplatRenderer:
        """Full update: clear, visibility pass, accumulation pass over all ``clouds`` together.

        Parameters
        ----------
        clouds : SurfelCloud, list of SurfelCloud, or SurfelArrays
            Splatted as given (:func:`unmesh.render.render` passes only the surface samples,
            :meth:`SurfelCloud.visible`).
        opaque : GBuffer, optional
            Already rasterised opaque geometry; its depth initialises the visibility buffer.
        clip : ClipPlanes or ClipTree, optional
            Per-surfel clip planes, or clipping partners with a CSG tree (chapter 4), one entry
            per surfel of the concatenated clouds.
        clip_surfels : ClipSurfels, optional
            Discontinuity surfels of the view (4.3), kept in :attr:`clip_surfels`; without
            ``clip`` the geometry ones clip the surfels crossing them (:func:`discontinuity_clip`).
            They produce no colour.
        """
        if clip_surfels is not None and not isinstance(clip_surfels, ClipSurfels):
            raise InputError(f"clip_surfels: expected ClipSurfels, got {type(clip_surfels).__name__}")
        self._reset(opaque)
        try:
            self.clip_surfels = clip_surfels
            if clip is None and clip_surfels is not None and len(clip_surfels):
                arrays = clouds if isinstance(clouds, SurfelArrays) else surfel_arrays(clouds)
                clip = discontinuity_clip(arrays, clip_surfels)
                clouds = arrays
            self._run(clouds, clip, visibility=True, sign=1)
        finally:
            if self._stale:  # nothing splatted (or an error): the sums are cleared the plain way
                self._zero_sums()
        return self

    def splat(self, clouds: SurfelCloud | Sequence[SurfelCloud] | SurfelArrays, clip: ClipPlanes | ClipTree | None = None) -> SplatRenderer:
        """Add surfels (accumulation only; the visibility buffer is not changed)."""
        self._run(clouds, clip, visibility=False, sign=1)
        return self

    def unsplat(self, clouds: SurfelCloud | Sequence[SurfelCloud] | SurfelArrays, clip: ClipPlanes | ClipTree | None = None) -> SplatRenderer:
        """Remove surfels previously splatted: subtract exactly their contributions."""
        self._run(clouds, clip, visibility=False, sign=-1)
        return self

    def _run(self, clouds: Any, clip: ClipPlanes | ClipTree | None, visibility: bool, sign: int) -> None:
        arrays = clouds if isinstance(clouds, SurfelArrays) else surfel_arrays(clouds)
        n = len(arrays)
        if n == 0:
            return
        if clip is not None and not isinstance(clip, ClipPlanes | ClipTree):
            raise InputError(f"clip: expected ClipPlanes or ClipTree, got {type(clip).__name__}")
        if clip is not None and len(clip) != n:
            raise InputError(f"clip: expected clip data for {n} surfels, got {len(clip)}")
        cam = self.camera
        opt = self.options
        f, cx, cy, ortho, near = cam.kernel_params()
        h, w = cam.shape
        frame = cam.rotation
        rf = opt.filter_radius
        elliptical = arrays.axes is not None
        axes = arrays.axes if elliptical else np.zeros((1, 2, 3))
        params = self._scratch("params", (n, NPARAM), self.param_dtype)
        box = self._scratch("box", (n, 4), np.int32)
        group = self._scratch("group", (n,), np.int8)
        tile = opt.tile
        ntx = (w + tile - 1) // tile
        nty = (h + tile - 1) // tile
        with serial_if_small(n):  # small partial updates: no parallel launch overhead
            offsets, items, visits = splat_setup_bin(arrays.positions, arrays.normals, arrays.radii, axes, elliptical,
                                                     arrays.colors, frame, cam.eye, f, cx, cy, ortho, near, w, h, rf,
                                                     params, box, group, tile, ntx, nty, 8)
        ctree, cleaf = None, None
        if clip is None:
            coff, cpl, cmode, has_clip = np.zeros(1, dtype=np.int64), np.zeros((0, 4)), np.zeros(1, dtype=np.int8), False
        elif isinstance(clip, ClipTree):
            coff, cpl, cmode, has_clip = clip.offsets, clip.partners, _NO_MODE, True
            ctree, cleaf = clip.tree, clip.leaf
        else:
            coff, cpl, cmode, has_clip = clip.offsets, clip.planes, clip.mode, True
        with serial_if_small(int(visits), 20 * SERIAL_BELOW):
            splat_tiles(params, items, offsets, tile_order(ntx * nty), tile, w, h, f, cx, cy, ortho, near, rf,
                        opt.kappa, opt.depth_tolerance, has_clip, cam.eye, frame, coff, cpl, cmode, ctree, cleaf, visibility,
                        float(sign), self.zvis, self.sum_weight, self.sum_color, self.sum_normal, self.sum_depth,
                        self.count, self._dirty)
        if visibility:
            self._stale = False  # the full update overwrote every tile that could hold values

    @staticmethod
    def _scratch(name: str, shape: tuple[int, ...], dtype: Any) -> np.ndarray:
        """A reusable work array of this thread (grown geometrically, see :data:`_SCRATCH`), so
        repeated renders, also by new renderers, avoid page faults."""
        size = int(np.prod(shape))
        buffers = getattr(_SCRATCH, "buffers", None)
        if buffers is None:
            buffers = _SCRATCH.buffers = {}
        key = (name, np.dtype(dtype).str)  # one buffer per dtype: renderers of both precisions alternate
        buf = buffers.get(key)
        if buf is None or buf.size < size:
            buf = np.empty(max(size, int(1.25 * buf.size) if buf is not None else size), dtype=dtype)
            buffers[key] = buf
        return buf[:size].reshape(shape)

    # -- results -------------------------------------------------------------------------
    def gbuffer(self) -> GBuffer:
        """Normalised G-buffer (third pass): splats where they contributed, the opaque layer elsewhere.

        Returns
        -------
        GBuffer
            albedo = ``sum w c / sum w``, normal = normalised ``sum w n``, depth = ``sum w z / sum w``,
            weight = ``sum w``.
        """
        return self._resolve(self._opaque.copy())

    def _resolve(self, g: GBuffer) -> GBuffer:
        """Normalise the sums into ``g`` (the opaque layer) in place; returns ``g``."""
        with serial_if_small(self.count.size, 4 * SERIAL_BELOW):
            splat_resolve(self.sum_weight, self.sum_color, self.sum_normal, self.sum_depth, self.count,
                          self.camera.rotation, g.albedo, g.normal, g.depth, g.coverage, g.weight)
        return g

    def resolve_window(self, gbuffer: GBuffer, window: tuple[int, int, int, int] | None = None) -> GBuffer:
        """Normalise the sums into ``gbuffer`` in place, only within ``window`` (after partial updates, 5.7).

        The window ``(r0, r1, c0, c1)`` (rows ``r0:r1``, columns ``c0:c1``; default the whole
        image) of ``gbuffer`` is reset to empty and gets what :meth:`gbuffer` has there
        without an opaque layer; the rest of ``gbuffer`` is not touched.

        Parameters
        ----------
        gbuffer : GBuffer
            Of the camera's shape.
        window : (r0, r1, c0, c1), optional

        Returns
        -------
        GBuffer
            ``gbuffer``.

        Example
        -------
        >>> cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5])
        >>> r = SplatRenderer(Camera((0, 0, 3), (0, 0, 0), width=8, height=8, ortho=2.0)).render(cloud)
        >>> g = r.resolve_window(GBuffer.empty(8, 8), (4, 5, 4, 5))
        >>> int(g.coverage.sum())
        1
        """
        h, w = self.camera.shape
        if not isinstance(gbuffer, GBuffer) or gbuffer.depth.shape != (h, w):
            raise InputError(f"gbuffer: expected a GBuffer of shape {(h, w)}, got "
                             f"{getattr(getattr(gbuffer, 'depth', None), 'shape', type(gbuffer).__name__)}")
        r0, r1, c0, c1 = (0, h, 0, w) if window is None else _check_window(window, h, w)
        sl = (slice(r0, r1), slice(c0, c1))
        g = gbuffer
        g.albedo[sl] = 0.0
        g.normal[sl] = 0.0
        g.depth[sl] = np.inf
        g.coverage[sl] = False
        g.weight[sl] = 0.0
        with serial_if_small((r1 - r0) * (c1 - c0), 4 * SERIAL_BELOW):
            splat_resolve(self.sum_weight[sl], self.sum_color[sl], self.sum_normal[sl], self.sum_depth[sl],
                          self.count[sl], self.camera.rotation, g.albedo[sl], g.normal[sl], g.depth[sl],
                          g.coverage[sl], g.weight[sl])
        return g

    def _render_in_place(self, clouds: SurfelCloud | Sequence[SurfelCloud] | SurfelArrays, gbuffer: GBuffer,
                         clip_surfels: ClipSurfels | None = None, clip: ClipPlanes | ClipTree | None = None) -> GBuffer:
        """:meth:`render` against the opaque layer ``gbuffer``, then :meth:`gbuffer` written into
        ``gbuffer`` itself instead of a copy (what :func:`unmesh.render.render` needs: it owns
        the buffer, and copying 1024x1024 G-buffers twice costs as much as the binning). The
        image is the same as ``render(clouds, opaque=gbuffer).gbuffer()``. The renderer is
        spent afterwards: its opaque layer is the result, and its sums and visibility buffer are
        this thread's work buffers (:data:`_SCRATCH`, reused by the next such call), so it must
        not be updated further; its :attr:`zvis` stays valid until then."""
        self._adopt_opaque = True
        try:
            self.render(clouds, opaque=gbuffer, clip=clip, clip_surfels=clip_surfels)
        finally:
            self._adopt_opaque = False
        return self._resolve(gbuffer)

    def result(self, shading: Any = "phong", background: Any = (1.0, 1.0, 1.0)) -> RenderResult:
        """The normalised, shaded image and buffers as a :class:`~unmesh.render.shading.RenderResult`.

        Example
        -------
        >>> cloud = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5], colors=[[1, 0, 0]])
        >>> r = SplatRenderer(Camera((0, 0, 3), (0, 0, 0), width=8, height=8, ortho=2.0)).render(cloud)
        >>> r.result(shading="none").color[4, 4].tolist()
        [1.0, 0.0, 0.0]
        """
        g = self.gbuffer()
        return RenderResult.from_gbuffer(g, self.camera, shade(g, self.camera, shading, background))

