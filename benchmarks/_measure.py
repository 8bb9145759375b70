"""What the benchmarks share: CPU time of a process tree and the load average.

Imported by the scripts of this folder (run as ``python benchmarks/NAME.py``,
so the folder is on ``sys.path``).
"""

from __future__ import annotations

import os

__all__ = ["cpu_seconds", "load_average"]


def cpu_seconds() -> float:
    """CPU time (user + system) of this process (all its threads) and its live
    descendants, in seconds."""
    import psutil

    me = psutil.Process()
    total = 0.0
    for p in [me, *me.children(recursive=True)]:
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system
    return total


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, ``"1.2, 0.9, 0.7"``."""
    return ", ".join(f"{x:.1f}" for x in os.getloadavg())
