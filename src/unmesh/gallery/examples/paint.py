"""Gallery examples of 3D painting (thesis chapter 5), replayed from shipped stroke files.

``paint-backtransfer``: a stroke through wet paint with and without back-transfer (Fig. 5.8).
``paint-diffusion``: a watercolour stroke with and without diffusion, and its wet-volume
distribution (Fig. 5.9). ``paint-relief``: hair imprints in viscous paint, beaten gold and
metallic paint (Fig. 5.10). ``paint-downsampling``: a painted blob before and after
downsampling with its sampling density (Fig. 5.7). ``paint-art``: a multi-colour design on the
bunny-like blob with its density map ("art on bunnies", Fig. 5.12).

The stroke files are in ``unmesh/scenes/paint/*.json`` (format: ``docs/paint.md``); their extra
key ``"model"`` names the model they were drawn on.
"""

from __future__ import annotations

import copy
import json
import time
from importlib import resources
from typing import Any

import numpy as np

from unmesh.gallery.registry import ExampleContext, example

__all__ = ["model_for", "shipped_strokes"]


def shipped_strokes(name: str) -> dict[str, Any]:
    """A shipped stroke file ``unmesh/scenes/paint/<name>.json`` as a dict."""
    text = resources.files("unmesh.scenes").joinpath("paint", f"{name}.json").read_text(encoding="utf-8")
    return json.loads(text)


def model_for(data: dict[str, Any]) -> Any:
    """The surfel model a shipped stroke file was drawn on (its ``"model"`` key)."""
    from unmesh.shapes import by_name
    from unmesh.surfels import sample_mesh

    m = data["model"]
    if m["shape"] == "plane":
        return by_name("plane", size=m["size"]).surfels(m["spacing"])
    return sample_mesh(by_name(m["shape"]).mesh(m["mesh_spacing"]), m["spacing"])


def _replay(cloud: Any, data: dict[str, Any], strokes: int | None = None) -> Any:
    from unmesh.paint import PaintOptions, Session

    s = Session(cloud, PaintOptions(haptics=False))
    d = copy.deepcopy(data)
    if strokes is not None:
        d["strokes"] = d["strokes"][:strokes]
    s.replay(d)
    return s


def _canvas_camera(width: int, height: int, extent: float, centre: tuple[float, float] = (0.0, 0.0)) -> Any:
    from unmesh.render import Camera

    cx, cz = centre
    return Camera((cx, 2.0, cz), (cx, 0.0, cz), up=(0, 0, -1), width=width, height=height, ortho=extent)


def _closed() -> Any:
    from unmesh.render.splat import SplatOptions

    return SplatOptions(cull_backfaces=True)


def _still(session: Any, camera: Any, **options: Any) -> np.ndarray:
    """The session's image (H,W,3) through ``camera``, anti-aliased: rendered 2x2 larger and averaged."""
    from unmesh.render.options import STILL_SUPERSAMPLE as K

    h, w = camera.shape
    big = session.render(camera.resized(w * K, h * K), **options).color
    return big.reshape(h, K, w, K, big.shape[-1]).mean(axis=(1, 3))


def _side_by_side(images: list[np.ndarray], gap: int = 6) -> np.ndarray:
    h = max(i.shape[0] for i in images)
    parts = []
    for k, img in enumerate(images):
        if k:
            parts.append(np.ones((h, gap, 3)))
        pad = np.ones((h - img.shape[0], img.shape[1], 3))
        parts.append(np.concatenate([img, pad]))
    return np.concatenate(parts, axis=1)


def _stacked(images: list[np.ndarray], gap: int = 6) -> np.ndarray:
    w = images[0].shape[1]
    parts = []
    for k, img in enumerate(images):
        if k:
            parts.append(np.ones((gap, w, 3)))
        parts.append(img)
    return np.concatenate(parts, axis=0)


def _density_colors(session: Any, cmap: str = "magma") -> tuple[Any, float, float]:
    """The visible surfels coloured by sampling density (surfels per unit area, log10)."""
    from unmesh.render import map_colors

    c = session.cloud()
    dens = np.log10(1.0 / (np.pi * c.radii ** 2))
    lo, hi = float(np.floor(dens.min() * 2) / 2), float(np.ceil(dens.max() * 2) / 2)
    return c.replace(colors=np.clip(map_colors(dens, lo, hi, cmap), 0, 1)), lo, hi


@example("paint-backtransfer", "Stroke through wet paint: with and without back-transfer (Fig. 5.8)",
         section="Painting")
