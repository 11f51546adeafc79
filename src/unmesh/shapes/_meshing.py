"""Mesh and sample construction helpers shared by the analytic shapes (local frame).

Vertices that must be shared between patches are computed with identical
floating-point expressions, so :func:`weld` merges them by exact equality.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = [
    "cell_radii",
    "grid_faces",
    "polar_rings",
    "project_to_zero",
    "ring_zipper",
    "weld",
]


def grid_faces(nu: int, nv: int, wrap_u: bool = False, wrap_v: bool = False) -> np.ndarray:
    """Triangles (2*nu*nv, 3) of a vertex grid indexed ``i * (nv') + j``.

    The grid has ``nu' = nu (+1 unless wrap_u)`` by ``nv' = nv (+1 unless wrap_v)``
    vertices; quads ``(i,j), (i+1,j), (i+1,j+1), (i,j+1)`` are split into two
    triangles that are counter-clockwise when u x v points outward.
    """
    nu_v = nu if wrap_u else nu + 1
    nv_v = nv if wrap_v else nv + 1
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    i = i.ravel()
    j = j.ravel()
    i1 = (i + 1) % nu_v
    j1 = (j + 1) % nv_v
    a = i * nv_v + j
    b = i1 * nv_v + j
    c = i1 * nv_v + j1
    d = i * nv_v + j1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge bit-identical vertices and drop faces that became degenerate."""
    uniq, inverse = np.unique(vertices, axis=0, return_inverse=True)
    f = inverse.reshape(-1)[faces]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    return np.ascontiguousarray(uniq), np.ascontiguousarray(f[keep], dtype=np.int64)


def ring_zipper(inner: np.ndarray, inner_angles: np.ndarray, outer: np.ndarray, outer_angles: np.ndarray) -> np.ndarray:
    """Triangulate the annulus between two closed rings of vertex indices.

    Angles increase from the first vertex of each ring (in [0, 2 pi)); the
    triangles are counter-clockwise seen from +z when the rings circle +z
    counter-clockwise and ``inner`` has the smaller radius. A ring of one vertex
    (the centre) gives a fan.
    """
    a, b = len(inner), len(outer)
    tris = []
    i = j = 0
    while i < a or j < b:
        ang_i = inner_angles[(i + 1) % a] + 2 * np.pi * ((i + 1) // a) if a > 1 else np.inf
        ang_j = outer_angles[(j + 1) % b] + 2 * np.pi * ((j + 1) // b)
        if a > 1 and (j >= b or (i < a and ang_i <= ang_j)):
            tris.append((inner[i % a], outer[j % b], inner[(i + 1) % a]))
            i += 1
        else:
            tris.append((inner[i % a], outer[j % b], outer[(j + 1) % b]))
            j += 1
            if a == 1 and j >= b:
                i = a
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def polar_rings(radius: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V,3) at z=0 and CCW faces (F,3) of a disc of ``radius`` in the xy plane.

    Concentric rings about ``spacing`` apart; the outer ring has
    ``max(8, ceil(2 pi radius / spacing))`` vertices at angles ``2 pi i / n`` with
    coordinates ``radius * 1.0 * cos``, identical to a cylinder side built with the
    same count.
    """
    n_out = max(8, int(np.ceil(2 * np.pi * radius / spacing)))
    m = max(1, int(np.ceil(radius / spacing)))
    verts = [np.zeros((1, 3))]
    rings = [np.array([0])]
    angles = [np.array([0.0])]
    start = 1
    for k in range(1, m + 1):
        frac = k / m
        n_k = n_out if k == m else max(6, round(n_out * frac))
        th = 2 * np.pi * np.arange(n_k) / n_k
        rk = radius * frac
        ring = np.stack([rk * np.cos(th), rk * np.sin(th), np.zeros(n_k)], 1)
        verts.append(ring)
        rings.append(np.arange(start, start + n_k))
        angles.append(th)
        start += n_k
    faces = [ring_zipper(rings[k], angles[k], rings[k + 1], angles[k + 1]) for k in range(m)]
    return np.concatenate(verts), np.concatenate(faces)


def cell_radii(param: Callable[[np.ndarray, np.ndarray], np.ndarray], centers_uv: np.ndarray,
               lo_uv: np.ndarray, hi_uv: np.ndarray, per_edge: int = 6, margin: float = 1.01) -> np.ndarray:
    """Covering radius of each parametric cell seen from its sample.

    ``param(u, v) -> (N,3)`` maps parameters to surface points. For cell i with
    parameter box ``[lo_uv[i], hi_uv[i]]`` and sample ``param(centers_uv[i])``, the
    result is ``margin`` times the largest 3-D distance from the sample to
    ``per_edge`` points on each edge of the cell boundary (corners included). The
    splat of that radius contains the projection of the whole (small) cell.
    """
    c = param(centers_uv[:, 0], centers_uv[:, 1])
    t = np.linspace(0.0, 1.0, per_edge + 1)
    best = np.zeros(len(c))
    for s in t:
        for u, v in (
            (lo_uv[:, 0] + s * (hi_uv[:, 0] - lo_uv[:, 0]), lo_uv[:, 1]),
            (lo_uv[:, 0] + s * (hi_uv[:, 0] - lo_uv[:, 0]), hi_uv[:, 1]),
            (lo_uv[:, 0], lo_uv[:, 1] + s * (hi_uv[:, 1] - lo_uv[:, 1])),
            (hi_uv[:, 0], lo_uv[:, 1] + s * (hi_uv[:, 1] - lo_uv[:, 1])),
        ):
            best = np.maximum(best, np.linalg.norm(param(u, v) - c, axis=1))
    return best * margin


def polar_cells(radius: float, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell-centred samples of a disc: centre sample plus rings of annular sectors.

    Returns
    -------
    centers : (N, 2) polar (rho, phi) of the samples
    lo, hi : (N, 2) parameter boxes of their cells (the centre cell is a full disc).
    """
    m = max(1, int(np.ceil(radius / spacing + 0.5)))
    if m == 1:
        return np.array([[0.0, 0.0]]), np.array([[0.0, 0.0]]), np.array([[radius, 2 * np.pi]])
    dr = radius / (m - 0.5)
    centers = [np.array([[0.0, 0.0]])]
    lo = [np.array([[0.0, 0.0]])]
    hi = [np.array([[0.5 * dr, 2 * np.pi]])]
    for k in range(1, m):
        r0 = (k - 0.5) * dr
        r1 = radius if k == m - 1 else (k + 0.5) * dr
        rm = 0.5 * (r0 + r1)
        n = max(3, int(np.ceil(2 * np.pi * rm / dr)))
        phi = 2 * np.pi * np.arange(n) / n
        dphi = 2 * np.pi / n
        centers.append(np.stack([np.full(n, rm), phi + 0.5 * dphi], 1))
        lo.append(np.stack([np.full(n, r0), phi], 1))
        hi.append(np.stack([np.full(n, r1), phi + dphi], 1))
    return np.concatenate(centers), np.concatenate(lo), np.concatenate(hi)


def project_to_zero(func: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], points: np.ndarray,
                    spacing: float, iterations: int = 6, tol: float = 1e-13) -> np.ndarray:
    """Newton projection of points (N,3) onto the zero set of ``func(x) -> (values, unit normals)``.

    Steps ``x -= f(x) n(x) / s`` where the slope ``s = |grad f|`` along the normal is
    a forward difference of length ``1e-4 * spacing`` (re-estimated at every step,
    only for points not yet converged) and each step is at most ``spacing`` long;
    stops after ``iterations`` steps or when ``|f| <= tol * spacing``.
    """
    x = np.array(points, dtype=np.float64)
    f, n = func(x)
    eps = 1e-4 * spacing
    active = np.flatnonzero(np.abs(f) > tol * spacing)
    for _ in range(iterations):
        if not len(active):
            break
        xa = x[active]
        fa = f[active]
        na = n[active]
        slope = np.maximum((func(xa + eps * na)[0] - fa) / eps, 1e-3)
        step = np.clip(fa / slope, -spacing, spacing)
        x[active] = xa - step[:, None] * na
        fa, na = func(x[active])
        f[active] = fa
        n[active] = na
        active = active[np.abs(fa) > tol * spacing]
    return x


def _grid_values(func: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], lo: np.ndarray, spacing: float,
                 counts: np.ndarray, lipschitz: bool, block: int = 4) -> np.ndarray:
    """Values of ``func`` on the grid ``lo + spacing * (i, j, k)``.

    With ``lipschitz`` (|grad f| <= 1) only blocks of ``block^3`` points that can
    contain the zero level (|f(block centre)| <= half diagonal + one cell
    diagonal) are evaluated point by point; the others take their centre value,
    which has the right sign everywhere in the block.
    """
    axes = [lo[k] + spacing * np.arange(counts[k]) for k in range(3)]
    if not lipschitz:
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        return func(grid)[0].reshape(tuple(counts))
    nb = -(-counts // block)
    centers = [lo[k] + spacing * (block * np.arange(nb[k]) + 0.5 * (block - 1)) for k in range(3)]
    cgrid = np.stack(np.meshgrid(*centers, indexing="ij"), -1).reshape(-1, 3)
    fc = func(cgrid)[0].reshape(tuple(nb))
    reach = (0.5 * (block - 1) + 1.0) * math.sqrt(3.0) * spacing
    values = np.repeat(np.repeat(np.repeat(fc, block, 0), block, 1), block, 2)[: counts[0], : counts[1], : counts[2]].copy()
    near = np.argwhere(np.abs(fc) <= reach)
    if len(near):
        off = np.stack(np.meshgrid(*([np.arange(block)] * 3), indexing="ij"), -1).reshape(-1, 3)
        idx = (near[:, None, :] * block + off[None]).reshape(-1, 3)
        idx = idx[np.all(idx < counts, axis=1)]
        values[idx[:, 0], idx[:, 1], idx[:, 2]] = func(lo + spacing * idx)[0]
    return values


def marching_mesh(func: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], lo: np.ndarray, hi: np.ndarray,
                  spacing: float, lipschitz: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes of ``func(x) -> (values, unit normals)`` over the box [lo, hi].

    The box is padded by two cells and sampled (``lipschitz=True``, i.e. |grad f| <= 1,
    evaluates ``func`` only near the surface); the surface is
    :func:`unmesh.meshes.marching_cubes` with ``func`` refining the vertices: each lies
    on a grid edge whose end values have opposite signs and is moved along that edge
    to the exact zero of ``func`` (regula falsi), so vertices are on the surface to
    round-off while every triangle stays in its cube (no folds). Faces are oriented
    outward (positive volume).
    """
    from unmesh.meshes.marching import marching_cubes

    lo = np.asarray(lo, dtype=np.float64) - 2 * spacing
    hi = np.asarray(hi, dtype=np.float64) + 2 * spacing
    counts = np.maximum(np.ceil((hi - lo) / spacing).astype(np.int64) + 1, 3)
    values = _grid_values(func, lo, spacing, counts, lipschitz)
    mesh = marching_cubes(values, lo, spacing, 0.0, inside="below", function=lambda x: func(x)[0])
    out, faces = mesh.vertices, mesh.faces
    v0, v1, v2 = out[faces[:, 0]], out[faces[:, 1]], out[faces[:, 2]]
    vol = np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum()
    if vol < 0:  # never for a closed surface (marching_cubes orients outward); kept as a guard
        faces = faces[:, ::-1].copy()
    return np.ascontiguousarray(out), np.ascontiguousarray(faces)
