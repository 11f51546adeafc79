"""Plain numpy reference implementations of the render kernels (slow; for tests on small scenes).

They are written independently of the kernels: in world space, with unit ray directions from
:meth:`unmesh.render.Camera.rays`, evaluating every primitive at every pixel (no boxes, no
tiles), so they also check the kernels' conservative pixel boxes and binning.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh.render.camera import Camera

__all__ = ["shade_reference", "spheres_reference", "splat_reference", "triangles_reference"]


def _pixel_centres(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    h, w = camera.shape
    rows, cols = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    return rows, cols


def splat_reference(positions: np.ndarray, normals: np.ndarray, axes: np.ndarray, colors: np.ndarray, camera: Camera,
                    kappa: float = 2.0, filter_radius: float = 0.71, depth_tolerance: float = 1.0,
                    zinit: np.ndarray | None = None) -> dict[str, Any]:
    """EWA splatting of N surfels (3.2) by brute force.

    A surfel with tangent axes ``a1, a2`` is the ellipse ``{c + u a1 + v a2 : u^2 + v^2 <= 1}``.

    Returns a dict with ``zvis``, ``sum_weight``, ``sum_color``, ``sum_normal`` (world),
    ``sum_depth`` and ``count`` as :class:`unmesh.render.SplatRenderer` defines them.
    """
    h, w = camera.shape
    origins, dirs = camera.rays()
    fwd = camera.forward
    along = dirs @ fwd
    rows, cols = _pixel_centres(camera)
    prow, pcol, pdepth = camera.project(positions)
    near = camera.near_distance
    rf2 = filter_radius**2
    frags = []
    zvis = np.full((h, w), np.inf) if zinit is None else zinit.astype(np.float64).copy()
    for i in range(len(positions)):
        c = positions[i]
        n = normals[i]
        a1, a2 = axes[i]
        gram = np.array([[a1 @ a1, a1 @ a2], [a1 @ a2, a2 @ a2]])
        r = float(np.sqrt(np.linalg.eigvalsh(gram).max()))  # largest semi-axis of {c + u a1 + v a2}
        b1, b2 = np.linalg.solve(gram, np.stack([a1, a2]))  # dual basis: b_i . a_j = delta_ij
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            dn = dirs @ n
            t = ((c - origins) @ n) / dn
            p = origins + t[..., None] * dirs
            u = (p - c) @ b1
            v = (p - c) @ b2
            rho3 = u * u + v * v
            rho3 = np.where(np.isfinite(rho3) & (np.abs(dn) > 1e-12), rho3, np.inf)
            cz = pdepth[i]
            if camera.is_ortho:
                cos = abs(n @ camera.forward)
            else:
                cos = abs(n @ (c - camera.eye)) / np.linalg.norm(c - camera.eye)
            sin = np.sqrt(max(1 - cos * cos, 0.0))
            edge_on = sin > 4.0 * cos
            ewa = edge_on and rf2 > 0
            if rf2 > 0 and np.isfinite(prow[i]):
                ey, ex = rows - prow[i], cols - pcol[i]
                q = np.eye(2) / rf2  # the disc; edge-on: rf across, up to 1 pixel along (_filter_form)
                if ewa and (camera.is_ortho or (cz > near and r < 0.25 * cz)):
                    jj = np.zeros((2, 2))
                    for ax in (a1, a2):  # screen images (col, row) of the axes, projection linearised at c
                        hstep = 1e-4
                        pr, pc, _ = camera.project(np.stack([c + hstep * ax, c - hstep * ax]))
                        jv = np.array([pc[0] - pc[1], pr[0] - pr[1]]) / (2 * hstep)
                        jj += np.outer(jv, jv)
                    lam, vec = np.linalg.eigh(jj)
                    if lam[1] > 0:
                        reach = max(filter_radius, min(np.sqrt(lam[1] + rf2), 1.0))  # EDGE_FILTER_REACH
                        e1, e2 = vec[:, 1], vec[:, 0]
                        q = np.outer(e1, e1) / reach**2 + np.outer(e2, e2) / rf2
                rho2 = q[0, 0] * ex * ex + 2 * q[0, 1] * ex * ey + q[1, 1] * ey * ey
            else:
                rho2 = np.full((h, w), np.inf)
            # depth range: ellipse plus the screen filter footprint on the tilted plane
            if camera.is_ortho:
                fw = filter_radius / camera.pixels_per_unit
            else:
                fw = filter_radius * cz / camera.pixels_per_unit if cz > near else 0.0
            zr = r + fw * 4.0 if edge_on else r + fw * sin / cos
            zt = np.clip(t * along, cz - zr, cz + zr)
            z = np.where(np.isfinite(rho3) & (~edge_on | (rho3 <= rho2)) & np.isfinite(zt), zt, cz)
            rho = np.minimum(rho3, rho2)
        mask = (rho < 1.0) & (z > near)
        frags.append((mask, rho, z))
        zvis = np.where(mask, np.minimum(zvis, z + depth_tolerance * r), zvis)
    sw = np.zeros((h, w))
    sc = np.zeros((h, w, 3))
    sn = np.zeros((h, w, 3))
    sd = np.zeros((h, w))
    cnt = np.zeros((h, w), dtype=np.int64)
    for i, (mask, rho, z) in enumerate(frags):
        ok = mask & (z <= zvis)
        wgt = np.where(ok, np.exp(-kappa * np.where(ok, rho, 0.0)), 0.0)
        sw += wgt
        sc += wgt[..., None] * colors[i]
        sn += wgt[..., None] * normals[i]
        sd += wgt * np.where(ok, z, 0.0)
        cnt += ok
    return {"zvis": zvis, "sum_weight": sw, "sum_color": sc, "sum_normal": sn, "sum_depth": sd, "count": cnt}


def shade_reference(albedo: np.ndarray, normal: np.ndarray, coverage: np.ndarray, camera: Camera,
                    light_dirs: np.ndarray, light_cols: np.ndarray, ambient: float, specular: float,
                    shininess: float, background: np.ndarray) -> np.ndarray:
    """Two-sided Blinn-Phong of a G-buffer (see :func:`unmesh.render.shading.shade`)."""
    _, dirs = camera.rays()
    v = -dirs
    n = np.where((np.sum(normal * v, axis=-1) < 0)[..., None], -normal, normal)
    diff = np.full(albedo.shape, ambient)
    spec = np.zeros(albedo.shape)
    for ldir, lcol in zip(light_dirs, light_cols, strict=True):
        ndl = n @ ldir
        lit = ndl > 0
        diff += np.where(lit, ndl, 0.0)[..., None] * lcol
        hv = ldir + v
        hv /= np.linalg.norm(hv, axis=-1, keepdims=True)
        ndh = np.sum(n * hv, axis=-1)
        spec += np.where(lit & (ndh > 0), np.maximum(ndh, 0.0) ** shininess, 0.0)[..., None] * lcol
    out = np.clip(albedo * diff + specular * spec, 0.0, 1.0)
    return np.where(coverage[..., None], out, background)


def triangles_reference(vertices: np.ndarray, faces: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-buffer of triangles: ``(depth (H,W), face (H,W) int, barycentrics (H,W,3))``.

    A pixel sees a triangle when its centre ray meets it (barycentrics >= 0) in front of
    ``near``; the nearest hit wins (lowest face index on exact ties).
    """
    h, w = camera.shape
    origins, dirs = camera.rays()
    along = dirs @ camera.forward
    depth = np.full((h, w), np.inf)
    face = np.full((h, w), -1, dtype=np.int64)
    bary = np.zeros((h, w, 3))
    for fi, (i, j, k) in enumerate(faces):
        v0, v1, v2 = vertices[i], vertices[j], vertices[k]
        e1 = v1 - v0
        e2 = v2 - v0
        pvec = np.cross(dirs, e2)
        det = pvec @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tvec = origins - v0
            u = np.sum(tvec * pvec, axis=-1) * inv
            qvec = np.cross(tvec, e1)
            v = np.sum(dirs * qvec, axis=-1) * inv
            t = (qvec @ e2) * inv
        z = t * along
        tol = 1e-12
        hit = (np.abs(det) > 1e-300) & (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol) & (z > camera.near_distance)
        better = hit & (z < depth)
        depth = np.where(better, z, depth)
        face = np.where(better, fi, face)
        bary = np.where(better[..., None], np.stack([1 - u - v, u, v], axis=-1), bary)
    return depth, face, bary


