r"""Sampled-data closed-loop simulation (Sec. 5).

The continuous plant eq. (6) with arm friction is integrated between samples;
the controller (:func:`frictionlab.model.controller.controller_step`: observers,
state feedback, compensator) runs every h with zero-order hold on u.  Time is
the integer tick k, t = k h.

Integration scheme
------------------
The arm and its friction do not depend on the pendulum (except through the
LuGre plant's eq. (19) term, below), so within a sample they are integrated
on their own grid: ``Config.substeps`` equal substeps (``sim.substeps``, by
default 10 for the static friction models and 6 for LuGre).  In a substep
the friction force is evaluated once and held (friction is discontinuous, so
a higher-order integration *through* it gains nothing) and the arm moves
with the resulting constant acceleration (exact).
The LuGre bristle state is advanced with the exact exponential update for
frozen velocity (:func:`frictionlab.model.friction.friction_step`), so a stiff
bristle (``sigma0`` = 1000) stays stable at any substep count; the velocity
it sees is the substep's midpoint velocity predicted with the last friction,
which makes the smooth LuGre model second order in the substep (first order
without the predictor: 3.4 % feature error at 10 substeps for the slow design
with sigma0 = 1000, 0.02 % with it; docs/model.md).

With the LuGre plant's observer gain k > 0 (eq. 19, e = -theta) the bristle
also sees the pendulum angle: at each substep's midpoint, the angle predicted
by the second-order Taylor expansion from the start of the pendulum step (its
acceleration from the current arm state and the last friction).  That keeps
the scheme second order (the features of k = 1 and 2 runs are within 0.04 %
of 20 times finer steps).  With k = 0 nothing of this is evaluated and the
result is plain eq. (18), bit for bit.

The pendulum is smooth and is driven by the arm only through the net arm
acceleration a and the arm velocity squared (eq. 6).  It takes
``sim.pendulum_steps`` velocity-Verlet steps per sample (2 by default), each
driven by the exact means of a and of the squared arm velocity over its
substeps; that keeps the impulse the friction gives the pendulum exact and
costs almost no accuracy against pendulum steps as fine as the arm's (the
features change by at most 0.15 %, the classical model's max u; 0.02 %
otherwise) for a quarter of the pendulum's cost.

Zero-velocity band (classical model)
------------------------------------
As in the thesis's Simnon runs (Sec. 5.2), speeds inside the band count as
rest: friction balances the applied force (the arm's acceleration is zero)
unless that force exceeds the stiction level.  The arm keeps the small speed
it entered the band with until the force breaks it loose; the band must
therefore be wider than the speed change of one substep for sticking to be
seen at all (the thesis needed 0.03 rad/s; with 0.001 the arm skips over it).

A run whose pendulum falls (``|theta| > sim.fall_angle``) or whose state
becomes non-finite stops at once with status ``"fell"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ._jit import jit, jit_inline, keep_alive
from .controller import (
    DEFAULT_ERROR_SIGNAL,
    STATE_DTYPE,
    Controller,
    compensator_levels,
    controller_step,
    estimates,
    switch_controller,
)
from .design import design as make_design
from .design import gain_path
from .friction import (
    FRICTION_DTYPE,
    KINDS,
    LUGRE,
    NONE,
    copy_friction_into,
    drifted_params,
    drifted_rows,
    friction_row,
    friction_step,
    friction_view,
    is_drifting,
    resolve_drift,
)
from .plant import accelerations_sc, plant_record
from .sensor import SensorParams, ideal_reading, measure, sensor_params

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

#: The ten signals the thesis's controller saves (Sec. 7.1), in its order.
LOGGED = (
    "theta_m", "theta_hat", "theta_dot_hat", "u", "arm_m", "arm_dot_m", "arm_hat",
    "arm_dot_hat", "friction_hat", "z_hat",
)
#: One tick of a ``.dat`` log: the :data:`LOGGED` signals, space separated (the
#: simulator's :meth:`Trajectory.save_dat` and the real-time logger both write it).
DAT_LINE = " ".join(["%.9g"] * len(LOGGED)) + "\n"
#: All recorded columns: the ten logged signals, the true plant signals, then the
#: Coulomb and stiction levels the compensator used (the adaptive compensator's
#: estimates; a fixed compensator's own ``compensation.coulomb``/``stiction``; 0
#: without compensation).
COLUMNS = (*LOGGED, "theta", "theta_dot", "arm", "arm_dot", "z", "friction", "coulomb_hat",
           "stiction_hat")
NC = len(COLUMNS)

STATUS = ("ok", "fell")

#: Longest recorded run in ticks: the longest ``sim.duration`` (1e5 s) at
#: h = 5 ms, 2.4 GiB of signals.
MAX_TICKS = 20_000_000


@jit
def plant_tick(x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """Advance the plant state ``x`` (5,) in place over one sample with u held.

    The arm and its friction take ``substeps`` substeps: friction from the
    substep's initial state (LuGre: at the predicted midpoint velocity and,
    with k > 0, the error e = -theta at the pendulum's predicted midpoint
    angle, eq. 19), held;
    the arm moves with the resulting constant acceleration (exact).  The
    pendulum takes one velocity-Verlet step per ``ratio`` substeps, driven by
    the mean net acceleration and the mean squared arm velocity over them (both
    exact for the piecewise-linear arm velocity); its sin/cos are rotated
    through the angle increment and recomputed at the start of every sample.

    Parameters
    ----------
    x : ndarray (5,)
        Plant state ``[theta, theta_dot, arm, arm_dot, z]`` (advanced in place).
    u : float
        Control signal held over the sample (m/s^2).
    mem : float
        The friction model's memory: the Coulomb relay state, or the LuGre
        friction of the last substep (for the velocity predictor); else unused.
    substeps, ratio : int
        Arm substeps per sample and arm substeps per pendulum step.
    h : float
        Sampling period (s).
    pp : PlantRecord
        Plant parameters (:meth:`frictionlab.model.plant.PlantParams.record`).
    fkind, fp
        Friction model code, friction record
        (:meth:`frictionlab.model.friction.FrictionParams.record`), by reference.

    Returns
    -------
    (mean friction over the sample, mem)
    """
    omega0, zeta, g, arm_len, ku = pp.omega0, pp.zeta, pp.g, pp.arm_length, pp.input_gain
    dt = h / substeps
    fe = ku * u
    half_dt_over_l = 0.5 * dt / arm_len
    f_sum = 0.0
    th, thd, arm, ad, z = x[0], x[1], x[2], x[3], x[4]
    sn = np.sin(th)
    cs = np.cos(th)
    k = fp.k  # read unconditionally (model.friction's docstring, "Reads")
    kgain = k if fkind == LUGRE else 0.0
    done = 0
    while done < substeps:
        m = min(ratio, substeps - done)
        a_sum = 0.0
        v2_sum = 0.0
        th_acc = 0.0
        tau = 0.0
        if kgain != 0.0:
            # eq. (19)'s error e = -theta at each substep's midpoint, from the
            # pendulum's Taylor prediction over this pendulum step
            th_acc, _ = accelerations_sc(sn, cs, thd, ad, fe - mem, omega0, zeta, g, arm_len)
            tau = 0.5 * dt
        for _ in range(m):
            if fkind == LUGRE:
                # the bristle sees the velocity at the substep's midpoint, predicted
                # with the last friction: second order for this smooth model
                v = ad + (fe - mem) * half_dt_over_l
                e = 0.0
                if kgain != 0.0:
                    e = -(th + tau * (thd + 0.5 * tau * th_acc))
                    tau += dt
                f, z = friction_step(LUGRE, fp, z, v, fe, dt, e)
                mem = f
            elif fkind == NONE:
                f = 0.0
            else:
                f, mem = friction_step(fkind, fp, mem, ad, fe, dt, 0.0)
            f_sum += f
            a = fe - f
            _, arm_acc = accelerations_sc(sn, cs, thd, ad, a, omega0, zeta, g, arm_len)
            ad_new = ad + dt * arm_acc
            v2_sum += ad * ad + ad * ad_new + ad_new * ad_new  # 3 x mean of ad^2
            arm = arm + dt * (ad + 0.5 * dt * arm_acc)
            ad = ad_new
            a_sum += a
        done += m
        # pendulum: one velocity-Verlet step over the m substeps
        dtp = m * dt
        a_m = a_sum / m
        v_rms = math.sqrt(v2_sum / (3.0 * m))
        acc0, _ = accelerations_sc(sn, cs, thd, v_rms, a_m, omega0, zeta, g, arm_len)
        dth = dtp * (thd + 0.5 * dtp * acc0)
        th = th + dth
        if abs(dth) < 1e-2:
            # rotate (sin, cos) by the increment: the truncated series are exact
            # to rounding for |dth| < 1e-2 (next terms below 2e-18)
            d2 = dth * dth
            sd = dth * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0)))
            cd = 1.0 - 0.5 * d2 * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0)))
            sn, cs = sn * cd + cs * sd, cs * cd - sn * sd
        else:
            sn = np.sin(th)
            cs = np.cos(th)
        acc1, _ = accelerations_sc(sn, cs, thd + dtp * acc0, v_rms, a_m, omega0, zeta, g,
                                   arm_len)
        thd = thd + 0.5 * dtp * (acc0 + acc1)
    x[0], x[1], x[2], x[3], x[4] = th, thd, arm, ad, z
    return f_sum / substeps, mem


#: The per-tick steps as :func:`_run` calls them: the same laws (the same Python
#: functions), inlined into the compiled loop (their calls every tick cost about
#: 10 % of a run; with a noisy converter, the sensor's call as much again).
_controller_step_inline = jit_inline(controller_step.py_func)
_plant_tick_inline = jit_inline(plant_tick.py_func)
_measure_inline = jit_inline(measure.py_func)


@jit_inline
def record_tick(out, k, th_m, th_hat, thd_hat, u, arm_m, armd_m, arm_hat, armd_hat, f_hat,
                z_hat, theta, x, fc_used, fs_used):
    """Write tick ``k``'s signals into row k of ``out`` (columns :data:`COLUMNS`
    but ``friction``, written after the plant step): the measurements and the
    estimates the controller used, the plant state ``x`` with its angle given
    as ``theta``, and the compensator's levels."""
    out[k, 0] = th_m
    out[k, 1] = th_hat
    out[k, 2] = thd_hat
    out[k, 3] = u
    out[k, 4] = arm_m
    out[k, 5] = armd_m
    out[k, 6] = arm_hat
    out[k, 7] = armd_hat
    out[k, 8] = f_hat
    out[k, 9] = z_hat
    out[k, 10] = theta
    out[k, 11] = x[1]
    out[k, 12] = x[2]
    out[k, 13] = x[3]
    out[k, 14] = x[4]
    out[k, 16] = fc_used
    out[k, 17] = fs_used


