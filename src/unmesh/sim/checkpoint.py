"""Checkpoints: a simulation's state plus the runner's bookkeeping in one ``.npz``.

Arrays are stored as they are; everything else that is JSON-able (numbers,
strings, RNG states given as dicts) goes into one JSON string, so files load with
``allow_pickle=False``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import SimulationError
from unmesh.io.atomic import atomic_path

__all__ = ["expect_shapes", "load_checkpoint", "save_checkpoint"]

_FORMAT = 1


def save_checkpoint(path: str | os.PathLike[str], state: dict[str, Any], meta: dict[str, Any]) -> None:
    """Write ``state`` (the simulation's ``state_dict``) and runner ``meta`` atomically."""
    arrays: dict[str, np.ndarray] = {}
    other: dict[str, Any] = {}
    for key, value in state.items():
        if isinstance(value, np.ndarray):
            arrays[f"s/{key}"] = value
        else:
            other[key] = value.item() if isinstance(value, np.generic) else value
    try:
        blob = json.dumps({"format": _FORMAT, "meta": meta, "state": other})
    except TypeError as exc:
        raise SimulationError(f"checkpoint: state_dict values must be arrays or JSON-able, {exc}") from None
    arrays["__json__"] = np.frombuffer(blob.encode("utf-8"), dtype=np.uint8)
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


class _State(dict):
    """A checkpoint's state: a key the simulation needs but the file lacks is a SimulationError."""

    def __init__(self, data: dict[str, Any], path: Path) -> None:
        super().__init__(data)
        self._path = path

    def __missing__(self, key: str) -> Any:
        raise SimulationError(f"{self._path}: the checkpoint has no {key!r} (written by another kind of "
                              "simulation or another version?); run without --resume to start over")


#: Bookkeeping every checkpoint carries: key -> accepted types.
_META = {"frame": (int,), "steps": (int,), "wall_seconds": (int, float), "frames": (list,)}


def load_checkpoint(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Read a checkpoint; returns ``(state, meta)``.

    Raises
    ------
    SimulationError
        The file is missing, truncated or not a checkpoint (the message names it),
        its bookkeeping is malformed, or a key the simulation asks ``state`` for is
        absent (another simulation's checkpoint).
    """
    p = Path(path)
    if not p.is_file():
        raise SimulationError(f"no checkpoint to resume from: {p} does not exist")
    try:
        with np.load(p, allow_pickle=False) as npz:
            if not hasattr(npz, "files"):
                raise ValueError("not an .npz archive")
            blob = json.loads(bytes(npz["__json__"]).decode("utf-8"))
            state: dict[str, Any] = {k[2:]: npz[k] for k in npz.files if k.startswith("s/")}
    except Exception as exc:  # zipfile, zlib, numpy and json raise many types for damaged files
        raise SimulationError(f"{p}: unreadable checkpoint ({type(exc).__name__}: {exc}); "
                              "run without --resume to start over") from None
    if not isinstance(blob, dict) or blob.get("format") != _FORMAT:
        got = blob.get("format") if isinstance(blob, dict) else type(blob).__name__
        raise SimulationError(f"{p}: checkpoint format {got} is not supported")
    meta, other = blob.get("meta"), blob.get("state")
    if not isinstance(meta, dict) or not isinstance(other, dict):
        raise SimulationError(f"{p}: malformed checkpoint (no 'meta' and 'state' tables)")
    for key, types in _META.items():
        value = meta.get(key)
        if isinstance(value, bool) or not isinstance(value, types):
            raise SimulationError(f"{p}: malformed checkpoint: meta {key!r} is {value!r}")
    if meta["frame"] < 0 or meta["steps"] < 0:
        raise SimulationError(f"{p}: malformed checkpoint: negative frame or step count")
    state.update(other)
    return _State(state, p), meta


def expect_shapes(state: Mapping[str, Any], shapes: Mapping[str, tuple[int | None, ...]]) -> None:
    """Check the shapes of a checkpoint's arrays before a simulation restores them.

    Parameters
    ----------
    state : mapping
        What :func:`load_checkpoint` returned (or a plain ``state_dict``).
    shapes : mapping of str to tuple
        Expected shape per key; ``None`` matches any length on that axis.

    Raises
    ------
    SimulationError
        One line naming the checkpoint, the array and both shapes (a checkpoint of
        another scene whose keys match), or the missing key.

    Example
    -------
    >>> import numpy as np
    >>> expect_shapes({"x": np.zeros((4, 3))}, {"x": (4, 3)})
    >>> expect_shapes({"x": np.zeros((5, 3))}, {"x": (4, None)})
    Traceback (most recent call last):
    ...
    unmesh.errors.SimulationError: checkpoint: array 'x' has shape (5, 3) but this scene needs (4, any) ...
    """
    where = getattr(state, "_path", "checkpoint")
    for key, want in shapes.items():
        got = np.shape(state[key])
        if len(got) != len(want) or any(w is not None and g != w for g, w in zip(got, want, strict=True)):
            need = "(" + ", ".join("any" if w is None else str(w) for w in want) + ("," if len(want) == 1 else "") + ")"
            raise SimulationError(f"{where}: array {key!r} has shape {tuple(got)} but this scene needs {need} "
                                  "(the checkpoint belongs to another scene); run without --resume to start over")
