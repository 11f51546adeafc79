"""The haptic loop (thesis 5.4.2, Fig. 5.4): forces at 1 kHz, decoupled from painting.

The painting loop publishes the contact parameters of the handle points (penetration depth d,
direction N, handle velocity; :meth:`HapticLoop.publish`); a thread evaluates the penalty (5.6)
and friction (5.7) forces from them at :data:`RATE` Hz and low-passes the result over the last
1/60 s (a moving average of :data:`WINDOW` samples). :attr:`HapticLoop.force` is the published
force signal (a force-feedback device, or the studio, reads it). The loop measures its own rate
and jitter (standard deviation and maximum of the period error).

Example
-------
>>> f = lowpass_window(RATE)
>>> f
17
"""

from __future__ import annotations

import multiprocessing as mp
import threading
import time
from collections import deque
from typing import Any

import numpy as np

__all__ = ["RATE", "WINDOW", "HapticLoop", "HapticProcess", "haptic_force", "lowpass_window"]

RATE = 1000.0


def lowpass_window(rate: float) -> int:
    """Samples in 1/60 s at ``rate`` Hz (rounded up)."""
    return int(np.ceil(rate / 60.0))


WINDOW = lowpass_window(RATE)


def haptic_force(depth: np.ndarray, normal: np.ndarray, velocity: np.ndarray, k_penalty: float, eta: float,
                 extra: np.ndarray) -> np.ndarray:
    """``sum_h K_p d_h N_h - eta d_h v_t`` over handle points inside (d > 0), plus ``extra``
    (the reaction of the bristle springs on the handle), (3,)."""
    f = np.array(extra, dtype=np.float64)
    for d, n in zip(depth, normal, strict=True):
        if d > 0:
            vt = velocity - np.dot(velocity, n) * n
            f += k_penalty * d * n - eta * d * vt
    return f


class HapticLoop:
    """A 1 kHz thread evaluating :func:`haptic_force` from the latest published contact."""

    def __init__(self, k_penalty: float, rate: float = RATE) -> None:
        self.k_penalty = float(k_penalty)
        self.rate = float(rate)
        self._lock = threading.Lock()
        self._contact = (np.zeros(0), np.zeros((0, 3)), np.zeros(3), 0.0, np.zeros(3))
        self._window: deque[np.ndarray] = deque(maxlen=lowpass_window(rate))
        self.force = np.zeros(3)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.periods: deque[float] = deque(maxlen=5000)

    def publish(self, depth: np.ndarray, normal: np.ndarray, velocity: np.ndarray, eta: float, extra: np.ndarray) -> None:
        """New contact parameters from the painting loop (cheap; never blocks on the loop)."""
        with self._lock:
            self._contact = (np.array(depth, float), np.array(normal, float), np.array(velocity, float), float(eta),
                             np.array(extra, float))

    def step(self) -> np.ndarray:
        """One haptic update: evaluate, push into the low-pass window, return the filtered force."""
        with self._lock:
            d, n, v, eta, extra = self._contact
        self._window.append(haptic_force(d, n, v, self.k_penalty, eta, extra))
        self.force = np.mean(np.asarray(self._window), axis=0)
        return self.force

    def start(self) -> HapticLoop:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="unmesh-haptic", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout=1.0)
            self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None

    def _run(self) -> None:
        period = 1.0 / self.rate
        nxt = time.perf_counter()
        last = nxt
        while not self._stop.is_set():
            self.step()
            nxt += period
            now = time.perf_counter()
            if nxt > now:  # sleep only (no spinning: the machine is shared); Linux wakes within ~0.1 ms
                time.sleep(nxt - now)
            now = time.perf_counter()
            self.periods.append(now - last)
            last = now
            if now - nxt > 0.05:  # fell far behind (machine busy): do not try to catch up
                nxt = now

    def stats(self) -> dict[str, float]:
        """Measured rate (Hz), jitter (std of the period, s) and the largest period error (s)."""
        p = np.asarray(self.periods)
        if len(p) < 2:
            return {"rate": 0.0, "jitter": 0.0, "max_error": 0.0, "samples": float(len(p))}
        return {"rate": float(1.0 / p.mean()), "jitter": float(p.std()),
                "max_error": float(np.abs(p - 1.0 / self.rate).max()), "samples": float(len(p))}


