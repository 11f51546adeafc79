"""Analysis: where one view's error between the splatted surfels and the textured mesh sits (issue #20).

Converts the model as ``bench_convert.py`` does (same procedural colours, default thresholds),
then for one view renders the surfels (splatter), the textured mesh (rasteriser) and the ray-cast
MLS surface of the same surfels (the arbiter: about 15 s), and prints

* PSNR of each pair on the pixels both cover (mesh vs splats is the issue #20 figure),
* the pixels only one rendering covers (the splats' overhang past the MLS surface),
* the share of the squared error within 1-4 pixels of the outline, at depth differences above
  a few thresholds, and the PSNR without the worst 100-3000 pixels,
* the attribution of the error to albedo and to normals (the G-buffers shaded crosswise),
* the splats with other screen filters (``--filters``) and with back-face culling, against the
  mesh in all views and against the ray-cast surface in this one.

``--png DIR`` writes the three renderings, the per-pixel error (x4) and a coverage map (red:
splats only, blue: mesh only), each magnified 2x, plus crops ``--crop r0 r1 c0 c1`` (x6), for
a look with an image viewer (docs/performance.md, stop 35). Not part of the test suite.

Usage::

    python benchmarks/analyze_convert_view.py [--model PATH] [--view 3] [--png DIR] [--crop 30 90 90 150]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

DEFAULT_MODEL = Path(__file__).resolve().parents[2] / "shared" / "data" / "models" / "igea.ply"


def _psnr(x, y) -> float:
    both = x.coverage & y.coverage
    return float(10 * np.log10(1.0 / np.mean((x.color[both] - y.color[both]) ** 2)))


def _save(img: np.ndarray, path: Path, scale: int) -> None:
    from PIL import Image

    a = (np.clip(img, 0, 1) * 255).astype(np.uint8)
    Image.fromarray(a).resize((a.shape[1] * scale, a.shape[0] * scale), Image.NEAREST).save(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default=os.fspath(DEFAULT_MODEL))
    ap.add_argument("--view", type=int, default=3)
    ap.add_argument("--views", type=int, default=6)
    ap.add_argument("--filters", type=float, nargs="*", default=[1.0, 0.9, 0.8])
    ap.add_argument("--png", default=None)
    ap.add_argument("--crop", type=int, nargs=4, default=None)
    args = ap.parse_args()

    from scipy import ndimage

    from bench_convert import patterned_cloud  # the benchmark's input (run from benchmarks/ or as a script)
    from unmesh.convert import ConvertOptions, convert_cloud
    from unmesh.render import Camera, render
    from unmesh.render.shading import GBuffer, shade
    from unmesh.render.splat import SplatOptions

    cloud = patterned_cloud(args.model)
    res = convert_cloud(cloud, ConvertOptions())
    center = cloud.positions.mean(axis=0)
    size = np.ptp(cloud.positions, axis=0).max()

    def camera(k: int) -> Camera:
        ang = 2 * np.pi * k / args.views
        eye = center + 2.2 * size * np.array([np.sin(ang), 0.2, np.cos(ang)])
        return Camera(eye, center, width=400, height=400, fov=30)

    cam = camera(args.view)
    a, b = render(cloud, cam), render(res.textured, cam)
    c = render(cloud, cam, method="raycast")
    print(f"view {args.view}: mesh vs splats {_psnr(a, b):.2f} dB, mesh vs ray cast {_psnr(b, c):.2f} dB, "
          f"splats vs ray cast {_psnr(a, c):.2f} dB")
    print(f"pixels covered only by: splats vs ray cast {(a.coverage & ~c.coverage).sum()}, ray cast vs splats "
          f"{(c.coverage & ~a.coverage).sum()}, mesh vs ray cast {(b.coverage & ~c.coverage).sum()}, ray cast vs "
          f"mesh {(c.coverage & ~b.coverage).sum()}, splats vs mesh {(a.coverage & ~b.coverage).sum()}, mesh vs "
          f"splats {(b.coverage & ~a.coverage).sum()}")
    both = a.coverage & b.coverage
    se = np.where(both, ((a.color - b.color) ** 2).mean(-1), 0.0)
    tot, n = se.sum(), both.sum()
    outline = ndimage.distance_transform_edt(a.coverage | b.coverage)
    for d in (1, 2, 3, 4):
        m = both & (outline <= d)
        print(f"  within {d} px of the outline: {m.sum()} px, {100 * se[m].sum() / tot:.1f} % of the squared error")
    dz = np.where(both, a.depth - np.where(both, b.depth, 0.0), 0.0)
    for t in (1e-3, 2e-3, 5e-3, 1e-2):
        m = both & (np.abs(dz) > t)
        front = float((dz[m] < 0).mean()) if m.any() else 0.0
        print(f"  |depth difference| > {t:g}: {m.sum()} px, {100 * se[m].sum() / tot:.1f} % of the squared error, "
              f"splat in front on {100 * front:.1f} %")
    worst = np.sort(se[both])[::-1]
    print("  PSNR without the worst k pixels: " + ", ".join(
        f"k={k}: {10 * np.log10((n - k) / worst[k:].sum()):.2f} dB" for k in (100, 300, 1000, 3000)))

    def shaded(alb, nrm, g):
        return shade(GBuffer(np.ascontiguousarray(alb), np.ascontiguousarray(nrm), g.depth, g.coverage,
                             np.ones(g.coverage.shape)), cam)

    def ps(x, y):
        return 10 * np.log10(1.0 / ((x - y) ** 2).mean(-1)[both].mean())

    print(f"  attribution: albedo only {ps(a.color, shaded(b.albedo, a.normal, a)):.2f} dB, normals only "
          f"{ps(a.color, shaded(a.albedo, b.normal, a)):.2f} dB, unlit albedo {ps(a.albedo, b.albedo):.2f} dB")

    variants = {f"filter {r:g}": SplatOptions(filter_radius=r) for r in args.filters}
    variants["default, back faces culled"] = SplatOptions(cull_backfaces=True)
    meshes = [render(res.textured, camera(k)) for k in range(args.views)]
    print(f"splatter variants (default filter {SplatOptions().filter_radius:g} px): mesh vs splats per view; "
          f"view {args.view}: splats vs ray cast, overhang")
    for name, so in {"default": SplatOptions(), **variants}.items():
        row = [_psnr(render(cloud, camera(k), splat=so), meshes[k]) for k in range(args.views)]
        s = render(cloud, cam, splat=so)
        print(f"  {name:28s} {np.round(row, 2).tolist()}  {_psnr(s, c):.2f} dB, "
              f"{(s.coverage & ~c.coverage).sum()} px")

    if args.png:
        out = Path(args.png)
        out.mkdir(parents=True, exist_ok=True)
        err = np.repeat(np.sqrt(se)[..., None] * 4, 3, axis=-1)
        cov = np.zeros((*se.shape, 3))
        cov[a.coverage & ~b.coverage] = (1, 0, 0)
        cov[b.coverage & ~a.coverage] = (0, 0, 1)
        cov[both] = 0.3
        images = {"splats": a.color, "mesh": b.color, "raycast": c.color, "error": err, "coverage": cov}
        for name, img in images.items():
            _save(img, out / f"view{args.view}_{name}.png", 2)
        if args.crop:
            r0, r1, c0, c1 = args.crop
            sep = np.ones((r1 - r0, 2, 3))
            tiles = []
            for img in images.values():
                tiles += [img[r0:r1, c0:c1], sep]
            tiles.pop()
            _save(np.concatenate(tiles, axis=1), out / f"view{args.view}_crop.png", 6)
        print(f"images in {out}")


if __name__ == "__main__":
    main()
