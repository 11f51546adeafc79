"""Raw RGBA tiles of differential frames (``FrameEncoder(tiles="rgba")``): the page's copy of the
image equals the image exactly."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from unmesh.errors import InputError
from unmesh.paint.studio.frames import FrameEncoder, decode


def _apply(canvas, head, blobs):
    """What the page does: JPEG blobs decoded, RGBA rows copied."""
    for (x, y, w, h, n), blob in zip(head["rects"], blobs, strict=True):
        if head["fmt"] == "rgba":
            assert n == len(blob) == 4 * w * h
            rgba = np.frombuffer(blob, np.uint8).reshape(h, w, 4)
            assert (rgba[..., 3] == 255).all()
            canvas[y:y + h, x:x + w] = rgba[..., :3]
        else:
            canvas[y:y + h, x:x + w] = np.asarray(Image.open(io.BytesIO(blob)).convert("RGB"))


def test_rgba_tiles_carry_the_changed_pixels_exactly():
    rng = np.random.default_rng(3)
    enc = FrameEncoder(tile=16, tiles="rgba")
    img = (rng.random((70, 100, 3)) * 255).astype(np.uint8)
    head, blobs = decode(enc.encode("model", img))
    assert head["full"] and head["fmt"] == "jpeg"  # whole images stay JPEG
    canvas = img.copy()  # the page's image after the whole frame (exact here, to compare the tiles)
    for step in range(5):
        new = img.copy()
        r, c = rng.integers(0, 60), rng.integers(0, 90)
        new[r:r + 11, c:c + 9] = rng.integers(0, 256, (min(11, 70 - r), min(9, 100 - c), 3))
        new[69, 99] = step  # the last, partial tile
        head, blobs = decode(enc.encode("model", new, windows=[(r, r + 11, c, c + 9), (69, 70, 99, 100)]))
        assert not head["full"] and head["fmt"] == "rgba"
        _apply(canvas, head, blobs)
        assert np.array_equal(canvas, new)
        img = new
    # the same rectangles as JPEG tiles
    jpeg = FrameEncoder(tile=16)
    jpeg.encode("model", img)
    rgba = FrameEncoder(tile=16, tiles="rgba")
    rgba.encode("model", img)
    new = img.copy()
    new[20:23, 40:75] = [200, 10, 10]
    a, b = decode(jpeg.encode("model", new))[0], decode(rgba.encode("model", new))[0]
    assert [r[:4] for r in a["rects"]] == [r[:4] for r in b["rects"]] == [[32, 16, 48, 16]]


def test_tiles_format_is_checked():
    with pytest.raises(InputError, match="tiles"):
        FrameEncoder(tiles="png")
