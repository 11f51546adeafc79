"""``unmesh sample`` end to end."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from unmesh.cli import main
from unmesh.io import load, save
from unmesh.shapes import Sphere, Torus


def test_sample_a_built_in_shape(tmp_path, capsys):
    out = tmp_path / "torus.ply"
    assert main(["sample", "torus", "-o", str(out), "--spacing", "0.1"]) == 0
    text = capsys.readouterr().out
    cloud = load(out)
    assert f"-> {len(cloud)} surfels" in text and str(out) in text
    v, _ = Torus().implicit(cloud.positions)
    assert np.abs(v).max() < 1e-12


def test_sample_a_mesh_file_with_default_spacing(tmp_path, capsys):
    mesh_path = tmp_path / "sphere.obj"
    mesh = Sphere(radius=2.0).mesh(resolution=24)
    save(mesh_path, mesh)
    out = tmp_path / "s.ply"
    assert main(["sample", str(mesh_path), "-o", str(out), "--ascii", "--no-progress"]) == 0
    text = capsys.readouterr().out
    diag = np.linalg.norm(np.subtract(*mesh.bounds()[::-1]))
    assert f"spacing: {diag / 200:.6g}" in text
    assert out.read_bytes().startswith(b"ply\nformat ascii")
    cloud = load(out)
    assert abs(np.linalg.norm(cloud.positions, axis=1) - 2.0).max() < 0.02


def test_errors_are_one_line(tmp_path, capsys):
    assert main(["sample", "nothing-here", "-o", str(tmp_path / "x.ply")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "blob, box, cylinder" in err
    assert main(["sample", "sphere", "-o", str(tmp_path / "x.txt")]) == 1
    assert ".ply" in capsys.readouterr().err
    assert main(["sample", "sphere", "-o", str(tmp_path / "x.ply"), "--spacing", "0"]) == 1
    assert "--spacing" in capsys.readouterr().err
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nf 1 2 3\n")
    assert main(["sample", str(bad), "-o", str(tmp_path / "y.ply")]) == 1
    assert "bad.obj" in capsys.readouterr().err


def test_console_script(tmp_path):
    out = tmp_path / "blob.ply"
    res = subprocess.run([sys.executable, "-m", "unmesh", "sample", "blob", "-o", str(out), "--spacing", "0.08"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert out.exists() and "wrote" in res.stdout
