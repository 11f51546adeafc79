"""The one thread policy of unmesh's numba kernels (bottom layer: every capability may use it).

:func:`serial_if_small` runs a block on one thread when its work is below a fixed size
(:data:`SERIAL_BELOW` by default) and leaves the thread count alone otherwise: spatial
queries, the renderers and SPH use it, since waking numba's thread pool costs more than it
saves on small inputs (milliseconds on a loaded machine against microseconds of work).

:class:`threads_for` runs a block of numba kernels on one thread or on all of numba's
threads. Small work always runs on one thread; above ``minimum`` work items the block is
timed both ways now and then, per kernel name and size class, and the faster choice is
kept, so the choice follows the machine's load: on 2 idle cores two threads nearly halve a
shell force pass of 7 600 fibers (1.9 -> 1.0 ms), while on 2 cores shared with other busy
processes two threads can be several times slower (a balloon step of 10 166 fibers: 3.3 ms
on one thread, 16 ms on two). Kernels run this way must give the same result on any
number of threads.

:class:`serial_region` runs everything inside it on one thread (parallel regions on small
arrays cost more in synchronisation than they save) but records the thread count in
effect outside it, which a :class:`threads_for` inside may still use. A count of one set
by the user (``numba.set_num_threads(1)``) before the region is respected: the region
records one.

:class:`background_work` marks work of this process running in a background thread (FEM's
background refactorisation): while it runs, :class:`threads_for` leaves it a core (on two
cores, one thread without timing).

Spinning workers: ``import unmesh`` sets ``GOMP_SPINCOUNT=30000`` unless the user set it
(numba's OpenMP layer, libgomp, spins 300,000 rounds by default after each parallel region). The figures behind both choices are in
``docs/performance.md``.

Example
-------
>>> import numba
>>> with serial_region():
...     with threads_for(10, key="doc"):     # below the minimum: one thread
...         numba.get_num_threads()
1
"""

from __future__ import annotations

import math
import threading
import time

import numba
from numba.np.ufunc import parallel as _parallel

__all__ = ["PARALLEL_MIN", "SERIAL_BELOW", "available_threads", "background_work", "serial_if_small", "serial_region",
           "threads_for"]

#: Default smallest work (items) that may run on all threads (a shell force pass: fibers).
PARALLEL_MIN = 4000

#: Default work (items: points + queries, primitives) below which :func:`serial_if_small` runs on one thread.
SERIAL_BELOW = 20000


class _Tuner:
    """Chooses one thread or all threads for a kernel by timing both now and then.

    ``period``: calls from one probe round (``PROBE`` calls per mode) to the next.
    """

    PROBE = 3       # calls per mode in a probe round
    PERIOD = 250    # calls from one probe round to the next

    def __init__(self, period: int | None = None) -> None:
        self.calls = 0
        self.best = {True: math.inf, False: math.inf}
        self.serial = False
        self.period = self.PERIOD if period is None else max(int(period), 2 * self.PROBE + 1)

    def choose_serial(self) -> bool:
        c = self.calls % self.period
        return c % 2 == 0 if c < 2 * self.PROBE else self.serial

    def record(self, serial: bool, seconds: float) -> None:
        c = self.calls % self.period
        if c < 2 * self.PROBE:
            if c == 0:
                self.best = {True: math.inf, False: math.inf}
            self.best[serial] = min(self.best[serial], seconds)
            if c == 2 * self.PROBE - 1:
                self.serial = self.best[True] <= self.best[False]
        self.calls += 1


_TUNERS: dict[tuple[str, int], _Tuner] = {}

#: Per Python thread (numba's thread count is per thread too): ``outer``, the count in effect
#: outside the outermost :class:`serial_region`, or absent outside any.
_STATE = threading.local()


def _num_threads() -> int:
    """``numba.get_num_threads()``; once numba's threads run, without its start-up lock (a
    multiprocessing lock: a few microseconds per call, three calls per time step)."""
    get = getattr(_parallel, "_get_num_threads", None)
    if getattr(_parallel, "_is_initialized", False) and get is not None:
        return int(get())
    return numba.get_num_threads()


def _set_num_threads(n: int) -> None:
    """``numba.set_num_threads(n)`` for an ``n`` already valid (1, or a value :func:`_num_threads` gave)."""
    set_ = getattr(_parallel, "_set_num_threads", None)
    if getattr(_parallel, "_is_initialized", False) and set_ is not None:
        set_(int(n))
        return
    numba.set_num_threads(n)


