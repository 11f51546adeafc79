"""A 2-worker local Dask cluster shared by the batch tests (of one test process)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def client():
    pytest.importorskip("distributed")
    from unmesh.distributed import connect

    with connect(workers=2, dashboard=None, progress_output=None) as c:
        yield c
