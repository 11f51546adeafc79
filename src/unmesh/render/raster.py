"""Z-buffered triangle rasterisation into the G-buffer (meshes from conversion, ch. 6, and
simulation surfaces).

Each pixel centre's ray is intersected with the triangles (Moller-Trumbore in camera space), so
interpolation of normals, colours and texture coordinates is perspective-correct. Supported:
per-vertex colours, uv textures with trilinear (mip-mapped) filtering (uv (0,0) = bottom-left
of the texture, which is stored with row 0 at the top, as in OBJ; coordinates outside [0, 1]
repeat, texels are clamped at the borders; the level of detail from the pixel's texel
footprint, :func:`texture_levels`; ``texture_filter="bilinear"`` for plain bilinear lookup),
tangent-space normal maps (filtered alike) (OpenGL convention: green = +v), and
smooth vertex normals with a crease angle (corners whose vertex normal deviates from the face
normal by more than ``crease_angle`` use the face normal, so boxes stay boxy). Both sides of a
triangle are drawn; shading is two-sided.

Example
-------
>>> from unmesh import TriangleMesh
>>> from unmesh.render import Camera
>>> quad = TriangleMesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]])
>>> cam = Camera((0, 0, 5), (0, 0, 0), width=20, height=20, ortho=4.0)
>>> g = GBuffer.empty(20, 20)
>>> draw_meshes(g, [quad], cam)
>>> int(g.coverage.sum())
100
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.render._kernels import SERIAL_BELOW, bin_boxes, box_visits, serial_if_small, tile_order
from unmesh.render._raster_kernels import texture_level, triangle_setup, triangle_tiles
from unmesh.render.camera import Camera
from unmesh.render.shading import GBuffer
from unmesh.surfels import DEFAULT_COLOR

__all__ = ["REGION_LEVELS", "TEXTURE_FILTERS", "corner_normals", "draw_meshes", "texture_levels", "vertex_tangents"]

_TILE = 32
TEXTURE_FILTERS = ("trilinear", "bilinear")
_TAPS = ((-1, 0.125), (0, 0.75), (1, 0.125))
_LEVEL_CACHE: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray]] = {}
_LEVEL_CACHE_BYTES = 256 * 2**20
#: Levels of a texture with regions (each a full copy of the texture): a blur of up to 32 texels.
REGION_LEVELS = 6


def texture_levels(image: np.ndarray, regions: np.ndarray | None = None, count: int | None = None) -> list[np.ndarray]:
    """Filtered levels of a texture for trilinear (mip-mapped) lookup: level k has the blur of a
    box of 2^k texels.

    Without ``regions``: the usual mip pyramid, level k + 1 = the 2 x 2 means of level k (an
    odd edge repeats its last row or column), down to one texel. With ``regions`` (an id per
    texel, e.g. the patch of an atlas texel): every level at full resolution, level k = level
    k - 1 filtered by the taps (1/8, 3/4, 1/8) spaced 2^(k-1) texels along each axis (the "a
    trous" scheme, variance (4^k - 1)/12 texel^2 beyond level 0, like a box of 2^k texels),
    where a tap counts only if its texel has the centre's id (weights renormalised): the levels
    of an atlas of separate patches never mix two patches or a patch with the page background
    (6.5), which a decimated pyramid cannot do for patches of a few texels. Taps beyond the
    image edge clamp to it.

    Parameters
    ----------
    image : (h, w, c) array
    regions : (h, w) integer array, optional
    count : int, optional
        Number of levels (default: down to one texel; with ``regions`` at most
        :data:`REGION_LEVELS`, a blur of 2^(REGION_LEVELS - 1) texels, as every level costs a
        full page).

    Returns
    -------
    list of (h_k, w_k, c) float64 arrays

    Example
    -------
    >>> img = np.zeros((4, 4, 1)); img[:, 2:] = 1.0
    >>> [lv.shape[:2] for lv in texture_levels(img)]
    [(4, 4), (2, 2), (1, 1)]
    >>> lv = texture_levels(img, regions=np.repeat([[0, 0, 1, 1]], 4, axis=0))
    >>> len(lv), bool(lv[-1][:, :2].max() == 0.0)       # the two halves never mix
    (3, True)
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3:
        raise InputError(f"image: expected an (h, w, c) array, got shape {img.shape}")
    h, w = img.shape[:2]
    if regions is not None:
        regions = np.asarray(regions)
        if regions.shape != (h, w):
            raise InputError(f"regions: expected shape {(h, w)}, got {regions.shape}")
    full = 1 + math.ceil(math.log2(max(h, w, 1)))
    n = (full if regions is None else min(full, REGION_LEVELS)) if count is None else int(count)
    if n < 1:
        raise InputError(f"count: expected at least 1 level, got {count}")
    out = [np.ascontiguousarray(img)]
    if regions is None:
        for _ in range(1, n):
            prev = out[-1]
            ph, pw = prev.shape[:2]
            if ph == 1 and pw == 1:
                break
            prev = np.pad(prev, ((0, ph % 2), (0, pw % 2), (0, 0)), mode="edge")
            hh, ww = prev.shape[0] // 2, prev.shape[1] // 2
            out.append(prev.reshape(hh, 2, ww, 2, -1).mean(axis=(1, 3)))
        return out
    reg = np.ascontiguousarray(regions, dtype=np.int64)
    for k in range(1, n):
        nxt = np.empty_like(img)
        texture_level(out[-1], reg, 1 << (k - 1), nxt)
        out.append(nxt)
    return out


def texture_level_reference(prev: np.ndarray, regions: np.ndarray, s: int) -> np.ndarray:
    """Plain numpy reference of :func:`unmesh.render._raster_kernels.texture_level`: level
    ``prev`` (h, w, c) filtered by the taps (1/8, 3/4, 1/8) spaced ``s`` texels, within regions."""
    h, w = prev.shape[:2]
    ri, ci = np.arange(h), np.arange(w)
    acc = np.zeros_like(prev)
    wsum = np.zeros((h, w))
    for dy, wy in _TAPS:
        rows = np.clip(ri + dy * s, 0, h - 1)
        for dx, wx in _TAPS:
            cols = np.clip(ci + dx * s, 0, w - 1)
            wt = wy * wx * (regions[np.ix_(rows, cols)] == regions)
            acc += wt[..., None] * prev[np.ix_(rows, cols)]
            wsum += wt
    return acc / wsum[..., None]


def corner_normals(mesh: TriangleMesh, crease_angle: float = 45.0) -> np.ndarray:
    """Per-corner world normals (F, 3, 3) with a crease angle (smoothing groups).

    Without stored vertex normals, the normal of corner ``(f, k)`` is the area-weighted mean of
    the normals of the faces around its vertex that deviate from face ``f``'s normal by at most
    ``crease_angle`` degrees; so smooth surfaces shade smoothly and boxes keep flat faces.
    Stored vertex normals are used as given, except where they deviate from the face normal by
    more than ``crease_angle`` (then the face normal is used).

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> corner_normals(m)[0, 0].tolist()
    [0.0, 0.0, 1.0]
    """
    faces = mesh.faces
    nf = len(faces)
    fn = mesh.face_normals()
    cos_c = math.cos(math.radians(crease_angle))
    if mesh.vertex_normals is not None:
        vn = mesh.vertex_normals[faces]
        cos = np.einsum("fkj,fj->fk", vn, fn)
        use_face = (cos < cos_c) & (np.linalg.norm(fn, axis=1) > 0)[:, None]
        return np.ascontiguousarray(np.where(use_face[..., None], fn[:, None, :], vn))
    weighted = np.cross(mesh.vertices[faces[:, 1]] - mesh.vertices[faces[:, 0]],
                        mesh.vertices[faces[:, 2]] - mesh.vertices[faces[:, 0]])  # 2 area * normal
    nv = len(mesh.vertices)
    # incident faces of every vertex (CSR)
    vert = faces.reshape(-1)
    order = np.argsort(vert, kind="stable")
    inc_face = (order // 3).astype(np.int64)
    start = np.zeros(nv + 1, dtype=np.int64)
    np.cumsum(np.bincount(vert, minlength=nv), out=start[1:])
    # every (corner, incident face of the corner's vertex) pair
    deg = start[vert + 1] - start[vert]
    corner = np.repeat(np.arange(3 * nf), deg)
    first = np.repeat(start[vert], deg)
    within = np.arange(len(corner)) - np.repeat(np.cumsum(deg) - deg, deg)
    other = inc_face[first + within]
    own = corner // 3
    ok = np.einsum("ij,ij->i", fn[own], fn[other]) >= cos_c - 1e-12
    acc = np.zeros((3 * nf, 3))
    np.add.at(acc, corner[ok], weighted[other[ok]])
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    acc = np.divide(acc, length, out=np.repeat(fn, 3, axis=0), where=length > 0)
    return np.ascontiguousarray(acc.reshape(nf, 3, 3))


def vertex_tangents(mesh: TriangleMesh) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex tangent and bitangent (V,3) each: the area-weighted directions of increasing
    u and v over the adjacent faces (for tangent-space normal maps). Zero without uv.

    Example
    -------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=[[0, 0], [1, 0], [0, 1]])
    >>> t, b = vertex_tangents(m)
    >>> t[0].tolist(), b[0].tolist()
    ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    """
    nv = len(mesh.vertices)
    tan = np.zeros((nv, 3))
    bit = np.zeros((nv, 3))
    if mesh.uv is None or len(mesh.faces) == 0:
        return tan, bit
    v = mesh.vertices[mesh.faces]
    uv = mesh.uv[mesh.faces]
    e1 = v[:, 1] - v[:, 0]
    e2 = v[:, 2] - v[:, 0]
    d1 = uv[:, 1] - uv[:, 0]
    d2 = uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv[:, None]
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv[:, None]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)

    def unit(x: np.ndarray) -> np.ndarray:
        n = np.linalg.norm(x, axis=1, keepdims=True)
        return np.divide(x, n, out=np.zeros_like(x), where=n > 0)

    t = unit(t) * area[:, None]
    b = unit(b) * area[:, None]
    for k in range(3):
        np.add.at(tan, mesh.faces[:, k], t)
        np.add.at(bit, mesh.faces[:, k], b)
    return unit(tan), unit(bit)


def _fingerprint(a: np.ndarray | None) -> tuple[Any, ...]:
    if a is None:
        return ()
    return (id(a), a.shape, float(np.sum(a)), float(np.sum(a[::3, ::5])))


def _levels(image: np.ndarray, regions: np.ndarray | None, texture_filter: str) -> tuple[np.ndarray, np.ndarray]:
    """The levels the tile kernel looks up, as one flat (N, 3) buffer and (L, 3) rows (offset,
    height, width); one level for bilinear lookup. Filtered levels are cached for the textures
    drawn last (by identity and content sums, at most 256 MB), so drawing the same mesh again
    (other views, frames) does not rebuild them."""
    if texture_filter == "bilinear":
        h, w = image.shape[:2]
        return np.ascontiguousarray(image, dtype=np.float64).reshape(-1, 3), np.array([[0, h, w]], np.int64)
    if regions is not None and np.shape(regions) != image.shape[:2]:
        raise InputError(f"texture_regions: expected the texture's shape {image.shape[:2]}, got {np.shape(regions)}")
    key = (_fingerprint(image), _fingerprint(regions))
    hit = _LEVEL_CACHE.pop(key, None)
    if hit is None:
        levels = texture_levels(image, regions)
        dims = np.array([[0, lv.shape[0], lv.shape[1]] for lv in levels], np.int64)
        dims[1:, 0] = np.cumsum(dims[:-1, 1] * dims[:-1, 2])
        hit = (np.concatenate([lv.reshape(-1, 3) for lv in levels]), dims)
    _LEVEL_CACHE[key] = hit
    while sum(v[0].nbytes for v in _LEVEL_CACHE.values()) > _LEVEL_CACHE_BYTES and len(_LEVEL_CACHE) > 1:
        _LEVEL_CACHE.pop(next(iter(_LEVEL_CACHE)))
    return hit


def draw_meshes(gbuffer: GBuffer, meshes: Sequence[TriangleMesh], camera: Camera,
                vertex_colors: Sequence[np.ndarray | None] | None = None, crease_angle: float = 45.0,
                texture_filter: str = "trilinear",
                texture_regions: Sequence[np.ndarray | None] | None = None) -> None:
    """Rasterise triangle meshes into ``gbuffer`` (in place, z-buffered against its depth).

    Parameters
    ----------
    gbuffer : GBuffer
        Updated where a triangle is nearer than the current depth.
    meshes : sequence of TriangleMesh
    camera : Camera
    vertex_colors : sequence of (V, 3) arrays or None, optional
        Colour overrides per mesh (e.g. an attribute through a colormap); otherwise the mesh's
        vertex colours, white under a texture, or the default grey.
    crease_angle : float
        Degrees; see :func:`corner_normals`.
    texture_filter : {"trilinear", "bilinear"}
        ``"trilinear"`` (default): mip-mapped lookup of textures and normal maps, the level
        from the pixel's texel footprint (the longer of its screen-space edges in texels), in
        the filtered levels of :func:`texture_levels`; magnified textures are bilinear either way.
    texture_regions : sequence of (h, w) integer arrays or None, optional
        Per mesh, the region (e.g. atlas patch) of every texel of its texture and normal map:
        the filtered levels never mix two regions.

    Example
    -------
    >>> m = TriangleMesh([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[0, 1, 2]], vertex_colors=[[1, 0, 0]] * 3)
    >>> g = GBuffer.empty(8, 8)
    >>> draw_meshes(g, [m], Camera((0, 0, 3), (0, 0, 0), width=8, height=8, ortho=2.5))
    >>> g.albedo[g.coverage].mean(axis=0).tolist()
    [1.0, 0.0, 0.0]
    """
    h, w = camera.shape
    if gbuffer.depth.shape != (h, w):
        raise InputError(f"gbuffer: expected shape {(h, w)}, got {gbuffer.depth.shape}")
    if texture_filter not in TEXTURE_FILTERS:
        raise InputError(f"texture_filter: expected one of {TEXTURE_FILTERS}, got {texture_filter!r}")
    if texture_regions is not None and len(texture_regions) != len(meshes):
        raise InputError(f"texture_regions: expected one entry per mesh ({len(meshes)}), got {len(texture_regions)}")
    f, cx, cy, ortho, near = camera.kernel_params()
    frame = camera.rotation
    for mi, mesh in enumerate(meshes):
        if not isinstance(mesh, TriangleMesh):
            raise InputError(f"meshes[{mi}]: expected a TriangleMesh, got {type(mesh).__name__}")
        nf = len(mesh.faces)
        if nf == 0:
            continue
        faces = mesh.faces
        override = None if vertex_colors is None else vertex_colors[mi]
        if override is not None:
            vc = np.asarray(override, dtype=np.float64)
        elif mesh.vertex_colors is not None:
            vc = mesh.vertex_colors
        elif mesh.texture is not None and mesh.uv is not None:
            vc = np.ones((len(mesh.vertices), 3))
        else:
            vc = np.tile(np.asarray(DEFAULT_COLOR, dtype=np.float64), (len(mesh.vertices), 1))
        has_tex = mesh.texture is not None and mesh.uv is not None and override is None
        has_nmap = mesh.normal_map is not None and mesh.uv is not None
        corner_uv = np.ascontiguousarray(mesh.uv[faces]) if mesh.uv is not None else np.zeros((1, 3, 2))
        regions = None if texture_regions is None else texture_regions[mi]
        none = (np.zeros((1, 3)), np.array([[0, 1, 1]], np.int64))
        texture, tex_dims = _levels(mesh.texture, regions, texture_filter) if has_tex else none
        nmap, nmap_dims = _levels(mesh.normal_map, regions, texture_filter) if has_nmap else none
        if has_nmap:
            tan, bit = vertex_tangents(mesh)
            ctan = np.ascontiguousarray(tan[faces])
            cbit = np.ascontiguousarray(bit[faces])
        else:
            ctan = cbit = np.zeros((1, 3, 3))
        T = np.empty((nf, 13))
        box = np.empty((nf, 4), dtype=np.int32)
        with serial_if_small(len(box)):
            triangle_setup(mesh.vertices, faces, frame, camera.eye, f, cx, cy, ortho, near, w, h, T, box)
            ntx = (w + _TILE - 1) // _TILE
            nty = (h + _TILE - 1) // _TILE
            offsets, items = bin_boxes(box, np.zeros(nf, dtype=np.int8), 1, _TILE, ntx, nty, 8)
        with serial_if_small(box_visits(box), 20 * SERIAL_BELOW):
            triangle_tiles(T, items, offsets, tile_order(ntx * nty), _TILE, w, h, f, cx, cy, ortho, near,
                           corner_normals(mesh, crease_angle), np.ascontiguousarray(vc[faces]), corner_uv, texture,
                           tex_dims, has_tex, nmap, nmap_dims, has_nmap, ctan, cbit, gbuffer.depth, gbuffer.albedo,
                           gbuffer.normal, gbuffer.coverage, gbuffer.weight)
