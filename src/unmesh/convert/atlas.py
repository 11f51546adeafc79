"""Atlas assembly: patches + placement -> pages, uv coordinates and tangent-space normals (6.2, 6.3, 6.5).

Texel ``(r, c)`` of patch t (row 0 at the top, base edge along the bottom) goes to page texel
``(y_t + r', x_t + c')`` with ``r' = H - 1 - r`` when flipped vertically and ``c' = W - 1 - c``
when flipped horizontally; only the patch's footprint texels are copied. A corner with local
patch coordinates (x, y) gets the continuous texel position ``(o + x s, H - o - y s)`` (o: the
corner offset :attr:`~unmesh.convert.patches.Patches.offset`, 0.5 or 1; s =
texels per unit; mirrored with the flips) and ``u = X / E``, ``v = 1 - Y / E`` on a page of
edge E (uv origin bottom-left, as in OBJ and the rasteriser).

Normal maps are tangent-space, in exactly the frame the rasteriser (and glTF/OpenGL tools)
rebuild per pixel: N = the interpolated corner normal (:func:`unmesh.render.raster.corner_normals`),
T = the direction of +u (±e_x of the patch frame), B = +v (±e_y), orthonormalised by
Gram-Schmidt around N; a baked normal n is stored as ``((n.T, n.B, n.N) + 1) / 2``.

Mip levels (6.5) reuse the placement: level k of a page averages each 2^k x 2^k block of
the page over the footprint texels that fall into it (a box filter in the same layout;
texels outside every footprint do not count). Blocks straddling two patches mix them, a simplification
of the thesis, which renders every patch again at half and quarter resolution.
"""

from __future__ import annotations

import numpy as np

from unmesh.convert._patch_kernels import footprints
from unmesh.convert.packing import Placement
from unmesh.convert.patches import CORNER_OFFSET, Patches, TriangleFrames, spacings
from unmesh.convert.textured import TexturedMesh
from unmesh.meshes import TriangleMesh
from unmesh.render.raster import corner_normals

__all__ = ["assemble", "patch_corners", "patch_masks"]


def patch_corners(frames: TriangleFrames, level: np.ndarray, height: np.ndarray,
                  offset: float = CORNER_OFFSET) -> np.ndarray:
    """Corners (F, 3, 2) of every triangle in its patch's texel coordinates (column, row), in face
    order; ``offset``: :attr:`unmesh.convert.patches.Patches.offset`."""
    s = spacings(level) / frames.length
    loc = frames.corners_local()
    out = np.empty_like(loc)
    out[:, :, 0] = offset + loc[:, :, 0] * s[:, None]
    out[:, :, 1] = (height[:, None] - offset) - loc[:, :, 1] * s[:, None]
    return out


