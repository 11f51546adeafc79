"""Exceptions raised by unmesh.

Every error a user can cause derives from :class:`UnmeshError`. Errors about bad
arguments or bad files also derive from :class:`ValueError`, so generic handlers
keep working. Messages name the argument (or file and key), what was expected and
what was found; the command line prints them as one line ``unmesh: error: ...``.

Example
-------
>>> from unmesh.errors import InputError
>>> try:
...     raise InputError("radius: expected a positive number, got -1.0")
... except ValueError as exc:
...     print(exc)
radius: expected a positive number, got -1.0
"""

from __future__ import annotations

__all__ = [
    "FormatError",
    "InputError",
    "MissingDependencyError",
    "SceneError",
    "SimulationError",
    "UnmeshError",
    "UnstableSimulationError",
]


class UnmeshError(Exception):
    """Base class of every exception unmesh raises on purpose."""


class InputError(UnmeshError, ValueError):
    """A function argument has the wrong shape, type, or value."""


class FormatError(UnmeshError, ValueError):
    """A file is malformed, truncated, or inconsistent.

    The message names the file and, where it applies, the element.
    """


class SceneError(UnmeshError, ValueError):
    """A scene file is invalid; the message names the file and the key."""


class SimulationError(UnmeshError):
    """A simulation could not continue."""


class UnstableSimulationError(SimulationError):
    """The state blew up (NaN, infinite or exploding energy).

    The run stops; its last good frame stays on disk.
    """


class MissingDependencyError(UnmeshError, ImportError):
    """An optional dependency needed for this feature is not installed."""
