"""Operating-system real-time settings for the calling thread.

* ``SCHED_FIFO`` at a given priority (needs CAP_SYS_NICE or an RLIMIT_RTPRIO
  allowance; where it is refused the caller carries on at normal priority);
* the thread's timer slack set to 1 ns (``prctl(PR_SET_TIMERSLACK)``), so
  absolute sleeps are not rounded up by the default 50 us slack;
* optionally pinning the thread to one CPU.  The loop thread and the
  emulated rig are pinned to the *same* CPU by default: a request and its
  reply then hand over on one CPU, whereas waking a process on an idle
  second CPU costs an inter-processor interrupt, which on the project's
  virtual machine took 0.1-3 ms (see ``docs/realtime.md``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading

__all__ = ["default_cpu", "normal_priority", "try_realtime_priority"]

_PR_SET_TIMERSLACK = 29


def default_cpu() -> int | None:
    """The CPU the real-time threads are pinned to by default: the last one allowed."""
    try:
        cpus = os.sched_getaffinity(0)
    except (AttributeError, OSError):
        return None
    return max(cpus) if cpus else None


def try_realtime_priority(priority: int, cpu: int | None = None) -> str | None:
    """Put the calling thread on SCHED_FIFO ``priority`` (and pin it to ``cpu``).

    Returns None on success, else a one-line explanation of what was not
    permitted (the thread keeps running, at normal priority).
    """
    notes = []
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_TIMERSLACK, 1, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    tid = threading.get_native_id()
    if cpu is not None:
        try:
            os.sched_setaffinity(tid, {cpu})
        except (OSError, ValueError, AttributeError) as exc:
            notes.append(f"cannot pin to CPU {cpu} ({exc})")
    try:
        os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        notes.append(f"SCHED_FIFO is not permitted here ({exc}); running at normal priority")
    return "; ".join(notes) or None


def normal_priority() -> None:
    """Put the calling thread back on the normal scheduler (SCHED_OTHER); never raises."""
    try:
        os.sched_setscheduler(threading.get_native_id(), os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass
