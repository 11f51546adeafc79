import pytest

from unmesh.errors import InputError
from unmesh.gallery import ExampleContext, example, select
from unmesh.gallery.page import run_examples


@example("zz-test-ok", "A passing example", section="Tests")
def _ok(ctx: ExampleContext):
    p = ctx.path("note.txt")
    p.write_text("hi")
    ctx.file(p, "a note")
    ctx.metric("answer", 42.0, "units")
    ctx.text("explanation")


@example("zz-test-fail", "A failing example", section="Tests")
def _fail(ctx: ExampleContext):
    raise RuntimeError("deliberate")


def test_select_patterns_and_unknown():
    names = [e.name for e in select("zz-test-*")]
    assert names == ["zz-test-ok", "zz-test-fail"]
    with pytest.raises(InputError, match="no example matches nope"):
        select("nope")


def test_run_writes_index_and_records_failures(tmp_path):
    results = run_examples(select("zz-test-*"), tmp_path, quick=True, progress=False)
    assert [r.error is None for r in results] == [True, False]
    html = (tmp_path / "index.html").read_text()
    assert "A passing example" in html and "42" in html and "zz-test-ok/note.txt" in html
    assert "deliberate" in html and "This example failed" in html
