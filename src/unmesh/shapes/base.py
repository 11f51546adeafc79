"""The :class:`Shape` protocol shared by every built-in shape, and frame helpers.

Every shape is defined in its own *local* frame (centred at the origin, symmetry
axis along local z) and placed in the world by a rigid motion
``x_world = center + rotation @ x_local``. A rigid motion preserves distances, so a
signed distance function in the local frame is one in the world frame too.
:meth:`Shape.transformed` accepts similarity transforms (rotation, uniform scale,
translation); the scale is folded into the shape's size parameters.

Sign convention: ``implicit`` is negative inside, positive outside, zero on the
surface; its normals point outward (the direction of increasing value).
"""

from __future__ import annotations

import abc
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from unmesh._validate import as_array, as_points
from unmesh.errors import InputError

if TYPE_CHECKING:
    from unmesh.meshes import TriangleMesh
    from unmesh.surfels import SurfelCloud

__all__ = ["FramedShape", "Shape", "euler_rotation", "rotation_from_axis"]


def rotation_from_axis(axis: Any, name: str = "axis") -> np.ndarray:
    """The minimal rotation (3,3) taking local +z to the unit vector along ``axis``.

    For ``axis = -z`` it is the half turn about x. Used to orient cylinders, tori,
    discs and planes, whose local symmetry axis (or normal) is +z. For the default
    ``axis = +y`` this maps local x to world x and local y to world -z.

    Parameters
    ----------
    axis : array_like, shape (3,)
        Direction (normalised here; must be non-zero).
    name : str
        Argument name for error messages.

    Returns
    -------
    numpy.ndarray, shape (3, 3), float64
        Proper rotation ``R`` with ``R @ (0, 0, 1) = axis / |axis|``.

    Example
    -------
    >>> np.round(rotation_from_axis((0, 1, 0)) @ [0, 0, 1], 12)
    array([0., 1., 0.])
    """
    a = as_array(axis, name, (3,))
    n = float(np.linalg.norm(a))
    if not n > 1e-12:
        raise InputError(f"{name}: expected a non-zero direction, got {a.tolist()}")
    a = a / n
    c = a[2]
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    v = np.array([-a[1], a[0], 0.0])  # z x a
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def euler_rotation(degrees: Any, name: str = "rotate") -> np.ndarray:
    """Rotation (3,3) from angles ``[rx, ry, rz]`` in degrees, applied about x, then y, then z.

    ``R = Rz @ Ry @ Rx`` (extrinsic x-y-z order), the convention of scene files'
    ``rotate`` key.

    Example
    -------
    >>> np.round(euler_rotation([0, 0, 90]) @ [1, 0, 0], 12)
    array([0., 1., 0.])
    """
    rx, ry, rz = np.radians(as_array(degrees, name, (3,)))
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx


def as_rotation(value: Any, name: str = "rotation") -> np.ndarray:
    """Check that ``value`` is a proper rotation matrix (3,3); re-orthonormalise it."""
    m = as_array(value, name, (3, 3))
    if not np.allclose(m.T @ m, np.eye(3), atol=1e-6) or np.linalg.det(m) < 0:
        raise InputError(f"{name}: expected a proper rotation matrix (orthonormal, det +1), got {m.tolist()}")
    u, _, vt = np.linalg.svd(m)
    return np.ascontiguousarray(u @ vt)


