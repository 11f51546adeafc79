"""Deprecated: the thread policy is :mod:`unmesh._threads` (bottom layer since issue 16).

``unmesh.sim.threads`` warns on import and gives :mod:`unmesh._threads`'s names
(``threads_for``, ``serial_region``, ``background_work``, ``available_threads``,
``PARALLEL_MIN``, ...); change settings such as ``PARALLEL_MIN`` on :mod:`unmesh._threads`.

Example
-------
>>> import unmesh._threads
>>> threads_for is unmesh._threads.threads_for
True
"""

from __future__ import annotations

import warnings
from typing import Any

from unmesh import _threads
from unmesh._threads import (
    PARALLEL_MIN,
    available_threads,
    background_work,
    serial_region,
    threads_for,
)

__all__ = ["PARALLEL_MIN", "available_threads", "background_work", "serial_region", "threads_for"]

warnings.warn("unmesh.sim.threads is deprecated: the thread policy is unmesh._threads "
              "(threads_for, serial_region, serial_if_small, background_work)", DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> Any:
    """Every other name of :mod:`unmesh._threads` (``_TUNERS``, ``serial_if_small``, ...)."""
    return getattr(_threads, name)
