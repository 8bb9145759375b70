r"""Closed-loop simulation of a swing-up (:mod:`frictionlab.model.swingup`).

The closed loop of :func:`frictionlab.model.closedloop.run_loop` with its
swing-up supervisor (:func:`frictionlab.model.swingup.swingup_step`) on: the
same compiled tick, plant, sensor and friction drift as
:func:`frictionlab.runs.simulate_config`.  The pendulum's angle is
unbounded in the plant (it may go over the top); the recorded ``theta`` and
``theta_m`` columns are wrapped into [-pi, pi).

A run ends early when the swing-up stops (its time limit, arm travel or arm
speed, :data:`frictionlab.model.swingup.STOP_CODES`) or, once balancing, when the
pendulum falls (``|theta| > sim.fall_angle``, wrapped) or the state becomes
non-finite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Config
from ..model.closedloop import FELL, NC, SWING_STOPPED, run_loop
from ..model.controller import Controller
from ..model.friction import KINDS, plant_record, resolve_drift
from ..model.limit_cycles import LimitCycleFeatures, trajectory_features
from ..model.simulation import Trajectory
from ..model.swingup import (
    BALANCING,
    PHASES,
    STOP_CODES,
    SwingUp,
    swing_record,
    swing_vector,
    swingup_row,
)
from ..runs import make_controller, make_sensor

__all__ = ["ROBUST_DESIGN", "SwingUpResult", "simulate_swingup", "swingup_outcome"]

#: The balancing design for a plant the design does not know (``--set`` pairs,
#: the same for the thesis plant and the motor plants): both closed-loop pole
#: pairs critically damped and the arm's pair at 5 rad/s.  The fast preset's
#: arm pair (omega_2 = 10 rad/s, zeta 0.7; eqs. 13-16) leaves too little margin
#: for a plant drawn within the swing-up Monte Carlo's spread: on the thesis
#: plant its friction limit cycle needs more than a 10 m/s^2 actuator when
#: F_C is high and the plant's omega_0 near the design's, on the QUBE-Servo 2
#: its linear loop is unstable or nearly so on about 2 % of the plants
#: (docs/swingup.md, "Plants the design does not know").
ROBUST_DESIGN = (("design.omega2", 5.0), ("design.zeta1", 1.0), ("design.zeta2", 1.0))

@dataclass(frozen=True)
class SwingUpResult:
    """Outcome of a swing-up run.

    Attributes
    ----------
    trajectory : Trajectory
        The signals (``meta["phase"]`` holds the phase code of every tick).
    swing_up_time : float or None
        Time of the catch that led to balancing (s), None if never balancing.
    balanced : bool
        The phase reached ``balancing``.
    stop_reason : str
        ``not_caught``, ``arm_travel``, ``arm_speed`` (the swing-up stopped),
        ``fell`` (fell after balancing) or ``""`` (ran to the end).
    catches : int
        Number of hand-overs (failed catches return to swinging).
    max_u_swinging : float
        Largest |u| while swinging (units of u: m/s^2, or V for a motor plant).
    """

    trajectory: Trajectory
    swing_up_time: float | None
    balanced: bool
    stop_reason: str
    catches: int
    max_u_swinging: float


def simulate_swingup(cfg: Config, duration: float | None = None, *,
                     controller: Controller | None = None) -> SwingUpResult:
    """Swing the pendulum up from ``sim.initial_angle`` (pi = hanging) and balance it.

    Parameters
    ----------
    cfg : Config
        Plant, design, friction, compensation, ``sim.*`` and ``swingup.*``.
    duration : float, optional
        Simulated time in s (default ``cfg.sim.duration``).
    controller : Controller, optional
        The balancing controller (default: the one ``cfg`` describes).
    """
    duration = cfg.sim.duration if duration is None else float(duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be > 0 s, got {duration}")
    h = cfg.design.h
    n = max(1, round(duration / h))
    if n > 20_000_000:
        raise ValueError(f"duration {duration:g} s is too long for a recorded swing-up run")
    sw = SwingUp(controller or make_controller(cfg), cfg.swingup)
    gp, cp, sp = sw.record()
    w, s = sw.init(cfg.sim.initial_angle)
    wx = swing_vector(w)
    x = np.zeros(5)
    x[0] = cfg.sim.initial_angle
    out = np.zeros((n, NC))
    phase = np.zeros(n)
    fp = resolve_drift(plant_record(cfg.friction_kind, cfg.friction), n * h)
    done, status, _, _ = run_loop(x, 0.0, n, cfg.plant_model.code, cfg.substeps,
                                  cfg.pendulum_ratio, cfg.plant_row(),
                                  KINDS.index(cfg.friction_kind), fp, gp, cp, s,
                                  make_sensor(cfg), 0, 0.0, cfg.sim.fall_angle, out, True, True,
                                  swingup_row(sp), wx, phase)
    phase = phase[:done]
    # the end state's fields, read as items (about 1 us each; an attribute of a
    # numpy record costs about 4 us from Python)
    w = swing_record(wx)
    stop_code, catch_tick, ticks, catches = (w[f] for f in ("stop", "catch_tick", "tick",
                                                             "catches"))
    balanced = bool((phase == BALANCING).any())
    stop = STOP_CODES[int(stop_code)] if status == SWING_STOPPED else ""
    if status == FELL:
        stop = "fell"
    catch_time = float(catch_tick) * h if balanced and catch_tick >= 0 else None
    swinging = phase == 0
    u = out[:done, 3]
    max_u = float(np.abs(u[swinging]).max()) if swinging.any() else 0.0
    traj = Trajectory(np.arange(done), h, out[:done], "fell" if status == FELL else "ok", cfg,
                      noise=cfg.sim.noise,
                      meta={"phase": phase, "phases": PHASES, "ticks": int(ticks)})
    return SwingUpResult(traj, catch_time, balanced, stop, int(catches), max_u)


def swingup_outcome(res: SwingUpResult, window: float | None = None):
    """``(status, features)`` of a swing-up run, as ``simulate --swing-up`` reports them.

    ``status`` is the features' ``limit_cycle``/``settled`` once balanced (the
    features measured over the last ``window`` s, by default the last half of
    the balancing part), ``fell`` if the pendulum fell (or a swing-up safety limit stopped the
    run) after balancing, and
    ``not_caught`` otherwise.
    """
    traj = res.trajectory
    if not res.balanced:
        return "not_caught", LimitCycleFeatures("not_caught", *([None] * 7))
    if res.stop_reason:
        return "fell", LimitCycleFeatures("fell", *([None] * 7))
    first = int(np.argmax(traj.meta["phase"] == BALANCING))
    part = Trajectory(traj.k[first:] - first, traj.h, traj.data[first:], traj.status,
                      traj.config, noise=traj.noise)
    if window is None:
        window = 0.5 * len(part) * traj.h
    feats = trajectory_features(part, window)
    return feats.status, feats
