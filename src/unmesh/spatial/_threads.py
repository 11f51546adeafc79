"""Thread-count control for small inputs."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numba

__all__ = ["SERIAL_BELOW", "serial_if_small"]

#: Inputs with less work (points + queries) run numba kernels on one thread.
SERIAL_BELOW = 20000


@contextmanager
def serial_if_small(work: int) -> Iterator[None]:
    """Run numba-parallel kernels on one thread when ``work`` is below
    :data:`SERIAL_BELOW`: waking the thread pool costs more than it saves there
    (milliseconds on a loaded machine vs. microseconds of work).

    Example
    -------
    >>> with serial_if_small(10):
    ...     numba.get_num_threads()
    1
    """
    if work >= SERIAL_BELOW or numba.get_num_threads() == 1:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(old)
