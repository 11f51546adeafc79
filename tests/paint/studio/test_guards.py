"""Studio guards without a server: tokens, origins, static files, output paths, messages."""

from __future__ import annotations

import os

import pytest

from unmesh.errors import InputError
from unmesh.paint.studio import protocol, security


def test_token_is_random_and_compared_exactly():
    a, b = security.new_token(), security.new_token()
    assert a != b and len(a) >= 40
    assert security.token_ok(a, a)
    for wrong in (None, "", b, a[:-1], a + "x", a.upper() if a.upper() != a else a.lower()):
        assert not security.token_ok(wrong, a)


@pytest.mark.parametrize("origin, ok", [
    ("http://127.0.0.1:8123", True), ("http://localhost:8123", True), ("http://127.0.0.1:8124", False),
    ("https://127.0.0.1:8123", False), ("http://evil.example", False), ("null", False), (None, False), ("", False),
    ("http://127.0.0.1:8123.evil.example", False),
])
def test_origin(origin, ok):
    assert security.origin_ok(origin, 8123) is ok


def test_host():
    assert security.host_ok("127.0.0.1:80", 80) and security.host_ok("localhost:80", 80)
    assert not security.host_ok("evil.example:80", 80) and not security.host_ok(None, 80)


@pytest.fixture
def static_root(tmp_path):
    root = tmp_path / "static"
    (root / "js").mkdir(parents=True)
    (root / "index.html").write_text("<p>hi</p>")
    (root / "js" / "a.js").write_text("export {}")
    (tmp_path / "secret.js").write_text("secret")
    (tmp_path / "secret.html").write_text("secret")
    os.symlink(tmp_path / "secret.js", root / "js" / "link.js")
    os.symlink(tmp_path, root / "up")
    return root


def test_static_serves_own_files(static_root):
    assert security.static_file(static_root, "index.html").read_text() == "<p>hi</p>"
    assert security.static_file(static_root, "js/a.js").name == "a.js"
    with pytest.raises(FileNotFoundError):
        security.static_file(static_root, "js/missing.js")


@pytest.mark.parametrize("path", [
    "../secret.js", "js/../../secret.js", "..", ".", "./index.html", "/etc/passwd", "//etc/passwd",
    "%2e%2e/secret.js", "%252e%252e/secret.js", "..%2fsecret.js", "js\\..\\..\\secret.js", "js//a.js",
    "js/link.js", "up/secret.js", "up/secret.html", "index.html\x00.js", "", "js/", ".hidden.js", "server.py",
])
def test_static_refuses_escapes(static_root, path):
    with pytest.raises(security.PathRefused):
        security.static_file(static_root, path)


def test_output_paths(tmp_path):
    assert security.output_path(tmp_path, "a-b_1.ply", (".ply",)) == tmp_path.resolve() / "a-b_1.ply"
    (tmp_path / "link.ply").symlink_to(tmp_path / "elsewhere.ply")
    for name in ("../a.ply", "/tmp/a.ply", "sub/a.ply", "a.txt", ".a.ply", "a..ply", "", None, "link.ply",
                 "a.ply\x00", "%2e%2e%2fa.ply", "x" * 200 + ".ply"):
        with pytest.raises(security.PathRefused):
            security.output_path(tmp_path, name, (".ply",))


@pytest.mark.parametrize("text, key", [
    ("not json", "message"), ("[1, 2]", "message"), ('{"type": 3}', "type"), ('{"type": "drop_tables"}', "type"),
    ("x" * (protocol.MAX_MESSAGE + 1), "message"),
])
def test_malformed_messages(text, key):
    with pytest.raises(InputError, match=f"^{key}"):
        protocol.parse_message(text)


def test_specs_name_the_key():
    assert protocol.brush_spec({"type": "flat", "size": 0.1}) == {"type": "flat", "size": 0.1}
    with pytest.raises(InputError, match=r"brush\.type"):
        protocol.brush_spec({"type": "sponge", "size": 0.1})
    with pytest.raises(InputError, match=r"brush\.size"):
        protocol.brush_spec({"type": "round", "size": float("nan")})
    with pytest.raises(InputError, match=r"paint\.color\[1\]"):
        protocol.paint_spec({"type": "oil", "color": [0.1, 2.0, 0.3]})
    with pytest.raises(InputError, match=r"samples\[1\]\.pressure"):
        protocol.samples_spec([[0, 1, 1, 0.5, 0, 0], [1, 1, 1, 1.5, 0, 0]], 10, 10)
    with pytest.raises(InputError, match=r"samples\[0\]"):
        protocol.samples_spec([[0, 1]], 10, 10)
    with pytest.raises(InputError, match="samples"):
        protocol.samples_spec([[0, 1, 1, 0.5, 0, 0]] * (protocol.MAX_SAMPLES + 1), 10, 10)
