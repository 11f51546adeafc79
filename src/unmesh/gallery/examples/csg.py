"""Gallery examples of CSG on point-sampled surfaces (thesis chapter 4).

``csg-fig41``: closest-surfel vs two-surfel classification at a differently sampled edge.
``csg-fig43``: discarding surfels by their centre (holes) vs the three surfel classes.
``csg-fig47``: a cube of six half-spaces sampled with 1, 25 and 900 surfels per face.
``csg-fig48``: the blob minus two spheres, with a corner of three surfaces magnified 16x.
``csg-fig49``: thin spikes left by four large spheres cut from a ball.
``csg-fig410``: an icosahedron as the intersection of 20 half-spaces, one surfel per face.
``csg-fig46``: a square painted on a sphere, with and without texture-discontinuity surfels.
``csg-limits``: the known limit of 4.5, nearly coplanar clipping surfels (jagged, bleeding edges).
``csg-dynamic``: dynamic CSG videos, a sphere carved through a box and a rotating union.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from unmesh.gallery.registry import ExampleContext, example

__all__ = ["coplanar_limits", "side_by_side"]


def side_by_side(*images: np.ndarray, gap: int = 6) -> np.ndarray:
    """Images (H, W, 3) of one height joined left to right with white gaps."""
    h = images[0].shape[0]
    parts = []
    for k, im in enumerate(images):
        if k:
            parts.append(np.ones((h, gap, 3)))
        parts.append(im)
    return np.concatenate(parts, axis=1)


def _scene(name: str) -> Any:
    from unmesh import scenes
    from unmesh.csg.scene import load

    return load(scenes.path(f"csg/{name}.toml"))


def _drawn(model: Any) -> Any:
    from unmesh.csg import prepare
    from unmesh.surfels import SurfelCloud

    a = prepare(model).arrays
    return SurfelCloud(a.positions, a.normals, radii=a.radii)


def _still(model: Any, camera: Any, **options: Any) -> np.ndarray:
    """A still (H,W,3) of ``model``, anti-aliased by 2x2 supersampling (timed frames are rendered apart)."""
    from unmesh.render import render
    from unmesh.render.options import STILL_SUPERSAMPLE

    return render(model, camera, supersample=STILL_SUPERSAMPLE, **options).color


def _sampling(model: Any, camera: Any) -> np.ndarray:
    """The drawn surfels as small discs in their patch colours (the sampling of a model)."""
    from unmesh.csg import prepare
    from unmesh.surfels import SurfelCloud

    f = prepare(model)
    a = f.arrays
    small = SurfelCloud(a.positions, a.normals, radii=np.minimum(a.radii * 0.35, 0.06), colors=a.colors)
    return _still(small, camera, background=(0.12, 0.12, 0.14))


@example("csg-fig41", "Closest surfel vs two closest surfels at an edge (Fig. 4.1)", section="CSG")
def fig41_example(ctx: ExampleContext) -> None:
    """Inside/outside classification near a convex edge whose two faces are sampled differently.
    A slice through the edge: blue marks points wrongly classified outside, red wrongly inside;
    left the closest surfel (4.3), right the closest surfel and the closest one off its plane with the
    concave/convex rule (4.4)."""
    from unmesh.csg import inside_patch
    from unmesh.render import save_image
    from unmesh.surfels import SurfelCloud

    n = 160 if ctx.quick else 400
    h1, h2, off1, off2 = 0.05, 0.08, 0.01, 0.06
    y1 = np.arange(-0.2, 0.2, h1)
    top = np.array([[-a, y, 0.0] for a in np.arange(0, 1, h1) + off1 for y in y1])
    y2 = np.arange(-0.2, 0.2, h2)
    side = np.array([[0.0, y, -a] for a in np.arange(0, 1, h2) + off2 for y in y2])
    cloud = SurfelCloud(np.concatenate([top, side]),
                        np.concatenate([np.tile([0, 0, 1.0], (len(top), 1)), np.tile([1.0, 0, 0], (len(side), 1))]),
                        radii=np.full(len(top) + len(side), 0.1))
    g = np.linspace(-0.15, 0.15, n)
    xx, zz = np.meshgrid(g, g[::-1])
    pts = np.stack([xx.ravel(), np.full(xx.size, 0.01), zz.ravel()], axis=1)
    exact = (pts[:, 0] < 0) & (pts[:, 2] < 0)
    panels = []
    for rule in ("closest", "two"):
        got = inside_patch(cloud, pts, rule)
        img = np.where(exact[:, None], [0.75, 0.75, 0.75], [1.0, 1.0, 1.0])
        img[got & ~exact] = [0.85, 0.1, 0.1]
        img[~got & exact] = [0.1, 0.3, 0.9]
        img = img.reshape(n, n, 3)
        panels.append(img)
        ctx.metric(f"misclassified pixels, {'closest surfel' if rule == 'closest' else 'two surfels'}",
                   int((got != exact).sum()))
    path = save_image(ctx.path("fig41.png"), side_by_side(*panels))
    ctx.image(path, "a slice through the edge: grey inside; red wrongly inside, blue wrongly outside; "
                    "left closest surfel, right two surfels (4.4)")


@example("csg-fig43", "Discarding surfels vs edge clipping (Fig. 4.3)", section="CSG")
def fig43_example(ctx: ExampleContext) -> None:
    """A cube of six half-spaces minus a sphere. Left: the surfels classified (blue surface,
    grey edge, red outside). Middle: only the surfels whose centre is on the result, splatted
    as they are. Right: surface surfels splatted, edge surfels clipped per fragment."""
    from unmesh.csg import EDGE, prepare
    from unmesh.csg.cli import classify_cloud
    from unmesh.csg.draw import front_facing
    from unmesh.csg.frame import centre_classified
    from unmesh.render import Camera, render, save_image

    size = 200 if ctx.quick else 400
    model = _scene("carved_cube").model
    cam = Camera((1.9, 1.5, 2.3), (0, 0, 0), width=size, height=size, fov=36)
    f = prepare(model)
    classes = _still(classify_cloud(model), cam)
    conv = centre_classified(model)
    conv = conv.subset(front_facing(conv.positions, conv.normals, cam))
    plain = _still(conv, cam)
    t0 = time.perf_counter()
    render(model, cam)
    ctx.metric("frame time (partners, classes, splatting)", round(time.perf_counter() - t0, 3), "s")
    clipped = _still(model, cam)
    path = save_image(ctx.path("fig43.png"), side_by_side(classes, plain, clipped))
    ctx.image(path, "left: surfel classes (blue surface, grey edge, red outside); middle: surfels kept by "
                    "their centre, unclipped; right: edge surfels clipped per fragment")
    ctx.metric("edge surfels", int((f.classes == EDGE).sum()))
    ctx.metric("surfels", len(f.cloud))


@example("csg-fig47", "A cube sampled with 1, 25 and 900 surfels per face (Fig. 4.7)", section="CSG")
def fig47_example(ctx: ExampleContext) -> None:
    """Six half-space patches sampled at wildly different densities: the edges and corners are
    where the planes meet, whatever the sampling. Left: unlit colours; middle: shaded; right:
    the sampling."""
    from unmesh.render import Camera, save_image

    size = 200 if ctx.quick else 360
    model = _scene("sampled_cube").model
    cam = Camera((2.0, 1.7, 2.4), (0, 0, 0), width=size, height=size, fov=30)
    a = _still(model, cam, shading="none")
    b = _still(model, cam)
    c = _sampling(model, cam)
    path = save_image(ctx.path("fig47.png"), side_by_side(a, b, c))
    ctx.image(path, "left: unlit face colours; middle: shaded; right: the surfels (1, 25 and 900 per face)")


@example("csg-fig48", "The blob minus two spheres, a corner magnified 16x (Fig. 4.8)", section="CSG")
def fig48_example(ctx: ExampleContext) -> None:
    """Three patches of different sampling densities; where all three meet, the corner stays
    sharp when magnified 16 times (right)."""
    from unmesh.csg import prepare
    from unmesh.render import Camera, save_image

    scene = _scene("blob_minus_spheres")
    model = scene.model
    size = 200 if ctx.quick else 400
    cam = Camera.fit(_drawn(model).positions, size, size, fov=35)
    full = _still(model, cam)
    # a corner: an edge surfel of the blob with clipping partners on both spheres
    f = prepare(model)
    blob_leaf = [p.name for p in f.flat.leaves].index("blob")
    rows = np.repeat(np.arange(len(f.cloud)), np.diff(f.offsets))
    both = np.zeros((len(f.cloud), len(f.flat.leaves)), dtype=bool)
    both[rows, f.leaf[f.partners]] = True
    three = np.flatnonzero((f.leaf == blob_leaf) & both.sum(axis=1).astype(bool) & (both.sum(axis=1) >= 2))
    pick = three if len(three) else np.flatnonzero(f.classes == 1)
    corner = f.cloud.positions[pick[len(pick) // 2]]
    close = cam.replace(target=corner, eye=corner + (cam.eye - cam.target)).zoomed(16.0)
    zoom = _still(model, close)
    sampling = _sampling(model, cam)
    path = save_image(ctx.path("fig48.png"), side_by_side(full, sampling, zoom))
    ctx.image(path, "left: blob minus two spheres; middle: the sampling; right: 16x magnification "
                    "at the corner where the three surfaces meet")


@example("csg-fig49", "Thin spikes from sphere differences (Fig. 4.9)", section="CSG")
def fig49_example(ctx: ExampleContext) -> None:
    """A ball minus four large spheres around it (tetrahedral setup): four spikes remain that
    taper to points on the ball; each surfel of a spike wall is clipped by the other cuts from
    several sides, so the thin spikes render without holes or fins."""
    from unmesh.render import Camera, save_image

    model = _scene("spikes").model
    size = 200 if ctx.quick else 400
    cam = Camera((0.6, 0.9, 3.2), (0, 0, 0), width=size, height=size, fov=40)
    a = _still(model, cam)
    b = _still(model, cam.replace(eye=(-2.6, 1.2, 1.8)))
    path = save_image(ctx.path("fig49.png"), side_by_side(a, b))
    ctx.image(path, "a ball minus four large spheres: four spikes with tiny caps of the ball at their tips, "
                    "from two sides")


@example("csg-fig410", "An icosahedron of 20 half-spaces, one surfel each (Fig. 4.10)", section="CSG")
def fig410_example(ctx: ExampleContext) -> None:
    """Twenty half-space patches of one surfel each; their intersection is an icosahedron whose
    faces show exactly their own colours (unlit, left) with sharp edges."""
    from unmesh.render import Camera, render, save_image

    model = _scene("icosahedron").model
    size = 200 if ctx.quick else 400
    cam = Camera((1.8, 1.3, 2.4), (0, 0, 0), width=size, height=size, fov=35)
    render(model, cam.resized(16, 16))
    t0 = time.perf_counter()
    render(model, cam, shading="none")
    ctx.metric(f"frame time at {size}x{size}", round(time.perf_counter() - t0, 3), "s")
    a = _still(model, cam, shading="none")
    b = _still(model, cam)
    c = _sampling(model, cam)
    path = save_image(ctx.path("fig410.png"), side_by_side(a, b, c))
    ctx.image(path, "left: unlit; middle: shaded; right: the 20 surfels")


def painted_sphere(a: float = 0.4, h: float = 0.03, discontinuities: bool = True) -> Any:
    """A unit sphere sampled at spacing ``h``, red inside the square ``|x|, |y| < a`` on its
    ``z > 0`` side, with texture-discontinuity surfels (4.3) along the square's border: a pair
    facing either way every ``h/2`` on the arcs ``x = +-a`` and ``y = +-a`` (none on a corner;
    near a corner the second surfel of 4.4 is the closest one off the first one's plane, so it
    comes from the other side and the concave/convex rule applies). Surfels within ``1.5 h`` of the border are enlarged to ``1.3 h`` so that the
    surfels of each colour cover the border strip up to the border (they are clipped there).
    Returns ``[sphere, discontinuity surfels]`` or the sphere alone."""
    from unmesh.shapes import Sphere
    from unmesh.surfels import SurfelCloud

    s = Sphere(radius=1.0).surfels(h)
    p = s.positions
    front = p[:, 2] > 0
    inside = (np.abs(p[:, 0]) < a) & (np.abs(p[:, 1]) < a) & front
    col = np.where(inside[:, None], [0.85, 0.2, 0.15], [0.85, 0.85, 0.8])
    near = np.minimum(np.abs(np.abs(p[:, 0]) - a), np.abs(np.abs(p[:, 1]) - a)) < 1.5 * h
    radii = np.where(near & front, np.maximum(s.radii, 1.3 * h), s.radii)
    sphere = SurfelCloud(p, s.normals, radii=radii, colors=col, attributes={"discontinuity": np.zeros(len(p))})
    if not discontinuities:
        return sphere
    t = np.arange(-a + h / 4, a - h / 4 + 1e-9, h / 2)
    pos, nrm, axes = [], [], []
    for axis in (0, 1):
        other = 1 - axis
        for sign in (-1.0, 1.0):
            q = np.zeros((len(t), 3))
            q[:, axis] = sign * a
            q[:, other] = t
            q[:, 2] = np.sqrt(1 - q[:, 0] ** 2 - q[:, 1] ** 2)
            tang = np.zeros((len(t), 3))
            tang[:, other] = 1.0
            tang -= (tang * q).sum(axis=1)[:, None] * q  # along the border arc
            tang /= np.linalg.norm(tang, axis=1)[:, None]
            n = np.zeros((len(t), 3))
            n[:, axis] = 1.0
            for facing in (1.0, -1.0):
                pos.append(q)
                nrm.append(facing * n)
                axes.append(np.stack([tang * h, q * h], axis=1))
    pos_, nrm_, axes_ = np.concatenate(pos), np.concatenate(nrm), np.concatenate(axes)
    discs = SurfelCloud(pos_, nrm_, axes=axes_, attributes={"discontinuity": np.full(len(pos_), 2)})
    return [sphere, discs]


@example("csg-fig46", "A square painted on a sphere, with texture-discontinuity surfels (Fig. 4.6)", section="CSG")
def fig46_example(ctx: ExampleContext) -> None:
    """Texture-discontinuity surfels along the border of a painted square clip the colour only
    (4.3): the border is sharp, while normals and depth blend across it; without them the
    colours of the samples on either side blend over a surfel's width."""
    from unmesh.render import Camera, save_image

    size = 160 if ctx.quick else 300
    cam = Camera((0.9, 0.6, 2.6), (0.1, 0.1, 0.6), width=size, height=size, fov=35)
    zoom = cam.zoomed(6.0).replace(target=(0.4, 0.4, float(np.sqrt(1 - 0.32))))
    sharp, soft = painted_sphere(), painted_sphere(discontinuities=False)
    images = [_still(sharp, cam), _still(soft, cam), _still(sharp, zoom), _still(soft, zoom)]
    path = save_image(ctx.path("fig46.png"), side_by_side(*images))
    ctx.image(path, "a red square painted on a sphere; left to right: with texture-discontinuity surfels, "
                    "without, and both magnified 6x at a corner of the square")


