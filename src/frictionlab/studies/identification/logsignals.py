"""Reading and fitting the signals of an identification experiment's log.

A log is anything indexable by signal name: a simulated
:class:`~frictionlab.model.simulation.Trajectory`, the dict
:func:`frictionlab.io.logs.read_log` returns, or the rows of a rig run.  The
analyses of :mod:`.friction_tests` and :mod:`.rig_tests` read their signals
and fit their lines with the functions here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...model.plants.thesis import PlantParams

__all__ = ["ARM_LENGTH", "IdentificationError", "constant_runs", "estimates_only", "line_fit",
           "log_signal", "log_time", "noise_level", "ordered", "quantum"]

#: The arm length L_1 an analysis assumes when it is not given (``plant.arm_length``'s
#: default, m).
ARM_LENGTH = PlantParams().arm_length


class IdentificationError(ValueError):
    """The log does not contain what the experiment needs (or a simulated
    experiment would not end within its longest simulated time)."""


def log_signal(log: Any, name: str) -> np.ndarray:
    """The signal ``name`` of ``log`` as floats."""
    try:
        v = np.asarray(log[name], dtype=float)
    except (KeyError, IndexError, ValueError):
        raise IdentificationError(f"the log has no {name!r} signal") from None
    return v


def log_time(log: Any) -> np.ndarray:
    """The log's time ``t`` (at least 3 samples)."""
    t = log_signal(log, "t")
    if len(t) < 3:
        raise IdentificationError("the log is too short (fewer than 3 samples)")
    return t


def noise_level(y: np.ndarray) -> float:
    """Measurement-noise standard deviation from second differences."""
    if len(y) < 4:
        return 0.0
    d2 = np.diff(y, 2)
    mad = np.median(np.abs(d2 - np.median(d2)))
    return float(1.4826 * mad / math.sqrt(6.0))


def quantum(y: np.ndarray) -> float:
    """The step of a quantised signal: the most common smallest change between samples
    (the 10th percentile of the nonzero absolute differences; 0 if it never changes)."""
    d = np.abs(np.diff(y[np.isfinite(y)]))
    d = d[d > 1e-12]
    return float(np.percentile(d, 10)) if len(d) else 0.0


def constant_runs(u: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs [a, b) of equal consecutive values of ``u``."""
    if len(u) == 0:
        return []
    edges = np.flatnonzero(np.diff(u) != 0.0) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [len(u)]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def line_fit(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares line y = a t + b: (a, b, standard error of a)."""
    tc = t - t.mean()
    stt = float(np.sum(tc * tc))
    a = float(np.sum(tc * (y - y.mean())) / stt)
    b = float(y.mean() - a * t.mean())
    dof = len(t) - 2
    res = y - (a * t + b)
    se = math.sqrt(float(np.sum(res * res)) / dof / stt) if dof > 0 else math.inf
    return a, b, se



def ordered(d: dict, first: Sequence[str]) -> dict:
    """``d`` with the keys ``first`` (those present) in front."""
    return {**{k: d[k] for k in first if k in d}, **{k: v for k, v in d.items()
                                                     if k not in first}}


def estimates_only(result: Mapping[str, Any]) -> dict[str, float]:
    """The scalar estimates of an analysis result (for printing)."""
    return {k: v for k, v in result.items() if isinstance(v, float)}

