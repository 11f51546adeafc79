"""A simulation's frames rendered in parallel on Dask workers (``unmesh render OUTDIR --workers N``).

:func:`sequence_plan` fixes everything shared by the frames exactly as
:func:`unmesh.render.sequence.render_sequence` does (one camera over sampled frames, the colour
range, the particle radius, static geometry in grey with its cut-away); :func:`render_frame`
renders frame ``i`` of a plan. :func:`render_sequence_parallel` sends the plan to the workers
once, renders the frames there and writes the video (or PNGs) in frame order on the client,
so the output is that of :func:`render_sequence` bit for bit.

Example
-------
>>> import tempfile, pathlib
>>> from unmesh import Particles, io
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> for k in range(2):
...     io.save(d / "frames" / f"frame_{k:05d}.ply", Particles([[0.1 * k, 0, 0], [0, 0.2, 0]]))
>>> plan = sequence_plan(d, width=32, height=24)
>>> len(plan.groups), render_frame(plan, 1).shape
(2, (24, 32, 3))
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.particles import Particles
from unmesh.render.camera import Camera
from unmesh.render.pipeline import collect, render, scene_bounds, scene_points
from unmesh.render.sequence import STATIC_COLOR, _frame_objects, _sample_indices, find_frames

__all__ = ["SequencePlan", "render_frame", "render_sequence_parallel", "sequence_plan"]


@dataclass(frozen=True)
class SequencePlan:
    """What every frame of a sequence shares (see :func:`sequence_plan`)."""

    groups: tuple[tuple[Path, ...], ...]
    static_objects: tuple[Any, ...]
    camera: Camera
    color_by: str | None
    color_range: tuple[float, float] | None
    particle_radius: float | None
    render_options: dict[str, Any] = field(default_factory=dict)


def sequence_plan(frames: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], camera: Camera | None = None,
                  width: int = 640, height: int = 480, color_by: str | None = None,
                  color_range: Sequence[float] | None = None, particle_radius: float | None = None,
                  cutaway: bool = True, **render_options: Any) -> SequencePlan:
    """The camera, colour range, particle radius and static geometry of a frame sequence.

    Parameters are those of :func:`unmesh.render.sequence.render_sequence` (the same defaults
    and the same choices, so a frame of the plan is the frame ``render_sequence`` draws).
    """
    from unmesh.render.colormap import attribute_values, value_range
    from unmesh.render.particles import estimate_radius

    groups, static_paths = find_frames(frames)
    static = collect(_frame_objects(static_paths))
    sampled = {i: collect(_frame_objects(groups[i])) for i in _sample_indices(len(groups))}
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for sc in sampled.values():
        b = scene_bounds(sc)
        lo = np.minimum(lo, b[0])
        hi = np.maximum(hi, b[1])
    dyn_bounds = np.stack([lo, hi])
    if camera is None:
        pts = np.concatenate([scene_points(sc, 4000) for sc in [*sampled.values(), static]])
        margin = 1.35 if color_by is not None and render_options.get("legend", True) else 1.08
        cam = Camera.fit(pts, width, height, margin=margin) if len(pts) else \
            Camera.framing(np.stack([lo, hi]), width, height, margin=margin)
    else:
        cam = camera
    if color_by is not None and color_range is None:
        vals = []
        for sc in sampled.values():
            for obj in sc.all():
                try:
                    vals.append(attribute_values(obj, color_by))
                except InputError:
                    pass
        if not vals:
            raise InputError(f"color_by: no frame object has attribute {color_by!r}")
        color_range = value_range(vals)
    first = sampled[0]
    if particle_radius is None and first.particles:
        missing = [p for p in first.particles if p.radii is None]
        if missing:
            particle_radius = estimate_radius(np.concatenate([p.positions for p in missing]))
    static_particles: list[Particles] = []
    for p in static.particles:
        keep = np.ones(len(p), dtype=bool)
        if cutaway and np.all(np.isfinite(dyn_bounds)) and len(p):
            corners = np.array([[dyn_bounds[i, 0], dyn_bounds[j, 1], dyn_bounds[k, 2]]
                                for i in (0, 1) for j in (0, 1) for k in (0, 1)])
            zmin = float(cam.to_camera(corners)[:, 2].min())
            keep = cam.to_camera(p.positions)[:, 2] >= zmin - 1e-9 * max(1.0, abs(zmin))
        sub = p.subset(keep)
        col = np.tile(STATIC_COLOR, (len(sub), 1))
        static_particles.append(sub.replace(attributes={**sub.attributes, "colors": col}))
    static_objects = (*static.clouds, *static.meshes, *static_particles)
    crange = None if color_range is None else (float(color_range[0]), float(color_range[1]))
    return SequencePlan(tuple(tuple(g) for g in groups), static_objects, cam, color_by, crange,
                        particle_radius, dict(render_options))


def render_frame(plan: SequencePlan, i: int) -> np.ndarray:
    """Frame ``i`` of a plan: (H, W, 3) float colours, as :func:`render_sequence` draws it."""
    if not 0 <= int(i) < len(plan.groups):
        raise InputError(f"i: expected a frame index in [0, {len(plan.groups)}), got {i}")
    sc = collect(_frame_objects(plan.groups[int(i)]))
    return render([*plan.static_objects, *sc.all()], plan.camera, color_by=plan.color_by,
                  color_range=plan.color_range, particle_radius=plan.particle_radius, **plan.render_options).color


def render_sequence_parallel(frames: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
                             out_path: str | os.PathLike[str], *, workers: int | None = None,
                             scheduler: str | None = None, client: Any = None, fps: float = 30.0,
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
    import contextlib

    from unmesh.distributed import connect, imap_ordered, require_dask
    from unmesh.render.image import VIDEO_EXTENSIONS, save_image, write_video

    out = Path(out_path)
    if out.suffix and out.suffix.lower() not in VIDEO_EXTENSIONS:
        raise InputError(f"output: expected .mp4, .gif or a directory for a frame sequence, got {out.name!r}")
    require_dask()
    plan = sequence_plan(frames, **plan_options)
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(connect(workers, scheduler))
        shared = client.scatter(plan, broadcast=True)

        def images() -> Iterator[np.ndarray]:
            yield from imap_ordered(client, render_frame, [(shared, i) for i in range(len(plan.groups))],
                                    progress=progress, desc="render")

        if out.suffix.lower() in VIDEO_EXTENSIONS:
            return write_video(images(), out, fps=fps)
        out.mkdir(parents=True, exist_ok=True)
        for k, img in enumerate(images()):
            save_image(out / f"frame_{k:05d}.png", img)
        return out
