"""Reading recorded logs for the identification experiments (file I/O).

Two formats, both written by :meth:`frictionlab.simulation.Trajectory.save`:

* ``.csv``: a header line naming the columns (``t`` first, then any of
  :data:`frictionlab.simulation.COLUMNS`), comma separated.  Extra or
  missing columns are allowed; an analysis names the signal it lacks.
* ``.dat``: the thesis's ten logged signals (Sec. 7.1) as whitespace
  separated columns in the order of :data:`frictionlab.simulation.LOGGED`,
  without time; sample k is at ``t = k h``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..simulation import LOGGED

__all__ = ["read_log"]


def read_log(path: str | Path, h: float = 0.005) -> dict[str, np.ndarray]:
    """Signals of a log file by name (``t`` always present).

    Parameters
    ----------
    path : path
        ``.csv`` (with header) or ``.dat`` (ten columns).
    h : float
        Sampling period for ``.dat`` files (``design.h``).

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
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{p}: empty log")
    try:
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
