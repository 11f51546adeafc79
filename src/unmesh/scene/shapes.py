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

from typing import TYPE_CHECKING, Any

import numpy as np

from unmesh.errors import FormatError, InputError

if TYPE_CHECKING:
    from unmesh.scene.table import Table

__all__ = ["placement_matrix", "shape_from_table"]

_PLACEMENT = ("center", "rotate", "scale")


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


def shape_from_table(t: Table) -> Any:
    """Build the shape an inline shape table describes (see module docstring)."""
    from unmesh import shapes

    center = t.vector("center", 3, default=(0.0, 0.0, 0.0))
    rotate = t.vector("rotate", 3, default=(0.0, 0.0, 0.0))
    scale = t.number("scale", default=1.0, positive=True)
    if "file" in t:
        from unmesh import io

        path = t.path("file")
        try:
            mesh = io.load_mesh(path)
        except (FormatError, InputError) as exc:
            raise t.error("file", str(exc)) from None
        lo, hi = mesh.bounds()
        shift = np.eye(4)
        shift[:3, 3] = -(lo + hi) / 2.0
        mesh = mesh.transformed(placement_matrix(center, rotate, scale) @ shift)
        try:
            return shapes.MeshShape(mesh)
        except InputError as exc:
            raise t.error("file", str(exc)) from None
    kind = t.string("type")
    params: dict[str, Any] = {}
    for key in t.keys():
        if key in _PLACEMENT or key == "type":
            continue
        value = t.raw(key)
        params[key] = np.asarray(value, dtype=np.float64) if isinstance(value, list) else value
    try:
        shape = shapes.by_name(kind, **params)
    except InputError as exc:
        raise t.error("type", str(exc)) from None
    m = placement_matrix(center, rotate, scale)
    if np.allclose(m, np.eye(4)):
        return shape
    return shape.transformed(m)