#: Handle points a :class:`HapticProcess` can take, and its shared-memory layout:
#: ``[count, eta, v(3), extra(3), depth(MAX), normal(3 MAX)]``.
_MAXH = 16
_NC = 8 + 4 * _MAXH
_NPER = 5000


def _process_loop(contact: Any, force: Any, periods: Any, count: Any, stop: Any, rate: float, k_penalty: float) -> None:
    """The haptic loop of :class:`HapticProcess` (runs in its own process: no interpreter lock
    shared with the painting loop)."""
    period = 1.0 / rate
    window: deque[np.ndarray] = deque(maxlen=lowpass_window(rate))
    nxt = time.perf_counter()
    last = nxt
    k = 0
    while not stop.is_set():
        with contact.get_lock():
            c = np.array(contact[:])
        n = int(c[0])
        depth = c[8:8 + n]
        normal = c[8 + _MAXH:8 + _MAXH + 3 * n].reshape(n, 3)
        window.append(haptic_force(depth, normal, c[2:5], k_penalty, c[1], c[5:8]))
        f = np.mean(np.asarray(window), axis=0)
        with force.get_lock():
            force[:] = f
        nxt += period
        now = time.perf_counter()
        if nxt > now:
            time.sleep(nxt - now)
        now = time.perf_counter()
        periods[k % _NPER] = now - last
        k += 1
        count.value = k
        last = now
        if now - nxt > 0.05:
            nxt = now


class HapticProcess(HapticLoop):
    """:class:`HapticLoop` in a separate process: the force is evaluated at 1 kHz without
    waiting for the painting loop's interpreter lock (lower jitter while painting). Same
    interface; :attr:`force` reads the shared force."""

    def __init__(self, k_penalty: float, rate: float = RATE) -> None:
        super().__init__(k_penalty, rate)
        ctx = mp.get_context("spawn")
        self._ctx = ctx
        self._shared_contact = ctx.Array("d", _NC)
        self._shared_force = ctx.Array("d", 3)
        self._shared_periods = ctx.Array("d", _NPER, lock=False)
        self._shared_count = ctx.Value("q", 0, lock=False)
        self._pstop = ctx.Event()
        self._proc: Any = None

    def publish(self, depth: np.ndarray, normal: np.ndarray, velocity: np.ndarray, eta: float, extra: np.ndarray) -> None:
        super().publish(depth, normal, velocity, eta, extra)
        d = np.asarray(depth, float)[:_MAXH]
        n = len(d)
        buf = np.zeros(_NC)
        buf[0], buf[1] = n, eta
        buf[2:5] = velocity
        buf[5:8] = extra
        buf[8:8 + n] = d
        buf[8 + _MAXH:8 + _MAXH + 3 * n] = np.asarray(normal, float)[:n].ravel()
        with self._shared_contact.get_lock():
            self._shared_contact[:] = buf

    @property
    def force(self) -> np.ndarray:  # type: ignore[override]
        if self._proc is None:
            return self._force_local
        with self._shared_force.get_lock():
            return np.array(self._shared_force[:])

    @force.setter
    def force(self, value: np.ndarray) -> None:
        self._force_local = value

    def start(self) -> HapticProcess:
        if self._proc is None:
            self._pstop.clear()
            self._proc = self._ctx.Process(target=_process_loop, name="unmesh-haptic", daemon=True,
                                           args=(self._shared_contact, self._shared_force, self._shared_periods,
                                                 self._shared_count, self._pstop, self.rate, self.k_penalty))
            self._proc.start()
        return self

    def stop(self) -> None:
        if self._proc is not None:
            self._pstop.set()
            self._proc.join(timeout=2.0)
            if self._proc.is_alive():
                self._proc.terminate()
            self._proc = None

    @property
    def running(self) -> bool:
        return self._proc is not None

    def stats(self) -> dict[str, float]:
        k = int(self._shared_count.value)
        p = np.array(self._shared_periods[:min(k, _NPER)])
        if len(p) < 2:
            return {"rate": 0.0, "jitter": 0.0, "max_error": 0.0, "samples": float(len(p))}
        p = p[1:]  # the first period includes the start
        return {"rate": float(1.0 / p.mean()), "jitter": float(p.std()),
                "max_error": float(np.abs(p - 1.0 / self.rate).max()), "samples": float(len(p))}
