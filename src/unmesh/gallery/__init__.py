"""The gallery: every capability's examples, run on built-in data, shown in one page.

Capabilities register examples with the :func:`example` decorator in a module
listed in :data:`EXAMPLE_MODULES`. An example is a function taking an
:class:`ExampleContext`; it writes its results (images, videos, data files) into
``ctx.outdir`` and reports them, with measured figures, through the context.
``ctx.quick`` asks for a small, fast version (used by the tests).

Example
-------
>>> from unmesh.gallery import example
>>> @example("demo", "A demo", section="Surfels")
... def _demo(ctx):
...     ctx.metric("answer", 42)
"""

from __future__ import annotations

import fnmatch
import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from unmesh.errors import InputError

__all__ = ["EXAMPLE_MODULES", "Example", "ExampleContext", "all_examples", "example", "select"]

#: Modules that register gallery examples, in page order.
EXAMPLE_MODULES: tuple[str, ...] = (
    "unmesh.surfels.examples",
    "unmesh.mls.examples",
    "unmesh.render.examples",
    "unmesh.shells.examples",
    "unmesh.sph.examples",
    "unmesh.fem.examples",
)


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


def all_examples() -> list[Example]:
    """Every registered example, in module order."""
    for name in EXAMPLE_MODULES:
        importlib.import_module(name)
    return list(_REGISTRY.values())


def select(patterns: str | None) -> list[Example]:
    """Examples whose names match any comma-separated glob pattern (all when None)."""
    examples = all_examples()
    if not patterns:
        return examples
    wanted = [p.strip() for p in patterns.split(",") if p.strip()]
    chosen = [e for e in examples if any(fnmatch.fnmatchcase(e.name, p) for p in wanted)]
    unknown = [p for p in wanted if not any(fnmatch.fnmatchcase(e.name, p) for e in examples)]
    if unknown:
        names = ", ".join(e.name for e in examples)
        raise InputError(f"--only: no example matches {', '.join(unknown)}; available: {names}")
    return chosen
