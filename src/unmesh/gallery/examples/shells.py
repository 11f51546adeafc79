"""Gallery examples of point-sampled thin shells (thesis chapter 7).

Each example runs a shipped scene (``examples/shells/*.toml``), renders the dense surfel
frames (discontinuity surfels only clip, section 4.3) with one fixed camera into a video
and a strip of stills, and reports figures read from ``summary.json``. ``ctx.quick`` runs
them coarser and shorter.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.gallery.registry import ExampleContext, example

__all__ = ["render_frames", "run_shell_scene"]

SECTION = "Thin shells"


def run_shell_scene(ctx: ExampleContext, name: str, quick: dict[str, Any], duration: float | None = None) -> Path:
    """Run ``examples/shells/NAME.toml`` into ``ctx.path(NAME)`` (with ``quick`` overrides in quick mode).

    Returns the output directory.
    """
    from unmesh.shells.scene import build_simulation

    return ctx.run_scene(f"shells/{name}", build_simulation, quick if ctx.quick else None, duration)[0]


def render_frames(outdir: Path, frames: list[int], direction: Any, video: Path | None = None, size: int = 320,
                  fps: float = 25.0, floor: bool = False, context: tuple[Any, ...] = (), closed: bool = False,
                  ) -> tuple[list[np.ndarray], Path | None]:
    """Render selected frames (stills, anti-aliased by 2x2 supersampling) and optionally every
    frame (video, at least 640x480) with one camera.

    The frames keep their discontinuity surfels (``SurfelCloud.surfel_kinds``): the renderer
    passes them to the splatter as clip information (section 4.3) and draws no colour for them.
    ``floor`` draws the floor ``y = 0`` of the scenes' plane colliders with a grid and the
    contact shadow of the shell (:class:`unmesh.render.Floor`); ``context`` adds fixed objects
    (e.g. the clamp, :func:`_clamps`). ``closed`` culls back-facing splats (a closed shell that does
    not tear: the far side of a thin part then shows no dark rim at its silhouette).
    """
    from unmesh import io
    from unmesh.gallery.figures import floor_under
    from unmesh.render import Camera, SplatOptions, render, write_video

    files = sorted((outdir / "frames").glob("frame_*.ply"))
    clouds = {}

    def load(i: int) -> Any:
        if i not in clouds:
            clouds.clear()
            clouds[i] = io.load(files[i])
        return clouds[i]

    pts = np.concatenate([load(i).visible().positions[::7] for i in np.linspace(0, len(files) - 1, 6).astype(int)])
    ground = floor_under(pts, extent=3.0) if floor else None
    framed = np.concatenate([pts, pts * [1.0, 0.0, 1.0]]) if floor else pts  # keep the floor contact in view
    corners = [np.array([[b.lo, b.hi][i][0], [b.lo, b.hi][j][1], [b.lo, b.hi][k][2]])
               for b in context for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    if corners:
        framed = np.concatenate([framed, np.repeat(np.array(corners), 50, axis=0)])  # the clamps in view too

    def scene(i: int) -> list[Any]:
        cloud = load(i)
        if ground is None:
            return [cloud, *context]
        vis = cloud.visible().positions
        return [cloud, ground.with_casters(vis[:: max(1, len(vis) // 20000)]), *context]

    cull = {"splat": SplatOptions(cull_backfaces=True)} if closed else {}
    cam = Camera.fit(framed, size, size, direction=direction)
    stills = [render(scene(min(i, len(files) - 1)), cam, supersample=2, **cull).color for i in frames]  # anti-aliased
    written = None
    if video is not None:
        vcam = Camera.fit(framed, 640, 480, direction=direction)
        written = write_video((render(scene(i), vcam, **cull).color for i in range(len(files))), video, fps=fps)
    return stills, written


def _clamps(scene: str) -> tuple[Any, ...]:
    """The ``[[pinned]]`` box regions of a shipped shell scene as dark bars (drawing context):
    the clamp, flattened to a tenth of its height so the sheet's edge shows above and below it."""
    import tomllib

    from unmesh import scenes
    from unmesh.render import Box

    table = tomllib.loads(scenes.path(f"shells/{scene}.toml").read_text())
    out = []
    for pin in table.get("pinned", []):
        r = pin.get("region", {})
        if r.get("type") == "box":
            c, half = np.asarray(r["center"], float), 0.5 * np.asarray(r["size"], float)
            half[1] *= 0.1
            out.append(Box(c - half, c + half, color=(0.35, 0.36, 0.40)))
    return tuple(out)


