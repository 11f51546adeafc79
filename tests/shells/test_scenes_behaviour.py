"""The shipped scenes do what they show (slow: full simulations)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from unmesh import io
from unmesh.scenes import path
from unmesh.shells.scene import build_simulation
from unmesh.sim.cli import run_scene


def run(tmp_path, name, overrides=None, duration=None):
    out = tmp_path / name
    run_scene(path(f"shells/{name}.toml"), out, build_simulation, overrides=overrides, duration=duration,
              progress=False)
    return out, json.loads((out / "summary.json").read_text())


@pytest.mark.slow
def test_hanging_sheet_sags_smoothly_symmetrically_and_rests(tmp_path):
    out, s = run(tmp_path, "hanging_sheet")
    last = s["frames"][-1]["frame"]
    x = io.load(out / "nodes" / f"frame_{last:05d}.ply").positions
    sag = 1.0 - x[:, 1]
    assert sag.max() > 0.01                                   # it sags
    free = x[:, 0] > -0.4
    # symmetric about z = 0: compare each node with the node nearest to its mirror image
    from unmesh.spatial import knn

    _, i = knn(x[:, [0, 2]], 1, queries=x[:, [0, 2]] * [1.0, -1.0])
    assert np.abs(sag - sag[i[:, 0]]).max() < 0.1 * sag.max()
    # smooth: a quadratic in (x, z) fits the sag of the free part to within 10 % of its range
    a = np.stack([np.ones(free.sum()), x[free, 0], x[free, 2] ** 2, x[free, 0] ** 2, x[free, 0] * x[free, 2] ** 2],
                 axis=1)
    coef, *_ = np.linalg.lstsq(a, sag[free], rcond=None)
    assert np.abs(a @ coef - sag[free]).max() < 0.1 * np.ptp(sag[free])
    # at rest
    ke = [f["kinetic_energy"] for f in s["frames"]]
    assert ke[-1] < 1e-3 * max(ke)
    assert s["status"] == "completed"


@pytest.mark.slow
def test_balloon_grows_then_tears(tmp_path):
    out, s = run(tmp_path, "balloon")
    first = next(f["frame"] for f in s["frames"] if f["cracks"] > 0)
    r = [np.linalg.norm(io.load(out / "nodes" / f"frame_{k:05d}.ply").positions, axis=1).mean()
         for k in (0, first - 1)]
    assert r[1] > 1.05 * r[0]                       # visibly inflated before it tears
    last = s["frames"][-1]
    assert last["cracks"] >= 5 and last["components"] == 1   # one opening, not shattered
    assert s["frames"][-1]["cracks"] > 0 and s["frames"][-1]["fibers"] < s["fibers_initial"]
    disc = io.load(out / "frames" / f"frame_{s['frames'][-1]['frame']:05d}.ply").attributes["discontinuity"]
    assert disc.sum() == 2 * s["frames"][-1]["cracks"]
    assert s["frames"][-1]["pressure"] < 0.1 * max(f["pressure"] for f in s["frames"])   # the air escaped


@pytest.mark.slow
def test_elastic_dome_bounces(tmp_path):
    _, s = run(tmp_path, "elastic_drop", {"surface.nodes": 600, "surface.spacing": 0.45}, duration=4.0)
    g = np.array([f["gravity_energy"] for f in s["frames"]])
    hit = int(np.argmin(g[:60]))
    assert g[hit:].max() > g[hit] + 0.02 * (g[0] - g[hit])   # the centre of mass rises again after the impact
    assert s["status"] == "completed"


@pytest.mark.slow
def test_plastic_blob_stays_dented(tmp_path):
    out, s = run(tmp_path, "plastic_drop", {"surface.nodes": 500, "surface.spacing": 0.45})
    last = s["frames"][-1]["frame"]
    h0 = np.ptp(io.load(out / "nodes" / "frame_00000.ply").positions[:, 1])
    h1 = np.ptp(io.load(out / "nodes" / f"frame_{last:05d}.ply").positions[:, 1])
    assert h1 < 0.97 * h0
    assert s["frames"][-1]["kinetic_energy"] < 0.05 * s["frames"][0]["kinetic_energy"]


@pytest.mark.slow
def test_plastic_blob_splats_stay_on_the_surface(tmp_path):
    """The shipped plastic drop (gallery resolution): no splat grows past 5x the median radius
    in any frame. Before frames on the node normals (skinning.frame_normals) one surfel at an
    ear's base, bound to nodes with no plane, left the surface as an 8.5x disc (issue 23)."""
    out, _ = run(tmp_path, "plastic_drop")
    worst = 0.0
    for f in sorted((out / "frames").glob("frame_*.ply")):
        r = io.load(f).radii
        worst = max(worst, float(r.max() / np.median(r)))
    print(f"largest splat: {worst:.2f} x the median radius")
    assert worst < 5.0


