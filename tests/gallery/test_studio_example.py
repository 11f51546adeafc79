"""The studio gallery example: a screenshot of the studio painted in headless Chromium; without
Playwright or Chromium it fails with a message that says what to install (never skips)."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import MissingDependencyError
from unmesh.gallery import ExampleContext, select


def test_missing_browser_is_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("UNMESH_CHROMIUM", str(tmp_path / "no-chromium"))
    (ex,) = select("paint-studio")
    ctx = ExampleContext(outdir=tmp_path, root=tmp_path, quick=True, progress=False)
    with pytest.raises(MissingDependencyError, match=r"Chromium at .*no-chromium.*install-browser"):
        ex.func(ctx)
    assert not ctx.artifacts


@pytest.mark.slow
def test_studio_example_screenshot(tmp_path):
    from PIL import Image

    from unmesh.paint.session import Session

    (ex,) = select("paint-studio")
    ctx = ExampleContext(outdir=tmp_path, root=tmp_path, quick=True, progress=False)
    ex.func(ctx)
    shot = tmp_path / "studio.png"
    with Image.open(shot) as im:
        assert im.size == (1200, 720)
        img = np.asarray(im.convert("RGB")).astype(float)
    # the design's colours are on screen (the palette and the model): red, blue-ish and yellow pixels
    for rgb in ((0.8, 0.1, 0.1), (0.98, 0.86, 0.12)):
        assert (np.linalg.norm(img - 255 * np.asarray(rgb), axis=2) < 45).sum() > 100, rgb
    painted = Session.load(tmp_path / "blob_painted.ply").cloud()
    assert np.linalg.norm(painted.colors - (0.8, 0.1, 0.1), axis=1).min() < 0.2
    metrics = dict((m[0], m[1]) for m in ctx.metrics)
    assert metrics["pen strokes (palette + model)"] == 4
