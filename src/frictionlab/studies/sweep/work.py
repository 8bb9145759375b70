"""The unit of work of a sweep, run in the workers: one closed-loop run of a point
reduced to a row (its limit-cycle features by default), and a chunk of points to
rows; a point whose configuration or run fails becomes an ``error`` row."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from ...config import Config
from ...model.limit_cycles import FEATURES
from ...runs import run_features

__all__ = ["STATUSES", "SWINGUP_COLUMNS", "Reduce", "check_reduce", "error_row",
           "reduce_features", "reduce_swingup", "run_chunk"]

#: Row statuses: the three of ``frictionlab simulate`` plus ``error``.
STATUSES = ("limit_cycle", "settled", "fell", "not_caught", "error")
#: The extra columns of a swing-up sweep (:func:`reduce_swingup`).
SWINGUP_COLUMNS = ("caught", "swing_up_time")


def _clean(v: Any) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def error_row(point: Mapping[str, Any], message: str) -> dict[str, Any]:
    row: dict[str, Any] = dict(point)
    row.update({name: None for name in FEATURES})
    row["status"] = "error"
    row["error"] = message
    return row


#: A reduction: ``reduce(cfg, duration, window) -> {"status": ..., feature: ..., ...}``.
Reduce = Callable[[Config, float | None, float | None], Mapping[str, Any]]


def reduce_features(cfg: Config, duration: float | None,
                    window: float | None) -> dict[str, Any]:
    """The default reduction of a run: its status and limit-cycle features.

    Parameters
    ----------
    cfg : Config
        The point's configuration.
    duration, window : float or None
        As for :func:`frictionlab.runs.run_features`.

    Returns
    -------
    dict
        The seven features of :data:`~frictionlab.model.limit_cycles.FEATURES`
        (``None`` where undefined) and ``status`` (``limit_cycle``,
        ``settled`` or ``fell``).
    """
    feats = run_features(cfg, duration, window)
    out: dict[str, Any] = {name: getattr(feats, name) for name in FEATURES}
    out["status"] = feats.status
    return out


def reduce_swingup(cfg: Config, duration: float | None,
                   window: float | None) -> dict[str, Any]:
    """The reduction of a swing-up run (``sweep --swing-up``).

    Returns the features and status of
    :func:`frictionlab.studies.swingup_sim.swingup_outcome` (``not_caught`` when it
    never reached the balancing phase) and ``caught`` (1 when it did, else 0)
    and ``swing_up_time`` (s, the catch that led to balancing; ``None`` if none).
    """
    # start-up: the swing-up simulation loads with the first swing-up sweep, not with
    # the command line (which imports this package)
    from ..swingup_sim import simulate_swingup, swingup_outcome

    res = simulate_swingup(cfg, duration)
    status, feats = swingup_outcome(res, window)
    out: dict[str, Any] = {name: getattr(feats, name) for name in FEATURES}
    out["status"] = status
    out["caught"] = int(res.balanced)
    out["swing_up_time"] = res.swing_up_time
    return out


def _row(point: Mapping[str, Any], result: Any) -> dict[str, Any]:
    """A point's row from its reduction: the point, the features, status, error, extras."""
    if not isinstance(result, Mapping):
        raise TypeError(f"reduce returned {type(result).__name__}, not a mapping")
    missing = [k for k in ("status", *FEATURES) if k not in result]
    if missing:
        raise ValueError(f"reduce returned no {', '.join(missing)}")
    if result["status"] not in STATUSES[:-1]:
        raise ValueError(f"reduce returned status {result['status']!r}; expected one of "
                         f"{', '.join(STATUSES[:-1])}")
    row: dict[str, Any] = dict(point)
    row.update({name: _clean(result[name]) for name in FEATURES})
    row["status"] = result["status"]
    row["error"] = None
    for k, v in result.items():
        if k in FEATURES or k == "status":
            continue
        if k in row:
            raise ValueError(f"reduce returned a column {k!r}, which the row has already")
        row[k] = v
    return row


def run_chunk(base: Config, points: Sequence[Mapping[str, Any]], duration: float | None,
               window: float | None, reduce: Reduce | None = None) -> list[dict[str, Any]]:
    """Evaluate a chunk of points (executed in a worker process, or in-process).

    Each point's configuration is run and reduced by ``reduce`` (default:
    :func:`reduce_features`'s rows, computed by the compiled batch evaluator
    :func:`frictionlab.studies.batch.evaluate_rows` on one thread); a point whose
    configuration is invalid, or whose run or reduction raises, is an error row.
    """
    if reduce is None:
        # the default reduction, every point in one compiled batch (no Python per run);
        # start-up: the batch evaluator loads with the first sweep, not the command line
        from ..batch import evaluate_rows

        return evaluate_rows(base, points, duration, window)
    rows = []
    for p in points:
        try:
            rows.append(_row(p, reduce(base.with_values(p), duration, window)))
        except Exception as exc:
            rows.append(error_row(p, f"{type(exc).__name__}: {exc}"))
    return rows


def check_reduce(reduce: Any) -> None:
    """A ``reduce`` must reach the workers by reference: a picklable top-level function."""
    import pickle

    if not callable(reduce):
        raise TypeError(f"reduce must be a function, got {type(reduce).__name__}")
    try:
        pickle.dumps(reduce)
    except Exception as exc:
        raise TypeError(f"reduce must be a picklable top-level function (it runs in worker "
                        f"processes); {reduce!r} is not: {exc}") from None
