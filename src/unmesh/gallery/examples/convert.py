"""Gallery examples of point-cloud-to-textured-mesh conversion (thesis chapter 6).

``convert-resolutions`` (Fig. 6.6): the blob with a procedural colour pattern and carved
normal detail, converted at several mesh resolutions; textured meshes with and without the
normal map, the surfels and the meshes.
``convert-atlas`` (Fig. 6.2): the packed colour atlas of one conversion, with its fill.
``convert-sampling`` (Fig. 6.4): surfel sampling against triangle sampling: the mesh follows
the geometry, the patch sizes follow the colour detail.

``convert-painted`` (Fig. 6.3): a model painted with the chapter 5 engine (a shipped stroke
file replayed) converted to a textured mesh; painted triangles get large patches, bare ones
tiny patches.
"""

from __future__ import annotations

import time
from functools import lru_cache
from typing import Any

import numpy as np

from unmesh.gallery.figures import tile
from unmesh.gallery.registry import ExampleContext, example

__all__: list[str] = []

SECTION = "Conversion: surfels to textured meshes"


@lru_cache(maxsize=2)
def _plain_blob(spacing: float) -> Any:
    from unmesh.shapes import Blob

    return Blob().surfels(spacing)


@lru_cache(maxsize=2)
def _blob_cloud(spacing: float, carved: bool = True) -> Any:
    """The blob's surfels with a colour pattern (stripes and spots) and carved normal detail."""
    cloud = _plain_blob(spacing)
    p = cloud.positions
    stripes = 0.5 + 0.5 * np.sin(14.0 * p[:, 1] + 4.0 * np.sin(5.0 * p[:, 0]))
    spots = (np.sin(11.0 * p[:, 0]) * np.sin(11.0 * p[:, 2]) > 0.55).astype(float)
    col = np.c_[0.85 - 0.35 * stripes, 0.55 + 0.25 * stripes, 0.35 + 0.1 * stripes]
    col = np.where(spots[:, None] > 0, [0.75, 0.2, 0.15], col)
    if not carved:
        return cloud.replace(colors=np.clip(col, 0, 1))
    n = cloud.normals
    bump = 0.35 * np.c_[np.sin(25 * p[:, 1]), np.sin(25 * p[:, 2]), np.sin(25 * p[:, 0])]
    bump -= np.einsum("ij,ij->i", bump, n)[:, None] * n
    return cloud.replace(colors=np.clip(col, 0, 1), normals=n + bump)


@lru_cache(maxsize=8)
def _converted(spacing: float, faces: int) -> Any:
    from unmesh.convert import ConvertOptions, convert_cloud

    t0 = time.perf_counter()
    res = convert_cloud(_blob_cloud(spacing), ConvertOptions(faces=faces))
    return res, time.perf_counter() - t0


def _spacing(ctx: ExampleContext) -> float:
    return 0.03 if ctx.quick else 0.016


def _camera(bounds: np.ndarray, size: int) -> Any:
    from unmesh.render import Camera

    return Camera.framing(bounds, size, size, fov=30)


def _still(obj: Any, cam: Any, closed: bool = True, **options: Any) -> np.ndarray:
    """A still (H,W,3) anti-aliased by 2x2 supersampling; surfels of a ``closed`` model cull their
    back faces (no far-side splats poking through)."""
    from unmesh.render import render
    from unmesh.render.options import STILL_SUPERSAMPLE
    from unmesh.render.splat import SplatOptions

    return render(obj, cam, supersample=STILL_SUPERSAMPLE, splat=SplatOptions(cull_backfaces=closed), **options).color

