"""Task runners for the batch tests (imported by the Dask workers by name)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any


def _attempt(spec: Mapping[str, Any]) -> int:
    """Count this attempt in OUTDIR/attempts/<id> (outside the task folder, which a rerun empties)."""
    f = Path(spec["outdir"]).parent / "attempts" / spec["id"]
    f.parent.mkdir(parents=True, exist_ok=True)
    with open(f, "a") as fh:
        fh.write("x")
    return len(f.read_text())


def count_runner(spec: Mapping[str, Any], resume: bool) -> dict[str, Any]:
    """Writes summary.json with x * 2; fails when the parameter ``fail`` is true (always) or
    ``flaky`` is true (first attempt only), or when OUTDIR/broken exists."""
    n = _attempt(spec)
    p = spec["parameters"]
    if p.get("fail") or (p.get("flaky") and n == 1) or (Path(spec["outdir"]).parent / "broken").exists():
        raise ValueError(f"task {spec['id']} failed on attempt {n}\nsecond line of the message")
    (Path(spec["outdir"]) / "summary.json").write_text(json.dumps({"status": "completed", "double": 2 * p["x"]}))
    return {"attempt": n}
