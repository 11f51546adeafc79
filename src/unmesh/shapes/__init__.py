"""Procedural shapes: the built-in data of unmesh (no downloads at run time).

Sphere, box, cylinder, torus, disc, plane and a smooth bunny-like blob, each as an
exact implicit function with normals, as a triangle mesh, and sampled as surfels;
plus :class:`MeshShape`, which gives a triangle mesh (e.g. a loaded scan) the same
protocol (signed distance, winding-number inside test, LDC surfels).

Every shape implements :class:`Shape`:

- ``implicit(x) -> (values (N,), normals (N,3))``, negative inside;
- ``contains(x) -> (N,) bool``;
- ``mesh(spacing=None, *, resolution=None) -> TriangleMesh``;
- ``surfels(spacing, color=None) -> SurfelCloud``;
- ``bounds() -> (2,3)``, ``area()``, ``volume()``, ``size()``, ``transformed(matrix)``.

Example
-------
>>> from unmesh.shapes import by_name
>>> shape = by_name("torus", major=1.0, minor=0.25)
>>> shape.contains([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]).tolist()
[True, False]
>>> cloud = shape.surfels(0.1)
>>> len(cloud) > 500
True
"""

from __future__ import annotations

import inspect
from typing import Any

from unmesh.errors import InputError
from unmesh.shapes.base import FramedShape, Shape, euler_rotation, rotation_from_axis
from unmesh.shapes.blob import Blob
from unmesh.shapes.mesh_shape import MeshShape
from unmesh.shapes.revolved import Cylinder, Torus
from unmesh.shapes.sheets import Disc, Plane
from unmesh.shapes.solids import Box, Sphere

__all__ = [
    "SHAPES",
    "Blob",
    "Box",
    "Cylinder",
    "Disc",
    "FramedShape",
    "MeshShape",
    "Plane",
    "Shape",
    "Sphere",
    "Torus",
    "by_name",
    "euler_rotation",
    "parameters",
    "rotation_from_axis",
]

#: Built-in shape classes by name (the names scene files and ``unmesh sample`` accept).
SHAPES: dict[str, type[FramedShape]] = {
    cls.kind: cls for cls in (Sphere, Box, Cylinder, Torus, Disc, Plane, Blob)
}


def parameters(name: str) -> dict[str, Any]:
    """Parameter names and defaults of the built-in shape ``name``.

    Example
    -------
    >>> parameters("sphere")
    {'center': (0.0, 0.0, 0.0), 'radius': 1.0, 'rotation': None}
    """
    cls = _lookup(name)
    sig = inspect.signature(cls.__init__)
    return {k: p.default for k, p in sig.parameters.items() if k != "self"}


def _lookup(name: str) -> type[FramedShape]:
    key = str(name).strip().lower()
    if key not in SHAPES:
        raise InputError(f"shape: unknown name {name!r}; expected one of {', '.join(sorted(SHAPES))}")
    return SHAPES[key]


def by_name(name: str, **params: Any) -> FramedShape:
    """Build the built-in shape ``name`` with keyword parameters.

    Parameters
    ----------
    name : str
        One of ``sphere, box, cylinder, torus, disc, plane, blob`` (case-insensitive).
    **params
        Constructor parameters of that shape (see :func:`parameters`), e.g.
        ``radius=0.5`` or ``center=(0, 1, 0)``.

    Returns
    -------
    Shape

    Raises
    ------
    unmesh.errors.InputError
        Unknown name (the message lists the valid names) or unknown/invalid
        parameter (the message lists the shape's parameters).

    Example
    -------
    >>> by_name("box", size=(1, 2, 3)).volume()
    6.0
    """
    cls = _lookup(name)
    valid = parameters(name)
    unknown = sorted(set(params) - set(valid))
    if unknown:
        raise InputError(
            f"{cls.kind}: unknown parameter{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
            f"expected {', '.join(valid)}"
        )
    try:
        return cls(**params)
    except InputError as exc:
        raise InputError(f"{cls.kind}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{cls.kind}: invalid parameters ({exc}); expected {', '.join(valid)}") from None