@example("convert-resolutions", "Converted blob at several mesh resolutions (Fig. 6.6)", section=SECTION)
def resolutions_example(ctx: ExampleContext) -> None:
    """The blob's surfels (colour pattern plus carved normal detail) converted to textured
    meshes of decreasing triangle count. First column: the surfels (top), the same surfels with
    smooth normals (middle) and shrunk to show the sampling (bottom). Other columns, top row:
    textured meshes with the tangent-space normal map; middle row: without it; bottom row: the
    bare meshes. The colour survives strong simplification; without the normal map the carved
    detail disappears; at 40 triangles the orthographic patches distort (Fig. 6.7)."""
    from unmesh.render import save_image

    spacing = _spacing(ctx)
    counts = (600, 150, 40) if ctx.quick else (3000, 800, 200, 40)
    cloud = _blob_cloud(spacing)
    size = 150 if ctx.quick else 260
    cam = _camera(cloud.bounds(), size)
    small = cloud.replace(radii=0.4 * cloud.radii)
    # the carved detail tilts the surfel normals by up to 30 degrees, which opens gaps between
    # discs of the sampling's radii (a tilted disc covers cos 30 = 0.87 of its width): drawn 1.3x
    top = [_still(cloud.replace(radii=1.3 * cloud.radii), cam)]
    mid = [_still(_blob_cloud(spacing, carved=False), cam)]
    bottom = [_still(small, cam)]
    for faces in counts:
        res, dt = _converted(spacing, faces)
        top.append(_still(res.textured, cam))
        mid.append(_still(res.textured.without_normal_map(), cam))
        bottom.append(_still(res.mesh, cam, shading="phong"))
        rep = res.report
        ctx.metric(f"{faces} faces: texels", rep["patches"]["texels_total"])
        ctx.metric(f"{faces} faces: atlas fill", round(100 * rep["atlas"]["fill_total"], 1), "%")
        ctx.metric(f"{faces} faces: conversion time", round(dt, 2), "s")
    grid = tile([*top, *mid, *bottom], len(counts) + 1)
    path = ctx.path("resolutions.png")
    save_image(path, grid)
    ctx.image(path, "First column: the surfels with their carved normals, with smooth normals, shrunk to 40 %; "
                    f"other columns: {', '.join(map(str, counts))} triangles, textured with the normal map, "
                    "without it, and the bare mesh")
    ctx.metric("surfels", len(cloud))


