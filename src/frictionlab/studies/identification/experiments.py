r"""Simple identification experiments of Appendices A, B.4 and E.

Each experiment has two halves:

* ``simulate_*(cfg, ...) -> Trajectory``: runs the experiment open loop (or
  under the experiment's own P velocity loop) against the simulated rig
  (:class:`frictionlab.model.simulation.SimulatedPlant` with the plant and friction
  of ``cfg``), recording the signals the rig would log (columns of
  :data:`frictionlab.model.simulation.COLUMNS`; measurement noise ``sim.noise``);
* ``analyse_*(log, ...) -> dict``: derives the estimates from a log, which is
  anything indexable by signal name (a :class:`~frictionlab.model.simulation.Trajectory`
  or the dict :func:`frictionlab.io.logs.read_log` returns), so
  the same analysis runs on a real rig's recording.

Friction levels are in the plant's units (m/s^2 of arm-tip acceleration, like
u).  At rest or at constant speed the friction balances the force the plant
receives, :math:`k_u u` (eq. 5), so the analyses multiply the logged u by the
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

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...config import Config
from ...io.notes import Note
from ...model.friction import stribeck_magnitude
from ...model.params import ParamError, check_range
from ...model.rig import RigScaling
from ...model.sensor import measure
from ...model.simulation import COLUMNS, NC, PlantState, Trajectory
from ...runs import make_sensor, simulated_plant

__all__ = [
    "EXPERIMENTS",
    "IdentificationError",
    "analyse_angle_scales",
    "analyse_control_scaling",
    "analyse_free_oscillation",
    "analyse_stiction",
    "analyse_stribeck",
    "analyse_velocity_scale",
    "simulate_control_scaling",
    "simulate_free_oscillation",
    "simulate_stiction",
    "simulate_stribeck",
    "stribeck_model",
]

#: Experiment names of ``frictionlab identify experiment``.
EXPERIMENTS = ("stiction", "stribeck", "free-oscillation", "control-scaling",
               "velocity-scale", "angle-scales")

_I = {name: i for i, name in enumerate(COLUMNS)}


class IdentificationError(ValueError):
    """The log does not contain what the experiment needs (or a simulated
    experiment would not end within :data:`MAX_EXPERIMENT_S`)."""


#: Longest simulated experiment, in simulated seconds (360 000 samples at
#: h = 5 ms, about 130 MB while recording, 10 s of computing): the thesis's
#: experiments take 1-2 minutes; a run that has not finished by then (a
#: staircase too fine or held too long to reach the breakaway level) stops
#: with an :class:`IdentificationError` instead of filling the memory.
MAX_EXPERIMENT_S = 1800.0
#: Longest hold of one level of the stiction staircase or one Stribeck velocity (s).
MAX_HOLD_S = 60.0
#: Most velocity references (Stribeck) or constant u levels (control scaling).
MAX_LEVELS = 100


# ---------------------------------------------------------------------------
# recording the simulated rig
# ---------------------------------------------------------------------------


class _Recorder:
    """Steps a :class:`SimulatedPlant` and records one row of COLUMNS per tick.

    The measured signals are the simulator's (:func:`frictionlab.model.sensor.measure`:
    ``sim.noise`` seeded by ``sim.seed``, the 12-bit converter with
    ``sim.quantization``, the ``rig.*`` factors; sample n = tick n); the
    controller-estimate columns stay zero (the experiments run open loop).
    """

    def __init__(self, cfg: Config, theta0: float, name: str = "experiment"):
        self.cfg = cfg
        self.name = name
        self.plant = simulated_plant(cfg)
        self.state = self.plant.init(theta0=theta0)
        self.rows: list[np.ndarray] = []
        self.max_rows = round(MAX_EXPERIMENT_S / self.plant.h)
        self.sensor = make_sensor(cfg)
        self._x0 = 0.0

    @property
    def h(self) -> float:
        return self.plant.h

    def measure(self) -> tuple[float, float, float]:
        x = self.state.x
        th, arm, ad, self._x0 = measure(self.sensor, float(x[0]), float(x[2]), float(x[3]),
                                        len(self.rows), self._x0)
        return th, arm, ad

    def step(self, u: float, measured: tuple[float, float, float] | None = None) -> None:
        if len(self.rows) >= self.max_rows:
            raise IdentificationError(
                f"the simulated {self.name} experiment did not finish within "
                f"{MAX_EXPERIMENT_S:g} s of simulated time; use shorter holds or fewer, "
                "coarser levels")
        th_m, arm_m, ad_m = measured if measured is not None else self.measure()
        row = np.zeros(NC)
        row[_I["theta_m"]], row[_I["arm_m"]], row[_I["arm_dot_m"]] = th_m, arm_m, ad_m
        row[_I["u"]] = u
        x = self.state.x
        row[_I["theta"]], row[_I["theta_dot"]] = x[0], x[1]
        row[_I["arm"]], row[_I["arm_dot"]], row[_I["z"]] = x[2], x[3], x[4]
        self.state = self.plant.step(self.state, u)
        row[_I["friction"]] = self.state.friction
        self.rows.append(row)

    def hold(self, u: float, seconds: float) -> None:
        for _ in range(max(1, round(seconds / self.h))):
            self.step(u)

    def push_arm(self, velocity: float) -> None:
        """Give the arm a push: set its velocity (the hand of App. E.1)."""
        x = self.state.x.copy()
        x[3] = velocity
        self.state = PlantState(x, self.state.memory, self.state.friction, self.state.tick)

    @property
    def arm_dot(self) -> float:
        return float(self.state.x[3])

    def trajectory(self, **meta) -> Trajectory:
        data = np.array(self.rows) if self.rows else np.zeros((0, NC))
        return Trajectory(np.arange(len(data)), self.h, data, "ok", self.cfg, meta,
                          noise=self.cfg.sim.noise)


def _signal(log: Any, name: str) -> np.ndarray:
    try:
        v = np.asarray(log[name], dtype=float)
    except (KeyError, IndexError, ValueError):
        raise IdentificationError(f"the log has no {name!r} signal") from None
    return v


def _time(log: Any) -> np.ndarray:
    t = _signal(log, "t")
    if len(t) < 3:
        raise IdentificationError("the log is too short (fewer than 3 samples)")
    return t


def _noise_level(y: np.ndarray) -> float:
    """Measurement-noise standard deviation from second differences."""
    if len(y) < 4:
        return 0.0
    d2 = np.diff(y, 2)
    mad = np.median(np.abs(d2 - np.median(d2)))
    return float(1.4826 * mad / math.sqrt(6.0))


def _quantum(y: np.ndarray) -> float:
    """The step of a quantised signal: the most common smallest change between samples
    (the 10th percentile of the nonzero absolute differences; 0 if it never changes)."""
    d = np.abs(np.diff(y[np.isfinite(y)]))
    d = d[d > 1e-12]
    return float(np.percentile(d, 10)) if len(d) else 0.0


def _runs(u: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs [a, b) of equal consecutive values of ``u``."""
    if len(u) == 0:
        return []
    edges = np.flatnonzero(np.diff(u) != 0.0) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [len(u)]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _slope(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares line y = a t + b: (a, b, standard error of a)."""
    tc = t - t.mean()
    stt = float(np.sum(tc * tc))
    a = float(np.sum(tc * (y - y.mean())) / stt)
    b = float(y.mean() - a * t.mean())
    dof = len(t) - 2
    res = y - (a * t + b)
    se = math.sqrt(float(np.sum(res * res)) / dof / stt) if dof > 0 else math.inf
    return a, b, se


# ---------------------------------------------------------------------------
# E.1: stiction and Coulomb friction
# ---------------------------------------------------------------------------


def simulate_stiction(
    cfg: Config,
    *,
    step: float = 0.02,
    hold: float = 0.25,
    u_max: float = 20.0,
    coulomb_levels: Sequence[float] = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
    push: float = 1.5,
    slide: float = 0.8,
    v_detect: float = 0.1,
) -> Trajectory:
    """App. E.1 on the simulated rig, both directions, pendulum hanging down.

    Stiction: constant u of increasing magnitude (staircase of ``step``,
    each held ``hold`` s) until the arm moves (speed above ``v_detect``),
    then u = 0 until it stops.  Coulomb: for each level ``c`` of
    ``coulomb_levels`` (fractions of the breakaway u), the arm is pushed to
    ``push`` rad/s in the direction of u and u = c times the breakaway level
    is held for ``slide`` s (the arm decelerates below the Coulomb level and
    keeps accelerating above it), then u = 0 until it stops.
    """
    check_range("step", step, 0.0, u_max, lo_open=True)
    check_range("hold", hold, 0.0, MAX_HOLD_S, lo_open=True)
    rec = _Recorder(cfg, theta0=math.pi, name="stiction")
    rec.hold(0.0, 0.5)
    breakaway = {}
    for d in (1.0, -1.0):
        level = 0.0
        moved = False
        while level < u_max and not moved:
            level = round(level + step, 12)
            for _ in range(max(1, round(hold / rec.h))):
                rec.step(d * level)
                if d * rec.arm_dot > v_detect:
                    moved = True
        breakaway[d] = level
        rec.hold(d * level, 0.1)
        _coast(rec)
    for d in (1.0, -1.0):
        for c in coulomb_levels:
            rec.push_arm(d * push)
            rec.hold(d * c * breakaway[d], slide)
            _coast(rec)
    return rec.trajectory(experiment="stiction")


def _coast(rec: _Recorder, limit: float = 5.0) -> None:
    """u = 0 until the arm has (nearly) stopped, then 0.3 s more."""
    n = 0
    while abs(rec.arm_dot) > 0.05 and n * rec.h < limit:
        rec.step(0.0)
        n += 1
    rec.hold(0.0, 0.3)


def analyse_stiction(log: Any, *, input_gain: float = 1.0, arm_length: float = 0.21,
                     v_detect: float | None = None, v_slide: float | None = None) -> dict:
    r"""Stiction and Coulomb friction per direction (App. E.1).

    Stiction (per direction d): the first sample where the arm speed d
    :math:`\dot\Omega` exceeds ``v_detect`` while d u > 0 marks the breakaway;
    the stiction is the largest d u applied before it, less half the
    staircase step (the true level lies within the last step).  The step is
    the median increment between the staircase's levels.  When the arm
    breaks away at the staircase's first level L, the log bounds the
    stiction only from above: it lies in (0, L] (u was 0 before the
    staircase).  The estimate is then L/2 and a warning says so.

    Coulomb (per direction): every run of constant u with d u > 0 below the
    breakaway level during which the arm slides in direction d faster than
    ``v_slide`` gives the acceleration a by a straight-line fit of the
    measured arm velocity; eq. (5) :math:`L_1 a = k_u u - F_C` then gives
    :math:`F_C = k_u u - L_1 a`, averaged over the runs (weighted by their
    length).  Decelerating and accelerating runs both count: the Coulomb
    level is where the fitted acceleration crosses zero, which is the
    thesis's "smallest u that keeps the arm moving".

    Returns
    -------
    dict
        ``stiction``, ``coulomb`` (means of both directions) and
        ``stiction_positive``, ``stiction_negative``, ``coulomb_positive``,
        ``coulomb_negative``, ``breakaway_time_positive/negative``,
        ``segments`` (per sliding run: direction, u, acceleration, friction),
        ``warnings``.
    """
    t = _time(log)
    u = _signal(log, "u")
    v = _signal(log, "arm_dot_m")
    sig = _noise_level(v)
    v_detect = max(0.1, 6.0 * sig) if v_detect is None else v_detect
    v_slide = max(0.2, 6.0 * sig) if v_slide is None else v_slide
    out: dict[str, Any] = {}
    segments = []
    warnings = []
    for d, name in ((1.0, "positive"), (-1.0, "negative")):
        drive = d * u > 0
        moving = d * v > v_detect
        hits = np.flatnonzero(drive & moving)
        if len(hits) == 0:
            raise IdentificationError(f"no breakaway in the {name} direction: the arm never "
                                      f"moved faster than {v_detect:g} rad/s under d*u > 0")
        k = int(hits[0])
        # the staircase leading to the breakaway: same-sign u before k
        j = k
        while j > 0 and drive[j - 1]:
            j -= 1
        stair = d * u[j:k + 1]
        levels = np.unique(stair)
        level = float(stair.max())
        if len(levels) > 1:
            step = float(np.median(np.diff(levels)))
        else:
            # breakaway at the first level: u rose from 0 to it in one step
            step = level
            warnings.append(Note(
                f"the arm broke away at the first level of the {name} staircase "
                f"(u = {d * level:g}): the stiction is only known to be at most "
                f"{input_gain * level:.4g}; reported as half of that.  Repeat with a "
                "smaller staircase step", "step"))
        stiction = input_gain * (level - 0.5 * step)
        out[f"stiction_{name}"] = stiction
        out[f"breakaway_time_{name}"] = float(t[k])
        # Coulomb: constant-u runs below the breakaway level with sliding (the
        # staircase's levels below it leave the arm at rest)
        est, wts = [], []
        for a, b in _runs(u):
            uu = float(u[a])
            if not 0 < d * uu < level:
                continue
            idx = np.arange(a + 1, b)  # the first sample may hold the push
            idx = idx[d * v[idx] > v_slide]
            if len(idx) < 8:
                continue
            acc, _, _ = _slope(t[idx], v[idx])
            f = d * (input_gain * uu - arm_length * acc)
            est.append(f)
            wts.append(len(idx))
            segments.append({"direction": name, "u": uu, "acceleration": acc,
                             "friction": f, "t0": float(t[idx[0]]), "t1": float(t[idx[-1]])})
        if not est:
            raise IdentificationError(f"no sliding run below the breakaway level in the "
                                      f"{name} direction: cannot estimate Coulomb friction")
        out[f"coulomb_{name}"] = float(np.average(est, weights=wts))
    out["stiction"] = 0.5 * (out["stiction_positive"] + out["stiction_negative"])
    out["coulomb"] = 0.5 * (out["coulomb_positive"] + out["coulomb_negative"])
    out["segments"] = segments
    out["warnings"] = warnings
    return _ordered(out, ("stiction", "coulomb", "stiction_positive", "stiction_negative",
                          "coulomb_positive", "coulomb_negative"))


def _ordered(d: dict, first: Sequence[str]) -> dict:
    return {**{k: d[k] for k in first if k in d}, **{k: v for k, v in d.items()
                                                     if k not in first}}


# ---------------------------------------------------------------------------
# E.2: the Stribeck curve
# ---------------------------------------------------------------------------

#: Default velocity references of the Stribeck test (rad/s, both signs are run).
STRIBECK_REFERENCES = (0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0)


def simulate_stribeck(cfg: Config, *, references: Sequence[float] = STRIBECK_REFERENCES,
                      gain: float = 20.0, hold: float = 2.0) -> Trajectory:
    r"""App. E.2 on the simulated rig: P control of the arm velocity.

    :math:`u = K(v_{ref} - \dot\Omega_m)` at each reference (positive ones,
    then the negative ones), each held ``hold`` s; the P loop's steady-state
    error is harmless because only the reached velocity and the steady u
    are used.
    """
    check_range("gain", gain, 0.0, 1e4, lo_open=True)
    check_range("hold", hold, 0.0, MAX_HOLD_S, lo_open=True)
    if len(references) > MAX_LEVELS:
        raise ParamError("references", f"{len(references)} values", f"at most {MAX_LEVELS}",
                         f"references: {len(references)} values, at most {MAX_LEVELS}")
    for r in references:
        check_range("references", r, -100.0, 100.0)
    refs = [r for r in references if r != 0]
    if not refs:
        raise ParamError("references", list(references), "nonzero values",
                         "references: the Stribeck test needs nonzero references")
    rec = _Recorder(cfg, theta0=math.pi, name="stribeck")
    for d in (1.0, -1.0):
        for r in sorted(abs(x) for x in refs):
            for _ in range(max(1, round(hold / rec.h))):
                meas = rec.measure()
                rec.step(gain * (d * r - meas[2]), meas)
    return rec.trajectory(experiment="stribeck")


def stribeck_model(v: np.ndarray, coulomb: float, stiction: float, viscous: float,
                   stribeck_velocity: float) -> np.ndarray:
    r"""Steady-state friction magnitude at speed :math:`|v|` (the curve of eq. 18):
    :math:`F_C + (F_S - F_C)e^{-(v/v_S)^2} + F_v|v|`."""
    a = np.abs(np.asarray(v, dtype=float))
    return stribeck_magnitude(a, coulomb, stiction, stribeck_velocity) + viscous * a


def _steady_points(t, u, v, chunk: float, v_min: float) -> np.ndarray:
    """(mean v, mean u, samples) of every steady chunk of the log.

    A chunk is steady when neither signal moves over it by more than its
    measurement noise allows: the peak-to-peak range of the arm velocity
    stays below 2 % of its level plus 8 noise standard deviations, that of u
    below 5 % plus 8 (the noise levels come from second differences of the
    whole log, which a few reference steps do not disturb).  This rejects
    the chunks holding a reference step and the transient after it.
    """
    h = float(np.median(np.diff(t)))
    n = max(8, round(chunk / h))
    # noise, and the converters' resolution (a quantised signal at rest has no second
    # differences but its steps; under a P loop u moves in steps of gain x quantum)
    tol_v = 8.0 * _noise_level(v) + 2.0 * _quantum(v) + 1e-9
    tol_u = 8.0 * _noise_level(u) + 2.0 * _quantum(u) + 1e-9
    pts = []
    for a in range(0, len(t) - n + 1, n):
        s = slice(a, a + n)
        vv, uu = v[s], u[s]
        vm, um = float(vv.mean()), float(uu.mean())
        if abs(vm) < v_min or np.mean(np.sign(vv) != np.sign(vm)) > 0.05:
            continue
        if np.ptp(vv) > 0.02 * abs(vm) + tol_v:
            continue
        if np.ptp(uu) > 0.05 * abs(um) + tol_u:
            continue
        pts.append((vm, um, n))
    return np.array(pts).reshape(-1, 3)


def _fit_stribeck(v: np.ndarray, f: np.ndarray) -> tuple[dict, list[str]]:
    """Least-squares fit of :func:`stribeck_model` to (|v|, |F|) points."""
    a, fa = np.abs(v), np.abs(f)
    order = np.argsort(a)
    a, fa = a[order], fa[order]
    hi = a >= np.median(a)
    fv0 = max(0.0, np.polyfit(a[hi], fa[hi], 1)[0]) if hi.sum() >= 2 else 0.0
    fc0 = max(1e-3, float(np.min(fa - fv0 * a)))
    fs0 = max(fc0, float(fa[0] - fv0 * a[0]))
    vs0 = max(0.1, float(a[0]))

    def res(p):
        return stribeck_model(a, *p) - fa

    lo = [0.0, 0.0, 0.0, 1e-3]
    hi_b = [np.inf, np.inf, np.inf, np.inf]
    x0 = np.clip([fc0, fs0 * 1.05 + 1e-3, fv0, vs0], np.array(lo) + 1e-9, None)
    from scipy.optimize import least_squares  # heavy import, only when used

    sol = least_squares(res, x0, bounds=(lo, hi_b), x_scale="jac")
    fc, fs, fv, vs = (float(x) for x in sol.x)
    warnings = []
    if a.min() > 3.0 * vs or fs - fc < 0.01 * fc:
        # no Stribeck rise within the measured speeds: F_S and v_S are not
        # determined; fit the Coulomb + viscous line alone
        fv, fc = (float(x) for x in np.polyfit(a, fa, 1))
        fv = max(fv, 0.0)
        warnings.append(f"no Stribeck rise above the Coulomb level at the measured speeds "
                        f"(lowest {a.min():.2g} rad/s): stiction and stribeck_velocity are "
                        "not identifiable from this curve (App. E.2 had the same "
                        "limitation); fitted Coulomb + viscous only")
        return {"coulomb": fc, "viscous": fv, "stribeck_velocity": None,
                "stiction": None}, warnings
    if a.min() > 2.0 * vs:
        warnings.append(f"no steady point below {a.min():.2g} rad/s, about twice the "
                        f"fitted Stribeck velocity {vs:.2g}: stiction and stribeck_velocity "
                        "are extrapolated (App. E.2 had the same limitation)")
    return {"coulomb": fc, "viscous": fv, "stribeck_velocity": vs, "stiction": fs}, warnings


def analyse_stribeck(log: Any, *, input_gain: float = 1.0, chunk: float = 0.25,
                     v_min: float = 0.05) -> dict:
    r"""Stribeck curve from steady velocity-control runs (App. E.2).

    The log is cut into chunks of ``chunk`` s; a chunk is steady when
    neither the measured arm velocity nor u moves over it by more than a few
    percent plus their measurement noise (see :func:`_steady_points`).
    At constant velocity eq. (5) gives friction = :math:`k_u u`; the steady
    points (both directions, as magnitudes) are fitted with
    :func:`stribeck_model` by least squares.  Per-direction fits are added
    when each direction has at least 4 steady velocities.

    Returns
    -------
    dict
        ``coulomb``, ``viscous``, ``stribeck_velocity``, ``stiction`` (the
        curve's level at zero speed), per-direction ``*_positive``/
        ``*_negative``, ``points`` ([v, friction] per steady chunk) and
        ``warnings``.
    """
    t = _time(log)
    u = _signal(log, "u")
    v = _signal(log, "arm_dot_m")
    pts = _steady_points(t, u, v, chunk, v_min)
    if len(pts) < 4:
        raise IdentificationError(f"only {len(pts)} steady chunk(s) of constant arm velocity "
                                  "in the log; the Stribeck fit needs at least 4")
    vv, ff = pts[:, 0], input_gain * pts[:, 1]
    est, warnings = _fit_stribeck(vv, ff)
    out: dict[str, Any] = dict(est)
    for d, name in ((1.0, "positive"), (-1.0, "negative")):
        sel = d * vv > 0
        speeds = np.unique(np.round(np.abs(vv[sel]), 1))
        if len(speeds) >= 4:
            e, _ = _fit_stribeck(vv[sel], ff[sel])
            for k, val in e.items():
                out[f"{k}_{name}"] = val
    out["points"] = [[float(a), float(b)] for a, b in zip(vv, ff, strict=True)]
    out["warnings"] = warnings
    return _ordered(out, ("coulomb", "viscous", "stribeck_velocity", "stiction"))


# ---------------------------------------------------------------------------
# A.1-A.2: free oscillation about the downward position
# ---------------------------------------------------------------------------


def simulate_free_oscillation(cfg: Config, *, amplitude: float = 0.25,
                              duration: float = 12.0) -> Trajectory:
    """App. A.1 on the simulated rig: arm held, pendulum released from
    ``amplitude`` rad beside the downward position, u = 0.

    With the arm at rest and u = 0 no force reaches the arm (the model's arm
    is driven by u alone), so the arm stays held and the pendulum swings
    about theta = pi as eq. (22) describes, including the nonlinearity of
    eq. (6) at larger amplitudes.
    """
    if not 0 < abs(amplitude) < 1.5:
        raise ParamError("amplitude", amplitude, "0 < |amplitude| < 1.5 rad",
                         f"amplitude must be in (0, 1.5) rad, got {amplitude:g}")
    check_range("duration", duration, 0.0, MAX_EXPERIMENT_S, lo_open=True)
    rec = _Recorder(cfg, theta0=math.pi + amplitude, name="free-oscillation")
    rec.hold(0.0, duration)
    return rec.trajectory(experiment="free-oscillation")


def _parabolic_peak(y: np.ndarray, i: int) -> tuple[float, float]:
    """Sub-sample offset and height of a maximum at sample i (parabola through 3 points)."""
    if i <= 0 or i >= len(y) - 1:
        return 0.0, float(y[i])
    a, b, c = y[i - 1], y[i], y[i + 1]
    den = a - 2 * b + c
    if den >= 0:
        return 0.0, float(b)
    off = 0.5 * (a - c) / den
    return float(off), float(b - 0.25 * (a - c) * off)


def analyse_free_oscillation(log: Any, *, max_amplitude: float = 0.15,
                             min_amplitude: float | None = None) -> dict:
    r"""Natural frequency and damping from damped free oscillations (App. A.1-A.2).

    1. The rest angle :math:`\theta_0` is the median of the measured angle.
    2. Peaks of :math:`\theta - \theta_0` between ``min_amplitude`` (default
       3 noise standard deviations, at least 0.005 rad) and
       ``max_amplitude`` (the thesis discarded peaks above 0.15 rad as
       nonlinear) are located with sub-sample (parabolic) precision.
    3. Eq. (24): :math:`\omega_d = 2\pi/T` with T the mean peak spacing;
       eq. (25): the log of the peak heights is fitted by a straight line of
       slope :math:`-\zeta\omega_0`; then
       :math:`\omega_0 = \sqrt{\omega_d^2 + (\zeta\omega_0)^2}` (eq. 23).
    4. Refinement: eq. (22) (:math:`\theta_0 + A e^{-\sigma t}\cos(\omega_d t +
       \phi)`) is fitted by least squares to the samples between the first
       and the last used peak, which uses every sample rather than the
       peaks alone.

    Returns
    -------
    dict
        ``omega0``, ``zeta`` (refined), ``omega0_peaks``, ``zeta_peaks``
        (steps 1-3, the thesis's method), ``period``, ``rest_angle``,
        ``peaks`` ([t, height] of the used peaks), ``warnings`` (e.g. peak
        heights that grow instead of decaying: zeta is then 0).
    """
    t = _time(log)
    y = _signal(log, "theta_m")
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    sig = _noise_level(y)
    min_amp = max(0.005, 3.0 * sig) if min_amplitude is None else min_amplitude
    theta0 = float(np.median(y))
    d = y - theta0
    ys = d
    if sig > 0:
        from scipy.ndimage import uniform_filter1d

        ys = uniform_filter1d(d, size=5, mode="nearest")
    from scipy.signal import find_peaks  # heavy import, only when used

    h = float(np.median(np.diff(t)))
    idx, _ = find_peaks(ys, prominence=max(min_amp, 6.0 * sig), distance=max(1, int(0.1 / h)))
    pk_t, pk_y = [], []
    for i in idx:
        off, hy = _parabolic_peak(ys, int(i))
        if min_amp <= hy <= max_amplitude:
            pk_t.append(t[i] + off * h)
            pk_y.append(hy)
    if len(pk_t) < 3:
        raise IdentificationError(
            f"only {len(pk_t)} oscillation peak(s) between {min_amp:.3g} and "
            f"{max_amplitude:g} rad; need at least 3 (is the pendulum swinging freely?)")
    pk_t, pk_y = np.array(pk_t), np.array(pk_y)
    period = float(np.mean(np.diff(pk_t)))
    wd = 2.0 * math.pi / period
    slope, _, _ = _slope(pk_t, np.log(pk_y))
    warnings = []
    if slope > 0:
        warnings.append(
            f"the oscillation grows (peak heights rise by {100 * math.expm1(slope * period):.2g} "
            "% per period), so it is not a free decay (is the arm held, and nothing driving "
            "the pendulum?): zeta is reported as 0")
    sigma = max(0.0, -slope)
    w0_pk = math.hypot(wd, sigma)
    out = {"omega0_peaks": w0_pk, "zeta_peaks": sigma / w0_pk}
    # refinement on the samples spanning the used peaks
    m = (t >= pk_t[0] - 0.5 * period) & (t <= pk_t[-1] + 0.5 * period)
    tt, yy = t[m] - pk_t[0], y[m]

    def model(p):
        c0, amp, s, w, ph = p
        return c0 + amp * np.exp(-s * tt) * np.cos(w * tt + ph)

    p0 = [theta0, pk_y[0], sigma, wd, 0.0]
    from scipy.optimize import least_squares

    sol = least_squares(lambda p: model(p) - yy, p0, x_scale="jac")
    c0, _amp, s, w, _ = sol.x
    w, s = abs(float(w)), float(s)
    if sol.success and abs(w - wd) < 0.1 * wd and s >= 0:
        w0 = math.hypot(w, s)
        out = {"omega0": w0, "zeta": s / w0, **out, "rest_angle": float(c0)}
    else:
        out = {"omega0": w0_pk, "zeta": sigma / w0_pk, **out, "rest_angle": theta0}
    out["period"] = 2.0 * math.pi / (out["omega0"] * math.sqrt(max(0.0, 1 - out["zeta"] ** 2)))
    out["peaks"] = [[float(a), float(b)] for a, b in zip(pk_t, pk_y, strict=True)]
    out["warnings"] = warnings
    return out


# ---------------------------------------------------------------------------
# B.4: the control scaling
# ---------------------------------------------------------------------------

#: Default constant control signals of the scaling test (m/s^2 of u).
SCALING_LEVELS = (3.0, 4.0, 5.0, 7.0, 9.0)


def simulate_control_scaling(cfg: Config, *, levels: Sequence[float] = SCALING_LEVELS,
                             v_stop: float = 4.0, limit: float = 3.0) -> Trajectory:
    """App. B.4 on the simulated rig: from rest, constant u until the arm
    exceeds ``v_stop`` rad/s (at most ``limit`` s), then u = 0 until it stops;
    once per level (the thesis used four negative u_DA, i.e. positive
    arm velocities)."""
    if len(levels) > MAX_LEVELS:
        raise ParamError("levels", f"{len(levels)} values", f"at most {MAX_LEVELS}",
                         f"levels: {len(levels)} values, at most {MAX_LEVELS}")
    for lv in levels:
        check_range("levels", lv, -100.0, 100.0)
        if lv == 0:
            raise ParamError("levels", lv, "nonzero", "control-scaling levels must be nonzero")
    rec = _Recorder(cfg, theta0=math.pi, name="control-scaling")
    rec.hold(0.0, 0.3)
    for lv in levels:
        n = 0
        while abs(rec.arm_dot) < v_stop and n * rec.h < limit:
            rec.step(lv)
            n += 1
        _coast(rec)
    return rec.trajectory(experiment="control-scaling")


def analyse_control_scaling(log: Any, *, coulomb: float = 1.5, arm_length: float = 0.21,
                            v_range: tuple[float, float] = (0.1, 3.0),
                            nominal_u_scale: float | None = None) -> dict:
    r"""Control scaling :math:`k_u` from constant-u accelerations (App. B.4, eq. 26).

    For each run of constant nonzero u, the measured arm velocity in
    ``v_range`` (the thesis fitted :math:`\dot\Omega\in[0, 3]` rad/s; the
    lower limit keeps the in-band breakaway out) in the direction of u is
    fitted with a straight line: slope :math:`\ddot\Omega`.  With the known
    Coulomb friction :math:`F_C` (``friction.coulomb``) eq. (26) in this
    package's units, :math:`L_1\ddot\Omega = k_u u - F_C\,\mathrm{sgn}\,\dot\Omega`,
    gives :math:`k_u = (L_1\ddot\Omega + F_C)/|u|` per level; the estimate
    is their least-squares combination.  A regression of
    :math:`L_1\ddot\Omega` on u with free intercept gives :math:`k_u` and
    :math:`F_C` without the prior (``input_gain_free``, ``coulomb_free``).

    Returns
    -------
    dict
        ``input_gain`` (the plant's :math:`k_u`), ``u_scale`` (the DAC
        scaling that would make it 1: the nominal App. B value -0.022
        divided by ``input_gain``), ``levels`` (u, acceleration, k_u per
        run), ``input_gain_free``, ``coulomb_free``.
    """
    t = _time(log)
    u = _signal(log, "u")
    v = _signal(log, "arm_dot_m")
    rows = []
    for a, b in _runs(u):
        uu = float(u[a])
        if uu == 0:
            continue
        d = math.copysign(1.0, uu)
        idx = np.arange(a, b)
        sel = idx[(d * v[idx] >= v_range[0]) & (d * v[idx] <= v_range[1])]
        if len(sel) < 6:
            continue
        acc, _, _ = _slope(t[sel], v[sel])
        acc = d * acc
        rows.append({"u": uu, "acceleration": acc,
                     "input_gain": (arm_length * acc + coulomb) / abs(uu)})
    if not rows:
        raise IdentificationError(
            f"no run of constant u with the arm speeding through {v_range[0]:g}.."
            f"{v_range[1]:g} rad/s in its direction: nothing to fit")
    uu = np.array([abs(r["u"]) for r in rows])
    la = np.array([arm_length * r["acceleration"] for r in rows])
    k = float(np.sum(uu * (la + coulomb)) / np.sum(uu * uu))
    nominal = RigScaling().u_scale if nominal_u_scale is None else nominal_u_scale
    out: dict[str, Any] = {"input_gain": k, "u_scale": nominal / k, "levels": rows}
    if len(np.unique(uu)) >= 2:
        slope, icpt = np.polyfit(uu, la, 1)
        out["input_gain_free"] = float(slope)
        out["coulomb_free"] = float(-icpt)
    return out


# ---------------------------------------------------------------------------
# B.3: the arm-velocity channel
# ---------------------------------------------------------------------------


def analyse_velocity_scale(log: Any, *, chunk: float = 0.25, v_min: float = 0.5) -> dict:
    r"""Scale and bias of the arm-velocity channel (App. B.3).

    The arm angle :math:`\Omega` (``arm_m``, whose scale ``rig.arm_scale`` is
    known from App. B.2) gives the true arm velocity; the raw velocity
    channel ``v`` is compared with it at several steady speeds.  The log is
    cut into chunks of ``chunk`` s of time (ticks the loop missed leave gaps;
    a chunk counts if it holds at least half its samples); in each the
    velocity is the slope of a straight line fitted to :math:`\Omega(t)` and the raw reading is the
    mean of ``v``.  A chunk counts when the arm moves faster than ``v_min``
    rad/s, the raw reading is steady (its range below 3 % of its level plus
    8 noise standard deviations) and the line fits (residual below 2 % of
    the distance travelled plus the angle's noise).  A straight line through
    the (raw, velocity) points of both directions, velocity =
    :math:`s(v + b)`, gives the scale s (``velocity_scale``) and bias b
    (``velocity_bias``) in the convention of ``rig.velocity_scale`` and
    ``rig.velocity_bias``.

    Returns
    -------
    dict
        ``velocity_scale``, ``velocity_bias``, ``points`` ([raw v, velocity]
        per chunk), ``residual_rms`` (rad/s), ``warnings``.
    """
    t = _time(log)
    arm = _signal(log, "arm_m")
    v = _signal(log, "v")
    ok = np.isfinite(t) & np.isfinite(arm) & np.isfinite(v)
    t, arm, v = t[ok], arm[ok], v[ok]
    if len(t) < 16:
        raise IdentificationError("the log is too short for the velocity-scale analysis")
    h = float(np.median(np.diff(t)))
    n = max(8, round(chunk / h))
    sig_v, sig_a = _noise_level(v), _noise_level(arm)
    pts = []
    # chunks of time, not of samples: ticks a stalled host made the loop miss leave gaps
    # in the log; the line is fitted to the samples' own times, so a chunk with gaps
    # counts when at least half its samples are there
    edges = np.searchsorted(t, np.arange(t[0], t[-1] + h, n * h) - 0.5 * h)
    for a, b in itertools.pairwise(edges):
        if b - a < max(8, n // 2):
            continue
        tt, aa, vv = t[a:b], arm[a:b], v[a:b]
        vel, icpt, _ = _slope(tt, aa)
        vm = float(vv.mean())
        if abs(vel) < v_min:
            continue
        if np.ptp(vv) > 0.03 * abs(vm) + 8.0 * sig_v + 1e-9:
            continue
        res = aa - (vel * tt + icpt)
        if float(np.sqrt(np.mean(res * res))) > 0.02 * abs(vel) * (tt[-1] - tt[0]) + 3 * sig_a:
            continue
        pts.append((vm, vel))
    if len(pts) < 4:
        raise IdentificationError(f"only {len(pts)} steady chunk(s) of arm motion faster "
                                  f"than {v_min:g} rad/s; the velocity-scale fit needs at "
                                  "least 4")
    p = np.array(pts)
    warnings = []
    if not (p[:, 1].min() < 0 < p[:, 1].max()):
        warnings.append("steady motion in one direction only: the bias is extrapolated")
    slope, icpt = np.polyfit(p[:, 0], p[:, 1], 1)
    res = p[:, 1] - (slope * p[:, 0] + icpt)
    return {"velocity_scale": float(slope), "velocity_bias": float(icpt / slope),
            "residual_rms": float(np.sqrt(np.mean(res * res))),
            "points": [[float(a), float(b)] for a, b in p], "warnings": warnings}


# ---------------------------------------------------------------------------
# B.1, B.2: the angle channels (a lap by hand)
# ---------------------------------------------------------------------------


def _unwrap_raw(r: np.ndarray) -> np.ndarray:
    """Undo the +-1 wrap-around of a raw angle channel (jumps of more than 1)."""
    d = np.diff(r)
    steps = np.where(d > 1.0, -2.0, np.where(d < -1.0, 2.0, 0.0))
    return r + np.concatenate([[0.0], np.cumsum(steps)])


def analyse_angle_scales(log: Any, marks: Mapping[str, float]) -> dict:
    r"""Scale and bias of the pendulum angle and scale of the arm angle (App. B.1, B.2).

    The log is the guided ``angle-scales`` run: the pendulum hanging at rest
    (``pendulum_before_*`` marks), one lap by hand, hanging at rest again
    (``pendulum_after_*``), then the arm turned exactly one lap and held
    (``arm_after_*``).  The raw channels are unwrapped (a jump of more than 1
    is the converter's wrap-around, 2 units); a lap is :math:`2\pi` rad, so

    * ``theta_scale`` = :math:`2\pi/|\Delta y|`,
    * ``theta_bias``: the hanging pendulum is at :math:`	heta = \pi`, so
      :math:`b = \pi/s_	heta - y_{hang}`, wrapped into [-1, 1) (the
      convention of ``rig.theta_bias``: :math:`	heta = s_	heta(y + b)`),
    * ``arm_scale`` = :math:`2\pi/|\Delta x|` (x before the arm's lap: its
      rest during ``pendulum_after``).

    Returns
    -------
    dict
        ``theta_scale``, ``theta_bias``, ``arm_scale``, ``pendulum_lap_raw``,
        ``arm_lap_raw``, ``warnings``.
    """
    t = _time(log)
    y = _unwrap_raw(_signal(log, "y"))
    x = _unwrap_raw(_signal(log, "x"))
    need = ("pendulum_before_start", "pendulum_before_end", "pendulum_after_start",
            "pendulum_after_end", "arm_after_start", "arm_after_end")
    missing = [k for k in need if k not in marks]
    if missing:
        raise IdentificationError(f"the run has no {missing[0]!r} mark (is it a complete "
                                  "angle-scales run? its sidecar holds the marks)")

    def mean(sig, a, b):
        sel = (t >= marks[a]) & (t <= marks[b])
        if not sel.any():
            raise IdentificationError(f"no samples between the marks {a} and {b}")
        return float(sig[sel].mean())

    y0 = mean(y, "pendulum_before_start", "pendulum_before_end")
    y1 = mean(y, "pendulum_after_start", "pendulum_after_end")
    x0 = mean(x, "pendulum_after_start", "pendulum_after_end")
    x1 = mean(x, "arm_after_start", "arm_after_end")
    span_y, span_x = y1 - y0, x1 - x0
    if abs(span_y) < 0.5 or abs(span_x) < 1e-3:
        raise IdentificationError("no lap in the log (the readings before and after hardly "
                                  "differ)")
    ts = 2.0 * math.pi / abs(span_y)
    y_hang = (y0 + 1.0) % 2.0 - 1.0
    tb = (math.pi / ts - y_hang + 1.0) % 2.0 - 1.0
    return {"theta_scale": ts, "theta_bias": tb, "arm_scale": 2.0 * math.pi / abs(span_x),
            "pendulum_lap_raw": span_y, "arm_lap_raw": span_x, "warnings": []}


def estimates_only(result: Mapping[str, Any]) -> dict[str, float]:
    """The scalar estimates of an analysis result (for printing)."""
    return {k: v for k, v in result.items() if isinstance(v, float)}
