"""Benchmark: unmesh's conversion against a peer pipeline on the same coloured scan (issue 20).

Peer pipeline (what a user would assemble from well-kept tools): Open3D's screened Poisson
reconstruction (depth 9, vertices of the lowest 2 % density cropped, as Open3D's tutorial does for
open scans), QEM simplification to the same number of triangles as unmesh's mesh
(fast-simplification), an xatlas parametrisation packed into one square page holding the same
number of texels as unmesh's atlas, and per-vertex colours (Gaussian-weighted average of the 8
nearest surfels) baked into the atlas by linear interpolation over each triangle, with a 4-texel
gutter. Both results are drawn by unmesh's rasteriser and compared with the splatted surfels
from the same 6 views (PSNR over the pixels both cover, SSIM). Fill: texels inside a chart
triangle over the page, and the same with a one-texel border (unmesh's fill counts the patch
texels with their one-texel borders).

The input is the same as ``bench_convert.py``: Igea's vertices and normals, estimated radii, a
procedural colour pattern. Both conversions run once untimed first (numba, Open3D start-up).

Needs the ``peers`` extra (``pip install -e ".[peers]"``: open3d, ~500 MB, and xatlas); without it
the script prints that and runs unmesh's conversion only.

Usage::

    python benchmarks/bench_convert_peer.py [--model PATH] [--views 6]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

DEFAULT_MODEL = Path(__file__).resolve().parents[2] / "shared" / "data" / "models" / "igea.ply"


def coloured_scan(path: str):
    """Igea's points as surfels with the procedural colour pattern of ``bench_convert.py``."""
    from unmesh import io
    from unmesh.convert import cloud_from_mesh

    cloud = cloud_from_mesh(io.load(path))
    p = (cloud.positions - cloud.positions.mean(axis=0)) / np.ptp(cloud.positions, axis=0).max()
    col = 0.55 + 0.35 * np.c_[np.sin(40 * p[:, 0]) * np.cos(30 * p[:, 1]), np.sin(25 * p[:, 2] + 3 * p[:, 0]),
                              np.cos(35 * p[:, 1])]
    return cloud.replace(colors=np.clip(col, 0, 1))


def compare(cloud, drawn, views: int) -> tuple[list[float], list[float]]:
    """PSNR (dB) over the pixels both cover and SSIM of ``drawn`` against the splatted ``cloud``, per view."""
    from skimage.metrics import structural_similarity

    from unmesh.render import Camera, render

    psnr, ssim = [], []
    center = cloud.positions.mean(axis=0)
    size = np.ptp(cloud.positions, axis=0).max()
    for k in range(views):
        ang = 2 * np.pi * k / views
        eye = center + 2.2 * size * np.array([np.sin(ang), 0.2, np.cos(ang)])
        cam = Camera(eye, center, width=400, height=400, fov=30)
        a, b = render(cloud, cam), render(drawn, cam)
        both = a.coverage & b.coverage
        psnr.append(float(10 * np.log10(1.0 / np.mean((a.color[both] - b.color[both]) ** 2))))
        ssim.append(float(structural_similarity(a.color, b.color, channel_axis=2, data_range=1.0)))
    return psnr, ssim


def vertex_colors(cloud, points: np.ndarray, k: int = 8) -> np.ndarray:
    """Gaussian-weighted colour of the ``k`` nearest surfels (sigma = the nearest one's radius), (V, 3)."""
    from unmesh.spatial import knn

    dist, idx = knn(cloud.positions, k, queries=points)
    sigma = np.maximum(cloud.radii[idx[:, 0]], 1e-12)[:, None]
    w = np.exp(-0.5 * (dist / sigma) ** 2) + 1e-30
    return (w[:, :, None] * cloud.colors[idx]).sum(axis=1) / w.sum(axis=1)[:, None]


def bake(uv: np.ndarray, faces: np.ndarray, colors: np.ndarray, side: int, gutter: int = 4):
    """Rasterise per-vertex ``colors`` over the uv triangles into a ``side`` x ``side`` page.

    Returns the page (side, side, 3) with the charts dilated by ``gutter`` texels, and the mask of
    texels whose centre lies in a chart triangle. The rasteriser is unmesh's (an orthographic
    camera over the page, unlit).
    """
    from scipy import ndimage

    from unmesh.meshes import TriangleMesh
    from unmesh.render import Camera, render

    flat = TriangleMesh(np.c_[uv * side, np.zeros(len(uv))], faces, vertex_colors=colors)
    cam = Camera((side / 2, side / 2, 1.0), (side / 2, side / 2, 0.0), up=(0, 1, 0), width=side, height=side,
                 ortho=float(side))
    res = render(flat, cam, shading="none", background=(0.0, 0.0, 0.0))
    inside = res.coverage
    page = res.color.copy()
    _, (ri, ci) = ndimage.distance_transform_edt(~inside, return_indices=True)
    grown = ndimage.binary_dilation(inside, iterations=gutter)
    page[grown] = page[ri[grown], ci[grown]]
    return page, inside


