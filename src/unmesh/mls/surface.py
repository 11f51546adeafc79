"""The MLS surface of a surfel cloud: kernel parameters plus prepared search grids.

An :class:`MLSSurface` fixes how the implicit surface of section 3.1 is defined for
a :class:`~unmesh.surfels.SurfelCloud` (kernel, widths, normals, polynomial degree)
and holds the search structures used by every query, so that repeated calls (e.g. a
renderer casting rays tile by tile) build them once. The operators
:func:`unmesh.mls.project`, :func:`unmesh.mls.inside`, :func:`unmesh.mls.intersect`
and :func:`unmesh.mls.interpolate` accept either a cloud (and build a surface with
the given options) or a prepared surface.

Varying radii (LDC samplings of meshes, scans, adaptive clouds) give varying kernel
supports ``cutoff·σ_i``. A single grid sized for the largest support would make
every query scan the neighbours of the largest kernel (for the Blob's 6.5k surfels,
about 1,000 candidates instead of 50), so the samples are split into power-of-two
*support levels* (:func:`size_levels`), each with its own
:class:`unmesh.spatial.CellGrid` whose cell edge matches the level's largest support,
and every query searches the 27 cells around it in each level. The ray-start discs
are split the same way by radius (:meth:`MLSSurface.ray_grid`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError
from unmesh.mls._ray_kernels import ray_cells
from unmesh.spatial import CellGrid, build_cell_grid
from unmesh.spatial._kernels import compress_cells, compute_keys, counting_sort
from unmesh.surfels import SurfelCloud

__all__ = ["DEFAULT_SIGMA_FACTOR", "MLSSurface", "as_surface", "size_levels"]

#: Default kernel width in units of the surfel radius: ``σ_i = 2·r_i``.
DEFAULT_SIGMA_FACTOR = 2.0

_KERNELS = {"gaussian": 0, "wendland": 1}
_NORMALS = {"hermite": 0, "covariance": 1}
_MAX_SKIP_CELLS = 1 << 24  # largest empty-space skip grid of one ray-grid level
_SKIP_BUDGET = 1 << 25  # and of all levels together (bytes)
_MAX_RAY_CELLS_PER_AXIS = 1 << 20
_RAY_CELL = 3.0  # ray-grid cell edge in units of the largest disc radius of a level
_MAX_LEVELS = 8  # support levels (powers of two below the largest support)
_MIN_LEVEL_SIZE = 64  # sparser finer levels merge into the next coarser one
_GATHER_MARGIN = 0.05  # candidate lists serve points within this fraction of the finest level's support
_RHO_MARGIN = 1e-6  # ray-start discs are capped at support·(1 + _RHO_MARGIN)
SURFACE_OPTIONS = ("sigma", "sigma_factor", "cutoff", "kernel", "normal", "degree")


@dataclass(frozen=True, eq=False, repr=False)
class MLSSurface:
    """The MLS surface defined by a surfel cloud (thesis section 3.1).

    The weight of sample i at x is ``w_i(x) = φ(‖x − x_i‖ / σ_i)`` with a per-sample
    width σ_i; only samples with ``‖x − x_i‖ < cutoff·σ_i`` contribute. The samples
    are searched in one cell grid per power-of-two band of the supports
    (:attr:`level_grids`), so the cost of a query follows the local kernel size even
    when the radii vary a lot.

    Parameters
    ----------
    cloud : SurfelCloud
        The samples: positions, normals (the Hermite data of eq. 3.8, also used to
        orient covariance normals) and radii. Elliptical surfels use their larger
        semi-axis as radius.
    sigma : float or array_like (N,), optional
        Kernel widths σ_i (> 0), global or per sample. Default ``sigma_factor·r_i``.
    sigma_factor : float, default 2
        σ_i in units of the surfel radius when ``sigma`` is not given. unmesh's
        samplers give hole-free radii of about 0.65 sample spacings h (the covering
        radius of a hexagonal sampling is h/√3), so the default is σ ≈ 1.3 h: about 50
        samples within the support ``3σ ≈ 4 h``, a smooth surface, and queries up to
        about 4 spacings from the samples still find neighbours. For clouds whose
        radii are about one spacing, ``sigma_factor=1.3`` gives the same σ.
    cutoff : float, default 3
        Support radius in units of σ_i: the clipped Gaussian (3.11, ``d < c·σ``) is
        cut there, the Wendland kernel (3.12) has that support radius.
    kernel : {"gaussian", "wendland"}
        Clipped Gaussian (3.10, 3.11) or Wendland C² (3.12).
    normal : {"hermite", "covariance"}
        Plane normal: weighted average of the sample normals (3.8) or the smallest
        eigenvector of the weighted covariance (3.5), oriented like the Hermite
        normal.
    degree : {1, 2}
        1: the simplified projection onto the weighted least-squares plane
        (3.5–3.7). Its surface lies about ``σ²·H/2`` inside (H = (κ₁+κ₂)/2 the mean
        curvature), e.g. ``σ²/(2R)`` on a sphere of radius R. 2 (default): after the plane, a
        quadratic height field is fitted in the plane's frame with the same weights
        (Levin's second step, 3.3–3.4, with ``w_i(x)``); the projection is its value
        above the query and the normal its normal there. This removes the curvature
        bias (the error becomes O(σ⁴/R³)).

    Raises
    ------
    unmesh.errors.InputError
        On an empty cloud or invalid options.

    Example
    -------
    >>> import numpy as np
    >>> from unmesh.surfels import SurfelCloud
    >>> g = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11)), -1).reshape(-1, 2) * 0.1
    >>> plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.1))
    >>> surf = MLSSurface(plane)
    >>> round(surf.support, 3)  # cutoff 3 · σ, σ = 2 · radius
    0.6
    >>> len(surf.level_grids)  # equal radii: one support level
    1
    """

    cloud: SurfelCloud
    sigma: Any = None
    sigma_factor: float = DEFAULT_SIGMA_FACTOR
    cutoff: float = 3.0
    kernel: str = "gaussian"
    normal: str = "hermite"
    degree: int = 2
    _sigmas: np.ndarray = field(init=False)
    _grids: tuple[CellGrid, ...] = field(init=False)
    _order: np.ndarray = field(init=False)
    _margin: float = field(init=False)
    _arrays: tuple[np.ndarray, ...] = field(init=False)
    _levels: tuple[np.ndarray, ...] = field(init=False)
    _cache: dict[str, Any] = field(init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.cloud, SurfelCloud):
            raise InputError(f"cloud: expected a SurfelCloud, got {type(self.cloud).__name__}")
        n = len(self.cloud)
        if n == 0:
            raise InputError("cloud: expected at least one surfel, got an empty cloud")
        if self.kernel not in _KERNELS:
            raise InputError(f"kernel: expected one of {sorted(_KERNELS)}, got {self.kernel!r}")
        if self.normal not in _NORMALS:
            raise InputError(f"normal: expected one of {sorted(_NORMALS)}, got {self.normal!r}")
        if isinstance(self.degree, bool) or self.degree not in (1, 2):
            raise InputError(f"degree: expected 1 or 2, got {self.degree!r}")
        object.__setattr__(self, "cutoff", positive_scalar(self.cutoff, "cutoff"))
        object.__setattr__(self, "sigma_factor", positive_scalar(self.sigma_factor, "sigma_factor"))
        radii = np.asarray(self.cloud.radii, dtype=np.float64)
        if self.sigma is None:
            sig = self.sigma_factor * radii
        elif np.ndim(self.sigma) == 0:
            sig = np.full(n, positive_scalar(self.sigma, "sigma"))
        else:
            sig = as_array(self.sigma, "sigma", (None,), length=n)
            if not np.all(sig > 0):
                raise InputError(f"sigma: expected positive widths, got {sig.min()}")
        sig = np.ascontiguousarray(sig)
        supp = self.cutoff * sig
        level = size_levels(supp)
        nlev = int(level.max()) + 1
        bound = np.zeros(nlev)
        np.maximum.at(bound, level, supp)
        margin = _GATHER_MARGIN * float(bound.min())
        pos = self.cloud.positions
        grids, parts, keys, starts, koff = [], [], [], [], [0]
        base = 0
        for lv in range(nlev):
            idx = np.flatnonzero(level == lv)
            g = build_cell_grid(pos[idx], float(bound[lv]) + margin)
            grids.append(g)
            parts.append(idx[g.order])
            keys.append(g.cell_keys)
            starts.append(g.cell_start + base)
            koff.append(koff[-1] + g.n_cells)
            base += len(idx)
        order = np.concatenate(parts)
        rho = np.minimum(np.maximum(radii, sig), float(supp.max()) * (1.0 + _RHO_MARGIN))
        inv = 1.0 / sig**2 if self.kernel == "gaussian" else 1.0 / supp
        gpack = np.empty((n, 10))
        gpack[:, 0:3] = pos[order]
        gpack[:, 3:6] = self.cloud.normals[order]
        gpack[:, 6] = supp[order] ** 2
        gpack[:, 7] = inv[order]
        gpack[:, 8] = sig[order]
        gpack[:, 9] = supp[order]
        arrays = (gpack, np.ascontiguousarray(rho[order]))
        levels = (
            np.ascontiguousarray(np.stack([g.origin for g in grids])),
            np.array([g.inv_cell for g in grids]),
            np.ascontiguousarray(np.stack([g.dims for g in grids])),
            np.array(koff, dtype=np.int64),
            np.ascontiguousarray(np.concatenate(keys), dtype=np.int64),
            np.ascontiguousarray(np.concatenate(starts), dtype=np.int64),
        )
        object.__setattr__(self, "_sigmas", sig)
        object.__setattr__(self, "_grids", tuple(grids))
        object.__setattr__(self, "_order", order)
        object.__setattr__(self, "_margin", margin)
        object.__setattr__(self, "_arrays", arrays)
        object.__setattr__(self, "_levels", levels)
        object.__setattr__(self, "_cache", {})

    def __repr__(self) -> str:
        return (f"MLSSurface({len(self.cloud)} samples, kernel={self.kernel!r}, normal={self.normal!r}, "
                f"degree={self.degree}, sigma in [{self._sigmas.min():.3g}, {self._sigmas.max():.3g}], "
                f"cutoff={self.cutoff:g}, {len(self._grids)} support level(s))")

    @property
    def sigmas(self) -> np.ndarray:
        """Kernel widths σ_i, shape (N,) float64 (in the cloud's order)."""
        return self._sigmas

    @property
    def support(self) -> float:
        """Largest kernel support radius ``cutoff·max σ_i``: queries farther than this from
        every sample have no neighbours."""
        return self.cutoff * float(self._sigmas.max())

    @property
    def level_grids(self) -> tuple[CellGrid, ...]:
        """The search grids, one per support level (coarsest first).

        Level ℓ holds the samples whose support ``cutoff·σ_i`` lies in a power-of-two
        band below the largest one; its cell edge is the largest support in the level
        plus the gather margin, so the 27 cells around a point hold every sample of the
        level whose kernel reaches any point within the margin. Each grid's points are
        the level's samples (``grid.order`` indexes into them, not into the cloud).
        """
        return self._grids

    def ray_grid(self) -> tuple[Any, ...]:
        """Acceleration grids for ray starts (built on the first call, cached).

        The samples are split into power-of-two levels of their disc radius
        ``ρ_i = max(r_i, σ_i)`` (capped at :attr:`support`); each level has cubic cells
        of edge ``3·max ρ_i`` of the level, and every sample is listed in each cell of
        its level that its disc's bounding sphere overlaps (at most 8). Returns
        ``(origin (L,3), cell (L,), dims (L,3) int64, koff (L+1,) int64, keys int64,
        start int64, items int64, skoff (L+1,) int64, skip uint8, use_skip (L,) bool)``:
        level ℓ's sorted non-empty cell keys are ``keys[koff[ℓ]:koff[ℓ+1]]``, their
        offsets into ``items`` (sample indices in the kernels' order)
        ``start[koff[ℓ]+ℓ : koff[ℓ+1]+ℓ+1]``, and ``skip[skoff[ℓ]:skoff[ℓ+1]]`` is the
        level's flattened grid of Chebyshev distances in cells to the nearest non-empty
        cell (capped at 255) for empty-space skipping, when ``use_skip[ℓ]`` (grids of at
        most 2^24 cells).
        """
        if "ray" not in self._cache:
            self._cache["ray"] = _build_ray_grids(np.ascontiguousarray(self._arrays[0][:, :3]), self._arrays[1])
        return self._cache["ray"]

    def _kernel_args(self) -> tuple[Any, ...]:
        """Surface arguments shared by the numba kernels (see ``unmesh.mls._kernels``):
        ``gpack, kernel, normal_mode, degree, margin`` and the six level-grid arrays."""
        return (self._arrays[0], _KERNELS[self.kernel], _NORMALS[self.normal], int(self.degree), self._margin,
                *self._levels)

    def _locality_keys(self, x: np.ndarray) -> np.ndarray:
        """Cell keys of points ``x`` in the finest level grid (to sort queries for memory locality)."""
        g = self._grids[-1]
        return compute_keys(x, g.origin, g.inv_cell, g.dims)


def size_levels(values: np.ndarray, max_levels: int = _MAX_LEVELS, min_size: int = _MIN_LEVEL_SIZE) -> np.ndarray:
    """Power-of-two size classes of positive values (0 = the class of the largest value).

    Class ℓ holds ``max/2^(ℓ+1) < v <= max/2^ℓ``; values below ``max/2^(max_levels-1)``
    go into the last class. A class with fewer than ``min_size`` members moves into the
    next coarser class (coarser cells stay correct for smaller supports), and the
    non-empty classes are numbered 0, 1, ... from the coarsest.

    Parameters
    ----------
    values : numpy.ndarray, shape (N,), float64
        Positive sizes (supports or disc radii), N >= 1.
    max_levels : int
    min_size : int

    Returns
    -------
    numpy.ndarray, shape (N,), int64

    Example
    -------
    >>> size_levels(np.array([1.0, 0.9, 0.4, 0.3, 0.05]), min_size=1).tolist()
    [0, 0, 1, 1, 2]
    >>> size_levels(np.array([1.0, 0.9, 0.4, 0.3, 0.05]), min_size=2).tolist()
    [0, 0, 1, 1, 1]
    """
    v = np.asarray(values, dtype=np.float64)
    ratio = v.max() / v
    lev = np.minimum(np.floor(np.log2(ratio)), max_levels - 1).astype(np.int64)
    lev = np.maximum(lev, 0)
    counts = np.bincount(lev, minlength=max_levels)
    for lv in range(max_levels - 1, 0, -1):
        if 0 < counts[lv] < min_size:
            lev[lev == lv] = lv - 1
            counts[lv - 1] += counts[lv]
            counts[lv] = 0
    remap = np.cumsum(counts > 0) - 1
    return remap[lev].astype(np.int64)


def _build_ray_grids(pos: np.ndarray, rho: np.ndarray) -> tuple[Any, ...]:
    level = size_levels(rho)
    nlev = int(level.max()) + 1
    counts = np.bincount(level, minlength=nlev)
    origins, cells, dims_l, koff, keys_l, start_l, items_l, skoff, skip_l, use_l = [], [], [], [0], [], [], [], [0], [], []
    base = 0
    budget = _SKIP_BUDGET
    for lv in np.argsort(-counts, kind="stable"):  # walk the most populated level first
        idx = np.flatnonzero(level == lv)
        lo, cell, dims, ukeys, start, items, skip, use_skip = _build_ray_grid(pos, rho, idx, budget)
        budget -= skip.size if use_skip else 0
        origins.append(lo)
        cells.append(cell)
        dims_l.append(dims)
        koff.append(koff[-1] + len(ukeys))
        keys_l.append(ukeys)
        start_l.append(start + base)
        items_l.append(items)
        skoff.append(skoff[-1] + skip.size)
        skip_l.append(skip.ravel())
        use_l.append(use_skip)
        base += len(items)
    return (np.ascontiguousarray(np.stack(origins)), np.array(cells), np.ascontiguousarray(np.stack(dims_l)),
            np.array(koff, dtype=np.int64), np.ascontiguousarray(np.concatenate(keys_l), dtype=np.int64),
            np.ascontiguousarray(np.concatenate(start_l), dtype=np.int64),
            np.ascontiguousarray(np.concatenate(items_l), dtype=np.int64), np.array(skoff, dtype=np.int64),
            np.ascontiguousarray(np.concatenate(skip_l)), np.array(use_l, dtype=np.bool_))


def _build_ray_grid(pos: np.ndarray, rho: np.ndarray, idx: np.ndarray, budget: int) -> tuple[Any, ...]:
    """Ray grid of the samples ``idx``: cells of edge 3·max ρ, each sample listed in the cells its disc's
    bounding sphere overlaps; with a skip grid when it has at most ``min(2^24, budget)`` cells."""
    p = pos[idx]
    rmax = float(rho[idx].max())
    lo = p.min(axis=0) - rmax
    hi = p.max(axis=0) + rmax
    cell = _RAY_CELL * rmax * (1.0 + 1e-9)
    cell = max(cell, float((hi - lo).max()) / (_MAX_RAY_CELLS_PER_AXIS - 1))
    dims = (np.floor((hi - lo) / cell).astype(np.int64) + 1).astype(np.int64)
    keys = np.empty(8 * len(idx), np.int64)
    items = np.empty(8 * len(idx), np.int64)
    m = ray_cells(pos, rho, idx, np.ascontiguousarray(lo), cell, dims, keys, items)
    keys, items = keys[:m], items[:m]
    total = int(dims[0]) * int(dims[1]) * int(dims[2])
    if total <= 4 * len(keys) + 4096:
        order = counting_sort(keys, total)
    else:
        order = np.argsort(keys, kind="stable")
    items = np.ascontiguousarray(items[order])
    ukeys, start = compress_cells(np.ascontiguousarray(keys[order]))
    if total <= min(_MAX_SKIP_CELLS, budget):
        from scipy.ndimage import distance_transform_cdt

        empty = np.ones(total, dtype=bool)
        empty[ukeys] = False
        dist = distance_transform_cdt(empty.reshape(tuple(int(v) for v in dims)), metric="chessboard")
        skip = np.ascontiguousarray(np.minimum(dist, 255).astype(np.uint8))
        use_skip = True
    else:
        skip = np.zeros(1, np.uint8)
        use_skip = False
    return (np.ascontiguousarray(lo), cell, dims, np.ascontiguousarray(ukeys, dtype=np.int64), start, items,
            skip, use_skip)


def as_surface(cloud: SurfelCloud | MLSSurface, **options: Any) -> MLSSurface:
    """An :class:`MLSSurface` from a cloud and options, or the given surface unchanged.

    Raises
    ------
    unmesh.errors.InputError
        If options are given together with a prepared surface, or an option is unknown.

    Example
    -------
    >>> from unmesh.surfels import SurfelCloud
    >>> c = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.1])
    >>> as_surface(c, degree=1).degree
    1
    """
    unknown = set(options) - set(SURFACE_OPTIONS)
    if unknown:
        raise InputError(f"options: unknown MLS option(s) {sorted(unknown)}; expected some of {list(SURFACE_OPTIONS)}")
    if isinstance(cloud, MLSSurface):
        if options:
            raise InputError(f"options {sorted(options)}: give them when building the MLSSurface, not with a prepared one")
        return cloud
    if not isinstance(cloud, SurfelCloud):
        raise InputError(f"cloud: expected a SurfelCloud or MLSSurface, got {type(cloud).__name__}")
    return MLSSurface(cloud, **options)
