"""Scene files, the tree parser and ``unmesh csg``."""

import re

import numpy as np
import pytest

from unmesh import SurfelCloud, scenes
from unmesh.cli import main
from unmesh.csg import Patch
from unmesh.csg.scene import load, parse_tree
from unmesh.errors import SceneError
from unmesh.io import save

P = {k: Patch(SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0]), k) for k in ("a", "b", "c", "d")}


def test_parser_uses_python_precedence():
    for text in ["a | b & c - d", "(a | b) & ~c", "a - b - c", "~~a & (b | ~(c - d))", "a & b | c & d"]:
        expected = eval(text, {}, dict(P))  # Python's operators on the patches build the reference tree
        assert str(parse_tree(text, P)) == str(expected), text


@pytest.mark.parametrize(("text", "message"), [
    ("a & e", "unknown patch 'e' at column 5"),
    ("a & (b | c", "expected ')' at column 11 (opened at column 5)"),
    ("a + b", "unexpected character '+' at column 3"),
    ("a b", "unexpected 'b' at column 3"),
    ("a &", "expected a patch name, '~' or '(' at column 4, got end of the expression"),
])
def test_parser_errors_name_the_column(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_tree(text, P)


SCENE = """
[patches.top]
file = "top.ply"
[patches.ball]
shape = { type = "sphere", radius = 0.6, center = [0.5, 0.5, 0.5] }
spacing = 0.1
color = [0.8, 0.2, 0.2]
[patches.floor]
halfspace = { point = [0, 0, 0], normal = [0, -1, 0], extent = 2.0 }
spacing = 0.25
[csg]
tree = "(top & floor) - ball"
"""


def _write(tmp_path, text, cloud=None):
    cloud = cloud if cloud is not None else Patch.halfspace((0, 1, 0), (0, 1, 0), 2.0, 0.25).cloud
    save(tmp_path / "top.ply", cloud)
    f = tmp_path / "scene.toml"
    f.write_text(text)
    return f


def test_issue_example_scene_loads(tmp_path):
    sc = load(_write(tmp_path, SCENE))
    assert str(sc.model) == "((top & floor) & ~ball)"
    assert np.allclose(sc.patches["ball"].cloud.colors, [0.8, 0.2, 0.2])
    assert np.allclose(sc.patches["floor"].cloud.normals, [0, -1, 0])


@pytest.mark.parametrize(("change", "message"), [
    (('tree = "(top & floor) - ball"', 'tree = "(top & flor) - ball"'), "key 'csg.tree': unknown patch 'flor' at column 8"),
    (('tree = "(top & floor) - ball"', 'tree = "(top & floor - ball"'), "key 'csg.tree': expected '\\)' at column"),
    (("spacing = 0.1", "spacing = -0.1"), "key 'patches.ball.spacing'"),
    (("extent = 2.0", "extent = nan"), "key 'patches.floor.halfspace.extent'"),
    (("normal = [0, -1, 0]", "normal = [0, 0, 0]"), "key 'patches.floor.halfspace.normal'"),
    (("radius = 0.6,", "radius = 0.6, wobble = 1,"), "patches.ball.shape"),
    (('file = "top.ply"', 'file = "nope.ply"'), "key 'patches.top.file': file not found"),
    (("spacing = 0.25", "spacing = 0.25\nspacng = 1"), "patches.floor.spacng"),
])
def test_scene_errors_name_file_and_key(tmp_path, change, message):
    f = _write(tmp_path, SCENE.replace(*change))
    with pytest.raises(SceneError, match=message) as exc:
        load(f)
    assert "scene.toml" in str(exc.value)


def test_inward_normals_and_empty_patch_are_rejected(tmp_path):
    from unmesh.shapes import Sphere

    inward = Sphere(radius=0.5).surfels(0.1)
    inward = inward.replace(normals=-inward.normals)
    with pytest.raises(SceneError, match=r"key 'patches.top.file'.*inwards"):
        load(_write(tmp_path, SCENE, inward))
    empty = SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0))
    with pytest.raises(SceneError, match=r"key 'patches.top.file'.*non-empty"):
        load(_write(tmp_path, SCENE, empty))


def test_every_shipped_scene_loads():
    names = [n for n in scenes.available() if n.startswith("csg/")]
    assert len(names) >= 5
    for n in names:
        load(scenes.path(n))


def test_cli_renders_image_buffers_and_classes(tmp_path, capsys):
    f = _write(tmp_path, SCENE)
    out = tmp_path / "out.png"
    rc = main(["csg", str(f), "-o", str(out), "--size", "48x32", "--buffers", str(tmp_path / "buf"),
               "--classify", str(tmp_path / "cls.png")])
    assert rc == 0 and out.exists() and (tmp_path / "cls.png").exists()
    depth = np.load(tmp_path / "buf" / "depth.npy")
    assert depth.shape == (32, 48) and np.isfinite(depth).any()
    assert main(["csg", "icosahedron", "-o", str(tmp_path / "ico.png"), "--size", "32x32"]) == 0
    assert main(["csg", str(f), "-o", str(tmp_path / "bad.txt")]) == 1
    assert "expected an image file" in capsys.readouterr().err
