"""Frames for the WebSocket: full images, or only the tiles that changed.

A frame message is binary: a little-endian ``uint32`` header length, the UTF-8 JSON header,
then the images one after another. The header lists the rectangles
``[x, y, w, h, nbytes]`` in pixels of the full-resolution image (``scale`` > 1 for a
low-resolution preview that the page stretches)::

    {"type": "frame", "target": "model", "seq": 7, "w": 640, "h": 480, "full": false,
     "scale": 1, "fmt": "jpeg", "rects": [[64, 32, 96, 32, 2211]], ...}

While painting only the tiles whose pixels changed are sent (runs of changed
``tile x tile`` blocks on each tile row merge into one rectangle); a view change, a first frame
or a change covering most of the image sends the whole image. Images are JPEG (``fmt``
``"jpeg"``), except that an encoder made with ``tiles="rgba"`` sends the changed tiles of a
differential frame as raw RGBA bytes, row by row (``fmt`` ``"rgba"``, ``nbytes`` = 4 w h): a
few kilobytes per painting frame, which the page copies into its canvas at once (no image
decoder, no round trip through the browser's blob store), and exact.

Example
-------
>>> import numpy as np
>>> enc = FrameEncoder(tile=8)
>>> img = np.zeros((16, 32, 3), np.uint8)
>>> head, _ = decode(enc.encode("model", img))
>>> head["full"], head["rects"][0][:4]
(True, [0, 0, 32, 16])
>>> img[9:11, 20:22] = 255
>>> head, _ = decode(enc.encode("model", img))
>>> head["full"], [r[:4] for r in head["rects"]]
(False, [[16, 8, 8, 8]])
"""

from __future__ import annotations

import io
import json
import struct
import time
from typing import Any

import numpy as np

from unmesh.errors import InputError

__all__ = ["FrameEncoder", "decode", "to_uint8"]


def to_uint8(color: np.ndarray) -> np.ndarray:
    """A float RGB image (H,W,3) in [0, 1] as uint8 (rounded)."""
    return np.ascontiguousarray(np.clip(np.asarray(color) * 255.0 + 0.5, 0, 255).astype(np.uint8))


def _jpeg(img: np.ndarray, quality: int) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="JPEG", quality=quality, subsampling=0 if quality >= 90 else 2)
    return buf.getvalue()


def _rgba(img: np.ndarray) -> bytes:
    """An (h, w, 3) uint8 image as RGBA bytes (opaque), row by row: the page's ``ImageData``."""
    out = np.empty((*img.shape[:2], 4), dtype=np.uint8)
    out[..., :3] = img
    out[..., 3] = 255
    return out.tobytes()


def decode(message: bytes) -> tuple[dict[str, Any], list[bytes]]:
    """The header and image blobs of a frame message (the inverse of :meth:`FrameEncoder.encode`)."""
    (n,) = struct.unpack_from("<I", message, 0)
    head = json.loads(message[4:4 + n].decode("utf-8"))
    blobs, pos = [], 4 + n
    for rect in head["rects"]:
        blobs.append(message[pos:pos + rect[4]])
        pos += rect[4]
    return head, blobs