def paint_backtransfer(ctx: ExampleContext) -> None:
    from unmesh.render import save_image

    data = shipped_strokes("backtransfer")
    cloud = model_for(data)
    size = (320, 200) if ctx.quick else (560, 340)
    cam = _canvas_camera(*size, extent=0.62)
    images, t0 = [], time.perf_counter()
    events = 0
    for back in (None, 0.0):
        d = copy.deepcopy(data)
        if back is not None:
            d["strokes"][-1]["paint"]["back_transfer"] = back
        s = _replay(cloud, d)
        events += sum(len(st["samples"]) for st in d["strokes"])
        images.append(_still(s, cam, brush=False))
    elapsed = time.perf_counter() - t0
    path = ctx.path("backtransfer.png")
    save_image(path, _stacked(images))
    ctx.image(path, "A yellow stroke drawn across two wet blue bands. Top: bidirectional transfer, the brush "
                    "picks up blue and carries it on. Bottom: no transfer from the surface to the brush.")
    ctx.metric("paint events per second (replay, both images)", round(events / elapsed, 1))
    ctx.metric("surfels after painting", len(s.cloud()))


@example("paint-diffusion", "Watercolour with and without diffusion, and the wet-volume distribution (Fig. 5.9)",
         section="Painting")
def paint_diffusion(ctx: ExampleContext) -> None:
    from unmesh.render import draw_legend, map_colors, render, save_image
    from unmesh.render.options import STILL_SUPERSAMPLE as K

    data = shipped_strokes("diffusion")
    cloud = model_for(data)
    size = (320, 180) if ctx.quick else (520, 300)
    cam = _canvas_camera(*size, extent=0.4)
    d0 = copy.deepcopy(data)
    d0["strokes"][0]["paint"]["diffusion"] = 0.0
    dry = _replay(cloud, d0)
    wet = _replay(cloud, data)
    images = [_still(dry, cam, brush=False), _still(wet, cam, brush=False)]
    c = wet.cloud()
    S = wet.surface
    rows = S.visible_rows()
    thick = S.vw[rows] / S.area[rows]
    hi = float(thick.max())
    vol = render(c.replace(colors=np.clip(map_colors(thick, 0.0, hi, "viridis"), 0, 1)), cam, shading="none", supersample=K).color
    vol = draw_legend(vol, 0.0, hi, "viridis", "wet paint thickness")
    path = ctx.path("diffusion.png")
    save_image(path, _stacked([*images, vol]))
    ctx.image(path, "Top: a watercolour stroke without diffusion. Middle: the same stroke after 4 s of "
                    "surface diffusion. Bottom: its wet-paint thickness.")
    v0 = dry.surface.total_volume()
    ctx.metric("paint volume, no diffusion vs diffusion (relative difference)",
               f"{abs(wet.surface.total_volume() - v0) / v0:.1e}")


@example("paint-relief", "Hair imprints in viscous paint, beaten gold, metallic paint (Fig. 5.10)",
         section="Painting")
def paint_relief(ctx: ExampleContext) -> None:
    from unmesh.render import Camera, Light, Shading, save_image

    data = shipped_strokes("relief")
    cloud = model_for(data)
    s = _replay(cloud, data, strokes=None)
    size = (480, 200) if ctx.quick else (900, 360)
    cam = Camera((0.02, 0.9, 0.55), (0.02, 0.0, 0.0), up=(0, 1, 0), width=size[0], height=size[1], fov=26)
    grazing = Shading(lights=(Light((-0.8, 0.6, -0.4), intensity=0.6), Light((0.3, 0.3, -1.0), intensity=0.2)),
                      ambient=0.2, specular=0.3, shininess=30.0)
    img = _still(s, cam, shading=grazing, brush=False)
    path = ctx.path("relief.png")
    save_image(path, img)
    ctx.image(path, "Left: oil paint with hair imprints along the strokes. Middle: beaten gold, small patches "
                    "with one normal each. Right: metallic paint reflecting a sky environment map.")
    S = s.surface
    rows = S.visible_rows()
    ctx.metric("largest relief height (world units)", f"{float(S.lift[rows].max()):.4f}")


@example("paint-downsampling", "Before and after downsampling, with the sampling density (Fig. 5.7)",
         section="Painting")
