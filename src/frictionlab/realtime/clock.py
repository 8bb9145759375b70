"""Clocks for the real-time loop: the monotonic clock and a fake one for tests.

A clock has two methods, both in integer nanoseconds:

* ``now_ns()`` - the current time;
* ``sleep_until(t_ns)`` - return at (or as soon as possible after) ``t_ns``;
* ``spin_until(t_ns)`` - the same by busy-waiting (for the last fraction of
  a millisecond before a deadline, see the loop's pre-warming).

The loop computes its deadlines as ``t0 + k * h_ns`` with integer k, so they
never drift, and it only ever sleeps *until* an absolute deadline.
:class:`MonotonicClock` does that with ``clock_nanosleep(CLOCK_MONOTONIC,
TIMER_ABSTIME)`` (through ctypes, which releases the GIL while sleeping) and
falls back to ``time.sleep`` of the remaining time where that call is not
available.

:class:`FakeClock` never sleeps: ``sleep_until`` jumps the time forward and
runs the callbacks scheduled up to then, so tests can drive the loop through
thousands of ticks, stalls and faults in milliseconds.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import heapq
import itertools
import time
from collections.abc import Callable

__all__ = ["FakeClock", "MonotonicClock"]

_CLOCK_MONOTONIC = 1
_TIMER_ABSTIME = 1
_EINTR = 4


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _libc_nanosleep():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        fn = libc.clock_nanosleep
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec),
                   ctypes.POINTER(_Timespec)]
    fn.restype = ctypes.c_int
    # check that CLOCK_MONOTONIC is time.monotonic_ns's clock (it is on Linux)
    if time.get_clock_info("monotonic").implementation != "clock_gettime(CLOCK_MONOTONIC)":
        return None
    return fn


class MonotonicClock:
    """The system's monotonic clock with absolute-deadline sleeping."""

    def __init__(self):
        self._nanosleep = _libc_nanosleep()
        self._ts = _Timespec()
        self.now_ns = time.monotonic_ns

    @property
    def absolute(self) -> bool:
        """Whether sleeps use ``clock_nanosleep(TIMER_ABSTIME)``."""
        return self._nanosleep is not None

    def sleep_until(self, t_ns: int) -> None:
        """Sleep until the monotonic time ``t_ns`` (no-op if it has passed)."""
        target = t_ns
        now = time.monotonic_ns
        if self._nanosleep is not None:
            ts = self._ts
            ts.tv_sec, ts.tv_nsec = divmod(target, 1_000_000_000)
            while now() < target and self._nanosleep(_CLOCK_MONOTONIC, _TIMER_ABSTIME,
                                                     ctypes.byref(ts), None) == _EINTR:
                pass
        else:
            while True:
                rest = target - now()
                if rest <= 0:
                    break
                time.sleep(rest / 1e9)

    @staticmethod
    def spin_until(t_ns: int) -> None:
        """Busy-wait until ``t_ns`` (holds the CPU and the GIL: keep it short)."""
        now = time.monotonic_ns
        while now() < t_ns:
            pass


class FakeClock:
    """A clock for tests: time advances only when the code under test sleeps.

    Parameters
    ----------
    start_ns : int
        Initial time.
    wake_latency : callable, optional
        ``wake_latency(deadline_ns) -> ns`` added to every wake-up (models
        scheduling jitter or a stall of the host).

    Attributes
    ----------
    sleeps : list of int
        Every deadline passed to :meth:`sleep_until`, in order.
    """

    def __init__(self, start_ns: int = 1_000_000_000,
                 wake_latency: Callable[[int], int] | None = None):
        self._now = int(start_ns)
        self._latency = wake_latency
        self._events: list[tuple[int, int, Callable[[], None]]] = []
        self._order = itertools.count()
        self.sleeps: list[int] = []

    def now_ns(self) -> int:
        return self._now

    def call_at(self, t_ns: int, fn: Callable[[], None]) -> None:
        """Run ``fn()`` when the clock passes ``t_ns`` (the clock reads ``t_ns`` then)."""
        heapq.heappush(self._events, (int(t_ns), next(self._order), fn))

    def advance(self, ns: int) -> None:
        """Let ``ns`` nanoseconds pass (e.g. computation), running due callbacks."""
        self._run_to(self._now + int(ns))

    def sleep_until(self, t_ns: int) -> None:
        self.sleeps.append(int(t_ns))
        target = max(self._now, int(t_ns))
        if self._latency is not None:
            target += int(self._latency(int(t_ns)))
        self._run_to(target)

    spin_until = sleep_until

    def _run_to(self, target: int) -> None:
        while self._events and self._events[0][0] <= target:
            t, _, fn = heapq.heappop(self._events)
            self._now = max(self._now, t)
            fn()
        self._now = max(self._now, target)
