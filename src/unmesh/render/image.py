"""Writing images and videos: PNG (Pillow), MP4 (imageio-ffmpeg, H.264 yuv420p) and GIF
(Pillow). Every file is written atomically: a temporary file next to the target is renamed over
it only when writing succeeded.

Images are float arrays in [0, 1] (H, W, 3) (or (H, W) grey, or (H, W, 4) RGBA) or uint8.

Example
-------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> p = save_image(d / "red.png", np.tile([1.0, 0.0, 0.0], (4, 6, 1)))
>>> from PIL import Image
>>> Image.open(p).size
(6, 4)
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from unmesh._validate import positive_scalar
from unmesh.errors import InputError, MissingDependencyError
from unmesh.io.atomic import atomic_path

__all__ = ["IMAGE_EXTENSIONS", "VIDEO_EXTENSIONS", "save_image", "to_uint8", "write_video"]

#: File extensions :func:`save_image` writes.
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
#: File extensions :func:`write_video` writes.
VIDEO_EXTENSIONS = (".mp4", ".gif")


def to_uint8(image: Any) -> np.ndarray:
    """Convert an image to uint8 RGB(A) (H, W, 3|4): floats in [0, 1] are clipped, scaled by 255
    and rounded; grey (H, W) becomes RGB.

    Example
    -------
    >>> to_uint8(np.array([[0.0, 0.5, 1.0]]))[0].tolist()
    [[0, 0, 0], [128, 128, 128], [255, 255, 255]]
    """
    arr = np.asarray(image)
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4) or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise InputError(f"image: expected shape (H, W), (H, W, 3) or (H, W, 4), got {arr.shape}")
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    if not np.issubdtype(arr.dtype, np.number) and arr.dtype != bool:
        raise InputError(f"image: expected numbers, got dtype {arr.dtype}")
    f = np.nan_to_num(arr.astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.ascontiguousarray(np.floor(np.clip(f, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))


def save_image(path: str | os.PathLike[str], color: Any) -> Path:
    """Write an image file atomically (format from the extension, PNG by default).

    Parameters
    ----------
    path : path-like
        Target file; missing parent directories are created.
    color : array_like
        (H, W, 3) float in [0, 1] (or uint8, grey, RGBA).

    Returns
    -------
    pathlib.Path
        The written path.

    Example
    -------
    >>> import tempfile, pathlib
    >>> save_image(pathlib.Path(tempfile.mkdtemp()) / "g.png", np.zeros((2, 2))).suffix
    '.png'
    """
    from PIL import Image

    target = Path(path)
    if target.suffix == "":
        target = target.with_suffix(".png")
    if target.suffix.lower() not in IMAGE_EXTENSIONS:
        raise InputError(f"path: expected an image extension ({', '.join(IMAGE_EXTENSIONS)}), got {target.name!r}")
    data = to_uint8(color)
    img = Image.fromarray(data)
    if target.suffix.lower() in (".jpg", ".jpeg") and img.mode == "RGBA":
        img = img.convert("RGB")
    with atomic_path(target) as tmp:
        img.save(tmp)
    return target


def _even(frame: np.ndarray) -> np.ndarray:
    """Pad a frame by edge replication to even width and height (yuv420p needs them)."""
    h, w = frame.shape[:2]
    ph, pw = h % 2, w % 2
    if ph or pw:
        frame = np.pad(frame, ((0, ph), (0, pw), (0, 0)), mode="edge")
    return np.ascontiguousarray(frame)


def write_video(frames: Iterable[Any], path: str | os.PathLike[str], fps: float = 30.0, quality: int = 8) -> Path:
    """Write frames as an MP4 (H.264, yuv420p, padded to even size) or a looping GIF, atomically.

    Frames are consumed one at a time for MP4 (memory stays flat); a GIF keeps the palettised
    frames until the end (Pillow merges identical consecutive GIF frames, adding their
    durations). All frames must have the size of the first.

    Parameters
    ----------
    frames : iterable of array_like
        (H, W, 3) float in [0, 1] or uint8 images.
    path : path-like
        ``.mp4`` or ``.gif``.
    fps : float
        Frames per second.
    quality : int
        MP4 quality 0-10 (imageio-ffmpeg's scale; 10 is best).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    unmesh.errors.InputError
        On an unknown extension, no frames, or frames of different sizes.
    unmesh.errors.MissingDependencyError
        When MP4 is requested and imageio-ffmpeg is missing.

    Example
    -------
    >>> import tempfile, pathlib
    >>> frames = [np.full((8, 8, 3), v) for v in (0.0, 0.5, 1.0)]
    >>> write_video(frames, pathlib.Path(tempfile.mkdtemp()) / "a.gif", fps=10).suffix
    '.gif'
    """
    target = Path(path)
    ext = target.suffix.lower()
    if ext not in VIDEO_EXTENSIONS:
        raise InputError(f"path: expected a video extension ({', '.join(VIDEO_EXTENSIONS)}), got {target.name!r}")
    fps = positive_scalar(fps, "fps")
    it = iter(frames)
    size: tuple[int, int] | None = None

    def frames_u8() -> Iterable[np.ndarray]:
        nonlocal size
        for k, fr in enumerate(it):
            data = to_uint8(fr)[:, :, :3]
            if size is None:
                size = data.shape[:2]
            elif data.shape[:2] != size:
                raise InputError(f"frames[{k}]: expected size {size[1]}x{size[0]} like the first frame, got {data.shape[1]}x{data.shape[0]}")
            yield data

    with atomic_path(target) as tmp:
        if ext == ".gif":
            _write_gif(frames_u8(), tmp, fps)
        else:
            _write_mp4(frames_u8(), tmp, fps, quality)
    return target


def _write_gif(frames: Iterable[np.ndarray], path: Path, fps: float) -> None:
    from PIL import Image

    pal = [Image.fromarray(f).quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
           for f in frames]
    if not pal:
        raise InputError("frames: expected at least one frame, got none")
    duration = max(10, round(1000.0 / fps))
    pal[0].save(path, format="GIF", save_all=True, append_images=pal[1:], duration=duration, loop=0, disposal=1)


def _write_mp4(frames: Iterable[np.ndarray], path: Path, fps: float, quality: int) -> None:
    try:
        import imageio_ffmpeg
    except ImportError as exc:  # pragma: no cover - dependency of unmesh
        raise MissingDependencyError("writing MP4 needs imageio-ffmpeg: pip install imageio-ffmpeg") from exc
    writer = None
    count = 0
    try:
        for fr in frames:
            fr = _even(fr)
            if writer is None:
                writer = imageio_ffmpeg.write_frames(str(path), (fr.shape[1], fr.shape[0]), fps=fps, codec="libx264",
                                                     pix_fmt_out="yuv420p", quality=quality, macro_block_size=1,
                                                     ffmpeg_log_level="error")
                writer.send(None)
            writer.send(fr)
            count += 1
    finally:
        if writer is not None:
            writer.close()
    if count == 0:
        raise InputError("frames: expected at least one frame, got none")
