"""The painting gallery examples run (quick mode) from the shipped stroke files."""

from __future__ import annotations

import pytest

from unmesh.gallery import ExampleContext, select
from unmesh.gallery.examples.paint import shipped_strokes
from unmesh.paint import parse_strokes

NAMES = ["paint-backtransfer", "paint-diffusion", "paint-relief", "paint-downsampling", "paint-art"]


@pytest.mark.parametrize("name", ["backtransfer", "diffusion", "relief", "downsampling", "art"])
def test_shipped_stroke_files_are_valid(name):
    assert parse_strokes(shipped_strokes(name), name)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_example_runs_quick(tmp_path, name):
    (ex,) = select(name)
    out = tmp_path / name
    out.mkdir()
    ctx = ExampleContext(outdir=out, root=tmp_path, quick=True, progress=False)
    ex.func(ctx)
    assert ctx.artifacts and all((tmp_path / a.path).exists() for a in ctx.artifacts if a.path)
    metrics = dict((m[0], m[1]) for m in ctx.metrics)
    if name == "paint-downsampling":
        assert metrics["surfels after downsampling"] < metrics["surfels before downsampling"]
    if name == "paint-diffusion":
        assert float(metrics["paint volume, no diffusion vs diffusion (relative difference)"]) <= 1e-12
