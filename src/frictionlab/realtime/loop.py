r"""The periodic control loop: the thesis's *Regul* process (Sec. 7.3) at h = 5 ms.

One tick k, against the absolute deadline :math:`t_0 + k h` (integer
nanoseconds on the monotonic clock, so there is no drift):

1. sleep until the deadline; *jitter* = wake-up time - deadline;
2. if the wake-up is a whole period or more late, skip ahead to the
   latest deadline that has passed (never a burst of catch-up ticks),
   count the skipped ones as *missed* and record the stall (with a rig whose
   plant waits for the loop, ``Rig.realtime_plant`` False, the deadlines move
   on instead and k does not skip: t = k h stays the plant's time);
3. read the rig's raw (y, x, v), check them (finite, inside [-1, 1]),
   convert them to SI with App. B (the laws of :mod:`frictionlab.model.sensor`
   with the ``rig.*`` factors; the arm channel is unwrapped and its bias
   x_0 captured at the first tick, so Omega = 0 at the start), check the
   angle limit;
4. run the compiled controller step - the simulator's own code
   (:func:`frictionlab.model.controller.controller_step`: u from the predicted
   estimates, saturation, observer update);
5. write u_DA = k_u u (``rig.u_scale``, saturated to [-1, 1]); *compute* = u written -
   wake-up, less the time spent reading the rig (*rig*: request to reply
   over UDP/serial, the plant's step for ``sim``), which is measured
   separately; an *overrun* is a u written after the next deadline;
6. hand the :class:`~frictionlab.realtime.samples.Sample` to the sinks
   (log writer, console subscriptions) without blocking;
7. between ticks, after every tick (one without a reading too): apply
   pending parameter changes atomically (the mailbox; in effect from the
   next tick, made bumpless: see below), and the scheduled
   housekeeping (garbage collection once a second, the host's steal time
   every 100 ms).

Switching while running (bumpless; docs/realtime.md and docs/compensation.md,
"Switching while running"): a change is made by
:func:`frictionlab.model.switching.switch_controller`, as the simulator makes
it.  New gains (a design change) move from the gains in use to the new ones
over :attr:`Safety.gain_transition` seconds (2 s), along the gains of the
designs in between (:func:`frictionlab.model.design.gain_path`, computed
outside the loop), one step per tick: switched at once in the middle of the
slow design's limit cycle, the fast design's gains throw the pendulum past the
0.35 rad angle limit two times in three.  A compensator switched on (or to
another kind) starts at its steady estimate for the last measured arm velocity
and is ramped in over :attr:`Safety.compensation_transition` seconds (2 s).
``0`` switches at once.

Pre-warming (``prewarm_us`` > 0): on a virtual machine whose CPU sits idle
between ticks, the first microseconds after a wake-up run from cold caches
(on the project's VM a tick's code ran 2-20 times slower right after a
5 ms sleep than back-to-back).  The loop can therefore wake ``prewarm_us``
before the deadline, run the tick's code on scratch data (a copy of the
controller state, the rig's :meth:`~.rigs.Rig.warm`), and busy-wait to the
deadline.  Jitter and compute are still measured from the deadline and the
real wake-up; the price is the CPU time of the dry pass and the spin.

Safety (every stop writes u_DA = 0 in the tick that detects it and records
its reason): ``angle_limit`` (|theta| above :attr:`Safety.angle_limit`),
``bad_reading`` (NaN, out of range, corrupted frame, duplicated or
out-of-order sequence number), ``rig_silent`` (nothing at all from the rig
in :attr:`Safety.silent_periods` consecutive sample periods - a late reply
to an earlier request counts as a sign of life - or no timely reading in
:attr:`Safety.unread_limit` consecutive ticks), ``not_upright`` (the first
reading is not within :attr:`Safety.start_tolerance` of upright: there is no
swing-up), ``rig_fault`` (the rig reports that its watchdog zeroed the motor,
or its echo of the u_DA being applied - or its ``HELD`` status after the
first command - disagrees with the command for more than
:attr:`Safety.echo_ticks` consecutive ticks), ``nonfinite_u`` (the controller
computed u = NaN or +-inf: nothing is written but the zero), ``paused`` (the
loop was not running for more than :attr:`Safety.max_pause`: a wake-up that
late, or a tick that took that long from its deadline to its output - the
process was suspended, e.g. SIGSTOP, or the host stalled - so the
controller's state is stale; the tick zeroes the motor instead of acting on
it; not with a rig whose plant waits for the loop, ``Rig.realtime_plant``
False), ``exception``, an identification experiment's ``finished`` (its
schedule is done) and ``experiment_limit`` (arm speed, travel or waiting time
exceeded, :mod:`.experiment`), a board's ``watchdog_expired``, ``amplifier_fault``,
``motor_stall`` (:mod:`.qube`), and the requested stops ``duration``, ``user``,
``signal``, ``exit`` and ``log_failed`` (the log writer: :mod:`.datalog`).

Garbage collection: the cyclic collector is frozen (``gc.freeze()``: every
object alive at the start is exempt) and disabled while the loop runs, so it
can never start inside a tick; the loop itself runs a young-generation
collection once a second, a middle one every 10 s and a full one every
60 s, right after a tick's output (outside the critical section), and
times them.  The tick allocates no reference cycles.
"""

