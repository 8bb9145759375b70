r"""Simple identification experiments of Appendices A, B and E.

Each experiment has two halves:

* its **schedule**, the one a rig runs: a controller of the real-time loop
  (:mod:`frictionlab.realtime.experiment`); ``simulate_*(cfg, ...) ->
  Trajectory`` runs that same schedule against the simulated rig in-process
  (:mod:`.simulated`), recording the signals the rig would log (columns of
  :data:`frictionlab.model.simulation.COLUMNS`; measurement noise
  ``sim.noise``);
* its **analysis**, ``analyse_*(log, ...) -> dict``: derives the estimates
  from a log, which is anything indexable by signal name (a
  :class:`~frictionlab.model.simulation.Trajectory` or the dict
  :func:`frictionlab.io.logs.read_log` returns), so the same analysis runs
  on a real rig's recording (:mod:`.friction_tests` for App. E,
  :mod:`.rig_tests` for App. A and B; the log's signals and line fits:
  :mod:`.logsignals`).

This module gathers them under one name.  Friction levels are in the
plant's units (m/s^2 of arm-tip acceleration, like u).  At rest or at
constant speed the friction balances the force the plant receives,
:math:`k_u u` (eq. 5), so the analyses multiply the logged u by the
*assumed* control scaling ``plant.input_gain`` (1 by default), as App. E.1
divided its DAC readings by :math:`|k_u|`.

Signals each analysis needs
---------------------------
=================  ==========================================
experiment         signals
=================  ==========================================
stiction           ``t``, ``u``, ``arm_dot_m``
stribeck           ``t``, ``u``, ``arm_dot_m``
free-oscillation   ``t``, ``theta_m``
control-scaling    ``t``, ``u``, ``arm_dot_m``
velocity-scale     ``t``, ``arm_m``, ``v`` (the raw velocity channel)
angle-scales       ``t``, ``y``, ``x`` (raw) and the run's marks
=================  ==========================================
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

from .friction_tests import analyse_stiction, analyse_stribeck, stribeck_model
from .logsignals import IdentificationError, estimates_only
from .rig_tests import (
    analyse_angle_scales,
    analyse_control_scaling,
    analyse_free_oscillation,
    analyse_velocity_scale,
)

if TYPE_CHECKING:  # pragma: no cover - for type checkers only
    from ...realtime.experiment import MAX_LEVELS, SCALING_LEVELS, STRIBECK_REFERENCES
    from .simulated import (
        MAX_EXPERIMENT_S,
        simulate_control_scaling,
        simulate_experiment,
        simulate_free_oscillation,
        simulate_stiction,
        simulate_stribeck,
    )

#: Names loaded on first use (start-up: the command line imports this module for
#: :data:`EXPERIMENTS`; the schedules bring the real-time loop's modules): name ->
#: module.
_LAZY = {"MAX_LEVELS": "...realtime.experiment", "SCALING_LEVELS": "...realtime.experiment",
         "STRIBECK_REFERENCES": "...realtime.experiment",
         **{n: ".simulated" for n in ("MAX_EXPERIMENT_S", "simulate_control_scaling",
                                      "simulate_experiment", "simulate_free_oscillation",
                                      "simulate_stiction", "simulate_stribeck")}}

__all__ = [
    "EXPERIMENTS",
    "MAX_EXPERIMENT_S",
    "MAX_LEVELS",
    "SCALING_LEVELS",
    "STRIBECK_REFERENCES",
    "IdentificationError",
    "analyse_angle_scales",
    "analyse_control_scaling",
    "analyse_free_oscillation",
    "analyse_stiction",
    "analyse_stribeck",
    "analyse_velocity_scale",
    "estimates_only",
    "simulate_control_scaling",
    "simulate_experiment",
    "simulate_free_oscillation",
    "simulate_stiction",
    "simulate_stribeck",
    "stribeck_model",
]

#: Experiment names of ``frictionlab identify experiment``.
EXPERIMENTS = ("stiction", "stribeck", "free-oscillation", "control-scaling",
               "velocity-scale", "angle-scales")


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(module, __package__), name)
    globals()[name] = value
    return value