def paint_downsampling(ctx: ExampleContext) -> None:
    from unmesh.render import Camera, draw_legend, render, save_image
    from unmesh.render.options import STILL_SUPERSAMPLE as K

    data = shipped_strokes("downsampling")
    cloud = model_for(data)
    for st in data["strokes"]:
        st.pop("advance", None)
    s = _replay(cloud, data, strokes=2 if ctx.quick else None)
    s.advance(3.0, downsample=False)  # the paint dries (opaque, uniform colour)
    size = (300, 225) if ctx.quick else (440, 330)
    cam = Camera.framing(cloud.bounds(), *size, direction=(0.0, 0.15, 1.0))
    before = _still(s, cam, brush=False)
    n_before = len(s.cloud())
    dens_before, lo, hi = _density_colors(s)
    t = time.perf_counter()
    s.advance(0.0)  # drying, diffusion and downsampling; 0 s: only downsampling changes anything
    dt = time.perf_counter() - t
    after = _still(s, cam, brush=False)
    dens_after, _, _ = _density_colors(s)
    from unmesh.render import map_colors

    c = dens_after.replace(colors=np.clip(map_colors(np.log10(1.0 / (np.pi * dens_after.radii ** 2)), lo, hi,
                                                     "magma"), 0, 1))
    d0 = render(dens_before, cam, shading="none", supersample=K, splat=_closed()).color
    d1 = draw_legend(render(c, cam, shading="none", supersample=K, splat=_closed()).color, lo, hi, "magma", "log10 surfels per unit area")
    path = ctx.path("downsampling.png")
    save_image(path, _stacked([_side_by_side([before, after]), _side_by_side([d0, d1])]))
    ctx.image(path, "Top: the painted blob before (left) and after (right) downsampling. Bottom: sampling "
                    "density; after downsampling the dense samples stay only along the thin dark line and "
                    "the edges of the orange band.")
    ctx.metric("surfels before downsampling", n_before)
    ctx.metric("surfels after downsampling", len(s.cloud()))
    ctx.metric("downsampling time", round(dt, 3), "s")


def _art_palette(data: dict[str, Any]) -> Any:
    """A palette with a dab of each of the design's oil paints and a stroke mixing two of them."""
    from unmesh.paint import Brush, Paint, Palette, PaletteInset, Sample

    palette = Palette(inset=PaletteInset(corner="top-right", width=0.34, margin=6))
    colors = []
    for st in data["strokes"]:
        c = tuple(st["paint"]["color"])
        if c not in colors:
            colors.append(c)
    brush = Brush("round", 0.09)

    def dab(color: tuple[float, ...], x0: float, y0: float, x1: float, y1: float, t0: float) -> None:
        n = 6
        samples = [Sample(t0 + 0.05 * i, (x0 + (x1 - x0) * i / (n - 1), y0 + (y1 - y0) * i / (n - 1), 0.0), 0.8)
                   for i in range(n)]
        palette.session.stroke(samples, brush=brush, paint=Paint("oil", color, relief="none"))

    for k, c in enumerate(colors):
        x = -0.66 + 0.33 * k
        dab(c, x, 0.32, x, 0.12, 1.0 * k)
    dab(colors[0], -0.55, -0.22, 0.15, -0.22, 10.0)  # red, then yellow over it: orange where they mix
    dab(colors[1], -0.2, -0.32, 0.5, -0.32, 11.0)
    return palette


@example("paint-art", "Art on the blob: a multi-colour design and its sampling density (Fig. 5.12)",
         section="Painting")
def paint_art(ctx: ExampleContext) -> None:
    from unmesh.render import Camera, draw_legend, render, save_image
    from unmesh.render.options import STILL_SUPERSAMPLE as K

    data = shipped_strokes("art")
    cloud = model_for(data)
    t = time.perf_counter()
    s = _replay(cloud, data, strokes=2 if ctx.quick else None)
    elapsed = time.perf_counter() - t
    events = sum(len(st["samples"]) for st in data["strokes"][:2 if ctx.quick else None])
    size = (300, 225) if ctx.quick else (480, 360)
    cams = [Camera.framing(cloud.bounds(), *size, direction=d) for d in ((0.0, 0.15, 1.0), (0.8, 0.3, 0.7))]
    palette = _art_palette(data)
    views = [_still(s, cams[0], brush=False), _still(s, cams[1], brush=False, palette=palette)]
    dens, lo, hi = _density_colors(s)
    dmap = draw_legend(render(dens, cams[0], shading="none", supersample=K, splat=_closed()).color, lo, hi, "magma", "log10 surfels per unit area")
    path = ctx.path("art.png")
    save_image(path, _side_by_side([*views, dmap]))
    ctx.image(path, "A design painted on the bunny-like blob from the shipped stroke file: two views and the "
                    "sampling density (dense where paint landed). The second view has the palette in its "
                    "corner, drawn by the engine into the same image: the design's paints dabbed on it, "
                    "and two of them mixed by painting one over the other.")
    ctx.metric("paint events per second (replay)", round(events / elapsed, 1))
    ctx.metric("surfels: model / painted", f"{len(cloud)} / {len(s.cloud())}")