def spheres_reference(centers: np.ndarray, radii: np.ndarray, camera: Camera, filter_radius: float = 0.0
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray-cast spheres: ``(depth (H,W), index (H,W) int, world normal (H,W,3))``.

    With ``filter_radius > 0`` a pixel whose centre lies within that many pixels of a sphere's
    projected centre also sees it (at depth ``z_c - r``, normal towards the viewer) when the ray
    misses, so spheres smaller than a pixel never vanish.
    """
    h, w = camera.shape
    origins, dirs = camera.rays()
    along = dirs @ camera.forward
    rows, cols = _pixel_centres(camera)
    prow, pcol, pdepth = camera.project(centers)
    depth = np.full((h, w), np.inf)
    index = np.full((h, w), -1, dtype=np.int64)
    normal = np.zeros((h, w, 3))
    for i, (c, r) in enumerate(zip(centers, radii, strict=True)):
        oc = origins - c
        b = np.sum(oc * dirs, axis=-1)
        disc = b * b - (np.sum(oc * oc, axis=-1) - r * r)
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        hit = (disc >= 0) & (t * along > camera.near_distance)
        z = np.where(hit, t * along, np.inf)
        nrm = (origins + t[..., None] * dirs - c) / r
        if filter_radius > 0 and np.isfinite(prow[i]):
            near = ~hit & (((rows - prow[i]) ** 2 + (cols - pcol[i]) ** 2) <= filter_radius**2) & (pdepth[i] - r > camera.near_distance)
            z = np.where(near, pdepth[i] - r, z)
            nrm = np.where(near[..., None], -camera.forward, nrm)
            hit = hit | near
        better = hit & (z < depth)
        depth = np.where(better, z, depth)
        index = np.where(better, i, index)
        normal = np.where(better[..., None], nrm, normal)
    return depth, index, normal
