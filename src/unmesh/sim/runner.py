"""The one simulation runner shared by SPH, thin shells and FEM.

A simulation implements :class:`Simulation` (step, check, frame output,
diagnostics, state for checkpoints); :func:`run` does everything else:

- the time loop: frame 0 is the initial state; frame k is written once
  ``sim.time >= k / fps`` (fixed-step simulations land within one step of it);
- ``sim.check()`` after every step; a reason (NaN, energy blow-up) or a non-finite
  frame record stops the run with status ``"unstable"`` and raises
  :class:`unmesh.errors.UnstableSimulationError` — nothing is written for the bad
  state, so the last good frame and its checkpoint stay on disk;
- ``summary.json`` rewritten atomically after every frame (always readable):
  ``{"status", "message", "steps", "wall_seconds", **sim.summary_header(),
  "frames": [{"frame", "time", "step_seconds", **sim.frame_record()}]}``;
- ``checkpoint.npz`` after every ``checkpoint_every`` frames, and ``resume=True``
  to continue from it (to the same or a new duration);
- Ctrl-C: status ``"interrupted"``, summary and last checkpoint kept, then
  KeyboardInterrupt propagates (the CLI exits with 130);
- a progress bar over frames showing simulated time and steps per second.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError, UnstableSimulationError
from unmesh.io.atomic import atomic_write_json
from unmesh.sim.checkpoint import load_checkpoint, save_checkpoint

__all__ = ["RunResult", "RunSettings", "Simulation", "run"]


class Simulation(ABC):
    """Interface between a simulation and :func:`run`.

    Subclasses keep ``self.time`` (simulated seconds) current in :meth:`step`.
    """

    #: Shown in the progress bar and messages.
    name: str = "simulation"
    #: Glob patterns (relative to OUTDIR) of per-frame files; stale matches are
    #: removed when a fresh (non-resumed) run starts in an existing directory.
    frame_patterns: tuple[str, ...] = ("frames/frame_*.ply",)
    time: float = 0.0

    @abstractmethod
    def step(self) -> float:
        """Advance one time step; return the step size used."""

    @abstractmethod
    def check(self) -> str | None:
        """None when the state is sane, else a short reason (cheap; runs every step)."""

    @abstractmethod
    def write_frame(self, outdir: Path, frame: int) -> None:
        """Write the files of frame ``frame`` (atomically)."""

    @abstractmethod
    def frame_record(self) -> dict[str, Any]:
        """Diagnostics of the current state for ``summary.json`` (JSON-able values)."""

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume: arrays, numbers, strings, JSON-able dicts (RNG state)."""

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned (arrays come back as numpy arrays)."""

    def summary_header(self) -> dict[str, Any]:
        """Top-level ``summary.json`` entries (e.g. particle counts)."""
        return {}

    def write_static(self, outdir: Path) -> None:  # noqa: B027 - optional hook
        """Write files that do not change over the run (e.g. boundary particles)."""


@dataclass(frozen=True)
class RunSettings:
    """How long and how often to write.

    Parameters
    ----------
    duration : float
        Simulated seconds (> 0).
    fps : float
        Frames per simulated second (> 0).
    checkpoint_every : int
        Write ``checkpoint.npz`` every this many frames (the last frame always).
    """

    duration: float
    fps: float = 30.0
    checkpoint_every: int = 1

    def __post_init__(self) -> None:
        if not (self.duration > 0 and math.isfinite(self.duration)):
            raise InputError(f"duration: expected a positive number of seconds, got {self.duration}")
        if not (self.fps > 0 and math.isfinite(self.fps)):
            raise InputError(f"fps: expected a positive frame rate, got {self.fps}")
        if self.checkpoint_every < 1:
            raise InputError(f"checkpoint_every: expected >= 1, got {self.checkpoint_every}")

    @property
    def frames(self) -> int:
        """Index of the last frame (frame 0 is the initial state)."""
        return max(1, math.floor(self.duration * self.fps + 1e-9))

    def replace(self, **changes: Any) -> RunSettings:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class RunResult:
    """What :func:`run` did."""

    status: str
    frames: int
    steps: int
    wall_seconds: float
    outdir: Path
    summary: dict[str, Any]


def _finite(value: Any) -> bool:
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, list | tuple):
        return all(_finite(v) for v in value)
    if isinstance(value, np.ndarray):
        return not np.issubdtype(value.dtype, np.floating) or bool(np.all(np.isfinite(value)))
    if isinstance(value, float | np.floating):
        return math.isfinite(float(value))
    return True


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


class _Run:
    """Bookkeeping of one run (kept out of the Simulation)."""

    def __init__(self, sim: Simulation, outdir: Path, settings: RunSettings) -> None:
        self.sim = sim
        self.outdir = outdir
        self.settings = settings
        self.summary: dict[str, Any] = {"status": "running", "message": "", "steps": 0, "wall_seconds": 0.0}
        self.summary.update(_jsonable(sim.summary_header()))
        self.summary["frames"] = []
        self.frame = 0
        self.steps = 0
        self.wall_before = 0.0
        self.t_start = time.perf_counter()

    @property
    def checkpoint_path(self) -> Path:
        return self.outdir / "checkpoint.npz"

    def wall(self) -> float:
        return self.wall_before + time.perf_counter() - self.t_start

    def write_summary(self) -> None:
        self.summary["steps"] = self.steps
        self.summary["wall_seconds"] = round(self.wall(), 6)
        atomic_write_json(self.outdir / "summary.json", self.summary)

    def write_checkpoint(self) -> None:
        meta = {"frame": self.frame, "steps": self.steps, "wall_seconds": self.wall(), "frames": self.summary["frames"]}
        save_checkpoint(self.checkpoint_path, self.sim.state_dict(), meta)

    def record(self, step_seconds: float) -> dict[str, Any]:
        rec = _jsonable(self.sim.frame_record())
        if not _finite(rec):
            bad = [k for k, v in rec.items() if not _finite(v)]
            raise _Unstable(f"non-finite {', '.join(bad)} in the frame diagnostics")
        return {"frame": self.frame, "time": float(self.sim.time), "step_seconds": step_seconds, **rec}


class _Unstable(Exception):
    pass


def _clean_stale(sim: Simulation, outdir: Path) -> None:
    for pattern in sim.frame_patterns:
        for p in outdir.glob(pattern):
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    for name in ("checkpoint.npz", "summary.json"):
        with contextlib.suppress(FileNotFoundError):
            (outdir / name).unlink()


def run(sim: Simulation, outdir: str | os.PathLike[str], settings: RunSettings, *, resume: bool = False,
        progress: bool = True) -> RunResult:
    """Run ``sim`` for ``settings.duration`` simulated seconds, writing into ``outdir``.

    Parameters
    ----------
    sim : Simulation
        The simulation, in its initial state (or any state when ``resume``).
    outdir : path-like
        Output directory (created).
    settings : RunSettings
        Duration, frame rate, checkpoint interval.
    resume : bool
        Continue from ``outdir/checkpoint.npz``.
    progress : bool
        Show a progress bar.

    Returns
    -------
    RunResult

    Raises
    ------
    unmesh.errors.UnstableSimulationError
        The state blew up; ``summary.json`` says so and the last good frame stays.
    KeyboardInterrupt
        After recording status ``"interrupted"``.
    """
    from tqdm import tqdm

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    r = _Run(sim, out, settings)
    if resume:
        state, meta = load_checkpoint(r.checkpoint_path)
        sim.load_state_dict(state)
        r.frame = int(meta["frame"])
        r.steps = int(meta["steps"])
        r.wall_before = float(meta["wall_seconds"])
        r.summary["frames"] = list(meta["frames"])[: r.frame + 1]
    else:
        _clean_stale(sim, out)
        sim.write_static(out)
    last = settings.frames
    bar = tqdm(total=last, initial=r.frame, desc=sim.name, unit="frame", disable=not progress, leave=True)
    try:
        if not resume:
            reason = sim.check()
            if reason:
                raise _Unstable(f"initial state: {reason}")
            r.summary["frames"].append(r.record(0.0))
            sim.write_frame(out, 0)
            r.write_checkpoint()
            r.write_summary()
        while r.frame < last:
            target = (r.frame + 1) / settings.fps
            tol = 1e-9 * max(1.0, target)
            spent = 0.0
            n = 0
            while sim.time < target - tol:
                t0 = time.perf_counter()
                sim.step()
                spent += time.perf_counter() - t0
                n += 1
                r.steps += 1
                reason = sim.check()
                if reason:
                    raise _Unstable(reason)
            r.frame += 1
            rec = r.record(spent / n if n else 0.0)
            sim.write_frame(out, r.frame)
            r.summary["frames"].append(rec)
            if r.frame % settings.checkpoint_every == 0 or r.frame == last:
                r.write_checkpoint()
            r.write_summary()
            bar.update(1)
            bar.set_postfix_str(f"t={sim.time:.3g}s {n / spent if spent > 0 else 0:.0f} steps/s")
    except _Unstable as exc:
        good = r.summary["frames"][-1]["frame"] if r.summary["frames"] else None
        where = f"last good frame {good} is in {out}" if good is not None else "no frame was written"
        msg = (f"{sim.name} became unstable at t={sim.time:.6g} s (step {r.steps}): {exc}; {where}; "
               "try a smaller time step")
        r.summary["status"] = "unstable"
        r.summary["message"] = msg
        r.write_summary()
        raise UnstableSimulationError(msg) from None
    except KeyboardInterrupt:
        r.summary["status"] = "interrupted"
        r.summary["message"] = f"interrupted at t={sim.time:.6g} s; continue with --resume (from frame {r.frame})"
        r.write_summary()
        raise
    except Exception as exc:
        r.summary["status"] = "failed"
        r.summary["message"] = f"{type(exc).__name__}: {exc}"
        r.write_summary()
        raise
    finally:
        bar.close()
    r.summary["status"] = "completed"
    r.summary["message"] = ""
    r.write_summary()
    return RunResult("completed", r.frame, r.steps, r.wall(), out, r.summary)