@pytest.mark.slow
def test_plastic_blob_ear_surfels_keep_the_surface_normal(tmp_path):
    """The shipped plastic drop: in every frame the normal of every surfel of the ears and the
    top of the head turns by at most 50° more than at rest away from the mean normal of its 12
    nearest rest neighbours on its side (normals within 60°). Bound also to nodes on the far
    face of the ear (one node spacing thick) or to frames across its rim, surfels followed the
    other face: sunken dark flecks, knobs and needles at the ear tips, up to 173° (issue 23)."""
    from unmesh.spatial import knn

    out, _ = run(tmp_path, "plastic_drop")
    files = sorted((out / "frames").glob("frame_*.ply"))
    rest = io.load(files[0])
    _, nbr = knn(rest.positions, 13)
    nbr = nbr[:, 1:]
    side = np.einsum("sa,ska->sk", rest.normals, rest.normals[nbr]) >= 0.5

    def turn(normals):
        mean = np.where(side[..., None], normals[nbr], 0.0).sum(axis=1)
        mean /= np.linalg.norm(mean, axis=1, keepdims=True)
        return np.degrees(np.arccos(np.clip(np.einsum("sa,sa->s", normals, mean), -1.0, 1.0)))

    at_rest = turn(rest.normals)
    top = rest.positions[:, 1] > 22.0                     # the ears and the top of the head
    worst = 0.0
    for f in files:
        worst = max(worst, float((turn(io.load(f).normals) - at_rest)[top].max()))
    print(f"largest extra turn of an ear surfel's normal: {worst:.1f} degrees")
    assert worst < 50.0


@pytest.mark.slow
def test_torn_poster_ends_in_two_pieces(tmp_path):
    out, s = run(tmp_path, "tearing_poster")
    assert s["status"] == "completed"
    d = np.load(out / "fibers" / f"frame_{s['frames'][-1]['frame']:05d}.npz")
    f = d["fibers"]
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = s["nodes"]
    g = coo_matrix((np.ones(2 * len(f)), (np.r_[f[:, 0], f[:, 1]], np.r_[f[:, 1], f[:, 2]])), shape=(n, n))
    _, labels = connected_components(g, directed=False)
    sizes = np.sort(np.bincount(labels))[::-1]
    assert sizes[1] > 0.3 * n                  # two big pieces (plus loose crumbs along the tear)
    assert sizes[:2].sum() > 0.9 * n
    x = io.load(out / "nodes" / f"frame_{s['frames'][-1]['frame']:05d}.ply").positions
    rest = io.load(out / "nodes" / "frame_00000.ply").positions
    for size in sizes[:2]:
        piece = np.bincount(labels)[labels] == size
        side = np.sign(rest[piece, 0])
        assert max((side > 0).mean(), (side < 0).mean()) > 0.9   # each big piece is one half of the poster
    assert x[:, 0].max() - x[:, 0].min() > 48.0                   # and the halves have moved apart
    # crumbs cut off by crossing crack discs ride with a piece: exactly two pieces in the end
    assert s["frames"][-1]["components"] == 2
