"""The gallery examples run (quick mode) and report their figures."""

from __future__ import annotations

import pytest

from unmesh.gallery import ExampleContext, select

SLOW = pytest.mark.slow  # sampling the blob and ray casting MLS surfaces take a while


@pytest.mark.parametrize("name", ["render-surfels", pytest.param("render-zoom", marks=SLOW),
                                  pytest.param("render-splat-vs-raycast", marks=SLOW), "render-partial-update",
                                  "render-mixed"])
def test_example_runs_quick(tmp_path, name):
    (ex,) = select(name)
    out = tmp_path / name
    out.mkdir()
    ctx = ExampleContext(outdir=out, root=tmp_path, quick=True, progress=False)
    ex.func(ctx)
    assert ctx.artifacts and all((tmp_path / a.path).exists() for a in ctx.artifacts if a.path)
    metrics = dict((m[0], m[1]) for m in ctx.metrics)
    if name == "render-zoom":
        assert metrics["uncovered pixels when magnified 8x"] == 0
        assert metrics["minified RMS error, EWA prefilter"] < metrics["minified RMS error, no prefilter"]
    if name == "render-partial-update":
        assert float(metrics["max |partial - full| colour"]) <= 1e-6
    if name == "render-splat-vs-raycast":
        assert metrics["mean absolute colour difference"] < 0.05
