"""Every registered gallery example runs in quick mode and reports at least one result (slow)."""

import pytest

from unmesh.gallery import all_examples
from unmesh.gallery.page import run_examples

EXAMPLES = [e for e in all_examples() if not e.name.startswith("zz-")]  # zz-: the tests own examples


@pytest.mark.slow
@pytest.mark.parametrize("ex", EXAMPLES, ids=[e.name for e in EXAMPLES])
def test_example_runs_quick(tmp_path, ex):
    (result,) = run_examples([ex], tmp_path, quick=True, progress=False)
    assert result.error is None, result.error
    assert result.context.artifacts, f"{ex.name} reported nothing"
    for art in result.context.artifacts:
        if art.path:
            assert (tmp_path / art.path).is_file(), art.path
