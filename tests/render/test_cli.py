"""``unmesh render`` end to end (tiny sizes)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import Particles, TriangleMesh, io
from unmesh.cli import main

from .conftest import fibonacci_sphere


@pytest.fixture
def sphere_file(tmp_path):
    path = tmp_path / "sphere.ply"
    io.save(path, fibonacci_sphere(2000))
    return path


def test_still_with_buffers(tmp_path, sphere_file, capsys):
    out = tmp_path / "img.png"
    bufs = tmp_path / "buffers"
    rc = main(["render", str(sphere_file), "-o", str(out), "--size", "40x30", "--eye", "0,0,3", "--target", "0,0,0",
               "--fov", "40", "--buffers", str(bufs)])
    assert rc == 0 and out.exists()
    from PIL import Image

    assert Image.open(out).size == (40, 30)
    depth = np.load(bufs / "depth.npy")
    normal = np.load(bufs / "normal.npy")
    coverage = np.load(bufs / "coverage.npy")
    weight = np.load(bufs / "weight.npy")
    assert depth.shape == (30, 40) and depth.dtype == np.float64
    assert normal.shape == (30, 40, 3) and coverage.dtype == bool and weight.shape == (30, 40)
    assert np.all(np.isinf(depth[~coverage])) and np.all(normal[~coverage] == 0)
    assert depth[15, 20] == pytest.approx(2.0, abs=0.01)
    assert np.allclose(normal[15, 20], [0.024, -0.024, 1.0], atol=0.01)  # analytic normal at that pixel ray
    assert np.all(weight[coverage] > 0)
    assert "wrote" in capsys.readouterr().out


def test_default_camera_ortho_shading_none_color_by(tmp_path, sphere_file):
    out = tmp_path / "a.png"
    assert main(["render", str(sphere_file), "-o", str(out), "--size", "32x32", "--ortho", "2.5", "--shading", "none",
                 "--color-by", "height", "--no-legend", "--colormap", "gray"]) == 0
    from PIL import Image

    img = np.asarray(Image.open(out)).astype(float) / 255
    assert img[16, 16, 0] != img[3, 16, 0] or img[3, 16, 0] == 1.0


def test_turntable_gif(tmp_path, sphere_file):
    from PIL import Image

    out = tmp_path / "spin.gif"
    assert main(["render", str(sphere_file), "-o", str(out), "--size", "24x16", "--turntable", "3", "--no-progress"]) == 0
    assert Image.open(out).n_frames == 3


def test_frames_directory_to_gif_and_mixed_inputs(tmp_path, sphere_file):
    d = tmp_path / "run"
    for k in range(2):
        io.save(d / "frames" / f"frame_{k:05d}.ply", Particles([[0.1 * k, 0, 0], [0, 0.3, 0]], attributes={"density": [1.0, 2.0]}))
    out = tmp_path / "run.gif"
    assert main(["render", str(d), "-o", str(out), "--size", "20x20", "--no-progress", "--color-by", "density"]) == 0
    assert out.exists()
    mesh = tmp_path / "quad.obj"
    io.save(mesh, TriangleMesh([[-2, -1.2, -2], [2, -1.2, -2], [2, -1.2, 2], [-2, -1.2, 2]], [[0, 2, 1], [0, 3, 2]]))
    assert main(["render", str(sphere_file), str(mesh), "-o", str(tmp_path / "mix.png"), "--size", "30x20"]) == 0


@pytest.mark.parametrize("argv, message", [
    (["--size", "12"], "--size"),
    (["--eye", "1,2"], "--eye"),
    (["-o", "x.txt"], "-o"),
    (["--turntable", "3", "-o", "x.png"], "--turntable"),
])
def test_errors_are_one_line(tmp_path, sphere_file, capsys, argv, message):
    args = ["render", str(sphere_file), "-o", str(tmp_path / "a.png"), *argv]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.startswith("unmesh: error:") and message in err and err.count("\n") == 1


def test_missing_input(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope.ply"), "-o", str(tmp_path / "a.png")]) == 1
    assert "nope.ply" in capsys.readouterr().err


def test_stills_are_antialiased_by_default(tmp_path, sphere_file):
    from PIL import Image

    args = ["render", str(sphere_file), "--size", "40x40", "--ortho", "2.4", "--shading", "none"]
    assert main([*args, "-o", str(tmp_path / "aa.png")]) == 0
    assert main([*args, "-o", str(tmp_path / "one.png"), "--aa", "1"]) == 0
    aa = np.asarray(Image.open(tmp_path / "aa.png")).astype(float) / 255
    one = np.asarray(Image.open(tmp_path / "one.png")).astype(float) / 255
    interior = aa[20, 20, :3]

    def blended(img):  # neither the background (white) nor the surface colour
        rgb = img[..., :3]
        return (np.abs(rgb - 1.0).max(-1) > 0.03) & (np.abs(rgb - interior).max(-1) > 0.03)

    assert blended(aa).sum() > 20 and blended(one).sum() == 0
