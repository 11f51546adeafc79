"""Validated access to one TOML table of a scene file.

Every accessor records the key as read, converts and checks the value, and raises
:class:`unmesh.errors.SceneError` naming the file and the dotted key::

    dam_break.toml: key 'materials.water.density': expected a positive number, got -1

:meth:`Table.finish` reports keys that were never read (typos), with a suggestion.
"""

from __future__ import annotations

import contextlib
import difflib
import math
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import FormatError, InputError, SceneError
from unmesh.scene.shapes import shape_from_table

__all__ = ["INFINITY_WORDS", "REQUIRED", "Table", "parse_infinite"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Sentinel default meaning "this key must be present".
REQUIRED: Any = _Required()

#: Strings a number accepting infinity reads as +inf ("off" = no limit).
INFINITY_WORDS = ("inf", "+inf", "infinity", "off", "none")


def parse_infinite(value: Any) -> Any:
    """The shared reading of "no limit" values: ``"inf"``, ``"off"``, ... -> ``math.inf``.

    ``"-inf"`` / ``"-infinity"`` give ``-math.inf``; any other value is returned
    unchanged (TOML's own ``inf`` and ``-inf`` are already floats).

    Example
    -------
    >>> parse_infinite("off"), parse_infinite("-inf"), parse_infinite(2.5)
    (inf, -inf, 2.5)
    """
    if isinstance(value, str):
        word = value.strip().lower()
        if word in INFINITY_WORDS:
            return math.inf
        if word in ("-inf", "-infinity"):
            return -math.inf
    return value


def _describe(value: Any) -> str:
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return f"an array {value!r}" if len(repr(value)) < 60 else "an array"
    if isinstance(value, str):
        return repr(value)
    return repr(value)


class Table:
    """One table of a scene file, with typed, validated accessors.

    Parameters
    ----------
    data : dict
        The parsed TOML table.
    file : pathlib.Path
        The scene file (for messages and for resolving relative paths).
    prefix : str
        Dotted path of this table inside the file ("" for the root).

    Example
    -------
    >>> t = Table({"dt": 0.001}, Path("scene.toml"))
    >>> t.number("dt", positive=True)
    0.001
    >>> t.finish()
    """

    def __init__(self, data: dict[str, Any], file: Path, prefix: str = "") -> None:
        self._data = data
        self.file = Path(file)
        self.prefix = prefix
        self._used: set[str] = set()
        self._queried: set[str] = set()
        self._children: list[Table] = []

    # -- basics ---------------------------------------------------------------------
    def dotted(self, key: str) -> str:
        """The full dotted name of ``key`` in this table."""
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str | None, message: str) -> SceneError:
        """A SceneError naming the file and (if given) the key."""
        where = f"key '{self.dotted(key)}': " if key is not None else (f"[{self.prefix}]: " if self.prefix else "")
        return SceneError(f"{self.file.name}: {where}{message}")

    def __contains__(self, key: str) -> bool:
        return key in self._data

    def keys(self) -> list[str]:
        """Keys present in this table."""
        return list(self._data)

    def _get(self, key: str, default: Any) -> Any:
        self._queried.add(key)
        if key in self._data:
            self._used.add(key)
            return self._data[key]
        if default is REQUIRED:
            found = difflib.get_close_matches(key, [k for k in self._data if k not in self._queried], n=1, cutoff=0.7)
            extra = f"; found '{self.dotted(found[0])}' instead (misspelt?)" if found else ""
            raise self.error(key, f"missing (required){extra}")
        return default

    def raw(self, key: str, default: Any = REQUIRED) -> Any:
        """The value as parsed, unchecked."""
        return self._get(key, default)

    # -- scalars --------------------------------------------------------------------
    def number(self, key: str, default: Any = REQUIRED, *, positive: bool = False, nonnegative: bool = False,
               minimum: float | None = None, maximum: float | None = None, infinite: bool = False) -> float:
        """A finite float; integers are accepted.

        With ``infinite=True`` the value may also be ``inf`` / ``-inf`` (TOML) or one of
        the words of :func:`parse_infinite` (``"inf"``, ``"off"``, ...): "no limit".
        """
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value
        if infinite:
            value = parse_infinite(value)
        if isinstance(value, bool) or not isinstance(value, int | float):
            words = " or 'inf' / 'off'" if infinite else ""
            raise self.error(key, f"expected a number{words}, got {_describe(value)}")
        try:
            v = float(value)
        except OverflowError:  # integers beyond the float range
            raise self.error(key, f"expected a number of magnitude below 1e308, got {value}") from None
        if math.isnan(v) or (not infinite and not np.isfinite(v)):
            raise self.error(key, f"expected a finite number, got {v}")
        if positive and v <= 0:
            raise self.error(key, f"expected a positive number, got {value}")
        if nonnegative and v < 0:
            raise self.error(key, f"expected a number >= 0, got {value}")
        if minimum is not None and v < minimum:
            raise self.error(key, f"expected a number >= {minimum}, got {value}")
        if maximum is not None and v > maximum:
            raise self.error(key, f"expected a number <= {maximum}, got {value}")
        return v

    def integer(self, key: str, default: Any = REQUIRED, *, minimum: int | None = None,
                maximum: int | None = None) -> int:
        """An integer."""
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {_describe(value)}")
        if minimum is not None and value < minimum:
            raise self.error(key, f"expected an integer >= {minimum}, got {value}")
        if maximum is not None and value > maximum:
            raise self.error(key, f"expected an integer <= {maximum}, got {value}")
        return int(value)

    def string(self, key: str, default: Any = REQUIRED, *, choices: Sequence[str] | None = None) -> str:
        """A string, optionally one of ``choices``."""
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {_describe(value)}")
        if choices is not None and value not in choices:
            hint = difflib.get_close_matches(value, list(choices), n=1)
            extra = f" (did you mean '{hint[0]}'?)" if hint else ""
            raise self.error(key, f"expected one of {', '.join(repr(c) for c in choices)}, got {value!r}{extra}")
        return value

    def boolean(self, key: str, default: Any = REQUIRED) -> bool:
        """true or false."""
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {_describe(value)}")
        return value

    # -- arrays ---------------------------------------------------------------------
    def array_of_numbers(self, key: str, default: Any = REQUIRED, *, shape: Sequence[int | None] | None = None,
                         positive: bool = False) -> np.ndarray:
        """A (nested) array of numbers as float64, optionally of a given shape (None = any)."""
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value if value is None else np.asarray(value, dtype=np.float64)
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.error(key, f"expected an array of numbers, got {_describe(value)}") from None
        if shape is not None and (arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True))):
            want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
            raise self.error(key, f"expected an array of shape {want}, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self.error(key, "expected finite numbers")
        if positive and np.any(arr <= 0):
            raise self.error(key, f"expected positive numbers, got {value!r}")
        return arr

    def vector(self, key: str, n: int, default: Any = REQUIRED, *, positive: bool = False) -> np.ndarray:
        """An array of exactly ``n`` numbers."""
        value = self._get(key, default)
        if value is None:
            return None  # type: ignore[return-value]
        if key not in self._data:
            return np.asarray(value, dtype=np.float64)
        if not isinstance(value, list) or len(value) != n or any(isinstance(x, bool) or not isinstance(x, int | float) for x in value):
            raise self.error(key, f"expected an array of {n} numbers, got {_describe(value)}")
        arr = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            raise self.error(key, "expected finite numbers")
        if positive and np.any(arr <= 0):
            raise self.error(key, f"expected {n} positive numbers, got {value!r}")
        return arr

    def path(self, key: str, default: Any = REQUIRED, *, must_exist: bool = True) -> Path:
        """A file path, resolved relative to the scene file's directory."""
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value
        if not isinstance(value, str) or not value:
            raise self.error(key, f"expected a file path, got {_describe(value)}")
        p = Path(value).expanduser()
        if not p.is_absolute():
            p = (self.file.parent / p).resolve()
        if must_exist and not p.exists():
            raise self.error(key, f"file not found: {p}")
        return p

    # -- sub-tables -----------------------------------------------------------------
    def table(self, key: str, required: bool = True) -> Table | None:
        """A sub-table ``[prefix.key]``; None when absent and not required."""
        value = self._get(key, REQUIRED if required else None)
        if value is None:
            return None
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {_describe(value)}")
        child = Table(value, self.file, self.dotted(key))
        self._children.append(child)
        return child

    def tables(self, key: str, required: bool = False) -> dict[str, Table]:
        """Named sub-tables ``[key.NAME]`` as ``{NAME: Table}`` (empty when absent)."""
        parent = self.table(key, required=required)
        if parent is None:
            return {}
        out: dict[str, Table] = {}
        for name in parent.keys():
            out[name] = parent.table(name)  # type: ignore[assignment]
        return out

    def array(self, key: str, required: bool = False) -> list[Table]:
        """An array of tables ``[[key]]`` (empty when absent)."""
        value = self._get(key, REQUIRED if required else [])
        if isinstance(value, dict):
            value = [value]
        if not isinstance(value, list) or any(not isinstance(v, dict) for v in value):
            raise self.error(key, f"expected an array of tables ([[{self.dotted(key)}]]), got {_describe(value)}")
        children = [Table(v, self.file, f"{self.dotted(key)}[{i}]") for i, v in enumerate(value)]
        self._children.extend(children)
        return children

    def shape(self, key: str, default: Any = REQUIRED) -> Any:
        """A shape spec (inline table) as an ``unmesh.shapes`` shape; see :mod:`unmesh.scene.shapes`."""
        value = self._get(key, default)
        if value is None or (value is default and key not in self._data):
            return value
        if not isinstance(value, dict):
            raise self.error(key, f"expected a shape table like {{ type = \"box\", size = [1, 1, 1] }}, got {_describe(value)}")
        child = Table(value, self.file, self.dotted(key))
        self._children.append(child)
        return shape_from_table(child)

    # -- completion -----------------------------------------------------------------
    def finish(self) -> None:
        """Raise SceneError for keys never read, here and in every sub-table read from here."""
        unknown = [k for k in self._data if k not in self._used]
        if unknown:
            key = unknown[0]
            hint = difflib.get_close_matches(key, sorted(self._queried), n=1)
            extra = f" (did you mean '{hint[0]}'?)" if hint else ""
            more = f" (and {len(unknown) - 1} more: {', '.join(unknown[1:])})" if len(unknown) > 1 else ""
            raise SceneError(f"{self.file.name}: unknown key '{self.dotted(key)}'{extra}{more}")
        for child in self._children:
            child.finish()

    # -- errors of the code a scene drives -------------------------------------------
    def wrap_input_error(self, key: str | None, exc: Exception) -> SceneError:
        """The SceneError naming the file and ``key`` for an error raised while building from ``key``.

        The one conversion every simulation uses (through :meth:`guard` and :meth:`call`).
        ``key=None`` names this table only.
        """
        return self.error(key, str(exc))

    @contextlib.contextmanager
    def guard(self, key: str | None = None) -> Iterator[None]:
        """Turn :class:`InputError` / :class:`FormatError` raised inside into a SceneError naming ``key``.

        Example
        -------
        >>> t = Table({"n": -1}, Path("s.toml"))
        >>> try:
        ...     with t.guard("n"):
        ...         raise InputError("n: expected a positive integer, got -1")
        ... except SceneError as exc:
        ...     print(exc)
        s.toml: key 'n': n: expected a positive integer, got -1
        """
        try:
            yield
        except (InputError, FormatError) as exc:
            raise self.wrap_input_error(key, exc) from None

    def call(self, key: str | None, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)`` inside :meth:`guard` (``key``)."""
        with self.guard(key):
            return fn(*args, **kwargs)

    def check_budget(self, key: str, nbytes: float, what: str) -> None:
        """SceneError naming ``key`` when ``nbytes`` exceed the memory budget (:mod:`unmesh.io.budget`)."""
        from unmesh.io.budget import budget_problem

        problem = budget_problem(nbytes, what)
        if problem is not None:
            raise self.error(key, problem)
