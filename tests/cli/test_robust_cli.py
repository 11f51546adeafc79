"""Issue 24.3 / 23.15-16: one-line errors for everything, --debug anywhere, shipped scenes, plain help."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from unmesh.cli import main, plain_text

FEM_DROP = """
[simulation]
dt = 0.01
duration = {duration}
fps = 50
[material]
young = 50
[ground]
[[objects]]
mesh = {{ type = "hex_grid", cells = {cells}, origin = [0, 0.5, 0] }}
"""


def _unmesh(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "unmesh", *args], capture_output=True, text=True, cwd=cwd)


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("unmesh: error:")
    return lines[0]


def test_unexpected_exception_is_one_line_and_debug_anywhere(monkeypatch, capsys, tmp_path):
    import unmesh.cli.info as info

    def boom(args):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(info, "run", boom)
    assert main(["info", str(tmp_path / "x.ply")]) == 1
    line = _one_line(capsys.readouterr().err)
    assert line == "unmesh: error: unexpected RuntimeError: boom | second line (run with --debug for the traceback)"
    for argv in (["--debug", "info", "x.ply"], ["info", "x.ply", "--debug"], ["info", "--debug", "x.ply"]):
        with pytest.raises(RuntimeError, match="boom"):
            main(argv)


def test_debug_after_the_sub_command_shows_the_traceback(tmp_path):
    bad = tmp_path / "big.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n")
    proc = _unmesh("info", str(bad))
    assert proc.returncode == 1 and "big.obj: element 'f': line 4" in _one_line(proc.stderr)
    proc = _unmesh("info", str(bad), "--debug")
    assert proc.returncode != 0 and "Traceback" in proc.stderr and "FormatError" in proc.stderr


@pytest.mark.parametrize(("name", "content", "needle"), [
    ("off.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999999999999\n", "element 'face'"),
    ("junk.obj", bytes(range(256)) * 12, "not an OBJ"),
    ("count.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\n"
                  b"property float y\nproperty float z\nend_header\n" + bytes(12), "file ends after 1 of 1000000000000"),
])
def test_loader_reproducers_via_the_cli(tmp_path, capsys, name, content, needle):
    p = tmp_path / name
    (p.write_bytes if isinstance(content, bytes) else p.write_text)(content)
    assert main(["info", str(p)]) == 1
    assert needle in _one_line(capsys.readouterr().err)


def test_oversized_scene_is_refused_before_any_output(tmp_path):
    scene = tmp_path / "grid.toml"
    scene.write_text(FEM_DROP.format(duration=0.02, cells="[1000000, 2, 2]"))
    out = tmp_path / "out"
    proc = _unmesh("fem", str(scene), "-o", str(out), "--no-progress")
    assert proc.returncode == 1
    assert "key 'objects[0].mesh.cells'" in _one_line(proc.stderr) and "memory budget" in proc.stderr
    assert not out.exists()


def test_resume_with_a_truncated_or_foreign_checkpoint(tmp_path, capsys):
    from unmesh.sim.checkpoint import load_checkpoint, save_checkpoint

    scene = tmp_path / "drop.toml"
    scene.write_text(FEM_DROP.format(duration=0.02, cells="[1, 1, 1]"))
    out = tmp_path / "out"
    assert main(["fem", str(scene), "-o", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    ck = out / "checkpoint.npz"
    good, good_meta = load_checkpoint(ck)
    good = dict(good)
    data = ck.read_bytes()
    ck.write_bytes(data[: len(data) // 2])
    assert main(["fem", str(scene), "-o", str(out), "--resume", "--no-progress"]) == 1
    assert "unreadable checkpoint" in _one_line(capsys.readouterr().err)
    save_checkpoint(ck, {"positions": np.zeros((4, 3)), "time": 0.0},
                    {"frame": 0, "steps": 0, "wall_seconds": 0.0, "frames": []})
    assert main(["fem", str(scene), "-o", str(out), "--resume", "--no-progress"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "checkpoint.npz: the checkpoint has no 'points' (written by another kind of simulation" in line
    # same keys, other shapes (another scene's checkpoint): the array and both shapes in one line
    state = {k: (np.zeros((3, 3)) if k == "u" else v) for k, v in good.items()}
    save_checkpoint(ck, state, good_meta)
    assert main(["fem", str(scene), "-o", str(out), "--resume", "--no-progress"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "checkpoint.npz: array 'u' has shape (3, 3) but this scene needs (8, 3)" in line


def test_scenes_command_lists_one_line_per_shipped_scene(capsys):
    from unmesh.scene import shipped_scenes

    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    names = shipped_scenes()
    listed = [ln.split()[0] for ln in lines if ln.split() and ln.split()[0] in names]
    assert listed == names
    assert any(ln.startswith("sph/dam_break ") and "Dam break" in ln for ln in lines)
    assert main(["scenes", "fem"]) == 0
    assert all(ln.startswith("fem/") for ln in capsys.readouterr().out.strip().splitlines()[:-2])


def test_shipped_scene_by_name_runs(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["fem", "single_element", "-o", str(out), "--duration", "0.02", "--no-progress"]) == 0
    assert "single_element.toml: completed" in capsys.readouterr().out
    assert main(["sph", "no_such_scene", "-o", str(tmp_path / "o2")]) == 1
    assert "no_such_scene: scene file not found (shipped scenes: 'unmesh scenes')" in _one_line(capsys.readouterr().err)


@pytest.mark.parametrize("command", ["render", "fem", "sph", "shell", "info", "sample", "scenes", "gallery"])
def test_help_has_no_rest_markup(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    assert "``" not in text and "::" not in text and ":func:" not in text


def test_plain_text():
    assert plain_text("Examples::\n\n    unmesh x\n") == "Examples:\n\n    unmesh x\n"
    assert plain_text("see :class:`~unmesh.io.Foo` and ``a.ply``") == "see unmesh.io.Foo and a.ply"