def patch_masks(corners: np.ndarray, width: np.ndarray, height: np.ndarray) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Footprint masks (list of (H, W) bool), the flat buffer and its offsets."""
    offs = np.concatenate([[0], np.cumsum(width * height)]).astype(np.int64)
    flat = np.zeros(int(offs[-1]), bool)
    footprints(np.ascontiguousarray(corners), width.astype(np.int64), height.astype(np.int64), offs, flat)
    masks = [flat[offs[i]:offs[i + 1]].reshape(height[i], width[i]) for i in range(len(width))]
    return masks, flat, offs


def assemble(mesh: TriangleMesh, frames: TriangleFrames, patches: Patches, place: Placement,
             normal_map: bool, mipmaps: bool = False) -> TexturedMesh:
    """Build the pages and the per-page meshes of a conversion."""
    w, h = patches.width, patches.height
    corners = patch_corners(frames, patches.level, h, patches.offset)
    _, flat, offs = patch_masks(corners, w, h)
    # every footprint texel: its patch, row, column
    pix = np.flatnonzero(flat)
    t = np.searchsorted(offs, pix, side="right") - 1
    k = pix - offs[t]
    r, c = k // w[t], k % w[t]
    rr = np.where(place.flip_v[t], h[t] - 1 - r, r) + place.y[t]
    cc = np.where(place.flip_h[t], w[t] - 1 - c, c) + place.x[t]
    col_flat = np.concatenate([p.reshape(-1, 3) for p in patches.color])[pix]
    dep_flat = None if patches.depth is None else np.concatenate([d.ravel() for d in patches.depth])[pix]
    depth_pages = []
    # uv per corner
    X = np.where(place.flip_h[:, None], w[:, None] - corners[:, :, 0], corners[:, :, 0]) + place.x[:, None]
    Y = np.where(place.flip_v[:, None], h[:, None] - corners[:, :, 1], corners[:, :, 1]) + place.y[:, None]
    vnorm = mesh.computed_vertex_normals()
    parts = []
    mips = []
    regions = []
    for p, edge in enumerate(place.pages):
        on = np.flatnonzero(place.page == p)
        uv = np.stack([X[on] / edge, 1.0 - Y[on] / edge], axis=2).reshape(-1, 2)
        verts = mesh.vertices[mesh.faces[on]].reshape(-1, 3)
        part = TriangleMesh(verts, np.arange(3 * len(on)).reshape(-1, 3), uv=uv,
                            vertex_normals=vnorm[mesh.faces[on]].reshape(-1, 3))
        sel = place.page[t] == p
        img = np.empty((edge, edge, 3))
        img[:] = col_flat[sel].mean(axis=0) if sel.any() else 0.5
        img[rr[sel], cc[sel]] = np.clip(col_flat[sel], 0.0, 1.0)
        nmap = None
        if normal_map:
            nmap = np.empty((edge, edge, 3))
            nmap[:] = (0.5, 0.5, 1.0)
            nmap[rr[sel], cc[sel]] = _tangent_normals(part, on, frames, patches, place, t[sel], r[sel], c[sel])
        parts.append(part.replace(texture=img, normal_map=nmap))
        reg = np.full((edge, edge), -1, np.int64)
        reg[rr[sel], cc[sel]] = t[sel]
        regions.append(reg)
        if dep_flat is not None:
            dpage = np.zeros((edge, edge))
            dpage[rr[sel], cc[sel]] = dep_flat[sel]
            depth_pages.append(dpage)
        if mipmaps:
            mips.append(tuple(_mip(rr[sel], cc[sel], np.clip(col_flat[sel], 0.0, 1.0), edge, k, img[0, 0])
                              for k in (1, 2)))
    return TexturedMesh(tuple(parts), tuple(mips), tuple(depth_pages), tuple(regions))


def _tangent_normals(part: TriangleMesh, on: np.ndarray, frames: TriangleFrames, patches: Patches,
                     place: Placement, t: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Encoded tangent-space normals of texels (r, c) of patches t (all on ``part``'s page)."""
    nf = len(frames.length)
    row_of = np.full(nf, -1, np.int64)
    row_of[on] = np.arange(len(on))
    cn = corner_normals(part).reshape(len(on), 3, 3)  # world, face order
    rot = frames.rotation[t]
    cn_loc = np.einsum("pij,pkj->pki", rot, cn[row_of[t]])
    h = frames.length[t] / spacings(patches.level[t])
    lx = (c + 0.5 - patches.offset) * h
    ly = (patches.height[t] - patches.offset - (r + 0.5)) * h
    loc = frames.corners_local()[t]  # (P, 3, 2) face order
    # barycentric coordinates in the face's corner order, clamped to the triangle
    a, b, cc = loc[:, 0], loc[:, 1], loc[:, 2]
    v0, v1 = b - a, cc - a
    v2 = np.stack([lx, ly], axis=1) - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    bv = (d11 * d20 - d01 * d21) / den
    bw = (d00 * d21 - d01 * d20) / den
    bary = np.clip(np.stack([1.0 - bv - bw, bv, bw], axis=1), 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    n = np.einsum("pk,pkj->pj", bary, cn_loc)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    tan = np.zeros_like(n)
    bit = np.zeros_like(n)
    tan[:, 0] = np.where(place.flip_h[t], -1.0, 1.0)
    bit[:, 1] = np.where(place.flip_v[t], -1.0, 1.0)
    tan -= np.einsum("ij,ij->i", tan, n)[:, None] * n
    tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-12)
    bit -= np.einsum("ij,ij->i", bit, n)[:, None] * n + np.einsum("ij,ij->i", bit, tan)[:, None] * tan
    bit /= np.maximum(np.linalg.norm(bit, axis=1, keepdims=True), 1e-12)
    baked = _gather(patches.normal, t, r, c)
    baked /= np.maximum(np.linalg.norm(baked, axis=1, keepdims=True), 1e-12)
    s = np.stack([np.einsum("ij,ij->i", baked, tan), np.einsum("ij,ij->i", baked, bit),
                  np.einsum("ij,ij->i", baked, n)], axis=1)
    return np.clip(0.5 * (s + 1.0), 0.0, 1.0)


def _gather(images: list[np.ndarray], t: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``images[t][r, c]`` for many texels, through one flat buffer."""
    sizes = np.array([im.shape[0] * im.shape[1] for im in images], np.int64)
    offs = np.concatenate([[0], np.cumsum(sizes)])
    widths = np.array([im.shape[1] for im in images], np.int64)
    flat = np.concatenate([im.reshape(-1, im.shape[2]) for im in images])
    return flat[offs[t] + r * widths[t] + c]


def _mip(rows: np.ndarray, cols: np.ndarray, colors: np.ndarray, edge: int, k: int, background: np.ndarray) -> np.ndarray:
    """A colour page at 2^-k resolution from its footprint texels (same layout, 6.5): the mean
    of the footprint texels in every 2^k x 2^k block, the page background elsewhere."""
    f = 1 << k
    e = max(1, edge // f)
    acc = np.zeros((e, e, 3))
    cnt = np.zeros((e, e))
    np.add.at(acc, (rows // f, cols // f), colors)
    np.add.at(cnt, (rows // f, cols // f), 1.0)
    out = np.where(cnt[..., None] > 0, acc / np.maximum(cnt[..., None], 1.0), background)
    return np.clip(out, 0.0, 1.0)