#: Offsets of the second sphere in :func:`coplanar_limits`: crossing angles of about 17, 6, 1.7
#: and 0.6 degrees.
LIMIT_OFFSETS = (0.3, 0.1, 0.03, 0.01)


def coplanar_limits(size: int = 200) -> np.ndarray:
    """The union of two unit spheres (red spacing 0.05, blue 0.06) whose centres are ``d`` apart
    (:data:`LIMIT_OFFSETS`), unlit, seen along the crossing circle from outside: four panels
    (size, size) joined left to right. The smaller ``d``, the more nearly coplanar the
    clipping surfels at the crossing; the front/back test (4.3) against surfel planes becomes
    unreliable where the surfaces are closer than the surfels' deviation from the sphere (4.5)."""
    from unmesh.csg.model import Patch
    from unmesh.render import Camera
    from unmesh.shapes import Sphere

    panels = []
    for d in LIMIT_OFFSETS:
        a = Patch.from_shape(Sphere(radius=1.0), 0.05, color=(0.85, 0.25, 0.2), name="a")
        b = Patch.from_shape(Sphere(radius=1.0, center=(d, 0, 0)), 0.06, color=(0.2, 0.35, 0.85), name="b")
        x = d / 2
        z = float(np.sqrt(1 - x * x))
        cam = Camera((x, 0, z + 3), (x, 0, z), up=(0, 1, 0), width=size, height=size, ortho=0.25)
        panels.append(_still(a | b, cam, shading="none"))
    return side_by_side(*panels)


