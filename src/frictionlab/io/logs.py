"""Reading recorded logs for the identification experiments (file I/O).

Two formats, both written by :meth:`frictionlab.model.simulation.Trajectory.save`:

* ``.csv``: a header line naming the columns (``t`` first, then any of
  :data:`frictionlab.model.simulation.COLUMNS`), comma separated.  Extra or
  missing columns are allowed; an analysis names the signal it lacks.
* ``.dat``: the thesis's ten logged signals (Sec. 7.1) as whitespace
  separated columns in the order of :data:`frictionlab.model.simulation.LOGGED`,
  without time; sample k is at ``t = k h``.  A real-time run's ``.dat``
  has no line for a missed tick, so its time axis is then wrong:
  :func:`log_warnings` reads the run's sidecar (``<run_id>.json``) to say so.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..model.simulation import LOGGED

__all__ = ["log_warnings", "read_log"]


def read_log(path: str | Path, h: float = 0.005, *,
             partial: bool = False) -> dict[str, np.ndarray]:
    """Signals of a log file by name (``t`` always present).

    The one reader of the project's logs (the simulator's and the real-time
    loop's ``.dat`` and ``.csv``).

    Parameters
    ----------
    path : path
        ``.csv`` (with header) or ``.dat`` (ten columns).
    h : float
        Sampling period for ``.dat`` files (``design.h``).
    partial : bool
        The log may still be being written: a last line without its newline
        is left out (else it is read like any other).

    Raises
    ------
    ValueError
        Unreadable file, unknown extension, malformed contents.
    """
    p = Path(path)
    if p.suffix not in (".csv", ".dat"):
        raise ValueError(f"{p}: log extension must be .csv or .dat")
    try:
        text = p.read_text()
    except OSError as exc:
        raise ValueError(f"cannot read log {p}: {exc.strerror}") from None
    if partial and not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{p}: empty log")
    try:
        with warnings.catch_warnings():
            # a header without rows: the error below says so in one line
            warnings.filterwarnings("ignore", "loadtxt: input contained no data")
            if p.suffix == ".csv":
                names = [c.strip() for c in lines[0].split(",")]
                data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
            else:
                names = list(LOGGED)
                data = np.loadtxt(lines, ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{p}: malformed log ({exc})") from None
    if data.shape[0] == 0:
        raise ValueError(f"{p}: the log has no samples")
    if data.shape[1] != len(names):
        raise ValueError(f"{p}: {data.shape[1]} columns, expected {len(names)} "
                         f"({', '.join(names)})")
    out = {name: data[:, i] for i, name in enumerate(names)}
    if "t" not in out:
        out["t"] = np.arange(data.shape[0]) * h
    return out


def log_warnings(path: str | Path) -> list[str]:
    """Warnings about a log's time axis, from the real-time run's sidecar.

    A ``.dat`` has no time column: sample k is taken to be at ``t = k h``.
    The real-time loop writes no line for a missed tick, nor for a sample
    its log writer dropped, so after either the samples of a ``.dat`` are
    closer together in the file than they were in time (a free oscillation
    then looks faster than it was).  The sidecar of a run, ``<run_id>.json``
    next to ``<run_id>.dat``, counts both (``stats.missed``,
    ``dropped_log_samples``).  A ``.csv`` carries ``t`` and needs no check.

    Parameters
    ----------
    path : path
        The log file.

    Returns
    -------
    list of str
        Empty for a ``.csv``, a ``.dat`` without a readable sidecar, or a
        sidecar that reports no missed ticks and no dropped samples.
    """
    p = Path(path)
    sidecar = p.with_suffix(".json")
    if p.suffix != ".dat" or not sidecar.is_file():
        return []
    try:
        meta = json.loads(sidecar.read_text())
    except (OSError, ValueError):
        return []
    if not isinstance(meta, dict):
        return []
    stats = meta.get("stats") if isinstance(meta.get("stats"), dict) else {}
    gaps = {"missed tick(s)": stats.get("missed"),
            "dropped log sample(s)": meta.get("dropped_log_samples")}
    found = [f"{int(n)} {what}" for what, n in gaps.items()
             if isinstance(n, int | float) and n > 0]
    if not found:
        return []
    return [f"{p.name}: its run reports {' and '.join(found)} ({sidecar.name}); a .dat has "
            "no time column and no line for them, so the analysis's time axis (t = k h) "
            f"is compressed there.  Use the run's .csv ({p.with_suffix('.csv').name}), "
            "which has t"]
