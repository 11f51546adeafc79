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
  ``{"status", "message", "steps", "wall_seconds", **sim.summary_header(), "process",
  "frames": [{"frame", "time", "step_seconds", **sim.frame_record()}]}``;
- ``frames.json``, the manifest of every file the run wrote, rewritten atomically after
  every frame: ``{"frames": [{"frame", "time", "files": [...]}], "static": [...], "fps",
  "simulation"}`` with paths relative to OUTDIR (the lists :meth:`Simulation.write_frame`
  and :meth:`Simulation.write_static` return). ``unmesh render OUTDIR`` reads it;
- ``checkpoint.npz`` after every ``checkpoint_every`` frames, and ``resume=True``
  to continue from it (to the same or a new duration); the manifest continues from the
  checkpoint's frame, files of later frames (written before an interruption) are removed;
- output folders: a fresh run into a non-empty folder raises :class:`unmesh.errors.InputError`
  unless ``force=True``; then it removes only the files the folder's previous run recorded
  in its ``frames.json`` (plus that run's ``summary.json``, ``frames.json`` and
  ``checkpoint.npz``), never other files; a folder whose summary says ``"running"`` for a
  process that is still alive is refused even with ``force`` (and for ``resume``);
- Ctrl-C: status ``"interrupted"``, summary and last checkpoint kept, then
  KeyboardInterrupt propagates (the CLI exits with 130); SIGTERM: status ``"terminated"``,
  then the signal's previous handling (by default the process ends by the signal);
  any other error, write errors included (a full disk): status ``"failed"`` (the summary is
  then rewritten in place when an atomic rewrite is impossible);
- ``kill -9`` cannot be caught: the summary stays ``"running"`` with the ``"process"``
  (``pid``, ``host``, ``start``) that wrote it; :func:`read_summary` reports such a summary
  as ``"interrupted"`` once that process is gone, and ``resume`` / ``force`` accept it;
- a progress bar over frames showing simulated time and steps per second.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import signal
import socket
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from unmesh.errors import InputError, SimulationError, UnstableSimulationError
from unmesh.io.atomic import atomic_write_json
from unmesh.sim.checkpoint import load_checkpoint, save_checkpoint

__all__ = ["MANIFEST", "RunResult", "RunSettings", "Simulation", "read_manifest", "read_summary", "run"]

#: The manifest of a run's files, in OUTDIR.
MANIFEST = "frames.json"
#: Files of the runner itself, in OUTDIR.
_RUNNER_FILES = ("summary.json", MANIFEST, "checkpoint.npz")


class Simulation(ABC):
    """Interface between a simulation and :func:`run`.

    Subclasses keep ``self.time`` (simulated seconds) current in :meth:`step`.
    """

    #: Shown in the progress bar and messages.
    name: str = "simulation"
    time: float = 0.0

    @abstractmethod
    def step(self) -> float:
        """Advance one time step; return the step size used."""

    @abstractmethod
    def check(self) -> str | None:
        """None when the state is sane, else a short reason (cheap; runs every step)."""

    @abstractmethod
    def write_frame(self, outdir: Path, frame: int) -> Sequence[str | os.PathLike[str]] | None:
        """Write the files of frame ``frame`` (atomically) and return them.

        Returns the written files, relative to ``outdir`` (or absolute paths inside it);
        the renderable frame itself goes into ``outdir/frames/``. :func:`run` records
        them in ``frames.json``. ``None`` means no files.
        """

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

    def write_static(self, outdir: Path) -> Sequence[str | os.PathLike[str]] | None:
        """Write files that do not change over the run (e.g. boundary particles) and return them.

        Called once by a fresh run, before frame 0; the returned files (as for
        :meth:`write_frame`) are the manifest's ``"static"`` list.
        """
        return None


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


def _relative(outdir: Path, files: Sequence[str | os.PathLike[str]] | None, what: str) -> list[str]:
    """Paths returned by a simulation as POSIX paths relative to ``outdir`` (checked to lie inside)."""
    if files is None:
        return []
    if isinstance(files, str | os.PathLike):
        raise InputError(f"{what}: expected a list of written files, got the single path {os.fspath(files)!r}")
    out: list[str] = []
    root = outdir.resolve()
    for f in files:
        p = Path(f)
        q = p.resolve() if p.is_absolute() else (outdir / p).resolve()
        try:
            rel = q.relative_to(root).as_posix()
        except ValueError:
            raise InputError(f"{what}: expected files inside {outdir}, got {os.fspath(f)!r}") from None
        if rel not in out:
            out.append(rel)
    return out


