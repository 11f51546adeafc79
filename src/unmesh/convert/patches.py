"""Per-triangle texture patches by orthographic EWA splatting with iterative refinement (6.2.1).

For every triangle t the surfels are projected orthogonally onto its plane, its longest edge
along the x axis and the third corner above it (Fig. 6.1 a), and splatted with the renderer's
EWA splatter (:class:`unmesh.render.SplatRenderer`, visibility splatting included). Patch
size follows level ``l >= 1``: ``2**l`` texels along the longest edge, ``2**l - 1`` texel
spacings (:func:`spacings`, ``h_t = L_t / (2**l - 1)``) between the corners on texel centres
(:data:`CORNER_OFFSET`), and the texels around it that a bilinear lookup inside the triangle
reads. Patch widths are powers of two, as the atlas pages' edges are (6.3). Starting at
``l = 1`` the level grows (slivers start at the level whose texel spacing is at most twice their height) until the
error (6.1)

    E_t = sum_s A_s e(C_s, T(x_s, y_s)) / sum_s A_s

over the visible surfels whose centres project into t drops below the threshold, for the
colour (``e`` = RGB distance) and, with normal maps, the normal (``e_N = 1 - N_s . N_t``, 6.2),
or until the texel spacing reaches ``d_min / (2 sqrt 2)`` (d_min: the smallest distance
between two of the triangle's surfels) or ``max_level``. Normalising by the surfel area makes
the threshold independent of the triangle size (a mean colour error).

Batching: all the patches of one level are laid out side by side on *canvases* (orthographic
views of 1024 x 1024 pixels whose world unit is one texel); each triangle's candidate surfels
are transformed into its patch frame (rotation, scale ``1 / h_t``, offset of its slot) and the
whole canvas is splatted with one :meth:`SplatRenderer.render`. Slots are separated by more
than the largest splat, so patches do not see each other's surfels. Candidates of t are the
surfels whose nearest triangle shares a vertex with t and whose normal faces t's side.

Colour and normal patches share the texel layout at the larger of the two levels (one uv set,
as OBJ, glTF viewers and the rasteriser use); each level is recorded. Texels of the patch
footprint no splat reached (Fig. 6.7: the projection does not cover the triangle) take the
colour and normal of the nearest surfel, and the triangles with such texels are counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh.convert._patch_kernels import bilinear, bilinear_reference, candidate_pairs, pair_frames
from unmesh.meshes import TriangleMesh
from unmesh.render import Camera, SplatOptions, SplatRenderer
from unmesh.render.splat import SurfelArrays
from unmesh.spatial import TriangleBVH, knn
from unmesh.surfels import SurfelCloud

__all__ = ["CANVAS", "CORNER_OFFSET", "STALL", "Patches", "TriangleFrames", "render_patches", "spacings",
           "triangle_frames"]

#: Canvas edge (pixels) of the batched patch renders.
CANVAS = 1024
#: Distance (texels) of the triangle's corners from the left and bottom edge of its patch: the
#: corners sit on texel centres, so the outermost texels along the base and at the corners are
#: centred on the triangle's edge and a bilinear lookup inside the triangle never reads the
#: texels beyond them. (Corners on texel boundaries, offset 1, need one more row and column:
#: on Igea at 11,340 triangles 264,288 instead of 208,636 texels, and the wider rims of the
#: footprints pack worse, atlas fill 0.86 instead of 0.93.)
CORNER_OFFSET = 0.5
#: Refinement stalls when an unmet error at level l is above STALL times its value at level
#: l - 1: on Igea (1,690 triangles) 18 triangles' normal errors stayed at 0.007-0.07 from
#: level 4 or 5 on and went to level 7, 117,000 of the atlas' 138,000 texels.
STALL = 0.75
#: Screen filter (texels) of the patch renders: the one-texel disc with which the thresholds,
#: the stall rule and the depth tolerance were measured, kept when the splatter's default went
#: down to ``render.splat.FILTER_RADIUS`` (0.71). With 0.71 the same thresholds stop many
#: patches a level earlier; docs/performance.md ("Igea view 3: the splatter's screen filter at
#: outlines, stop 35") has the figures.
PATCH_FILTER_RADIUS = 1.0


@dataclass(frozen=True)
class TriangleFrames:
    """The patch frame of every triangle (Fig. 6.1 a).

    Attributes
    ----------
    origin : (F, 3) float64
        First corner of the longest edge.
    rotation : (F, 3, 3) float64
        Rows ``(e_x, e_y, n)``: longest edge direction, in-plane normal to it towards the third
        corner, face normal. Local coordinates are ``rotation @ (p - origin)``.
    length : (F,) float64
        Longest edge length L.
    apex : (F, 2) float64
        Local (x, y) of the third corner; ``0 <= x <= L``, ``y > 0``.
    first : (F,) int64
        Which corner k of the face starts the longest edge (corners k, k+1, k+2 map to
        (0, 0), (L, 0), apex).
    """

    origin: np.ndarray
    rotation: np.ndarray
    length: np.ndarray
    apex: np.ndarray
    first: np.ndarray

    def corners_local(self) -> np.ndarray:
        """Local (x, y) of the face corners in the face's own order (F, 3, 2)."""
        nf = len(self.length)
        loc = np.zeros((nf, 3, 2))
        ar = np.arange(nf)
        loc[ar, (self.first + 1) % 3, 0] = self.length
        loc[ar, (self.first + 2) % 3] = self.apex
        return loc