def split_similarity(matrix: Any) -> tuple[float, np.ndarray, np.ndarray]:
    """Split a 4x4 (or 3x3) similarity transform into ``(scale, rotation, translation)``.

    Raises InputError for shears, non-uniform scales and reflections, which would
    break the exact signed distance functions of the analytic shapes.
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape == (3, 3):
        lin, trans = m, np.zeros(3)
    elif m.shape == (4, 4):
        lin, trans = m[:3, :3], m[:3, 3].copy()
    else:
        raise InputError(f"matrix: expected shape (4, 4) or (3, 3), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise InputError("matrix: expected finite values")
    det = float(np.linalg.det(lin))
    if det <= 0:
        raise InputError(f"matrix: expected a rotation with uniform positive scale (det > 0), got det {det:.6g}")
    scale = float(np.sqrt(np.trace(lin.T @ lin) / 3.0))  # exact for scaled rotations (det is not)
    rot = lin / scale
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6):
        raise InputError(
            "matrix: analytic shapes accept only similarity transforms (rotation, uniform scale, translation); "
            "convert to a mesh first (MeshShape(shape.mesh()).transformed(matrix)) for general affine maps"
        )
    u, _, vt = np.linalg.svd(rot)
    return scale, np.ascontiguousarray(u @ vt), trans


class Shape(abc.ABC):
    """The protocol every shape implements (built-in analytic shapes and :class:`MeshShape`).

    Methods (all vectorised over points ``x`` of shape (N,3)):

    - ``implicit(x) -> (values (N,), normals (N,3))``: exact signed distance where a
      closed form exists (sphere, box, cylinder, torus, disc, plane; meshes via the
      closest point), otherwise the exact defining function with its exact
      normalised gradient (blob); negative inside. Normals are unit vectors
      pointing outward (the direction in which the value increases).
    - ``contains(x) -> (N,) bool``: strictly inside.
    - ``mesh(spacing=None, *, resolution=None) -> TriangleMesh``: counter-clockwise
      faces seen from outside, closed (no boundary edges) for closed shapes.
    - ``surfels(spacing, color=None) -> SurfelCloud``: near-uniform samples on the
      exact surface, exact normals, radii such that the splats cover the surface.
    - ``bounds() -> (2,3)``, ``area()``, ``volume()``, ``size()``,
      ``transformed(matrix)``.

    Attributes
    ----------
    closed : bool
        True for solids; False for open sheets (disc, plane, meshes with holes).
    """

    closed: bool = True
    #: Name used by :func:`unmesh.shapes.by_name` ("" for shapes it cannot build).
    kind: str = ""

    @abc.abstractmethod
    def implicit(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        """Signed implicit values (N,) (negative inside) and outward unit normals (N,3)."""

    def contains(self, x: Any) -> np.ndarray:
        """True (N,) where ``x`` is strictly inside (``implicit(x) < 0``).

        Example
        -------
        >>> from unmesh.shapes import Box
        >>> Box(size=(2, 2, 2)).contains([[0, 0, 0], [2, 0, 0]]).tolist()
        [True, False]
        """
        return self.implicit(x)[0] < 0.0

    @abc.abstractmethod
    def mesh(self, spacing: float | None = None, *, resolution: int | None = None) -> TriangleMesh:
        """A triangle mesh of the surface."""

    @abc.abstractmethod
    def surfels(self, spacing: float, color: Any = None) -> SurfelCloud:
        """Surfels on the surface about ``spacing`` apart, covering it without holes."""

    @abc.abstractmethod
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2,3) ``[min, max]``."""

    @abc.abstractmethod
    def transformed(self, matrix: Any) -> Shape:
        """The shape moved by a transform."""

    @abc.abstractmethod
    def size(self) -> float:
        """A characteristic length (largest extent) used for default resolutions."""

    @abc.abstractmethod
    def area(self) -> float:
        """Surface area."""

    @abc.abstractmethod
    def volume(self) -> float:
        """Enclosed volume."""

    def params(self) -> dict[str, Any]:
        """The constructor parameters (JSON-able), used by ``repr``."""
        return {}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"