def _safe_member(outdir: Path, rel: Any) -> Path | None:
    """``outdir / rel`` when ``rel`` (from a manifest on disk) is a plain relative path inside ``outdir``."""
    if not isinstance(rel, str) or not rel:
        return None
    pp = PurePosixPath(rel)
    if pp.is_absolute() or ".." in pp.parts or "\\" in rel:
        return None
    return outdir / pp


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def read_manifest(outdir: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``frames.json`` of a run folder, or None when there is none (or it is unreadable).

    Example
    -------
    >>> import tempfile
    >>> read_manifest(tempfile.mkdtemp()) is None
    True
    """
    data = _read_json(Path(outdir) / MANIFEST)
    if data is None or not isinstance(data.get("frames"), list):
        return None
    return data


def _proc_start(pid: int) -> str | None:
    """Start time of process ``pid`` in clock ticks since boot (Linux), else None."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            stat = fh.read()
        return stat[stat.rindex(")") + 2:].split()[19]
    except (OSError, ValueError, IndexError):
        return None


def _process_info() -> dict[str, Any]:
    pid = os.getpid()
    return {"pid": pid, "host": socket.gethostname(), "start": _proc_start(pid)}


def _alive(info: Any) -> bool | None:
    """Whether the process recorded in a summary still runs: True, False, or None (unknown)."""
    if not isinstance(info, dict) or not isinstance(info.get("pid"), int):
        return None
    if info.get("host") != socket.gethostname():
        return None
    pid = info["pid"]
    if pid == os.getpid():
        return False  # an earlier run of this process that ended without recording its status
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    except OSError:
        return None
    start = info.get("start")
    if start is not None:
        now = _proc_start(pid)
        if now is not None and now != start:
            return False  # the pid was reused by another process
    return True


def read_summary(outdir: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``summary.json`` of a run folder, with a dead run's ``"running"`` read as ``"interrupted"``.

    A run killed with ``kill -9`` (or by a power cut) cannot record its end; its summary
    keeps ``"status": "running"``. When the recorded process (same host) no longer exists,
    the returned summary says ``"interrupted"`` (the file is not changed). None when there
    is no readable summary.

    Example
    -------
    >>> import tempfile
    >>> read_summary(tempfile.mkdtemp()) is None
    True
    """
    summary = _read_json(Path(outdir) / "summary.json")
    if summary is None:
        return None
    if summary.get("status") == "running" and _alive(summary.get("process")) is False:
        pid = summary["process"]["pid"]
        summary = {**summary, "status": "interrupted",
                   "message": f"process {pid} ended without recording a status (killed); continue with --resume"}
    return summary


def _busy(outdir: Path) -> str | None:
    """A message when ``outdir`` is being written by another live process."""
    summary = _read_json(outdir / "summary.json")
    if summary and summary.get("status") == "running" and _alive(summary.get("process")) is True:
        info = summary["process"]
        return (f"{outdir} is being written by process {info['pid']} on {info['host']} (summary.json says "
                "\"running\"); wait for it to end or stop it first")
    return None


def _remove_recorded(outdir: Path, manifest: dict[str, Any] | None, keep: set[str] = frozenset(),  # type: ignore[assignment]
                     frames_after: int | None = None) -> list[Path]:
    """Remove files a previous run recorded in its manifest (all, or of frames after ``frames_after``).

    Only plain relative paths inside ``outdir`` are touched; directories left empty by the
    removal are removed too. Returns the removed files.
    """
    if manifest is None:
        return []
    rels: list[Any] = []
    for entry in manifest.get("frames", []):
        if not isinstance(entry, dict):
            continue
        if frames_after is not None and not (isinstance(entry.get("frame"), int) and entry["frame"] > frames_after):
            continue
        files = entry.get("files", [])
        rels.extend(files if isinstance(files, list) else [])
    if frames_after is None:
        static = manifest.get("static", [])
        rels.extend(static if isinstance(static, list) else [])
    removed: list[Path] = []
    dirs: set[Path] = set()
    for rel in rels:
        p = _safe_member(outdir, rel)
        if p is None or rel in keep or rel in _RUNNER_FILES:
            continue
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, NotADirectoryError):
            p.unlink()
            removed.append(p)
            dirs.update(q for q in p.parents if q != outdir and outdir in q.parents)
    for d in sorted(dirs, key=lambda q: len(q.parts), reverse=True):
        with contextlib.suppress(OSError):
            d.rmdir()  # only when empty
    return removed


def _prepare_fresh(sim: Simulation, outdir: Path, force: bool) -> None:
    """Refuse a non-empty folder (unless ``force``); with ``force`` remove the previous run's own files."""
    busy = _busy(outdir)
    if busy:
        raise SimulationError(busy)
    entries = sorted(p.name for p in outdir.iterdir())
    if not entries:
        return
    if not force:
        summary = read_summary(outdir)
        shown = ", ".join(entries[:5]) + (", ..." if len(entries) > 5 else "")
        if summary is not None:
            kind = f"a previous run (status {summary.get('status')!r})"
            hint = ("continue it with --resume (resume=True), or replace the files that run wrote with --force "
                    "(force=True; other files are kept)")
        else:
            kind = "files that are not a simulation run"
            hint = "choose a new or empty folder, or write into it anyway with --force (force=True; no file is deleted)"
        raise InputError(f"outdir: expected a new or empty folder, got {outdir} holding {kind} "
                         f"({len(entries)} entries: {shown}); {hint}")
    _remove_recorded(outdir, read_manifest(outdir))
    for name in _RUNNER_FILES:
        with contextlib.suppress(FileNotFoundError):
            (outdir / name).unlink()


class _Terminated(BaseException):
    """SIGTERM arrived (raised by the handler :func:`_sigterm_raises` installs)."""


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[list[Any]]:
    """While active, SIGTERM raises :class:`_Terminated` (main thread only); yields [previous handler]."""
    holder: list[Any] = []
    if threading.current_thread() is not threading.main_thread():
        yield holder
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous == signal.SIG_IGN:
        yield holder
        return

    def handler(signum: int, frame: Any) -> None:
        raise _Terminated

    holder.append(previous)
    signal.signal(signal.SIGTERM, handler)
    try:
        yield holder
    finally:
        signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)


class _Run:
    """Bookkeeping of one run (kept out of the Simulation)."""

    def __init__(self, sim: Simulation, outdir: Path, settings: RunSettings) -> None:
        self.sim = sim
        self.outdir = outdir
        self.settings = settings
        self.summary: dict[str, Any] = {"status": "running", "message": "", "steps": 0, "wall_seconds": 0.0}
        self.summary.update(_jsonable(sim.summary_header()))
        self.summary["process"] = _process_info()
        self.summary["frames"] = []
        self.manifest: dict[str, Any] = {"frames": [], "static": [], "fps": float(settings.fps), "simulation": sim.name}
        self.frame = 0
        self.checkpoint_frame: int | None = None
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

    def write_final_summary(self) -> None:
        """Record the run's end even when an atomic rewrite fails (a full disk): then in place."""
        try:
            self.write_summary()
            return
        except OSError:
            pass
        path = self.outdir / "summary.json"
        text = json.dumps(_jsonable(self.summary), indent=1, default=str) + "\n"
        short = json.dumps({k: self.summary[k] for k in ("status", "message", "steps", "wall_seconds")}) + "\n"
        for body in (text, short):
            try:
                with open(path, "r+" if path.exists() else "w", encoding="utf-8") as fh:
                    fh.truncate(0)  # frees the old blocks first
                    fh.write(body)
                    fh.flush()
                    os.fsync(fh.fileno())
                return
            except (OSError, ValueError):
                continue

    def write_manifest(self) -> None:
        atomic_write_json(self.outdir / MANIFEST, self.manifest)

    def add_frame(self, files: Sequence[str | os.PathLike[str]] | None) -> None:
        rel = _relative(self.outdir, files, f"{type(self.sim).__name__}.write_frame")
        self.manifest["frames"].append({"frame": self.frame, "time": float(self.sim.time), "files": rel})

    def write_checkpoint(self) -> None:
        meta = {"frame": self.frame, "steps": self.steps, "wall_seconds": self.wall(), "frames": self.summary["frames"],
                "manifest": {"frames": self.manifest["frames"], "static": self.manifest["static"]}}
        save_checkpoint(self.checkpoint_path, self.sim.state_dict(), meta)
        self.checkpoint_frame = self.frame

    def record(self, step_seconds: float) -> dict[str, Any]:
        rec = _jsonable(self.sim.frame_record())
        if not _finite(rec):
            bad = [k for k, v in rec.items() if not _finite(v)]
            raise _Unstable(f"non-finite {', '.join(bad)} in the frame diagnostics")
        return {"frame": self.frame, "time": float(self.sim.time), "step_seconds": step_seconds, **rec}

    def resume_hint(self) -> str:
        if self.checkpoint_frame is None:
            return "no checkpoint was written; start again"
        return f"continue with --resume (from frame {self.checkpoint_frame})"


class _Unstable(Exception):
    pass


def _resume(r: _Run, sim: Simulation, out: Path) -> None:
    busy = _busy(out)
    if busy:
        raise SimulationError(busy)
    state, meta = load_checkpoint(r.checkpoint_path)
    try:  # first: a checkpoint of another kind of simulation is named as such
        sim.load_state_dict(state)
    except (ValueError, IndexError, TypeError) as exc:  # a simulation that does not check its arrays' shapes
        raise SimulationError(f"{r.checkpoint_path}: the checkpoint does not fit this scene "
                              f"({type(exc).__name__}: {exc}); run without --resume to start over") from None
    manifest = meta.get("manifest")
    if not isinstance(manifest, dict):
        raise SimulationError(f"{r.checkpoint_path}: the checkpoint predates {MANIFEST} (the record of the run's "
                              "files); start the run again with --force (force=True)")
    r.frame = int(meta["frame"])
    r.checkpoint_frame = r.frame
    r.steps = int(meta["steps"])
    r.wall_before = float(meta["wall_seconds"])
    r.summary["frames"] = list(meta["frames"])[: r.frame + 1]
    r.manifest["frames"] = [e for e in manifest["frames"] if int(e["frame"]) <= r.frame]
    r.manifest["static"] = list(manifest["static"])
    # files of frames after the checkpoint (written before the interruption) are dropped
    keep = {f for e in r.manifest["frames"] for f in e["files"]} | set(r.manifest["static"])
    _remove_recorded(out, read_manifest(out), keep=keep, frames_after=r.frame)
    r.write_manifest()


def run(sim: Simulation, outdir: str | os.PathLike[str], settings: RunSettings, *, resume: bool = False,
        progress: bool = True, force: bool = False) -> RunResult:
    """Run ``sim`` for ``settings.duration`` simulated seconds, writing into ``outdir``.

    Parameters
    ----------
    sim : Simulation
        The simulation, in its initial state (or any state when ``resume``).
    outdir : path-like
        Output directory (created). A fresh run needs it new or empty unless ``force``.
    settings : RunSettings
        Duration, frame rate, checkpoint interval.
    resume : bool
        Continue from ``outdir/checkpoint.npz``.
    progress : bool
        Show a progress bar.
    force : bool
        Start a fresh run in a non-empty folder: the files its previous run recorded in
        ``frames.json`` (and that run's ``summary.json``, ``frames.json``, ``checkpoint.npz``)
        are removed, every other file is kept (files at the names this run writes are
        overwritten).

    Returns
    -------
    RunResult

    Raises
    ------
    unmesh.errors.InputError
        A fresh run into a non-empty folder without ``force``.
    unmesh.errors.SimulationError
        The folder is being written by another live process, or there is no usable checkpoint to resume.
    unmesh.errors.UnstableSimulationError
        The state blew up; ``summary.json`` says so and the last good frame stays.
    KeyboardInterrupt
        After recording status ``"interrupted"``.
    """
    from tqdm import tqdm

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    r = _Run(sim, out, settings)
    terminated = False
    with _sigterm_raises() as previous:
        try:
            # checks that write nothing when they refuse
            if resume:
                _resume(r, sim, out)
            else:
                _prepare_fresh(sim, out, force)
        except _Terminated:
            raise SystemExit(128 + signal.SIGTERM) from None
        last = settings.frames
        bar = tqdm(total=last, initial=r.frame, desc=sim.name, unit="frame", disable=not progress, leave=True)
        try:
            r.write_summary()  # "running" with this process, before anything else is written
            if not resume:
                r.manifest["static"] = _relative(out, sim.write_static(out), f"{type(sim).__name__}.write_static")
                r.write_manifest()
                reason = sim.check()
                if reason:
                    raise _Unstable(f"initial state: {reason}")
                r.summary["frames"].append(r.record(0.0))
                r.add_frame(sim.write_frame(out, 0))
                r.write_manifest()  # first: files on disk are recorded as soon as possible
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
                r.add_frame(sim.write_frame(out, r.frame))
                r.write_manifest()
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
            r.write_final_summary()
            raise UnstableSimulationError(msg) from None
        except KeyboardInterrupt:
            r.summary["status"] = "interrupted"
            r.summary["message"] = f"interrupted at t={sim.time:.6g} s; {r.resume_hint()}"
            r.write_final_summary()
            raise
        except _Terminated:
            r.summary["status"] = "terminated"
            r.summary["message"] = f"terminated (SIGTERM) at t={sim.time:.6g} s; {r.resume_hint()}"
            r.write_final_summary()
            terminated = True
        except Exception as exc:
            r.summary["status"] = "failed"
            r.summary["message"] = f"{type(exc).__name__}: {exc}"
            r.write_final_summary()
            raise
        finally:
            bar.close()
    if terminated:
        # the previous SIGTERM handling again: by default the process ends by the signal
        if previous and callable(previous[0]):
            previous[0](signal.SIGTERM, None)
        elif not previous or previous[0] in (signal.SIG_DFL, None):
            os.kill(os.getpid(), signal.SIGTERM)
        raise SystemExit(128 + signal.SIGTERM)
    r.summary["status"] = "completed"
    r.summary["message"] = ""
    r.write_final_summary()
    return RunResult("completed", r.frame, r.steps, r.wall(), out, r.summary)
