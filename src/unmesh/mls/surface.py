"""The MLS surface of a surfel cloud: kernel parameters plus a prepared search grid.

An :class:`MLSSurface` fixes how the implicit surface of section 3.1 is defined for
a :class:`~unmesh.surfels.SurfelCloud` (kernel, widths, normals, polynomial degree)
and holds the cell grid used by every query, so that repeated calls (e.g. a
renderer casting rays tile by tile) build it once. The operators
:func:`unmesh.mls.project`, :func:`unmesh.mls.inside` and
:func:`unmesh.mls.intersect` accept either a cloud (and build a surface with the
given options) or a prepared surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, positive_scalar
from unmesh.errors import InputError
from unmesh.spatial import CellGrid, build_cell_grid
from unmesh.spatial._kernels import compress_cells, counting_sort
from unmesh.surfels import SurfelCloud

__all__ = ["DEFAULT_SIGMA_FACTOR", "MLSSurface", "as_surface"]

#: Default kernel width in units of the surfel radius: ``σ_i = 2·r_i``.
DEFAULT_SIGMA_FACTOR = 2.0

_KERNELS = {"gaussian": 0, "wendland": 1}
_NORMALS = {"hermite": 0, "covariance": 1}
_MAX_SKIP_CELLS = 1 << 24
_MAX_RAY_CELLS_PER_AXIS = 1 << 20
_RAY_CELL = 3.0  # ray-grid cell edge in units of the largest disc radius
SURFACE_OPTIONS = ("sigma", "sigma_factor", "cutoff", "kernel", "normal", "degree")


@dataclass(frozen=True, eq=False, repr=False)
class MLSSurface:
    """The MLS surface defined by a surfel cloud (thesis section 3.1).

    The weight of sample i at x is ``w_i(x) = φ(‖x − x_i‖ / σ_i)`` with a per-sample
    width σ_i; only samples with ``‖x − x_i‖ < cutoff·σ_i`` contribute.

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
    """

    cloud: SurfelCloud
    sigma: Any = None
    sigma_factor: float = DEFAULT_SIGMA_FACTOR
    cutoff: float = 3.0
    kernel: str = "gaussian"
    normal: str = "hermite"
    degree: int = 2
    _sigmas: np.ndarray = field(init=False)
    _grid: CellGrid = field(init=False)
    _arrays: tuple[np.ndarray, ...] = field(init=False)
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
        support = self.cutoff * float(sig.max())
        grid = build_cell_grid(self.cloud.positions, support)
        order = grid.order
        rho = np.minimum(np.maximum(radii, sig), grid.cell_size)
        arrays = (
            grid.points,
            np.ascontiguousarray(self.cloud.normals[order]),
            np.ascontiguousarray(sig[order]),
            np.ascontiguousarray(rho[order]),
        )
        object.__setattr__(self, "_sigmas", sig)
        object.__setattr__(self, "_grid", grid)
        object.__setattr__(self, "_arrays", arrays)
        object.__setattr__(self, "_cache", {})

    def __repr__(self) -> str:
        return (f"MLSSurface({len(self.cloud)} samples, kernel={self.kernel!r}, normal={self.normal!r}, "
                f"degree={self.degree}, sigma in [{self._sigmas.min():.3g}, {self._sigmas.max():.3g}], "
                f"cutoff={self.cutoff:g})")

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
    def grid(self) -> CellGrid:
        """The cell grid of the sample positions (cell edge = :attr:`support`)."""
        return self._grid

    def ray_grid(self) -> tuple[Any, ...]:
        """Acceleration grid for ray starts (built once, cached).

        Cubic cells of edge ``3·max ρ_i`` (ρ_i the disc radius ``max(r_i, σ_i)``); every
        sample is listed in each cell its disc's bounding sphere overlaps (at most 8).
        Returns ``(origin (3,), cell, dims (3,) int64, keys (C,) int64 sorted,
        start (C+1,) int64, items (M,) int64 sample indices in grid order, skip, use_skip)``
        where ``skip`` (``dims`` uint8) is the Chebyshev distance in cells to the nearest
        non-empty cell, capped at 255, used for empty-space skipping when the grid has at
        most 2^24 cells.
        """
        if "ray" not in self._cache:
            self._cache["ray"] = _build_ray_grid(self._arrays[0], self._arrays[3])
        return self._cache["ray"]

    def _kernel_args(self) -> tuple[Any, ...]:
        """Arguments shared by the numba kernels (see ``unmesh.mls._kernels``)."""
        gp, gn, gs, _ = self._arrays
        g = self._grid
        return (gp, gn, gs, self.cutoff, _KERNELS[self.kernel], _NORMALS[self.normal], int(self.degree),
                g.origin, g.inv_cell, g.dims, g.cell_keys, g.cell_start)


def _build_ray_grid(pos: np.ndarray, rho: np.ndarray) -> tuple[Any, ...]:
    rmax = float(rho.max())
    lo = pos.min(axis=0) - rmax
    hi = pos.max(axis=0) + rmax
    cell = _RAY_CELL * rmax * (1.0 + 1e-9)
    cell = max(cell, float((hi - lo).max()) / (_MAX_RAY_CELLS_PER_AXIS - 1))
    dims = (np.floor((hi - lo) / cell).astype(np.int64) + 1).astype(np.int64)
    i0 = np.clip(np.floor((pos - rho[:, None] - lo) / cell).astype(np.int64), 0, dims - 1)
    i1 = np.clip(np.floor((pos + rho[:, None] - lo) / cell).astype(np.int64), 0, dims - 1)
    ids = np.arange(len(pos), dtype=np.int64)
    keys_l, items_l = [], []
    for off in np.ndindex(2, 2, 2):
        c = i0 + np.asarray(off, dtype=np.int64)
        ok = np.all(c <= i1, axis=1)
        cc = c[ok]
        keys_l.append((cc[:, 0] * dims[1] + cc[:, 1]) * dims[2] + cc[:, 2])
        items_l.append(ids[ok])
    keys = np.concatenate(keys_l)
    items = np.concatenate(items_l)
    total = int(dims[0]) * int(dims[1]) * int(dims[2])
    if total <= 4 * len(keys) + 4096:
        order = counting_sort(keys, total)
    else:
        order = np.argsort(keys, kind="stable")
    items = np.ascontiguousarray(items[order])
    ukeys, start = compress_cells(np.ascontiguousarray(keys[order]))
    if total <= _MAX_SKIP_CELLS:
        from scipy.ndimage import distance_transform_cdt

        empty = np.ones(total, dtype=bool)
        empty[ukeys] = False
        dist = distance_transform_cdt(empty.reshape(tuple(int(v) for v in dims)), metric="chessboard")
        skip = np.ascontiguousarray(np.minimum(dist, 255).astype(np.uint8))
        use_skip = True
    else:
        skip = np.zeros((1, 1, 1), np.uint8)
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
