import subprocess
import sys

import pytest

from unmesh import __version__
from unmesh.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert __version__ in capsys.readouterr().out


def test_usage_error_is_one_line_exit_1(capsys):
    with pytest.raises(SystemExit) as info:
        main(["no-such-command"])
    assert info.value.code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("unmesh: error:")


def test_user_error_is_one_line_and_debug_shows_traceback(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_text("this is not a ply file\n")
    proc = subprocess.run([sys.executable, "-m", "unmesh", "info", str(bad)], capture_output=True, text=True)
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("unmesh: error:") and "bad.ply" in lines[0]
    proc = subprocess.run([sys.executable, "-m", "unmesh", "--debug", "info", str(bad)], capture_output=True, text=True)
    assert proc.returncode != 0 and "Traceback" in proc.stderr


def test_missing_file_is_one_line(tmp_path, capsys):
    assert main(["info", str(tmp_path / "missing.ply")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.ply" in err[0]