@jit
def _run(x, mem, n_ticks, substeps, ratio, pp, fkind, fp, gp, cp, s, sp, n0, x0,
         fall_angle, out, record):
    """The closed loop for ``n_ticks`` ticks; returns (ticks done, status code, mem, x0).

    ``x`` (plant state) and ``s`` (controller state) are advanced in place;
    ``mem`` is the friction model's memory (:func:`plant_tick`) at the start,
    returned at the end.  The measurements are :func:`frictionlab.model.sensor.measure`
    with the sensor ``sp`` at sample numbers ``n0, n0 + 1, ...``; ``x0`` is its
    arm zero (taken at sample 0, returned for a continuation chunk).
    Row k of ``out`` receives the signals of tick k when ``record`` is true.
    ``n0`` is also the run's tick at the first of these ticks: the plant's
    friction levels drift with the time ``(n0 + k) h`` when ``fp`` has a
    drift with a resolved drift time (:func:`frictionlab.model.friction.resolve_drift`;
    an unresolved one, NaN, is ignored).  ``fp`` and ``cp`` are the plant's
    and the compensator's friction records (by reference).
    """
    h = gp.h
    drifting = is_drifting(fp)
    # the plant's levels at the tick, in a scratch record (kept alive to the end:
    # a record does not hold its array)
    buf = np.empty(1, FRICTION_DTYPE)
    fpt = buf[0]
    copy_friction_into(fp, fpt)
    # an ideal noise-free sensor measures the true signals: its (inlined) reading
    # saves the call of measure every tick; the same values bit for bit
    ideal = not (sp.noise > 0.0) and not (sp.step > 0.0)
    for k in range(n_ticks):
        if ideal:
            th_m, arm_m, armd_m, x0 = ideal_reading(x[0], x[2], x[3], n0 + k == 0, x0)
        else:
            th_m, arm_m, armd_m, x0 = _measure_inline(sp, x[0], x[2], x[3], n0 + k, x0)
        th_hat, thd_hat, arm_hat, armd_hat, z_hat = estimates(s, gp)
        u, _u_fb, f_hat = _controller_step_inline(s, gp, cp, th_m, arm_m, armd_m)
        if record:
            fc_used, fs_used = compensator_levels(s, gp, cp)
            record_tick(out, k, th_m, th_hat, thd_hat, u, arm_m, armd_m, arm_hat, armd_hat,
                        f_hat, z_hat, x[0], x, fc_used, fs_used)
        if drifting:
            drifted_params(fp, (n0 + k) * h, fpt)
        f_mean, mem = _plant_tick_inline(x, u, mem, substeps, ratio, h, pp, fkind, fpt)
        if record:
            out[k, 15] = f_mean
        if not (abs(x[0]) <= fall_angle) or not np.isfinite(x[1] + x[3] + x[4]):
            keep_alive(buf)
            return k + 1, 1, mem, x0
    keep_alive(buf)
    return n_ticks, 0, mem, x0


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
        The friction model's memory (:func:`plant_tick`): the Coulomb relay
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
    """:func:`plant_tick` with the plant record stored as the float row ``pp``
    (``np.array(record)``) and the friction record as the float row ``fp``
    (:func:`frictionlab.model.friction.friction_row`): the form for a caller
    in Python at every tick (the emulated rigs), since numba takes a float
    array from Python faster than it types a record argument."""
    return plant_tick(x, u, mem, substeps, ratio, h, plant_record(pp), fkind, friction_view(fp))


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
        self._pp = np.array(cfg.plant.record(), dtype=float)  # plant_tick_rows reads it
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
    switches: Sequence[tuple[float, Controller]] = (),
    transition: tuple[float, float] = (2.0, 2.0),
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
    switches : sequence of (t, Controller)
        Changes of controller while the loop runs, as the operator makes them in
        the 200 Hz loop: from the tick nearest ``t`` (s) on, that controller runs
        on the plant, the sensor and the controller state as they are, made
        bumpless as the loop makes it
        (:func:`frictionlab.model.controller.switch_controller`: a new
        compensator started at its steady value for the last measured arm
        velocity and ramped in, new gains L ramped) over ``transition`` =
        (gain, compensation) seconds (the loop's ``safety.gain_transition``
        and ``safety.compensation_transition``).
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
    pp = cfg.plant.record()
    substeps, ratio = cfg.substeps, cfg.pendulum_ratio
    if switches:
        if not record:
            raise ValueError("a run with switches is recorded (record=True)")
        done, status = _run_switched(x, n, substeps, ratio, pp, fkind, fp, ctrl, s, sp,
                                     cfg.sim.fall_angle, out, switches, transition, h,
                                     cfg.plant)
    elif progress is None:
        done, status, _, _ = _run(x, 0.0, n, substeps, ratio, pp, fkind, fp, gp, cp, s, sp,
                                  0, 0.0, cfg.sim.fall_angle, out, record)
    else:
        # chunks of whole ticks; the noise of sample n is a function of (seed, n), and
        # the arm's zero x0 is carried over, so a chunked run is the unchunked one bit
        # for bit
        chunk = max(1, n // 50)
        done, status, mem, x0 = 0, 0, 0.0, 0.0
        while done < n and status == 0:
            m = min(chunk, n - done)
            view = out[done:done + m] if record else out
            d, status, mem, x0 = _run(x, mem, m, substeps, ratio, pp, fkind, fp, gp, cp, s, sp,
                                      done, x0, cfg.sim.fall_angle, view, record)
            done += d
            progress(done / n)
    data = out[:done] if record else out[:0]
    return Trajectory(np.arange(len(data)), h, data, STATUS[status], cfg)


def _run_switched(x, n, substeps, ratio, pp, fkind, fp, ctrl, s, sp, fall_angle, out,
                  switches, transition, h, plant):
    """:func:`_run` in chunks between the switches, and tick by tick through each
    switch's transition (:class:`frictionlab.model.controller.Transition`); the
    plant, its friction memory, the sensor's arm zero and the controller state
    carry over, so that a run without switches is the unchunked one bit for bit."""
    gp, cp = ctrl.record()
    spec = ctrl.design.spec
    events = sorted((round(t / h), i, c) for i, (t, c) in enumerate(switches))
    n_gain, n_comp = (round(t / h) for t in transition)
    arm_dot_m = COLUMNS.index("arm_dot_m")
    done, status, mem, x0 = 0, 0, 0.0, 0.0
    trans = None
    while done < n and status == 0:
        while events and events[0][0] <= done:
            new = events.pop(0)[2]
            new_gp, new_cp = new.record()
            v = out[done - 1, arm_dot_m] if done else 0.0
            path = (gain_path(spec, new.design.spec, plant) if new.design.spec != spec
                    else None)
            spec = new.design.spec
            trans = switch_controller(s, gp, cp, new_gp, new_cp, v, n_gain, n_comp, path)
            gp, cp = trans.current(), new_cp
        if trans is not None and not trans.done:
            gp, m = trans.advance(), 1
        else:
            m = min(n, events[0][0] if events else n) - done
        d, status, mem, x0 = _run(x, mem, m, substeps, ratio, pp, fkind, fp, gp, cp, s, sp,
                                  done, x0, fall_angle, out[done:done + m], True)
        done += d
    return done, status


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

