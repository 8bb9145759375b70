r"""The identification experiments on the simulated rig: the rig's schedules, in-process.

A simulated experiment is the schedule a rig run executes, the same
:class:`~frictionlab.realtime.experiment.RigExperiment` object
(:func:`frictionlab.studies.identification.onrig.make_rig_experiment`), stepped
here against the simulator's plant instead of through the 200 Hz loop: in each
tick the plant's state is measured (:func:`frictionlab.model.sensor.measure`,
``sim.noise``, ``sim.quantization``, ``rig.*``; the raw ``y, x, v`` by
:func:`~frictionlab.model.sensor.adc` for a schedule that reads them), the
experiment's ``step`` returns u,
u goes through the DAC law (:func:`~frictionlab.model.sensor.dac`, then
:func:`~frictionlab.model.sensor.u_from_dac` on the rig's side) and the plant
steps with it.  That is what the loop does with the in-process simulated rig
(``--backend sim``, :class:`~frictionlab.realtime.rigs.SimRig`) on a fake
clock, so for the same configuration the two issue the same u in every tick
(tests/test_experiment_schedules.py); a converter (``sim.quantization = 1``)
makes the readings bit for bit those of the loop's.  Only the analyses
(:mod:`.friction_tests`, :mod:`.rig_tests`) are separate from the rig's
side.

The simulated rig's pendulum starts hanging at rest (theta = pi), the arm at
0, as a rig run expects.  The recording has the columns of
:data:`frictionlab.model.simulation.COLUMNS` (the measured signals, u, and the
true state and friction) and the experiment's marks in ``meta["marks"]``
(:func:`frictionlab.studies.identification.onrig.analyse_log` cuts the free
oscillation to its free decay with them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ...config import Config
from ...model.sensor import adc, dac, measure, u_from_dac
from ...model.simulation import COLUMNS, NC, Trajectory
from ...realtime.experiment import (
    SCALING_LEVELS,
    STRIBECK_REFERENCES,
    Limits,
    RigExperiment,
    make_experiment,
)
from ...realtime.loop import ExperimentEnd
from ...runs import make_sensor, simulated_plant
from .logsignals import IdentificationError

__all__ = [
    "MAX_EXPERIMENT_S",
    "SimulatedRun",
    "run_simulated",
    "simulate_control_scaling",
    "simulate_experiment",
    "simulate_free_oscillation",
    "simulate_stiction",
    "simulate_stribeck",
]

#: Longest simulated experiment, in simulated seconds (360 000 samples at
#: h = 5 ms, about 130 MB while recording, 10 s of computing): the thesis's
#: experiments take 1-2 minutes; a run that has not finished by then (a
#: staircase too fine or held too long to reach the breakaway level) stops
#: with an :class:`IdentificationError` instead of filling the memory.
MAX_EXPERIMENT_S = 1800.0

_COL = {name: i for i, name in enumerate(COLUMNS)}


@dataclass
class SimulatedRun:
    """A schedule run on the simulated rig.

    Attributes
    ----------
    trajectory : Trajectory
        One row per tick that commanded a u (columns ``COLUMNS``).
    reason : str
        Why it ended: ``finished`` (the schedule is done) or
        ``experiment_limit`` (a limit of the experiment, ``detail`` says
        which), as the loop's stop reason.
    detail : str
    marks : dict
        The experiment's named times (s).
    """

    trajectory: Trajectory
    reason: str
    detail: str = ""
    marks: dict[str, float] = field(default_factory=dict)

    @property
    def commands(self) -> np.ndarray:
        """The u of every tick (m/s^2), in order."""
        return self.trajectory["u"]


def run_simulated(experiment: RigExperiment, cfg: Config, *,
                  max_seconds: float = MAX_EXPERIMENT_S) -> SimulatedRun:
    """Step ``experiment``'s schedule against the simulated rig of ``cfg``.

    Parameters
    ----------
    experiment : RigExperiment
        A fresh experiment (one run per object) with ``cfg``'s period.
    cfg : Config
        The simulated rig: plant, friction, ``sim.noise``/``sim.seed``/
        ``sim.quantization`` and the ``rig.*`` factors (the rig's true ones,
        which the experiment assumes too).
    max_seconds : float
        Longest simulated time.

    Raises
    ------
    IdentificationError
        The schedule did not end within ``max_seconds``.
    """
    plant = simulated_plant(cfg)
    h = plant.h
    if abs(experiment.h - h) > 1e-12 * h:
        raise ValueError(f"the experiment's period {experiment.h:g} s is not the "
                         f"configuration's design.h = {h:g} s")
    sensor = make_sensor(cfg)
    k_u = cfg.rig.u_scale
    state = plant.init(theta0=math.pi)
    rows: list[np.ndarray] = []
    max_rows = round(max_seconds / h)
    step = experiment.step
    # the raw readings only for a schedule that reads them (a second sensor call per tick)
    raw = experiment.reads_raw
    y = xr = v = math.nan
    # the laws as plain Python: called per tick from Python, no dispatch
    to_da, from_da = dac.py_func, u_from_dac.py_func
    x0 = 0.0
    reason, detail = "finished", ""
    th_c, thd_c, arm_c, armd_c = _COL["theta"], _COL["theta_dot"], _COL["arm"], _COL["arm_dot"]
    z_c, f_c, u_c = _COL["z"], _COL["friction"], _COL["u"]
    thm_c, armm_c, armdm_c = _COL["theta_m"], _COL["arm_m"], _COL["arm_dot_m"]
    n = 0
    while True:
        x = state.x
        theta, arm, arm_dot = float(x[0]), float(x[2]), float(x[3])
        th_m, arm_m, ad_m, x0 = measure(sensor, theta, arm, arm_dot, n, x0)
        if raw:
            y, xr, v = adc(sensor, theta, arm, arm_dot, n)
        try:
            u = step(n * h, th_m, arm_m, ad_m, y, xr, v)
        except ExperimentEnd as end:
            reason, detail = end.reason, end.detail
            break
        if n >= max_rows:
            raise IdentificationError(
                f"the simulated {experiment.name} experiment did not finish within "
                f"{max_seconds:g} s of simulated time; use shorter holds or fewer, "
                "coarser levels")
        row = np.zeros(NC)
        row[thm_c], row[armm_c], row[armdm_c], row[u_c] = th_m, arm_m, ad_m, u
        row[th_c], row[thd_c], row[arm_c], row[armd_c], row[z_c] = x[0], x[1], x[2], x[3], x[4]
        state = plant.step(state, from_da(to_da(u, k_u), k_u))
        row[f_c] = state.friction
        rows.append(row)
        n += 1
    data = np.array(rows) if rows else np.zeros((0, NC))
    marks = dict(experiment.marks)
    traj = Trajectory(np.arange(len(data)), h, data, "ok", cfg,
                      {"experiment": experiment.name, "marks": marks}, noise=cfg.sim.noise)
    return SimulatedRun(traj, reason, detail, marks)


def simulate_experiment(name: str, cfg: Config, limits: Limits | None = None,
                        **options) -> Trajectory:
    """The experiment ``name`` (options as on a rig, None: the default) on the
    simulated rig of ``cfg``; its recording.

    Raises
    ------
    IdentificationError
        The experiment stopped at one of its limits, or did not end.
    ParamError
        A refused option.
    """
    if name == "free-oscillation":
        options.setdefault("omega0", cfg.design.omega0)
    exp = make_experiment(name, cfg.design.h, cfg.rig.u_scale, limits,
                          **{k: v for k, v in options.items() if v is not None})
    run = run_simulated(exp, cfg)
    if run.reason != "finished":
        raise IdentificationError(f"the simulated {name} experiment stopped before it "
                                  f"finished: {run.detail}")
    return run.trajectory


def simulate_stiction(cfg: Config, *, step: float = 0.02, hold: float = 0.25,
                      coulomb_levels: Sequence[float] = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
                      push: float = 1.5, slide: float = 0.8, v_detect: float = 0.1,
                      limits: Limits | None = None) -> Trajectory:
    """App. E.1 on the simulated rig: the schedule of
    :class:`~frictionlab.realtime.experiment.Stiction` (a staircase of constant
    u in each direction until the arm breaks away; then, per Coulomb level, a
    motor push to ``push`` rad/s and c times the breakaway u held ``slide`` s).
    The staircase stops at the u the ``limits`` allow (|u_DA| 0.5: 22.7 m/s^2)."""
    return simulate_experiment("stiction", cfg, limits, step=step, hold=hold,
                               coulomb_levels=coulomb_levels, push=push, slide=slide,
                               v_detect=v_detect)


def simulate_stribeck(cfg: Config, *, references: Sequence[float] = STRIBECK_REFERENCES,
                      gain: float = 20.0, hold: float = 2.0,
                      limits: Limits | None = None) -> Trajectory:
    r"""App. E.2 on the simulated rig: the schedule of
    :class:`~frictionlab.realtime.experiment.Stribeck`, P control of the arm
    velocity :math:`u = K(v_{ref} - \dot\Omega_m)` at each reference, +r then
    -r, each held ``hold`` s; the P loop's steady-state error is harmless
    because only the reached velocity and the steady u are used."""
    return simulate_experiment("stribeck", cfg, limits, references=references, gain=gain,
                               hold=hold)


def simulate_free_oscillation(cfg: Config, *, amplitude: float = 0.12,
                              duration: float = 12.0,
                              limits: Limits | None = None) -> Trajectory:
    """App. A.1 on the simulated rig: the schedule of
    :class:`~frictionlab.realtime.experiment.FreeOscillation` (the arm held by
    a PD loop whose reference, a square wave at ``design.omega0``, sets the
    hanging pendulum swinging to ``amplitude`` rad; then ``duration`` s of
    free decay, from the mark ``meta["marks"]["free"]``)."""
    return simulate_experiment("free-oscillation", cfg, limits, amplitude=amplitude,
                               duration=duration)


def simulate_control_scaling(cfg: Config, *, levels: Sequence[float] = SCALING_LEVELS,
                             v_stop: float = 4.0, limit: float = 3.0,
                             limits: Limits | None = None) -> Trajectory:
    """App. B.4 on the simulated rig: the schedule of
    :class:`~frictionlab.realtime.experiment.ControlScaling` (from rest,
    constant u until the arm passes ``v_stop`` rad/s, at most ``limit`` s,
    then u = 0 until it stops; once per level, alternating signs)."""
    return simulate_experiment("control-scaling", cfg, limits, levels=levels, v_stop=v_stop,
                               limit=limit)
