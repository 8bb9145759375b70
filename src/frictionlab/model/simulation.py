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
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ._jit import jit
from .closedloop import COLUMNS, LOGGED, NC, no_swing, run_loop
from .controller import DEFAULT_ERROR_SIGNAL, STATE_DTYPE, Controller
from .design import design as make_design
from .friction import (
    KINDS,
    drifted_rows,
    friction_row,
    friction_view,
    is_drifting,
    resolve_drift,
)
from .plants import THESIS
from .plants.thesis import tick
from .sensor import SensorParams, sensor_params

if TYPE_CHECKING:  # only annotations: the configuration layer builds what the model runs
    from ..config import Config

__all__ = [
    "COLUMNS",
    "DAT_LINE",
    "LOGGED",
    "SimulatedPlant",
    "Trajectory",
    "run_features",
    "simulate_config",
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
    config : Config
    """

    k: np.ndarray
    h: float
    data: np.ndarray
    status: str
    config: Config | None = None
    meta: dict = field(default_factory=dict)

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
class PlantState:
    """Explicit state of :class:`SimulatedPlant`.

    Attributes
    ----------
    x : ndarray (5,)
        ``[theta, theta_dot, arm, arm_dot, z]`` (rad, rad/s, rad, rad/s, rad).
    memory : float
        The friction model's memory (:func:`frictionlab.model.plants.plant_step`): the Coulomb relay
        state, or the LuGre friction of the last substep.
    friction : float
        Mean friction over the last sample (m/s^2).
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
def plant_tick_rows(x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """The plant's step with the friction record stored as the float row ``fp``
    (:func:`frictionlab.model.friction.friction_row`): the form for a caller in
    Python at every tick (the emulated rigs), since numba takes a float array
    from Python faster than it types a record argument."""
    return tick(x, u, mem, substeps, ratio, h, pp, fkind, friction_view(fp))


class SimulatedPlant:
    """The plant with its friction, stepped one sample at a time.

    The same compiled integrator as :func:`simulate_config`; used by the
    emulated rig and the real-time loop's ``sim`` backend.

    Examples
    --------
    >>> plant = SimulatedPlant(build_config())
    >>> st = plant.init()
    >>> st = plant.step(st, u=0.0)
    """

    def __init__(self, cfg: Config, duration: float | None = None):
        self.cfg = cfg
        self.h = cfg.design.h
        self._pp = cfg.plant_row()  # the float row plant_tick_rows reads
        self._fkind = KINDS.index(cfg.friction_kind)
        # friction.drift: over friction.drift_time, else to the end of the run
        # (``duration``, default sim.duration)
        # float rows: plant_tick_rows and drifted_rows view them as the record
        fp = resolve_drift(cfg.friction.record(),
                           cfg.sim.duration if duration is None else duration)
        self._drifting = bool(is_drifting(fp))
        self._fp = friction_row(fp)
        self._fpt = self._fp.copy()
        self._substeps = cfg.substeps
        self._ratio = cfg.pendulum_ratio

    def init(self, theta0: float | None = None) -> PlantState:
        x = np.zeros(5)
        x[0] = self.cfg.sim.initial_angle if theta0 is None else theta0
        return PlantState(x)

    def step(self, state: PlantState, u: float) -> PlantState:
        """Advance one sampling period with u held (returns a new state)."""
        x = state.x.copy()
        fp = self._fp
        if self._drifting:
            drifted_rows(fp, state.tick * self.h, self._fpt)
            fp = self._fpt
        f, memory = plant_tick_rows(x, float(u), state.memory, self._substeps, self._ratio,
                                    self.h, self._pp, self._fkind, fp)
        return PlantState(x, memory, f, state.tick + 1)

    def push(self, state: PlantState, theta_dot_kick: float) -> PlantState:
        """Disturb the pendulum: add ``theta_dot_kick`` rad/s to its velocity."""
        x = state.x.copy()
        x[1] += theta_dot_kick
        return PlantState(x, state.memory, state.friction, state.tick)


def make_sensor(cfg: Config) -> SensorParams:
    """The sensor a configuration describes (``rig.*``, ``sim.quantization``,
    ``sim.noise``, ``sim.seed``; the arm's raw zero :data:`~frictionlab.model.sensor.ARM_START`)."""
    return sensor_params(cfg.rig, cfg.sim.quantization, cfg.sim.noise, cfg.sim.seed)


def make_controller(cfg: Config, error_signal: str = DEFAULT_ERROR_SIGNAL) -> Controller:
    """The controller a configuration describes."""
    d = make_design(cfg.design, cfg.plant)
    return Controller(d, cfg.compensation_kind, cfg.compensation, error_signal=error_signal,
                      u_max=cfg.rig.u_max)


def run_ticks(cfg: Config, duration: float | None = None, record: bool = True) -> int:
    """Ticks of a run of ``duration`` s (default ``cfg.sim.duration``).

    Raises
    ------
    ValueError
        The duration is not positive and finite, is shorter than one sampling
        period, or (``record``) is longer than a recorded run can hold
        (:data:`MAX_TICKS`).
    """
    duration = cfg.sim.duration if duration is None else float(duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be > 0 s, got {duration}")
    h = cfg.design.h
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


def simulate_config(
    cfg: Config,
    duration: float | None = None,
    *,
    record: bool = True,
    progress: Callable[[float], None] | None = None,
    controller: Controller | None = None,
) -> Trajectory:
    """Run the closed loop described by ``cfg``.

    Parameters
    ----------
    cfg : Config
        Plant, design, friction, compensation and simulation settings.
    duration : float, optional
        Simulated time in s (default ``cfg.sim.duration``).
    record : bool
        Keep every tick's signals (always true for the public API).
    progress : callable, optional
        Called with the fraction done (runs are chunked so long runs can
        report progress).
    controller : Controller, optional
        Use this controller instead of the one ``cfg`` describes.
    """
    n = run_ticks(cfg, duration, record)
    h = cfg.design.h
    ctrl = controller or make_controller(cfg)
    gp, cp = ctrl.record()
    x = np.zeros(5)
    x[0] = cfg.sim.initial_angle
    s = ctrl.init(cfg.sim.initial_angle)
    assert s.dtype == STATE_DTYPE
    out = np.zeros((n, NC)) if record else np.zeros((1, NC))
    sp = make_sensor(cfg)
    fkind = KINDS.index(cfg.friction_kind)
    fp = resolve_drift(cfg.friction.record(), n * h)
    pp = cfg.plant_row()
    substeps, ratio = cfg.substeps, cfg.pendulum_ratio
    # the swing-up supervisor's arguments, unused here (run_loop's swing is off)
    sup_row, wx, phase = no_swing()
    # chunks of whole ticks when progress is reported; the noise of sample n is a
    # function of (seed, n), and the arm's zero x0 is carried over, so a chunked
    # run is the unchunked one bit for bit
    chunk = n if progress is None else max(1, n // 50)
    done, status, mem, x0 = 0, 0, 0.0, 0.0
    while done < n and status == 0:
        m = min(chunk, n - done)
        view = out[done:done + m] if record else out
        d, status, mem, x0 = run_loop(x, mem, m, THESIS.code, substeps, ratio, pp, fkind, fp,
                                      gp, cp, s, sp, done, x0, cfg.sim.fall_angle, view, record,
                                      False, sup_row, wx, phase)
        done += d
        if progress is not None:
            progress(done / n)
    data = out[:done] if record else out[:0]
    return Trajectory(np.arange(len(data)), h, data, STATUS[status], cfg)


def run_features(cfg: Config, duration: float | None = None, window: float | None = None):
    """Simulate ``cfg`` and reduce the run to its limit-cycle features.

    The unit of work of sweeps, identification and tuning.

    Returns
    -------
    LimitCycleFeatures
        ``status`` is ``"fell"`` if the pendulum fell, else the features'
        status (``"limit_cycle"`` or ``"settled"``).
    """
    from .limit_cycles import trajectory_features

    traj = simulate_config(cfg, duration)
    return trajectory_features(traj, window)