class _Background:
    """Count of background threads of this process at work (:class:`background_work`)."""

    lock = threading.Lock()
    busy = 0


class background_work:
    """Mark the block, run in a background thread, as holding a core (``with background_work(): ...``).

    Example
    -------
    >>> with background_work():
    ...     with threads_for(10**9, key="doc") as tf:
    ...         tf.threads <= max(1, available_threads() - 1)
    True
    """

    def __enter__(self) -> None:
        with _Background.lock:
            _Background.busy += 1

    def __exit__(self, *exc: object) -> None:
        with _Background.lock:
            _Background.busy -= 1


def available_threads() -> int:
    """numba threads a :class:`threads_for` of this thread may use: the count outside serial regions.

    Example
    -------
    >>> with serial_region():
    ...     available_threads() >= numba.get_num_threads()
    True
    """
    outer = getattr(_STATE, "outer", None)
    return _num_threads() if outer is None else outer


class serial_region:
    """Run numba kernels on one thread inside the block (``enabled``), keeping the outer count for :class:`threads_for`.

    Parameters
    ----------
    enabled : bool
        False leaves the thread count alone (e.g. a problem large enough for all threads).

    Example
    -------
    >>> with serial_region():
    ...     numba.get_num_threads()
    1
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = bool(enabled)

    def __enter__(self) -> None:
        if not self.enabled:
            return
        self.before = _num_threads()
        self.outer = getattr(_STATE, "outer", None)
        if self.outer is None:                  # the outermost region records the user's count
            _STATE.outer = self.before
        if self.before != 1:
            _set_num_threads(1)

    def __exit__(self, *exc: object) -> None:
        if not self.enabled:
            return
        _set_num_threads(self.before)
        _STATE.outer = self.outer


class threads_for:
    """Run numba kernels on one thread or on all (``with threads_for(n, key=...): ...``).

    Below ``minimum`` work items always on one thread; above it, the block is timed and the
    faster choice kept, per ``key`` and size class (probed again every ``period`` calls, so
    the choice follows the machine's load). "All" is the count in effect outside any
    :class:`serial_region` (:func:`available_threads`) less one per :class:`background_work`
    running (its timings are not taken then). Kernels run this way must give the
    same result on any number of threads. ``with threads_for(...) as tf`` gives the choice
    (``tf.serial``), e.g. to run a serial kernel instead of a parallel one.

    Parameters
    ----------
    items : int
        Size of the work (fibers, surfels, elements, nodes).
    minimum : int
        Smallest size that may run on all of numba's threads (default :data:`PARALLEL_MIN`).
    key : str
        Name of the kernel (each has its own timings).
    period : int, optional
        Calls from one probe round to the next (default :attr:`_Tuner.PERIOD`, 250; a kernel
        called a few times per time step of a fraction of a second wants fewer).

    Example
    -------
    >>> with threads_for(10):
    ...     pass
    """

    def __init__(self, items: int, minimum: int | None = None, key: str = "forces", period: int | None = None) -> None:
        self.previous = _num_threads()
        self.threads = max(1, available_threads() - _Background.busy)  # leave background work its cores
        self.serial = items < (PARALLEL_MIN if minimum is None else minimum)
        self.tuner = None
        if not self.serial and self.threads > 1:
            tuner = _TUNERS.get(tkey := (key, int(items).bit_length()))
            if tuner is None:
                tuner = _TUNERS[tkey] = _Tuner(period)
            self.tuner = tuner
            self.serial = tuner.choose_serial()
        self.serial = self.serial or self.threads == 1
        self.want = 1 if self.serial else self.threads

    def __enter__(self) -> threads_for:
        if self.want != self.previous:
            _set_num_threads(self.want)
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        elapsed = time.perf_counter() - self.start
        if self.want != self.previous:
            _set_num_threads(self.previous)
        if self.tuner is not None and exc[0] is None:
            self.tuner.record(self.serial, elapsed)


def serial_if_small(work: int, below: int | None = None) -> serial_region:
    """Run the enclosed numba kernels on one thread when ``work < below`` (a :class:`serial_region`).

    Parameters
    ----------
    work : int
        Size of the work (points + queries, primitives, particles).
    below : int, optional
        Smallest work left on all threads (default :data:`SERIAL_BELOW`).

    Example
    -------
    >>> with serial_if_small(10):
    ...     numba.get_num_threads()
    1
    """
    return serial_region(work < (SERIAL_BELOW if below is None else below))
