"""The studio server's guards over real HTTP and WebSocket connections (raw requests, so that
no client normalises the paths first)."""

from __future__ import annotations

import asyncio
import base64
import http.client
import json
import os

import numpy as np
import pytest

from unmesh.paint.studio.protocol import MAX_MESSAGE


def request(studio, method, path, headers=None, body=None):
    conn = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=30)
    hdrs = {"Host": f"127.0.0.1:{studio.port}"}
    hdrs.update(headers or {})
    conn.request(method, path, body=body, headers=hdrs)
    res = conn.getresponse()
    data = res.read()
    conn.close()
    return res.status, res.headers, data


def ws_handshake(studio, query, origin):
    headers = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": base64.b64encode(os.urandom(16)).decode()}
    if origin is not None:
        headers["Origin"] = origin
    conn = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=30)
    conn.request("GET", "/ws" + query, headers={"Host": f"127.0.0.1:{studio.port}", **headers})
    status = conn.getresponse().status
    conn.close()
    return status


def test_page_and_headers(studio):
    status, headers, body = request(studio, "GET", "/")
    assert status == 200 and b"unmesh studio" in body
    assert headers["Content-Type"].startswith("text/html")
    assert "default-src 'self'" in headers["Content-Security-Policy"]
    assert headers["Referrer-Policy"] == "no-referrer"
    status, headers, body = request(studio, "GET", "/static/js/main.js")
    assert status == 200 and headers["Content-Type"].startswith("text/javascript") and b"import" in body


@pytest.mark.parametrize("path", [
    "/static/../server.py", "/static/%2e%2e/server.py", "/static/%2E%2E/server.py", "/static/%252e%252e/server.py",
    "/static/..%2fserver.py", "/static/..%252fserver.py", "/static/js/../../server.py", "/static//etc/passwd",
    "/static/%2fetc%2fpasswd", "/../../../etc/passwd", "/static/..\\server.py", "/static/server.py",
    "/static/%5c..%5cserver.py", "/static/js/%2e%2e/%2e%2e/security.py", "/static/.%2e/server.py",
])
def test_traversal_refused(studio, path):
    status, _, body = request(studio, "GET", path)
    assert status in (403, 404), (path, status)
    assert b"aiohttp" not in body and b"def " not in body and b"root:" not in body


def test_missing_file_and_symlink(studio, tmp_path):
    status, _, _ = request(studio, "GET", "/static/js/missing.js")
    assert status == 404
    root = tmp_path / "static"
    root.mkdir()
    (root / "index.html").write_text("<p>own</p>")
    (tmp_path / "secret.js").write_text("secret")
    os.symlink(tmp_path / "secret.js", root / "link.js")
    saved, studio.static_root = studio.static_root, root
    try:
        assert request(studio, "GET", "/")[0] == 200
        status, _, body = request(studio, "GET", "/static/link.js")
        assert status == 403 and b"secret" not in body
    finally:
        studio.static_root = saved


def test_wrong_host_refused(studio):
    status, _, _ = request(studio, "GET", "/", headers={"Host": f"evil.example:{studio.port}"})
    assert status == 403


def test_websocket_needs_token_and_origin(studio):
    own = f"http://127.0.0.1:{studio.port}"
    assert ws_handshake(studio, f"?token={studio.token}", own) == 101
    assert ws_handshake(studio, "", own) == 403
    assert ws_handshake(studio, "?token=", own) == 403
    assert ws_handshake(studio, f"?token={studio.token[:-2]}xx", own) == 403
    assert ws_handshake(studio, f"?token={studio.token}", "http://evil.example") == 403
    assert ws_handshake(studio, f"?token={studio.token}", f"http://127.0.0.1:{studio.port + 1}") == 403
    assert ws_handshake(studio, f"?token={studio.token}", None) == 403


