import json

import pytest

from unmesh.io.atomic import atomic_path, atomic_write, atomic_write_json, atomic_write_text


def test_failed_write_keeps_old_file_and_leaves_no_temp(tmp_path):
    target = tmp_path / "out.txt"
    atomic_write_text(target, "old")
    with pytest.raises(RuntimeError), atomic_write(target, "w") as fh:
        fh.write("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_atomic_path_keeps_extension_and_creates_dirs(tmp_path):
    target = tmp_path / "a" / "b" / "img.png"
    with atomic_path(target) as tmp:
        assert tmp.suffix == ".png" and tmp.parent == target.parent
        tmp.write_bytes(b"x")
    assert target.read_bytes() == b"x"


def test_json_nan_becomes_null(tmp_path):
    atomic_write_json(tmp_path / "s.json", {"a": float("nan"), "b": [1.0, float("inf")]})
    assert json.loads((tmp_path / "s.json").read_text()) == {"a": None, "b": [1.0, None]}


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_written_files_get_the_umask_mode_not_0600(tmp_path, mask):
    import os
    import stat

    from unmesh import Particles, io
    from unmesh.io.atomic import file_mode

    old = os.umask(mask)
    try:
        assert file_mode() == 0o666 & ~mask
        atomic_write_text(tmp_path / "a.txt", "x")
        with atomic_path(tmp_path / "b.bin") as tmp:
            tmp.write_bytes(b"y")
        io.save(tmp_path / "c.ply", Particles([[0.0, 0.0, 0.0]]))
    finally:
        os.umask(old)
    for name in ("a.txt", "b.bin", "c.ply"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~mask, name