def _strip(ctx: ExampleContext, name: str, images: list[np.ndarray], caption: str) -> None:
    from unmesh.render import save_image

    path = ctx.path(f"{name}.png")
    save_image(path, np.concatenate(images, axis=1))
    ctx.image(path, caption)


def _summary(outdir: Path) -> dict[str, Any]:
    return json.loads((outdir / "summary.json").read_text())


def _nodes(outdir: Path, frame: int) -> Any:
    from unmesh import io

    return io.load(outdir / "nodes" / f"frame_{frame:05d}.ply")


def _times(ctx: ExampleContext, s: dict[str, Any]) -> None:
    # the median over the frames: warm figures (the first frames include numba compilation)
    fr = s["frames"][1:]
    for key in ("force_seconds", "fracture_seconds", "surface_seconds"):
        ctx.metric(f"median {key.replace('_seconds', '')} time per frame",
                   round(float(1000 * np.median([f[key] for f in fr])), 1), "ms")
    ctx.metric("nodes / surfels / fibers", f"{s['nodes']} / {s['surfels']} / {s['fibers_initial']}")


@example("shell-hanging-sheet", "A clamped sheet sags under gravity", SECTION)
def hanging_sheet(ctx: ExampleContext) -> None:
    """A 1 m sheet clamped along one edge sags into a smooth, symmetric shape and comes to rest.
    The sag is a few centimetres, too small to see in the oblique stills: the last image colours
    the final sheet by its sag (drop below its initial height, in mm), seen from above and from
    the side along the clamped edge with the sag drawn 10x (the oblique stills above do not
    show it)."""
    out = run_shell_scene(ctx, "hanging_sheet", {"surface.nodes": 150, "surface.spacing": 0.02,
                                                 "simulation.duration": 1.0})
    s = _summary(out)
    last = len(s["frames"]) - 1
    picks = [0, last // 4, last // 2, last]
    stills, video = render_frames(out, picks, (0.5, 0.3, 1.0), ctx.path("hanging_sheet.mp4"),
                                  context=_clamps("hanging_sheet"))
    _strip(ctx, "hanging_sheet", stills, "frames 0, 1/4, 1/2 and the end")
    ctx.video(video, "the sheet sagging")
    _sag_image(ctx, out, last)
    x = _nodes(out, last).positions
    ctx.metric("tip sag", round(float(1.0 - x[:, 1].min()), 3), "m")
    ctx.metric("mirror asymmetry of the sag (z -> -z)", round(float(_asymmetry(x)), 4), "m")
    ctx.metric("final kinetic energy / max", f"{s['frames'][-1]['kinetic_energy'] / max(f['kinetic_energy'] for f in s['frames']):.2e}")
    _times(ctx, s)
    ctx.keep_frames(out, picks)


def _sag_image(ctx: ExampleContext, outdir: Path, frame: int, size: int = 320) -> None:
    """The final sheet coloured by its sag in mm (drop below the initial plane y = 1), from above
    and from the side, slightly above (looking along the clamped edge, the z axis), sag drawn 10x."""
    from unmesh import io
    from unmesh.render import Camera, render
    from unmesh.surfels import estimate_normals, estimate_radii

    cloud = io.load(sorted((outdir / "frames").glob("frame_*.ply"))[frame])
    sag = 1000.0 * (1.0 - cloud.positions[:, 1])
    cloud = cloud.replace(attributes={**dict(cloud.attributes), "sag_mm": sag})
    top = float(max(np.percentile(sag, 99.9), 1e-3))
    moved = cloud.positions - [0.0, 9.0 * 0.001, 0.0] * sag[:, None]  # sag drawn 10x
    normals = estimate_normals(moved, k=16)
    # drawing the sag 10x stretches the sheet: splats sized for the drawn positions leave no gaps
    exaggerated = cloud.replace(positions=moved, normals=normals,
                                radii=np.maximum(cloud.radii, estimate_radii(moved, normals)))
    images = []
    for shown, direction in ((cloud, (0.0, 1.0, 0.35)), (exaggerated, (0.0, 0.4, 1.0))):
        cam = Camera.fit(shown.visible().positions, int(1.3 * size), size, direction=direction)
        images.append(render(shown, cam, color_by="sag_mm", colormap="viridis", color_range=(0.0, top),
                             supersample=2).color)
    _strip(ctx, "hanging_sheet_sag", images,
           f"final frame coloured by sag (0 to {top:.0f} mm below the initial plane). Left: from above, clamped "
           "edge on the left. Right: from the side, slightly above, along the clamped edge, sag drawn 10x")


def _asymmetry(x: np.ndarray) -> float:
    """Mean |y(x, z) - y(x, -z)| between each node and its mirror image's nearest node."""
    from unmesh.spatial import knn

    mirror = x[:, [0, 2]] * [1.0, -1.0]
    _, i = knn(x[:, [0, 2]], 1, queries=mirror)
    return float(np.abs(x[:, 1] - x[i[:, 0], 1]).mean())


@example("shell-elastic-drop", "An elastic dome bounces (Fig. 7.4)", SECTION)
def elastic_drop(ctx: ExampleContext) -> None:
    """An elastic dome (F.1: K_s = K_b = 25, D = 0.4, dt = 0.01) thrown on the floor deforms,
    bounces and comes to rest."""
    out = run_shell_scene(ctx, "elastic_drop", {"surface.nodes": 400, "surface.spacing": 0.5,
                                                "simulation.duration": 3.0})
    s = _summary(out)
    last = len(s["frames"]) - 1
    g = [f["gravity_energy"] for f in s["frames"]]
    hit = int(np.argmin(g[: last // 2 + 1]))
    picks = [0, hit, min(hit + 5, last), last]
    stills, video = render_frames(out, picks, (0.0, 0.35, 1.0), ctx.path("elastic_drop.mp4"), floor=True)
    _strip(ctx, "elastic_drop", stills, "before, at and after the impact, and the rest state")
    ctx.video(video, "the dome bouncing")
    ctx.metric("rise of the centre of mass after the impact (bounce)",
               round(float((max(g[hit:]) - g[hit]) / (s["mass"] * 1.0)), 3), "units")
    _times(ctx, s)
    ctx.keep_frames(out, picks)


@example("shell-plastic-drop", "A plastic bust dents (Fig. 7.5)", SECTION)
def plastic_drop(ctx: ExampleContext) -> None:
    """A heavy plastic blob (F.1: K_s = K_b = 1000, alpha = 2, beta = 0.2, D = 0.5) thrown on
    the floor dents and stays dented."""
    out = run_shell_scene(ctx, "plastic_drop", {"surface.nodes": 400, "surface.spacing": 0.6,
                                                "simulation.duration": 2.5})
    s = _summary(out)
    last = len(s["frames"]) - 1
    picks = [0, last // 4, last // 2, last]
    stills, video = render_frames(out, picks, (0.4, 0.3, 1.0), ctx.path("plastic_drop.mp4"), floor=True, closed=True)
    _strip(ctx, "plastic_drop", stills, "the blob denting on impact; the dent stays")
    ctx.video(video, "plastic impact")
    h0 = np.ptp(_nodes(out, 0).positions[:, 1])
    h1 = np.ptp(_nodes(out, last).positions[:, 1])
    ctx.metric("height after / before", round(float(h1 / h0), 3))
    _times(ctx, s)
    ctx.keep_frames(out, picks)


@example("shell-tearing-poster", "A poster tears from a weak point (Fig. 7.8)", SECTION)
def tearing_poster(ctx: ExampleContext) -> None:
    """A poster (F.1: K_s = 1000, K_b = 10000, gamma_s = 0.02, D = 0.3, dt = 0.001) pulled
    apart at its corners, harder at the top, tears from a weak point at the top down into two
    halves."""
    from unmesh.errors import UnstableSimulationError

    try:
        # quick: the same nodes (the crack path depends on the node set), a shorter run
        out = run_shell_scene(ctx, "tearing_poster", {"simulation.duration": 2.2})
        note = ""
    except UnstableSimulationError as exc:
        out = ctx.path("tearing_poster")
        note = f" The run stopped early: {exc}"
    s = _summary(out)
    last = len(s["frames"]) - 1
    first = next((f["frame"] for f in s["frames"] if f["cracks"] > 0), last)
    split = next((f["frame"] for f in s["frames"] if f["components"] >= 2), last)
    picks = [0, min((first + split) // 2, last), split, last]
    stills, video = render_frames(out, picks, (0.0, 0.0, 1.0), ctx.path("tearing_poster.mp4"))
    times = ", ".join(f"{s['frames'][k]['time']:.1f}" for k in picks)
    _strip(ctx, "tearing_poster", stills, f"t = {times} s: intact; torn top to bottom; the last link "
                                          "broken, two halves; pulled apart")
    ctx.video(video, "tearing")
    ctx.text(f"Cracks: {s['frames'][-1]['cracks']}, pieces: {s['frames'][-1]['components']}, "
             f"the halves separate at t = {s['frames'][split]['time']:.2f} s.{note}")
    ctx.metric("cracks", s["frames"][-1]["cracks"])
    ctx.metric("pieces of the fiber graph", s["frames"][-1]["components"])
    ctx.metric("time of the first crack", round(s["frames"][first]["time"], 2), "s")
    ctx.metric("time the halves separate", round(s["frames"][split]["time"], 2), "s")
    _times(ctx, s)
    ctx.keep_frames(out, picks)


@example("shell-balloon", "A balloon inflated until it tears (Fig. 7.10)", SECTION)
def balloon(ctx: ExampleContext) -> None:
    """A sphere (F.1: K_s = K_b = 100, D = 0.4, dt = 0.001; gamma_s = 0.3, see the scene file) under rising
    pressure grows until it tears; the air escapes and the shell relaxes."""
    # quick: fewer surfels, but the scene's 1170 nodes: with 500 the membrane never reaches the
    # tearing stretch before the end (the fiber energies depend on the node count, docs/shell_scene.md)
    out = run_shell_scene(ctx, "balloon", {"surface.spacing": 0.4})
    s = _summary(out)
    last = len(s["frames"]) - 1
    cracked = next((f["frame"] for f in s["frames"] if f["cracks"] > 0), last)
    picks = [0, max(cracked - 1, 0), min(cracked + 3, last), last]
    stills, video = render_frames(out, picks, (0.8, 0.7, 0.45), ctx.path("balloon.mp4"))
    _strip(ctx, "balloon", stills, "at rest, inflated, tearing, relaxed")
    ctx.video(video, "inflation and tear")
    r0 = np.linalg.norm(_nodes(out, 0).positions, axis=1).mean()
    r1 = np.linalg.norm(_nodes(out, max(cracked - 1, 0)).positions, axis=1).mean()
    ctx.metric("radius growth before the tear", f"{100 * (r1 / r0 - 1):.1f}", "%")
    ctx.metric("cracks", s["frames"][-1]["cracks"])
    _times(ctx, s)
    ctx.keep_frames(out, picks)