from __future__ import annotations

import gc
import math
import sys
import traceback
from collections import deque
from dataclasses import dataclass

from ..model import sensor
from ..model.controller import (
    controller_step_rows,
    gains_row,
    state_index,
    state_record,
    state_vector,
)
from ..model.params import Validated, param
from ..model.rig import RigScaling
from ..model.swingup import (
    BALANCING,
    CAUGHT,
    PHASES,
    STOP_CODES,
    SWINGING,
    SwingUp,
    SwingUpParams,
    swing_index,
    swing_record,
    swing_vector,
    swingup_row,
    swingup_step_rows,
)
from ..model.switching import switch_controller
from .osrt import normal_priority, try_realtime_priority
from .params import ControlParams
from .protocol import STATUS_HELD, STATUS_WATCHDOG
from .rigs import BadReading, Rig
from .samples import (
    CAUGHT_FLAG,
    CHANGED,
    COMPENSATE,
    MISSED,
    NO_READING,
    OVERRUN,
    START,
    STOP,
    SWINGING_FLAG,
    Sample,
)
from .stats import Histogram, StallLog

__all__ = ["STOP_REASONS", "ExperimentEnd", "Loop", "Safety"]

#: Every stop reason the loop records.
STOP_REASONS = ("duration", "user", "signal", "exit", "angle_limit", "bad_reading",
                "rig_silent", "not_upright", "rig_fault", "nonfinite_u", "paused",
                "log_failed", "exception", "finished", "experiment_limit", "not_caught",
                "arm_travel", "arm_speed", "watchdog_expired", "amplifier_fault", "motor_stall")
_NAN = math.nan
#: The controller state's estimates in its float vector (the tick reads the vector:
#: a state record's field costs microseconds to read from Python).
_X1, _X2, _ARM, _ARMDOT, _ZHAT = (state_index(n) for n in ("x1", "x2", "arm", "arm_dot", "z_hat"))
# positions of the swing-up state's fields in its float vector
_PHASE, _TH_SW, _THD_SW, _CATCH, _STOP = (swing_index(n) for n in (
    "phase", "theta_hat", "theta_dot_hat", "catch_tick", "stop"))
#: The signals of a :class:`Sample` from ``theta_m`` to ``v`` in a tick without a reading.
_NO_SIGNALS = (_NAN,) * 13
_TWO_PI = 2.0 * math.pi
_FMAX = sys.float_info.max
_rt_warned = False


