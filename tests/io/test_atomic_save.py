"""A failure while saving leaves the previous files (or none), never half-written ones."""

from __future__ import annotations

import numpy as np
import pytest

import unmesh.io._common as common
import unmesh.io._plyformat as plyformat
from unmesh.io import load, save
from unmesh.meshes import TriangleMesh
from unmesh.surfels import SurfelCloud


class Boom(RuntimeError):
    pass


def _cloud(n, value):
    return SurfelCloud(np.full((n, 3), value), np.tile([0, 0, 1.0], (n, 1)), radii=np.ones(n))


def test_failed_ply_write_keeps_old_file(tmp_path, monkeypatch):
    path = tmp_path / "c.ply"
    save(path, _cloud(5, 1.0))
    old = path.read_bytes()

    def broken(*args, **kwargs):
        raise Boom("disk full")

    monkeypatch.setattr(plyformat, "encode_ply", broken)
    import unmesh.io.ply as ply

    monkeypatch.setattr(ply, "encode_ply", broken)
    with pytest.raises(Boom):
        save(path, _cloud(7, 2.0))
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply"]
    with pytest.raises(Boom):
        save(tmp_path / "new.ply", _cloud(7, 2.0))
    assert not (tmp_path / "new.ply").exists()


def test_failure_while_writing_bytes_leaves_no_partial_file(tmp_path, monkeypatch):
    path = tmp_path / "c.ply"
    save(path, _cloud(5, 1.0))
    old = path.read_bytes()
    import os

    real_fsync = os.fsync

    def failing_fsync(fd):
        raise Boom("I/O error after the data was written")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(Boom):
        save(path, _cloud(1000, 3.0))
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply"]
    assert len(load(path)) == 5


def test_obj_mtl_png_are_replaced_together_or_not_at_all(tmp_path, monkeypatch, rng):
    v = rng.random((3, 3))
    mesh = TriangleMesh(v, [[0, 1, 2]], uv=rng.random((3, 2)), texture=np.zeros((2, 2, 3)),
                        normal_map=np.ones((2, 2, 3)))
    save(tmp_path / "m.obj", mesh)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert sorted(before) == ["m.mtl", "m.obj", "m.png", "m_normal.png"]
    calls = []
    real = common.write_png

    def second_png_fails(path, image):
        calls.append(path)
        if len(calls) == 2:
            raise Boom("cannot encode")
        real(path, image)

    import unmesh.io.obj as obj

    monkeypatch.setattr(obj, "write_png", second_png_fails)
    mesh2 = mesh.replace(vertices=v + 1.0, texture=np.ones((2, 2, 3)))
    with pytest.raises(Boom):
        save(tmp_path / "m.obj", mesh2)
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert after == before  # nothing replaced, no temporary files left
    monkeypatch.setattr(obj, "write_png", real)
    save(tmp_path / "m.obj", mesh2)
    np.testing.assert_array_equal(load(tmp_path / "m.obj").texture, np.ones((2, 2, 3)))
