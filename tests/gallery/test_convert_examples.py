"""The conversion gallery examples run in quick mode and write their images."""

from __future__ import annotations

from unmesh.gallery import ExampleContext, select


def test_convert_examples_quick(tmp_path):
    examples = select("convert-*")
    assert [e.name for e in examples] == ["convert-resolutions", "convert-atlas", "convert-sampling", "convert-painted"]
    for ex in examples:
        out = tmp_path / ex.name
        out.mkdir()
        ctx = ExampleContext(outdir=out, root=tmp_path, quick=True, progress=False)
        ex.func(ctx)
        images = [a.path for a in ctx.artifacts if a.kind == "image"]
        assert images
        for p in images:
            assert (tmp_path / p).stat().st_size > 1000
        m = {name: value for name, value, _ in ctx.metrics}
        if ex.name == "convert-atlas":
            assert 50.0 < float(m["fill (all pages)"]) <= 100.0
        if ex.name == "convert-painted":
            assert float(m["PSNR textured mesh vs surfels (pixels both cover)"]) >= 30.0
