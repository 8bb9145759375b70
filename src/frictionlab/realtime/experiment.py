r"""Identification experiments as controllers of the real-time loop (App. A, B, E).

An experiment takes the balancing controller's place in the loop
(:class:`~.loop.Loop` ``experiment=``): in every tick with a reading the loop
calls :meth:`RigExperiment.step` with the measured signals (SI, and the raw
``y, x, v``) and writes the u it returns, with the same timing, safety
checks, stop handling (u_DA = 0 in the tick that detects a fault, a signal
or a stop request) and logging as a balancing run.  Only the ``not_upright``
and ``angle_limit`` checks are off: the pendulum hangs or swings freely.

The schedules (a reference or u held for a while, P velocity and position
loops) are the thesis's experiments:

==================  ===========================================================
``stiction``        App. E.1: a staircase of constant u in each direction until
                    the arm breaks away; then, per Coulomb level and in each
                    direction in turn, a short motor push to ``push`` rad/s and
                    a constant u below the breakaway level while the arm slides
                    (it decelerates below the Coulomb level and keeps going
                    above it)
``stribeck``        App. E.2: a P velocity loop
                    :math:`u = K(v_{ref} - \dot\Omega_m)` at each reference,
                    alternately positive and negative
``free-oscillation`` App. A: the arm held by a PD position loop while the
                    pendulum hangs; a square-wave arm reference at the expected
                    pendulum frequency sets it swinging up to ``amplitude``,
                    then the reference stays 0 and the free decay is recorded
``control-scaling`` App. B.4: constant u (so constant u_DA) from rest until the
                    arm reaches ``v_stop`` rad/s, then u = 0 until it stops,
                    alternating directions
``velocity-scale``  App. B.3: a P velocity loop at a few references of both
                    signs; the arm angle (its scale known) gives the true
                    velocity that the raw velocity channel is compared with
``angle-scales``    App. B.1/B.2, guided: the motor stays off; the operator is
                    asked to turn the pendulum one lap (hanging to hanging)
                    and then the arm exactly one lap; the experiment waits
                    for each (at most ``wait`` s) and the raw readings before
                    and after give ``rig.theta_scale``, ``rig.theta_bias``
                    and ``rig.arm_scale``
==================  ===========================================================

Guided steps: an instruction for the operator is appended to
:attr:`RigExperiment.prompts` (``{"text": ..., "hand": {...}}``, where
``hand`` is what ``rig-sim``'s emulated hand would do, :data:`.rigsim.HAND`);
the runner prints it and, against ``rig-sim``, may play the hand.

Limits (:class:`Limits`): the experiment stops with reason
``experiment_limit`` when the measured arm speed exceeds ``max_speed`` or the
arm is more than ``max_travel`` from where it started; u is clipped so that
:math:`|u_{DA}|` stays within ``max_u_da``.  A schedule that ends stops the
run with reason ``finished``.

Progress: :attr:`RigExperiment.progress` (0..1) and :attr:`RigExperiment.phase`
(text) are updated by the tick and may be read from any thread;
:attr:`RigExperiment.marks` holds named times (s from the start of the run)
the analysis uses, e.g. where the free decay starts.

Each schedule is a generator that yields the u of one tick and reads the
latest measurement from the experiment's attributes (``t``, ``theta``,
``arm``, ``arm_dot``, ``y``, ``x``, ``v``); it allocates no reference cycles
per tick.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from ..model.params import ParamError, Validated, check_range, param
from ..model.rig import RigScaling
from ..model.sensor import unwrap, wrap_angle
from .loop import ExperimentEnd

__all__ = [
    "EXPERIMENT_CLASSES",
    "AngleScales",
    "ControlScaling",
    "FreeOscillation",
    "Limits",
    "RigExperiment",
    "Stiction",
    "Stribeck",
    "VelocityScale",
    "make_experiment",
]

#: Default velocity references of the Stribeck test (rad/s, both signs are run).
STRIBECK_REFERENCES = (0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0)
#: Default constant u of the control-scaling test (m/s^2; alternating signs).
SCALING_LEVELS = (3.0, 4.0, 5.0, 7.0, 9.0)
#: Default velocity references of the velocity-scale test (rad/s; both signs).
VELOCITY_REFERENCES = (1.5, 3.0, 4.5, 6.0)
#: Most levels or references of one experiment.
MAX_LEVELS = 100

# the sensor model's laws as plain Python (called per tick; no dispatch)
_wrap_angle = wrap_angle.py_func
_unwrap = unwrap.py_func


@dataclass(frozen=True)
class Limits(Validated):
    """What an experiment may do with the rig (checked in every tick)."""

    _prefix = "limits."

    max_speed: float = param(15.0, "stop (experiment_limit) when the measured arm speed "
                             "exceeds this", "rad/s", lo=0.0, hi=100.0, lo_open=True)
    max_travel: float = param(60.0, "stop (experiment_limit) when the arm is farther than "
                              "this from where it started", "rad", lo=0.0, lo_open=True)
    max_u_da: float = param(0.5, "largest |u_DA| the experiment commands (u is clipped)",
                            "1", lo=0.0, hi=1.0, lo_open=True)


class RigExperiment(ABC):
    """Base of the experiments: limits, progress, the generator schedule.

    Parameters
    ----------
    h : float
        Sampling period (s).
    u_scale : float, optional
        k_u of App. B (``rig.u_scale``): u_DA per m/s^2, for the u_DA limit
        (default :class:`~frictionlab.model.rig.RigScaling`'s).
    limits : Limits, optional
    """

    name = "experiment"
    #: Signals the analysis needs (log columns).
    signals: tuple[str, ...] = ("t", "u", "arm_dot_m")
    #: Whether the schedule reads the raw ``y, x, v`` (a runner that has only the SI
    #: signals at hand may pass NaN for them otherwise).
    reads_raw = False

    def __init__(self, h: float, u_scale: float | None = None, limits: Limits | None = None):
        self.h = float(h)
        self.limits = limits or Limits()
        if u_scale is None:
            u_scale = RigScaling().u_scale
        self.u_max = self.limits.max_u_da / abs(u_scale)
        self.progress = 0.0
        self.phase = "waiting for the first reading"
        self.marks: dict[str, float] = {}
        self._gen: Iterator[float] | None = None
        self.prompts: deque[dict] = deque()
        self.t = self.theta = self.arm = self.arm_dot = 0.0
        self.y = self.x = self.v = 0.0
        self.arm0 = 0.0
        self.theta0 = 0.0

    # --- the loop's side -----------------------------------------------------------

    def step(self, t: float, theta: float, arm: float, arm_dot: float, y: float, x: float,
             v: float) -> float:
        """The u (m/s^2) of this tick; raises :class:`ExperimentEnd` to stop."""
        lim = self.limits
        if self._gen is None:
            self.arm0 = arm
            self.theta0 = theta
            self._gen = self.schedule()
        if not abs(arm_dot) <= lim.max_speed:
            raise ExperimentEnd("experiment_limit", f"arm speed {abs(arm_dot):.3g} rad/s > "
                                f"the limit {lim.max_speed:g} rad/s ({self.phase})")
        if not abs(arm - self.arm0) <= lim.max_travel:
            raise ExperimentEnd("experiment_limit", f"the arm moved {abs(arm - self.arm0):.3g}"
                                f" rad from its start > the limit {lim.max_travel:g} rad "
                                f"({self.phase})")
        self.t, self.theta, self.arm, self.arm_dot = t, theta, arm, arm_dot
        self.y, self.x, self.v = y, x, v
        try:
            u = next(self._gen)
        except StopIteration:
            self.progress = 1.0
            self.phase = "done"
            raise ExperimentEnd("finished", f"the {self.name} experiment is done") from None
        um = self.u_max
        if u > um:
            return um
        if u < -um:
            return -um
        return u

    def describe(self) -> dict:
        """JSON-ready settings (the run's sidecar)."""
        return {"name": self.name, "limits": {"max_speed": self.limits.max_speed,
                                              "max_travel": self.limits.max_travel,
                                              "max_u_da": self.limits.max_u_da},
                "marks": dict(self.marks)}

    # --- building blocks of the schedules ----------------------------------------------

    @abstractmethod
    def schedule(self) -> Iterator[float]:
        """The experiment's u, one value per tick (a generator built from the
        building blocks below); each experiment defines it."""

    def _ticks(self, seconds: float) -> int:
        return max(1, round(seconds / self.h))

    def hold(self, u: float, seconds: float) -> Iterator[float]:
        """Constant u for ``seconds``."""
        for _ in range(self._ticks(seconds)):
            yield u

    def coast(self, v_rest: float = 0.05, limit: float = 5.0, after: float = 0.3):
        """u = 0 until the arm has (nearly) stopped (at most ``limit`` s), then ``after`` s."""
        n = 0
        while abs(self.arm_dot) > v_rest and n * self.h < limit:
            n += 1
            yield 0.0
        yield from self.hold(0.0, after)

    def velocity_loop(self, ref: float, gain: float, seconds: float) -> Iterator[float]:
        r"""P velocity loop :math:`u = K(v_{ref} - \dot\Omega_m)` for ``seconds``."""
        for _ in range(self._ticks(seconds)):
            yield gain * (ref - self.arm_dot)


def _levels(what: str, values: Sequence[float], *, positive: bool = False) -> list[float]:
    if len(values) > MAX_LEVELS:
        raise ParamError(what, f"{len(values)} values", f"at most {MAX_LEVELS}",
                         f"{what}: {len(values)} values, at most {MAX_LEVELS}")
    out = []
    for val in values:
        check_range(what, val, -100.0, 100.0)
        if val != 0:
            out.append(abs(val) if positive else float(val))
    if not out:
        raise ParamError(what, list(values), "nonzero values", f"{what}: give nonzero values")
    return out


class Stiction(RigExperiment):
    """App. E.1: breakaway staircase both directions, then Coulomb slides after a push.

    Parameters
    ----------
    step, hold : float
        Staircase increment of u (m/s^2) and how long each level is held (s).
    coulomb_levels : sequence of float
        Fractions of the breakaway level held while the arm slides.
    push : float
        Arm speed (rad/s) the motor's push gives before each slide.
    slide : float
        Seconds each Coulomb level is held.
    v_detect : float
        Arm speed (rad/s) that counts as breakaway.
    """

    name = "stiction"

    def __init__(self, h, u_scale=None, limits=None, *, step: float = 0.02,
                 hold: float = 0.25,
                 coulomb_levels: Sequence[float] = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
                 push: float = 1.5, slide: float = 0.8, v_detect: float = 0.1):
        super().__init__(h, u_scale, limits)
        check_range("step", step, 0.0, 100.0, lo_open=True)
        check_range("hold", hold, 0.0, 60.0, lo_open=True)
        check_range("push", push, 0.0, 50.0, lo_open=True)
        check_range("slide", slide, 0.0, 60.0, lo_open=True)
        for c in coulomb_levels:
            check_range("coulomb_levels", c, 0.0, 1.0, lo_open=True, hi_open=True)
        self.step_u, self.hold_s = float(step), float(hold)
        self.coulomb_levels = tuple(float(c) for c in coulomb_levels)
        self.push, self.slide, self.v_detect = float(push), float(slide), float(v_detect)
        self.breakaway: dict[float, float] = {}

    def schedule(self):
        self.phase = "at rest"
        yield from self.hold(0.0, 0.5)
        n_trials = 2 + 2 * len(self.coulomb_levels)
        done = 0
        for d in (1.0, -1.0):
            self.phase = f"staircase, {'positive' if d > 0 else 'negative'} direction"
            level = 0.0
            moved = False
            while not moved:
                level = round(level + self.step_u, 12)
                if level > self.u_max:
                    raise ExperimentEnd("experiment_limit", f"no breakaway up to |u| = "
                                        f"{self.u_max:.3g} (the u_DA limit "
                                        f"{self.limits.max_u_da:g})")
                self.phase = (f"staircase, {'positive' if d > 0 else 'negative'} direction, "
                              f"u = {d * level:.3g}")
                for _ in range(self._ticks(self.hold_s)):
                    yield d * level
                    if d * self.arm_dot > self.v_detect:
                        moved = True
            self.breakaway[d] = level
            self.marks[f"breakaway_{'positive' if d > 0 else 'negative'}"] = self.t
            yield from self.hold(d * level, 0.1)
            yield from self.coast()
            done += 1
            self.progress = done / n_trials
        # each level in both directions before the next: the arm's travel stays
        # within a slide or two of its start
        for c in self.coulomb_levels:
            for d in (1.0, -1.0):
                self.phase = (f"Coulomb slide, {'positive' if d > 0 else 'negative'} "
                              f"direction, {c:g} x breakaway")
                # the push: the motor accelerates the arm to the push speed
                kick = d * min(self.u_max, 2.0 * self.breakaway[d] + 1.0)
                n = 0
                while d * self.arm_dot < self.push and n * self.h < 2.0:
                    n += 1
                    yield kick
                yield from self.hold(d * c * self.breakaway[d], self.slide)
                yield from self.coast()
                done += 1
                self.progress = done / n_trials


class Stribeck(RigExperiment):
    """App. E.2: a P velocity loop at each reference, alternately +r and -r."""

    name = "stribeck"

    def __init__(self, h, u_scale=None, limits=None, *,
                 references: Sequence[float] = STRIBECK_REFERENCES, gain: float = 20.0,
                 hold: float = 2.0):
        super().__init__(h, u_scale, limits)
        check_range("gain", gain, 0.0, 1e4, lo_open=True)
        check_range("hold", hold, 0.0, 60.0, lo_open=True)
        self.references = sorted(_levels("references", references, positive=True))
        self.gain, self.hold_s = float(gain), float(hold)

    def schedule(self):
        n = 2 * len(self.references)
        i = 0
        for r in self.references:
            for d in (1.0, -1.0):
                self.phase = f"velocity loop at {d * r:g} rad/s"
                yield from self.velocity_loop(d * r, self.gain, self.hold_s)
                i += 1
                self.progress = i / n
        self.phase = "stopping"
        yield from self.coast()


class FreeOscillation(RigExperiment):
    r"""App. A: arm held by a PD position loop, pendulum hanging, set swinging, free decay.

    Parameters
    ----------
    omega0 : float
        Expected pendulum frequency (rad/s; ``design.omega0``): the arm
        reference is a square wave of this frequency until the pendulum swings
        with ``amplitude`` rad (at most ``max_cycles`` periods).
    amplitude : float
        Swing to reach before the free decay (rad, below the analysis's
        0.15 rad).
    excite : float
        Amplitude of the arm reference's square wave (rad).
    duration : float
        Seconds of free decay recorded.
    kp, kd : float
        Position loop :math:`u = k_p(\Omega_{ref} - \Omega) - k_d\dot\Omega`.
    """

    name = "free-oscillation"
    signals = ("t", "theta_m")

    def __init__(self, h, u_scale=None, limits=None, *, omega0: float = 6.8,
                 amplitude: float = 0.12, excite: float = 0.05, duration: float = 12.0,
                 kp: float = 60.0, kd: float = 4.0, max_cycles: int = 20):
        super().__init__(h, u_scale, limits)
        check_range("omega0", omega0, 0.5, 100.0)
        if not 0 < amplitude < 1.5:
            raise ParamError("amplitude", amplitude, "0 < amplitude < 1.5 rad",
                             f"amplitude must be in (0, 1.5) rad, got {amplitude:g}")
        check_range("excite", excite, 0.0, 1.0, lo_open=True)
        check_range("duration", duration, 0.0, 1800.0, lo_open=True)
        self.omega0, self.amplitude, self.excite = float(omega0), float(amplitude), float(excite)
        self.duration, self.kp, self.kd = float(duration), float(kp), float(kd)
        self.max_cycles = int(max_cycles)

    def _deflection(self) -> float:
        return _wrap_angle(self.theta - self.theta0)

    def _pd(self, ref: float) -> float:
        return self.kp * (ref - (self.arm - self.arm0)) - self.kd * self.arm_dot

    def schedule(self):
        self.phase = "arm held, pendulum settling"
        for _ in range(self._ticks(1.0)):
            yield self._pd(0.0)
        period = 2.0 * math.pi / self.omega0
        n_half = self._ticks(period / 2)
        peak = 0.0
        self.phase = "setting the pendulum swinging"
        for cycle in range(self.max_cycles):
            for half in (1.0, -1.0):
                for _ in range(n_half):
                    peak = max(peak, abs(self._deflection()))
                    yield self._pd(half * self.excite)
            self.progress = 0.2 * (cycle + 1) / self.max_cycles
            if peak >= self.amplitude:
                break
            peak = 0.0
        self.phase = "arm held, pendulum swinging freely"
        for _ in range(self._ticks(0.5)):
            yield self._pd(0.0)
        self.marks["free"] = self.t + self.h
        n = self._ticks(self.duration)
        for i in range(n):
            yield self._pd(0.0)
            if i % 50 == 0:
                self.progress = 0.2 + 0.8 * i / n


class ControlScaling(RigExperiment):
    """App. B.4: constant u from rest until ``v_stop`` rad/s, alternating directions."""

    name = "control-scaling"

    def __init__(self, h, u_scale=None, limits=None, *,
                 levels: Sequence[float] = SCALING_LEVELS, v_stop: float = 4.0,
                 limit: float = 3.0):
        super().__init__(h, u_scale, limits)
        self.levels = _levels("levels", levels)
        check_range("v_stop", v_stop, 0.0, 100.0, lo_open=True)
        check_range("limit", limit, 0.0, 60.0, lo_open=True)
        self.v_stop, self.limit = float(v_stop), float(limit)

    def schedule(self):
        self.phase = "at rest"
        yield from self.hold(0.0, 0.3)
        for i, lv in enumerate(self.levels):
            u = lv if i % 2 == 0 else -lv
            self.phase = f"constant u = {u:g}"
            n = 0
            while abs(self.arm_dot) < self.v_stop and n * self.h < self.limit:
                n += 1
                yield u
            self.phase = "coasting"
            yield from self.coast()
            self.progress = (i + 1) / len(self.levels)


class VelocityScale(Stribeck):
    """App. B.3: P velocity loop at ``references`` (each +r then -r), held ``hold`` s
    (the schedule of :class:`Stribeck`, its own references and signals)."""

    name = "velocity-scale"
    signals = ("t", "arm_m", "v")

    def __init__(self, h, u_scale=None, limits=None, *,
                 references: Sequence[float] = VELOCITY_REFERENCES, gain: float = 20.0,
                 hold: float = 2.0):
        super().__init__(h, u_scale, limits, references=references, gain=gain, hold=hold)


class AngleScales(RigExperiment):
    """App. B.1/B.2 as guided steps: a lap of the pendulum, then one of the arm, by hand.

    The motor stays off (u = 0).  Each step waits for the reading to change by
    more than ``min_change`` of a lap and come to rest again (its range over
    ``settle`` s below ``rest_band``), at most ``wait`` s; the readings at
    rest before and after are marked for the analysis
    (:func:`frictionlab.studies.identification.experiments.analyse_angle_scales`).

    Parameters
    ----------
    wait : float
        Longest wait for the operator per step (s); then ``experiment_limit``.
    settle : float
        Seconds of rest that end a step.
    lap_seconds : float
        How long the emulated hand takes for a lap (``rig-sim`` only).
    """

    name = "angle-scales"
    signals = ("t", "y", "x")
    reads_raw = True

    def __init__(self, h, u_scale=None, limits=None, *, wait: float = 120.0,
                 settle: float = 1.0, lap_seconds: float = 2.0):
        super().__init__(h, u_scale, limits)
        check_range("wait", wait, 1.0, 3600.0)
        check_range("settle", settle, 0.1, 10.0)
        check_range("lap_seconds", lap_seconds, 0.05, 60.0)
        self.wait, self.settle, self.lap_seconds = float(wait), float(settle), float(lap_seconds)

    def _rest(self, raw: str, band: float, moved_from: float | None, min_change: float):
        """u = 0 until the unwrapped raw reading ``raw`` ('y' or 'x') has moved more than
        ``min_change`` from ``moved_from`` (None: no move needed) and then stayed within
        ``band`` for ``settle`` s.  Marks ``<raw>_rest<i>_start/_end``."""
        n_settle = self._ticks(self.settle)
        window: deque[float] = deque(maxlen=n_settle)
        prev = getattr(self, raw)
        wraps = 0
        n = 0
        moved = moved_from is None
        limit = self._ticks(self.wait)
        while True:
            cur = getattr(self, raw)
            wraps = _unwrap(prev, cur, wraps)
            prev = cur
            val = cur + 2.0 * wraps
            window.append(val)
            if not moved and abs(val - moved_from) > min_change:
                moved = True
                window.clear()
            if moved and len(window) == n_settle and max(window) - min(window) <= band:
                return sum(window) / len(window), wraps
            n += 1
            if n > limit:
                raise ExperimentEnd("experiment_limit", f"the operator did not finish in "
                                    f"{self.wait:g} s ({self.phase})")
            yield 0.0

    def schedule(self):
        self.phase = "let the pendulum hang still and the arm rest"
        t0 = self.t
        y0, _ = yield from self._rest("y", 0.005, None, 0.0)
        self.marks["pendulum_before_start"] = t0
        self.marks["pendulum_before_end"] = self.t
        self.phase = ("turn the pendulum one full lap by hand, from hanging to hanging, then "
                      "let it hang still")
        self.prompts.append({"text": self.phase, "hand": {"lap": "pendulum",
                                                          "seconds": self.lap_seconds}})
        self.progress = 0.2
        # settle: the unwrapped raw angle has moved more than 3/4 of the full range
        yield from self._rest("y", 0.02, y0, 1.5)
        self.marks["pendulum_after_start"] = self.t - self.settle
        self.marks["pendulum_after_end"] = self.t
        self.progress = 0.5
        self.phase = "turn the arm exactly one lap by hand and hold it still"
        x0 = self.x
        self.marks["arm_before"] = self.t
        self.prompts.append({"text": self.phase, "hand": {"lap": "arm",
                                                          "seconds": self.lap_seconds}})
        yield from self._rest("x", 0.002, x0, 0.02)
        self.marks["arm_after_start"] = self.t - self.settle
        self.marks["arm_after_end"] = self.t
        self.progress = 1.0


#: Experiment name -> class.
EXPERIMENT_CLASSES = {c.name: c for c in (Stiction, Stribeck, FreeOscillation, ControlScaling,
                                          VelocityScale, AngleScales)}


def make_experiment(name: str, h: float, u_scale: float | None = None,
                    limits: Limits | None = None, **options) -> RigExperiment:
    """The experiment ``name`` with its options (None values take the defaults)."""
    try:
        cls = EXPERIMENT_CLASSES[name]
    except KeyError:
        raise ValueError(f"unknown experiment {name!r}; known: "
                         f"{', '.join(EXPERIMENT_CLASSES)}") from None
    return cls(h, u_scale, limits, **{k: v for k, v in options.items() if v is not None})
