"""Checkpoints: a simulation's state plus the runner's bookkeeping in one ``.npz``.

Arrays are stored as they are; everything else that is JSON-able (numbers,
strings, RNG states given as dicts) goes into one JSON string, so files load with
``allow_pickle=False``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import SimulationError
from unmesh.io.atomic import atomic_path

__all__ = ["load_checkpoint", "save_checkpoint"]

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


def load_checkpoint(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Read a checkpoint; returns ``(state, meta)``."""
    p = Path(path)
    if not p.is_file():
        raise SimulationError(f"no checkpoint to resume from: {p} does not exist")
    try:
        with np.load(p, allow_pickle=False) as npz:
            blob = json.loads(bytes(npz["__json__"]).decode("utf-8"))
            state: dict[str, Any] = {k[2:]: npz[k] for k in npz.files if k.startswith("s/")}
    except (OSError, ValueError, KeyError) as exc:
        raise SimulationError(f"{p}: unreadable checkpoint ({exc})") from None
    if blob.get("format") != _FORMAT:
        raise SimulationError(f"{p}: checkpoint format {blob.get('format')} is not supported")
    state.update(blob["state"])
    return state, blob["meta"]
