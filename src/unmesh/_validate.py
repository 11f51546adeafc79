"""Input conversion and validation at the public boundary.

Public functions call these once on their arguments; kernels never do. Arrays come
back C-contiguous with a fixed dtype (float64 for coordinates, int64 for indices),
so everything behind the boundary can rely on it. Problems raise
:class:`unmesh.errors.InputError` with a message that names the argument, what was
expected and what came, and the first offending index.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from unmesh.errors import InputError

__all__ = [
    "as_array",
    "as_indices",
    "as_points",
    "first_index",
    "positive_scalar",
    "scalar",
]


def _shape_text(shape: Sequence[int | None]) -> str:
    names = iter("NMKLPQ")
    return "(" + ", ".join(next(names) if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def first_index(mask: np.ndarray) -> int | tuple[int, ...]:
    """Index of the first True entry of ``mask`` (row index for 2-D masks).

    Example
    -------
    >>> first_index(np.array([False, True, True]))
    1
    """
    if mask.ndim == 1:
        return int(np.flatnonzero(mask)[0])
    flat = mask.reshape(mask.shape[0], -1).any(axis=1)
    return int(np.flatnonzero(flat)[0])


def as_array(
    value: Any,
    name: str,
    shape: Sequence[int | None],
    dtype: type = np.float64,
    finite: bool = True,
    length: int | None = None,
) -> np.ndarray:
    """Convert ``value`` to a C-contiguous array of ``dtype`` and check its shape.

    Parameters
    ----------
    value : array_like
        Input.
    name : str
        Argument name used in error messages.
    shape : sequence of int or None
        Expected shape; ``None`` matches any size.
    dtype : numpy dtype
        Result dtype (float64 or int64 in unmesh).
    finite : bool
        Reject NaN and infinity (floating dtypes only).
    length : int, optional
        Required size of the first axis.

    Returns
    -------
    numpy.ndarray
        C-contiguous array of the requested dtype.

    Example
    -------
    >>> as_array([[0, 0, 1]], "points", (None, 3)).dtype
    dtype('float64')
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise InputError(f"{name}: expected an array of shape {_shape_text(shape)}, got {type(value).__name__} ({exc})") from None
    if arr.dtype == object:
        raise InputError(f"{name}: expected a numeric array of shape {_shape_text(shape)}, got a ragged or object array")
    if arr.ndim == 1 and len(shape) == 2 and shape[1] is not None and arr.size == 0:
        arr = arr.reshape(0, shape[1])
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True)):
        raise InputError(f"{name}: expected shape {_shape_text(shape)}, got {arr.shape}")
    if length is not None and arr.shape[0] != length:
        raise InputError(f"{name}: expected {length} rows to match the other arrays, got {arr.shape[0]}")
    if np.issubdtype(np.dtype(dtype), np.integer):
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            if not np.issubdtype(arr.dtype, np.number) or not np.all(np.mod(arr, 1) == 0):
                raise InputError(f"{name}: expected integer values, got dtype {arr.dtype}")
    elif arr.size and not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise InputError(f"{name}: expected numbers, got dtype {arr.dtype}")
    out = np.ascontiguousarray(arr, dtype=dtype)
    if finite and out.size and np.issubdtype(out.dtype, np.floating):
        bad = ~np.isfinite(out)
        if bad.any():
            raise InputError(f"{name}: expected finite values, got NaN or infinity at index {first_index(bad)}")
    return out


def as_points(value: Any, name: str = "points", dim: int = 3, length: int | None = None) -> np.ndarray:
    """Convert to an (N, dim) float64 C-contiguous array of finite coordinates.

    A single point of shape (dim,) is accepted and returned as (1, dim).

    Example
    -------
    >>> as_points([0.0, 1.0, 2.0]).shape
    (1, 3)
    """
    if not isinstance(value, np.ndarray):
        try:
            value = np.asarray(value)
        except (TypeError, ValueError):
            return as_array(value, name, (None, dim), np.float64, finite=True, length=length)
    if value.ndim == 1 and value.shape[0] == dim:
        value = value[None, :]
    return as_array(value, name, (None, dim), np.float64, finite=True, length=length)


def as_indices(
    value: Any, name: str, shape: Sequence[int | None], upper: int | None = None, length: int | None = None
) -> np.ndarray:
    """Convert to a C-contiguous int64 index array; check ``0 <= index < upper``.

    Example
    -------
    >>> as_indices([[0, 1, 2]], "faces", (None, 3), upper=3).dtype
    dtype('int64')
    """
    arr = as_array(value, name, shape, np.int64, finite=False, length=length)
    if arr.size and upper is not None:
        bad = (arr < 0) | (arr >= upper)
        if bad.any():
            i = first_index(bad)
            row = arr[i]
            raise InputError(f"{name}: expected indices in [0, {upper}), got {row.tolist() if hasattr(row, 'tolist') else row} at index {i}")
    return arr


def scalar(value: Any, name: str, minimum: float | None = None, maximum: float | None = None) -> float:
    """Convert to a finite float within optional inclusive bounds.

    Example
    -------
    >>> scalar("0.5", "alpha", 0, 1)
    0.5
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise InputError(f"{name}: expected a finite number, got {v}")
    if minimum is not None and v < minimum:
        raise InputError(f"{name}: expected a number >= {minimum}, got {v}")
    if maximum is not None and v > maximum:
        raise InputError(f"{name}: expected a number <= {maximum}, got {v}")
    return v


def positive_scalar(value: Any, name: str) -> float:
    """Convert to a finite float > 0.

    Example
    -------
    >>> positive_scalar(2, "radius")
    2.0
    """
    v = scalar(value, name)
    if v <= 0:
        raise InputError(f"{name}: expected a positive number, got {v}")
    return v
