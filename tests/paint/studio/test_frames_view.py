"""Tile encoding (frames) and the orbit view (cameras)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from unmesh.errors import InputError
from unmesh.paint.studio.frames import FrameEncoder, decode
from unmesh.paint.studio.view import PRESETS, Framing, View


def _apply(canvas, head, blobs):
    for (x, y, w, h, _), blob in zip(head["rects"], blobs, strict=True):
        canvas[y:y + h, x:x + w] = np.asarray(Image.open(io.BytesIO(blob)).convert("RGB"))


def test_tiles_cover_exactly_the_changed_pixels():
    rng = np.random.default_rng(1)
    enc = FrameEncoder(tile=16, quality=95)
    img = (rng.random((70, 100, 3)) * 40 + 100).astype(np.uint8)
    head, blobs = decode(enc.encode("model", img))
    assert head["full"] and head["rects"][0][:4] == [0, 0, 100, 70]
    canvas = np.zeros_like(img)
    _apply(canvas, head, blobs)
    new = img.copy()
    new[20:23, 40:75] = [200, 10, 10]      # tiles (1, 2..4)
    new[69, 99] = [0, 0, 0]                # the last, partial tile
    head, blobs = decode(enc.encode("model", new))
    assert not head["full"]
    assert [r[:4] for r in head["rects"]] == [[32, 16, 48, 16], [96, 64, 4, 6]]
    _apply(canvas, head, blobs)
    changed = np.any(new != img, axis=2)
    # the changed pixels reach the page (JPEG: within a few levels)
    assert np.abs(canvas[changed].astype(int) - new[changed].astype(int)).max() <= 40
    assert enc.encode("model", new) is None
    assert decode(enc.encode("model", new, full=True))[0]["full"]


def test_large_change_sends_a_full_frame_and_previews_are_not_a_base():
    enc = FrameEncoder(tile=8)
    img = np.zeros((32, 32, 3), np.uint8)
    enc.encode("m", img)
    head, _ = decode(enc.encode("m", img + 50))
    assert head["full"]
    head, _ = decode(enc.encode("m", img[:16, :16], scale=2))
    assert head["scale"] == 2 and head["w"] == 32 and head["full"]
    head, _ = decode(enc.encode("m", img))
    assert head["full"]  # after a preview the next frame is whole
    head, blobs = decode(enc.encode("m", img[:11, :10], scale=3, size=(32, 32)))
    assert (head["w"], head["h"], head["scale"]) == (32, 32, 3) and head["rects"][0][:4] == [0, 0, 10, 11]
    assert head["enc"] >= 0 and len(blobs) == 1


def test_view_cameras_look_at_the_framed_centre():
    fr = Framing(center=np.array([1.0, 2.0, 3.0]), radius=0.5)
    for name, (yaw, pitch) in PRESETS.items():
        cam = fr.camera(View(yaw=yaw, pitch=pitch), 320, 200)
        row, col, _depth = cam.project(fr.center[None])
        assert abs(row[0] - 100) < 1e-6 and abs(col[0] - 160) < 1e-6, name
        # the framing sphere fits: a point at radius along camera right/up stays inside the image
        for axis in (cam.right, cam.true_up):
            r, c, _ = cam.project((fr.center + fr.radius * axis)[None])
            assert 0 <= r[0] <= 200 and 0 <= c[0] <= 320
    front = fr.camera(View(yaw=90, pitch=0), 100, 100)
    assert np.allclose(front.forward, [-1, 0, 0])
    top = fr.camera(View(yaw=0, pitch=90), 100, 100)
    assert np.allclose(top.forward, [0, -1, 0])
    near = fr.camera(View(yaw=90, pitch=0, zoom=2.0), 100, 100)
    assert near.pixels_per_unit == pytest.approx(2 * front.pixels_per_unit)
    panned = fr.camera(View(yaw=90, pitch=0, pan=(1.0, 0.0)), 100, 100)
    assert np.allclose(panned.target - fr.center, 0.5 * front.right)


@pytest.mark.parametrize("kw, key", [({"pitch": 91}, "pitch"), ({"zoom": 0}, "zoom"), ({"yaw": float("nan")}, "yaw"),
                                     ({"pan": (1,)}, "pan"), ({"pan": ("a", 1)}, "pan"), ({"yaw": True}, "yaw")])
def test_bad_views(kw, key):
    with pytest.raises(InputError, match=f"view.{key}"):
        View(**kw)


def test_changed_rects_within_windows_equal_the_whole_image_search():
    rng = np.random.default_rng(3)
    enc = FrameEncoder(tile=16)
    for _ in range(30):
        h, w = rng.integers(20, 90, size=2)
        old = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
        new = old.copy()
        windows = []
        for _ in range(rng.integers(1, 4)):
            r0, c0 = rng.integers(0, h), rng.integers(0, w)
            r1, c1 = r0 + rng.integers(1, 30), c0 + rng.integers(1, 30)
            windows.append((int(r0), int(r1), int(c0), int(c1)))
            new[r0:r1, c0:c1] = rng.integers(0, 255, new[r0:r1, c0:c1].shape, dtype=np.uint8)
        assert enc.changed_rects(old, new, windows) == enc.changed_rects(old, new)
    # the encoder's base image follows the sent tiles
    enc = FrameEncoder(tile=8)
    img = np.zeros((32, 32, 3), np.uint8)
    enc.encode("m", img)
    new = img.copy()
    new[3, 3] = 9
    head, _ = decode(enc.encode("m", new, windows=[(0, 5, 0, 5)]))
    assert [r[:4] for r in head["rects"]] == [[0, 0, 8, 8]]
    assert enc.encode("m", new) is None