def density_jump_limit(size: int = 320, fine: float = 0.05, coarse: float = 0.3, z_jump: float = 0.6) -> np.ndarray:
    """A unit sphere (blue) united with a floor (red half-space ``y < 0``), seen from above the front:
    left the sphere sampled evenly (spacing ``fine``), right sampled ``coarse`` where ``z >= z_jump``
    and ``fine`` elsewhere (an abrupt change of density within one patch, Fig. 4.11). Two panels
    (size, size) side by side."""
    from unmesh.csg.model import Patch
    from unmesh.render import Camera
    from unmesh.shapes import Sphere
    from unmesh.surfels import SurfelCloud

    sphere = Sphere(radius=1.0)
    a, b = sphere.surfels(fine), sphere.surfels(coarse)
    keep_a, keep_b = a.positions[:, 2] < z_jump, b.positions[:, 2] >= z_jump
    blue = (0.2, 0.35, 0.85)
    jump = SurfelCloud(np.r_[a.positions[keep_a], b.positions[keep_b]], np.r_[a.normals[keep_a], b.normals[keep_b]],
                       radii=np.r_[a.radii[keep_a], b.radii[keep_b]], colors=np.tile(blue, (keep_a.sum() + keep_b.sum(), 1)))
    floor = Patch.halfspace((0, 0, 0), (0, 1, 0), extent=3.0, spacing=0.05, color=(0.85, 0.25, 0.2), name="floor")
    cam = Camera((0.0, 1.6, 3.2), (0, 0, 0.5), width=size, height=size, fov=40)
    return side_by_side(*(_still(Patch(c, name="ball") | floor, cam)
                          for c in (Patch.from_shape(sphere, fine, color=blue).cloud, jump)))


