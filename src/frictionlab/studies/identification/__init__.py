"""Friction and process identification (Sec. 5, Appendices A, B.4 and E).

* :mod:`.limit_cycle` - fit any parameter keys (friction levels, the
  process parameters ``plant.omega0`` and ``plant.input_gain``) to measured
  limit-cycle features of several experiments at once
  (``frictionlab identify limit-cycle``);
* :mod:`.experiments` - the simple experiments: breakaway/Coulomb test
  (E.1), Stribeck curve (E.2), free oscillation (A.1-A.2), control scaling
  (B.4), each against the simulated rig or on a recorded log
  (``frictionlab identify experiment``);
* :mod:`.plots` - figures.

Reading the project's ``.csv``/``.dat`` logs: :mod:`frictionlab.io.logs`; the
command line: :mod:`frictionlab.cli.identify`.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

__all__ = ["Experiment", "FitResult", "fit_limit_cycle", "parse_experiments"]

if TYPE_CHECKING:  # pragma: no cover - for type checkers only
    from .limit_cycle import Experiment, FitResult, fit_limit_cycle, parse_experiments


def __getattr__(name: str):
    # the fit (and scipy.optimize) load on first use, not with the command line
    if name in ("Experiment", "FitResult", "fit_limit_cycle", "parse_experiments"):
        value = getattr(import_module(".limit_cycle", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

