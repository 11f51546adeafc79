"""The memory budget: how much a file header or a scene may make unmesh allocate.

Sizes read from a file header (element counts, list lengths) or a scene file
(grid resolutions, cell counts) are checked against the file's length and against
this budget *before* anything is allocated, so a corrupt or hostile input fails
with a one-line error instead of a ``MemoryError`` minutes later.

The budget is read from the environment variable ``UNMESH_MEMORY_BUDGET``: a
number of bytes with an optional unit (``512M``, ``4GiB``, ``1.5G``, ``0`` = no
limit). The default is 4 GiB.

Example
-------
>>> parse_size("4GiB") == 4 * 2**30, parse_size("512M") == 512 * 2**20
(True, True)
>>> format_bytes(8 * 10**12)
'7.28 TiB'
"""

from __future__ import annotations

import os
import re

from unmesh.errors import InputError

__all__ = ["DEFAULT_BUDGET", "ENV_VAR", "budget_problem", "format_bytes", "memory_budget", "parse_size"]

#: Environment variable holding the budget.
ENV_VAR = "UNMESH_MEMORY_BUDGET"
#: Budget when the variable is unset: 4 GiB.
DEFAULT_BUDGET = 4 * 2**30

_SIZE = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*([kmgt]?)(i?b)?\s*$", re.IGNORECASE)
_UNITS = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


def parse_size(text: str) -> int:
    """Bytes in ``text`` (``"4GiB"``, ``"512M"``, ``"1e9"`` is not accepted: write ``1000000000``).

    Units are binary (``k`` = 1024); ``B``/``iB`` suffixes are optional.

    Raises
    ------
    InputError
        When the text is not a size.
    """
    m = _SIZE.match(str(text))
    if m is None:
        raise InputError(f"{ENV_VAR}: expected a size such as 4GiB, 512M or 1000000 (bytes), got {text!r}")
    return int(float(m.group(1)) * _UNITS[m.group(2).lower()])


def memory_budget() -> int:
    """The budget in bytes (0 = unlimited), from ``UNMESH_MEMORY_BUDGET`` or the 4 GiB default."""
    raw = os.environ.get(ENV_VAR, "").strip()
    return DEFAULT_BUDGET if not raw else parse_size(raw)


def format_bytes(n: float) -> str:
    """``n`` bytes in binary units with three significant digits (``'7.28 TiB'``)."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024.0 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} EiB"  # pragma: no cover - the loop returns


def budget_problem(nbytes: float, what: str) -> str | None:
    """A message when ``nbytes`` exceed the budget, else None.

    Example
    -------
    >>> budget_problem(100, "grid") is None
    True
    >>> budget_problem(2**50, "a 1000000 x 1000000 grid")  # doctest: +ELLIPSIS
    'a 1000000 x 1000000 grid would need about 1 PiB, more than the memory budget of 4 GiB (...)'
    """
    budget = memory_budget()
    if budget <= 0 or nbytes <= budget:
        return None
    return (f"{what} would need about {format_bytes(nbytes)}, more than the memory budget of "
            f"{format_bytes(budget)} (raise it with the environment variable {ENV_VAR}, e.g. {ENV_VAR}=16GiB)")
