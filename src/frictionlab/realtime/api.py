"""RealtimeController: the loop thread, the log writer, the mailbox and the console API.

See the package docstring (:mod:`frictionlab.realtime`) for the API summary.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import sys
import threading
import time
from concurrent.futures import Future
from pathlib import Path

import numpy as np

from ..config import Config
from ..model.adaptive import ADAPT_STATES
from ..model.rig import RigScaling
from .clock import MonotonicClock
from .datalog import LogWriter, link_no_clobber, writer_identity
from .loop import STOP_REASONS, Loop, Safety
from .osrt import single_thread_blas, try_realtime_priority
from .params import ControlParams
from .rigs import Rig, RigError, open_rig, parse_backend
from .samples import Subscription

__all__ = ["GC_POLICY", "ControllerStateError", "RealtimeController"]

GC_POLICY = ("gc.freeze() + gc.disable() during the run; the loop runs gc.collect(0) every "
             "1 s, gc.collect(1) every 10 s, gc.collect(2) every 60 s, after a tick's output")
_SWITCH_INTERVAL = 2e-4


class ControllerStateError(RuntimeError):
    """A start refused because of the controller's state (closed, or already
    running), not because of the rig (:class:`~frictionlab.realtime.rigs.RigError`)."""


class RealtimeController:
    """The real-time controller: owns the loop thread, the rig and the run's log.

    Parameters
    ----------
    cfg : Config
        Plant (``sim`` backend), design, compensation and ``sim.*`` settings.
    backend : str or Rig
        ``"sim"``, ``"udp://HOST:PORT"``, ``"serial://DEVICE"`` or a rig object.
    log_dir : path
        Where runs are logged (created).  ``None`` disables logging.
    clock : clock, optional
        Default :class:`~.clock.MonotonicClock` (tests pass a fake one).
    safety : Safety, optional
        Angle limit, start tolerance, silence limit.
    duration : float, optional
        Stop each run after this many seconds (reason ``duration``).
    realtime : bool
        Try SCHED_FIFO for the loop thread (and the log writer, at a lower
        priority, so it cannot be preempted while holding the GIL), and keep
        the process's OpenBLAS to one thread
        (:func:`~.osrt.single_thread_blas`: a design change then holds the
        GIL for about 1 ms instead of up to 12).
    manage_gc : bool
        Freeze/disable the garbage collector during runs (see :mod:`.loop`).
    fsync : bool
        fsync the log after every write.
    prewarm_us : float
        Cache pre-warming before each deadline (see :mod:`.loop`); 0 = off.
    cpu : int, optional
        Pin the loop thread to this CPU (with ``realtime``; see :mod:`.osrt`).
    sim_lockstep : bool
        ``sim`` backend: one plant step per executed tick (see
        :class:`~.rigs.SimRig`).
    swing_up : bool
        Runs start with the swing-up (``swingup.*`` of ``cfg``,
        :mod:`frictionlab.model.swingup`); may be changed between runs (the
        console's Swing up button sets it for the run it starts).
    experiment : object, optional
        Run an identification experiment (:mod:`.experiment`) in place of
        the balancing controller: same loop, timing, safety and logging;
        the run ends with reason ``finished`` when its schedule is done.
        Its ``describe()`` goes into the sidecar (``experiment``) and
        :meth:`status`, its ``progress`` into :meth:`status`.
    """

    def __init__(self, cfg: Config, backend: str | Rig = "sim", *, log_dir="runs",
                 clock=None, safety: Safety | None = None, duration: float | None = None,
                 realtime: bool = True, manage_gc: bool = True, fsync: bool = False,
                 scaling: RigScaling | None = None, prewarm_us: float = 0.0,
                 cpu: int | None = None, sim_lockstep: bool = False,
                 log_formats: tuple[str, ...] = ("csv",), experiment=None,
                 swing_up: bool = False):
        self.cfg = cfg
        self.swing_up = swing_up
        self.experiment = experiment
        #: The experiment of the current (or last) run: ``experiment``, or the one given
        #: to :meth:`start` for that run.
        self.run_experiment = experiment
        self.log_formats = tuple(log_formats)
        self.sim_lockstep = sim_lockstep
        self.backend = backend
        self.backend_name = backend if isinstance(backend, str) else backend.name
        self.log_dir = None if log_dir is None else Path(log_dir)
        self.clock = clock or MonotonicClock()
        self.safety = safety or Safety()
        self.duration = duration
        self.realtime = realtime
        self.manage_gc = manage_gc
        self.fsync = fsync
        self.prewarm_us = prewarm_us
        self.cpu = cpu
        if not 0 <= prewarm_us < cfg.design.h * 1e6 / 2:
            raise ValueError(f"prewarm_us must be in [0, h/2), got {prewarm_us}")
        self.scaling = scaling or cfg.rig
        if isinstance(backend, str) and backend != "sim":
            check_backend(backend)
        self._params = ControlParams.from_config(cfg)
        self._params.warm()
        self.blas_single_threaded = single_thread_blas() if realtime else []
        self._lock = threading.RLock()
        self._accepting = False
        self._subs: list[Subscription] = []
        self._loop: Loop | None = None
        self._rig: Rig | None = None
        self._writer: LogWriter | None = None
        self._thread: threading.Thread | None = None
        self._done = threading.Event()
        self._done.set()
        self._closed = False
        self._unnamed_recording: dict | None = None
        self._stop_asked: tuple[str, str] | None = None
        self.run_id: str | None = None
        self.started: str | None = None
        self.events: list[dict] = []
        self.last_stats: dict | None = None
        self._initial_params: ControlParams | None = None
        self._t_start = 0.0
        self._writer_identity = writer_identity()

    # --- life cycle ---------------------------------------------------------------

    def start(self, experiment=None, swing_up: bool | None = None, *,
              hanging: bool = False) -> None:
        """Start a run in the loop thread (open the rig, the log, go).

        ``experiment`` (a :class:`~.experiment.RigExperiment`, one run per
        object) runs in place of the balancing controller for this run only
        (the console's Experiments panel); on the ``sim`` backend its
        pendulum then starts hanging.  ``swing_up`` True/False starts this run
        with/without the swing-up (None: :attr:`swing_up`, the controller's
        setting).  ``hanging``: on an emulated rig (``sim``; ``rig-sim`` over
        UDP, whose operator's hand lets it hang) the pendulum starts hanging
        at rest (the console's Swing up); a real rig starts from where the
        pendulum is.
        """
        loop = self._prepare(experiment, swing_up, hanging)
        self._thread = threading.Thread(target=self._execute, args=(loop,),
                                        name="frictionlab-rt", daemon=True)
        self._thread.start()

    def run(self) -> dict:
        """Run in the calling thread until a stop; return the statistics."""
        loop = self._prepare()
        self._execute(loop)
        return self.last_stats

    def stop(self, reason: str = "user", detail: str | None = None) -> None:
        """Ask the loop to stop (u = 0 at the next tick); returns at once.

        Safe to call from a signal handler or any thread, at any moment: a
        stop asked for while :meth:`start` is still opening the rig (the
        ``HELLO`` exchange, up to a second) ends that attempt at once, and the
        run then stops at its first tick, before any command but the zero.
        ``detail`` is recorded with the reason (default ``"requested"``).
        """
        if reason not in STOP_REASONS:
            raise ValueError(f"reason must be one of {', '.join(STOP_REASONS)}; got {reason!r}")
        # seen by a start in progress (_prepare sets _loop, then reads this)
        self._stop_asked = (reason, detail or "requested")
        loop = self._loop
        if loop is not None:
            loop.request_stop(reason, detail or "requested")

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the current run has ended; False on timeout."""
        return self._done.wait(timeout)

    @property
    def running(self) -> bool:
        return not self._done.is_set()

    def close(self) -> None:
        """Stop a run in progress (reason ``exit``) and wait for it."""
        if self.running:
            self.stop("exit")
            self.wait(10.0)
        self._closed = True

    def __enter__(self) -> RealtimeController:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _prepare(self, experiment=None, swing_up: bool | None = None,
                 hanging: bool = False) -> Loop:
        swing_up = self.swing_up if swing_up is None else bool(swing_up)
        with self._lock:
            if self._closed:
                raise ControllerStateError("the controller is closed")
            if self.running:
                raise ControllerStateError("the controller is already running")
            self._stop_asked = None
            experiment = experiment if experiment is not None else self.experiment
            self.run_experiment = experiment
            rig_cfg = self.cfg
            if (experiment is not None or hanging) and self.backend == "sim":
                # the simulated rig's pendulum hangs at rest, as a rig's does before an
                # experiment
                rig_cfg = rig_cfg.with_values({"sim.initial_angle": math.pi})
            rig = (open_rig(self.backend, rig_cfg, lockstep=self.sim_lockstep,
                            duration=self.duration)
                   if isinstance(self.backend, str)
                   else self.backend)
            rig.open(h=self.cfg.design.h, cancel=lambda: self._stop_asked is not None)
            if hanging and self.backend != "sim" and getattr(rig, "emulated", False):
                # rig-sim's operator lets the pendulum hang; another rig: where it is
                with contextlib.suppress(RigError, OSError):
                    rig.hand({"hang": True})
            try:
                loop = Loop(rig, self.clock, self._params, safety=self.safety,
                            scaling=self.scaling, duration=self.duration,
                            realtime=self.realtime, manage_gc=self.manage_gc,
                            prewarm_us=self.prewarm_us, cpu=self.cpu,
                            experiment=experiment,
                            swingup=self.cfg.swingup if swing_up and experiment is None
                            else None)
                self._writer = None
                if self.log_dir is not None:
                    self._writer = self._open_log(loop)
                else:
                    self.run_id = self._new_run_id()
            except BaseException:
                rig.close()
                raise
            self._rig = rig
            self._initial_params = self._params
            self.started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
            self._t_start = time.monotonic()
            self.events = []
            self._loop = loop
            asked = self._stop_asked
            if asked is not None:  # a stop (a signal) came while the rig was being opened
                loop.request_stop(*asked)
            self._update_sinks()
            self._accepting = True
            self._done.clear()
            self.last_stats = None
            if self._writer is not None:
                self._writer.write_meta(self._meta())
                # the writer shares the loop's CPU: holding the GIL, it is preempted by
                # the loop and hands the GIL over at once, whereas on another CPU that
                # is busy (or paused by the host) it could keep the loop waiting
                prio = ((lambda: try_realtime_priority(10, self.cpu)) if self.realtime
                        else None)
                self._writer.start(prio)
            self._event("start", backend=self.backend_name)
            return loop

    def _execute(self, loop: Loop) -> None:
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(_SWITCH_INTERVAL)
        try:
            loop.run()
        finally:
            sys.setswitchinterval(old_switch)
            with self._lock:
                self._accepting = False
                while loop.mailbox:
                    _p, fut = loop.mailbox.popleft()
                    if fut is not None and not fut.done():
                        fut.set_result(None)
            try:
                self._finish(loop)
            finally:
                self._done.set()

    def _finish(self, loop: Loop) -> None:
        """After the loop: release the rig, close the log, final statistics."""
        self._event("stop", reason=loop.stop_reason, detail=loop.stop_detail)
        try:
            self._rig.close()
        except Exception as exc:
            self._event("rig_close_error", error=repr(exc))
        self.last_stats = self._stats()
        if self._writer is not None:
            was_recording = self._writer.recording

            def final_meta() -> dict:
                # the last rows are written after the loop stopped: if that failed, the
                # run's outcome is a failed log whatever ended it (no silent data loss)
                failed = self._writer.failed
                if failed and loop.stop_reason in ("duration", "user", "signal", "exit",
                                                   "finished"):
                    loop.stop_detail = (f"{failed} (after the run had stopped: "
                                        f"{loop.stop_reason}, {loop.stop_detail})")
                    loop.stop_reason = "log_failed"
                    self._event("stop", reason=loop.stop_reason, detail=loop.stop_detail)
                return self._meta()

            self._writer.close(final_meta)
            if was_recording:
                self._unnamed_recording = self._writer.last_recording
            self.last_stats = self._stats()

    def _new_run_id(self, n: int = 1) -> str:
        base = time.strftime("run-%Y%m%d-%H%M%S") + f"-{os.getpid()}"
        return base if n == 1 else f"{base}-{n}"

    def _open_log(self, loop: Loop) -> LogWriter:
        """The run's log writer under the first run id whose files do not exist yet
        (nothing of an earlier run or a recording is ever overwritten)."""

        def failed(message: str) -> None:
            loop.request_stop("log_failed", message)

        for n in range(1, 10_000):
            self.run_id = self._new_run_id(n)
            try:
                return LogWriter(self.log_dir, self.run_id, fsync=self.fsync,
                                 meta_fn=self._meta, on_error=failed,
                                 formats=self.log_formats)
            except FileExistsError:
                continue
        raise OSError(f"no free run name in {self.log_dir}")

    # --- mailbox ----------------------------------------------------------------------

    def submit(self, changes: dict, *, confirm: bool = False) -> Future:
        """Validate ``changes`` now and apply them atomically between two ticks.

        Unless ``confirm`` is true, the changed settings must also pass the
        model's check (:attr:`~.params.ControlParams.loop_check`: the sampled
        loop and the compensator stable, the predicted peak of u within the
        DAC range); a change the model predicts unstable or saturating is
        refused with :class:`~.params.UnsafeChange`, which says why and what
        would be safe.

        Raises
        ------
        ValueError
            (:class:`~.params.ChangeError`, a
            :class:`~frictionlab.config.ConfigError`) if a change is invalid,
            or (:class:`~.params.UnsafeChange`) unsafe and not confirmed;
            nothing is applied then.  ``keys`` names what was refused.

        Returns
        -------
        Future
            Resolves to the tick number from which the change is in effect,
            or None if no run is in progress (the change then applies to the
            next run).
        """
        with self._lock, np.errstate(all="ignore"):
            # values the design cannot compute with (an omega_0 of 1e-300) are refused by
            # the check below, not printed as numpy's overflow warnings on the terminal
            current = self._params
            new = current.apply(changes)
            if not confirm and not new.loop_check.ok:
                raise current.refusal(new)
            new.l_path  # noqa: B018 - the gain transition's path, designed here, not in a tick
            self._params = new
            fut: Future = Future()
            loop = self._loop
            if self._accepting and loop is not None:
                loop.mailbox.append((new, fut))
            else:
                fut.set_result(None)
            self._event("change", changes=changes,
                        **({"confirmed_unsafe": new.loop_check.verdict}
                           if not new.loop_check.ok else {}))
        return fut

    # --- console data -----------------------------------------------------------------

    def subscribe(self, maxlen: int = 1000) -> Subscription:
        """A new queue receiving every tick's sample (dropping when full)."""
        sub = Subscription(maxlen)
        with self._lock:
            self._subs.append(sub)
            self._update_sinks()
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)
                sub.closed = True
            self._update_sinks()

    def _update_sinks(self) -> None:
        loop = self._loop
        if loop is None:
            return
        sinks = [s.put for s in self._subs]
        if self._writer is not None:
            sinks.insert(0, self._writer.put)
        loop.sinks = tuple(sinks)

    def push(self, kick: float) -> None:
        """Disturb the pendulum by ``kick`` rad/s (emulated rigs only)."""
        rig = self._rig
        if not self.running or rig is None:
            raise RuntimeError("push needs a running controller")
        rig.push(float(kick))
        self._event("push", kick=float(kick))

    def hand(self, action: dict) -> None:
        """The emulated operator's hand (``rig-sim`` over UDP: a lap of the pendulum or
        the arm, a push; see :data:`.rigsim.HAND`); ``RigError`` on another rig."""
        rig = self._rig
        if not self.running or rig is None:
            raise RuntimeError("the hand needs a running controller")
        rig.hand(dict(action))
        self._event("hand", **{k: v for k, v in action.items() if k != "event"})

    # --- Save Data ------------------------------------------------------------------

    def record_start(self) -> None:
        """Start saving the samples to a separate pair of files (the Save button)."""
        w = self._writer
        if not self.running or w is None:
            raise RuntimeError("recording needs a running controller with a log directory")
        w.record_start()
        self._unnamed_recording = None
        self._event("record_start")

    @property
    def unnamed_recording(self) -> dict | None:
        """The recording the end of the run closed under an automatic name, or None.

        ``{"dat": path, "csv": path, "rows": n}``, set before :attr:`running`
        turns false and kept until :meth:`record_stop` takes it (or a new
        recording starts): a console asks the operator for its name.
        """
        return self._unnamed_recording

    def record_stop(self, name: str | None = None) -> dict:
        """End the recording; save it as ``<log_dir>/<name>.dat`` and ``.csv``.

        Returns ``{"dat": path, "csv": path, "rows": n}``.  If the run ended
        while recording, the recording was closed under an automatic name and
        this renames it.
        """
        w = self._writer
        if w is not None and w.recording and self.running:
            out = w.record_stop(name)
        elif self._unnamed_recording is not None:
            out = _rename_recording(self._unnamed_recording, name, self.log_dir)
            self._unnamed_recording = None
        else:
            raise RuntimeError("no recording is running")
        self._event("record_stop", **out)
        return out

    # --- status -----------------------------------------------------------------------

    def _event(self, event: str, **info) -> None:
        loop = self._loop
        rec = {"t": round(time.monotonic() - self._t_start, 4), "event": event,
               "tick": None if loop is None else loop.k, **info}
        self.events.append(rec)

    def _stats(self) -> dict:
        loop = self._loop
        out = loop.stats()
        w = self._writer
        out["dropped_log_samples"] = w.dropped if w is not None else 0
        out["log_written"] = w.written if w is not None else 0
        out["log_error"] = w.error if w is not None else None
        out["dropped_console_samples"] = sum(s.dropped for s in self._subs)
        out["log"] = w.paths["csv"] if w is not None else None
        out["log_files"] = w.paths if w is not None else None
        out["backend"] = self.backend_name
        out["duration_s"] = loop.ticks * loop.h if loop.ticks else 0.0
        return out

    def status(self) -> dict:
        """A JSON-ready snapshot for the console (see the package docstring)."""
        loop = self._loop
        applied = loop.params if (loop is not None and self.running) else self._params
        out = {
            "running": self.running,
            "run_id": self.run_id,
            "backend": self.backend_name,
            "h": self.cfg.design.h,
            "friction": self._plant_friction(),
            **applied.describe(),
            "loop_check": applied.loop_check.to_json(),
            "adaptation": self._adaptation(),
            "pending_changes": len(loop.mailbox) if loop is not None else 0,
            "recording": bool(self._writer is not None and self._writer.recording),
            "safety": dataclasses.asdict(self.safety),
        }
        exp = self.run_experiment
        if exp is not None:
            out["experiment"] = {**exp.describe(), "progress": exp.progress,
                                 "phase": exp.phase}
        if loop is None:
            out.update({"stop_reason": None, "ticks": 0, "missed": 0, "overruns": 0,
                        "t": 0.0, "swing_up": None})
            return out
        st = self._stats()
        out.update(st)
        out["t"] = loop.k * loop.h
        out["rt_note"] = loop.rt_note
        out["swing_up"] = loop.swing_status()
        out.pop("stall_list", None)
        return out

    def _adaptation(self) -> dict | None:
        """The adaptive compensator's estimates now (None with another compensator).

        ``coulomb``/``stiction``: the adapted levels F_C, F_S (m/s^2) the
        compensator uses; ``start``: the values it started from (its
        ``compensation.*`` parameters); ``status``: what the law did at the
        last tick (:data:`frictionlab.model.adaptive.ADAPT_STATES`: ``adapting``,
        or frozen: ``stuck``, ``presliding``, ``bad_signal``, ``saturated``;
        ``off``: not started yet).
        """
        loop = self._loop
        params = loop.params if loop is not None else self._params
        if params.comp_kind != "adaptive" or not params.comp_enabled:
            return None
        start = params.comp_params["adaptive"]
        out = {"start": {"coulomb": start.coulomb, "stiction": start.stiction},
               "coulomb": start.coulomb, "stiction": start.stiction, "status": "off"}
        s = loop.state if loop is not None else None
        if s is not None and s.adapt > 0:
            out.update(coulomb=float(s.fc_hat), stiction=float(s.fs_hat),
                       status=ADAPT_STATES[int(s.adapt)])
        return out

    def _plant_friction(self) -> str | None:
        rig = self._rig
        if rig is not None and rig.plant_friction is not None:
            return rig.plant_friction
        if self.backend_name == "sim":
            return self.cfg.friction_kind
        return None

    def sidecar(self) -> dict:
        """The run's sidecar (``<run_id>.json``) as of now: configuration, ``h``, the
        initial and current design and compensation, events, statistics.  A Save Data
        recording gets one beside it, so that ``frictionlab features`` reads it alone."""
        return self._meta()

    def _meta(self) -> dict:
        loop = self._loop
        w = self._writer
        initial = self._initial_params.describe() if self._initial_params else None
        current = loop.params.describe() if loop is not None else None
        rig = self._rig
        return {
            "run_id": self.run_id,
            "started": self.started,
            "running": self.running and loop is not None and loop.stop_reason is None,
            "updated": time.time(),
            "writer": self._writer_identity,
            "backend": self.backend_name,
            "sim_lockstep": self.sim_lockstep,
            "h": self.cfg.design.h,
            "plant": self.cfg.plant_kind,
            "u_unit": self.cfg.plant_model.u_unit,
            "t0_monotonic_ns": None if loop is None else loop.t0_ns,
            "x0": None if loop is None else loop.x0,
            "config": self.cfg.as_flat_dict(),
            "plant_friction": self._plant_friction(),
            "rig": None if rig is None or rig.info is None else rig.info._asdict(),
            "scaling": dataclasses.asdict(self.scaling),
            "safety": dataclasses.asdict(self.safety),
            "initial": initial,
            "current": current,
            "adaptation": self._adaptation(),
            "stop_reason": None if loop is None else loop.stop_reason,
            "stop_detail": None if loop is None else loop.stop_detail,
            "stop_tick": None if loop is None else loop.stop_tick,
            "traceback": None if loop is None else loop.traceback,
            "stats": None if loop is None else self._stats(),
            "dropped_log_samples": 0 if w is None else w.dropped,
            "files": None if w is None else w.paths,
            "realtime": {"sched_fifo": bool(loop and loop.sched_fifo),
                         "note": None if loop is None else loop.rt_note,
                         "gc_policy": GC_POLICY if self.manage_gc else "default",
                         "switch_interval_s": _SWITCH_INTERVAL,
                         "blas_single_threaded": self.blas_single_threaded},
            "events": list(self.events),
            "experiment": (None if self.run_experiment is None
                           else self.run_experiment.describe()),
        }


def check_backend(spec: str) -> None:
    """Validate a backend string's syntax without connecting (:func:`.rigs.parse_backend`)."""
    parse_backend(spec)


def _rename_recording(rec: dict, name: str | None, log_dir) -> dict:
    if name is None:
        return rec
    import re

    name = re.sub(r"\.(dat|csv)$", "", name)
    if not re.match(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$", name):
        raise ValueError(f"recording name {name!r}: use letters, digits, '.', '_', '-'")
    out = dict(rec)
    for ext in ("dat", "csv"):
        dst = Path(log_dir) / f"{name}.{ext}"
        if dst.exists():
            raise FileExistsError(f"{dst} exists")
    done = []
    try:
        for ext in ("dat", "csv"):
            dst = Path(log_dir) / f"{name}.{ext}"
            link_no_clobber(rec[ext], dst)
            done.append((dst, rec[ext]))
            out[ext] = str(dst)
    except OSError:
        for dst, src in done:
            link_no_clobber(dst, src)
        raise
    return out

