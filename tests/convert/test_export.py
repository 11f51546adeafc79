"""Written files: OBJ + MTL + PNG and .glb load in trimesh with their textures, give the same
pixels, and are written as one atomic set; the ``unmesh convert`` command."""

import json

import numpy as np
import pytest

from unmesh.cli import main
from unmesh.convert import TexturedMesh, write_textured
from unmesh.convert.export import _write_all
from unmesh.io import save
from unmesh.meshes import TriangleMesh
from unmesh.render import Camera, render

trimesh = pytest.importorskip("trimesh")


def _parts_from_trimesh(scene):
    parts = []
    geoms = scene.geometry.values() if hasattr(scene, "geometry") else [scene]
    for g in geoms:
        mat = g.visual.material
        img = getattr(mat, "baseColorTexture", None) or getattr(mat, "image", None)
        tex = np.asarray(img.convert("RGB"), dtype=np.float64) / 255.0
        parts.append(TriangleMesh(np.asarray(g.vertices), np.asarray(g.faces), uv=np.asarray(g.visual.uv), texture=tex))
    return TexturedMesh(tuple(parts))


def test_obj_and_glb_load_in_trimesh_with_textures_and_give_the_same_pixels(converted, tmp_path):
    tm = converted.textured
    obj_files = write_textured(tmp_path / "m.obj", tm)
    glb_files = write_textured(tmp_path / "m.glb", tm)
    assert {p.suffix for p in obj_files} == {".obj", ".mtl", ".png"}
    mtl = (tmp_path / "m.mtl").read_text()
    assert "map_Kd" in mtl and "norm " in mtl and "map_Bump" in mtl
    a = trimesh.load(tmp_path / "m.obj", force="scene")  # a scene also for one page
    b = trimesh.load(glb_files[0], force="scene")
    assert len(a.geometry) == len(b.geometry) == len(tm.parts)
    for g in b.geometry.values():
        assert g.visual.material.baseColorTexture is not None and g.visual.material.normalTexture is not None
    cam = Camera((2.0, 1.5, 2.5), (0, 0, 0), width=160, height=160, fov=40)
    ia = render(_parts_from_trimesh(a), cam, shading="none")
    ib = render(_parts_from_trimesh(b), cam, shading="none")
    # the files carry no patch regions, so the rasteriser builds a plain mip pyramid for both
    ref = render(TexturedMesh(tm.parts, tm.mip_levels, tm.depth_pages), cam, shading="none")
    assert (ia.coverage == ib.coverage).all()
    assert np.abs(ia.color - ib.color).max() <= 1.0 / 255 + 1e-9
    # and the files hold the in-memory result up to 8-bit quantisation
    assert np.abs(ia.color - ref.color)[ia.coverage & ref.coverage].max() <= 1.0 / 255 + 1e-6


def test_a_failing_file_leaves_nothing_written(tmp_path):
    files = [(tmp_path / "a.obj", "v 0 0 0\n"), (tmp_path / "a.png", np.zeros((2, 2, 3))),
             (tmp_path / "report.json", object())]  # the last one cannot be written
    with pytest.raises(Exception):  # noqa: B017
        _write_all(files)
    assert not list(tmp_path.iterdir())


def test_convert_command_writes_mesh_textures_and_report(pattern_cloud, tmp_path, capsys):
    src = tmp_path / "in.ply"
    save(src, pattern_cloud.subset(np.arange(0, 8000, 2)))
    rc = main(["convert", str(src), "-o", str(tmp_path / "out.obj"), "--faces", "150", "--report",
               str(tmp_path / "r.json"), "--no-progress"])
    assert rc == 0
    rep = json.loads((tmp_path / "r.json").read_text())
    for key in ("reconstruction", "simplification", "patches", "atlas", "timings"):
        assert key in rep
    assert rep["patches"]["triangles"] <= 150
    assert sum(rep["patches"]["texel_histogram"].values()) == rep["patches"]["triangles"]
    assert (tmp_path / "out.mtl").exists()
    assert "triangles" in capsys.readouterr().out


def test_convert_command_rejects_other_outputs(tmp_path, capsys):
    rc = main(["convert", str(tmp_path / "x.ply"), "-o", str(tmp_path / "out.stl")])
    assert rc == 1
    assert "expected a .obj or .glb" in capsys.readouterr().err


def test_mip_levels_are_assembled_in_the_same_layout_and_written(pattern_cloud, tmp_path):
    from unmesh.convert import ConvertOptions, convert_cloud

    res = convert_cloud(pattern_cloud.subset(np.arange(0, 8000, 4)), ConvertOptions(faces=60, mipmaps=True))
    tm = res.textured
    assert len(tm.mip_levels) == len(tm.parts)
    for part, (half, quarter) in zip(tm.parts, tm.mip_levels, strict=True):
        e = part.texture.shape[0]
        assert half.shape == (e // 2, e // 2, 3) and quarter.shape == (e // 4, e // 4, 3)
        # box filter of the full page where every texel of a block belongs to a patch
        assert abs(half.mean() - part.texture.mean()) < 0.05
    files = write_textured(tmp_path / "m.obj", tm)
    assert any(f.name.endswith("_mip1.png") for f in files) and any(f.name.endswith("_mip2.png") for f in files)


def test_report_has_no_per_triangle_arrays(pattern_cloud, tmp_path):
    src = tmp_path / "in.ply"
    save(src, pattern_cloud.subset(np.arange(0, 8000, 4)))
    assert main(["convert", str(src), "-o", str(tmp_path / "o.glb"), "--faces", "60", "--report",
                 str(tmp_path / "r.json"), "--no-progress", "--no-normal-map"]) == 0
    rep = json.loads((tmp_path / "r.json").read_text())
    assert not [k for k in rep if k.startswith("_")]
    assert rep["options"]["normal_map"] is False
    assert (tmp_path / "o.glb").stat().st_size > 1000
