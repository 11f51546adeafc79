"""CSG rendering speed (thesis Table 4.1) and clipping-partner search (4.2.1).

For the shipped scenes of Figs. 4.9 (spikes), 4.10 (icosahedron) and 4.8 (blob minus two
spheres) at 512x512 and two zoom levels: frames per second of a full CSG frame (partners,
classes, the clip tree folded for the camera and one splatting pass with the clipped edge
surfels), the number of edge surfels and of
pixels covered by them (edge pixels), the split of the frame, and the same surfels splatted
without clipping. Then a fit of the clipped-splatting time against edge pixels, and the partner
search for 100k edge surfels by both methods.

Run: python benchmarks/bench_csg.py [--quick]
"""

from __future__ import annotations

import argparse
import itertools
import os
import time

import numpy as np

from unmesh import scenes
from unmesh.csg import Patch, find_partners, prepare
from unmesh.csg.draw import front_facing
from unmesh.csg.fold import fold_for_camera
from unmesh.csg.frame import EDGE, select
from unmesh.csg.model import Complement, patches
from unmesh.csg.partners import METHODS
from unmesh.csg.scene import load
from unmesh.render import Camera, SplatRenderer, scene_points
from unmesh.surfels import SurfelCloud

#: "wall" (time.perf_counter) or "cpu" (time.process_time: CPU time of this process, which
#: on a shared machine with NUMBA_NUM_THREADS=1 is the single-threaded cost)
CLOCK = {"wall": time.perf_counter, "cpu": time.process_time}
_clock = CLOCK["wall"]


def _best(fn, repeat):
    best = np.inf
    out = None
    for _ in range(repeat):
        t = _clock()
        out = fn()
        best = min(best, _clock() - t)
    return best, out


_moves = itertools.count(1)


def moved(model, which):
    """``model`` with the patches ``which`` (a set of ids, None: all) replaced by new patches
    moved by a tiny translation (a new one on every call): what a frame of dynamic CSG gets."""
    def sub(node):
        if isinstance(node, Patch):
            if which is None or id(node) in which:
                m = np.eye(4)
                m[:3, 3] = 1e-9 * next(_moves)
                return node.moved(m)
            return node
        if isinstance(node, Complement):
            return Complement(sub(node.child))
        return type(node)(sub(node.left), sub(node.right))
    return sub(model)


def frame_split(model, cam, repeat):
    """Times of the stages of one CSG frame: every patch moved (nothing reused but per-patch
    data: k-d trees, overlaps), and one patch moved (the insidePatch values of the pairs of
    patches that did not move are reused)."""
    t_all, _ = _best(lambda: prepare(moved(model, None)), repeat)
    last = {id(patches(model)[-1])}
    prepare(moved(model, last))
    t_one, _ = _best(lambda: prepare(moved(model, last)), repeat)
    flat_frame = prepare(model)
    cloud = flat_frame.cloud
    t_part, _ = _best(lambda: find_partners(cloud.positions, cloud.radii, flat_frame.leaf, cloud.normals), repeat)
    arrays, clip = select(flat_frame.arrays, flat_frame.clip,
                          front_facing(flat_frame.arrays.positions, flat_frame.arrays.normals, cam))
    r = SplatRenderer(cam)

    def clipped():  # what draw_models does per camera: fold the tree per surfel, splat
        fa, fc = fold_for_camera(arrays, clip, cam, r.options.filter_radius)
        r.render(fa, clip=fc)

    clipped()
    t_clip, _ = _best(clipped, repeat)
    t_plain, _ = _best(lambda: r.render(arrays), repeat)
    t_resolve, _ = _best(lambda: r.gbuffer(), repeat)
    edge = np.asarray(clip.offsets[1:] > clip.offsets[:-1])
    ea, ec = select(arrays, clip, edge)
    cov = SplatRenderer(cam).render(ea, clip=ec).gbuffer().coverage
    return {"partners": t_part, "classes": t_all - t_part, "one moved": t_one + t_clip + t_resolve, "splat CSG": t_clip, "splat plain": t_plain,
            "resolve": t_resolve, "edge surfels": int((flat_frame.classes == EDGE).sum()),
            "surfels": len(cloud), "edge pixels": int(cov.sum()), "total": t_all + t_clip + t_resolve}


