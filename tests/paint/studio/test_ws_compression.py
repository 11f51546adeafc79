"""The studio's WebSocket compresses its messages (permessage-deflate, RFC 7692) when the page
offers it, as browsers do: painting frames (raw RGBA tiles) arrive deflated and decode to the
same frames; a compressed message that inflates past the size limit is refused like an
oversized plain one, and the session keeps working."""

from __future__ import annotations

import asyncio
import json

import aiohttp

from unmesh.paint.studio.frames import decode
from unmesh.paint.studio.protocol import MAX_MESSAGE


def _stroke_messages() -> list[dict]:
    rows = [[8.0 * i, 110 + 8 * i, 120 + i, 0.9, 0, 0] for i in range(12)]
    return [{"type": "hello", "width": 320, "height": 240},
            {"type": "begin", "brush": {"type": "round", "size": 0.1},
             "paint": {"type": "oil", "color": [0.9, 0.2, 0.1], "drying": 0.05}},
            {"type": "samples", "samples": rows, "ts": 0}, {"type": "end"}, {"type": "sync", "id": 7}]


async def _frames(url: str, origin: dict, compress: int) -> tuple[int, list[bytes]]:
    frames = []
    async with aiohttp.ClientSession() as http, http.ws_connect(url, headers=origin, compress=compress) as ws:
        hello, *stroke = _stroke_messages()
        await ws.send_str(json.dumps(hello))
        while True:  # the first whole frame, before painting: the stroke's frames are then differential
            msg = await ws.receive(timeout=120)
            if msg.type == aiohttp.WSMsgType.BINARY:
                frames.append(msg.data)
                break
        for m in stroke:
            await ws.send_str(json.dumps(m))
        while True:
            msg = await ws.receive(timeout=120)
            if msg.type == aiohttp.WSMsgType.BINARY:
                frames.append(msg.data)
            elif msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data).get("type") == "synced":
                return ws.compress, frames


def test_frames_are_deflated_when_offered_and_decode_alike(studio):
    url = f"http://127.0.0.1:{studio.port}/ws?token={studio.token}"
    origin = {"Origin": f"http://127.0.0.1:{studio.port}"}
    negotiated, frames = asyncio.run(_frames(url, origin, compress=15))
    assert negotiated == 15                          # the server accepted permessage-deflate
    heads = [decode(f)[0] for f in frames]
    assert any(h["fmt"] == "rgba" and not h["full"] for h in heads)   # painting frames were sent
    for f in frames:                                 # inflated by the client: well-formed frames
        head, blobs = decode(f)
        assert [len(b) for b in blobs] == [r[4] for r in head["rects"]]
    plain, frames0 = asyncio.run(_frames(url, origin, compress=0))
    assert plain == 0 and frames0                    # a client that doesn't offer it gets plain frames


def test_compressed_message_over_the_limit_is_refused(studio):
    url = f"http://127.0.0.1:{studio.port}/ws?token={studio.token}"
    origin = {"Origin": f"http://127.0.0.1:{studio.port}"}
    bomb = " " * (4 * MAX_MESSAGE)                  # deflates to a few kilobytes

    async def run():
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(url, headers=origin, compress=15) as ws:
                await ws.send_str(bomb)
                msg = await ws.receive(timeout=60)
                while msg.type not in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED,
                                       aiohttp.WSMsgType.CLOSING):
                    msg = await ws.receive(timeout=60)
                closed = ws.close_code
            async with http.ws_connect(url, headers=origin, compress=15) as ws:
                await ws.send_str(json.dumps({"type": "sync", "id": 3}))
                while True:
                    msg = await ws.receive(timeout=60)
                    if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data).get("type") == "synced":
                        return closed

    assert asyncio.run(run()) == 1009                # message too big
