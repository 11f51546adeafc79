"""The surfel data model (thesis section 3.2).

A *surfel* is a small oriented disc: a position, a unit normal, and either a
radius (circular) or two tangent axes whose lengths are the semi-axes (elliptical,
eq. 3.13). A :class:`SurfelCloud` holds N of them plus colours and any number of
named per-surfel attributes (extra arrays whose first axis has length N). Arrays are
converted once, here: positions/normals/colors (N,3) float64, radii (N,) float64,
axes (N,2,3) float64, all C-contiguous.

Discontinuity surfels (thesis 4.3)
----------------------------------
The optional per-surfel attribute ``discontinuity`` (:data:`DISCONTINUITY_ATTRIBUTE`) tells
what a surfel is for:

* ``0`` (:data:`SURFACE`) - an ordinary surface sample (also every surfel of a cloud without
  the attribute);
* ``1`` (:data:`GEOMETRY_DISCONTINUITY`) - a geometry discontinuity surfel: invisible, it clips
  its neighbours to a clean edge (e.g. the pairs of opposite-facing surfels that the thin-shell
  simulation puts along every crack, 7.4);
* ``2`` (:data:`TEXTURE_DISCONTINUITY`) - a texture discontinuity surfel: invisible, it clips
  only the colour of its neighbours (normals and depth blend across it, fig. 4.6).

Any other non-zero value counts as a geometry discontinuity. Discontinuity surfels are not
samples of the surface ("discontinuity surfels are not drawn", 4.4): :meth:`SurfelCloud.visible`
gives the surface samples, :meth:`SurfelCloud.discontinuity_surfels` the clipping ones and
:meth:`SurfelCloud.surfel_kinds` the kind of each surfel; all three are computed from the
attribute, nothing else is stored.
"""

from __future__ import annotations

import dataclasses
import keyword
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, first_index
from unmesh.errors import InputError

__all__ = [
    "DEFAULT_COLOR",
    "DISCONTINUITY_ATTRIBUTE",
    "GEOMETRY_DISCONTINUITY",
    "RESERVED_NAMES",
    "SURFACE",
    "TEXTURE_DISCONTINUITY",
    "SurfelCloud",
    "similarity_scale",
]

DEFAULT_COLOR = (0.8, 0.8, 0.8)
#: Names that per-surfel attributes may not use (they are fields or PLY properties).
RESERVED_NAMES = frozenset(
    {"positions", "normals", "radii", "axes", "colors", "x", "y", "z", "nx", "ny", "nz", "radius",
     "red", "green", "blue", "alpha"}
)
#: Name of the per-surfel attribute that marks discontinuity surfels (thesis 4.3).
DISCONTINUITY_ATTRIBUTE = "discontinuity"
#: Surfel kinds (values of :data:`DISCONTINUITY_ATTRIBUTE`): surface sample, geometry
#: discontinuity (clips its neighbours, invisible), texture discontinuity (clips colour only).
SURFACE, GEOMETRY_DISCONTINUITY, TEXTURE_DISCONTINUITY = 0, 1, 2


def _unit_rows(vectors: np.ndarray, name: str) -> np.ndarray:
    norms = np.linalg.norm(vectors, axis=1)
    bad = ~(norms > 1e-12)
    if bad.any():
        raise InputError(f"{name}: expected non-zero vectors, got length {norms[bad][0]:.3g} at index {first_index(bad)}")
    return np.ascontiguousarray(vectors / norms[:, None])


def similarity_scale(linear: np.ndarray) -> float | None:
    """The scale ``s`` of a linear map (3,3) when it is a similarity (``L^T L = s^2 I``, relative
    tolerance 1e-9), else None: circular surfels stay circular under it, radii scale by ``s``.

    Example
    -------
    >>> similarity_scale(np.diag([2.0, 2.0, 2.0])), similarity_scale(np.diag([1.0, 2.0, 1.0]))
    (2.0, None)
    """
    gram = linear.T @ linear
    scale = float(np.sqrt(np.trace(gram) / 3.0))
    if np.allclose(gram, scale**2 * np.eye(3), rtol=1e-9, atol=1e-12 * scale**2):
        return scale
    return None