@example("csg-limits", "Known limits: nearly coplanar clipping surfels, abrupt density changes (4.5)", section="CSG")
def limits_example(ctx: ExampleContext) -> None:
    """Two spheres united, crossing at shrinking angles: the edge is nearly straight at 17 degrees, wavy at 6,
    and jagged with colour bleeding across it at 1.7 and 0.6 degrees (4.5). A sphere whose sampling becomes
    6x coarser along a circle: holes and bleeding there (Fig. 4.11)."""
    from unmesh.render import save_image

    path = save_image(ctx.path("limits.png"), coplanar_limits(100 if ctx.quick else 200))
    ctx.image(path, "a red and a blue sphere united, seen along their crossing, unlit; centres 0.3, 0.1, 0.03 "
                    "and 0.01 apart (left to right): the edge between the colours is nearly straight, then wavy, "
                    "then jagged with colour bleeding across it as the spheres cross more shallowly")
    path = save_image(ctx.path("density_jump.png"), density_jump_limit(160 if ctx.quick else 320))
    ctx.image(path, "a blue sphere united with a red floor. Left: the sphere sampled evenly (spacing 0.05). Right: "
                    "sampled at 0.3 where z >= 0.6 (towards the viewer): where the density jumps, the large tangent "
                    "discs lift off the sphere and leave holes, and fragments of the floor inside the sphere are "
                    "classified by the small surfels nearby instead of the large disc that covers them, so the "
                    "floor shows through in red (the artifact of Fig. 4.11)")


