"""Expected run times of the gallery examples, for a progress bar that estimates the time left.

The examples differ by two orders of magnitude in cost (a CSG figure takes a fraction of a
second, the freezing rod minutes), so a bar that counts examples predicts the remaining time
badly. :func:`expected_seconds` gives each example a weight in seconds: the time it took in the
last run into the same folder and mode (``timings.json``, written by :func:`record`), else the
time measured for the shipped defaults (``expected_seconds.json`` beside this module), else
the median of the known ones. The bar advances by an example's weight when it finishes, so its
estimate is right whenever the weights are proportional to the true times.

Example
-------
>>> from pathlib import Path
>>> from unmesh.gallery.registry import Example
>>> ex = Example("zz-doc", "doc", "doc", lambda ctx: None, "")
>>> expected_seconds([ex], Path("/nonexistent"), quick=True)   # unknown: the default
[10.0]
"""

from __future__ import annotations

import json
import statistics
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

from unmesh.gallery.registry import Example
from unmesh.io.atomic import atomic_write_text

__all__ = ["DEFAULT_SECONDS", "TIMINGS_FILE", "expected_seconds", "load_timings", "record"]

#: Weight of an example no timing knows (seconds).
DEFAULT_SECONDS = 10.0

#: The per-mode timings a gallery run writes into its output folder.
TIMINGS_FILE = "timings.json"


def _mode(quick: bool) -> str:
    return "quick" if quick else "full"


def _read(text: str) -> dict[str, dict[str, float]]:
    try:
        data = json.loads(text)
    except ValueError:
        return {}
    if not isinstance(data, dict):
        return {}
    out: dict[str, dict[str, float]] = {}
    for mode, table in data.items():
        if isinstance(table, dict):
            out[str(mode)] = {str(k): float(v) for k, v in table.items()
                              if isinstance(v, (int, float)) and not isinstance(v, bool) and v >= 0}
    return out


def load_timings(outdir: Path) -> dict[str, dict[str, float]]:
    """The timings of the last run into ``outdir`` (``{"quick"|"full": {name: seconds}}``; empty if none or unreadable)."""
    try:
        return _read((Path(outdir) / TIMINGS_FILE).read_text(encoding="utf-8"))
    except OSError:
        return {}


def _shipped() -> dict[str, dict[str, float]]:
    try:
        return _read(resources.files("unmesh.gallery").joinpath("expected_seconds.json").read_text(encoding="utf-8"))
    except (OSError, ModuleNotFoundError):
        return {}


def expected_seconds(examples: Sequence[Example], outdir: Path, quick: bool) -> list[float]:
    """Weight in seconds of each of ``examples`` for a run into ``outdir`` (see the module docstring).

    Returns
    -------
    list of float, one per example, each > 0.
    """
    mode = _mode(quick)
    last = load_timings(outdir).get(mode, {})
    shipped = _shipped().get(mode, {})
    known = [t for t in (last.get(e.name, shipped.get(e.name)) for e in examples) if t is not None]
    fallback = statistics.median(known) if known else DEFAULT_SECONDS
    return [max(float(last.get(e.name, shipped.get(e.name, fallback))), 0.05) for e in examples]


def record(outdir: Path, quick: bool, seconds: dict[str, float]) -> Path:
    """Merge ``seconds`` (example name -> wall seconds) into ``outdir/timings.json`` (atomically)."""
    path = Path(outdir) / TIMINGS_FILE
    data = load_timings(outdir)
    data.setdefault(_mode(quick), {}).update({k: round(float(v), 3) for k, v in seconds.items()})
    atomic_write_text(path, json.dumps(data, indent=1, sort_keys=True) + "\n")
    return path