class FrameEncoder:
    """Keeps the last image sent per target and encodes the next one as tiles or whole.

    Parameters
    ----------
    tile : int
        Tile edge in pixels (a multiple of 8 keeps JPEG blocks aligned).
    quality : int
        JPEG quality.
    full_fraction : float
        Send the whole image when more than this fraction of the tiles changed.
    tiles : {"jpeg", "rgba"}
        Format of the changed tiles of a differential frame (whole images are always JPEG).
    """

    def __init__(self, tile: int = 32, quality: int = 90, full_fraction: float = 0.5, tiles: str = "jpeg") -> None:
        if tiles not in ("jpeg", "rgba"):
            raise InputError(f"tiles: expected 'jpeg' or 'rgba', got {tiles!r}")
        self.tiles = tiles
        self.tile = int(tile)
        self.quality = int(quality)
        self.full_fraction = float(full_fraction)
        self._last: dict[str, np.ndarray] = {}
        self._seq = 0

    def reset(self, target: str | None = None) -> None:
        """Forget the last image (of one target or all): the next frame is sent whole."""
        if target is None:
            self._last.clear()
        else:
            self._last.pop(target, None)

    def changed_rects(self, old: np.ndarray, new: np.ndarray,
                      windows: list[tuple[int, int, int, int]] | None = None) -> list[tuple[int, int, int, int]]:
        """Rectangles ``(x, y, w, h)`` covering the tiles where ``new`` differs from ``old``.

        ``windows`` (pixel windows ``(r0, r1, c0, c1)``, e.g. ``Session.last_windows``) limits
        the comparison to the tiles they touch: the caller promises no change outside them, and
        a frame then costs in proportion to what changed instead of the whole image."""
        t = self.tile
        h, w = new.shape[:2]
        ny, nx = -(-h // t), -(-w // t)
        changed = np.zeros((ny, nx), dtype=bool)
        if windows is None:
            windows = [(0, h, 0, w)]
        for r0, r1, c0, c1 in windows:
            r0, c0 = max(0, int(r0)) // t, max(0, int(c0)) // t
            r1, c1 = -(-min(h, int(r1)) // t), -(-min(w, int(c1)) // t)
            if r0 >= r1 or c0 >= c1:
                continue
            y0, y1, x0, x1 = r0 * t, min(h, r1 * t), c0 * t, min(w, c1 * t)
            diff = np.zeros(((r1 - r0) * t, (c1 - c0) * t), dtype=bool)
            diff[:y1 - y0, :x1 - x0] = np.any(old[y0:y1, x0:x1] != new[y0:y1, x0:x1], axis=2)
            changed[r0:r1, c0:c1] |= diff.reshape(r1 - r0, t, c1 - c0, t).any(axis=(1, 3))
        rects = []
        for ty in np.flatnonzero(changed.any(axis=1)):
            row = changed[ty]
            tx = 0
            while tx < nx:
                if not row[tx]:
                    tx += 1
                    continue
                start = tx
                while tx < nx and row[tx]:
                    tx += 1
                x0, y0 = start * t, int(ty) * t
                rects.append((x0, y0, min(tx * t, w) - x0, min(y0 + t, h) - y0))
        return rects

    def encode(self, target: str, image: np.ndarray, *, full: bool = False, scale: int = 1,
               size: tuple[int, int] | None = None, extra: dict[str, Any] | None = None,
               windows: list[tuple[int, int, int, int]] | None = None) -> bytes | None:
        """The frame message for ``image`` (H,W,3) uint8; None when nothing changed.

        ``scale`` > 1 marks a low-resolution preview (never used as the base of tiles) of an
        image of ``size`` = (width, height) full-resolution pixels (default: ``scale`` times the
        image's). ``windows`` limits the search for changed tiles (:meth:`changed_rects`). The
        header's ``enc`` is the encoding time in milliseconds.
        """
        img = np.ascontiguousarray(image, dtype=np.uint8)
        h, w = img.shape[:2]
        last = self._last.get(target)
        if scale != 1:
            self._last.pop(target, None)
            rects = [(0, 0, w, h)]
            full = True
        elif full or last is None or last.shape != img.shape:
            rects = [(0, 0, w, h)]
            full = True
        else:
            rects = self.changed_rects(last, img, windows)
            if not rects:
                return None
            area = sum(r[2] * r[3] for r in rects)
            if area > self.full_fraction * w * h:
                rects, full = [(0, 0, w, h)], True
        if scale == 1:
            if full:
                self._last[target] = img.copy()
            else:  # only the sent tiles changed
                for x, y, rw, rh in rects:
                    last[y:y + rh, x:x + rw] = img[y:y + rh, x:x + rw]
        t0 = time.perf_counter()
        fmt = "rgba" if self.tiles == "rgba" and not full else "jpeg"
        if fmt == "rgba":
            blobs = [_rgba(img[y:y + rh, x:x + rw]) for x, y, rw, rh in rects]
        else:
            blobs = [_jpeg(img[y:y + rh, x:x + rw], self.quality) for x, y, rw, rh in rects]
        enc = round(1000 * (time.perf_counter() - t0), 2)
        self._seq += 1
        fw, fh = size if size is not None else (w * scale, h * scale)
        head = {"type": "frame", "target": target, "seq": self._seq, "w": int(fw), "h": int(fh),
                "full": bool(full), "scale": int(scale), "fmt": fmt, "enc": enc,
                "rects": [[x, y, rw, rh, len(b)] for (x, y, rw, rh), b in zip(rects, blobs, strict=True)]}
        if extra:
            head.update(extra)
        data = json.dumps(head, separators=(",", ":")).encode("utf-8")
        return struct.pack("<I", len(data)) + data + b"".join(blobs)