def tangent_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (N,3) completing each unit normal to a right-handed frame.

    ``t1 x t2 = n``. The construction is continuous except where the normal is
    parallel to the least-aligned coordinate axis switch (Frisvad-style).

    Example
    -------
    >>> t1, t2 = tangent_frame(np.array([[0.0, 0.0, 1.0]]))
    >>> np.allclose(np.cross(t1, t2), [[0, 0, 1]])
    True
    """
    n = np.asarray(normals, dtype=np.float64)
    helper = np.zeros_like(n)
    idx = np.argmin(np.abs(n), axis=1)
    helper[np.arange(len(n)), idx] = 1.0
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return t1, t2


@dataclass(frozen=True, eq=False, repr=False)
class SurfelCloud:
    """A set of N surfels.

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Surfel centres.
    normals : array_like, shape (N, 3)
        Normals; normalised on construction, zero vectors are rejected.
    radii : array_like, shape (N,), optional
        Radii of circular surfels (> 0). Give either ``radii`` or ``axes``; when
        ``axes`` is given, ``radii`` is the larger semi-axis.
    axes : array_like, shape (N, 2, 3), optional
        Tangent axes of elliptical surfels; their lengths are the semi-axes
        (eq. 3.13). Components along the normal are removed.
    colors : array_like, shape (N, 3), optional
        RGB in [0, 1] (uint8 input is divided by 255). Default light grey.
    attributes : mapping of str to array_like, optional
        Extra per-surfel arrays, each with first axis of length N. ``discontinuity`` marks
        discontinuity surfels (0 surface sample, 1 geometry discontinuity, 2 texture
        discontinuity; see the module notes and :meth:`surfel_kinds`).

    Raises
    ------
    unmesh.errors.InputError
        On wrong shapes, NaN/inf, non-positive radii, zero normals or axes, colours
        outside [0, 1], or attributes of the wrong length; the message names the
        field and the first bad index.

    Example
    -------
    >>> cloud = SurfelCloud(positions=[[0, 0, 0]], normals=[[0, 0, 2]], radii=[0.1])
    >>> cloud.normals
    array([[0., 0., 1.]])
    >>> len(cloud)
    1
    """

    positions: np.ndarray
    normals: np.ndarray
    radii: np.ndarray | None = None
    axes: np.ndarray | None = None
    colors: np.ndarray | None = None
    attributes: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        pos = as_points(self.positions, "positions")
        n = pos.shape[0]
        nrm = _unit_rows(as_points(self.normals, "normals", length=n), "normals")
        axes = None
        radii = None
        if self.axes is not None:
            axes = as_array(self.axes, "axes", (None, 2, 3), length=n).copy()
            axes -= np.einsum("nki,ni->nk", axes, nrm)[:, :, None] * nrm[:, None, :]
            lengths = np.linalg.norm(axes, axis=2)
            bad = ~(lengths > 0)
            if bad.any():
                raise InputError(f"axes: expected non-zero tangent axes, got a zero (or normal-parallel) axis at index {first_index(bad)}")
            radii = np.ascontiguousarray(lengths.max(axis=1))
            if self.radii is not None:
                given = as_array(self.radii, "radii", (None,), length=n)
                if not np.allclose(given, radii, rtol=1e-6, atol=0):
                    raise InputError("radii: expected radii equal to the larger tangent axis when axes are given (or give only axes)")
        elif self.radii is not None:
            radii = as_array(self.radii, "radii", (None,), length=n)
            bad = ~(radii > 0)
            if bad.any():
                i = first_index(bad)
                raise InputError(f"radii: expected positive values, got {radii[i]} at index {i}")
        else:
            raise InputError("radii: expected radii (N,) or tangent axes (N, 2, 3), got neither")
        if self.colors is None:
            colors = np.empty((n, 3))
            colors[:] = DEFAULT_COLOR
        else:
            raw = np.asarray(self.colors)
            if raw.dtype == np.uint8:
                raw = raw.astype(np.float64) / 255.0
            colors = as_array(raw, "colors", (None, 3), length=n)
            bad = (colors < 0) | (colors > 1)
            if bad.any():
                i = first_index(bad)
                raise InputError(f"colors: expected values in [0, 1], got {colors[i].tolist()} at index {i}")
        attrs: dict[str, np.ndarray] = {}
        for key, value in dict(self.attributes).items():
            if not isinstance(key, str) or not key.isidentifier() or keyword.iskeyword(key):
                raise InputError(f"attributes: expected identifier names, got {key!r}")
            if key in RESERVED_NAMES:
                raise InputError(f"attributes: name {key!r} is reserved for a surfel field")
            arr = np.ascontiguousarray(value)
            if arr.ndim == 0 or arr.shape[0] != n:
                raise InputError(f"attributes[{key!r}]: expected first axis of length {n}, got shape {arr.shape}")
            attrs[key] = arr
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "normals", nrm)
        object.__setattr__(self, "radii", radii)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "colors", colors)
        object.__setattr__(self, "attributes", attrs)

    # -- basic protocol -------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def __repr__(self) -> str:
        kind = "elliptical" if self.is_elliptical else "circular"
        extra = f", attributes={sorted(self.attributes)}" if self.attributes else ""
        return f"SurfelCloud({len(self)} {kind} surfels{extra})"

    @classmethod
    def unchecked(cls, positions: np.ndarray, normals: np.ndarray, radii: np.ndarray, colors: np.ndarray) -> SurfelCloud:
        """A circular cloud from arrays already as construction leaves them, taken as they are
        (no validation, no copies, no normalisation): positions and normals (N,3) float64
        C-contiguous with unit normals, radii (N,) > 0, colours (N,3) in [0, 1]. For callers
        that built them from valid clouds (the world cloud of a CSG frame,
        :func:`unmesh.csg.frame.world_cloud`); anything else should use the constructor."""
        obj = object.__new__(cls)
        object.__setattr__(obj, "positions", positions)
        object.__setattr__(obj, "normals", normals)
        object.__setattr__(obj, "radii", radii)
        object.__setattr__(obj, "axes", None)
        object.__setattr__(obj, "colors", colors)
        object.__setattr__(obj, "attributes", {})
        return obj

    @property
    def is_elliptical(self) -> bool:
        """True when the surfels carry explicit tangent axes."""
        return self.axes is not None

    # -- derived data ---------------------------------------------------------------
    def tangent_axes(self) -> np.ndarray:
        """Tangent axes (N, 2, 3) with semi-axis lengths; computed for circular surfels.

        Example
        -------
        >>> c = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[0.5])
        >>> np.linalg.norm(c.tangent_axes(), axis=2)
        array([[0.5, 0.5]])
        """
        if self.axes is not None:
            return self.axes
        t1, t2 = tangent_frame(self.normals)
        radii = np.asarray(self.radii)
        return np.ascontiguousarray(np.stack([t1, t2], axis=1) * radii[:, None, None])

    def surfel_kinds(self) -> np.ndarray:
        """The kind (N,) int8 of every surfel from the ``discontinuity`` attribute (thesis 4.3).

        :data:`SURFACE` (0) where the attribute is 0 or absent, :data:`TEXTURE_DISCONTINUITY` (2)
        where it is 2, :data:`GEOMETRY_DISCONTINUITY` (1) at every other non-zero value.

        Example
        -------
        >>> c = SurfelCloud(np.zeros((3, 3)), np.tile([0, 0, 1.0], (3, 1)), radii=[1, 1, 1],
        ...                 attributes={"discontinuity": [0, 1, 2]})
        >>> c.surfel_kinds().tolist()
        [0, 1, 2]
        """
        flag = self.attributes.get(DISCONTINUITY_ATTRIBUTE)
        if flag is None:
            return np.zeros(len(self), dtype=np.int8)
        flag = np.asarray(flag).reshape(len(self), -1)[:, 0]
        kinds = np.full(len(self), GEOMETRY_DISCONTINUITY, dtype=np.int8)
        kinds[flag == 0] = SURFACE
        kinds[flag == TEXTURE_DISCONTINUITY] = TEXTURE_DISCONTINUITY
        return kinds

    def visible(self) -> SurfelCloud:
        """The surface samples: the cloud without its discontinuity surfels (4.3, which are not drawn).

        Returns the cloud itself (not a copy) when it has no discontinuity surfels.

        Example
        -------
        >>> c = SurfelCloud(np.zeros((3, 3)), np.tile([0, 0, 1.0], (3, 1)), radii=[1, 2, 3],
        ...                 attributes={"discontinuity": [0, 1, 0]})
        >>> c.visible().radii, c.subset([0]).visible().radii
        (array([1., 3.]), array([1.]))
        """
        flag = self.attributes.get(DISCONTINUITY_ATTRIBUTE)
        if flag is None:
            return self
        keep = np.asarray(flag) == 0
        return self if keep.all() else self.subset(keep)

    def discontinuity_surfels(self) -> SurfelCloud:
        """The discontinuity surfels (geometry and texture, 4.3), with all attributes; empty when none.

        Example
        -------
        >>> c = SurfelCloud(np.zeros((3, 3)), np.tile([0, 0, 1.0], (3, 1)), radii=[1, 2, 3],
        ...                 attributes={"discontinuity": [0, 1, 2]})
        >>> c.discontinuity_surfels().surfel_kinds().tolist()
        [1, 2]
        """
        return self.subset(self.surfel_kinds() != SURFACE)

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2, 3) of the centres: ``[min, max]``; empty gives ``[inf, -inf]``."""
        if len(self) == 0:
            return np.array([[np.inf] * 3, [-np.inf] * 3])
        return np.stack([self.positions.min(axis=0), self.positions.max(axis=0)])

    # -- transformations (each returns a new cloud) ----------------------------------
    def replace(self, **changes: Any) -> SurfelCloud:
        """A copy with some fields replaced (validated again).

        Replacing ``axes`` drops the stored radii, which are then derived again.
        """
        if "axes" in changes and "radii" not in changes:
            changes["radii"] = None
        if "radii" in changes and changes["radii"] is not None and "axes" not in changes:
            changes["axes"] = None
        return dataclasses.replace(self, **changes)

    def subset(self, index: Any) -> SurfelCloud:
        """The surfels selected by a boolean mask or an index array, with all attributes.

        Example
        -------
        >>> c = SurfelCloud(np.zeros((3, 3)), np.tile([0, 0, 1.0], (3, 1)), radii=[1, 2, 3])
        >>> c.subset([2, 0]).radii
        array([3., 1.])
        """
        idx = np.asarray(index)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise InputError(f"index: expected a boolean mask of shape ({len(self)},), got {idx.shape}")
        else:
            idx = np.asarray(idx, dtype=np.int64).reshape(-1)
            if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
                raise InputError(f"index: expected indices in [0, {len(self)}), got range [{idx.min()}, {idx.max()}]")
        return SurfelCloud(
            positions=self.positions[idx],
            normals=self.normals[idx],
            radii=None if self.axes is not None else self.radii[idx],  # type: ignore[index]
            axes=None if self.axes is None else self.axes[idx],
            colors=self.colors[idx],  # type: ignore[index]
            attributes={k: v[idx] for k, v in self.attributes.items()},
        )

    def transformed(self, matrix: Any) -> SurfelCloud:
        """Apply a 4x4 affine transform (or 3x3 linear map).

        Normals use the inverse transpose; tangent axes are mapped as vectors.
        Circular surfels stay circular under similarity transforms and become
        elliptical otherwise.

        Example
        -------
        >>> c = SurfelCloud([[1, 0, 0]], [[1, 0, 0]], radii=[0.1])
        >>> c.transformed(np.diag([2.0, 2.0, 2.0, 1.0])).radii
        array([0.2])
        """
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape == (3, 3):
            lin, trans = m, np.zeros(3)
        elif m.shape == (4, 4):
            lin, trans = m[:3, :3], m[:3, 3]
        else:
            raise InputError(f"matrix: expected shape (4, 4) or (3, 3), got {m.shape}")
        det = np.linalg.det(lin)
        if not np.isfinite(det) or abs(det) < 1e-300:
            raise InputError("matrix: expected an invertible linear part")
        pos = self.positions @ lin.T + trans
        nrm = self.normals @ np.linalg.inv(lin)
        scale = similarity_scale(lin) if self.axes is None else None
        if scale is not None:
            return SurfelCloud(pos, nrm, radii=self.radii * scale, colors=self.colors,  # type: ignore[operator]
                               attributes=self.attributes)
        axes = np.einsum("ij,nkj->nki", lin, self.tangent_axes())
        return SurfelCloud(pos, nrm, axes=axes, colors=self.colors, attributes=self.attributes)

    @classmethod
    def concatenate(cls, clouds: Iterable[SurfelCloud], attributes: str = "same") -> SurfelCloud:
        """Join clouds.

        Mixing circular and elliptical clouds gives an elliptical cloud.

        Parameters
        ----------
        clouds : iterable of SurfelCloud
        attributes : {"same", "common", "none"}
            ``"same"``: every cloud must carry the same attribute names (default);
            ``"common"``: keep the attributes all clouds carry; ``"none"``: drop them.

        Example
        -------
        >>> a = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0], attributes={"t": [1.0]})
        >>> b = SurfelCloud([[1, 0, 0]], [[0, 0, 1]], radii=[2.0])
        >>> c = SurfelCloud.concatenate([a, b], attributes="none")
        >>> len(c), c.attributes
        (2, {})
        """
        items = list(clouds)
        if not items:
            raise InputError("clouds: expected at least one SurfelCloud, got none")
        if attributes not in ("same", "common", "none"):
            raise InputError(f"attributes: expected 'same', 'common' or 'none', got {attributes!r}")
        names = set(items[0].attributes)
        for i, c in enumerate(items):
            if attributes == "common":
                names &= set(c.attributes)
            elif attributes == "same" and set(c.attributes) != names:
                raise InputError(f"clouds[{i}]: expected attributes {sorted(names)}, got {sorted(c.attributes)}")
        if attributes == "none":
            names = set()
        attrs = {k: np.concatenate([c.attributes[k] for c in items]) for k in names}
        pos = np.concatenate([c.positions for c in items])
        nrm = np.concatenate([c.normals for c in items])
        col = np.concatenate([c.colors for c in items])
        if any(c.is_elliptical for c in items):
            return cls(pos, nrm, axes=np.concatenate([c.tangent_axes() for c in items]), colors=col, attributes=attrs)
        return cls(pos, nrm, radii=np.concatenate([c.radii for c in items]), colors=col, attributes=attrs)
