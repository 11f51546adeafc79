"""The gallery: every capability's examples, run on built-in data, shown in one page.

Examples live in the modules of :mod:`unmesh.gallery.examples` (one per topic,
listed in :data:`EXAMPLE_MODULES`, in page order), which register them with the
:func:`example` decorator of :mod:`unmesh.gallery.registry`; no capability knows
about the gallery. An example is a function taking an
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

from unmesh.errors import InputError
from unmesh.gallery.registry import _REGISTRY, Artifact, Example, ExampleContext, example

__all__ = ["EXAMPLE_MODULES", "Artifact", "Example", "ExampleContext", "all_examples", "example", "select"]

#: Modules that register gallery examples, in page order.
EXAMPLE_MODULES: tuple[str, ...] = (
    "unmesh.gallery.examples.sampling",
    "unmesh.gallery.examples.mls",
    "unmesh.gallery.examples.render",
    "unmesh.gallery.examples.shells",
    "unmesh.gallery.examples.sph",
    "unmesh.gallery.examples.fem",
    "unmesh.gallery.examples.csg",
    "unmesh.gallery.examples.paint",
    "unmesh.gallery.examples.studio",
    "unmesh.gallery.examples.convert",
)


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
