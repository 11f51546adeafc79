"""The FEM gallery examples run in quick mode and report their figures."""

from __future__ import annotations

import warnings

import pytest

from unmesh.gallery import ExampleContext, select


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fem-single-element", "fem-random-planes-cube", "fem-progressive-slicing",
                                  "fem-blob-slicing", "fem-accuracy"])
def test_fem_example_quick(tmp_path, name):
    (ex,) = select(name)
    out = tmp_path / name
    out.mkdir()
    ctx = ExampleContext(out, tmp_path, quick=True, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ex.func(ctx)
    assert ctx.metrics
    for art in ctx.artifacts:
        if art.path:
            assert (tmp_path / art.path).is_file()