@dataclass(frozen=True)
class Safety(Validated):
    """Safety limits of the loop."""

    _prefix = "safety."

    angle_limit: float = param(0.35, "stop when |theta| exceeds this", "rad", lo=0.0,
                               hi=math.pi, lo_open=True)
    start_tolerance: float = param(0.15, "start only if |theta| <= this at the first "
                                   "reading (no swing-up)", "rad", lo=0.0, hi=math.pi)
    silent_periods: int = param(2, "stop after this many consecutive sample periods in "
                                "which nothing arrived from the rig", "1", lo=1, hi=100,
                                integer=True)
    unread_limit: int = param(10, "stop after this many consecutive ticks without a timely "
                              "reading (the rig answers, but too late)", "1", lo=1, hi=1000,
                              integer=True)
    reply_timeout: float = param(0.5, "how long after its deadline a tick waits for the "
                                 "rig's reply, as a fraction of h", "1", lo=0.05, hi=0.9)
    min_reply_wait: float = param(0.25, "the least time a tick waits for the reply after a "
                                  "late wake-up, as a fraction of h", "1", lo=0.0, hi=0.9)
    gain_transition: float = param(2.0, "time over which new state-feedback gains L replace "
                                   "the running ones, linearly (0: at once)", "s", lo=0.0,
                                   hi=60.0)
    compensation_transition: float = param(2.0, "time over which a compensator switched on "
                                           "(or to another kind) is ramped in, linearly from "
                                           "its steady estimate times 0 (0: at once)", "s",
                                           lo=0.0, hi=60.0)
    max_pause: float = param(0.05, "stop (reason paused) when the loop was not running for "
                             "longer than this: a wake-up this late after its deadline, or a "
                             "tick this long from its deadline to its output (a suspended "
                             "process or a stalled host: the controller's state is stale)",
                             "s", lo=0.0, hi=10.0, lo_open=True)
    echo_tolerance: float = param(0.002, "largest difference between the u_DA the rig reports "
                                  "applying and the one commanded (float32 rounding, with a "
                                  "wide margin)", "1", lo=0.0, hi=2.0, lo_open=True)
    echo_ticks: int = param(3, "stop (reason rig_fault) after this many consecutive ticks in "
                            "which the rig's echo of u_DA disagrees with the command, or it "
                            "still reports HELD after the first command", "1", lo=1, hi=100,
                            integer=True)


