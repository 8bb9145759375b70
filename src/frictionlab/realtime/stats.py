"""Timing statistics of the real-time loop: histograms, stalls and host steal time.

The loop measures every tick (wake-up jitter, compute time) into fixed-size
histograms with 1 microsecond bins, so memory stays bounded however long
the run, adding a sample costs an array increment, and percentiles are exact
to 1 microsecond up to the histogram's range (values beyond it are counted in
the last bin; the exact maximum is kept separately).

A *stall* is a wake-up more than one sampling period late (ticks were
missed).  Each stall is recorded with the host's *steal time* over the same
interval (``/proc/stat``, the time the hypervisor ran something else while
this virtual machine wanted the CPU), which accounts for the host's own
pauses; a stall that the steal time does not cover is the loop's (or the
guest's) own.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["Histogram", "StallLog", "read_steal_ns"]

_CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class Histogram:
    """Counts of non-negative integer nanosecond values in 1 us bins.

    Parameters
    ----------
    max_us : int
        Range of the bins; larger values land in the last bin.
    """

    def __init__(self, max_us: int = 20_000):
        self.bins = np.zeros(max_us + 1, dtype=np.int64)
        self.max_us = max_us
        self.count = 0
        self.total_ns = 0
        self.max_ns = 0

    def add(self, ns: int) -> None:
        if ns < 0:
            ns = 0
        i = ns // 1000
        self.bins[i if i < self.max_us else self.max_us] += 1
        self.count += 1
        self.total_ns += ns
        if ns > self.max_ns:
            self.max_ns = ns

    def percentile_us(self, p: float) -> float | None:
        """The p-th percentile in microseconds (upper edge of its bin), or None."""
        if self.count == 0:
            return None
        cum = np.cumsum(self.bins)
        rank = max(1.0, np.ceil(p / 100.0 * cum[-1]))
        i = int(np.searchsorted(cum, rank))
        # the upper edge of the bin, but never more than the exact maximum
        return float(min(i + 1, max(self.max_ns / 1000.0, i)))

    def summary_us(self) -> dict:
        """p50, p99, p999, max and mean in microseconds."""
        return {
            "p50": self.percentile_us(50),
            "p99": self.percentile_us(99),
            "p999": self.percentile_us(99.9),
            "max": self.max_ns / 1000.0 if self.count else None,
            "mean": self.total_ns / self.count / 1000.0 if self.count else None,
        }


def read_steal_ns() -> int | None:
    """Cumulative steal time of all CPUs (ns) from ``/proc/stat``, or None."""
    try:
        with open("/proc/stat", "rb") as fh:
            fields = fh.readline().split()
    except OSError:
        return None
    if len(fields) < 9 or fields[0] != b"cpu":
        return None
    return int(fields[8]) * 1_000_000_000 // _CLK_TCK


class StallLog:
    """Stalls (late wake-ups of more than a period) with the host steal time.

    ``sample_steal()`` is called by the loop every 100 ms outside the tick;
    a stall's steal figure is the steal accumulated since that sample,
    divided by the number of CPUs (steal is summed over all of them).  The
    kernel counts steal in clock ticks (USER_HZ, usually 10 ms), so the figure is coarse.
    """

    def __init__(self, keep: int = 200):
        self.keep = keep
        self.stalls: list[dict] = []
        self.count = 0
        self.max_ms = 0.0
        self._ncpu = os.cpu_count() or 1
        self._steal = read_steal_ns()

    def sample_steal(self) -> None:
        self._steal = read_steal_ns()

    def add(self, tick: int, t_s: float, late_ns: int, missed: int) -> None:
        now = read_steal_ns()
        steal_ms = None
        if now is not None and self._steal is not None:
            steal_ms = (now - self._steal) / self._ncpu / 1e6
        self._steal = now
        ms = late_ns / 1e6
        self.count += 1
        self.max_ms = max(self.max_ms, ms)
        if len(self.stalls) < self.keep:
            self.stalls.append({"tick": tick, "t": round(t_s, 4), "late_ms": round(ms, 3),
                                "missed": missed,
                                "host_steal_ms": None if steal_ms is None else round(steal_ms, 3)})

    def unaccounted(self, threshold_ms: float = 50.0) -> list[dict]:
        """Stalls longer than ``threshold_ms`` not covered by host steal time."""
        out = []
        for s in self.stalls:
            if s["late_ms"] > threshold_ms:
                steal = s["host_steal_ms"] or 0.0
                if s["late_ms"] - steal > threshold_ms:
                    out.append(s)
        return out