def triangle_frames(mesh: TriangleMesh) -> TriangleFrames:
    """Patch frames of all triangles of ``mesh`` (non-degenerate faces expected)."""
    v = mesh.vertices[mesh.faces]
    edges = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]], axis=1)
    lens = np.linalg.norm(edges, axis=2)
    k = np.argmax(lens, axis=1)
    ar = np.arange(len(k))
    a = v[ar, k]
    ex = edges[ar, k] / lens[ar, k][:, None]
    n = mesh.face_normals()
    ey = np.cross(n, ex)
    rot = np.stack([ex, ey, n], axis=1)
    c = v[ar, (k + 2) % 3] - a
    apex = np.stack([np.einsum("ij,ij->i", c, ex), np.einsum("ij,ij->i", c, ey)], axis=1)
    return TriangleFrames(a, np.ascontiguousarray(rot), lens[ar, k], apex, k.astype(np.int64))


@dataclass
class Patches:
    """The texture patches of all triangles (output of :func:`render_patches`).

    Attributes
    ----------
    level : (F,) int64
        Layout level (>= 1): ``2**level`` texels along the longest edge (:func:`spacings`).
    color_level, normal_level : (F,) int64
        The levels at which each error first dropped below its threshold (or the cap).
    width, height : (F,) int64
        Patch size in texels, borders included.
    color, normal : list of (height, width, 3) float64 arrays
        Colour in [0, 1]; unit normals in the triangle's local frame.
    color_error, normal_error : (F,) float64
        Error (6.1) at the final level.
    capped : (F,) bool
        Refinement stopped by ``d_min / (2 sqrt 2)`` or ``max_level`` instead of the threshold.
    uncovered : (F,) int64
        Footprint texels inside the triangle that no splat reached (filled from the nearest
        surfels).
    samples : (F,) int64
        Surfels whose centres project into the triangle and are visible.
    depth : list of (height, width) float64 arrays or None
        With ``depth=True``: the height of the splatted surface above the triangle's plane
        (world units, along the face normal) at every texel, the depth (displacement) texture
        of 6.2 (:func:`_height_map`: the mean of the splatted depth and the splatted centre
        heights, unbiased on curved surfaces).
    offset : float
        Texels from the patch's left and bottom edge to the triangle's corners
        (:data:`CORNER_OFFSET`; depth textures use the same corners).
    """

    level: np.ndarray
    color_level: np.ndarray
    normal_level: np.ndarray
    width: np.ndarray
    height: np.ndarray
    color: list[np.ndarray]
    normal: list[np.ndarray]
    color_error: np.ndarray
    normal_error: np.ndarray
    capped: np.ndarray
    uncovered: np.ndarray
    samples: np.ndarray
    depth: list[np.ndarray] | None = None
    offset: float = CORNER_OFFSET
    depth_error: np.ndarray | None = None  # (F,) float64 with depth textures: mean |h_s - D| (world)


def spacings(level: np.ndarray | int) -> np.ndarray:
    """Texel spacings along the longest edge at ``level``: ``2**level - 1`` (at least 1), so that
    a patch with its corners on texel centres is ``2**level`` texels wide (a power of two, like
    the atlas pages: a level-7 patch fits a 128 page, where ``2**7 + 1`` texels needed 256).

    Example
    -------
    >>> spacings(np.array([1, 2, 7])).tolist()
    [1.0, 3.0, 127.0]
    """
    return np.maximum(2.0 ** np.asarray(level) - 1.0, 1.0)


