"""Neighbour-search benchmark (thesis section 3.4): grid vs. kd-tree.

Measures, in one run:

1. all-pairs radius neighbours of N = 10^6 uniform random points in the unit cube,
   radius chosen for ~30 neighbours per point:
   (a) ``scipy.spatial.cKDTree(points).query_pairs(r, output_type="ndarray")``,
   (b) ``unmesh.spatial.radius_pairs`` (checked to equal (a) exactly), also with
   ``sort=False`` (the same set, unordered like (a)); (a') the default ``query_pairs``
   call (Python set of tuples) once, for reference,
   (c) ``unmesh.spatial.radius_neighbors`` (full CSR, both directions + self),
   with construction and query reported separately for the grid;
2. ``unmesh.spatial.knn`` with k = 16 on the same points vs. raw ``cKDTree.query``;
3. the SPH use case: 10^5 points rebuilt every step (grid build + CSR), and the
   dynamic ``HashGrid`` (insert / move / query).

Numba compilation is excluded (everything is warmed up on a small input first);
every figure is the best of ``--repeat`` runs.  Run::

    python benchmarks/bench_neighbors.py [--n 1000000] [--repeat 3] [--threads 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial import cKDTree

from unmesh.spatial import HashGrid, build_cell_grid, knn, radius_neighbors, radius_pairs
from unmesh.spatial import _kernels as K
from unmesh.spatial import neighbors as nb


def best(fn, repeat):
    """(best seconds, last result) of ``repeat`` calls."""
    t_best = np.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        t_best = min(t_best, time.perf_counter() - t0)
    return t_best, out


def radius_for(n, neighbours, dim=3):
    """Radius giving ``neighbours`` expected neighbours (self excluded) in the unit cube."""
    vol = 4.0 / 3.0 * np.pi if dim == 3 else np.pi
    return (neighbours / (vol * n)) ** (1.0 / dim)


def warm_up():
    rng = np.random.default_rng(1)
    p = rng.random((2000, 3))
    radius_pairs(p, 0.1)
    radius_neighbors(p, 0.1)
    radius_neighbors(p, 0.1, p[:10])
    knn(p, 16)
    g = HashGrid(0.1)
    g.insert(np.arange(100), p[:100])
    g.move(np.arange(50), p[100:150])
    g.query_radius(p[:10], 0.1)
    g.remove(np.arange(10))


def row(name, seconds, extra=""):
    print(f"  {name:<52s} {seconds:9.3f} s  {extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="points for the all-pairs test")
    ap.add_argument("--neighbours", type=float, default=30.0, help="mean neighbours per point")
    ap.add_argument("--k", type=int, default=16, help="k for the knn test")
    ap.add_argument("--sph-n", type=int, default=100_000, help="points for the SPH rebuild test")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=0, help="numba threads (default: all)")
    ap.add_argument("--sections", default="1,2,3", help="comma-separated sections to run (1 pairs, 2 knn, 3 SPH)")
    args = ap.parse_args()

    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)

    if args.threads:
        numba.set_num_threads(args.threads)
    print(f"numba threads: {numba.get_num_threads()}")
    warm_up()
    sections = {int(v) for v in args.sections.split(",") if v.strip()}
    rng = np.random.default_rng(args.seed)
    n = args.n
    p = rng.random((n, 3))
    r = radius_for(n, args.neighbours)
    if 1 in sections:
        pairs_section(p, n, r, rng, args)
    if 2 in sections:
        knn_section(p, n, args)
    if 3 in sections:
        sph_section(rng, args)


def pairs_section(p, n, r, rng, args):
    print(f"\n1. all pairs, N = {n}, uniform unit cube, radius = {r:.6g} (~{args.neighbours:g} neighbours)")

    t_kd_build, tree = best(lambda: cKDTree(p), args.repeat)
    t_kd_pairs, kd_pairs = best(lambda: tree.query_pairs(r, output_type="ndarray"), args.repeat)
    t_kd = t_kd_build + t_kd_pairs
    row("(a) cKDTree construction", t_kd_build)
    row("(a) cKDTree.query_pairs", t_kd_pairs, f"{len(kd_pairs)} pairs")
    row("(a) total", t_kd)

    t_pairs, pairs = best(lambda: radius_pairs(p, r), args.repeat)
    kd_sorted = kd_pairs[np.lexsort((kd_pairs[:, 1], kd_pairs[:, 0]))]
    same = pairs.shape == kd_sorted.shape and bool(np.array_equal(pairs, kd_sorted))
    t_build, grid = best(lambda: nb._grid_for(p, r), args.repeat)
    g, reach = grid
    t_choose, method = best(lambda: nb.choose_method(p, r, None, g), args.repeat)
    t_q_pairs, _ = best(lambda: nb._grid_search(g, reach, None, r, True), args.repeat)
    row("(b) grid construction (sort by cell)", t_build, f"{g.n_cells} cells, auto -> {method} ({t_choose * 1e3:.1f} ms)")
    row("(b) grid pair search (each pair once, rows, sort)", t_q_pairs,
        f"vs query_pairs alone {t_kd_pairs / t_q_pairs:.2f}x")
    row("(b) radius_pairs total (public call)", t_pairs,
        f"{len(pairs)} pairs, identical to (a): {same}, speed-up vs (a) {t_kd / t_pairs:.2f}x")

    t_uns, uns = best(lambda: radius_pairs(p, r, sort=False), args.repeat)
    uns_same = uns.shape == kd_sorted.shape and bool(np.array_equal(uns[np.lexsort((uns[:, 1], uns[:, 0]))], kd_sorted))
    row("(b') radius_pairs(sort=False), unordered as (a)", t_uns,
        f"same set as (a): {uns_same}, speed-up vs (a) {t_kd / t_uns:.2f}x")
    t_set = time.perf_counter()
    n_set = len(cKDTree(p).query_pairs(r))
    t_set = time.perf_counter() - t_set
    row("(a') cKDTree build + query_pairs (default set output)", t_set,
        f"{n_set} pairs; radius_pairs speed-up vs (a') {t_set / t_pairs:.1f}x")
    del uns

    t_csr, (_, ind) = best(lambda: radius_neighbors(p, r), args.repeat)
    t_q_csr, _ = best(lambda: nb._grid_search(g, reach, None, r, False), args.repeat)
    row("(c) grid CSR search (both directions + self)", t_q_csr, f"vs query_pairs alone {t_kd_pairs / t_q_csr:.2f}x")
    consistent = len(ind) == 2 * len(pairs) + n
    row("(c) radius_neighbors total (public call)", t_csr,
        f"{len(ind)} entries (= 2 P + N: {consistent}), speed-up vs (a) {t_kd / t_csr:.2f}x")

    print("   cell-size tuning (radius_pairs, public call):")
    for f in (1, 2, 3):
        nb.CELLS_PER_RADIUS = f
        t_f, _ = best(lambda: radius_pairs(p, r), args.repeat)
        row(f"   cell = radius / {f} ({(2 * f + 1) ** 3} cells searched)", t_f)
    nb.CELLS_PER_RADIUS = 1

    u = rng.normal(size=(n, 3))
    s = u / np.linalg.norm(u, axis=1, keepdims=True)
    rs = np.sqrt(30 * 4.0 / n)  # ~30 neighbours on the unit sphere (area 4 pi)
    print(f"   surface sample: N = {n} on the unit sphere, radius = {rs:.4g}")
    t_s_kd, sp_kd = best(lambda: cKDTree(s).query_pairs(rs, output_type="ndarray"), args.repeat)
    row("   cKDTree build + query_pairs", t_s_kd, f"{len(sp_kd)} pairs")
    t_s, sp = best(lambda: radius_pairs(s, rs), args.repeat)
    row(f"   radius_pairs (auto -> {nb.choose_method(s, rs)})", t_s, f"{len(sp)} pairs, speed-up {t_s_kd / t_s:.2f}x")


def knn_section(p, n, args):
    print(f"\n2. knn, k = {args.k}, N = {n} (self queries)")
    tree = cKDTree(p)
    t_kq, _ = best(lambda: tree.query(p, k=args.k, workers=-1), args.repeat)
    row("cKDTree.query(k, workers=-1) (tree prebuilt)", t_kq)
    t_knn, (d, _) = best(lambda: knn(p, args.k), args.repeat)
    row("unmesh.spatial.knn (build + exact ties)", t_knn, f"mean k-th distance {d[:, -1].mean():.4g}")


def sph_section(rng, args):
    m = args.sph_n
    x = rng.random((m, 3))
    h = radius_for(m, 40.0)
    print(f"\n3. SPH case, N = {m}, h = {h:.4g} (~40 neighbours), rebuilt every step")
    t_g, gs = best(lambda: build_cell_grid(x, h), args.repeat)
    row("build_cell_grid", t_g, f"{gs.n_cells} cells")
    t_rn, (o2, _) = best(lambda: radius_neighbors(x, h), args.repeat)
    row("radius_neighbors (CSR, includes build)", t_rn, f"{o2[-1] / m:.1f} neighbours / point")
    t_kd2, _ = best(lambda: cKDTree(x).query_ball_point(x, h, workers=-1), args.repeat)
    row("cKDTree build + query_ball_point (lists)", t_kd2, f"grid speed-up {t_kd2 / t_rn:.2f}x")
    counts_ref = np.diff(o2)
    cnt = K.radius_count(gs.points, gs.order, gs.cell_keys, gs.cell_start, gs.dims, gs.reach(h), gs.points,
                         gs.order, gs.cell_keys, gs.cell_start, False, gs.origin, gs.upper, h, False)
    assert np.array_equal(cnt, counts_ref)

    ids = np.arange(m)
    x2 = x + rng.normal(scale=0.1 * h, size=x.shape)
    o4, i4 = radius_neighbors(x2, h)
    for factor, label in ((1.0, "cell = h, 27 cells"), (2.0, "cell = 2h, 8 cells")):
        hg = HashGrid(factor * h)
        t_ins, _ = best(lambda hg=hg: (hg.clear(), hg.insert(ids, x)), args.repeat)
        row(f"HashGrid({label}).insert (all points)", t_ins)
        t_mv, _ = best(lambda hg=hg: hg.move(ids, x2), args.repeat)
        row(f"HashGrid({label}).move (all, by ~0.1 h)", t_mv)
        t_hq, (o3, i3) = best(lambda hg=hg: hg.query_radius(x2, h), args.repeat)
        same = np.array_equal(o3, o4) and np.array_equal(i3, i4)
        row(f"HashGrid({label}).query_radius (all)", t_hq, f"equals radius_neighbors: {same}")
        sub = ids[:1000]
        t_mv1, _ = best(lambda hg=hg, sub=sub: hg.move(sub, x[:1000]), args.repeat)
        row(f"HashGrid({label}).move (1000 points)", t_mv1, f"{t_mv1 / 1000 * 1e6:.2f} us / point")


if __name__ == "__main__":
    main()
