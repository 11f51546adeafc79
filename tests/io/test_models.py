"""The classic test models (shared/data/models): counts and topology from their README."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from unmesh.io import load, load_mesh, save


def _directed_edges(faces):
    return np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])


def _edge_counts(edges, nv):
    """Occurrences of each distinct edge (rows as int64 keys: fast unique)."""
    return np.unique(edges[:, 0] * nv + edges[:, 1], return_counts=True)[1]


def test_bunny_obj(models_dir):
    m = load(models_dir / "stanford-bunny.obj")
    assert m.vertices.shape == (35947, 3) and m.faces.shape == (69451, 3)
    assert len(m.boundary_edges()) == 223
    unused = len(m.vertices) - len(np.unique(m.faces))
    assert unused == 1113  # unreferenced vertices are kept
    assert m.uv is None and m.vertex_normals is None


def test_igea_tristrips(models_dir):
    m = load(models_dir / "igea.ply")
    assert m.vertices.shape == (134345, 3) and m.faces.shape == (268686, 3)
    directed = _directed_edges(m.faces)
    nv = len(m.vertices)
    # consistently oriented: every directed edge once
    assert _edge_counts(directed, nv).max() == 1
    # closed manifold: every undirected edge in exactly two faces
    counts = _edge_counts(np.sort(directed, axis=1), nv)
    assert np.all(counts == 2)
    euler = len(m.vertices) - len(counts) + len(m.faces)
    assert euler == 2  # genus 0
    assert m.volume() > 0  # outward orientation


def test_igea_ply_round_trip_is_exact_and_float(models_dir, tmp_path):
    m = load_mesh(models_dir / "igea.ply")
    save(tmp_path / "igea.ply", m)
    head = (tmp_path / "igea.ply").read_bytes()[:300].decode("latin-1")
    assert "property float x" in head  # float32 source data stays float
    back = load(tmp_path / "igea.ply")
    np.testing.assert_array_equal(back.vertices, m.vertices)
    np.testing.assert_array_equal(back.faces, m.faces)


def test_spot_with_texture(models_dir, tmp_path):
    plain = load(models_dir / "spot.obj")
    assert plain.uv is not None and plain.texture is None
    assert plain.faces.shape == (5856, 3)
    assert len(plain.vertices) >= 2930  # seams split vertices with several uv
    # welding the split copies gives back the closed genus-0 surface
    _, weld = np.unique(plain.vertices, axis=0, return_inverse=True)
    faces = weld.reshape(-1)[plain.faces]
    counts = _edge_counts(np.sort(_directed_edges(faces), axis=1), len(plain.vertices))
    assert np.all(counts == 2) and weld.max() + 1 == 2930

    shutil.copy(models_dir / "spot.obj", tmp_path / "spot.obj")
    shutil.copy(models_dir / "spot_texture.png", tmp_path / "spot_texture.png")
    text = (tmp_path / "spot.obj").read_text()
    (tmp_path / "spot.obj").write_text("mtllib spot.mtl\nusemtl spot\n" + text)
    (tmp_path / "spot.mtl").write_text("newmtl spot\nKd 1 1 1\nmap_Kd spot_texture.png\n")
    m = load(tmp_path / "spot.obj")
    assert m.texture is not None and m.texture.shape == (1024, 1024, 3)
    np.testing.assert_array_equal(m.uv, plain.uv)
    # the cow's texture round-trips through OBJ + MTL + PNG
    save(tmp_path / "out" / "cow.obj", m)
    back = load(tmp_path / "out" / "cow.obj")
    np.testing.assert_array_equal(back.texture, m.texture)
    np.testing.assert_array_equal(back.uv, m.uv)
    np.testing.assert_array_equal(back.faces, m.faces)


@pytest.mark.parametrize("name,nv,nf", [("armadillo.obj", 43243, 86482), ("fandisk.obj", 6475, 12946),
                                        ("xyzrgb-dragon-20k.obj", 10002, 20000),
                                        ("max-planck-decimated.obj", 5272, 10540), ("cow.obj", 2903, 5804)])
def test_closed_models(models_dir, name, nv, nf):
    m = load(models_dir / name)
    assert m.vertices.shape == (nv, 3) and m.faces.shape == (nf, 3)
    assert len(m.boundary_edges()) == 0


def test_models_through_off_and_ascii_ply(models_dir, tmp_path):
    m = load(models_dir / "fandisk.obj")
    save(tmp_path / "f.off", m)
    back = load(tmp_path / "f.off")
    np.testing.assert_array_equal(back.vertices, m.vertices)
    np.testing.assert_array_equal(back.faces, m.faces)
    save(tmp_path / "f.ply", m, binary=False)
    back = load(tmp_path / "f.ply")
    np.testing.assert_array_equal(back.vertices, m.vertices)
    np.testing.assert_array_equal(back.faces, m.faces)
