"""The CSG gallery examples run (quick mode) and report their figures."""

from __future__ import annotations

import pytest

from unmesh.gallery import ExampleContext, select

SLOW = pytest.mark.slow


@pytest.mark.parametrize("name", ["csg-fig41", "csg-fig43", "csg-fig46", "csg-fig47", "csg-fig410", "csg-limits",
                                  pytest.param("csg-fig48", marks=SLOW), pytest.param("csg-fig49", marks=SLOW),
                                  pytest.param("csg-dynamic", marks=SLOW)])
def test_example_runs_quick(tmp_path, name):
    (ex,) = select(name)
    out = tmp_path / name
    out.mkdir()
    ctx = ExampleContext(outdir=out, root=tmp_path, quick=True, progress=False)
    ex.func(ctx)
    assert ctx.artifacts and all((tmp_path / a.path).exists() for a in ctx.artifacts if a.path)
    metrics = {m[0]: m[1] for m in ctx.metrics}
    if name == "csg-fig41":
        assert metrics["misclassified pixels, two surfels"] < metrics["misclassified pixels, closest surfel"]
