"""Gallery examples of the visco-elastic SPH simulation (thesis chapter 8).

Every example runs a shipped scene (``examples/sph/*.toml``; ``ctx.quick`` coarsens it and
shortens it), renders the particle frames into a video and a strip of stills with
:func:`unmesh.render.render_sequence`, and reports measured figures: momentum drift, the
rigid-fit deviation of the bouncing cube, the hydrostatic density error and pressure slope,
the dam-break front against Martin & Moyce (1952), melted and frozen fractions.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from unmesh.gallery.registry import ExampleContext, example

__all__ = ["run_shipped_scene"]

_SECTION = "SPH: fluids, elastic solids, phase changes"


def run_shipped_scene(ctx: ExampleContext, name: str, overrides: dict[str, Any]) -> tuple[Path, dict[str, Any]]:
    """Run ``examples/sph/<name>.toml`` into ``ctx.outdir/<name>``; returns (outdir, summary).

    Example
    -------
    Used by the examples of this module, e.g.
    ``run_shipped_scene(ctx, "dam_break", {"simulation.spacing": 0.02})``.
    """
    from unmesh.sph.scene import build_simulation

    return ctx.run_scene(f"sph/{name}", build_simulation, overrides)


def _frames(out: Path) -> list[Path]:
    return sorted((out / "frames").glob("frame_*.ply"))


_OBJECT_COLORS = np.array([[0.85, 0.30, 0.25], [0.25, 0.50, 0.85], [0.35, 0.70, 0.35], [0.90, 0.70, 0.25],
                           [0.60, 0.40, 0.75], [0.30, 0.70, 0.70], [0.85, 0.50, 0.65], [0.55, 0.55, 0.50]])


def _surface_meshes(out: Path, frame: int) -> list[Any]:
    """The skinned meshes (8.38) of ``frame`` in ``OUTDIR/surfaces`` (``<object>_NNNNN.ply``), one
    colour per object (in name order), or [] when the run wrote none."""
    from unmesh import io

    files = sorted((out / "surfaces").glob(f"*_{frame:05d}.ply"))
    meshes = []
    for k, f in enumerate(files):
        m = io.load(f)
        meshes.append(m.replace(vertex_colors=np.tile(_OBJECT_COLORS[k % len(_OBJECT_COLORS)], (len(m.vertices), 1))))
    return meshes


def _context(scene: str, dim: int, lo: np.ndarray, hi: np.ndarray) -> tuple[list[Any], np.ndarray]:
    """The floor and walls of a shipped scene's ``[[boundaries]]`` (drawing context only) and the
    points (M,3) the camera must keep in view besides the particles."""
    import tomllib

    from unmesh import scenes
    from unmesh.gallery.figures import floor_under
    from unmesh.render import Box
    from unmesh.render.context import open_box

    table = tomllib.loads(scenes.path(f"sph/{scene}.toml").read_text())
    size = float(np.max(hi - lo))
    out: list[Any] = []
    keep = []
    grey = (0.62, 0.62, 0.64)
    for b in table.get("boundaries", []):
        if b.get("type") == "plane" and dim == 2:  # the ground under the 2D view, as a slab
            y = float(b["point"][1])
            t = 0.04 * size
            out.append(Box((lo[0] - 3 * size, y - t, -t), (hi[0] + 3 * size, y, 0.0), color=grey))
            keep.append([0.5 * (lo[0] + hi[0]), y - t, 0.0])
        elif b.get("type") == "plane":
            pts = np.array([lo, hi])
            out.append(floor_under(pts, height=float(b["point"][1])))
        elif b.get("type") == "box" and dim == 2:
            bmin, bmax = np.asarray(b["min"], float), np.asarray(b["max"], float)
            t = 0.04 * float(np.max(bmax - bmin))
            out += [Box((bmin[0] - t, bmin[1] - t, -t), (bmax[0] + t, bmin[1], 0.0), color=grey),
                    Box((bmin[0] - t, bmin[1] - t, -t), (bmin[0], bmax[1], 0.0), color=grey),
                    Box((bmax[0], bmin[1] - t, -t), (bmax[0] + t, bmax[1], 0.0), color=grey)]
            keep += [[bmin[0] - t, bmin[1] - t, 0.0], [bmax[0] + t, bmin[1] - t, 0.0]]
        elif b.get("type") == "box":
            bmin, bmax = np.asarray(b["min"], float), np.asarray(b["max"], float)
            top = min(bmax[1], bmin[1] + 1.1 * (hi[1] - bmin[1]))  # walls up to a little above the action
            out.append(floor_under(np.array([bmin, bmax]), height=float(bmin[1]), extent=4.0))
            out += open_box(bmin, (bmax[0], top, bmax[2]))
            # frame the action: the tank's floor corners, but not far beyond the particles
            near_lo, near_hi = lo - 0.3 * size, hi + 0.3 * size
            keep += [[np.clip(x, near_lo[0], near_hi[0]), bmin[1], np.clip(z, near_lo[2], near_hi[2])]
                     for x in (bmin[0], bmax[0]) for z in (bmin[2], bmax[2])]
    return out, np.asarray(keep, dtype=np.float64).reshape(-1, 3)


def _render(ctx: ExampleContext, out: Path, name: str, caption: str, color_by: str, dim: int,
            color_range: Any = None, stills: int = 4, direction: Any = (0.35, 0.45, 1.0),
            surfaces: bool = False) -> None:
    """Video of all frames and a strip of stills (same camera), with the scene's floor and walls;
    ``surfaces`` draws the objects' skinned meshes (``OUTDIR/surfaces``) instead of the particles."""
    from unmesh import io
    from unmesh.render import Camera, render, render_sequence, save_image
    from unmesh.render.context import Floor

    frames = _frames(out)
    sample = [io.load(f) for f in frames[:: max(1, len(frames) // 8)]]
    pts = np.concatenate([p.positions for p in sample])
    lo = np.percentile(pts, 0.2, axis=0) if dim == 3 else pts.min(axis=0)
    hi = np.percentile(pts, 99.8, axis=0) if dim == 3 else pts.max(axis=0)
    context, keep = _context(name, dim, lo, hi)
    if color_range is None:
        vals = np.concatenate([np.asarray(p.attributes[color_by], dtype=np.float64) for p in sample])
        color_range = (float(np.percentile(vals, 1)), float(np.percentile(vals, 99)))
        if color_range[1] <= color_range[0]:
            color_range = (color_range[0], color_range[0] + 1.0)
    width, height = (640, 480) if not ctx.quick else (320, 240)
    inside = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
    framed = np.concatenate([inside[:: max(1, len(inside) // 20000)], keep])
    if dim == 2:
        # head-on, the content in the left 80 % of the image (the colour bar is on the right)
        flo, fhi = framed.min(axis=0), framed.max(axis=0)
        cw, ch = float(fhi[0] - flo[0]), float(fhi[1] - flo[1])
        size = max(1.1 * ch, 1.1 * cw / 0.8 * height / width) + 1e-6
        centre = np.array([0.5 * (flo[0] + fhi[0]) + 0.1 * size * width / height, 0.5 * (flo[1] + fhi[1]), 0.0])
        cam = Camera(centre + np.array([0.0, 0.0, 3.0 * size]), centre, width=width, height=height, ortho=size)
    else:
        cam = Camera.fit(framed, width, height, direction=direction, margin=1.3)

    def with_shadow(p: Any) -> list[Any]:
        return [c.with_casters(p.positions[:: max(1, len(p) // 20000)]) if isinstance(c, Floor) else c
                for c in context]

    picks = [frames[round(k)] for k in np.linspace(0, len(frames) - 1, stills)]
    scam = cam.resized(*((320, 240) if ctx.quick else (480, 360)))
    if surfaces and _surface_meshes(out, 0):
        # the skinned meshes of the objects (8.38) instead of their particles, one colour each
        from unmesh.render import write_video

        def scene(k: int) -> list[Any]:
            meshes = _surface_meshes(out, k)
            return [*meshes, *with_shadow(_Points(np.concatenate([m.vertices for m in meshes])))]

        video = write_video((render(scene(k), cam).color for k in range(len(frames))), ctx.path(f"{name}.mp4"), fps=30)
        ctx.video(video, caption)
        images = [render(scene(int(p.stem[-5:])), scam, supersample=2).color for p in picks]
    else:
        # the video's floors cast no shadow (fixed context, drawn once); the stills get the shadow
        video = render_sequence(out, ctx.path(f"{name}.mp4"), camera=cam, fps=30, progress=False, color_by=color_by,
                                color_range=color_range, legend=True, context=context)
        ctx.video(video, caption)
        images = []
        for path in picks:
            p = io.load(path)
            images.append(render([p, *with_shadow(p)], scam, color_by=color_by, color_range=color_range,
                                 supersample=2).color)
    strip = np.concatenate(images, axis=1)
    ctx.image(save_image(ctx.path(f"{name}_stills.png"), strip), f"{caption} — frames {', '.join(p.stem[-3:] for p in picks)}")


def _fluid_surface_stills(ctx: ExampleContext, out: Path, name: str, spacing: float, stills: int = 4) -> None:
    """The stills again as a surface: marching cubes of the SPH density (8.4) of all particles at
    half the rest density (:func:`unmesh.sph.surface.fluid_surface`, section 8.2.7), in the tank."""
    from unmesh import io
    from unmesh.render import Camera, render, save_image
    from unmesh.sph.surface import fluid_surface

    frames = _frames(out)
    sample = [io.load(f) for f in frames[:: max(1, len(frames) // 8)]]
    pts = np.concatenate([p.positions for p in sample])
    lo, hi = np.percentile(pts, 0.2, axis=0), np.percentile(pts, 99.8, axis=0)
    context, keep = _context(name, 3, lo, hi)
    inside = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
    framed = np.concatenate([inside[:: max(1, len(inside) // 20000)], keep])
    cam = Camera.fit(framed, *((320, 240) if ctx.quick else (480, 360)), direction=(0.35, 0.45, 1.0), margin=1.3)
    images = []
    picks = [frames[round(k)] for k in np.linspace(0, len(frames) - 1, stills)]
    for path in picks:
        x = io.load(path).positions
        # closest packing: mass d³/√2 per particle at rest density 1 (h = 2d)
        mesh = fluid_surface(x, np.full(len(x), spacing ** 3 / np.sqrt(2.0)), 1.0, 2.0 * spacing, step=0.5 * spacing)
        mesh = mesh.replace(vertex_colors=np.tile([0.30, 0.55, 0.85], (len(mesh.vertices), 1)))
        shown = [mesh, *(c.with_casters(x[:: max(1, len(x) // 20000)]) if hasattr(c, "with_casters") else c
                         for c in context)]
        images.append(render(shown, cam, supersample=2).color)
    ctx.image(save_image(ctx.path(f"{name}_surface.png"), np.concatenate(images, axis=1)),
              "the same frames as a surface: marching cubes of the SPH density at half the rest density")


class _Points:
    """Shadow casters: anything with ``positions`` (N,3)."""

    def __init__(self, positions: np.ndarray) -> None:
        self.positions = positions

    def __len__(self) -> int:
        return len(self.positions)


def _momentum_metrics(ctx: ExampleContext, summary: dict[str, Any], external: bool = True) -> None:
    f0, f1 = summary["frames"][0], summary["frames"][-1]
    ctx.metric("particles", summary["particles"])
    ctx.metric("steps", summary["steps"])
    warm = [f["step_seconds"] for f in summary["frames"][2:]]   # frame 1 includes numba compilation
    if warm:
        ctx.metric("time per step (median over the frames after the first)", round(1e3 * float(np.median(warm)), 2),
                   "ms")
    ctx.metric("mass drift", abs(f1["mass"] - f0["mass"]) / f0["mass"], "relative")


def _pressure_depth_plot(path: Any, depth: np.ndarray, pressure: np.ndarray, slope: float, r2: float,
                         rho0_g: float) -> None:
    """Per-particle pressure against depth (dots), the fit and ``ρ0 g depth`` (lines), drawn with Pillow."""
    from PIL import Image, ImageDraw

    from unmesh.render import save_image

    w, h, m = 640, 420, 60
    img = Image.new("RGB", (w, h), "white")
    dr = ImageDraw.Draw(img)
    dmax = float(depth.max()) * 1.05 + 1e-12
    plo = min(float(pressure.min()), 0.0)
    phi = max(float(pressure.max()), rho0_g * dmax) * 1.05 + 1e-12
    sx = lambda d: m + d / dmax * (w - 2 * m)  # noqa: E731
    sy = lambda v: h - m - (v - plo) / (phi - plo) * (h - 2 * m)  # noqa: E731
    dr.rectangle([m, m, w - m, h - m], outline="black")
    for k in range(6):
        d = dmax * k / 5
        dr.line([sx(d), h - m, sx(d), h - m + 5], fill="black")
        dr.text((sx(d) - 12, h - m + 8), f"{d:.2f}", fill="black")
        v = plo + (phi - plo) * k / 5
        dr.line([m - 5, sy(v), m, sy(v)], fill="black")
        dr.text((6, sy(v) - 6), f"{v:.2f}", fill="black")
    dr.line([(sx(0.0), sy(0.0)), (sx(dmax), sy(rho0_g * dmax))], fill=(150, 150, 150), width=5)
    icpt = float(np.mean(pressure) - slope * np.mean(depth))
    dr.line([(sx(0.0), sy(icpt)), (sx(dmax), sy(icpt + slope * dmax))], fill=(220, 80, 40), width=1)
    for d, v in zip(depth, pressure, strict=True):
        x0, y0 = sx(float(d)), sy(float(v))
        dr.ellipse([x0 - 2, y0 - 2, x0 + 2, y0 + 2], fill=(30, 90, 200))
    dr.text((m, 12), "per-particle pressure (Pa) against depth (m), last frame", fill="black")
    dr.text((m, 28), f"blue: particles; grey: rho0 g depth; red: fit, slope/(rho0 g) = {slope / rho0_g:.3f}, "
                     f"R^2 = {r2:.3f}", fill="black")
    save_image(path, np.asarray(img))


@example("sph-hydrostatic", "Water column at rest", _SECTION)
def hydrostatic(ctx: ExampleContext) -> None:
    """A 2D water column in a tank: density within 1 % of ρ0, pressure = ρ0 g depth (eq. 8.15).

    The scene's δ-SPH density filter (``density_diffusion``, :mod:`unmesh.sph._diffusion_kernels`)
    makes the per-particle pressure linear in depth; the plot shows it against ``ρ0 g depth``.
    """
    from unmesh import io

    ov = {"simulation.duration": 0.3 if ctx.quick else 1.5}
    out, summary = run_shipped_scene(ctx, "hydrostatic", ov)
    # colours span the physical range 0 .. ρ0 g H (not the start-up transient of frame 0); H is the
    # column height, the top layer of particles lying d/2 below the free surface (ρ0 = 1, g = 9.81)
    y0 = io.load(_frames(out)[0]).positions[:, 1]
    column = float(np.ptp(y0)) + float(summary["spacing"])
    _render(ctx, out, "hydrostatic", f"pressure in the resting column (colour: 0 to ρ0 g H = {9.81 * column:.2f} Pa)",
            "pressure", 2, color_range=(0.0, 9.81 * column))
    last = io.load(_frames(out)[-1])
    y = last.positions[:, 1]
    depth = y.max() - y
    pressure = np.asarray(last.attributes["pressure"], dtype=np.float64)
    sel = depth > 0.05
    slope = np.polyfit(depth[sel], pressure[sel], 1)[0]
    a, b = np.polyfit(depth, pressure, 1)
    r2 = 1.0 - float(np.sum((pressure - a * depth - b) ** 2) / np.sum((pressure - pressure.mean()) ** 2))
    _pressure_depth_plot(ctx.path("hydrostatic_pressure_depth.png"), depth, pressure, float(a), r2, 9.81)
    ctx.image(ctx.path("hydrostatic_pressure_depth.png"),
              "pressure against depth of every particle in the last frame, with ρ0 g depth")
    ctx.metric("max compression (last frame)", summary["frames"][-1]["max_density_error"])
    ctx.metric("pressure slope / (ρ0 g)", round(float(slope / 9.81), 3))
    ctx.metric("per-particle pressure vs depth R²", round(r2, 4))
    _momentum_metrics(ctx, summary)


@example("sph-dam-break", "Dam break against Martin & Moyce (1952)", _SECTION)
def dam_break(ctx: ExampleContext) -> None:
    """3D dam break, column a × 2a (n² = 2); surge front Z = x/a over T = t√(2g/a) vs the experiment."""
    from unmesh import io
    from unmesh.sph.front import surge_front

    a = 0.25
    # full: d = 0.0125 (18k particles) until 0.7 s, the surge running up the far wall (the experiment's
    # last time is T = 3.35, t = 0.38 s)
    spacing = 0.025 if ctx.quick else 0.0125
    ov = {"simulation.spacing": spacing, "simulation.duration": 0.4 if ctx.quick else 0.7}
    out, summary = run_shipped_scene(ctx, "dam_break", ov)
    _render(ctx, out, "dam_break", "dam break (colour: horizontal velocity vx)", "vx", 3)
    _fluid_surface_stills(ctx, out, "dam_break", spacing)
    t_mm = np.array([0.832, 1.219, 1.997, 2.547, 3.345])
    z_mm = np.array([1.217, 1.474, 2.292, 2.995, 4.134])
    times = np.array([f["time"] for f in summary["frames"]])
    frames = _frames(out)
    zs = []
    for big_t in t_mm:
        k = int(np.argmin(np.abs(times - big_t / np.sqrt(2 * 9.81 / a))))
        zs.append(surge_front(io.load(frames[k]).positions, spacing) / a)
    dev = (np.asarray(zs) - z_mm) / z_mm
    ctx.text("Surge front Z = x/a at the experiment's times T = " + ", ".join(f"{t:.2f}" for t in t_mm)
             + ": SPH " + ", ".join(f"{z:.2f}" for z in zs) + "; Martin & Moyce " + ", ".join(f"{z:.2f}" for z in z_mm))
    ctx.metric("front deviation from Martin & Moyce (max)", f"{100 * np.max(np.abs(dev)):.1f}", "%")
    ctx.metric("front deviation from Martin & Moyce (mean)", f"{100 * np.mean(np.abs(dev)):.1f}", "%")
    _momentum_metrics(ctx, summary)


@example("sph-elastic-cube", "Elastic cube bouncing (Fig. 8.7a)", _SECTION)
def elastic_cube(ctx: ExampleContext) -> None:
    """A 2D elastic cube dropped on the floor bounces and keeps its shape (implicit rest state, 8.2.1)."""
    from unmesh import io

    ov = {"simulation.spacing": 0.02 if ctx.quick else 0.01, "simulation.duration": 0.6 if ctx.quick else 1.5}
    out, summary = run_shipped_scene(ctx, "elastic_cube_2d", ov)
    _render(ctx, out, "elastic_cube_2d", "elastic cube (colour: pressure)", "pressure", 2)
    frames = _frames(out)
    x0 = io.load(frames[0]).positions
    worst = 0.0
    for f in frames:
        worst = max(worst, _rigid_deviation(x0, io.load(f).positions))
    ctx.metric("worst rigid-fit deviation", f"{100 * worst / 0.2:.2f}", "% of the edge")
    _momentum_metrics(ctx, summary)


def _pieces(x: np.ndarray, radius: float) -> int:
    """Connected components of the neighbour graph ``|x_i − x_j| ≤ radius``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from unmesh.spatial import radius_pairs

    pairs = radius_pairs(x, radius)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(x), len(x)))
    return int(connected_components(graph, directed=False)[0])


def _largest_hole(x: np.ndarray, d: float) -> float:
    """Radius of the largest empty disc centred at least ``d`` inside the convex hull of the 2D points ``x``."""
    from scipy.spatial import ConvexHull, cKDTree

    hull = ConvexHull(x)
    axes = [np.arange(a, b, d / 4) for a, b in zip(x.min(axis=0), x.max(axis=0), strict=True)]
    g = np.stack(np.meshgrid(*axes), -1).reshape(-1, 2)
    g = g[-(g @ hull.equations[:, :2].T + hull.equations[:, 2]).max(axis=1) >= d]
    return float(cKDTree(x).query(g)[0].max()) if len(g) else 0.0


def _rigid_deviation(x0: np.ndarray, x: np.ndarray) -> float:
    c0, c = x0.mean(axis=0), x.mean(axis=0)
    u, _, vt = np.linalg.svd((x - c).T @ (x0 - c0))
    if np.linalg.det(u @ vt) < 0:
        u[:, -1] *= -1
    fit = (x0 - c0) @ (u @ vt).T + c
    return float(np.sqrt(np.mean(np.sum((x - fit) ** 2, axis=1))))


@example("sph-plastic-cube", "Plastic cube (Fig. 8.7b)", _SECTION)
def plastic_cube(ctx: ExampleContext) -> None:
    """A clay cube deforms permanently on impact: the lattice's stored rest shape yields (8.2.5, 7.20–7.22)."""
    from unmesh import io

    # K_e ∝ 1/d² keeps the same clay at the coarser quick spacing (see the fracture example)
    ov = {"simulation.spacing": 0.02, "simulation.duration": 1.0, "materials.clay.elastic_stiffness": 2.5e6} \
        if ctx.quick else {"simulation.spacing": 0.01, "simulation.duration": 1.5}
    out, summary = run_shipped_scene(ctx, "plastic_cube_2d", ov)
    _render(ctx, out, "plastic_cube_2d", "plastic cube (colour: pressure)", "pressure", 2)
    frames = _frames(out)
    first, last = io.load(frames[0]).positions, io.load(frames[-1]).positions
    ctx.metric("permanent deformation (rigid-fit deviation)",
               f"{100 * _rigid_deviation(first, last) / 0.2:.1f}", "% of the edge")
    aspect = [float(np.ptp(p[:, 0]) / np.ptp(p[:, 1])) for p in (first, last)]
    ctx.metric("aspect ratio width/height (start → rest)", f"{aspect[0]:.2f} → {aspect[1]:.2f}")
    ctx.metric("pieces at rest (neighbours within 1.5 spacings)", _pieces(last[:, :2], 1.5 * ov["simulation.spacing"]))
    ctx.metric("largest hole inside at rest (radius; intact lattice 0.58)",
               f"{_largest_hole(last[:, :2], ov['simulation.spacing']) / ov['simulation.spacing']:.2f}", "spacings")
    _momentum_metrics(ctx, summary)


@example("sph-fracture", "Fracture of a clamped block (Fig. 8.7c)", _SECTION)
def fracture(ctx: ExampleContext) -> None:
    """A block clamped to a wall sags under gravity and breaks off (docking rates, 8.2.5)."""
    # K_e (8.31) acts per unit mass on displacements: the same chalk at twice the spacing needs K_e / 4
    ov = {"simulation.spacing": 0.02, "simulation.duration": 0.7, "materials.chalk.elastic_stiffness": 5e6} \
        if ctx.quick else {"simulation.spacing": 0.01, "simulation.duration": 1.5}
    out, summary = run_shipped_scene(ctx, "fracture_2d", ov)
    _render(ctx, out, "fracture_2d", "fracture (colour: pressure)", "pressure", 2)
    _momentum_metrics(ctx, summary)


@example("sph-melting", "Blob melting on a heated floor (Fig. 8.4)", _SECTION)
def melting(ctx: ExampleContext) -> None:
    """An elastic blob drops on a heated floor, conducts heat and melts into a puddle (8.35)."""
    from unmesh import io
    from unmesh.spatial import knn

    # quick: coarse, but long enough to melt completely; K_e ∝ 1/d² keeps the same jelly
    ov = {"simulation.spacing": 0.025, "simulation.duration": 2.0, "materials.jelly.elastic_stiffness": 8e5} \
        if ctx.quick else {"simulation.spacing": 0.0125, "simulation.duration": 2.0}
    out, summary = run_shipped_scene(ctx, "melting_blob", ov)
    _render(ctx, out, "melting_blob", "melting blob (colour: temperature)", "temperature", 3, color_range=(20, 100))
    _fluid_surface_stills(ctx, out, "melting_blob", ov["simulation.spacing"])
    last = summary["frames"][-1]["phase_counts"]
    ctx.metric("melted fraction at the end", round(last["fluid"] / (last["fluid"] + last["solid"]), 3))
    p = io.load(_frames(out)[-1]).positions
    d = ov["simulation.spacing"]
    ctx.metric("puddle: particles with a neighbour within 1.5 spacings",
               f"{100 * float(np.mean(knn(p, 2)[0][:, 1] < 1.5 * d)):.1f}", "%")
    ctx.metric("puddle: pieces", _pieces(p, 1.5 * d))
    ctx.metric("puddle: radius / height", f"{float(np.hypot(p[:, 0], p[:, 2]).max()):.3f} m / {float(p[:, 1].max()):.3f} m")
    _momentum_metrics(ctx, summary)


@example("sph-freezing", "Fluid freezing onto a cooled rod (Fig. 8.5)", _SECTION)
def freezing(ctx: ExampleContext) -> None:
    """Viscous fluid pours over a cold rod and freezes onto it (8.36); colour shows the phase."""
    ov = {"simulation.spacing": 0.025 if ctx.quick else 0.0125, "simulation.duration": 0.4 if ctx.quick else 0.8}
    out, summary = run_shipped_scene(ctx, "freezing_rod", ov)
    _render(ctx, out, "freezing_rod", "freezing rod (colour: phase, 1 = solid)", "phase", 3, color_range=(0, 1))
    f0, f1 = summary["frames"][0]["phase_counts"], summary["frames"][-1]["phase_counts"]
    ctx.metric("particles frozen onto the rod", f1["solid"] - f0["solid"])
    ctx.metric("fraction of the fluid frozen onto the rod", round((f1["solid"] - f0["solid"]) / f0["fluid"], 3))
    _momentum_metrics(ctx, summary)


@example("sph-dice", "Stiff elastic dice colliding (Fig. 8.8)", _SECTION)
def dice(ctx: ExampleContext) -> None:
    """Six stiff elastic dice collide and tumble; collisions are the repulsive part of the SPH forces (8.37)."""
    ov = {"simulation.spacing": 0.05 if ctx.quick else 0.035, "simulation.duration": 0.3 if ctx.quick else 1.5,
          "output.skin": True}
    out, summary = run_shipped_scene(ctx, "dice", ov)
    _render(ctx, out, "dice", "dice: the skinned cube meshes (8.38) moved by their particles, one colour per die",
            "object", 3, surfaces=True)
    _momentum_metrics(ctx, summary)
