"""The camera and the image conventions every unmesh renderer uses.

Conventions
-----------
* Camera frame: ``forward = normalize(target - eye)``, ``right = normalize(forward x up)``,
  ``up' = right x forward``. Camera space is ``x = (p - eye)·right``, ``y = (p - eye)·up'``,
  ``z = (p - eye)·forward``; ``z`` is positive in front of the camera.
* Image: ``width x height`` pixels; pixel ``(row 0, column 0)`` is the top-left corner, columns
  grow to camera right, rows grow down. Continuous image coordinates put pixel ``(r, c)`` on
  ``[r, r+1) x [c, c+1)``, so its centre is at ``(r + 0.5, c + 0.5)`` and ``floor`` of a projected
  coordinate is the pixel index.
* Perspective (``fov``, the vertical field of view in degrees): a camera-space point projects to
  ``col = W/2 + f x / z``, ``row = H/2 - f y / z`` with ``f = (H/2) / tan(fov/2)`` pixels.
* Orthographic (``ortho``, the world height of the image): ``col = W/2 + f x``,
  ``row = H/2 - f y`` with ``f = H / ortho`` pixels per world unit; rays start on the plane
  through the eye and run along ``forward``.
* Depth is camera-space ``z`` (the distance along the viewing direction, not along the ray),
  ``inf`` where nothing is hit. Only ``z > near`` is visible.

Example
-------
>>> cam = Camera(eye=(0, 0, 5), target=(0, 0, 0), width=64, height=48, fov=45)
>>> row, col, depth = cam.project([[0.0, 0.0, 0.0]])
>>> float(row[0]), float(col[0]), float(depth[0])
(24.0, 32.0, 5.0)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from unmesh._validate import as_array, as_points, positive_scalar, scalar
from unmesh.errors import InputError

__all__ = ["DEFAULT_FOV", "DEFAULT_VIEW", "Camera"]

#: Vertical field of view (degrees) used when neither ``fov`` nor ``ortho`` is given.
DEFAULT_FOV = 40.0
#: Direction from the target towards the eye used by :meth:`Camera.framing` (right, above, front).
DEFAULT_VIEW = (0.55, 0.45, 1.0)


def _vec3(value: Any, name: str) -> np.ndarray:
    return as_array(value, name, (3,))


def _size(value: Any, name: str) -> int:
    try:
        v = int(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a positive integer, got {value!r}") from None
    if v != value or v < 1:
        raise InputError(f"{name}: expected a positive integer, got {value!r}")
    return v


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole (perspective) or orthographic camera.

    Parameters
    ----------
    eye, target : array_like, shape (3,)
        Camera position and the point it looks at (must differ).
    up : array_like, shape (3,)
        Approximate up direction (default +Y). When it is parallel to the viewing direction
        the world axis least aligned with the view is used instead.
    width, height : int
        Image size in pixels.
    fov : float, optional
        Vertical field of view in degrees, in (0, 180): a perspective camera.
    ortho : float, optional
        World height of the image: an orthographic camera. Give at most one of ``fov`` and
        ``ortho``; with neither the camera is perspective with ``fov = 40``.
    near : float, optional
        Near distance; only ``z > near`` is drawn. Default ``1e-3 |target - eye|``.

    Raises
    ------
    unmesh.errors.InputError
        On coincident eye and target, both ``fov`` and ``ortho``, or bad sizes.

    Example
    -------
    >>> cam = Camera((0, 0, 3), (0, 0, 0), width=8, height=8, ortho=2.0)
    >>> cam.pixels_per_unit
    4.0
    """

    eye: Any
    target: Any
    up: Any = (0.0, 1.0, 0.0)
    width: int = 640
    height: int = 480
    fov: float | None = None
    ortho: float | None = None
    near: float | None = None

    def __post_init__(self) -> None:
        eye = _vec3(self.eye, "eye")
        target = _vec3(self.target, "target")
        up = _vec3(self.up, "up")
        fwd = target - eye
        dist = float(np.linalg.norm(fwd))
        if not dist > 0:
            raise InputError("eye, target: expected two different points, got the same point")
        fwd = fwd / dist
        if not np.linalg.norm(up) > 0:
            raise InputError("up: expected a non-zero vector, got (0, 0, 0)")
        up = up / np.linalg.norm(up)
        right = np.cross(fwd, up)
        if np.linalg.norm(right) < 1e-6:
            helper = np.zeros(3)
            helper[int(np.argmin(np.abs(fwd)))] = 1.0
            right = np.cross(fwd, helper)
        right /= np.linalg.norm(right)
        true_up = np.cross(right, fwd)
        if self.fov is not None and self.ortho is not None:
            raise InputError(f"fov, ortho: expected one of them, got fov={self.fov} and ortho={self.ortho}")
        fov = ortho = None
        if self.ortho is not None:
            ortho = positive_scalar(self.ortho, "ortho")
        else:
            fov = scalar(DEFAULT_FOV if self.fov is None else self.fov, "fov", 1e-6, 179.999)
        near = None if self.near is None else positive_scalar(self.near, "near")
        for name, value in (("eye", eye), ("target", target), ("up", up), ("width", _size(self.width, "width")),
                            ("height", _size(self.height, "height")), ("fov", fov), ("ortho", ortho),
                            ("near", near)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "_frame", np.ascontiguousarray(np.stack([right, true_up, fwd])))
        object.__setattr__(self, "_near", 1e-3 * dist if near is None else near)

    # -- derived quantities ------------------------------------------------------------
    @property
    def is_ortho(self) -> bool:
        """True for an orthographic camera."""
        return self.ortho is not None

    @property
    def rotation(self) -> np.ndarray:
        """World-to-camera rotation (3,3): rows are ``right``, ``up'`` and ``forward``."""
        return self._frame.copy()  # type: ignore[attr-defined]

    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction (3,)."""
        return self._frame[2].copy()  # type: ignore[attr-defined]

    @property
    def right(self) -> np.ndarray:
        """Unit camera-right direction (3,)."""
        return self._frame[0].copy()  # type: ignore[attr-defined]

    @property
    def true_up(self) -> np.ndarray:
        """Unit camera-up direction (3,), orthogonal to ``forward``."""
        return self._frame[1].copy()  # type: ignore[attr-defined]

    @property
    def near_distance(self) -> float:
        """The effective near distance (``near`` or ``1e-3 |target - eye|``)."""
        return float(self._near)  # type: ignore[attr-defined]

    @property
    def pixels_per_unit(self) -> float:
        """``f``: pixels per unit of ``x/z`` (perspective) or per world unit (orthographic)."""
        if self.ortho is not None:
            return float(self.height) / float(self.ortho)
        return 0.5 * float(self.height) / math.tan(math.radians(float(self.fov)) / 2.0)  # type: ignore[arg-type]

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height, width)``."""
        return (int(self.height), int(self.width))

    def kernel_params(self) -> tuple[float, float, float, int, float]:
        """Scalars the numba kernels take: ``(f, cx, cy, ortho_flag, near)``; ``cx = W/2``, ``cy = H/2``.

        Example
        -------
        >>> Camera((0, 0, 5), (0, 0, 0), width=8, height=4, ortho=2.0).kernel_params()
        (2.0, 4.0, 2.0, 1, 0.005)
        """
        return (self.pixels_per_unit, 0.5 * self.width, 0.5 * self.height, int(self.is_ortho), self.near_distance)

    # -- mapping -------------------------------------------------------------------------
    def to_camera(self, points: Any) -> np.ndarray:
        """Camera-space coordinates (N,3) ``[x, y, z]`` of world points (N,3).

        Example
        -------
        >>> Camera((0, 0, 5), (0, 0, 0)).to_camera([[1.0, 2.0, 0.0]])
        array([[1., 2., 5.]])
        """
        p = as_points(points, "points")
        return (p - self.eye) @ self._frame.T  # type: ignore[attr-defined]

    def to_world(self, points: Any) -> np.ndarray:
        """World coordinates (N,3) of camera-space points (N,3); inverse of :meth:`to_camera`.

        Example
        -------
        >>> Camera((0, 0, 5), (0, 0, 0)).to_world([[1.0, 2.0, 5.0]])
        array([[1., 2., 0.]])
        """
        p = as_points(points, "points")
        return p @ self._frame + self.eye  # type: ignore[attr-defined]

    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Continuous image coordinates and depth of world points.

        Parameters
        ----------
        points : array_like, shape (N, 3)

        Returns
        -------
        row, col : numpy.ndarray, shape (N,), float64
            ``floor`` gives the pixel index; pixel centres are at ``+0.5``. NaN for points with
            ``z <= 0`` in a perspective camera.
        depth : numpy.ndarray, shape (N,)
            Camera-space ``z``.

        Example
        -------
        >>> cam = Camera((0, 0, 5), (0, 0, 0), width=100, height=100, ortho=2.0)
        >>> row, col, z = cam.project([[0.5, 0.5, 0.0]])
        >>> float(row[0]), float(col[0])
        (25.0, 75.0)
        """
        pc = self.to_camera(points)
        f, cx, cy, ortho, _ = self.kernel_params()
        x, y, z = pc[:, 0], pc[:, 1], pc[:, 2]
        if ortho:
            return cy - f * y, cx + f * x, z
        with np.errstate(divide="ignore", invalid="ignore"):
            zz = np.where(z > 0, z, np.nan)
            return cy - f * y / zz, cx + f * x / zz, z

    def facing(self, positions: Any, normals: Any) -> np.ndarray:
        """Mask (N,) bool of the oriented points whose normal faces the camera, ``n . (eye - x) > 0``
        (``n . -forward > 0`` for an orthographic camera): the survivors of back-face culling.

        Parameters
        ----------
        positions, normals : array_like, shape (N, 3)

        Example
        -------
        >>> Camera((0, 0, 5), (0, 0, 0)).facing([[0.0, 0, 0], [0, 0, 0]], [[0.0, 0, 1], [0, 0, -1]]).tolist()
        [True, False]
        """
        n = np.asarray(normals, dtype=np.float64)
        if self.is_ortho:
            return n @ (-self.forward) > 0
        return np.einsum("ij,ij->i", n, self.eye - np.asarray(positions, dtype=np.float64)) > 0

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space rays through every pixel centre.

        Returns
        -------
        origins : numpy.ndarray, shape (H, W, 3)
            The eye (perspective) or the pixel's point on the plane through the eye (orthographic).
        directions : numpy.ndarray, shape (H, W, 3)
            Unit directions. A hit at ray parameter ``t`` has depth ``t * (direction · forward)``.

        Example
        -------
        >>> o, d = Camera((0, 0, 5), (0, 0, 0), width=3, height=3).rays()
        >>> np.allclose(d[1, 1], [0, 0, -1])
        True
        """
        f, cx, cy, ortho, _ = self.kernel_params()
        cols = (np.arange(self.width) + 0.5 - cx) / f
        rows = -(np.arange(self.height) + 0.5 - cy) / f
        X, Y = np.meshgrid(cols, rows)
        frame = self._frame  # type: ignore[attr-defined]
        if ortho:
            origins = self.eye + X[..., None] * frame[0] + Y[..., None] * frame[1]
            directions = np.broadcast_to(frame[2], origins.shape).copy()
        else:
            d = X[..., None] * frame[0] + Y[..., None] * frame[1] + frame[2]
            directions = d / np.linalg.norm(d, axis=-1, keepdims=True)
            origins = np.broadcast_to(self.eye, directions.shape).copy()
        return origins, directions

    # -- new cameras ----------------------------------------------------------------------
    def replace(self, **changes: Any) -> Camera:
        """A copy with some fields replaced; giving ``fov`` drops ``ortho`` and vice versa.

        Example
        -------
        >>> Camera((0, 0, 5), (0, 0, 0), fov=30).replace(ortho=2.0).is_ortho
        True
        """
        if "fov" in changes and changes["fov"] is not None:
            changes.setdefault("ortho", None)
        if "ortho" in changes and changes["ortho"] is not None:
            changes.setdefault("fov", None)
        return dataclasses.replace(self, **changes)

    def resized(self, width: int, height: int) -> Camera:
        """The same view at another image size (same vertical field of view or ortho height).

        Example
        -------
        >>> Camera((0, 0, 5), (0, 0, 0), width=10, height=10).resized(20, 10).shape
        (10, 20)
        """
        return self.replace(width=width, height=height)

    def orbit(self, degrees: float, axis: Sequence[float] | None = None) -> Camera:
        """The camera rotated by ``degrees`` about an axis through the target (default: ``up``).

        Positive angles follow the right-hand rule about the axis.

        Example
        -------
        >>> cam = Camera((0, 0, 5), (0, 0, 0)).orbit(90)
        >>> np.round(cam.eye, 6)
        array([5., 0., 0.])
        """
        ax = self.up if axis is None else _vec3(axis, "axis")
        ax = ax / np.linalg.norm(ax)
        a = math.radians(scalar(degrees, "degrees"))
        k = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
        rot = np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * (k @ k)
        return self.replace(eye=self.target + rot @ (self.eye - self.target))

    def zoomed(self, factor: float) -> Camera:
        """Magnify the image by ``factor`` (> 1 zooms in) keeping eye and target.

        Perspective cameras narrow the field of view (``tan(fov/2)`` divided by ``factor``);
        orthographic cameras divide ``ortho``.
        """
        k = positive_scalar(factor, "factor")
        if self.ortho is not None:
            return self.replace(ortho=self.ortho / k)
        half = math.atan(math.tan(math.radians(self.fov) / 2) / k)  # type: ignore[arg-type]
        return self.replace(fov=math.degrees(2 * half))

    @classmethod
    def framing(
        cls,
        bounds: Any,
        width: int = 640,
        height: int = 480,
        fov: float | None = DEFAULT_FOV,
        ortho: bool = False,
        direction: Sequence[float] | None = None,
        up: Sequence[float] = (0.0, 1.0, 0.0),
        margin: float = 1.08,
        _points: np.ndarray | None = None,
    ) -> Camera:
        """A camera that shows the whole axis-aligned box ``bounds``.

        The eye looks at the box centre from ``direction`` (from the target towards the eye;
        default :data:`DEFAULT_VIEW`, front-right-above; a box that is flat along one axis is
        viewed along that axis). Perspective cameras move back until all 8 corners project
        inside the image shrunk by ``margin``; orthographic cameras (``ortho=True``) choose the
        image height instead.

        Parameters
        ----------
        bounds : array_like, shape (2, 3)
            ``[min, max]``; non-finite (empty scenes) gives a unit box at the origin.
        width, height : int
        fov : float
            Vertical field of view (degrees) for perspective framing.
        ortho : bool
            Build an orthographic camera.
        direction, up : array_like, shape (3,), optional
        margin : float
            >= 1; extra room around the box.

        Returns
        -------
        Camera

        Example
        -------
        >>> cam = Camera.framing([[-1, -1, -1], [1, 1, 1]], 100, 100)
        >>> row, col, _ = cam.project([[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0]])
        >>> bool(np.all((row >= 0) & (row <= 100) & (col >= 0) & (col <= 100)))
        True
        """
        points = _points
        b = np.asarray(bounds, dtype=np.float64)
        if b.shape != (2, 3):
            raise InputError(f"bounds: expected shape (2, 3), got {b.shape}")
        if not np.all(np.isfinite(b)) or np.any(b[1] < b[0]):
            b = np.array([[-0.5] * 3, [0.5] * 3])
        margin = scalar(margin, "margin", 1.0)
        center = 0.5 * (b[0] + b[1])
        ext = b[1] - b[0]
        size = float(ext.max())
        if size <= 0:
            size = max(1.0, float(np.abs(center).max()) * 1e-3)
            b = np.stack([center - 0.5 * size, center + 0.5 * size])
            ext = b[1] - b[0]
        if direction is None:
            flat = ext < 1e-6 * size
            if flat.sum() == 1:
                dvec = np.zeros(3)
                dvec[int(np.flatnonzero(flat)[0])] = 1.0
                if flat[1]:  # looking down at a flat horizontal scene: keep -z as image top
                    up = (0.0, 0.0, -1.0)
            else:
                dvec = np.array(DEFAULT_VIEW)
        else:
            dvec = _vec3(direction, "direction")
        if not np.linalg.norm(dvec) > 0:
            raise InputError("direction: expected a non-zero vector")
        dvec = dvec / np.linalg.norm(dvec)
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return cls._fit(corners if points is None else points, center, dvec, up, width, height, fov, ortho, margin,
                        size)

    @classmethod
    def fit(
        cls,
        points: Any,
        width: int = 640,
        height: int = 480,
        fov: float | None = DEFAULT_FOV,
        ortho: bool = False,
        direction: Sequence[float] | None = None,
        up: Sequence[float] = (0.0, 1.0, 0.0),
        margin: float = 1.08,
    ) -> Camera:
        """Like :meth:`framing`, but fits the points themselves instead of their bounding box's
        corners (tighter for round objects). The view direction and target still come from the
        bounding box of the points.

        Parameters
        ----------
        points : array_like, shape (N, 3)
            E.g. a subsample of the scene's vertices (pad them by radii yourself).

        Example
        -------
        >>> rng = np.random.default_rng(0)
        >>> p = rng.normal(size=(500, 3))
        >>> p /= np.linalg.norm(p, axis=1, keepdims=True)
        >>> Camera.fit(p, 64, 64).eye[2] < Camera.framing([p.min(0), p.max(0)], 64, 64).eye[2]
        np.True_
        """
        pts = as_points(points, "points")
        if len(pts) == 0:
            return cls.framing([[np.inf] * 3, [-np.inf] * 3], width, height, fov, ortho, direction, up, margin)
        return cls.framing(np.stack([pts.min(axis=0), pts.max(axis=0)]), width, height, fov, ortho, direction, up,
                           margin, _points=pts)

    @classmethod
    def _fit(cls, points: np.ndarray, center: np.ndarray, dvec: np.ndarray, up: Any, width: int, height: int,
             fov: float | None, ortho: bool, margin: float, size: float) -> Camera:
        probe = cls(center + dvec, center, up=up, width=width, height=height, fov=None if ortho else fov,
                    ortho=1.0 if ortho else None)
        rel = (points - center) @ probe.rotation.T  # offsets from the centre in the camera frame
        rel[:, 2] *= -1.0  # positive = towards the eye
        aspect = width / height
        radius = float(np.sqrt(np.max(np.sum((points - center) ** 2, axis=1))))
        if ortho:
            h = 2.0 * max(np.abs(rel[:, 1]).max(), np.abs(rel[:, 0]).max() / aspect) * margin
            dist = float(rel[:, 2].max()) + radius + 1e-3 * size
            return cls(center + dist * dvec, center, up=probe.up, width=width, height=height, ortho=max(h, 1e-12))
        ty = math.tan(math.radians(float(probe.fov)) / 2) / margin  # type: ignore[arg-type]
        tx = ty * aspect
        need = np.maximum(np.abs(rel[:, 0]) / tx, np.abs(rel[:, 1]) / ty) + rel[:, 2]
        dist = max(float(need.max()), float(rel[:, 2].max()) + 1e-2 * size)
        return cls(center + dist * dvec, center, up=probe.up, width=width, height=height, fov=probe.fov)