@example("convert-atlas", "Packed texture atlas (Fig. 6.2)", section=SECTION)
def atlas_example(ctx: ExampleContext) -> None:
    """The colour pages of one conversion (Algorithm 6.1): triangular patches with their borders
    in rows of similar height, every second one upside down, pushed to the left and up into the
    gaps, left-over patches in the holes. Page edges are powers of two; the fill counts the
    texels the patches need (borders included)."""
    from unmesh.render import save_image

    spacing = _spacing(ctx)
    faces = 600 if ctx.quick else 800
    res, _ = _converted(spacing, faces)
    pages = [p.texture for p in res.textured.parts]
    zoom = max(1, 1024 // sum(p.shape[1] + 4 for p in pages))
    height = max(p.shape[0] for p in pages) * zoom
    strip = [np.ones((height, 4 * zoom, 3))]
    for page in pages:
        img = np.kron(page, np.ones((zoom, zoom, 1)))  # nearest-neighbour zoom: texels stay visible
        pad = np.ones((height, img.shape[1], 3))
        pad[:img.shape[0]] = img
        strip += [pad, np.ones((height, 4 * zoom, 3))]
    path = ctx.path("atlas.png")
    save_image(path, np.concatenate(strip, axis=1))
    sizes = ", ".join(f"{p.shape[1]}" for p in pages)
    fills = ", ".join(f"{100 * f:.0f} %" for f in res.report["atlas"]["fill"])
    ctx.image(path, f"{len(pages)} colour pages at the same texel scale, edges {sizes} texels, used {fills}")
    ctx.metric("pages", len(pages))
    ctx.metric("fill (all pages)", round(100 * res.report["atlas"]["fill_total"], 1), "%")
    ctx.metric("triangles", res.report["patches"]["triangles"])


@example("convert-sampling", "Surfel sampling and triangle sampling (Fig. 6.4)", section=SECTION)
def sampling_example(ctx: ExampleContext) -> None:
    """Left: the surfels, shrunk to 40 % to show the sampling. Right: the mesh, each triangle
    coloured by the refinement level of its colour patch (dark: 1 texel along the longest
    edge, bright: the most). The mesh resolution follows the geometry only; the patch
    resolution follows the colour detail."""
    from unmesh.meshes import TriangleMesh
    from unmesh.render import map_colors, save_image

    spacing = _spacing(ctx)
    faces = 600 if ctx.quick else 800
    res, _ = _converted(spacing, faces)
    cloud = _blob_cloud(spacing)
    size = 200 if ctx.quick else 360
    cam = _camera(cloud.bounds(), size)
    small = cloud.replace(radii=0.4 * cloud.radii)
    left = _still(small, cam)
    mesh = res.mesh
    level = np.asarray(res.report["_color_levels"], dtype=float)
    col = map_colors(level, 0.0, max(float(level.max()), 1.0), "viridis")
    split = TriangleMesh(mesh.vertices[mesh.faces].reshape(-1, 3), np.arange(3 * len(mesh.faces)).reshape(-1, 3),
                         vertex_colors=np.repeat(col, 3, axis=0))
    right = _still(split, cam)
    path = ctx.path("sampling.png")
    save_image(path, tile([left, right], 2))
    ctx.image(path, "Surfels (shrunk) and mesh triangles coloured by the refinement level of their colour patch")
    ctx.metric("patch levels (count per level)", str(np.bincount(level.astype(int)).tolist()))


@example("convert-painted", "A painted model converted to a textured mesh (Fig. 6.3)", section=SECTION)
def painted_example(ctx: ExampleContext) -> None:
    """A model painted with the chapter 5 engine (the shipped stroke file ``art``, replayed on
    the blob; quick mode: the watercolour stroke of ``diffusion`` on the plane) converted to a
    textured mesh. Left: the painted surfels; middle: the textured mesh; right: the mesh, each
    triangle coloured by the number of texels of its patch (log scale). Painted triangles get
    large patches, bare ones a few texels (thesis: 5,228 vs 6 pixels)."""
    import copy

    from unmesh.convert import ConvertOptions, convert_cloud
    from unmesh.convert.patches import patch_size, triangle_frames
    from unmesh.gallery.examples.paint import model_for, shipped_strokes
    from unmesh.meshes import TriangleMesh
    from unmesh.paint import PaintOptions, Session
    from unmesh.render import Camera, map_colors, render, save_image

    data = copy.deepcopy(shipped_strokes("diffusion" if ctx.quick else "art"))
    if not ctx.quick:
        data["strokes"] = data["strokes"][:4]
    session = Session(model_for(data), PaintOptions(haptics=False))
    session.replay(data)
    cloud = session.cloud()
    faces = 150 if ctx.quick else 1500
    res, seconds = ctx.timed(convert_cloud, cloud, ConvertOptions(faces=faces),
                             warm=lambda: convert_cloud(cloud.subset(np.arange(0, len(cloud), 8)),
                                                        ConvertOptions(faces=100)))
    mesh = res.mesh
    w, h = patch_size(triangle_frames(mesh), np.asarray(res.report["_levels"]))
    texels = (w * h).astype(float)
    col = map_colors(np.log2(texels), np.log2(4.0), max(float(np.log2(texels.max())), 4.0), "viridis")
    split = TriangleMesh(mesh.vertices[mesh.faces].reshape(-1, 3), np.arange(3 * len(mesh.faces)).reshape(-1, 3),
                         vertex_colors=np.repeat(col, 3, axis=0))
    size = 200 if ctx.quick else 340
    if ctx.quick:
        cam = Camera((0, 2.0, 0), (0, 0, 0), up=(0, 0, -1), width=size, height=size, ortho=1.05)
    else:
        cam = Camera.framing(cloud.bounds(), size, size, fov=30, direction=(0.0, 0.15, 1.0))
    a = render(cloud, cam)
    b = render(res.textured, cam)
    both = a.coverage & b.coverage
    psnr = 10 * np.log10(1.0 / np.mean((a.color[both] - b.color[both]) ** 2))
    path = ctx.path("painted.png")
    closed = not ctx.quick  # the blob (full) or the open canvas (quick)
    save_image(path, tile([_still(cloud, cam, closed), _still(res.textured, cam), _still(split, cam)], 3))
    ctx.image(path, f"Painted surfels ({len(cloud)}), the textured mesh ({len(mesh.faces)} triangles), and the "
                    "triangles coloured by the texels of their patch (dark: 9, bright: the most, log scale)")
    ctx.metric("PSNR textured mesh vs surfels (pixels both cover)", round(float(psnr), 1), "dB")
    ctx.metric("texels per patch: smallest, median, largest", f"{int(texels.min())}, {int(np.median(texels))}, "
                                                              f"{int(texels.max())}")
    ctx.metric("atlas fill", round(100 * res.report["atlas"]["fill_total"], 1), "%")
    ctx.metric("conversion time (warm)", round(seconds, 2), "s")