class FramedShape(Shape):
    """Base class of the analytic shapes: a local-frame definition placed by a rigid motion.

    Subclasses implement the ``_*_local`` methods in the local frame; this class
    handles the placement ``x_world = center + rotation @ x_local`` and the
    argument conversion.

    Attributes
    ----------
    center : numpy.ndarray, shape (3,)
        World position of the local origin.
    rotation : numpy.ndarray, shape (3, 3)
        Local-to-world rotation.
    """

    #: False for shapes with sharp edges (their meshes carry no vertex normals).
    smooth: bool = True

    def __init__(self, center: Any = (0.0, 0.0, 0.0), rotation: Any = None) -> None:
        self.center = as_array(center, "center", (3,))
        self.rotation = np.eye(3) if rotation is None else as_rotation(rotation)
        self.center.setflags(write=False)
        self.rotation.setflags(write=False)

    # -- placement -------------------------------------------------------------------
    def to_local(self, x: np.ndarray) -> np.ndarray:
        """World points (N,3) to local coordinates."""
        return (x - self.center) @ self.rotation

    def to_world(self, p: np.ndarray) -> np.ndarray:
        """Local points (N,3) to world coordinates."""
        return p @ self.rotation.T + self.center

    def to_world_vectors(self, v: np.ndarray) -> np.ndarray:
        """Local direction vectors (N,3) to world directions."""
        return v @ self.rotation.T

    # -- local-frame interface (implemented by subclasses) -----------------------------
    @abc.abstractmethod
    def _implicit_local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (N,) and unit gradients (N,3) at local points p (N,3)."""

    @abc.abstractmethod
    def _mesh_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        """Local vertices (V,3) and faces (F,3) with target edge length ``spacing``."""

    @abc.abstractmethod
    def _surfels_local(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Local positions (N,3), normals (N,3) and radii (N,) (None: estimate them)."""

    @abc.abstractmethod
    def _local_bounds_points(self) -> np.ndarray:
        """Points (K,3) in the local frame whose world bounding box is the shape's bounds."""

    @abc.abstractmethod
    def _scaled(self, factor: float, center: np.ndarray, rotation: np.ndarray) -> FramedShape:
        """A copy scaled by ``factor`` and placed at ``center`` with ``rotation``."""

    def params(self) -> dict[str, Any]:
        return {"center": self.center.tolist()}

    # -- public interface ----------------------------------------------------------------
    def implicit(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        """Signed implicit function and outward unit normals at points ``x``.

        Parameters
        ----------
        x : array_like, shape (N, 3) or (3,)
            Query points.

        Returns
        -------
        values : numpy.ndarray, shape (N,), float64
            Negative inside, zero on the surface; the exact signed distance for the
            analytic shapes (see the class docstring for exceptions).
        normals : numpy.ndarray, shape (N, 3), float64
            Unit gradient of ``values`` (outward surface normal on the surface).

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> v, n = Sphere(radius=2.0).implicit([[3.0, 0.0, 0.0]])
        >>> float(v[0]), n[0].tolist()
        (1.0, [1.0, 0.0, 0.0])
        """
        pts = as_points(x, "x")
        values, grads = self._implicit_local(self.to_local(pts))
        return values, np.ascontiguousarray(self.to_world_vectors(grads))

    def _spacing(self, spacing: Any, resolution: Any) -> float:
        if spacing is not None and resolution is not None:
            raise InputError("mesh: give spacing or resolution, not both")
        if resolution is not None:
            res = int(resolution)
            if res != resolution or res < 1:
                raise InputError(f"resolution: expected a positive integer, got {resolution!r}")
            return self.size() / res
        if spacing is None:
            return self.size() / 48.0
        from unmesh._validate import positive_scalar

        return positive_scalar(spacing, "spacing")

    def mesh(self, spacing: float | None = None, *, resolution: int | None = None) -> TriangleMesh:
        """A triangle mesh of the surface with edges about ``spacing`` long.

        Parameters
        ----------
        spacing : float, optional
            Target edge length. Default: ``size() / 48``.
        resolution : int, optional
            Number of edges across the largest extent (instead of ``spacing``).

        Returns
        -------
        TriangleMesh
            Vertices on the exact surface, faces counter-clockwise seen from
            outside, closed for closed shapes, with exact vertex normals for
            smooth shapes (none for the box and cylinder, whose edge vertices
            have no single normal).

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> m = Sphere().mesh(resolution=16)
        >>> len(m.boundary_edges())
        0
        """
        from unmesh.meshes import TriangleMesh

        h = self._spacing(spacing, resolution)
        verts, faces = self._mesh_local(h)
        if not self.smooth:
            return TriangleMesh(self.to_world(verts), faces)
        _, grads = self._implicit_local(verts)
        return TriangleMesh(self.to_world(verts), faces, vertex_normals=self.to_world_vectors(grads))

    def surfels(self, spacing: float, color: Any = None) -> SurfelCloud:
        """Surfels sampled on the exact surface about ``spacing`` apart.

        Parameters
        ----------
        spacing : float
            Target distance between neighbouring samples.
        color : array_like, shape (3,), optional
            RGB in [0, 1] for every surfel (default light grey).

        Returns
        -------
        SurfelCloud
            Positions on the exact surface, exact normals, and radii large enough
            that the splats cover the surface without holes (cell circumradius for
            the parametric samplings, the tangent-plane Voronoi rule of
            :func:`unmesh.surfels.estimate_radii` otherwise).

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> c = Sphere().surfels(0.2)
        >>> bool(abs(np.linalg.norm(c.positions, axis=1) - 1).max() < 1e-12)
        True
        """
        from unmesh._validate import positive_scalar
        from unmesh.surfels.cloud import SurfelCloud

        h = positive_scalar(spacing, "spacing")
        pos, nrm, radii = self._surfels_local(h)
        if radii is None:
            from unmesh.surfels.radii import estimate_radii

            radii = estimate_radii(pos, nrm)
        colors = None
        if color is not None:
            col = as_array(color, "color", (3,))
            colors = np.broadcast_to(col, pos.shape)
        return SurfelCloud(self.to_world(pos), self.to_world_vectors(nrm), radii=radii, colors=colors)

    def bounds(self) -> np.ndarray:
        """Axis-aligned world bounds (2,3) ``[min, max]`` of the surface.

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> Sphere(center=(1, 0, 0)).bounds().tolist()
        [[0.0, -1.0, -1.0], [2.0, 1.0, 1.0]]
        """
        pts = self.to_world(self._local_bounds_points())
        return np.stack([pts.min(axis=0), pts.max(axis=0)])

    def transformed(self, matrix: Any) -> FramedShape:
        """The shape moved by a similarity transform (4x4 or 3x3).

        Rotation and uniform scale are applied about the world origin, then the
        translation; general affine maps raise InputError (use
        ``MeshShape(shape.mesh())`` for those).

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> s = Sphere(radius=1.0).transformed(np.diag([2.0, 2.0, 2.0, 1.0]))
        >>> s.radius
        2.0
        """
        scale, rot, trans = split_similarity(matrix)
        return self._scaled(scale, scale * rot @ self.center + trans, rot @ self.rotation)

    def moved(self, center: Any = None, rotation: Any = None, scale: float = 1.0) -> FramedShape:
        """A copy scaled about and rotated about its own centre, then placed at ``center``.

        Example
        -------
        >>> from unmesh.shapes import Box
        >>> Box(size=(1, 1, 1)).moved(center=(0, 2, 0), scale=2.0).size_xyz.tolist()
        [2.0, 2.0, 2.0]
        """
        from unmesh._validate import positive_scalar

        s = positive_scalar(scale, "scale")
        rot = np.eye(3) if rotation is None else as_rotation(rotation)
        c = self.center if center is None else as_array(center, "center", (3,))
        return self._scaled(s, c, rot @ self.rotation)