def patch_size(frames: TriangleFrames, level: np.ndarray,
               offset: float = CORNER_OFFSET) -> tuple[np.ndarray, np.ndarray]:
    """Patch width and height (texels, borders included) at the given levels.

    With the corners on texel centres (``offset`` 0.5, :data:`CORNER_OFFSET`) the base spans
    ``2**l`` texel centres and the texels a bilinear lookup needs lie in
    ``ceil(apex height) + 1`` rows; with corners on texel boundaries (offset 1) one more each."""
    n = spacings(level)
    h = frames.length / n
    hy = np.ceil(frames.apex[:, 1] / h - 1e-9).astype(np.int64)
    extra = round(2 * offset)
    return (n.astype(np.int64) + extra, np.maximum(hy, 1) + extra)


def _layout(widths: np.ndarray, heights: np.ndarray, gap: int,
            edge: int = CANVAS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shelf layout of rectangles on canvases of ``edge`` x ``edge``: (canvas, x, y) per rectangle.

    A rectangle wider or taller than the canvas (with its gaps) gets a canvas of its own; no
    canvas stays empty.
    """
    order = np.lexsort((-widths, -heights))
    canvas = np.zeros(len(widths), np.int64)
    xs = np.zeros(len(widths), np.int64)
    ys = np.zeros(len(widths), np.int64)
    c = x = y = shelf = 0
    for i in order:
        w, h = int(widths[i]) + gap, int(heights[i]) + gap
        if x + w > edge and x > 0:
            x, y, shelf = 0, y + shelf, 0
        if y + h > edge and y > 0:
            c, x, y, shelf = c + 1, 0, 0, 0
        canvas[i], xs[i], ys[i] = c, x + gap, y + gap
        x += w
        shelf = max(shelf, h)
    return canvas, xs, ys


def render_patches(mesh: TriangleMesh, cloud: SurfelCloud, *, texture_error: float, normal_error: float | None,
                   max_level: int, progress: bool = False, depth: bool = False,
                   depth_error: float | None = None) -> Patches:
    """Adaptive texture patches of every triangle of ``mesh`` from the surfels (6.2.1).

    Parameters
    ----------
    mesh : TriangleMesh
        Non-degenerate triangles, outward.
    cloud : SurfelCloud
        The surfels (colours and normals are baked).
    texture_error : float
        Colour threshold of the error (6.1) (mean RGB distance).
    normal_error : float or None
        Normal threshold (mean ``1 - N_s . N_t``, eq. 6.2); None: no normal refinement.
    max_level : int
        Largest level.
    progress : bool
        Progress bar over the levels.
    depth : bool
        Also keep the depth (displacement) texture of every patch (``Patches.depth``).
    depth_error : float, optional
        With ``depth``: threshold of the depth error, the mean ``|h_s - D(x_s, y_s)|`` (world
        units) between the surfels' heights above the plane and the bilinear depth texture;
        the patch is refined until it holds as well (None: no depth refinement).
    """
    frames = triangle_frames(mesh)
    offset = CORNER_OFFSET
    nf = len(mesh.faces)
    _, nearest, _, _ = TriangleBVH(mesh.vertices, mesh.faces).closest(cloud.positions)
    pt, ps = candidate_pairs(mesh.faces, len(mesh.vertices), nearest, cloud.normals, frames.rotation[:, 2])
    loc = np.empty((len(pt), 3))
    lnrm = np.empty((len(pt), 3))
    pair_frames(pt, ps, frames.origin, frames.rotation, cloud.positions, cloud.normals, loc, lnrm)
    pt, ps, loc, lnrm = _depth_band(pt, ps, loc, lnrm, nearest, np.asarray(cloud.radii), nf)
    laxes = np.einsum("pij,pkj->pki", frames.rotation[pt], cloud.axes[ps]) if cloud.is_elliptical else None
    radii = np.asarray(cloud.radii)[ps]
    area = np.pi * (np.prod(np.linalg.norm(cloud.axes[ps], axis=2), axis=1) if cloud.is_elliptical else radii**2)
    colors = cloud.colors[ps]
    # inside the triangle (for the error sums) and d_min per triangle (6.2.1)
    length = frames.length[pt]
    ax, ay = frames.apex[pt, 0], frames.apex[pt, 1]
    x, y = loc[:, 0], loc[:, 1]
    inside = (y >= 0) & (ax * y - ay * x <= 0) & ((length - ax) * y + ay * (x - length) <= 0)
    # triangles without a surfel centre inside (slivers) measure the error at the surfels whose
    # disc reaches them (the distance to each edge line is at most the radius); otherwise their
    # error is zero at any level and bleeding from their neighbours goes unnoticed
    d_edge = np.minimum(np.minimum(y, (ay * x - ax * y) / np.hypot(ax, ay)),
                        -((length - ax) * y + ay * (x - length)) / np.hypot(length - ax, ay))
    has_inside = np.bincount(pt[inside], minlength=nf) > 0
    inside = inside | ((d_edge >= -radii) & ~has_inside[pt])
    nn_d, _ = knn(cloud.positions, 2)
    dmin = np.full(nf, np.inf)
    near_t = inside | ((x > -radii) & (x < length + radii) & (y > -radii) & (y < ay + radii))
    np.minimum.at(dmin, pt[near_t], nn_d[ps[near_t], 1])
    spacing_cap = dmin / (2.0 * np.sqrt(2.0))
    n_in = np.bincount(pt[inside], minlength=nf)
    mean_radius = np.bincount(pt[inside], weights=radii[inside], minlength=nf) / np.maximum(n_in, 1)
    mean_radius[n_in == 0] = float(np.median(radii)) if len(radii) else 0.0

    level = np.zeros(nf, np.int64)
    color_level = np.full(nf, -1, np.int64)
    normal_level = np.full(nf, -1 if normal_error is not None else 0, np.int64)
    done = np.zeros(nf, bool)
    capped = np.zeros(nf, bool)
    c_err = np.zeros(nf)
    prev_c = np.full(nf, np.inf)  # errors at the previous level (stall test)
    prev_n = np.full(nf, np.inf)
    prev_d = np.full(nf, np.inf)
    d_err = np.zeros(nf)
    depth_tol = depth_error if (depth and depth_error is not None) else np.inf
    n_err = np.zeros(nf)
    samples = np.zeros(nf, np.int64)
    out_color: list[np.ndarray | None] = [None] * nf
    out_normal: list[np.ndarray | None] = [None] * nf
    out_cov: list[np.ndarray | None] = [None] * nf
    out_depth: list[np.ndarray | None] | None = [None] * nf if depth else None
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=nf, desc="texture patches", unit="tri", leave=False)
    # slivers start finer: the texel spacing never exceeds twice the triangle's height, so the
    # texels a lookup inside the triangle reads lie close to it
    # (2**l - 1 >= L / (2 height)); levels start at 1 (two texels along the base)
    start = np.clip(np.ceil(np.log2(1.0 + frames.length / np.maximum(2.0 * frames.apex[:, 1], 1e-300)) - 1e-9), 1,
                    max_level).astype(np.int64)
    for lvl in range(max_level + 1):
        active = np.flatnonzero(~done & (start <= lvl))
        if not len(active):
            if done.all():
                break
            continue
        level[active] = lvl
        width, height = patch_size(frames, level, offset)
        scale = spacings(lvl) / frames.length  # texels per unit
        is_active = np.zeros(nf, bool)
        is_active[active] = True
        live = np.flatnonzero(is_active[pt])  # pairs of the triangles rendered at this level
        s_l = scale[pt[live]]
        px_l = offset + x[live] * s_l
        py_l = offset + y[live] * s_l
        w_l, h_l = width[pt[live]], height[pt[live]]
        # splat radii in texels, at most twice the patch size: a larger splat is constant over
        # the patch anyway, and the canvas gaps (which follow the largest splat) stay bounded
        r_l = np.minimum(radii[live] * s_l, 2.0 * np.maximum(w_l, h_l) + 2.0)
        keep = (px_l > -r_l - 1) & (px_l < w_l + r_l + 1) & (py_l > -r_l - 1) & (py_l < h_l + r_l + 1)
        sel = live[keep]
        s_p, px_s, py_s, r_s = s_l[keep], px_l[keep], py_l[keep], r_l[keep]
        gap = int(np.ceil(r_s.max())) + 3 if len(sel) else 3
        edge = max(CANVAS, int(width[active].max()) + 2 * gap, int(height[active].max()) + 2 * gap)
        canvas, ox, oy = _layout(width[active], height[active], gap, edge)
        slot_c = np.zeros(nf, np.int64)
        slot_x = np.zeros(nf, np.int64)
        slot_y = np.zeros(nf, np.int64)
        slot_c[active], slot_x[active], slot_y[active] = canvas, ox, oy
        sums = np.zeros((nf, 4))  # sum A, sum A e_color, sum A e_normal, sum A e_depth
        pair_canvas = slot_c[pt[sel]]
        by_canvas = np.argsort(pair_canvas, kind="stable")
        canvas_start = np.searchsorted(pair_canvas[by_canvas], np.arange(int(canvas.max()) + 2))
        for c in range(int(canvas.max()) + 1):
            tri_c = active[canvas == c]
            kk = by_canvas[canvas_start[c]:canvas_start[c + 1]]
            idx = sel[kk]
            t_i = pt[idx]
            sc = s_p[kk]
            r_c = r_s[kk]
            col = slot_x[t_i] + px_s[kk]
            row = slot_y[t_i] + height[t_i] - py_s[kk]
            z = loc[idx, 2] * sc
            zeye = float(z.max()) + 10.0 if len(z) else 10.0
            cw = int((slot_x[tri_c] + width[tri_c]).max() + gap)
            ch = int((slot_y[tri_c] + height[tri_c]).max() + gap)
            cam = Camera((cw / 2, -ch / 2, zeye), (cw / 2, -ch / 2, zeye - 1.0), width=cw, height=ch, ortho=float(ch))
            pos = np.ascontiguousarray(np.stack([col, -row, z], axis=1))
            arr = SurfelArrays(pos, np.ascontiguousarray(lnrm[idx]), np.ascontiguousarray(r_c),
                               None if laxes is None else np.ascontiguousarray(laxes[idx] * sc[:, None, None]),
                               np.ascontiguousarray(colors[idx]))
            # depth tolerance of at least two texels: under minification the screen filter spreads
            # every splat over a texel, and tilted surfels then reach a texel or more in front of
            # their neighbours (their depth range grows with the filter footprint); a tolerance of
            # one radius would let them hide the surface behind them
            tol = max(1.0, 2.0 / float(np.median(r_c))) if len(r_c) else 1.0
            rend = SplatRenderer(cam, SplatOptions(filter_radius=PATCH_FILTER_RADIUS, depth_tolerance=tol))
            g = rend.render(arr).gbuffer()
            hmap = _height_map(cam, arr, tol, g, zeye, z) if out_depth is not None else None
            # error (6.1) at the visible surfels inside their triangle
            ins = inside[idx]
            ri = np.clip(row.astype(np.int64), 0, ch - 1)
            ci = np.clip(col.astype(np.int64), 0, cw - 1)
            # visible: not behind the pixel's depth by more than the splatter's tolerance plus one
            # texel (a coarse pixel averages depths over a curved region of the triangle)
            vis = ins & ((zeye - z) <= g.depth[ri, ci] + r_c * rend.options.depth_tolerance + 1.0)
            q = np.flatnonzero(vis)
            if len(q):
                tc = np.empty((len(q), 3))
                bilinear(g.albedo, col[q], row[q], tc)
                e_c = np.linalg.norm(colors[idx[q]] - tc, axis=1)
                tn = np.empty((len(q), 3))
                bilinear(g.normal, col[q], row[q], tn)
                tn /= np.maximum(np.linalg.norm(tn, axis=1, keepdims=True), 1e-12)
                e_n = 1.0 - np.einsum("ij,ij->i", tn, lnrm[idx[q]])
                a = area[idx[q]]
                e_d = np.zeros(len(q))
                if hmap is not None:
                    e_d = np.abs(z[q] - bilinear_reference(hmap[..., None], col[q], row[q])[:, 0]) / sc[q]
                for j, wgt in enumerate((a, a * e_c, a * e_n, a * e_d)):
                    sums[:, j] += np.bincount(t_i[q], weights=wgt, minlength=nf)
            # extract the patches of the triangles that stop here
            with np.errstate(invalid="ignore", divide="ignore"):
                ec = np.where(sums[tri_c, 0] > 0, sums[tri_c, 1] / sums[tri_c, 0], 0.0)
                en = np.where(sums[tri_c, 0] > 0, sums[tri_c, 2] / sums[tri_c, 0], 0.0)
                ed = np.where(sums[tri_c, 0] > 0, sums[tri_c, 3] / sums[tri_c, 0], 0.0)
            c_err[tri_c], n_err[tri_c], d_err[tri_c] = ec, en, ed
            samples[tri_c] = np.bincount(t_i[q], minlength=nf)[tri_c] if len(q) else 0
            ok_c = ec <= texture_error
            ok_n = en <= normal_error if normal_error is not None else np.ones(len(tri_c), bool)
            ok_d = ed <= depth_tol  # the depth texture shares the layout with colour and normals
            first_c = ok_c & (color_level[tri_c] < 0)
            color_level[tri_c[first_c]] = lvl
            first_n = ok_n & (normal_level[tri_c] < 0)
            normal_level[tri_c[first_n]] = lvl
            cap = (lvl >= max_level) | (frames.length[tri_c] / spacings(lvl) <= spacing_cap[tri_c])
            # stalled (an extension): once the texels are no larger than the triangle's surfels,
            # an unmet error that fell by less than STALL since the previous level has reached
            # what the surfels resolve (occluded samples, a crease the splatted field blurs);
            # refining further only spends texels (at coarser levels errors may stall and fall)
            fine = frames.length[tri_c] / spacings(lvl) <= mean_radius[tri_c]
            stall_c = ok_c | (ec > STALL * prev_c[tri_c])
            stall_n = ok_n | (en > STALL * prev_n[tri_c])
            stall_d = ok_d | (ed > STALL * prev_d[tri_c])
            prev_c[tri_c], prev_n[tri_c], prev_d[tri_c] = ec, en, ed
            met = ok_c & ok_n & ok_d
            stop = met | cap | (fine & stall_c & stall_n & stall_d)
            capped[tri_c[stop & ~met]] = True
            for t in tri_c[stop]:
                r0, c0 = slot_y[t], slot_x[t]
                sl = (slice(r0, r0 + height[t]), slice(c0, c0 + width[t]))
                out_color[t] = g.albedo[sl].copy()
                out_normal[t] = g.normal[sl].copy()
                out_cov[t] = g.coverage[sl].copy()
                if out_depth is not None and hmap is not None:  # texel units -> world
                    out_depth[t] = hmap[sl] / scale[t]
            done[tri_c[stop]] = True
            if bar is not None:
                bar.update(int(stop.sum()))
    if bar is not None:
        bar.close()
    color_level[color_level < 0] = level[color_level < 0]
    normal_level[normal_level < 0] = level[normal_level < 0]
    width, height = patch_size(frames, level, offset)
    uncovered = _fill_uncovered(mesh, cloud, frames, level, offset, width, height, out_color, out_normal, out_cov,
                                out_depth)
    return Patches(level, color_level, normal_level, width, height, out_color, out_normal,  # type: ignore[arg-type]
                   c_err, n_err, capped, uncovered, samples, out_depth, offset,  # type: ignore[arg-type]
                   d_err if depth else None)


def _height_map(cam: Camera, arr: SurfelArrays, tol: float, g, zeye: float, z: np.ndarray) -> np.ndarray:
    """Height above the patch plane (texel units) of every canvas pixel, unbiased on curved surfaces.

    The splatted depth extrapolates every surfel's tangent plane over its footprint (a texel or
    more at coarse levels, where the screen filter dominates): on a convex surface the planes
    lie above it and the depth is biased upwards by ~ kappa sigma^2 / 2 (kappa: curvature,
    sigma^2: second moment of the footprint); the weighted mean of the surfels' *centre*
    heights with the same weights is biased down by as much (z(x) = a + b x - kappa x^2 / 2:
    E[z_s + z'_s (p - x_s)] = z(p) + kappa sigma^2 / 2, E[z_s] = z(p) - kappa sigma^2 / 2).
    Their mean is exact for a locally quadratic surface. The centre heights are splatted as a
    colour (mapped into [0, 1], which the splatter clamps to). Pixels no splat reached: 0.
    """
    z0, zr = float(z.min()), max(float(np.ptp(z)), 1e-12)
    hz = np.ascontiguousarray(np.repeat(((z - z0) / zr)[:, None], 3, axis=1))
    g_h = SplatRenderer(cam, SplatOptions(filter_radius=PATCH_FILTER_RADIUS, depth_tolerance=tol)).render(
        SurfelArrays(arr.positions, arr.normals, arr.radii, arr.axes, hz)).gbuffer()
    centre = z0 + zr * g_h.albedo[..., 0]
    return np.where(g.coverage, 0.5 * ((zeye - np.where(g.coverage, g.depth, zeye)) + centre), 0.0)


def _depth_band(pt: np.ndarray, ps: np.ndarray, loc: np.ndarray, lnrm: np.ndarray, nearest: np.ndarray,
                radii: np.ndarray, nf: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop the pairs whose surfel lies farther from the triangle's plane than the band of its own surfels.

    The band of t is twice the largest ``|z| + r`` of the surfels whose nearest triangle is t
    (at least the median radius). Without it, neighbouring surface that rises above the
    plane (a concave region, the far side of a ridge) occludes the triangle's own surfels at
    coarse levels, where the splatter's one-texel filter spreads it over the whole patch.
    """
    own = nearest[ps] == pt
    band = np.zeros(nf)
    np.maximum.at(band, pt[own], np.abs(loc[own, 2]) + radii[ps[own]])
    band = 2.0 * np.maximum(band, float(np.median(radii)))
    keep = np.abs(loc[:, 2]) <= band[pt]
    return pt[keep], ps[keep], loc[keep], lnrm[keep]


def texel_positions(frames: TriangleFrames, t: np.ndarray, level: np.ndarray, height: np.ndarray,
                    rows: np.ndarray, cols: np.ndarray,
                    offset: float = CORNER_OFFSET) -> tuple[np.ndarray, np.ndarray]:
    """Local (x, y) (N, 2) and world positions (N, 3) of texel centres ``(rows, cols)`` of patches ``t``."""
    h = frames.length[t] / spacings(level[t])
    lx = (cols + 0.5 - offset) * h
    ly = (height[t] - offset - (rows + 0.5)) * h
    world = frames.origin[t] + lx[:, None] * frames.rotation[t, 0] + ly[:, None] * frames.rotation[t, 1]
    return np.stack([lx, ly], axis=1), world


def _fill_uncovered(mesh: TriangleMesh, cloud: SurfelCloud, frames: TriangleFrames, level: np.ndarray, offset: float,
                    width: np.ndarray, height: np.ndarray, colors: list, normals: list, cov: list,
                    depths: list | None = None) -> np.ndarray:
    """Give texels no splat reached the nearest surfel's colour, normal (and height above the
    plane); count those inside."""
    nf = len(level)
    tt, rr, cc = [], [], []
    for t in range(nf):
        r, c = np.nonzero(~cov[t])
        if len(r):
            tt.append(np.full(len(r), t))
            rr.append(r)
            cc.append(c)
    uncovered = np.zeros(nf, np.int64)
    if not tt:
        return uncovered
    t_all = np.concatenate(tt)
    r_all = np.concatenate(rr)
    c_all = np.concatenate(cc)
    lxy, world = texel_positions(frames, t_all, level, height, r_all, c_all, offset)
    _, idx = knn(cloud.positions, 1, queries=world)
    j = idx[:, 0]
    col = cloud.colors[j]
    nrm = np.einsum("pij,pj->pi", frames.rotation[t_all], cloud.normals[j])
    hgt = np.einsum("pj,pj->p", frames.rotation[t_all, 2], cloud.positions[j] - frames.origin[t_all])
    ax, ay, length = frames.apex[t_all, 0], frames.apex[t_all, 1], frames.length[t_all]
    x, y = lxy[:, 0], lxy[:, 1]
    inside = (y >= 0) & (ax * y - ay * x <= 0) & ((length - ax) * y + ay * (x - length) <= 0)
    np.add.at(uncovered, t_all[inside], 1)
    starts = np.concatenate([[0], np.cumsum([len(a) for a in tt])])
    for k in range(len(tt)):
        s, e = starts[k], starts[k + 1]
        t = int(t_all[s])
        colors[t][r_all[s:e], c_all[s:e]] = col[s:e]
        normals[t][r_all[s:e], c_all[s:e]] = nrm[s:e]
        if depths is not None:
            depths[t][r_all[s:e], c_all[s:e]] = hgt[s:e]
    return uncovered
