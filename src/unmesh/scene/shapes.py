"""Shape specs in scene files, shared by every simulation.

A shape is an inline table. Built-in shapes::

    shape = { type = "box", size = [1, 1, 1], center = [0, 0.5, 0] }
    shape = { type = "sphere", radius = 0.5, center = [0, 1, 0] }
    shape = { type = "blob", scale = 0.5, rotate = [0, 90, 0] }

``type`` is any name accepted by :func:`unmesh.shapes.by_name`; the remaining keys
are that shape's parameters, plus the common placement keys ``center``
(translation, default origin), ``rotate`` (degrees about x, then y, then z) and
``scale`` (uniform factor). Mesh files::

    shape = { file = "bunny.obj", scale = 0.01, center = [0, 0, 0] }

load the mesh (path relative to the scene file) as :class:`unmesh.shapes.MeshShape`;
``center`` then moves the centre of the mesh's bounding box to that point.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh.errors import SceneError

__all__ = ["COORDINATE_LIMIT", "placement_matrix", "shape_from_table"]

_PLACEMENT = ("center", "rotate", "scale")
#: Largest magnitude accepted for shape coordinates, sizes and scale factors in a scene
#: (beyond it products of coordinates overflow float64 in sampling and geometry).
COORDINATE_LIMIT = 1e9


def _param(t: Any, key: str, value: Any) -> Any:
    """A shape parameter checked for type and range: a finite number, a string or bool, or
    an array of finite numbers (all below :data:`COORDINATE_LIMIT` in magnitude)."""
    if isinstance(value, str | bool):
        return value
    if isinstance(value, int | float):
        if not math.isfinite(value) or abs(value) > COORDINATE_LIMIT:
            raise t.error(key, f"expected a finite number of magnitude <= {COORDINATE_LIMIT:g}, got {value!r}")
        return value
    if isinstance(value, list):
        flat: list[Any] = []
        stack = [value]
        while stack:
            for x in stack.pop():
                (stack.append(x) if isinstance(x, list) else flat.append(x))
        if any(isinstance(x, bool) or not isinstance(x, int | float) for x in flat):
            raise t.error(key, f"expected an array of numbers, got {value!r}"[:300])
        try:
            arr = np.asarray(value, dtype=np.float64)
        except ValueError:
            raise t.error(key, "expected a rectangular array of numbers (rows of equal length)") from None
        if not np.all(np.isfinite(arr)) or (arr.size and np.abs(arr).max() > COORDINATE_LIMIT):
            raise t.error(key, f"expected finite numbers of magnitude <= {COORDINATE_LIMIT:g}, got {value!r}"[:300])
        return arr
    raise t.error(key, f"expected a number, string or array of numbers, got a {type(value).__name__}")


def _placement(t: Any) -> tuple[np.ndarray, np.ndarray, float]:
    center = t.vector("center", 3, default=(0.0, 0.0, 0.0))
    rotate = t.vector("rotate", 3, default=(0.0, 0.0, 0.0))
    scale = t.number("scale", default=1.0, positive=True)
    if np.abs(center).max() > COORDINATE_LIMIT:
        raise t.error("center", f"expected coordinates of magnitude <= {COORDINATE_LIMIT:g}, got {center.tolist()}")
    if np.abs(rotate).max() > 1e6:
        raise t.error("rotate", f"expected angles of magnitude <= 1e6 degrees, got {rotate.tolist()}")
    if not 1.0 / COORDINATE_LIMIT <= scale <= COORDINATE_LIMIT:
        raise t.error("scale", f"expected a factor between {1 / COORDINATE_LIMIT:g} and {COORDINATE_LIMIT:g}, got {scale}")
    return center, rotate, scale


def placement_matrix(center: Any = (0.0, 0.0, 0.0), rotate: Any = (0.0, 0.0, 0.0), scale: float = 1.0) -> np.ndarray:
    """4x4 matrix: uniform scale, then rotations about x, y, z (degrees), then translation.

    Example
    -------
    >>> placement_matrix(center=(1, 2, 3))[:3, 3]
    array([1., 2., 3.])
    """
    rx, ry, rz = np.radians(np.asarray(rotate, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = mz @ my @ mx * float(scale)
    m[:3, 3] = np.asarray(center, dtype=np.float64)
    return m


def shape_from_table(t: Any) -> Any:
    """Build the shape an inline shape table describes (see module docstring).

    ``t`` is an :class:`unmesh.scene.Table` (this module does not import it: the
    table module imports this one). Parameters are type- and range-checked
    (:data:`COORDINATE_LIMIT`); every error is a SceneError naming the key.
    """
    from unmesh import shapes

    center, rotate, scale = _placement(t)
    if "file" in t:
        from unmesh import io

        path = t.path("file")
        mesh = t.call("file", io.load_mesh, path)
        lo, hi = mesh.bounds()
        shift = np.eye(4)
        shift[:3, 3] = -(lo + hi) / 2.0
        mesh = mesh.transformed(placement_matrix(center, rotate, scale) @ shift)
        return t.call("file", shapes.MeshShape, mesh)
    kind = t.string("type")
    params: dict[str, Any] = {}
    for key in t.keys():
        if key in _PLACEMENT or key == "type":
            continue
        params[key] = _param(t, key, t.raw(key))
    try:
        shape = t.call("type", shapes.by_name, kind, **params)
    except SceneError:
        raise
    except (TypeError, ValueError) as exc:  # parameters of the wrong kind for this shape
        raise t.error("type", f"bad parameters for shape {kind!r}: {exc}") from None
    m = placement_matrix(center, rotate, scale)
    if np.allclose(m, np.eye(4)):
        return shape
    return shape.transformed(m)
