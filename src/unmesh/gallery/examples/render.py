"""Gallery examples of the renderer (thesis 3.1.3, 3.2, 5.7).

``render-surfels``: a surfel sphere and torus, EWA-splatted, plus a close-up of the splats.
``render-zoom``: the bunny-like blob from far away (minified: with and without the EWA
prefilter, against a supersampled reference), at normal size, and magnified 8x (no holes).
``render-splat-vs-raycast``: EWA splatting and MLS ray casting of the same object and their
difference. ``render-partial-update``: a paint stroke applied by unsplatting and splatting only
the changed surfels (5.7), compared with full re-renders. ``render-mixed``: surfels, a textured
mesh and particles coloured by an attribute in one scene, and a turntable.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from unmesh.gallery.registry import ExampleContext, example

__all__ = ["checker_texture", "hole_fraction", "supersampled"]


def _rainbow(cloud: Any, scale: float = 3.0) -> Any:
    p = cloud.positions
    col = 0.5 + 0.45 * np.stack([np.sin(scale * p[:, 0] + 0.3), np.sin(scale * p[:, 1] + 2.0),
                                 np.sin(scale * p[:, 2] + 4.0)], axis=1)
    return cloud.replace(colors=np.clip(col, 0, 1))


def checker_texture(n: int = 8, size: int = 256) -> np.ndarray:
    """An ``n x n`` checkerboard texture (size, size, 3) with a red bottom-left square
    (shows the uv orientation: (0, 0) is the bottom-left)."""
    idx = (np.arange(size) * n // size)
    board = (idx[:, None] + idx[None, :]) % 2
    img = np.where(board[..., None] == 1, [0.92, 0.92, 0.88], [0.25, 0.3, 0.45])
    cell = size // n
    img[size - cell:, :cell] = [0.85, 0.15, 0.1]
    return img


def supersampled(objects: Any, camera: Any, factor: int = 8, **options: Any) -> tuple[np.ndarray, np.ndarray]:
    """A reference image: render at ``factor`` times the size and box-filter down.

    Returns the colour (H, W, 3) and the covered fraction of each pixel (H, W).
    """
    from unmesh.render import render

    big = render(objects, camera.resized(camera.width * factor, camera.height * factor), **options)
    h, w = camera.shape
    color = big.color.reshape(h, factor, w, factor, 3).mean(axis=(1, 3))
    return color, big.coverage.reshape(h, factor, w, factor).mean(axis=(1, 3))


def hole_fraction(coverage: np.ndarray) -> float:
    """Fraction of uncovered pixels surrounded by covered ones (holes in the surface): pixels
    not covered whose 4 neighbours at distance 3 in each axis direction are all covered."""
    c = coverage
    inner = np.zeros_like(c)
    inner[3:-3, 3:-3] = ~c[3:-3, 3:-3] & c[:-6, 3:-3] & c[6:, 3:-3] & c[3:-3, :-6] & c[3:-3, 6:]
    return float(inner.sum() / max(1, c.sum()))


@example("render-surfels", "EWA splatting of surfel spheres and tori", section="Rendering")
def surfels_example(ctx: ExampleContext) -> None:
    """EWA surface splatting (3.2): perspective-correct elliptical Gaussian splats, extended
    depth test, per-pixel normals and deferred Phong shading. Right: a close-up where the
    individual splats are larger than a pixel; they blend into a smooth surface."""
    from scipy.ndimage import distance_transform_edt

    from unmesh.render import Camera, render, save_image, scene_points
    from unmesh.shapes import Sphere, Torus

    spacing = 0.08 if ctx.quick else 0.02
    size = (320, 200) if ctx.quick else (960, 600)
    sphere = _rainbow(Sphere(center=(-1.3, 0.0, 0.0), radius=0.9).surfels(spacing))
    torus = Torus(center=(1.1, 0.0, 0.0), major=0.8, minor=0.3, axis=(0.3, 1.0, 0.2)).surfels(spacing,
                                                                                           color=(0.85, 0.55, 0.2))
    cam = Camera.fit(scene_points([sphere, torus]), *size, fov=35)
    render([sphere, torus], cam.resized(16, 16))  # load the compiled kernels before timing
    t0 = time.perf_counter()
    res = render([sphere, torus], cam)
    dt = time.perf_counter() - t0
    res = render([sphere, torus], cam, supersample=2)  # anti-aliased silhouettes for the picture
    path = save_image(ctx.path("sphere_torus.png"), res.color)
    ctx.image(path, f"{len(sphere) + len(torus)} surfels, EWA splatting with Phong shading")
    # close-up: aim at the torus pixel farthest from its silhouette, zoom until splats are ~15 px
    only = render(torus, cam)
    inside = distance_transform_edt(only.coverage)
    r0, c0 = np.unravel_index(int(np.argmax(inside)), inside.shape)
    o, d = cam.rays()
    hit = o[r0, c0] + only.depth[r0, c0] / (d[r0, c0] @ cam.forward) * d[r0, c0]
    splat_px = float(np.median(torus.radii)) * cam.pixels_per_unit / only.depth[r0, c0]
    close = cam.replace(target=hit, eye=hit + (cam.eye - cam.target), width=size[0] // 2).zoomed(max(1.0, 15.0 / splat_px))
    rc = render([sphere, torus], close)
    path = save_image(ctx.path("closeup.png"), rc.color)
    ctx.image(path, "close-up of the torus: splats larger than pixels blend smoothly")
    ctx.metric("surfels", len(sphere) + len(torus))
    ctx.metric("render time", round(dt, 3), "s")
    ctx.metric("holes in close-up", hole_fraction(rc.coverage))


@example("render-zoom", "Minified, normal and magnified: prefiltered colours, no holes", section="Rendering")
def zoom_example(ctx: ExampleContext) -> None:
    """The bunny-like blob at three zoom levels. Minified (many surfels per pixel), the EWA
    screen-space prefilter averages the surfels that fall into a pixel; without it (point
    sampling of the reconstruction kernels) the colours alias. The prefilter does not anti-alias
    the silhouette (each pixel is covered or not); the fourth panel adds 2x2 supersampling, which
    does. Errors are RMS colour differences
    against an 8x supersampled reference over the pixels it covers fully. Magnified 8x, the surfels' reconstruction kernels still cover the
    surface without holes."""
    from unmesh.render import Camera, SplatOptions, render, save_image, scene_points
    from unmesh.shapes import Blob

    spacing = 0.03 if ctx.quick else 0.008
    blob = Blob().surfels(spacing)
    rng = np.random.default_rng(1)
    # high-frequency colour: random per surfel, so minification must average
    col = np.where((rng.random(len(blob)) < 0.5)[:, None], [0.9, 0.3, 0.2], [0.2, 0.4, 0.9])
    blob = blob.replace(colors=col)
    base = Camera.fit(scene_points(blob), 360 if not ctx.quick else 160, 300 if not ctx.quick else 130, fov=30)
    small = base.resized(48, 40)
    ref, frac = supersampled(blob, small, 8 if not ctx.quick else 4, shading="none")
    ewa = render(blob, small, shading="none")
    point = render(blob, small, shading="none", splat=SplatOptions(filter_radius=0.0))
    smooth_edge = render(blob, small, shading="none", supersample=2)
    interior = frac == 1.0  # compare colours where the reference pixel is fully covered
    err_ewa = float(np.sqrt(np.mean((ewa.color - ref)[interior] ** 2)))
    err_point = float(np.sqrt(np.mean((point.color - ref)[interior] ** 2)))

    def big(img: np.ndarray, k: int = 6) -> np.ndarray:
        return np.repeat(np.repeat(img, k, axis=0), k, axis=1)

    gap = np.ones((240, 6, 3))
    strip = np.concatenate([big(ref), gap, big(ewa.color), gap, big(point.color), gap, big(smooth_edge.color)], axis=1)
    path = save_image(ctx.path("minified.png"), strip)
    ctx.image(path, "minified to 48x40 (shown 6x): supersampled reference | EWA prefilter (colours averaged, "
                    "silhouette stair-stepped) | no prefilter (colours alias) | EWA prefilter + 2x2 supersampling "
                    "(silhouette anti-aliased too)")
    smooth = _rainbow(blob, 5.0)
    normal = render(smooth, base)
    path = save_image(ctx.path("normal.png"), normal.color)
    ctx.image(path, f"{len(blob)} surfels at normal size")
    # magnify 8x around the covered pixel farthest from the silhouette
    from scipy.ndimage import distance_transform_edt

    inside = distance_transform_edt(normal.coverage)
    r0, c0 = np.unravel_index(int(np.argmax(inside)), inside.shape)
    o, d = base.rays()
    hit = o[r0, c0] + normal.depth[r0, c0] / (d[r0, c0] @ base.forward) * d[r0, c0]
    mag = base.replace(target=hit, eye=hit + (base.eye - base.target)).zoomed(8.0)
    m = render(smooth, mag)
    path = save_image(ctx.path("magnified.png"), m.color)
    ctx.image(path, "magnified 8x: no holes between the splats")
    ctx.metric("surfels", len(blob))
    ctx.metric("minified RMS error, EWA prefilter", round(err_ewa, 4))
    ctx.metric("minified RMS error, no prefilter", round(err_point, 4))
    ctx.metric("uncovered pixels when magnified 8x", int((~m.coverage).sum()))
    ctx.metric("holes when magnified 8x", hole_fraction(m.coverage))


@example("render-splat-vs-raycast", "EWA splatting vs MLS ray casting", section="Rendering")
def splat_vs_raycast_example(ctx: ExampleContext) -> None:
    """The same surfel cloud splatted (3.2) and ray-cast as an MLS surface (3.1.3, Algorithm
    3.1), with the same camera, shading and buffers. The difference image (x4) shows where the
    two reconstructions differ: at silhouettes (splats are tangent discs) and in the
    interpolation of colour."""
    from unmesh.render import Camera, render, save_image, scene_points
    from unmesh.shapes import Blob

    spacing = 0.04 if ctx.quick else 0.015
    blob = _rainbow(Blob().surfels(spacing), 4.0)
    cam = Camera.fit(scene_points(blob), *((160, 130) if ctx.quick else (420, 340)), fov=30)
    render(blob, cam.resized(16, 16))  # load the compiled kernels before timing
    t0 = time.perf_counter()
    a = render(blob, cam)
    ta = time.perf_counter() - t0
    b, tb = ctx.timed(render, blob, cam, method="raycast", progress=ctx.progress,
                      warm=lambda: render(blob, cam.resized(16, 16), method="raycast", progress=False))
    both = a.coverage & b.coverage
    diff = np.where(both[..., None], np.clip(4 * np.abs(a.color - b.color), 0, 1), 0.0)
    path = save_image(ctx.path("splat_raycast.png"), np.concatenate([a.color, b.color, diff], axis=1))
    ctx.image(path, "EWA splatting | MLS ray casting | |difference| x4")
    ctx.metric("surfels", len(blob))
    ctx.metric("mean absolute colour difference", round(float(np.abs(a.color - b.color)[both].mean()), 4))
    ctx.metric("silhouette IoU", round(float(both.sum() / (a.coverage | b.coverage).sum()), 4))
    ctx.metric("splatting time", round(ta, 3), "s")
    ctx.metric("ray casting time", round(tb, 3), "s")


@example("render-partial-update", "Partial updates: painting without redrawing", section="Rendering")
def partial_update_example(ctx: ExampleContext) -> None:
    """Section 5.7: the renderer keeps the unnormalised sums, so a paint stroke is shown by
    unsplatting the old and splatting the recoloured surfels only. Each frame is compared with a
    full re-render; the difference stays at round-off because recolouring never changes the
    depth buffer."""
    from unmesh.render import Camera, SplatRenderer, scene_bounds, shade, write_video
    from unmesh.shapes import Blob

    spacing = 0.03 if ctx.quick else 0.01
    blob = Blob().surfels(spacing, color=(0.85, 0.82, 0.75))
    cam = Camera.framing(scene_bounds(blob), *((160, 130) if ctx.quick else (400, 330)), fov=30)
    renderer = SplatRenderer(cam).render(blob)
    colors = np.asarray(blob.colors).copy()
    steps = 8 if ctx.quick else 40
    b = scene_bounds(blob)
    path_pts = [b[0] + (b[1] - b[0]) * np.array([0.2 + 0.6 * t, 0.45 + 0.25 * np.sin(6 * t), 0.5]) for t in np.linspace(0, 1, steps)]
    brush = 0.12 * float(np.linalg.norm(b[1] - b[0]))
    warm = blob.subset(np.arange(min(len(blob), 50)))  # compile unsplat/splat/gbuffer before timing
    SplatRenderer(cam.resized(16, 16)).render(blob).unsplat(warm).splat(warm).gbuffer()
    frames = []
    max_diff = 0.0
    t_partial = 0.0
    t_full = 0.0
    updated = 0
    for k, centre in enumerate(path_pts):
        hit = np.linalg.norm(blob.positions - centre, axis=1) < brush
        paint = np.array([0.8, 0.15 + 0.5 * k / steps, 0.2])
        change = np.flatnonzero(hit & np.any(colors != paint, axis=1))
        if len(change) == 0:
            continue
        old = blob.subset(change).replace(colors=colors[change])
        colors[change] = paint
        new = blob.subset(change).replace(colors=colors[change])
        t0 = time.perf_counter()
        renderer.unsplat(old).splat(new)
        g = renderer.gbuffer()
        t_partial += time.perf_counter() - t0
        updated += len(change)
        frames.append(shade(g, cam))
        t0 = time.perf_counter()
        full = SplatRenderer(cam).render(blob.replace(colors=colors)).gbuffer()
        t_full += time.perf_counter() - t0
        max_diff = max(max_diff, float(np.abs(full.albedo - g.albedo).max()))
    path = write_video(frames, ctx.path("painting.gif"), fps=10)
    ctx.image(path, "a paint stroke, each frame a partial update")
    ctx.metric("frames", len(frames))
    ctx.metric("surfels updated per frame (mean)", round(updated / max(1, len(frames)), 1))
    ctx.metric("partial update time per frame", round(t_partial / max(1, len(frames)), 4), "s")
    ctx.metric("full re-render time per frame", round(t_full / max(1, len(frames)), 4), "s")
    ctx.metric("max |partial - full| colour", f"{max_diff:.2e}")


@example("render-mixed", "Surfels, textured meshes and particles in one scene", section="Rendering")
def mixed_example(ctx: ExampleContext) -> None:
    """One renderer for every primitive: a splatted surfel torus, a textured ground mesh (uv
    (0, 0) at the red square) rasterised with a z-buffer, and particles drawn as shaded spheres
    coloured by an attribute through a colormap with a legend; plus a turntable."""
    from unmesh import Particles, TriangleMesh
    from unmesh.render import Camera, render, save_image, turntable

    spacing = 0.06 if ctx.quick else 0.02
    from unmesh.shapes import Torus

    torus = Torus(center=(0.0, 0.45, 0.0), major=0.7, minor=0.25, axis=(0.0, 0.3, 1.0)).surfels(spacing, color=(0.8, 0.8, 0.82))
    ground = TriangleMesh([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], [[0, 2, 1], [0, 3, 2]],
                          uv=[[0, 1], [1, 1], [1, 0], [0, 0]], texture=checker_texture())
    rng = np.random.default_rng(2)
    n = 300 if ctx.quick else 1500
    ang = rng.uniform(0, 2 * np.pi, n)
    rad = rng.uniform(1.1, 1.7, n)
    pos = np.stack([rad * np.cos(ang), rng.uniform(0.05, 0.6, n), rad * np.sin(ang)], axis=1)
    speed = np.hypot(pos[:, 0], pos[:, 2]) * (1 + pos[:, 1])
    drops = Particles(pos, radii=np.full(n, 0.035), attributes={"speed": speed})
    size = (320, 220) if ctx.quick else (800, 540)
    cam = Camera((2.6, 2.0, 3.4), (0.0, 0.3, 0.0), width=size[0], height=size[1], fov=40)
    res = render([torus, ground, drops], cam, color_by="speed", colormap="plasma", supersample=2)
    path = save_image(ctx.path("mixed.png"), res.color)
    ctx.image(path, "surfels + textured mesh + particles coloured by speed")
    frames = 12 if ctx.quick else 72
    tt = turntable([torus, ground, drops], frames, ctx.path("turntable.gif" if ctx.quick else "turntable.mp4"),
                   camera=cam.resized(size[0] // 2 * 2, size[1] // 2 * 2), fps=24, color_by="speed", colormap="plasma")
    if ctx.quick:
        ctx.image(tt, "turntable")
    else:
        ctx.video(tt, "turntable")
    ctx.metric("surfels", len(torus))
    ctx.metric("particles", n)