class ExperimentEnd(Exception):
    """Raised by an experiment's ``step`` to end the run: reason ``finished`` (its
    schedule is done) or ``experiment_limit`` (one of its limits was exceeded)."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(detail)
        self.reason = reason
        self.detail = detail


class _Stop(Exception):
    """Internal: leave the loop with a reason."""

    def __init__(self, reason: str, detail: str = "", reading=None):
        self.reason = reason
        self.detail = detail
        self.reading = reading


class Loop:
    """One run of the periodic loop (see the module docstring).

    Parameters
    ----------
    rig : Rig
        An opened rig backend.
    clock : clock
        ``now_ns()`` and ``sleep_until(t_ns)`` (see :mod:`.clock`).
    params : ControlParams
        Initial design and compensation.
    safety : Safety
    scaling : RigScaling
        App. B conversion.
    duration : float, optional
        Stop with reason ``duration`` after this many seconds of ticks.
    realtime : bool
        Try SCHED_FIFO (and the timer slack, see :mod:`.osrt`) for the thread
        that calls :meth:`run`.
    cpu : int, optional
        Pin that thread to this CPU (with ``realtime``).
    manage_gc : bool
        Freeze and disable the cyclic garbage collector during the run (see
        the module docstring).
    experiment : object, optional
        An identification experiment in place of the balancing controller
        (:mod:`frictionlab.realtime.experiment`): ``step(t, theta, arm,
        arm_dot, y, x, v) -> u`` (m/s^2) is called in the tick instead of the
        controller step, and may raise :class:`ExperimentEnd`.  The
        ``not_upright`` and ``angle_limit`` checks are off (the pendulum hangs
        or swings freely); every other check, the timing and the logging are
        those of a balancing run.
    swingup : SwingUpParams, optional
        Start hanging (or anywhere) and swing up (:mod:`frictionlab.model.swingup`,
        the simulator's compiled :func:`~frictionlab.model.swingup.swingup_step`):
        no ``not_upright`` check at the start, the angle limit only once the
        phase is ``balancing``, and the swing-up's own stops ``not_caught``
        (its time limit, counted in executed ticks), ``arm_travel`` and
        ``arm_speed``.  Not with ``experiment``.

    Attributes read by other threads (single-word updates, no locks): ``k``,
    ``ticks``, ``missed``, ``overruns``, ``rig_timeouts``, ``jitter``,
    ``compute`` (:class:`~.stats.Histogram`), ``stalls``, ``stop_reason``,
    ``stop_detail``, ``running``.
    """

    def __init__(self, rig: Rig, clock, params: ControlParams, *,
                 safety: Safety | None = None, scaling: RigScaling | None = None,
                 duration: float | None = None, realtime: bool = True,
                 manage_gc: bool = True, priority: int = 50, prewarm_us: float = 0.0,
                 cpu: int | None = None, experiment=None,
                 swingup: SwingUpParams | None = None):
        if experiment is not None and swingup is not None:
            raise ValueError("a run is an experiment or a swing-up, not both")
        self.rig = rig
        self.experiment = experiment
        self.clock = clock
        self.params = params
        self.safety = safety or Safety()
        self.scaling = scaling or params.cfg.rig
        h = params.cfg.design.h
        self.h = h
        self.h_ns = round(h * 1e9)
        if duration is not None and not (duration > 0 and math.isfinite(duration)):
            raise ValueError(f"duration must be > 0 s, got {duration}")
        self.n_ticks = None if duration is None else round(duration / h)
        if not 0 <= prewarm_us < h * 1e6 / 2:
            raise ValueError(f"prewarm_us must be in [0, h/2), got {prewarm_us}")
        self.prewarm_ns = int(prewarm_us * 1000)
        self.realtime = realtime
        self.manage_gc = manage_gc
        self.priority = priority
        self.cpu = cpu
        # shared with other threads
        self.sinks: tuple = ()
        self.mailbox: deque = deque()
        self.stop_request: str | None = None
        self.stop_request_detail = ""
        self.k = 0
        self.ticks = 0
        self.missed = 0
        self.overruns = 0
        self.rig_timeouts = 0
        self.jitter = Histogram()
        self.compute = Histogram()
        self.rig_io = Histogram()
        self.stalls = StallLog()
        self.gc_runs = 0
        self.gc_max_us = 0.0
        self.changes_applied = 0
        self.stop_reason: str | None = None
        self.stop_detail = ""
        self.stop_tick: int | None = None
        self.t0_ns: int | None = None
        self.running = False
        self.rt_note: str | None = None
        self.sched_fifo = False
        self.x0: float | None = None
        self.traceback: str | None = None
        #: The controller state (:mod:`frictionlab.model.controller`'s table) from the first
        #: reading on, updated in place by each tick (for the sidecar's adapted levels).
        self.state = None
        self.swingup = swingup
        self._sp = (None if swingup is None
                    else swingup_row(SwingUp(params.controller, swingup).record()[2]))
        # swing-up state: a record viewing the float vector the ticks update (read by
        # other threads: phase, catches)
        self.swing_w = None
        self.swing_caught_tick: int | None = None

    # --- requests from other threads -------------------------------------------

    def request_stop(self, reason: str, detail: str = "requested") -> None:
        """Ask the loop to stop with ``reason`` at its next tick (any thread; the first
        request wins)."""
        if reason not in STOP_REASONS:
            raise ValueError(f"stop reason must be one of {', '.join(STOP_REASONS)}")
        if self.stop_request is None:
            self.stop_request_detail = detail
            self.stop_request = reason

    # --- the loop ------------------------------------------------------------------

    def run(self) -> str:
        """Run until a stop; return the stop reason."""
        global _rt_warned
        self.running = True
        # compile (or load from numba's cache) and collect garbage before the first
        # deadline, and before raising the priority: a long setup at real-time priority
        # would starve everything else on the CPU.  A run asked to stop before it started
        # (a signal during the handshake) skips all that and stops at tick 0 at once.
        setup = self.stop_request is None
        p = self.params
        if setup and self.experiment is None:
            controller_step_rows(state_vector(p.controller.init(0.0)), gains_row(p.gp), p.cp,
                                 0.0, 0.0, 0.0)
            if self.swingup is not None:
                w_, s_ = SwingUp(p.controller, self.swingup).init(0.0)
                swingup_step_rows(swing_vector(w_), state_vector(s_), gains_row(p.gp), p.cp,
                                  self._sp, 0.0,
                                  0.0, 0.0)
        gc_was = gc.isenabled()
        if self.manage_gc and setup:
            gc.collect()
            gc.freeze()
            gc.disable()
        if self.realtime and setup:
            self.rt_note = try_realtime_priority(self.priority, self.cpu)
            self.sched_fifo = self.rt_note is None or "SCHED_FIFO" not in self.rt_note
            if self.rt_note and not _rt_warned:
                _rt_warned = True
                print(f"frictionlab: {self.rt_note}", file=sys.stderr)
        try:
            self._ticks()
        except _Stop as stop:
            self._halt(stop)
        except BaseException as exc:
            reason = "signal" if isinstance(exc, KeyboardInterrupt) else "exception"
            detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            self.traceback = traceback.format_exc()
            self._halt(_Stop(reason, detail))
        finally:
            try:
                self.rig.stop_motor()
            finally:
                if self.sched_fifo:
                    normal_priority()
                if self.manage_gc:
                    gc.unfreeze()
                    if gc_was:
                        gc.enable()
                self.running = False
        return self.stop_reason

    def _halt(self, stop: _Stop) -> None:
        """Zero the motor, record the reason, log the stop row."""
        try:
            self.rig.write(self.k, 0.0)
        except Exception:
            self.rig.stop_motor()
        self.stop_reason = stop.reason
        self.stop_detail = stop.detail
        self.stop_tick = self.k
        r = stop.reading
        y, x, v = (r.y, r.x, r.v) if r is not None else (_NAN, _NAN, _NAN)
        sample = Sample(self.k, self.k * self.h, STOP, _NAN, _NAN, _NAN, 0.0, _NAN, _NAN,
                        _NAN, _NAN, _NAN, _NAN, y, x, v, 0.0, _NAN, _NAN, _NAN)
        for sink in self.sinks:
            try:
                sink(sample)
            except Exception:
                pass

    def _ticks(self) -> None:
        clock, rig, safety = self.clock, self.rig, self.safety
        now = clock.now_ns
        sleep_until = clock.sleep_until
        spin_until = clock.spin_until
        prewarm_ns = self.prewarm_ns
        rig_warm = rig.warm
        sample_rig = rig.sample
        write = rig.write
        h_ns, h = self.h_ns, self.h
        reply_ns = int(safety.reply_timeout * h_ns)
        angle_limit = safety.angle_limit
        silent_max = safety.silent_periods
        unread_max = safety.unread_limit
        min_reply_ns = int(safety.min_reply_wait * h_ns)
        # a plant that waits for the loop (the lockstep simulation) cannot go stale
        pause_ns = round(safety.max_pause * 1e9) if rig.realtime_plant else 1 << 62
        echo_tol = safety.echo_tolerance
        echo_max = safety.echo_ticks
        echo_bad = 0
        commanded = False
        sc = self.scaling
        # App. B.5 from the sensor model, as plain Python (no dispatch in the tick)
        theta_si = sensor.theta_from_raw.py_func
        arm_si = sensor.arm_from_raw.py_func
        velocity_si = sensor.velocity_from_raw.py_func
        unwrap = sensor.unwrap.py_func
        dac = sensor.dac.py_func
        ts, tb = sc.theta_scale, sc.theta_bias
        as_ = sc.arm_scale
        vs, vb = sc.velocity_scale, sc.velocity_bias
        us = sc.u_scale
        jit_add, comp_add, rig_add = self.jitter.add, self.compute.add, self.rig_io.add
        n_ticks = self.n_ticks
        mailbox = self.mailbox
        experiment = self.experiment
        exp_step = experiment.step if experiment is not None else None
        params = self.params
        gp, cp = params.gp, params.cp
        w0 = gp.omega0
        comp_flag = COMPENSATE if params.comp_enabled else 0
        ramp_n = round(safety.gain_transition / h)
        comp_n = round(safety.compensation_transition / h)
        # a change's transition (model.switching.Transition): the gains of the ticks
        # after it, with L and the compensator's weight moving (the record's field types
        # stay: nothing is compiled mid-run)
        trans = None
        g_row = gains_row(gp)  # what the compiled step reads (controller_step_rows)
        s = None  # the controller state: a record (self.state) viewing the vector sx
        sx = None
        swing = self.swingup is not None
        sp = self._sp
        w = None
        first = True
        silent = unread = 0
        rx_seen = rig.rx_frames
        x_prev = 0.0
        wraps = 0
        x0 = 0.0
        u_da_prev = 0.0
        theta = arm = arm_dot = 0.0
        pending_flags = 0
        k = 0
        t0 = now() + h_ns
        self.t0_ns = t0
        lockstep = not rig.realtime_plant
        while True:
            deadline = t0 + k * h_ns
            if prewarm_ns:
                sleep_until(deadline - prewarm_ns)
                if now() < deadline:
                    # bring the tick's code and data back into the caches (see docstring)
                    if sx is not None:
                        controller_step_rows(sx.copy(), g_row, cp, theta, arm, arm_dot)
                    rig_warm()
                    spin_until(deadline)
            else:
                sleep_until(deadline)
            wake = now()
            late = wake - deadline
            flags = pending_flags | comp_flag
            pending_flags = 0
            m = 0
            if late >= h_ns:
                m = late // h_ns
                # count only the deadlines inside the run (a stall at its very end)
                self.missed += m if n_ticks is None else max(0, min(m, n_ticks - k))
                deadline += m * h_ns
                if lockstep:
                    # the plant waits for the loop: the schedule moves on, the tick
                    # count - the simulated time, t = k h - does not (else the log's
                    # time would run ahead of the plant's by the stall)
                    t0 += m * h_ns
                    self.t0_ns = t0
                else:
                    k += m
                flags |= MISSED
                self.stalls.add(k, k * h, late, m)
                late -= m * h_ns
            self.k = k
            if self.stop_request is not None:
                raise _Stop(self.stop_request, self.stop_request_detail)
            if n_ticks is not None and k >= n_ticks:
                raise _Stop("duration", f"{n_ticks} ticks")
            gap = wake - deadline + m * h_ns
            if gap > pause_ns:
                raise _Stop("paused", f"the loop woke up {gap / 1e6:.1f} ms after its deadline "
                            f"(limit {safety.max_pause * 1e3:g} ms): the process was "
                            "suspended or the host stalled, so the controller's state is stale")
            # the rig gets reply_timeout h after the deadline, and at least min_reply_ns
            # after a late wake-up (else a wake late in the period would leave it no time)
            reply_by = deadline + reply_ns
            if reply_by < wake + min_reply_ns:
                reply_by = wake + min_reply_ns
            t_r = now()
            try:
                r = sample_rig(k, reply_by)
            except BadReading as exc:  # its reason: bad_reading, or a board's (.qube)
                raise _Stop(exc.reason, str(exc)) from None
            t_rd = now()
            rig_ns = t_rd - t_r
            if t_rd - deadline > pause_ns:
                # suspended (or stalled) while waiting for the reply: whatever came is stale
                raise _Stop("paused", f"the rig's reply was taken {(t_rd - deadline) / 1e6:.1f} "
                            f"ms after the tick's deadline (limit {safety.max_pause * 1e3:g} "
                            "ms): the process was suspended or the host stalled", r)
            if r is None:
                self.rig_timeouts += 1
                rx = rig.rx_frames
                # silence: ticks in which nothing at all came from the rig (a late
                # reply to an earlier request is a sign of life, not a reading)
                silent = silent + 1 if rx == rx_seen else 0
                rx_seen = rx
                unread += 1
                if silent >= silent_max:
                    raise _Stop("rig_silent", f"nothing from the rig for {silent} consecutive "
                                "sample periods")
                if unread >= unread_max:
                    raise _Stop("rig_silent", f"no timely reading for {unread} consecutive "
                                "ticks (the rig's replies come too late)")
                u_da = u_da_prev  # hold u, keep the rig's watchdog fed
                flags |= NO_READING
                signals = _NO_SIGNALS
            else:
                silent = 0
                unread = 0
                rx_seen = rig.rx_frames
                y, x, v = r.y, r.x, r.v
                if not (-1.0 <= y <= 1.0 and -1.0 <= x <= 1.0 and -1.0 <= v <= 1.0):
                    raise _Stop("bad_reading", f"raw reading out of range or NaN: y={y!r}, "
                                f"x={x!r}, v={v!r}", r)
                # trust, but verify: the rig's status and its echo of the u_DA it applies
                status = r.status
                if status & STATUS_WATCHDOG:
                    raise _Stop("rig_fault", "the rig reports that its watchdog zeroed the "
                                "motor (its commands came too late or not at all)", r)
                if not abs(r.u_da - u_da_prev) <= echo_tol or (commanded
                                                                and status & STATUS_HELD):
                    echo_bad += 1
                    if echo_bad > echo_max:
                        what = ("still reports HELD (it does not apply the commands)"
                                if status & STATUS_HELD else
                                f"applies u_DA = {r.u_da!r}, commanded {u_da_prev!r}")
                        raise _Stop("rig_fault", f"the rig {what} for {echo_bad} consecutive "
                                    "ticks", r)
                else:
                    echo_bad = 0
                if first:
                    x0 = x
                    self.x0 = x0
                else:
                    wraps = unwrap(x_prev, x, wraps)
                x_prev = x
                theta = theta_si(y, ts, tb)
                arm = arm_si(x + 2.0 * wraps, x0, as_)
                arm_dot = velocity_si(v, vs, vb)
                if exp_step is not None:
                    # an identification experiment: its own schedule and limits
                    try:
                        u = exp_step(k * h, theta, arm, arm_dot, y, x, v)
                    except ExperimentEnd as end:
                        raise _Stop(end.reason, end.detail, r) from None
                    if first:
                        flags |= START
                        first = False
                    th_hat = thd_hat = arm_hat = armd_hat = f_hat = z_hat = _NAN
                    if not -_FMAX <= u <= _FMAX:
                        raise _Stop("nonfinite_u", f"the experiment computed u = {float(u)!r}",
                                    r)
                else:
                    if first and swing:
                        w_rec, s0 = SwingUp(params.controller, self.swingup).init(theta)
                        w = swing_vector(w_rec)
                        sx = state_vector(s0)
                        s = state_record(sx)
                        self.swing_w = swing_record(w)
                        self.state = s
                        flags |= START
                        first = False
                    if first:
                        if not abs(theta) <= safety.start_tolerance:
                            raise _Stop("not_upright", f"|theta| = {abs(theta):.3f} rad at the "
                                        f"start (tolerance {safety.start_tolerance} rad; no "
                                        "swing-up)", r)
                        sx = state_vector(params.controller.init(theta))
                        s = state_record(sx)
                        self.state = s
                        flags |= START
                        first = False
                    if not abs(theta) <= angle_limit and (
                            not swing or (w[_PHASE] == BALANCING and not abs(
                                math.remainder(theta, _TWO_PI)) <= angle_limit)):
                        raise _Stop("angle_limit", f"|theta| = {abs(theta):.3f} rad > "
                                    f"{angle_limit} rad", r)
                    th_hat = sx[_X1]
                    thd_hat = w0 * sx[_X2]
                    arm_hat = sx[_ARM]
                    armd_hat = sx[_ARMDOT]
                    z_hat = sx[_ZHAT]
                    if trans is not None:
                        gp = trans.advance()
                        g_row = gains_row(gp)
                        if trans.done:
                            trans = None
                    if swing:
                        u, _u_fb, f_hat = swingup_step_rows(w, sx, g_row, cp, sp, theta, arm,
                                                            arm_dot)
                        ph = w[_PHASE]
                        if ph == SWINGING:
                            flags |= SWINGING_FLAG
                            th_hat = w[_TH_SW]
                            thd_hat = w[_THD_SW]
                        elif ph == CAUGHT:
                            flags |= CAUGHT_FLAG
                        elif ph == BALANCING:
                            if self.swing_caught_tick is None:
                                self.swing_caught_tick = int(w[_CATCH])
                        else:
                            code = STOP_CODES[int(w[_STOP])]
                            raise _Stop(code, _swing_stop_detail(code, self.swingup, arm,
                                                                 arm_dot), r)
                    else:
                        u, _u_fb, f_hat = controller_step_rows(sx, g_row, cp, theta, arm, arm_dot)
                    if not -_FMAX <= u <= _FMAX:
                        raise _Stop("nonfinite_u", f"the controller computed u = {float(u)!r} "
                                    "from the estimates theta, theta', arm, arm', z = "
                                    f"{th_hat:.4g}, {thd_hat:.4g}, {arm_hat:.4g}, "
                                    f"{armd_hat:.4g}, {z_hat:.4g}", r)
                u_da = dac(u, us)
                if now() - deadline > pause_ns:
                    # suspended (or stalled) inside the tick: the reading is stale
                    raise _Stop("paused", f"the tick's output was due "
                                f"{(now() - deadline) / 1e6:.1f} ms after its deadline "
                                f"(limit {safety.max_pause * 1e3:g} ms): the process was "
                                "suspended or the host stalled; the reading is stale", r)
                commanded = True
                signals = (theta, th_hat, thd_hat, u, arm, arm_dot, arm_hat, armd_hat, f_hat,
                           z_hat, y, x, v)
            # ---- the tick's output and its record (with a reading or without) ----
            write(k, u_da)
            t_w = now()
            u_da_prev = u_da
            if t_w > deadline + h_ns:
                self.overruns += 1
                flags |= OVERRUN
            jit_add(late)
            comp_add(t_w - wake - rig_ns)
            rig_add(rig_ns)
            smp = Sample(k, k * h, flags, *signals, u_da, late / 1e3,
                         (t_w - wake - rig_ns) / 1e3, rig_ns / 1e3)
            for sink in self.sinks:
                sink(smp)
            self.ticks += 1
            # ---- between ticks ----
            if mailbox:
                applied = []
                while mailbox:
                    applied.append(mailbox.popleft())
                params = applied[-1][0]
                self.params = params
                if swing:
                    # the swing-up's observer and energy use the design's omega_0 too
                    sp = self._sp = swingup_row(
                        SwingUp(params.controller, self.swingup).record()[2])
                # bumpless: from the gains in use (mid-transition too), a new compensator
                # started at its steady value for the arm's velocity and ramped in
                trans = switch_controller(s, gp, cp, params.gp, params.cp, arm_dot, ramp_n,
                                          comp_n, params.l_path)
                gp, cp = trans.current(), params.cp
                if trans.done:
                    trans = None
                g_row = gains_row(gp)
                w0 = gp.omega0
                comp_flag = COMPENSATE if params.comp_enabled else 0
                pending_flags = CHANGED
                self.changes_applied += len(applied)
                for _p, fut in applied:
                    if fut is not None and not fut.done():
                        fut.set_result(k + 1)
            if k % 20 == 10:
                self.stalls.sample_steal()
            elif k % 200 == 100:
                self._housekeeping(k)
            k += 1

    def swing_status(self) -> dict | None:
        """The swing-up's phase, catch time and number of catches (None: no swing-up)."""
        if self.swingup is None:
            return None
        w = self.swing_w
        if w is None:
            return {"phase": "swinging", "swing_up_time": None, "catches": 0}
        caught = self.swing_caught_tick
        return {"phase": PHASES[int(w.phase)],
                "swing_up_time": None if caught is None else caught * self.h,
                "catches": int(w.catches)}

    def _housekeeping(self, k: int) -> None:
        """Scheduled garbage collection (outside the tick)."""
        if not self.manage_gc:
            return
        now = self.clock.now_ns
        gen = 2 if k % 12000 == 100 else (1 if k % 2000 == 100 else 0)
        t = now()
        gc.collect(gen)
        us = (now() - t) / 1e3
        self.gc_runs += 1
        if us > self.gc_max_us:
            self.gc_max_us = us

    # --- statistics ------------------------------------------------------------------

    def stats(self) -> dict:
        """The run's timing statistics (``frictionlab run --json`` fields and more)."""
        j = self.jitter.summary_us()
        c = self.compute.summary_us()
        r = self.rig_io.summary_us()
        scheduled = self.ticks + self.missed

        def ms(v):
            return None if v is None else v / 1000.0

        return {
            "ticks": self.ticks,
            "missed": self.missed,
            "overruns": self.overruns,
            "jitter_ms": {"p50": ms(j["p50"]), "p99": ms(j["p99"]), "p999": ms(j["p999"]),
                          "max": ms(j["max"]), "mean": ms(j["mean"])},
            "compute_us": {"p50": c["p50"], "p99": c["p99"], "p999": c["p999"],
                           "max": c["max"], "mean": c["mean"]},
            "rig_us": {"p50": r["p50"], "p99": r["p99"], "p999": r["p999"],
                       "max": r["max"], "mean": r["mean"]},
            "missed_fraction": self.missed / scheduled if scheduled else 0.0,
            "rig_timeouts": self.rig_timeouts,
            "stalls": self.stalls.count,
            "max_stall_ms": self.stalls.max_ms,
            "stall_list": list(self.stalls.stalls),
            "unaccounted_stalls_over_50ms": len(self.stalls.unaccounted(50.0)),
            "gc": {"runs": self.gc_runs, "max_us": self.gc_max_us},
            "changes_applied": self.changes_applied,
            "sched_fifo": self.sched_fifo,
            "stop_reason": self.stop_reason,
            "stop_detail": self.stop_detail,
            "stop_tick": self.stop_tick,
            **({"swing_up": self.swing_status()} if self.swingup is not None else {}),
            **self.rig.counters(),
        }


def _swing_stop_detail(code: str, p: SwingUpParams, arm: float, arm_dot: float) -> str:
    if code == "not_caught":
        return f"the swing-up did not catch the pendulum within {p.time_limit:g} s"
    if code == "arm_travel":
        return f"|Omega| = {abs(arm):.3f} rad > swingup.arm_limit {p.arm_limit:g} rad"
    return (f"|Omega'| = {abs(arm_dot):.3f} rad/s > swingup.arm_speed_limit "
            f"{p.arm_speed_limit:g} rad/s")
