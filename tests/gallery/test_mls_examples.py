"""The MLS gallery example runs in quick mode and reports figures within the issue's targets."""

from __future__ import annotations

from unmesh.gallery import ExampleContext, select


def test_mls_accuracy_example_quick(tmp_path):
    (ex,) = select("mls-accuracy")
    out = tmp_path / ex.name
    out.mkdir()
    ctx = ExampleContext(outdir=out, root=tmp_path, quick=True, progress=False)
    ex.func(ctx)
    images = [a.path for a in ctx.artifacts if a.kind == "image"]
    assert images == ["mls-accuracy/torus_error.png", "mls-accuracy/raycast.png"]
    for p in images:
        assert (tmp_path / p).stat().st_size > 1000
    m = {name: value for name, value, _ in ctx.metrics}
    for shape in ("sphere", "torus"):
        assert float(m[f"{shape}: max distance of projections to the exact surface"]) < 1e-3
        assert float(m[f"{shape}: max normal error"]) < 1.0
        assert float(m[f"{shape}: inside test correct"]) == 100.0
        assert float(m[f"{shape}: max distance of ray hits to the exact surface"]) < 1e-3
