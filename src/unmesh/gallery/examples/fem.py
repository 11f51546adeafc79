"""Gallery examples of FEM on convex polyhedra (chapter 9).

``fem-single-element`` (Fig. 9.3), ``fem-random-planes-cube`` (Fig. 9.4),
``fem-progressive-slicing`` (Fig. 9.9), ``fem-blob-slicing`` (Fig. 9.10) run the shipped
scene files; ``fem-accuracy`` shows the patch test with and without the consistency
correction and the cantilever convergence. Surfaces are drawn faceted, every connected piece
in its own colour, on a floor with a grid and their contact shadow; blades are drawn translucent.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.gallery.registry import ExampleContext, example

__all__ = ["element_colored_surface", "piece_colored_surface", "pieces", "run_shipped_scene"]

_PALETTE = np.array([[0.85, 0.45, 0.30], [0.35, 0.60, 0.85], [0.55, 0.78, 0.40], [0.90, 0.75, 0.35],
                     [0.70, 0.50, 0.80], [0.40, 0.75, 0.75], [0.85, 0.55, 0.65], [0.60, 0.60, 0.55]])


def element_colored_surface(mesh: Any, displacement: np.ndarray) -> Any:
    """Faceted boundary TriangleMesh (unshared vertices) coloured by element (palette by id).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> m = hex_grid((2, 1, 1))
    >>> len(element_colored_surface(m, np.zeros((m.n_nodes, 3))).vertices)
    60
    """
    from unmesh.meshes import TriangleMesh

    tris, elems = mesh.boundary_triangles(return_elements=True)
    x = mesh.points + displacement
    v = x[tris].reshape(-1, 3)
    col = np.repeat(_PALETTE[elems % len(_PALETTE)], 3, axis=0)
    return TriangleMesh(v, np.arange(len(v)).reshape(-1, 3), vertex_colors=col)


def pieces(mesh: Any) -> np.ndarray:
    """Connected piece (E,) int64 of every element: elements sharing a node are in one piece.
    Pieces are numbered by the x coordinate of their centre (left to right), so a slice keeps
    its number (and colour) from frame to frame.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> pieces(hex_grid((2, 1, 1))).tolist()
    [0, 0]
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    off, nodes = mesh.element_nodes()
    rows = np.repeat(np.arange(mesh.n_elements), np.diff(off))
    graph = coo_matrix((np.ones(len(nodes)), (rows, nodes + mesh.n_elements)),
                       shape=(mesh.n_elements + mesh.n_nodes,) * 2)
    _, label = connected_components(graph, directed=False)
    label = label[: mesh.n_elements]
    _, label = np.unique(label, return_inverse=True)
    cx = np.bincount(label, weights=mesh.element_centers()[:, 0]) / np.bincount(label)
    rank = np.empty(len(cx), dtype=np.int64)
    rank[np.argsort(cx, kind="stable")] = np.arange(len(cx))
    return rank[label]


def piece_colored_surface(mesh: Any, displacement: np.ndarray) -> Any:
    """Faceted boundary TriangleMesh coloured by connected piece (:func:`pieces`), not by element.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> m = hex_grid((2, 1, 1))
    >>> len(np.unique(piece_colored_surface(m, np.zeros((m.n_nodes, 3))).vertex_colors, axis=0))
    1
    """
    from unmesh.meshes import TriangleMesh

    tris, elems = mesh.boundary_triangles(return_elements=True)
    x = mesh.points + displacement
    v = x[tris].reshape(-1, 3)
    col = np.repeat(_PALETTE[pieces(mesh)[elems] % len(_PALETTE)], 3, axis=0)
    return TriangleMesh(v, np.arange(len(v)).reshape(-1, 3), vertex_colors=col)


