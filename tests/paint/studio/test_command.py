"""``unmesh paint MODEL --no-browser``: the URL with its token, painting over the WebSocket,
autosave every few strokes, and Ctrl-C (SIGINT) saving the output file and exiting cleanly."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import aiohttp
import pytest

SRC = Path(__file__).resolve().parents[3] / "src"


async def _paint(url: str, n_strokes: int) -> list[dict]:
    base, token = url.split("/?token=")
    replies = []
    async with aiohttp.ClientSession() as http, \
            http.ws_connect(f"{base.replace('http', 'ws')}/ws?token={token}", headers={"Origin": base}) as ws:
        await ws.send_str(json.dumps({"type": "hello", "width": 200, "height": 150}))
        for k in range(n_strokes):
            await ws.send_str(json.dumps({"type": "begin", "brush": {"type": "round", "size": 0.08},
                                          "paint": {"type": "oil", "color": [0.1, 0.2, 0.9], "drying": 0.05}}))
            rows = [[10.0 * i, 90 + 2 * i, 70 + 3 * k, 0.8, 0, 0] for i in range(6)]
            await ws.send_str(json.dumps({"type": "samples", "samples": rows, "ts": 0}))
            await ws.send_str(json.dumps({"type": "end"}))
        await ws.send_str(json.dumps({"type": "sync", "id": 1}))
        while True:
            msg = await ws.receive(timeout=300)
            if msg.type == aiohttp.WSMsgType.TEXT:
                replies.append(json.loads(msg.data))
                if replies[-1]["type"] == "synced":
                    return replies


@pytest.mark.slow
def test_paint_command_serves_autosaves_and_saves_on_ctrl_c(tmp_path):
    out = tmp_path / "art.ply"
    env = {**os.environ, "PYTHONPATH": str(SRC), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "unmesh", "paint", "blob", "--spacing", "0.06", "--port", "0",
                             "--no-browser", "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=tmp_path)
    try:
        line = proc.stdout.readline()
        match = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[A-Za-z0-9_-]{40,})", line)
        assert match, line + proc.stderr.read() if proc.poll() is not None else line
        replies = asyncio.run(_paint(match.group(1), 5))
        kinds = [r["type"] for r in replies]
        assert "error" not in kinds, replies
        assert kinds.count("ended") == 5 and "autosaved" in kinds
        assert (tmp_path / "art.autosave.ply").is_file() and (tmp_path / "art.autosave.json").is_file()
        assert not out.exists()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert "saved" in stdout and out.is_file()
    strokes = json.loads((tmp_path / "art_strokes.json").read_text())["strokes"]
    assert len(strokes) == 5
    from unmesh.paint.session import Session

    assert len(Session.load(out).strokes_json()["strokes"]) == 5
