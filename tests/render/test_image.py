"""PNG, MP4 and GIF writing."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.render import save_image, to_uint8, write_video


def test_png_round_trip_and_atomic_overwrite(tmp_path):
    from PIL import Image

    img = np.zeros((5, 7, 3))
    img[0, 0] = [1, 0.5, 0]
    p = save_image(tmp_path / "sub" / "a.png", img)
    back = np.asarray(Image.open(p))
    assert back.shape == (5, 7, 3)
    assert back[0, 0].tolist() == [255, 128, 0]
    save_image(p, np.ones((2, 2)))
    assert np.asarray(Image.open(p)).shape == (2, 2, 3)
    assert [q.name for q in (tmp_path / "sub").iterdir()] == ["a.png"]  # no temporary files left
    with pytest.raises(InputError):
        save_image(tmp_path / "a.txt", img)
    with pytest.raises(InputError):
        save_image(tmp_path / "b.png", np.zeros((3, 3, 2)))


def test_to_uint8_clips_and_handles_nan():
    out = to_uint8(np.array([[[-1.0, np.nan, 2.0]]]))
    assert out.tolist() == [[[0, 0, 255]]]


def test_gif_frames_and_timing(tmp_path):
    from PIL import Image

    frames = [np.full((6, 9, 3), v) for v in (0.0, 0.5, 1.0)]
    p = write_video(frames, tmp_path / "a.gif", fps=10)
    im = Image.open(p)
    assert im.n_frames == 3 and im.size == (9, 6)
    assert im.info["duration"] == 100


def test_mp4_odd_size_is_padded_and_frames_stream(tmp_path):
    import imageio.v3 as iio

    def gen():
        for k in range(5):
            yield np.full((7, 11, 3), k / 4.0)

    p = write_video(gen(), tmp_path / "a.mp4", fps=24)
    frames = iio.imread(p, index=None)
    assert frames.shape[0] == 5 and frames.shape[1:3] == (8, 12)
    assert abs(int(frames[-1].mean()) - 255) <= 3


def test_video_errors(tmp_path):
    with pytest.raises(InputError):
        write_video([], tmp_path / "a.gif")
    with pytest.raises(InputError):
        write_video([np.zeros((4, 4, 3)), np.zeros((5, 4, 3))], tmp_path / "b.gif")
    with pytest.raises(InputError):
        write_video([np.zeros((4, 4, 3))], tmp_path / "c.avi")
    assert not list(tmp_path.iterdir())  # nothing half-written
