"""A triangle mesh (e.g. a loaded scan) as a shape.

Inside/outside uses the generalized winding number (Jacobson, Kavan, Sorkine-Hornung
2013): ``w(x) = sum_t Omega_t(x) / 4 pi`` over the triangles' signed solid angles;
``x`` is inside where ``w > 1/2``. Unlike ray parity or pseudo-normals this degrades
gracefully on meshes with holes (the Stanford bunny's base) and stray triangles.
It is evaluated with :class:`unmesh.spatial.TriangleBVH`: exact solid angles for nearby
triangles, the first-order dipole expansion of Barill et al. (2018) for clusters farther
than ``3x`` their radius (winding numbers accurate to about 0.01-0.02, which only
matters where the exact value is near 1/2, i.e. right at holes). The signed distance is the exact distance to the closest
point on the triangles (found with the same BVH), signed by the winding number.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import numpy as np

from unmesh._validate import as_array, as_points
from unmesh.errors import InputError
from unmesh.shapes.base import Shape
from unmesh.spatial.bvh import WINDING_BETA, TriangleBVH, closest_point_reference, winding_reference

if TYPE_CHECKING:
    from unmesh.meshes import TriangleMesh
    from unmesh.surfels import SurfelCloud

# closest_point_reference, winding_reference and WINDING_BETA moved to unmesh.spatial.bvh (re-exported).
__all__ = ["WINDING_BETA", "MeshShape", "closest_point_reference", "winding_reference"]


class MeshShape(Shape):
    """A triangle mesh with the shape protocol (signed distance, inside test, surfels).

    Parameters
    ----------
    mesh : TriangleMesh
        The surface; faces should be counter-clockwise seen from outside. Holes,
        unreferenced vertices and degenerate triangles are allowed.

    Notes
    -----
    - ``implicit(x)``: exact distance to the closest point on the triangles, negative
      where the generalized winding number exceeds 1/2; normals are the unit
      gradient ``sign * (x - closest) / |x - closest|`` (the face normal on the surface).
    - ``contains(x)``: winding number > 1/2.
    - ``mesh()`` returns the mesh itself; ``surfels(spacing)`` is LDC sampling
      (:func:`unmesh.surfels.sample_mesh`).
    - ``area()`` is the triangle area; ``volume()`` the signed volume by the
      divergence theorem (exact for closed meshes, approximate with holes).
    - ``transformed(matrix)`` accepts any invertible affine map.

    Example
    -------
    >>> from unmesh.shapes import Box
    >>> shape = MeshShape(Box(size=(2, 2, 2)).mesh(resolution=2))
    >>> v, n = shape.implicit([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    >>> v.tolist()
    [-1.0, 2.0]
    """

    kind = ""

    def __init__(self, mesh: TriangleMesh) -> None:
        from unmesh.meshes import TriangleMesh

        if not isinstance(mesh, TriangleMesh):
            raise InputError(f"mesh: expected a TriangleMesh, got {type(mesh).__name__}")
        if len(mesh.faces) == 0:
            raise InputError("mesh: expected at least one triangle, got an empty mesh")
        if not mesh.area() > 0:
            raise InputError("mesh: expected triangles with non-zero area, all are degenerate")
        self.mesh_data = mesh
        self.closed = len(mesh.boundary_edges()) == 0

    def params(self) -> dict[str, Any]:
        return {"mesh": repr(self.mesh_data)}

    def __repr__(self) -> str:
        return f"MeshShape({self.mesh_data!r})"

    @functools.cached_property
    def bvh(self) -> TriangleBVH:
        """The triangle tree of the mesh (:class:`unmesh.spatial.TriangleBVH`), built on first use."""
        return TriangleBVH(self.mesh_data.vertices, self.mesh_data.faces)

    # -- queries -----------------------------------------------------------------------
    def closest_points(self, x: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points on the triangles.

        Parameters
        ----------
        x : array_like, shape (N, 3)
            Query points.

        Returns
        -------
        distances : (N,) float64
        points : (N, 3) float64
        faces : (N,) int64
            Index of the triangle holding each closest point (one of them on exact ties).

        Example
        -------
        >>> from unmesh.meshes import TriangleMesh
        >>> m = MeshShape(TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]))
        >>> d, p, f = m.closest_points([[0.2, 0.2, 1.0]])
        >>> float(d[0]), np.round(p[0], 12).tolist()
        (1.0, [0.2, 0.2, 0.0])
        """
        dist, face, pts, _ = self.bvh.closest(as_points(x, "x"))
        return dist, pts, face

    def winding_number(self, x: Any) -> np.ndarray:
        """Generalized winding numbers (N,) at points ``x``: 1 inside, 0 outside a closed mesh.

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> m = MeshShape(Sphere().mesh(resolution=8))
        >>> [round(float(w), 1) + 0.0 for w in m.winding_number([[0, 0, 0], [5, 0, 0]])]
        [1.0, 0.0]
        """
        return self.bvh.winding_number(as_points(x, "x"), WINDING_BETA)

    def implicit(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (N,) (negative inside by winding number) and unit gradients (N,3).

        Example
        -------
        >>> from unmesh.shapes import Box
        >>> shape = MeshShape(Box(size=(2, 2, 2)).mesh(resolution=2))
        >>> shape.implicit([[0.0, 0.0, 3.0]])[1].tolist()
        [[0.0, 0.0, 1.0]]
        """
        pts = as_points(x, "x")
        dist, closest, face = self.closest_points(pts)
        sign = np.where(self.winding_number(pts) > 0.5, -1.0, 1.0)
        diff = pts - closest
        normals = np.empty_like(pts)
        ok = dist > 1e-12 * max(1.0, self.size())
        normals[ok] = sign[ok, None] * diff[ok] / dist[ok, None]
        fn = self.mesh_data.face_normals()[face[~ok]]
        normals[~ok] = fn
        bad = ~(np.linalg.norm(normals, axis=1) > 0)
        normals[bad] = (0.0, 0.0, 1.0)
        return sign * dist, normals

    def contains(self, x: Any) -> np.ndarray:
        """True (N,) where the generalized winding number exceeds 1/2.

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> MeshShape(Sphere().mesh(resolution=8)).contains([[0, 0, 0], [0, 2, 0]]).tolist()
        [True, False]
        """
        return self.winding_number(x) > 0.5

    # -- protocol ------------------------------------------------------------------------
    def mesh(self, spacing: float | None = None, *, resolution: int | None = None) -> TriangleMesh:
        """The mesh itself (``spacing`` and ``resolution`` are accepted for the protocol and ignored)."""
        return self.mesh_data

    def surfels(self, spacing: float, color: Any = None, *, progress: bool = False) -> SurfelCloud:
        """LDC samples of the mesh (:func:`unmesh.surfels.sample_mesh`); ``color`` overrides the mesh colours.

        Example
        -------
        >>> from unmesh.shapes import Sphere
        >>> c = MeshShape(Sphere().mesh(resolution=16)).surfels(0.1)
        >>> len(c) > 1000
        True
        """
        from unmesh.surfels.sampling import sample_mesh

        cloud = sample_mesh(self.mesh_data, spacing, progress=progress)
        if color is not None:
            col = as_array(color, "color", (3,))
            cloud = cloud.replace(colors=np.broadcast_to(col, cloud.positions.shape))
        return cloud

    def bounds(self) -> np.ndarray:
        """Bounds (2,3) of the vertices used by faces."""
        return self.mesh_data.bounds()

    def size(self) -> float:
        lo, hi = self.bounds()
        return float((hi - lo).max())

    def area(self) -> float:
        return self.mesh_data.area()

    def volume(self) -> float:
        return self.mesh_data.volume()

    def transformed(self, matrix: Any) -> MeshShape:
        """The mesh moved by any invertible 4x4 affine (or 3x3 linear) map."""
        return MeshShape(self.mesh_data.transformed(matrix))