def peer_pipeline(cloud, faces: int, texels: int) -> tuple[object, dict]:
    """Open3D Poisson + QEM + xatlas + baked vertex colours (see the module docstring)."""
    import fast_simplification
    import open3d as o3d
    import xatlas
    from scipy import ndimage

    from unmesh.meshes import TriangleMesh

    times = {}
    t0 = time.perf_counter()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.positions))
    pcd.normals = o3d.utility.Vector3dVector(cloud.normals)
    mesh, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=9)
    density = np.asarray(density)
    mesh.remove_vertices_by_mask(density < np.quantile(density, 0.02))
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.triangles, dtype=np.int64)
    times["poisson"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    v, f = fast_simplification.simplify(v, f, target_reduction=max(0.0, 1.0 - faces / len(f)))
    times["qem"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    side = int(np.ceil(np.sqrt(texels)))
    atlas = xatlas.Atlas()
    atlas.add_mesh(v, f)
    pack = xatlas.PackOptions()
    pack.resolution, pack.padding, pack.bilinear = side, 1, True
    atlas.generate(xatlas.ChartOptions(), pack)
    vmap, tri, uv = atlas.get_mesh(0)
    times["xatlas"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pos = v[vmap]
    page, inside = bake(uv, tri.astype(np.int64), vertex_colors(cloud, pos), side)
    times["bake"] = time.perf_counter() - t0
    textured = TriangleMesh(pos, tri.astype(np.int64), uv=uv, texture=page)
    a = uv[tri[:, 1]] - uv[tri[:, 0]]
    b = uv[tri[:, 2]] - uv[tri[:, 0]]
    chart_area = 0.5 * float(np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())
    stats = {"faces": len(tri), "page": side, "chart_area": chart_area, "atlases": int(atlas.atlas_count), "charts": int(atlas.chart_count),
             "xatlas_utilization": [float(u) for u in np.atleast_1d(atlas.utilization)], "fill": float(inside.mean()),
             "fill_with_border": float(ndimage.binary_dilation(inside).mean()), "times": times}
    return textured, stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default=os.fspath(DEFAULT_MODEL))
    ap.add_argument("--views", type=int, default=6)
    args = ap.parse_args()

    from unmesh.convert import ConvertOptions, convert_cloud

    print(f"load average at start: {np.round(os.getloadavg(), 1).tolist()}")
    cloud = coloured_scan(args.model)
    print(f"input: {len(cloud)} points")
    convert_cloud(cloud.subset(np.arange(0, len(cloud), 50)), ConvertOptions(faces=200))  # compile
    t0 = time.perf_counter()
    ours = convert_cloud(cloud, ConvertOptions())
    ours_s = time.perf_counter() - t0
    r = ours.report
    faces = int(r["simplification"]["faces"])
    texels = int(sum(p.texture.shape[0] * p.texture.shape[1] for p in ours.textured.parts))
    psnr, ssim = compare(cloud, ours.textured, args.views)
    rows = [("unmesh", faces, texels, r["atlas"]["fill_total"], float("nan"), ours_s, psnr, ssim)]
    try:
        import open3d  # noqa: F401
        import xatlas  # noqa: F401
    except ImportError:
        print("peer pipeline: skipped (install the 'peers' extra: open3d, ~500 MB, and xatlas)")
    else:
        peer_pipeline(cloud.subset(np.arange(0, len(cloud), 20)), 500, 256 * 256)  # start-up, untimed
        t0 = time.perf_counter()
        peer, stats = peer_pipeline(cloud, faces, texels)
        peer_s = time.perf_counter() - t0
        ppsnr, pssim = compare(cloud, peer, args.views)
        rows.append(("peer", stats["faces"], stats["page"] ** 2, stats["fill_with_border"], stats["fill"], peer_s,
                     ppsnr, pssim))
        print("peer stages (s): " + ", ".join(f"{k} {v:.2f}" for k, v in stats["times"].items()))
        print(f"peer atlas: {stats['atlases']} page(s) of {stats['page']}^2, {stats['charts']} charts, xatlas's own "
              f"utilization {np.round(stats['xatlas_utilization'], 3).tolist()}, area of the chart triangles "
              f"{stats['chart_area']:.3f} of the page")
    print(f"load average after: {np.round(os.getloadavg(), 1).tolist()}")
    print("| pipeline | faces | atlas texels | fill (with borders) | fill (charts only) | time s | "
          "PSNR dB (min / mean) | SSIM (min / mean) |")
    print("|---|---|---|---|---|---|---|---|")
    for name, nf, nt, fill_b, fill_c, secs, ps, ss in rows:
        print(f"| {name} | {nf} | {nt} | {fill_b:.3f} | {fill_c:.3f} | {secs:.1f} | {min(ps):.1f} / {np.mean(ps):.1f} "
              f"| {min(ss):.3f} / {np.mean(ss):.3f} |")


if __name__ == "__main__":
    main()
