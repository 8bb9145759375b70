r"""Sampled-data closed-loop simulation (Sec. 5).

The continuous plant eq. (6) with arm friction is integrated between samples;
the controller (:func:`frictionlab.model.controller.controller_step`: observers,
state feedback, compensator) runs every h with zero-order hold on u.  Time is
the integer tick k, t = k h.

The plant is advanced by its own integrator
(:func:`frictionlab.model.plants.plant_step`; the thesis plant's scheme is in
:mod:`frictionlab.model.plants.thesis`).

A run whose pendulum falls (``|theta| > sim.fall_angle``) or whose state
becomes non-finite stops at once with status ``"fell"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._jit import jit
from .closedloop import COLUMNS, LOGGED, NC, no_swing, run_loop
from .controller import STATE_DTYPE, Controller
from .design import DesignSpec, gain_path
from .friction import (
    KINDS,
    FrictionParams,
    drifted_rows,
    friction_row,
    friction_view,
    is_drifting,
    plant_record,
    resolve_drift,
)
from .plants import PlantKind, plant_step
from .plants.thesis import PlantParams
from .sensor import SensorParams
from .switching import switch_controller

__all__ = [
    "COLUMNS",
    "DAT_LINE",
    "LOGGED",
    "LoopSpec",
    "PlantState",
    "SimulatedPlant",
    "Trajectory",
    "run_ticks",
    "simulate",
]

#: One tick of a ``.dat`` log: the :data:`LOGGED` signals, space separated (the
#: simulator's :meth:`Trajectory.save_dat` and the real-time logger both write it).
DAT_LINE = " ".join(["%.9g"] * len(LOGGED)) + "\n"

STATUS = ("ok", "fell")

#: Longest recorded run in ticks: the longest ``sim.duration`` (1e5 s) at
#: h = 5 ms, 2.4 GiB of signals.
MAX_TICKS = 20_000_000


@dataclass(frozen=True)
class Trajectory:
    """Result of a closed-loop run.

    Attributes
    ----------
    k : ndarray of int
        Tick numbers; time is ``t = k * h``.
    h : float
        Sampling period (s).
    data : ndarray (n, len(COLUMNS))
        Signals per tick, columns :data:`COLUMNS` (SI units).  The first ten
        are the thesis's logged signals (Sec. 7.1); the estimates are those
        the controller used at that tick.  ``friction`` is the true friction
        averaged over the sample that follows.
    status : {"ok", "fell"}
        ``fell`` if the run stopped early because the pendulum fell.
    config : object or None
        What the run was made from (the caller's; for a run of a
        configuration, its ``frictionlab.config.Config``); the model does not
        read it.
    meta : dict
        Extra results of the runner (e.g. a swing-up's phases).
    noise : float
        The measurement noise of the run's sensor (its standard deviation, SI):
        the feature extraction's threshold for a peak that stands out.
    """

    k: np.ndarray
    h: float
    data: np.ndarray
    status: str
    config: Any = None
    meta: dict = field(default_factory=dict)
    noise: float = 0.0

    @property
    def t(self) -> np.ndarray:
        return self.k * self.h

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "t":
            return self.t
        try:
            return self.data[:, COLUMNS.index(name)]
        except ValueError:
            raise KeyError(
                f"unknown signal {name!r}; available: t, {', '.join(COLUMNS)}") from None

    def __len__(self) -> int:
        return len(self.k)

    def save_dat(self, path) -> None:
        """Write the ten logged signals as ASCII columns (the thesis's ``.dat``,
        one :data:`DAT_LINE` a tick, as the real-time logger writes it)."""
        with open(path, "w") as fh:
            fh.writelines(DAT_LINE % tuple(row) for row in self.data[:, :len(LOGGED)].tolist())

    def save_csv(self, path) -> None:
        """Write time and every signal as CSV with a header line."""
        arr = np.column_stack([self.t, self.data])
        np.savetxt(path, arr, fmt="%.9g", delimiter=",", header="t," + ",".join(COLUMNS),
                   comments="")

    def save(self, path) -> None:
        """Save by extension: ``.dat`` (thesis format) or ``.csv``."""
        p = str(path)
        if p.endswith(".dat"):
            self.save_dat(p)
        elif p.endswith(".csv"):
            self.save_csv(p)
        else:
            raise ValueError(f"cannot save {p!r}: the extension must be .dat or .csv")


@dataclass(frozen=True)
class LoopSpec:
    """One simulated closed loop: everything the compiled kernels run.

    Built from a configuration by :func:`frictionlab.runs.loop_spec`; the
    model never reads a configuration.

    Attributes
    ----------
    plant : PlantKind
        Which plant (:data:`frictionlab.model.plants.PLANTS`).
    plant_params
        The plant's parameters (its module's ``Params``; ``record()`` is the
        float row its step reads).
    friction_kind : str
        The plant's friction model (:data:`frictionlab.model.friction.KINDS`).
    friction : FrictionParams
        The plant's friction parameters (units of u).
    controller : Controller
        The balancing controller (design, compensator, saturation).
    sensor : SensorParams
        The sensor model (App. B).
    h : float
        Sampling period (s).
    substeps, ratio : int
        The plant integrator's substeps per sample and substeps per pendulum step.
    fall_angle : float
        ``|theta|`` (rad) beyond which the pendulum has fallen.
    initial_angle : float
        The pendulum's angle at the start (rad; at rest).
    duration : float
        The run's default duration (s).
    source : object, optional
        What the loop was built from (carried to :attr:`Trajectory.config`).
    open_loop : bool
        Hold u at 0 for the whole run (the controller's feedback and
        compensator off; its observers still run) and never stop for a fall:
        free swings (``simulate --open-loop``).
    """

    plant: PlantKind
    plant_params: Any
    friction_kind: str
    friction: FrictionParams
    controller: Controller
    sensor: SensorParams
    h: float
    substeps: int
    ratio: int
    fall_angle: float
    initial_angle: float
    duration: float
    source: Any = None
    open_loop: bool = False


@dataclass(frozen=True)
class PlantState:
    """Explicit state of :class:`SimulatedPlant`.

    Attributes
    ----------
    x : ndarray (5,)
        ``[theta, theta_dot, arm, arm_dot, z]`` (rad, rad/s, rad, rad/s, rad).
    memory : float
        The friction model's memory (:func:`frictionlab.model.plants.plant_step`):
        the Coulomb relay state, or the LuGre friction of the last substep.
    friction : float
        Mean friction over the last sample (units of u).
    tick : int
        Samples stepped since :meth:`SimulatedPlant.init` (the clock of
        ``friction.drift``).
    """

    x: np.ndarray
    memory: float = 0.0
    friction: float = 0.0
    tick: int = 0

    @property
    def theta(self) -> float:
        return float(self.x[0])


@jit
def plant_tick_rows(pcode, x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """The plant's step (:func:`frictionlab.model.plants.plant_step`) with the
    friction record stored as the float row ``fp``
    (:func:`frictionlab.model.friction.friction_row`): the form for a caller in
    Python at every tick (the emulated rigs), since numba takes a float array
    from Python faster than it types a record argument."""
    return plant_step(pcode, x, u, mem, substeps, ratio, h, pp, fkind, friction_view(fp))


class SimulatedPlant:
    """The plant with its friction, stepped one sample at a time.

    The same compiled integrator as :func:`simulate`; used by the emulated rig,
    the real-time loop's ``sim`` backend and the simulated identification
    experiments.

    Examples
    --------
    >>> plant = SimulatedPlant(loop_spec(build_config()))
    >>> st = plant.init()
    >>> st = plant.step(st, u=0.0)
    """

    def __init__(self, spec: LoopSpec, duration: float | None = None):
        self.spec = spec
        self.h = spec.h
        self._pcode = spec.plant.code
        self._pp = spec.plant_params.record()  # the float row plant_tick_rows reads
        self._fkind = KINDS.index(spec.friction_kind)
        # friction.drift: over friction.drift_time, else to the end of the run
        # (``duration``, default the spec's)
        # float rows: plant_tick_rows and drifted_rows view them as the record
        fp = resolve_drift(plant_record(spec.friction_kind, spec.friction),
                           spec.duration if duration is None else duration)
        self._drifting = bool(is_drifting(fp))
        self._fp = friction_row(fp)
        self._fpt = self._fp.copy()
        self._substeps = spec.substeps
        self._ratio = spec.ratio

    def init(self, theta0: float | None = None) -> PlantState:
        x = np.zeros(5)
        x[0] = self.spec.initial_angle if theta0 is None else theta0
        return PlantState(x)

    def step(self, state: PlantState, u: float) -> PlantState:
        """Advance one sampling period with u held (returns a new state)."""
        x = state.x.copy()
        fp = self._fp
        if self._drifting:
            drifted_rows(fp, state.tick * self.h, self._fpt)
            fp = self._fpt
        f, memory = plant_tick_rows(self._pcode, x, float(u), state.memory, self._substeps,
                                    self._ratio, self.h, self._pp, self._fkind, fp)
        return PlantState(x, memory, f, state.tick + 1)

    def push(self, state: PlantState, theta_dot_kick: float) -> PlantState:
        """Disturb the pendulum: add ``theta_dot_kick`` rad/s to its velocity."""
        x = state.x.copy()
        x[1] += theta_dot_kick
        return PlantState(x, state.memory, state.friction, state.tick)


def run_ticks(h: float, duration: float, record: bool = True) -> int:
    """Ticks of a run of ``duration`` s at the sampling period ``h``.

    Raises
    ------
    ValueError
        The duration is not positive and finite, is shorter than one sampling
        period, or (``record``) is longer than a recorded run can hold
        (:data:`MAX_TICKS`).
    """
    duration = float(duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be > 0 s, got {duration}")
    n = round(duration / h)
    if n < 1:
        raise ValueError(f"duration {duration:g} s is shorter than one sampling period "
                         f"(design.h = {h:g} s)")
    if record and n > MAX_TICKS:
        raise ValueError(f"duration {duration:g} s at design.h = {h:g} s is {n:,} ticks; "
                         f"a recorded run holds at most {MAX_TICKS:,} "
                         f"({MAX_TICKS * NC * 8 / 2**30:.1f} GiB): shorten the duration "
                         "or raise design.h")
    return n


def simulate(
    spec: LoopSpec,
    duration: float | None = None,
    *,
    record: bool = True,
    progress: Callable[[float], None] | None = None,
    switches: Sequence[tuple[float, Controller]] = (),
    transition: tuple[float, float] = (2.0, 2.0),
) -> Trajectory:
    """Run the closed loop ``spec`` (:func:`frictionlab.model.closedloop.run_loop`).

    Parameters
    ----------
    spec : LoopSpec
        Plant, friction, controller, sensor and integration settings.
    duration : float, optional
        Simulated time in s (default ``spec.duration``).
    record : bool
        Keep every tick's signals (always true for the public API).
    progress : callable, optional
        Called with the fraction done (runs are chunked so long runs can
        report progress).
    switches : sequence of (t, Controller)
        Changes of controller while the loop runs, as the operator makes them in
        the 200 Hz loop: from the tick nearest ``t`` (s) on, that controller runs
        on the plant, the sensor and the controller state as they are, made
        bumpless as the loop makes it
        (:func:`frictionlab.model.switching.switch_controller`: a new
        compensator started at its steady value for the last measured arm
        velocity and ramped in, new gains moved through the designs in between)
        over ``transition`` = (gain, compensation) seconds (the loop's
        ``safety.gain_transition`` and ``safety.compensation_transition``).
        A run with switches is recorded.
    """
    h = spec.h
    record = record or bool(switches)
    n = run_ticks(h, spec.duration if duration is None else duration, record)
    ctrl = spec.controller
    gp, cp = ctrl.record()
    fall_angle = spec.fall_angle
    if spec.open_loop:
        # u = -(0 x_hat) + 0 = 0 every tick, no fall stop (a non-finite state still ends it)
        gp = gp.with_feedback(np.zeros(4))._replace(compensator=0, feed_net=0.0)
        fall_angle = math.inf
    x = np.zeros(5)
    x[0] = spec.initial_angle
    s = ctrl.init(spec.initial_angle)
    assert s.dtype == STATE_DTYPE
    out = np.zeros((n, NC)) if record else np.zeros((1, NC))
    fkind = KINDS.index(spec.friction_kind)
    fp = resolve_drift(plant_record(spec.friction_kind, spec.friction), n * h)
    pp = spec.plant_params.record()
    # the swing-up supervisor's arguments, unused here (run_loop's swing is off)
    sup_row, wx, phase = no_swing()
    thesis = isinstance(spec.plant_params, PlantParams)
    events = sorted((round(t / h), i, c) for i, (t, c) in enumerate(switches))
    n_gain, n_comp = (round(t / h) for t in transition)
    arm_dot_m = COLUMNS.index("arm_dot_m")
    # run_loop in chunks of whole ticks: up to each switch, tick by tick through
    # its transition (:class:`frictionlab.model.switching.Transition`), and in 50
    # chunks when progress is reported.  The plant, its friction memory, the
    # sensor's arm zero and the controller state carry over, and the noise of
    # sample n is a function of (seed, n): a chunked run is the single run bit for bit
    chunk = n if progress is None else max(1, n // 50)
    done, status, mem, x0 = 0, 0, 0.0, 0.0
    trans = None
    while done < n and status == 0:
        while events and events[0][0] <= done:
            new = events.pop(0)[2]
            new_gp, new_cp = new.record()
            a, b = ctrl.design.spec, new.design.spec
            path = (gain_path(a, b, spec.plant_params)
                    if thesis and isinstance(a, DesignSpec) and isinstance(b, DesignSpec)
                    and a != b else None)
            v = out[done - 1, arm_dot_m] if done else 0.0
            trans = switch_controller(s, gp, cp, new_gp, new_cp, v, n_gain, n_comp, path)
            gp, cp, ctrl = trans.current(), new_cp, new
        if trans is not None and not trans.done:
            gp, m = trans.advance(), 1
        else:
            m = min(done + chunk, events[0][0] if events else n, n) - done
        view = out[done:done + m] if record else out
        d, status, mem, x0 = run_loop(x, mem, m, spec.plant.code, spec.substeps, spec.ratio, pp,
                                      fkind, fp, gp, cp, s, spec.sensor, done, x0,
                                      fall_angle, view, record, False, sup_row, wx, phase)
        done += d
        if progress is not None:
            progress(done / n)
    data = out[:done] if record else out[:0]
    return Trajectory(np.arange(len(data)), h, data, STATUS[status], spec.source,
                      noise=float(spec.sensor.noise))