def _area_samples(mesh: Any, n: int = 6000) -> np.ndarray:
    """``n`` points (n,3) spread over a triangle mesh by area (fixed seed): contact-shadow casters
    that do not depend on how finely the surface is triangulated."""
    tri = mesh.vertices[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    rng = np.random.default_rng(0)
    k = rng.choice(len(tri), size=n, p=area / area.sum())
    a, b = rng.random((2, n, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    return tri[k, 0] + a * (tri[k, 1] - tri[k, 0]) + b * (tri[k, 2] - tri[k, 0])


def _blades(scene: str) -> list[Any]:
    """The blade sweeps (:class:`unmesh.fem.events.BladeEvent`) of a shipped scene."""
    import tomllib

    from unmesh import scenes
    from unmesh.fem.events import BladeEvent

    table = tomllib.loads(scenes.path(f"fem/{scene}.toml").read_text())
    return [BladeEvent(float(c["start"]), float(c["stop"]), np.asarray(c["path"], dtype=np.float64))
            for c in table.get("cuts", []) if c.get("type") == "blade"]


def _blade_polygons(blades: list[Any], t: float, dt: float) -> list[Any]:
    """A translucent polygon per blade cutting at time ``t`` (from just before its start to just
    after its stop): the cutting edge and the blade's body behind it (along the path, back)."""
    from unmesh.render import Polygon

    out = []
    for b in blades:
        if not b.start - 2 * dt <= t <= b.stop + 2 * dt:
            continue
        a, c = b.blade(t)
        back = b.path[0].mean(axis=0) - b.path[-1].mean(axis=0)
        back *= 0.15 * np.linalg.norm(c - a) / max(np.linalg.norm(back), 1e-300)
        out.append(Polygon([a, c, c + back, a + back], color=(0.55, 0.62, 0.75), opacity=0.35, edge=1.5))
    return out


def run_shipped_scene(ctx: ExampleContext, name: str, overrides: dict[str, Any]) -> tuple[Path, dict[str, Any]]:
    """Run ``examples/fem/<name>.toml`` into ``ctx.outdir/<name>``; returns (outdir, summary).

    Example
    -------
    Used by the examples of this module, e.g.
    ``run_shipped_scene(ctx, "cantilever", {"simulation.duration": 20.0})``.
    """
    from unmesh.fem.scene import build_simulation

    return ctx.run_scene(f"fem/{name}", build_simulation, overrides)


def _render_run(ctx: ExampleContext, out: Path, summary: dict[str, Any], eye: Any, target: Any, picks: list[int],
                caption: str, size: tuple[int, int], scene: str = "", by_element: bool = False) -> None:
    """Video (at least 640x480) and a strip of stills with one camera framing the run: the pieces
    coloured by piece, the floor with a grid and their contact shadow, the blades translucent."""
    from unmesh.fem.vtk_io import read_vtu
    from unmesh.gallery.figures import floor_under, nice_step
    from unmesh.render import Camera, render, save_image, write_video

    n = len(summary["frames"])
    times = [f["time"] for f in summary["frames"]]
    dt = float(np.median(np.diff(times))) if n > 1 else 0.0
    blades = _blades(scene) if scene else []

    def surface(k: int) -> Any:
        mesh, pdata = read_vtu(out / "frames" / f"mesh_{k:05d}.vtu", check=False)
        paint = element_colored_surface if by_element else piece_colored_surface
        return paint(mesh, pdata["displacement"])

    sample = [surface(k).vertices for k in np.linspace(0, n - 1, 6).astype(int)]
    pts = np.concatenate(sample)
    framed = np.concatenate([pts, pts * [1.0, 0.0, 1.0]])
    direction = np.asarray(eye, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    ground = floor_under(sample[0], extent=5.0, grid=nice_step(float(np.ptp(sample[0], axis=0).max()), 3))

    def frame(k: int, cam: Any, supersample: int = 1) -> np.ndarray:
        surf = surface(k)
        objs = [surf, ground.with_casters(_area_samples(surf)), *_blade_polygons(blades, times[k], dt)]
        return render(objs, cam, supersample=supersample).color

    vcam = Camera.fit(framed, max(640, size[0]), max(480, size[1]), direction=direction, margin=1.1)
    write_video((frame(k, vcam) for k in range(n)), out / "movie.mp4", fps=min(30.0, n / max(times[-1], 1e-9)))
    ctx.video(out / "movie.mp4", caption)
    cam = vcam.resized(*size)
    strip = np.concatenate([frame(min(k, n - 1), cam, 2) for k in picks], axis=1)
    save_image(out / "frames.png", strip)
    ctx.image(out / "frames.png", f"{caption}: frames {', '.join(str(min(k, n - 1)) for k in picks)}")
    # keep the shown frames only (the gallery's size); mesh.pvd lists what is left
    from unmesh.fem.vtk_io import write_pvd

    kept = ctx.keep_frames(out, [min(k, n - 1) for k in picks])
    vtus = [(f, e["time"]) for e in kept for f in e["files"] if f.endswith(".vtu")]
    write_pvd(out / "mesh.pvd", [f for f, _ in vtus], [t for _, t in vtus])


def _per_frame(summary: dict[str, Any]) -> float:
    """Median over the frames of solve + re-integration + cut seconds: a warm figure (the first
    frames include numba compilation on a cold cache, which a mean would spread over the run)."""
    fr = summary["frames"][1:]
    return float(np.median([f["solve_seconds"] + f["reintegration_seconds"] + f.get("cut_seconds", 0.0)
                            for f in fr])) if fr else 0.0


@example("fem-single-element", "A single 12-node element dropped on the ground (Fig. 9.3)", section="FEM")
def single_element(ctx: ExampleContext) -> None:
    """One convex element with 12 nodes (a hexagonal antiprism): its mean value shape functions
    are non-linear, so the single element deforms non-linearly on impact, bounces and settles
    (Y = 50, ν = 0.3, Δt = 0.001, implicit Euler, stiffness warping)."""
    out, s = run_shipped_scene(ctx, "single_element", {"simulation.duration": 0.8} if ctx.quick else {})
    ctx.metric("nodes / elements", f"{s['nodes_initial']} / {s['elements_initial']}", "(thesis: 12 / 1)")
    ctx.metric("solve time per frame (median)", round(_per_frame(s), 4), "s (thesis: 0.012 s on 2007 hardware)")
    size = (240, 180) if ctx.quick else (480, 360)
    _render_run(ctx, out, s, (2.2, 1.3, 2.6), (0.0, 0.4, 0.0), [0, 12, 16, 20, 30, 60], "12-node element", size)


@example("fem-random-planes-cube", "A cube split by 30 random planes falls (Fig. 9.4)", section="FEM")
def random_planes(ctx: ExampleContext) -> None:
    """A single hexahedral element is split 30 times by random planes (9.3.1), each time in a
    randomly chosen element: a consistent mesh of 31 highly irregular convex elements (one
    colour each) that falls and deforms on impact."""
    out, s = run_shipped_scene(ctx, "random_planes_cube", {"simulation.duration": 0.7} if ctx.quick else {})
    last = s["frames"][-1]
    ctx.metric("nodes / elements after the splits", f"{last['nodes']} / {last['elements']}", "(thesis: 184 / 31)")
    ctx.metric("volume after the splits", round(last["volume"], 12), "(1 before)")
    ctx.metric("solve time per frame (median)", round(_per_frame(s), 4), "s (thesis: 0.22 s on 2007 hardware)")
    size = (240, 180) if ctx.quick else (480, 360)
    _render_run(ctx, out, s, (2.0, 1.5, 2.6), (0.0, 0.45, 0.0), [0, 9, 13, 18, 30, 74], "random planes", size,
                by_element=True)


@example("fem-progressive-slicing", "Progressive slicing of a 3×3×3 hexahedral block (Fig. 9.9)", section="FEM")
def progressive(ctx: ExampleContext) -> None:
    """Two slanted blades move down through a block of 27 hexahedra (9.3.2). Each step cuts the
    quad the blade swept: crossed elements are split by its plane, in-plane faces along the
    blade, and nodes inside the swept area are duplicated, so the slices separate and topple.
    Only the nodes needed to sample the cut surface are created; elements are not subdivided."""
    over = {"simulation.duration": 1.2} if ctx.quick else {}
    out, s = run_shipped_scene(ctx, "progressive_slicing", over)
    first, last = s["frames"][0], s["frames"][-1]
    ctx.metric("nodes", f"{first['nodes']} -> {last['nodes']}", "(thesis: 64 -> 1214)")
    ctx.metric("elements", f"{first['elements']} -> {last['elements']}", "(thesis: 27 -> 60)")
    ctx.metric("volume drift", f"{abs(last['volume'] - first['volume']):.2e}")
    ctx.metric("time per frame (solve + re-integration + cut, median)", round(_per_frame(s), 3),
               "s (thesis: 0.8 s, 0.04 s without re-integration)")
    size = (240, 180) if ctx.quick else (480, 360)
    _render_run(ctx, out, s, (1.7, 1.6, 2.4), (0.0, 0.4, 0.0), [0, 12, 25, 40, 55, 75], "progressive slicing", size,
                "progressive_slicing")


@example("fem-blob-slicing", "Slicing a tetrahedralised organic blob (Fig. 9.10)", section="FEM")
def blob(ctx: ExampleContext) -> None:
    """The built-in bunny-like blob, tetrahedralised with TetGen, is sliced on both sides by two
    tilted blades moving through it; the slices separate and tip over. Cut tetrahedra become
    general convex polyhedra (Y = 3000, ν = 0.3, Δt = 0.04)."""
    over = {"simulation.duration": 1.4, "objects[0].mesh.spacing": 0.15} if ctx.quick else {}
    out, s = run_shipped_scene(ctx, "blob_slicing", over)
    first, last = s["frames"][0], s["frames"][-1]
    ctx.metric("nodes", f"{first['nodes']} -> {last['nodes']}")
    ctx.metric("elements", f"{first['elements']} -> {last['elements']}")
    ctx.metric("time per frame (solve + re-integration + cut, median)", round(_per_frame(s), 3), "s (thesis: 6.08 s)")
    ctx.metric("cut steps skipped as degenerate", sum(f.get("cuts_skipped", 0) for f in s["frames"]))
    size = (240, 180) if ctx.quick else (480, 360)
    _render_run(ctx, out, s, (0.9, 1.5, 2.8), (0.0, 0.4, 0.0), [0, 15, 30, 45, 60, 75], "blob slicing", size,
                "blob_slicing")


@example("fem-accuracy", "Patch test and cantilever convergence", section="FEM")
def accuracy(ctx: ExampleContext) -> None:
    """Linear fields are reproduced exactly on irregular polyhedra only with the consistency
    correction (the sampled gradients integrate exactly); a 10×1×1 cantilever (Y = 1000,
    ν = 0.3, end load 1) converges towards the Euler–Bernoulli tip deflection 4.0."""
    from unmesh.fem import cut_by_plane, hex_grid, solve_static, voronoi_foam

    rng = np.random.default_rng(1)
    cube = hex_grid((2, 2, 2))
    for _ in range(6):
        cube = cut_by_plane(cube, rng.random(3), rng.normal(size=3))
    A = rng.normal(size=(3, 3)) * 1e-2
    for name, mesh in (("Voronoi foam (40 cells)", voronoi_foam(40, seed=4)), ("cube cut by 6 planes", cube)):
        exact = mesh.points @ A.T
        bnd = np.unique(mesh.boundary_triangles())
        for corr in (False, True):
            u = solve_static(mesh, 1e3, 0.3, bnd, np.zeros_like(exact), displacements=exact, correction=corr)
            err = float(np.abs(u - exact).max() / np.abs(exact).max())
            ctx.metric(f"patch test, {name}, {'with' if corr else 'without'} correction", f"{err:.2e}")
    sizes = (10, 20) if ctx.quick else (10, 20, 40, 80)
    rows = []
    tiny = hex_grid((2, 1, 1))  # compile before the timed solves
    solve_static(tiny, 1e3, 0.3, np.arange(4), np.ones((tiny.n_nodes, 3)))
    for nx in sizes:
        m = hex_grid((nx, nx // 10, nx // 10), size=(10, 1, 1))
        left = np.flatnonzero(np.isclose(m.points[:, 0], 0))
        right = np.flatnonzero(np.isclose(m.points[:, 0], 10))
        y, z = m.points[right, 1], m.points[right, 2]
        w = np.where(np.isclose(y, 0) | np.isclose(y, 1), 0.5, 1.0) * np.where(np.isclose(z, 0) | np.isclose(z, 1), 0.5, 1.0)
        f = np.zeros((m.n_nodes, 3))
        f[right, 1] = -w / w.sum()
        t = time.perf_counter()
        d = float(-solve_static(m, 1e3, 0.3, left, f)[right, 1].mean())
        rows.append(f"{nx}×{nx // 10}×{nx // 10} cells ({m.n_elements}): tip deflection {d:.4f} "
                    f"({100 * (d / 4 - 1):+.1f} %, {time.perf_counter() - t:.1f} s)")
        ctx.metric(f"cantilever {nx}×{nx // 10}×{nx // 10}", round(d, 4), "(Euler–Bernoulli: 4.0)")
    ctx.text("Cantilever convergence on cube cells: " + "; ".join(rows) + ". scikit-fem on the same problem: linear "
             "tetrahedra 3.58 (12,960 tets), trilinear hexahedra 3.94 (2,160).")
