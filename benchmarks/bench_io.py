"""I/O speed: load the large test models and write surfel clouds in every format.

Run: ``python benchmarks/bench_io.py`` (needs ../shared/data/models). Prints the
minimum and median of 5 runs.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from unmesh import SurfelCloud, io

MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


def timed(fn, repeat=5):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times)


def main() -> int:
    if not MODELS.is_dir():
        print(f"models not found at {MODELS}")
        return 1
    print("load (min / median of 5, seconds)")
    for name in ("igea.ply", "armadillo.obj", "stanford-bunny.obj"):
        lo, med = timed(lambda name=name: io.load_mesh(MODELS / name))
        m = io.load_mesh(MODELS / name)
        print(f"  {name:22s} {lo:7.3f} {med:7.3f}   ({len(m.vertices)} vertices, {len(m.faces)} faces)")
    rng = np.random.default_rng(0)
    n = 1_000_000
    cloud = SurfelCloud(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), radii=rng.uniform(0.01, 0.02, n),
                        colors=rng.uniform(0, 1, (n, 3)), attributes={"temperature": rng.normal(size=n)})
    print(f"save / load {n} surfels (min / median of 3, seconds)")
    with tempfile.TemporaryDirectory() as d:
        for binary in (True, False):
            p = Path(d) / f"cloud_{'bin' if binary else 'ascii'}.ply"
            lo, med = timed(lambda p=p, binary=binary: io.save(p, cloud, binary=binary), repeat=3)
            rlo, rmed = timed(lambda p=p: io.load(p), repeat=3)
            kind = "binary" if binary else "ascii"
            print(f"  PLY {kind:6s} save {lo:7.3f} {med:7.3f}   load {rlo:7.3f} {rmed:7.3f}   ({p.stat().st_size / 1e6:.0f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
