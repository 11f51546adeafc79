"""Running one gallery example into its folder: :func:`run_one` and its :class:`ExampleResult`.

Both the in-process loop and the worker processes of ``unmesh gallery --jobs N``
(:mod:`unmesh.gallery.pool`) run examples through :func:`run_one`, so an example sees the
same context either way.

Example
-------
>>> import tempfile
>>> from pathlib import Path
>>> from unmesh.gallery.registry import Example
>>> ex = Example("zz-doc-run", "doc", "doc", lambda ctx: ctx.metric("answer", 42))
>>> root = Path(tempfile.mkdtemp())
>>> run_one(ex, root, quick=True, progress=False).context.metrics
[('answer', 42, '')]
"""

from __future__ import annotations

import shutil
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from unmesh.gallery.registry import Example, ExampleContext

__all__ = ["ExampleResult", "run_one"]


@dataclass
class ExampleResult:
    """Outcome of one example run."""

    example: Example
    context: ExampleContext
    seconds: float
    error: str | None = None
    details: list[str] = field(default_factory=list)


def run_one(example: Example, outdir: Path, quick: bool, progress: bool) -> ExampleResult:
    """Run ``example`` into ``outdir/<name>/`` (emptied first); a failure is recorded, not raised.

    Parameters
    ----------
    example : Example
        The registered example.
    outdir : Path
        The gallery's root folder; the example writes into ``outdir / example.name``.
    quick : bool
        Small, fast version.
    progress : bool
        Let the example show its own progress bars (simulations).

    Returns
    -------
    ExampleResult
        Its artifacts and metrics (in ``context``), wall seconds, and the traceback text of an
        exception it raised (``KeyboardInterrupt`` propagates).
    """
    exdir = Path(outdir) / example.name
    if exdir.exists():
        shutil.rmtree(exdir)
    exdir.mkdir(parents=True)
    ctx = ExampleContext(outdir=exdir, root=Path(outdir), quick=quick, progress=progress)
    t0 = time.perf_counter()
    error = None
    try:
        example.func(ctx)
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # an example failing must not stop the gallery
        error = f"{type(exc).__name__}: {exc}\n\n{traceback.format_exc()}"
    return ExampleResult(example, ctx, time.perf_counter() - t0, error)
