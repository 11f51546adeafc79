"""Mean value coordinates of convex polyhedra with triangulated faces (9.8–9.10, App. D).

The coordinates ``φ_i(x)`` are positive inside a convex polyhedron, form a
partition of unity, reproduce linear functions (``Σ φ_i x_i = x``, 9.11), reduce
to barycentric coordinates on tetrahedra and, on the boundary, to barycentric
coordinates of the boundary triangle. The formulation is the one of Floater,
Kós & Reimers (2005) and Ju, Schaefer & Warren (2005), written with the
tetrahedron volumes of (9.8); see :mod:`unmesh.fem._mvc_kernels` for the
derivation and the exact gradients (Appendix D, with the corrected (D.3)).

Example
-------
>>> import numpy as np
>>> v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
>>> f = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
>>> phi, grad = mean_value_coordinates(v, f, [[0.1, 0.2, 0.3]])
>>> np.round(phi, 12).tolist()
[[0.4, 0.1, 0.2, 0.3]]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_indices, as_points
from unmesh.errors import InputError

__all__ = ["mean_value_coordinates", "mean_value_coordinates_reference"]


def _prepare(vertices: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    v = as_points(vertices, "vertices")
    if len(v) < 4:
        raise InputError(f"vertices: expected at least 4 vertices of a polyhedron, got {len(v)}")
    if isinstance(faces, list | tuple) and faces and any(len(f) != 3 for f in faces):
        from unmesh.fem import _kernels as K

        flat = np.array([i for f in faces for i in f], dtype=np.int64)
        off = np.r_[0, np.cumsum([len(f) for f in faces])].astype(np.int64)
        if flat.size and (flat.min() < 0 or flat.max() >= len(v)):
            raise InputError(f"faces: expected indices in [0, {len(v)})")
        f = K.triangulate_faces(v, flat, off, 1e-9)
    else:
        f = as_indices(faces, "faces", (None, 3), upper=len(v))
    if len(f) < 4:
        raise InputError(f"faces: expected a closed triangulated surface (at least 4 triangles), got {len(f)}")
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0
    scale = np.ptp(v, axis=0).max()
    if not abs(vol) > 1e-14 * scale**3:
        raise InputError("faces: the surface encloses no volume (open, flat, or inconsistently oriented)")
    if vol < 0:
        f = np.ascontiguousarray(f[:, ::-1])
    return v, np.ascontiguousarray(f)


def mean_value_coordinates(vertices: Any, faces: Any, points: Any, *,
                           gradients: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Mean value coordinates and their gradients in one convex polyhedron (9.8–9.10, App. D).

    Parameters
    ----------
    vertices : array_like, shape (n, 3)
        Polyhedron vertices (float64).
    faces : array_like, shape (m, 3) or list of polygons
        Triangulated faces, consistently oriented (outward or all inward: the
        orientation is detected from the signed volume). Convex polygons are
        triangulated first.
    points : array_like, shape (P, 3)
        Evaluation points (usually inside; outside, the coordinates are still
        defined away from the face planes but may be negative).
    gradients : bool, optional
        Also return ∇φ (default True).

    Returns
    -------
    phi : ndarray, shape (P, n)
        Coordinates φ_i(x) (9.10).
    grad : ndarray, shape (P, n, 3) or None
        Gradients ∇φ_i(x) (D.1). On the boundary (within 1e-12 of the diameter)
        φ is the barycentric coordinate of the boundary triangle and the
        gradient is evaluated 1e-7 diameters inside.

    Example
    -------
    >>> from unmesh.fem import convex_polyhedron
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> poly = convex_polyhedron(rng.normal(size=(20, 3)))
    >>> v, f = poly.points, poly.boundary_triangles()
    >>> phi, grad = mean_value_coordinates(v, f, [[0.01, 0.02, -0.03]])
    >>> bool(np.allclose(phi @ v, [[0.01, 0.02, -0.03]]))
    True
    """
    from unmesh.fem._mvc_kernels import mvc_many

    v, f = _prepare(vertices, faces)
    x = as_points(points, "points")
    phi, grad = mvc_many(v, f, x, bool(gradients))
    return phi, (grad if gradients else None)


def mean_value_coordinates_reference(vertices: Any, faces: Any, points: Any) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy reference of :func:`mean_value_coordinates` (interior points only).

    Vectorised over points and triangles; used by the tests to check the numba
    kernel. Same parameters and returns.

    Example
    -------
    >>> import numpy as np
    >>> v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> f = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    >>> phi, _ = mean_value_coordinates_reference(v, f, [[0.25, 0.25, 0.25]])
    >>> np.round(phi, 12).tolist()
    [[0.25, 0.25, 0.25, 0.25]]
    """
    v, f = _prepare(vertices, faces)
    x = as_points(points, "points")
    n = len(v)
    d = v[f][None, :, :, :] - x[:, None, None, :]  # (P, T, 3 corners, 3)
    nrm = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # (T,3)
    D = np.einsum("ptk,tk->pt", d[:, :, 0], nrm)
    m = np.zeros((*d.shape[:2], 3))
    J = np.zeros((*d.shape[:2], 3, 3))
    eye = np.eye(3)
    for e in range(3):
        a, b = d[:, :, e], d[:, :, (e + 1) % 3]
        c = np.cross(a, b)
        s = np.linalg.norm(c, axis=-1)
        t = np.einsum("ptk,ptk->pt", a, b)
        th = np.arctan2(s, t)
        nv = c / s[..., None]
        m += 0.5 * th[..., None] * nv
        g = b - a
        gth = (t[..., None] * np.cross(nv, g) + s[..., None] * (a + b)) / (s * s + t * t)[..., None]
        G = np.zeros((*g.shape, 3))
        G[..., 0, 1], G[..., 0, 2] = -g[..., 2], g[..., 1]
        G[..., 1, 0], G[..., 1, 2] = g[..., 2], -g[..., 0]
        G[..., 2, 0], G[..., 2, 1] = -g[..., 1], g[..., 0]
        proj = eye - nv[..., :, None] * nv[..., None, :]
        J += 0.5 * (nv[..., :, None] * gth[..., None, :] + (th / s)[..., None, None] * proj @ G)
    w = np.zeros((len(x), n))
    gw = np.zeros((len(x), n, 3))
    for r in range(3):
        j, k = (r + 1) % 3, (r + 2) % 3
        c = np.cross(d[:, :, j], d[:, :, k])
        N = np.einsum("ptk,ptk->pt", m, c)
        wi = N / D
        gN = np.einsum("ptij,pti->ptj", J, c) + np.cross(m, d[:, :, k] - d[:, :, j])
        gwi = (gN + wi[..., None] * nrm[None]) / D[..., None]
        for p in range(len(x)):
            np.add.at(w[p], f[:, r], wi[p])
            np.add.at(gw[p], f[:, r], gwi[p])
    W = w.sum(axis=1, keepdims=True)
    phi = w / W
    grad = (gw - phi[..., None] * gw.sum(axis=1, keepdims=True)) / W[..., None]
    return phi, grad