@example("csg-dynamic", "Dynamic CSG: a sphere carving a box, a rotating union", section="CSG")
def dynamic_example(ctx: ExampleContext) -> None:
    """Patches move between frames; clipping partners and surfel classes are recomputed every
    frame, nothing is resampled."""
    from unmesh.csg import Patch
    from unmesh.render import Camera, render, write_video
    from unmesh.shapes import euler_rotation

    scene = _scene("moving_carve")
    n = 6 if ctx.quick else scene.frames // 2
    width, height = (160, 120) if ctx.quick else (640, 480)  # videos at least 640 x 480 (#23 item 9)
    cam = Camera((1.9, 1.5, 2.6), (0, 0, 0), width=width, height=height, fov=38)
    t0 = time.perf_counter()
    frames = [render(scene.at_frame(k * scene.frames // n), cam).color for k in range(n)]
    ctx.metric("carving: time per frame", round((time.perf_counter() - t0) / n, 3), "s")
    path = write_video(frames, ctx.path("carve.mp4"), fps=scene.fps / 2)
    ctx.video(path, "a sphere moving through a box, subtracted from it")
    # rotating union of two cubes
    cube = None
    for v in np.eye(3).tolist() + (-np.eye(3)).tolist():
        p = Patch.halfspace(np.multiply(v, 0.45), v, 0.9001, 0.06, color=(0.9, 0.55, 0.25))
        cube = p if cube is None else cube & p
    other = []
    for v in np.eye(3).tolist() + (-np.eye(3)).tolist():
        other.append(Patch.halfspace(np.multiply(v, 0.3), v, 0.6001, 0.04, color=(0.3, 0.55, 0.9)))
    frames = []
    m = 6 if ctx.quick else 30
    for k in range(m):
        rot = np.eye(4)
        rot[:3, :3] = euler_rotation((25.0, 360.0 * k / m, 0.0))
        rot[:3, 3] = (0.35, 0.3, 0.3)
        small = None
        for p in other:
            q = p.moved(rot)
            small = q if small is None else small & q
        frames.append(render(cube | small, cam).color)
    path = write_video(frames, ctx.path("union.mp4"), fps=24)
    ctx.video(path, "a small cube rotating through a large one, their union")
