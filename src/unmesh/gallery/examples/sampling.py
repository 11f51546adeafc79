"""Gallery examples of surfel sampling and estimation (thesis 3.3, ch. 6; Pauly et al. 2002).

``sampling-shapes``: every built-in shape sampled as surfels on its exact surface.
``sampling-ldc``: LDC sampling of the blob's triangle mesh, with the sample-distance
statistics (maximum distance <= sqrt(3) d) and splat coverage.
``sampling-normals``: normal estimation on a noisy point cloud, angle error against the
exact normals.
``sampling-clustering``: hierarchical clustering simplification at several target counts,
coloured by cluster.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh.gallery.figures import tile
from unmesh.gallery.registry import ExampleContext, example

__all__: list[str] = []

SECTION = "Surfels: sampling and estimation"


def _label_colors(labels: np.ndarray, seed: int = 3) -> np.ndarray:
    """Distinct pastel colours (N,3) per cluster label."""
    k = int(labels.max()) + 1
    rng = np.random.default_rng(seed)
    hue = rng.permutation(k) / max(k, 1)
    sat = 0.45 + 0.35 * rng.random(k)
    val = 0.75 + 0.2 * rng.random(k)
    i = np.floor(hue * 6).astype(int) % 6
    f = hue * 6 - np.floor(hue * 6)
    p, q, t = val * (1 - sat), val * (1 - f * sat), val * (1 - (1 - f) * sat)
    table = np.select([i[:, None] == j for j in range(6)],
                      [np.stack(c, 1) for c in ((val, t, p), (q, val, p), (p, val, t), (p, q, val), (t, p, val),
                                                (val, p, q))])
    return table[labels]



def _view(objects: Any, bounds: np.ndarray, size: tuple[int, int], closed: bool = True, **options: Any) -> np.ndarray:
    """A still (H,W,3), anti-aliased by 2x2 supersampling unless ``supersample`` is given; the far
    side of a ``closed`` surface is culled (no dark back-facing splats past thin silhouettes)."""
    from unmesh.render import Camera, render
    from unmesh.render.options import STILL_SUPERSAMPLE
    from unmesh.render.splat import SplatOptions

    cam = Camera.framing(bounds, *size, fov=30)
    options.setdefault("supersample", STILL_SUPERSAMPLE)
    options.setdefault("splat", SplatOptions(cull_backfaces=closed))
    return render(objects, cam, **options).color


@example("sampling-shapes", "Built-in shapes sampled as surfels", section=SECTION)
def shapes_example(ctx: ExampleContext) -> None:
    """The procedural default data: sphere, box, cylinder, torus, disc, plane and the bunny-like
    blob, each sampled on its exact surface with exact normals (parametric cell-centred grids,
    a Fibonacci lattice, or maximal Poisson-disk sampling for the blob). Radii make neighbouring
    splats overlap; the box and cylinder keep their sharp edges (per-face samples). Left: splats
    shrunk to 40 % to show the sampling; right: the full splats rendered by EWA splatting."""
    from unmesh.render import save_image
    from unmesh.shapes import SHAPES, by_name
    from unmesh.spatial import knn

    size = (160, 140) if ctx.quick else (320, 280)
    params = {"plane": {"size": (2.0, 1.4), "normal": (0.0, 1.0, 0.4)}, "disc": {"normal": (0.0, 1.0, 0.4)}}
    shrunk, full = [], []
    for name in SHAPES:
        shape = by_name(name, **params.get(name, {}))
        if name == "blob":  # resolve the ears (spacing <= 0.05 * scale), also in quick mode
            spacing = shape.size() / (40 if ctx.quick else 60)
        else:
            spacing = shape.size() / (12 if ctx.quick else 30)
        cloud, dt = ctx.timed(shape.surfels, spacing, color=(0.85, 0.72, 0.55),
                              warm=lambda s=shape, h=spacing: s.surfels(4 * h))
        d, _ = knn(cloud.positions, 2)
        ctx.metric(f"{name}: surfels", len(cloud))
        ctx.metric(f"{name}: median neighbour distance / spacing", round(float(np.median(d[:, 1]) / spacing), 3))
        ctx.metric(f"{name}: mean radius / spacing", round(float(cloud.radii.mean() / spacing), 3))
        ctx.metric(f"{name}: sampling time", round(dt, 3), "s")
        bounds = shape.bounds()
        closed = name not in ("disc", "plane")
        shrunk.append(_view(cloud.replace(radii=0.4 * cloud.radii), bounds, size, closed=False))  # see-through
        full.append(_view(cloud, bounds, size, closed))
    path = ctx.path("shapes.png")
    save_image(path, tile([img for pair in zip(shrunk, full, strict=True) for img in pair], columns=4))
    ctx.image(path, "Each shape: splats at 40 % radius (sampling pattern) and full splats (closed surface).")


@example("sampling-ldc", "LDC sampling of a triangle mesh", section=SECTION)
def ldc_example(ctx: ExampleContext) -> None:
    """LDC sampling (chapter 6): three orthogonal bundles of parallel rays with spacing d; every
    ray-triangle intersection becomes a surfel. Left: samples coloured by the ray bundle that
    produced them (x red, y green, z blue): each bundle samples the parts of the surface facing
    it. Right: the splatted surfels. The guarantee is that every surface point has a sample
    within sqrt(3) d; the measured maximum over dense random surface points is reported."""
    from unmesh.render import save_image
    from unmesh.shapes import Blob
    from unmesh.spatial import knn
    from unmesh.surfels.sampling import sample_mesh

    blob = Blob()
    mesh = blob.mesh(0.02 if ctx.quick else 0.01)
    d = 0.04 if ctx.quick else 0.015
    cloud, dt = ctx.timed(sample_mesh, mesh, d, warm=lambda: sample_mesh(mesh, 4 * d))
    on_lattice = np.abs(cloud.positions / d - 0.5 - np.round(cloud.positions / d - 0.5)) < 1e-9
    axis = np.argmin(on_lattice, axis=1)  # the coordinate that is not a lattice coordinate: ray direction
    bundle = np.eye(3)[axis] * 0.75 + 0.15
    rng = np.random.default_rng(0)
    count = 50_000 if ctx.quick else 400_000
    areas = mesh.face_areas()
    tri = rng.choice(len(areas), count, p=areas / areas.sum())
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    f = mesh.faces[tri]
    v = mesh.vertices
    pts = (1 - r1)[:, None] * v[f[:, 0]] + (r1 * (1 - r2))[:, None] * v[f[:, 1]] + (r1 * r2)[:, None] * v[f[:, 2]]
    dist, near = knn(cloud.positions, 1, queries=pts)
    dist, near = dist[:, 0], near[:, 0]
    rel = pts - cloud.positions[near]
    h = np.einsum("ij,ij->i", rel, cloud.normals[near])
    tang = np.sqrt(np.maximum(0.0, np.einsum("ij,ij->i", rel, rel) - h * h))
    covered_by_nearest = np.mean(tang <= cloud.radii[near])
    ctx.metric("triangles", len(mesh.faces))
    ctx.metric("ray spacing d", d)
    ctx.metric("samples", len(cloud))
    ctx.metric("samples per bundle (x, y, z)", [int((axis == k).sum()) for k in range(3)])
    ctx.metric("sampling time (incl. radii)", round(dt, 3), "s")
    ctx.metric("max distance surface -> nearest sample / d", round(float(dist.max() / d), 4), "(bound sqrt(3) = 1.7321)")
    ctx.metric("mean distance surface -> nearest sample / d", round(float(dist.mean() / d), 4))
    ctx.metric("surface points inside the nearest splat", f"{100 * covered_by_nearest:.3f} %")
    ctx.metric("radius / d (min, median, max)", [round(float(q), 3) for q in np.percentile(cloud.radii / d, [0, 50, 100])])
    size = (320, 300) if ctx.quick else (640, 600)
    bounds = mesh.bounds()
    left = _view(cloud.replace(colors=bundle, radii=0.35 * cloud.radii), bounds, size, shading="none")
    right = _view(cloud.replace(colors=np.tile([0.85, 0.72, 0.55], (len(cloud), 1))), bounds, size)
    path = ctx.path("ldc.png")
    save_image(path, tile([left, right], 2))
    ctx.image(path, "Left: LDC samples by ray bundle (x red, y green, z blue). Right: splatted surfels.")
    hist_path = ctx.path("distance_histogram.png")
    save_image(hist_path, _histogram(dist / d, np.sqrt(3.0), size=(size[0], size[1] // 2)))
    ctx.image(hist_path, "Histogram of surface-to-nearest-sample distance / d; the red line is the bound sqrt(3).")


def _histogram(values: np.ndarray, bound: float, size: tuple[int, int], bins: int = 60) -> np.ndarray:
    """A bar chart (H,W,3) of ``values`` on [0, 1.1 bound] with a red line at ``bound`` and axis labels."""
    from PIL import Image, ImageDraw

    w, h = size
    counts, _ = np.histogram(values, bins=bins, range=(0.0, 1.1 * bound))
    img = np.ones((h, w, 3))
    left, right, top, bottom = 10, 10, 10, 24
    scale = (h - top - bottom) / max(counts.max(), 1)
    bw = (w - left - right) / bins
    for k, c in enumerate(counts):
        x0, x1 = int(left + k * bw), int(left + (k + 1) * bw) - 1
        img[h - bottom - int(c * scale):h - bottom, x0:max(x1, x0 + 1)] = (0.35, 0.45, 0.65)

    def xpix(v: float) -> int:
        return int(left + v / (1.1 * bound) * (w - left - right))

    img[top:h - bottom, max(xpix(bound) - 1, 0):xpix(bound) + 1] = (0.85, 0.1, 0.1)
    img[h - bottom:h - bottom + 1, left:w - right] = 0.0
    pil = Image.fromarray((img * 255).astype(np.uint8))
    draw = ImageDraw.Draw(pil)
    for tick in np.arange(0.0, 1.1 * bound, 0.25):
        x = xpix(float(tick))
        draw.line([(x, h - bottom), (x, h - bottom + 4)], fill=(0, 0, 0))
        if abs(tick - round(tick)) < 1e-9 or tick == 0.5:
            draw.text((x - 6, h - bottom + 6), f"{tick:g}", fill=(0, 0, 0))
    draw.text((xpix(bound) - 80, top), "sqrt(3) bound", fill=(200, 20, 20))
    draw.text((w - right - 150, h - bottom + 6), "distance / d", fill=(0, 0, 0))
    return np.asarray(pil, dtype=np.float64) / 255.0


@example("sampling-normals", "Normal estimation on a noisy point cloud", section=SECTION)
def normals_example(ctx: ExampleContext) -> None:
    """Normals of a raw point cloud: PCA of the k = 16 nearest neighbours (the least-squares
    plane, cf. eq. 3.5) oriented consistently by propagation along the minimum spanning tree of
    the neighbour graph (Hoppe et al. 1992) and flipped outward. The blob is sampled, jittered
    with Gaussian noise, and the estimates are compared with the exact normals. Left: estimated
    normals as colours; right: angle error (0 to 20 degrees)."""
    from unmesh.render import save_image
    from unmesh.shapes import Blob
    from unmesh.surfels import SurfelCloud, estimate_normals, estimate_radii

    blob = Blob()
    spacing = 0.03 if ctx.quick else 0.012
    exact = blob.surfels(spacing)
    rng = np.random.default_rng(1)
    sigma = 0.1 * spacing
    noisy = exact.positions + rng.normal(scale=sigma, size=exact.positions.shape)
    n, dt = ctx.timed(estimate_normals, noisy, k=16, warm=lambda: estimate_normals(noisy[:2000], k=16))
    err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, exact.normals), -1.0, 1.0)))
    ctx.metric("points", len(noisy))
    ctx.metric("noise sigma / spacing", 0.1)
    ctx.metric("estimation time", round(dt, 3), "s")
    ctx.metric("angle error median", round(float(np.median(err)), 3), "deg")
    ctx.metric("angle error 95th percentile", round(float(np.percentile(err, 95)), 3), "deg")
    ctx.metric("normals pointing inward (error > 90 deg)", int((err > 90).sum()))
    radii = estimate_radii(noisy, n)
    cloud = SurfelCloud(noisy, n, radii=radii, colors=0.5 + 0.5 * n, attributes={"angle_error": err})
    size = (320, 300) if ctx.quick else (640, 600)
    bounds = blob.bounds()
    left = _view(cloud, bounds, size, False, shading="none")  # estimated normals: both sides drawn
    right = _view(cloud, bounds, size, False, color_by="angle_error", colormap="viridis", color_range=(0.0, 20.0))
    path = ctx.path("normals.png")
    save_image(path, tile([left, right], 2))
    ctx.image(path, "Estimated normals (RGB = 0.5 + 0.5 n) and their angle error in degrees.")


@example("sampling-clustering", "Simplification by hierarchical clustering", section=SECTION)
def clustering_example(ctx: ExampleContext) -> None:
    """Pauly, Gross and Kobbelt (2002): the cloud is split recursively by the plane through a
    cluster's centroid normal to its largest covariance eigenvector; with a target count the
    cluster with the largest scatter along that axis is split first. Top: the dense blob coloured by cluster; bottom:
    one surfel per cluster (centroid, mean normal, radius covering the cluster's splats)."""
    from unmesh.render import save_image
    from unmesh.shapes import Blob
    from unmesh.surfels import simplify

    blob = Blob()
    dense = blob.surfels(0.03 if ctx.quick else 0.01, color=(0.8, 0.8, 0.8))
    targets = (50, 200) if ctx.quick else (100, 400, 1600)
    size = (240, 220) if ctx.quick else (420, 380)
    bounds = blob.bounds()
    top, bottom = [], []
    ctx.metric("input surfels", len(dense))
    for target in targets:
        (small, labels), dt = ctx.timed(simplify, dense, target=target, return_labels=True,
                                        warm=lambda: simplify(dense.subset(np.arange(min(len(dense), 3000))),
                                                              target=20, return_labels=True))
        counts = np.bincount(labels)
        ctx.metric(f"target {target}: clusters", len(small))
        ctx.metric(f"target {target}: points per cluster (min, median, max)",
                   [int(counts.min()), int(np.median(counts)), int(counts.max())])
        ctx.metric(f"target {target}: time", round(dt, 3), "s")
        col = _label_colors(labels)
        top.append(_view(dense.replace(colors=col), bounds, size))
        bottom.append(_view(small.replace(colors=_label_colors(np.arange(len(small)))), bounds, size))
    path = ctx.path("clustering.png")
    save_image(path, tile(top + bottom, len(targets)))
    ctx.image(path, "Columns: " + ", ".join(f"{t} clusters" for t in targets)
              + ". Top: input coloured by cluster; bottom: the simplified surfels.")
