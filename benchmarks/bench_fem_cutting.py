"""Cutting on convex polyhedra vs naive tetrahedral subdivision: node and element counts.

The same initial TetGen mesh (the built-in blob) and the same cut sequences are applied

1. by unmesh (convex elements are split into two convex elements, 9.3.1; progressive polygon
   cuts 9.3.2), and
2. by a naive tetrahedral subdivision: every tetrahedron the cut crosses (inside the cut
   polygon) is split into its two convex parts, and each part is tetrahedralised again
   (Delaunay of its corners); new nodes on crossed edges are shared. Each element is split at
   most once per cut (non-progressive), as in the thesis' comparison (9.4).

Sequences: (a) 12 random planes through the blob; (b) the blade sweeps of
``examples/fem/blob_slicing.toml`` (one cut polygon per time step).

Usage: ``python benchmarks/bench_fem_cutting.py [--spacing 0.12]``
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np


def naive_tet_cut(points: np.ndarray, tets: np.ndarray, origin: np.ndarray, normal: np.ndarray,
                  polygon: np.ndarray | None = None, snap: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Split every crossed tetrahedron (overlapping ``polygon`` when given) into tetrahedra."""
    from scipy.spatial import Delaunay

    from unmesh.fem._cutgeom import overlap as _overlap

    d = (points - origin) @ normal
    scale = np.ptp(points, axis=0).max()
    side = np.where(np.abs(d) <= snap * scale, 0, np.sign(d)).astype(int)
    s = side[tets]
    crossed = np.flatnonzero((s.min(axis=1) < 0) & (s.max(axis=1) > 0))
    if polygon is not None and len(crossed):
        c = polygon.mean(axis=0)
        e1 = polygon[0] - c
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(normal, e1)
        P2 = np.c_[(polygon - c) @ e1, (polygon - c) @ e2]
        keep = []
        for t in crossed:
            sec = []
            for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
                i, j = tets[t, a], tets[t, b]
                if side[i] * side[j] < 0:
                    u = d[i] / (d[i] - d[j])
                    sec.append((1 - u) * points[i] + u * points[j])
            for v in tets[t]:
                if side[v] == 0:
                    sec.append(points[v])
            q = np.array(sec)
            if len(q) >= 3 and _overlap(np.c_[(q - c) @ e1, (q - c) @ e2], P2, 1e-12 * scale):
                keep.append(t)
        crossed = np.array(keep, dtype=np.int64)
    new_pts = [points]
    edge_node: dict[tuple[int, int], int] = {}
    n = len(points)
    out = [np.delete(tets, crossed, axis=0)]
    for t in crossed:
        cut = []
        for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
            i, j = sorted((tets[t, a], tets[t, b]))
            if side[i] * side[j] < 0:
                if (i, j) not in edge_node:
                    u = d[i] / (d[i] - d[j])
                    new_pts.append(((1 - u) * points[i] + u * points[j])[None])
                    edge_node[(i, j)] = n
                    n += 1
                cut.append(edge_node[(i, j)])
        allp = np.concatenate(new_pts)
        for sgn in (-1, 1):
            ids = np.array([v for v in tets[t] if side[v] * sgn >= 0] + cut)
            if len(ids) == 4:
                out.append(ids[None])
                continue
            tri = Delaunay(allp[ids]).simplices
            vol = np.abs(np.einsum("ij,ij->i", allp[ids[tri[:, 1]]] - allp[ids[tri[:, 0]]],
                                   np.cross(allp[ids[tri[:, 2]]] - allp[ids[tri[:, 0]]],
                                            allp[ids[tri[:, 3]]] - allp[ids[tri[:, 0]]])))
            out.append(ids[tri[vol > 1e-14 * scale**3]])
    return np.concatenate(new_pts), np.concatenate(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacing", type=float, default=0.12, help="surface spacing of the blob (default 0.12)")
    args = ap.parse_args()
    from unmesh import scenes
    from unmesh.fem import tetrahedralize
    from unmesh.fem.cutting import PlaneCut, PolygonCut, apply_cuts
    from unmesh.fem.events import BladeEvent
    from unmesh.scene import load_scene
    from unmesh.shapes import Blob

    mesh = tetrahedralize(Blob(center=(0, 0.46, 0)).mesh(args.spacing))
    _, nodes = mesh.element_nodes()
    tets0 = nodes.reshape(-1, 4)
    print(f"initial TetGen mesh: {mesh.n_nodes} nodes, {mesh.n_elements} tetrahedra")
    rng = np.random.default_rng(7)
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    planes = [(lo + (hi - lo) * rng.uniform(0.2, 0.8, 3), rng.normal(size=3)) for _ in range(12)]
    for p in planes:
        p[1][:] /= np.linalg.norm(p[1])
    t = time.perf_counter()
    r = apply_cuts(mesh, [PlaneCut(tuple(o), tuple(nv)) for o, nv in planes])
    tu = time.perf_counter() - t
    pts, tets = mesh.points, tets0
    for o, nv in planes:
        pts, tets = naive_tet_cut(pts, tets, o, nv)
    tet_frac = float(np.mean(np.diff(r.mesh.element_nodes()[0]) == 4))
    print(f"(a) 12 random planes: unmesh {r.mesh.n_nodes} nodes, {r.mesh.n_elements} elements "
          f"({100 * tet_frac:.0f} % still tetrahedra, {tu:.2f} s); tetrahedral subdivision {len(pts)} nodes, "
          f"{len(tets)} tetrahedra")
    scene = load_scene(scenes.path("fem/blob_slicing.toml"))
    events = [BladeEvent(c.number("start"), c.number("stop"), c.array_of_numbers("path")) for c in scene.array("cuts")]
    dt = scene.table("simulation").number("dt")
    ops = []
    for k in range(round(3.0 / dt)):
        for ev in events:
            ops.extend(ev.operations(k * dt, (k + 1) * dt))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        cur = mesh
        for op in ops:  # one commit per step, as in the simulation
            try:
                cur = apply_cuts(cur, [op]).mesh
            except Exception as exc:
                print(f"  skipped a degenerate cut step: {exc}")
        tu = time.perf_counter() - t
    pts, tets = mesh.points, tets0
    for op in ops:
        assert isinstance(op, PolygonCut)
        P = op.polygon
        c = P.mean(axis=0)
        nv = np.cross(P[1] - P[0], P[2] - P[0])
        pts, tets = naive_tet_cut(pts, tets, c, nv / np.linalg.norm(nv), polygon=P)
    tet_frac = float(np.mean(np.diff(cur.element_nodes()[0]) == 4))
    maxn = int(np.diff(cur.element_nodes()[0]).max())
    print(f"(b) blade sweeps of blob_slicing.toml ({len(ops)} cut polygons): unmesh {cur.n_nodes} nodes, "
          f"{cur.n_elements} elements ({100 * tet_frac:.0f} % still tetrahedra, largest element {maxn} nodes, "
          f"{tu:.1f} s); tetrahedral subdivision {len(pts)} nodes, {len(tets)} tetrahedra")
    print("thesis (bunny, Fig. 9.10): 24079 -> 46132 nodes, 8278 -> 44118 elements with convex elements; "
          "> 75000 nodes and > 300000 elements with tetrahedral subdivision")


if __name__ == "__main__":
    main()
