"""Friction and process identification (Sec. 5, Appendices A, B.4 and E).

* :mod:`.limit_cycle` - fit any parameter keys (friction levels, the
  process parameters ``plant.omega0`` and ``plant.input_gain``) to measured
  limit-cycle features of several experiments at once
  (``frictionlab identify limit-cycle``);
* :mod:`.experiments` - the simple experiments: breakaway/Coulomb test
  (E.1), Stribeck curve (E.2), free oscillation (A.1-A.2), control scaling
  (B.4), each against the simulated rig or on a recorded log
  (``frictionlab identify experiment``);
* :mod:`.logs` - reading the project's ``.csv``/``.dat`` logs;
* :mod:`.plots`, :mod:`.cli` - figures and the command line.
"""

from __future__ import annotations

from .limit_cycle import Experiment, FitResult, fit_limit_cycle, parse_experiments

__all__ = ["Experiment", "FitResult", "fit_limit_cycle", "parse_experiments", "register_cli"]


def register_cli(sub) -> None:
    """Hook called by :func:`frictionlab.cli._register_optional`."""
    from .cli import register_cli as _register

    _register(sub)