def partners_100k(quick):
    """Two crossing sheets sampled at the same density, offset by half a spacing: every
    surfel intersects the other sheet, so all of them are edge surfels."""
    n = 20000 if quick else 100000
    h = 2.0 / np.sqrt(n / 2)
    a = Patch.halfspace((0, 0, 0), (0, 0, 1), 2.0, h).cloud
    pos = np.concatenate([a.positions, a.positions + np.array([h / 2, h / 2, 1e-3])])
    nrm = np.concatenate([a.normals, np.tile([0.0, 0.6, 0.8], (len(a), 1))])
    radii = np.concatenate([a.radii, a.radii])
    leaf = np.repeat([0, 1], [len(a), len(a)])
    off, _ = find_partners(pos, radii, leaf, nrm, method="range")
    edge = int((np.diff(off) > 0).sum())
    out = {}
    for method in METHODS:
        find_partners(pos[:100], radii[:100], leaf[:100], nrm[:100], method=method)
        t, (_, i) = _best(lambda m=method: find_partners(pos, radii, leaf, nrm, method=m), 3)
        out[method] = (t, len(i))
    return len(pos), edge, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--clock", choices=sorted(CLOCK), default="wall",
                    help="cpu: process CPU time (run with NUMBA_NUM_THREADS=1 for single-threaded costs)")
    ap.add_argument("--scenes", default="spikes,icosahedron,blob_minus_spheres")
    args = ap.parse_args()
    global _clock
    _clock = CLOCK[args.clock]
    figs = {"spikes": "4.9", "icosahedron": "4.10", "blob_minus_spheres": "4.8"}
    size = 256 if args.quick else 512
    repeat = 2 if args.quick else 5
    rows = []
    for name in args.scenes.split(","):
        fig = figs[name]
        scene = load(scenes.path(f"csg/{name}.toml"))
        model = scene.model
        fr = prepare(model)
        cam = Camera.fit(scene_points(SurfelCloud(fr.arrays.positions, fr.arrays.normals, radii=fr.arrays.radii)),
                         size, size, fov=35)
        for zoom in (1.0, 2.5):
            c = cam.zoomed(zoom)
            frame_split(model, c, 1)  # compile
            s = frame_split(model, c, repeat)
            rows.append((fig, name, zoom, s))
    print(f"CSG frames at {size}x{size} (best of {repeat}, {args.clock} clock, {os.environ.get('NUMBA_NUM_THREADS', 'all')} "
          f"numba threads; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print("fps: every patch moved (partners, classes and splatting every frame); fps 1 moved: the last patch "
          "of the tree moved; fps static: camera moved only (the frame of the unchanged model is reused)")
    hdr = ("fig", "zoom", "surfels", "edge surf", "edge px", "fps", "fps 1 moved", "fps static", "partners", "classes", "splat CSG",
           "splat plain", "resolve", "CSG/plain")
    print("  ".join(f"{h:>10}" for h in hdr))
    for fig, _name, zoom, s in rows:
        vals = (fig, f"{zoom:g}x", s["surfels"], s["edge surfels"], s["edge pixels"], f"{1 / s['total']:.1f}",
                f"{1 / s['one moved']:.1f}",
                f"{1 / (s['splat CSG'] + s['resolve']):.1f}",
                *(f"{1000 * s[k]:.1f}ms" for k in ("partners", "classes", "splat CSG", "splat plain", "resolve")),
                f"{s['splat CSG'] / s['splat plain']:.2f}")
        print("  ".join(f"{v:>10}" for v in vals))
    ep = np.array([s["edge pixels"] for *_, s in rows], float)
    extra = np.array([s["splat CSG"] - s["splat plain"] for *_, s in rows])
    if len(rows) >= 2:
        slope, icpt = np.polyfit(ep, extra, 1)
        print(f"clipped-splatting overhead ~ {1e6 * slope:.3f} us per edge pixel + {1000 * icpt:.2f} ms "
              f"(fit over {len(rows)} frames)")
    n, edge, out = partners_100k(args.quick)
    for method, (t, m) in out.items():
        print(f"partners, {method:>10}: {1000 * t:.1f} ms for {n} surfels ({edge} edge surfels), {m // 2} pairs")


if __name__ == "__main__":
    main()
