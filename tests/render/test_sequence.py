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


def sim_run(path, frames=3, fps=5.0):
    """A run folder written by the shared runner: OUTDIR/frames.json lists the frames and boundary.ply."""
    from unmesh.sim import RunSettings, Simulation, run

    class Mover(Simulation):
        name = "mover"

        def __init__(self):
            self.time = 0.0

        def step(self):
            self.time += 0.5 / fps
            return 0.5 / fps

        def check(self):
            return None

        def write_frame(self, outdir, frame):
            pts = np.array([[self.time, 0.0, 0.0], [self.time, 0.2, 0.0], [self.time + 0.1, 0.1, 0.0]])
            io.save(outdir / "frames" / f"body_{frame:05d}.ply", Particles(pts))
            io.save(outdir / "surfaces" / f"body_{frame:05d}.ply",
                    TriangleMesh(pts, [[0, 1, 2]]))
            return [f"frames/body_{frame:05d}.ply", f"surfaces/body_{frame:05d}.ply"]

        def write_static(self, outdir):
            io.save(outdir / "boundary.ply", Particles([[0.0, -0.1, 0.0], [1.0, -0.1, 0.0]]))
            return ["boundary.ply"]

        def frame_record(self):
            return {}

        def state_dict(self):
            return {"time": self.time}

        def load_state_dict(self, state):
            self.time = float(state["time"])

    run(Mover(), path, RunSettings(duration=(frames - 1) / fps, fps=fps), progress=False)
    return path


def test_run_folders_are_read_through_their_manifest(tmp_path):
    out = sim_run(tmp_path / "out")
    # stray files another tool (or an older run) left are not frames
    io.save(out / "frames" / "frame_00000.ply", Particles([[9.0, 9, 9]]))
    io.save(out / "frames" / "body_00099.ply", Particles([[9.0, 9, 9]]))
    io.save(out / "surface_00001.ply", Particles([[9.0, 9, 9]]))
    io.save(out / "boundary_old.ply", Particles([[9.0, 9, 9]]))
    frames, static = find_frames(out)
    assert [[p.relative_to(out).as_posix() for p in g] for g in frames] == \
        [[f"frames/body_{k:05d}.ply"] for k in range(3)]
    assert [p.name for p in static] == ["boundary.ply"]
    assert find_frames(out / "frames") == (frames, static)
    # another listed folder picks that series
    frames, static = find_frames(out / "surfaces")
    assert [[p.relative_to(out).as_posix() for p in g] for g in frames] == \
        [[f"surfaces/body_{k:05d}.ply"] for k in range(3)]
    assert [p.name for p in static] == ["boundary.ply"]
    # a listed file that is gone is an error, not a silently shorter video
    (out / "frames" / "body_00001.ply").unlink()
    with pytest.raises(InputError, match=r"frames\.json lists frames/body_00001\.ply"):
        find_frames(out)


def test_videos_default_to_the_simulations_frame_rate(tmp_path):
    from PIL import Image

    from unmesh.render.sequence import sequence_fps

    out = sim_run(tmp_path / "out", frames=3, fps=5.0)
    assert sequence_fps(out) == 5.0 and sequence_fps(out / "surfaces") == 5.0
    assert sequence_fps(tmp_path) is None
    gif = render_sequence(out, tmp_path / "a.gif", width=24, height=16, progress=False)
    im = Image.open(gif)
    assert im.n_frames == 3 and im.info["duration"] == 200  # ms per frame at 5 fps
    gif = render_sequence(out, tmp_path / "b.gif", fps=20, width=24, height=16, progress=False)
    assert Image.open(gif).info["duration"] == 50


def test_render_command_on_a_run_folder_uses_its_fps_and_says_when_a_size_is_rounded(tmp_path, capsys):
    import imageio.v3 as iio

    from unmesh.cli import main

    out = sim_run(tmp_path / "out", frames=3, fps=5.0)
    (out / "frames" / "frame_00007.ply").write_text("not a frame of this run")
    assert main(["render", str(out), "-o", str(tmp_path / "v.mp4"), "--size", "33x24", "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "at 5 fps (the simulation's frame rate)" in captured.out
    assert "33x24 is padded to 34x24" in captured.err
    meta = iio.immeta(tmp_path / "v.mp4", plugin="pyav") if _has_pyav() else iio.immeta(tmp_path / "v.mp4")
    assert float(meta["fps"]) == pytest.approx(5.0)
    assert main(["render", str(out), "-o", str(tmp_path / "w.mp4"), "--size", "32x24", "--fps", "12",
                 "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "padded" not in captured.err and "simulation's frame rate" not in captured.out


def _has_pyav():
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True
