"""The gallery's registry: the :func:`example` decorator and what an example gets (:class:`ExampleContext`).

Example modules (:mod:`unmesh.gallery.examples`) import this module, never the
``unmesh.gallery`` package, whose ``__init__`` loads them by name (an example module
importing the package back would be an import cycle).

Example
-------
>>> from unmesh.gallery.registry import example
>>> @example("demo", "A demo", section="Surfels")
... def _demo(ctx):
...     ctx.metric("answer", 42)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from unmesh.errors import InputError

__all__ = ["Artifact", "Example", "ExampleContext", "example", "timed"]


@dataclass
class Artifact:
    """One result shown in the gallery page."""

    kind: str  # "image", "video", "file", "text"
    path: str  # relative to the gallery root ("" for text)
    caption: str = ""


@dataclass
class ExampleContext:
    """What an example gets: where to write, how big to run, and where to report."""

    outdir: Path
    root: Path
    quick: bool = False
    progress: bool = True
    artifacts: list[Artifact] = field(default_factory=list)
    metrics: list[tuple[str, Any, str]] = field(default_factory=list)

    def path(self, name: str) -> Path:
        """A path inside this example's output directory."""
        return self.outdir / name

    def _rel(self, path: Path | str) -> str:
        return Path(path).resolve().relative_to(self.root.resolve()).as_posix()

    def image(self, path: Path | str, caption: str = "") -> None:
        """Show a PNG/GIF image written by the example."""
        self.artifacts.append(Artifact("image", self._rel(path), caption))

    def video(self, path: Path | str, caption: str = "") -> None:
        """Show an MP4 video written by the example."""
        self.artifacts.append(Artifact("video", self._rel(path), caption))

    def file(self, path: Path | str, caption: str = "") -> None:
        """Link a data file written by the example."""
        self.artifacts.append(Artifact("file", self._rel(path), caption))

    def text(self, text: str) -> None:
        """Add a paragraph of explanation."""
        self.artifacts.append(Artifact("text", "", text))

    def metric(self, name: str, value: Any, unit: str = "") -> None:
        """Report a measured figure."""
        self.metrics.append((name, value, unit))

    def timed(self, fn: Callable[..., Any], *args: Any, warm: Callable[[], Any] | None = None,
              **kwargs: Any) -> tuple[Any, float]:
        """:func:`timed`: ``fn(*args, **kwargs)`` and its warm wall time in seconds."""
        return timed(fn, *args, warm=warm, **kwargs)

    def keep_frames(self, outdir: Path | str, frames: Iterable[int]) -> list[dict[str, Any]]:
        """Thin a simulation run to what the page shows (issue 23, item 13: the gallery's size).

        Deletes the files of every frame not in ``frames`` and the checkpoint, and rewrites
        ``frames.json`` to list the kept frames only, so ``unmesh render OUTDIR`` still works
        on what is left; ``summary.json`` keeps the diagnostics of every frame.

        Returns
        -------
        list of dict
            The kept entries of ``frames.json`` (``frame``, ``time``, ``files``).

        Example
        -------
        ``ctx.keep_frames(out, [0, 12, last])`` after rendering the stills and the video.
        """
        from unmesh.io.atomic import atomic_write_json
        from unmesh.sim.runner import MANIFEST, read_manifest

        out = Path(outdir)
        manifest = read_manifest(out)
        if manifest is None:
            return []
        keep = {int(k) for k in frames}
        kept = [e for e in manifest["frames"] if int(e["frame"]) in keep]
        for entry in manifest["frames"]:
            if int(entry["frame"]) not in keep:
                for f in entry["files"]:
                    (out / f).unlink(missing_ok=True)
        (out / "checkpoint.npz").unlink(missing_ok=True)
        atomic_write_json(out / MANIFEST, {**manifest, "frames": kept})
        return kept

    def run_scene(self, scene: str, build: Callable[..., Any], overrides: dict[str, Any] | None = None,
                  duration: float | None = None) -> tuple[Path, dict[str, Any]]:
        """Run a shipped scene ``examples/<scene>.toml`` with the shared simulation runner.

        Parameters
        ----------
        scene : str
            Scene name relative to the shipped scenes, e.g. ``"sph/dam_break"``.
        build : callable
            The capability's ``build(scene) -> (simulation, settings)`` (see :mod:`unmesh.sim.cli`).
        overrides : dict, optional
            Dotted-key scene overrides (as ``--set``), e.g. ``{"simulation.dt": 1e-4}``.
        duration : float, optional
            Simulated seconds (as ``--duration``).

        Returns
        -------
        outdir : Path
            ``ctx.outdir / <scene file stem>``, holding the run's frames and ``summary.json``.
        summary : dict
            The parsed ``summary.json``, also linked on the gallery page.

        Example
        -------
        ``out, summary = ctx.run_scene("fem/cantilever", build_simulation, {"simulation.duration": 2.0})``
        """
        import json

        from unmesh import scenes
        from unmesh.sim.cli import run_scene

        name = Path(scene).name
        out = self.path(name)
        # the example reruns into its own folder: force replaces the files of its previous run only
        run_scene(scenes.path(f"{scene}.toml"), out, build, overrides=overrides or None, duration=duration,
                  progress=self.progress, force=True)
        summary = json.loads((out / "summary.json").read_text())
        self.file(out / "summary.json", f"{name}: summary.json")
        return out, summary


def timed(fn: Callable[..., Any], *args: Any, warm: Callable[[], Any] | None = None,
          **kwargs: Any) -> tuple[Any, float]:
    """``fn(*args, **kwargs)`` and its warm wall time in seconds.

    ``warm()`` runs first (default: the same call) so that what numba has not compiled
    yet is compiled outside the timing: tables report warm figures (issue 23, item 14).
    Pass a small version of the call as ``warm`` when the call itself is expensive.

    Example
    -------
    ``cloud, seconds = ctx.timed(sample_mesh, mesh, d, warm=lambda: sample_mesh(mesh, 4 * d))``
    """
    import time

    if warm is None:
        fn(*args, **kwargs)
    else:
        warm()
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


@dataclass(frozen=True)
class Example:
    """A registered gallery example."""

    name: str
    title: str
    section: str
    func: Callable[[ExampleContext], None]
    description: str = ""


_REGISTRY: dict[str, Example] = {}


def example(name: str, title: str, section: str, description: str = "") -> Callable[[Callable[[ExampleContext], None]], Callable[[ExampleContext], None]]:
    """Register a gallery example under a unique ``name``."""

    def deco(func: Callable[[ExampleContext], None]) -> Callable[[ExampleContext], None]:
        if name in _REGISTRY and _REGISTRY[name].func.__qualname__ != func.__qualname__:
            raise InputError(f"example name {name!r} is registered twice")
        _REGISTRY[name] = Example(name, title, section, func, description or (func.__doc__ or "").strip())
        return func

    return deco
