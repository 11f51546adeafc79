"""Frame sequences of simulation output, turntables."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import Particles, SurfelCloud, TriangleMesh, io
from unmesh.errors import InputError
from unmesh.render import Camera, find_frames, render_sequence, turntable

from .conftest import fibonacci_sphere


def sph_like(path, frames=3):
    """OUTDIR/frames/frame_NNNNN.ply particles with SPH attributes + OUTDIR/boundary.ply."""
    rng = np.random.default_rng(0)
    base = rng.uniform(0, 0.5, (200, 3))
    for k in range(frames):
        pos = base + np.array([0.1 * k, 0.0, 0.0])
        attrs = {"vx": np.full(200, 0.1), "vy": np.zeros(200), "vz": np.zeros(200), "density": 1000 + 10 * k + pos[:, 1],
                 "pressure": pos[:, 1], "temperature": np.full(200, 20.0), "phase": np.zeros(200), "object": np.zeros(200)}
        io.save(path / "frames" / f"frame_{k:05d}.ply", Particles(pos, attributes=attrs))
    g = np.stack(np.meshgrid(np.linspace(0, 1, 21), np.linspace(0, 1, 21)), -1).reshape(-1, 2)
    floor = Particles(np.c_[g[:, 0], np.full(len(g), -0.05), g[:, 1]])
    io.save(path / "boundary.ply", floor)


def test_find_frames_groups_series_and_static(tmp_path):
    sph_like(tmp_path)
    frames, static = find_frames(tmp_path)
    assert [[p.name for p in g] for g in frames] == [["frame_00000.ply"], ["frame_00001.ply"], ["frame_00002.ply"]]
    assert [p.name for p in static] == ["boundary.ply"]
    # several series per frame number, unnumbered static file, hidden temp files ignored
    d = tmp_path / "multi"
    for k in (0, 1):
        io.save(d / f"fluid_{k:05d}.ply", Particles([[0, 0, 0]]))
        io.save(d / f"solid_{k:05d}.ply", Particles([[1, 0, 0]]))
    io.save(d / "rest.ply", Particles([[2, 0, 0]]))
    (d / ".fluid_00002.tmp.ply").write_text("partial")
    frames, static = find_frames(d)
    assert [[p.name for p in g] for g in frames] == [["fluid_00000.ply", "solid_00000.ply"],
                                                      ["fluid_00001.ply", "solid_00001.ply"]]
    assert [p.name for p in static] == ["rest.ply"]
    with pytest.raises(InputError):
        find_frames(tmp_path / "nothing")


def test_sph_directory_to_gif_with_fixed_camera_and_range(tmp_path):
    from PIL import Image

    sph_like(tmp_path, frames=4)
    out = render_sequence(tmp_path, tmp_path / "movie.gif", width=48, height=32, progress=False, color_by="density")
    im = Image.open(out)
    assert im.n_frames == 4 and im.size == (48, 32)
    # frames differ (the block moves) but the camera is fixed: the static floor stays put
    a = np.asarray(im.convert("RGB")).astype(int)
    im.seek(3)
    b = np.asarray(im.convert("RGB")).astype(int)
    assert np.abs(a - b).sum() > 0


def test_sequence_to_png_directory_meshes_and_surfels(tmp_path):
    # FEM-like surface meshes and shell-like surfels with a discontinuity attribute
    d = tmp_path / "fem"
    for k in range(2):
        v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.2 * k]], dtype=float)
        io.save(d / f"surface_{k:05d}.ply", TriangleMesh(v, [[0, 1, 2], [0, 2, 3]], attributes={"stress": [0, 1, 2, 3.0]}))
    out = render_sequence(d, tmp_path / "pngs", width=24, height=20, progress=False, color_by="stress")
    assert sorted(p.name for p in out.iterdir()) == ["frame_00000.png", "frame_00001.png"]
    s = tmp_path / "shell" / "frames"
    for k in range(2):
        c = fibonacci_sphere(400).transformed(np.diag([1.0, 1.0 + 0.1 * k, 1.0, 1.0]))
        c = SurfelCloud(c.positions, c.normals, axes=c.tangent_axes(), attributes={"discontinuity": np.zeros(400)})
        io.save(s / f"frame_{k:05d}.ply", c)
    out = render_sequence(tmp_path / "shell", tmp_path / "shell.mp4", width=32, height=32, progress=False)
    assert out.stat().st_size > 0


def test_sequence_errors(tmp_path):
    sph_like(tmp_path, frames=2)
    with pytest.raises(InputError):
        render_sequence(tmp_path, tmp_path / "a.png", width=16, height=16, progress=False)
    with pytest.raises(InputError):
        render_sequence(tmp_path, tmp_path / "a.gif", width=16, height=16, progress=False, color_by="nope")


def test_turntable_frames_and_video(tmp_path):
    cloud = fibonacci_sphere(500, center=(0.5, 0, 0))
    frames = turntable(cloud, 4, width=32, height=24)
    assert len(frames) == 4 and frames[0].shape == (24, 32, 3)
    assert np.abs(frames[0] - frames[1]).sum() > 0
    cam = Camera((0, 0, 4), (0, 0, 0), width=16, height=16)
    p = turntable(cloud, 3, tmp_path / "t.gif", camera=cam, fps=5, color_by="height")
    assert p.exists()
    with pytest.raises(InputError):
        turntable(cloud, 0)
