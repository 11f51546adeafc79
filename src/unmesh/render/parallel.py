"""A simulation's frames rendered in parallel on Dask workers (``unmesh render OUTDIR --workers N``).

:func:`render_sequence_parallel` makes the sequence's plan once
(:func:`unmesh.render.sequence.sequence_plan`: camera, colour range, particle radius, static
geometry), sends it to the workers, renders the frames there with
:func:`unmesh.render.sequence.render_frame` and writes the video (or PNGs) in frame order on
the client, so the output is that of :func:`unmesh.render.sequence.render_sequence` bit for bit.

Example
-------
>>> import tempfile, pathlib
>>> from unmesh import Particles, io
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> for k in range(2):
...     io.save(d / "frames" / f"frame_{k:05d}.ply", Particles([[0.1 * k, 0, 0], [0, 0.2, 0]]))
>>> render_sequence_parallel(d, d / "movie.gif", workers=1, width=32, height=24, progress=False).name
'movie.gif'
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.render.sequence import check_output, render_frame, sequence_fps, sequence_plan, write_frames

__all__ = ["render_sequence_parallel"]


def render_sequence_parallel(frames: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
                             out_path: str | os.PathLike[str], *, workers: int | None = None,
                             scheduler: str | None = None, client: Any = None, fps: float | None = None,
                             progress: bool = True, **plan_options: Any) -> Path:
    """:func:`unmesh.render.sequence.render_sequence` with the frames rendered on Dask workers.

    Parameters
    ----------
    frames, out_path, fps, progress
        As for :func:`render_sequence`.
    workers : int, optional
        Worker processes of a local cluster (default: one per core).
    scheduler : str, optional
        Address of an existing Dask scheduler instead.
    client : distributed.Client, optional
        Use this client.
    **plan_options
        ``camera``, ``width``, ``height``, ``color_by``, ``color_range``, ``particle_radius``,
        ``cutaway`` and render options, as for :func:`render_sequence`.

    Raises
    ------
    unmesh.errors.MissingDependencyError
        Dask distributed is not installed (``pip install 'unmesh[batch]'``).
    """
    from unmesh.distributed import connect, imap_ordered, require_dask

    out = check_output(out_path)
    require_dask()
    if fps is None:
        fps = sequence_fps(frames) or 30.0
    plan = sequence_plan(frames, **plan_options)
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(connect(workers, scheduler))
        shared = client.scatter(plan, broadcast=True)

        def images() -> Iterator[np.ndarray]:
            yield from imap_ordered(client, render_frame, [(shared, i) for i in range(len(plan.groups))],
                                    progress=progress, desc="render")

        return write_frames(images(), out, fps)