def test_upload_guards(studio):
    own = {"Origin": f"http://127.0.0.1:{studio.port}"}
    ok = f"/api/upload?token={studio.token}&name=up.json"
    assert request(studio, "POST", ok, own, b"{}")[0] == 200
    assert (studio.workspace.folder / "up.json").read_bytes() == b"{}"
    assert request(studio, "POST", "/api/upload?name=up.json", own, b"{}")[0] == 403
    assert request(studio, "POST", ok, {"Origin": "http://evil.example"}, b"{}")[0] == 403
    assert request(studio, "POST", ok, {}, b"{}")[0] == 403
    for name in ("../up.json", "%2e%2e%2fup.json", "/tmp/up.json", "up.py", "sub%2fup.json"):
        status = request(studio, "POST", f"/api/upload?token={studio.token}&name={name}", own, b"{}")[0]
        assert status == 403, name
    # declared too large: refused before reading; chunked and too large: refused while reading
    saved, studio.max_upload = studio.max_upload, 1000
    try:
        assert request(studio, "POST", ok, own, b"x" * 1001)[0] == 413
        chunked = b"".join(b"258\r\n" + b"x" * 600 + b"\r\n" for _ in range(3)) + b"0\r\n\r\n"
        status = request(studio, "POST", ok, {**own, "Transfer-Encoding": "chunked"}, chunked)[0]
        assert status == 413
    finally:
        studio.max_upload = saved
    assert (studio.workspace.folder / "up.json").read_bytes() == b"{}"


def test_download_guards(studio):
    (studio.workspace.folder / "d.json").write_text("[1]")
    assert request(studio, "GET", f"/api/file?token={studio.token}&name=d.json")[2] == b"[1]"
    assert request(studio, "GET", "/api/file?name=d.json")[0] == 403
    assert request(studio, "GET", f"/api/file?token={studio.token}&name=../d.json")[0] == 403


def test_malformed_messages_keep_the_session(studio):
    import aiohttp

    before = studio.run_in_worker(lambda ws: ws.session.cloud().colors.copy())
    url = f"http://127.0.0.1:{studio.port}/ws?token={studio.token}"
    origin = {"Origin": f"http://127.0.0.1:{studio.port}"}
    bad = ["not json", "[]", '{"type": "explode"}', '{"type": "begin", "brush": {"type": "sponge", "size": 1}}',
           '{"type": "samples", "samples": [[0, 1, 2, 0.5, 0, 0]]}',
           '{"type": "begin", "brush": {"type": "round", "size": 0.05}, '
           '"paint": {"type": "oil", "color": [1, 0, 0], "drying": 0.1}}',
           '{"type": "samples", "samples": [[0, 1, "x", 0.5, 0, 0]]}', '{"type": "samples", "samples": 7}',
           '{"type": "end"}', '{"type": "view", "view": {"yaw": "north"}}', '{"type": "resize", "width": 1e9}',
           '{"type": "save", "name": "../../evil.ply"}', '{"type": "load", "name": "/etc/passwd"}',
           '{"type": "replay", "name": "nothere.json"}', '{"type": "pick_color", "x": -1, "y": 5}',
           '{"type": "undo", "extra": {"deep": [1, 2, 3]}}']

    async def run():
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(url, headers=origin) as ws:
                replies = []
                for text in bad:
                    await ws.send_str(text)
                await ws.send_bytes(b"\x00\x01")
                await ws.send_str(json.dumps({"type": "sync", "id": 1}))
                while True:
                    msg = await ws.receive(timeout=60)
                    if msg.type == aiohttp.WSMsgType.TEXT:
                        replies.append(json.loads(msg.data))
                        if replies[-1].get("type") == "synced":
                            break
            # an oversized message closes that connection (1009) ...
            async with http.ws_connect(url, headers=origin) as ws:
                await ws.send_str("x" * (MAX_MESSAGE + 10))
                msg = await ws.receive(timeout=60)
                while msg.type not in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING):
                    msg = await ws.receive(timeout=60)
                closed = ws.close_code
            # ... and a new one works
            async with http.ws_connect(url, headers=origin) as ws:
                await ws.send_str(json.dumps({"type": "sync", "id": 2}))
                while True:
                    msg = await ws.receive(timeout=60)
                    if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data).get("type") == "synced":
                        break
        return replies, closed

    replies, closed = asyncio.run(run())
    errors = [r["message"] for r in replies if r["type"] == "error"]
    assert len(errors) == 14, errors
    for key in ("message", "type", "brush.type", "samples: no stroke", "samples[0].y", "samples", "view.yaw",
                "width", "name", "x, y"):
        assert any(e.startswith(key) for e in errors), key
    assert closed == 1009
    assert not (studio.workspace.folder.parent / "evil.ply").exists()
    after = studio.run_in_worker(lambda ws: ws.session.cloud().colors.copy())
    assert before.shape == after.shape and np.array_equal(before, after)
