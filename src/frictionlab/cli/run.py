"""Subcommands ``frictionlab run`` (the real-time controller) and ``frictionlab rig-sim``.

``run --headless --duration S --json`` runs the loop without the console and
prints its statistics (``--json`` without ``--headless`` is bad input, exit
status 2: the console prints its address, never one JSON object); without
``--headless`` it hands the controller to the operator console
(``frictionlab.console.serve(controller, host, port, token)``) when that
module is installed, else it says so and runs headless until Ctrl-C.
Exit status of ``run``: 0 when the run ended as asked (``duration``,
``signal``, ``user``, ``exit``), 1 after a safety stop or when the rig
cannot be reached, 2 on bad input.

The serving bound: with ``FRICTIONLAB_SERVE_LIMIT=S`` in the environment
(the test suite sets it), a command that would otherwise serve until a signal
(``rig-sim`` and ``run --headless`` without ``--duration``, and the console)
stops after S seconds and exits with status 1, saying so: a test whose
expected refusal went away fails instead of serving forever
(docs/development.md).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import os
import signal
import sys

from ..startsignals import Interrupted, interface_stats, not_started, take_over
from .common import (
    UsageError,
    add_config_args,
    add_stall_args,
    check_output_dir,
    config_from_args,
    emit_json,
    finite,
    flush_notes,
    hanging_start,
    safety_from_args,
)

__all__ = ["SERVE_LIMIT_ENV", "WAIT_PRIORITY", "interface_stats", "register_cli",
           "serve_limit", "start_console", "waiting_priority"]

DEFAULT_RIG_PORT = 9870
PREWARM_US = 300.0
_OK_STOPS = ("duration", "signal", "user", "exit")
#: The environment variable of the serving bound (seconds; unset: no bound).
SERVE_LIMIT_ENV = "FRICTIONLAB_SERVE_LIMIT"
#: ``--log-format`` choices (:data:`frictionlab.realtime.datalog.LOG_FORMATS`; kept here so
#: that ``--help`` does not import the logger; a test checks they agree).
LOG_FORMATS = ("csv", "parquet")


def serve_limit() -> float | None:
    """The serving bound in seconds (``$FRICTIONLAB_SERVE_LIMIT``), None when unset.

    A command that serves until a signal (``rig-sim`` and ``run --headless``
    without ``--duration``, the console) stops after this long and exits 1.
    """
    text = os.environ.get(SERVE_LIMIT_ENV, "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0 and math.isfinite(value)):
        raise UsageError(f"{SERVE_LIMIT_ENV}={text[:40]!r}: the serving bound must be a "
                         "number of seconds > 0 (or unset)")
    return value


def _bound_hit(command: str, limit: float) -> int:
    print(f"frictionlab {command}: error: stopped after {limit:g} s, the serving bound "
          f"{SERVE_LIMIT_ENV} (give --duration for a run that ends by itself)",
          file=sys.stderr)
    return 1


class _ConsoleBound:
    """Ends the console after ``limit`` seconds as a SIGTERM would (the console and
    :class:`RunSignals` catch it), only while :meth:`close` has not been called."""

    def __init__(self, limit: float):
        import threading

        self.limit = limit
        self.fired = False
        self._done = False
        self._lock = threading.Lock()
        self._timer = threading.Timer(limit, self._fire)
        self._timer.daemon = True
        self._timer.start()

    def _fire(self) -> None:
        with self._lock:
            if not self._done:
                self.fired = True
                os.kill(os.getpid(), signal.SIGTERM)

    def close(self) -> None:
        with self._lock:
            self._done = True
        self._timer.cancel()


def _cpu_arg(text: str):
    """``--cpu``: auto, none or a CPU number (argparse turns the ValueError
    into its one-line usage error, exit status 2)."""
    if text in ("auto", "none"):
        return text
    try:
        cpu = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be auto, none or a CPU number, got {text[:40]!r}") from None
    try:
        allowed = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity on this system: any CPU number
        allowed = None
    if cpu < 0 or (allowed is not None and cpu not in allowed):
        which = f"one of {', '.join(map(str, allowed))}" if allowed else "a CPU number >= 0"
        raise argparse.ArgumentTypeError(f"must be auto, none or {which}, got {cpu}")
    return cpu


def _resolve_cpu(value):
    from ..realtime.osrt import default_cpu

    if value == "none":
        return None
    if value == "auto":
        return default_cpu()
    return value


_CPU_HELP = ("pin the real-time thread to this CPU: auto (the last CPU; run and rig-sim then "
             "share it), none, or a number (default auto; see docs/realtime.md)")


def register_cli(sub) -> None:
    p = sub.add_parser("run", help="the 200 Hz real-time controller with the operator console")
    p.add_argument("--backend", default="sim",
                   metavar="sim|udp://HOST:PORT|serial://DEVICE|qube2://ID|qube3://ID",
                   help="rig backend (default: sim, the simulated plant in-process; "
                        "qube2://0: a Quanser QUBE-Servo 2, docs/qube.md)")
    p.add_argument("--host", default="127.0.0.1", help="console address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="console port (default 8000)")
    p.add_argument("--token", default=None,
                   help="console access token (default $FRICTIONLAB_TOKEN); required when "
                        "--host is not a loopback address (docs/console.md)")
    p.add_argument("--headless", action="store_true", help="run without the console")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: run until Ctrl-C)")
    p.add_argument("--json", action="store_true",
                   help="with --headless: print the run's statistics as one JSON object "
                        "(without --headless it is refused, exit status 2)")
    p.add_argument("--log-dir", default="runs", help="where runs are logged (default ./runs)")
    p.add_argument("--log-format", choices=LOG_FORMATS, default="csv",
                   help="csv: the .dat/.csv pair and the JSON sidecar (default); parquet: "
                        "also a .parquet table of the CSV's columns for the run and every "
                        "recording, written when each ends (docs/logs.md)")
    add_config_args(p, backend=True)
    p.add_argument("--angle-limit", type=float, default=0.35, metavar="RAD",
                   help="stop when |theta| exceeds this (default 0.35 rad)")
    p.add_argument("--start-tolerance", type=float, default=0.15, metavar="RAD",
                   help="start only if |theta| <= this (default 0.15 rad; no swing-up)")
    add_stall_args(p)
    p.add_argument("--gain-transition", type=float, default=2.0, metavar="S",
                   help="new gains (a design change while running) replace the running "
                        "ones over S seconds, through the designs in between, so a switch in "
                        "mid-cycle does not throw the pendulum past the angle limit; 0: at "
                        "once (default: 2)")
    p.add_argument("--compensation-transition", type=float, default=2.0, metavar="S",
                   help="a compensator switched on while running (or to another kind) "
                        "starts at its steady estimate and is ramped in over S seconds, so "
                        "that u does not jump; 0: at once (default: 2)")
    p.add_argument("--prewarm-us", type=float, default=PREWARM_US, metavar="US",
                   help="wake US microseconds before each deadline, run the tick's code on "
                        f"scratch data and busy-wait to the deadline (default {PREWARM_US:g}; "
                        "0 = off; see docs/realtime.md)")
    p.add_argument("--cpu", type=_cpu_arg, default="auto", help=_CPU_HELP)
    p.add_argument("--fsync", action="store_true", help="fsync the log after every write")
    p.add_argument("--swing-up", action="store_true",
                   help="start from wherever the pendulum is (hanging) and swing it up by "
                        "energy control before balancing (swingup.* keys; the sim backend "
                        "starts hanging unless sim.initial_angle is set); the JSON adds "
                        "swing_up {phase, swing_up_time, catches}")
    p.add_argument("--sim-lockstep", action="store_true",
                   help="sim backend: advance the simulated plant one step per executed tick, "
                        "so that missed deadlines (host pauses) do not move it (default: it "
                        "moves on in real time with u held)")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("rig-sim",
                       help="an emulated rig speaking the UDP protocol (docs/protocol.md)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=DEFAULT_RIG_PORT,
                   help=f"UDP port (default {DEFAULT_RIG_PORT}; 0 picks a free one)")
    p.add_argument("--serial", metavar="DEVICE", default=None,
                   help="serve on a serial device instead of UDP")
    add_config_args(p, friction=False)
    from ..config import PLANT_FRICTION_KINDS

    p.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default="classical",
                   help="friction model of the emulated plant (default: classical)")
    p.add_argument("--hanging", action="store_true",
                   help="each session starts with the pendulum hanging at rest (for run "
                        "--swing-up; the same as --set sim.initial_angle=3.14159...)")
    p.add_argument("--watchdog", type=float, default=0.05, metavar="S",
                   help="zero the motor when no command arrives for S seconds (default 0.05)")
    p.add_argument("--fault", action="append", default=[], metavar="KEY=VALUE",
                   help="inject a fault (test/teaching feature; see docs/protocol.md): "
                        "nan, out_of_range, corrupt, duplicate, drop, ignore_commands "
                        "(counts), seq_offset, silent (s), push (rad/s)")
    p.add_argument("--fault-after", type=float, default=0.0, metavar="S",
                   help="apply the --fault settings S seconds after start-up (default 0: "
                        "at once)")
    p.add_argument("--hand", action="append", default=[], metavar="KEY=VALUE",
                   help="the operator's hand, scripted (docs/protocol.md): lap=pendulum|arm "
                        "(one full lap by hand), seconds, direction, push (rad/s to the "
                        "pendulum), push_arm (rad/s to the arm); repeatable")
    p.add_argument("--hand-after", type=float, default=0.0, metavar="S",
                   help="do the --hand actions S seconds after start-up (default 0)")
    p.add_argument("--no-realtime", action="store_true",
                   help="do not ask for SCHED_FIFO priority")
    p.add_argument("--cpu", type=_cpu_arg, default="auto", help=_CPU_HELP)
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="serve S seconds, then exit 0 (default: until Ctrl-C or SIGTERM)")
    p.add_argument("--json", action="store_true",
                   help="print {\"listening\", \"host\", \"port\"} as one JSON object when ready")
    p.set_defaults(func=cmd_rig_sim)


def cmd_run(args) -> int:
    try:
        return _cmd_run(args)
    except Interrupted as exc:
        # a stop signal before the run's own handlers took over (frictionlab.startsignals,
        # installed by the executable first thing): nothing opened, nothing written
        return _report(not_started(exc.name), args)


def _cmd_run(args) -> int:
    from ..realtime import RealtimeController
    from ..realtime.clock import MonotonicClock

    if args.json and not args.headless:
        raise UsageError("--json needs --headless: the console prints its address, not one "
                         "JSON object (use --headless --duration S --json)")
    cfg = hanging_start(args, config_from_args(args))
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise UsageError(f"--duration must be > 0, got {args.duration}")
    if not 0 <= args.prewarm_us < cfg.design.h * 1e6 / 2:
        raise UsageError(f"--prewarm-us must be in [0, h/2), got {args.prewarm_us}")
    if not 0 <= args.port < 65536:
        raise UsageError(f"--port must be in 0..65535, got {args.port}")
    safety = safety_from_args(args, angle_limit=args.angle_limit,
                              start_tolerance=args.start_tolerance,
                              gain_transition=args.gain_transition,
                              compensation_transition=args.compensation_transition)
    check_output_dir(args.log_dir, "--log-dir")
    limit = serve_limit()
    # the serving bound ends a headless run that has no --duration as a signal would
    args.bound = limit if args.headless and args.duration is None else None
    args.bound_hit = False
    flush_notes(args)
    with RunSignals() as signals:
        if signals.received is not None:  # came during the start-up: nothing ran
            return _report(not_started(signals.received), args)
        ctl = RealtimeController(cfg, args.backend, log_dir=args.log_dir,
                                 clock=MonotonicClock(), safety=safety,
                                 prewarm_us=args.prewarm_us, duration=args.duration,
                                 realtime=not args.no_realtime, fsync=args.fsync,
                                 cpu=_resolve_cpu(args.cpu), sim_lockstep=args.sim_lockstep,
                                 log_formats=("csv", args.log_format),
                                 swing_up=args.swing_up)
        signals.ctl = ctl
        if signals.received is not None:  # before anything ran: no rig opened, no log
            return _report(not_started(signals.received), args)
        if not args.headless:
            # until the console serves (and takes these signals over) a signal ends
            # `run` at once; nothing runs yet
            signals.interrupt = True
            bound = None if limit is None else _ConsoleBound(limit)
            try:
                if start_console(ctl, args.host, args.port, args.token):
                    return 0 if bound is None or not bound.fired else _bound_hit("run", limit)
            except KeyboardInterrupt:
                if bound is not None and bound.fired:
                    return _bound_hit("run", limit)
                print(f"frictionlab run: stopped by {signals.received or 'a signal'}",
                      file=sys.stderr)
                return 0
            finally:
                signals.interrupt = False
                if bound is not None:
                    bound.close()
            print("frictionlab run: the operator console (frictionlab.console) is not "
                  "installed; running headless until Ctrl-C", file=sys.stderr)
        return _run_headless(ctl, args)


def start_console(ctl, host: str, port: int, token: str | None = None) -> bool:
    """Hand ``ctl`` to the operator console and serve it until Exit or a signal.

    The hook of ``frictionlab run`` without ``--headless``: imports
    :mod:`frictionlab.console` and calls ``frictionlab.console.serve(ctl,
    host, port, token)`` (``token`` None: the console's default, e.g.
    ``$FRICTIONLAB_TOKEN``).  The controller is closed (motor zeroed, run
    logged) when the console returns or raises.  Returns False, without
    serving, when the console package is not installed.
    """
    try:
        console = importlib.import_module("frictionlab.console")
    except ModuleNotFoundError as exc:
        if exc.name == "frictionlab.console":
            return False
        raise
    try:
        console.serve(ctl, host, port, token)
    finally:
        ctl.close()
    return True


class RunSignals:
    """The signals of ``frictionlab run``, from the controller's creation to the output.

    SIGINT, SIGTERM, SIGHUP and SIGQUIT (:data:`~.realtime.osrt.STOP_SIGNALS`)
    stop the run with reason ``signal`` whenever they come: while the rig is
    being opened (the ``HELLO`` wait is cut short and the run stops at its
    first tick, writing only u = 0), while it runs (u = 0 at the next tick),
    during the shutdown (nothing more to do; no traceback).  One that comes
    before the run starts is remembered and the run does not start.  The
    console takes them over while it serves (and stops the loop at once too).

    SIGTSTP (Ctrl-Z) stops a running run first (reason ``signal``, detail
    ``SIGTSTP``, motor at zero) and then suspends the process as asked; after
    ``fg`` the process goes on (headless: reports and exits).  SIGXFSZ is
    ignored: a file-size limit then fails a log write, which stops the run as
    ``log_failed``, instead of killing the process with the motor running.
    """

    def __init__(self):
        self.ctl = None
        self.received: str | None = None
        self.interrupt = False
        self._previous: dict = {}

    def __enter__(self):
        from ..realtime.osrt import STOP_SIGNALS

        early = take_over()  # the executable's start-up handler raises no more
        for sig in STOP_SIGNALS:
            self._previous[sig] = signal.signal(sig, self._stop)
        if self.received is None:
            self.received = early
        if hasattr(signal, "SIGTSTP"):
            self._previous[signal.SIGTSTP] = signal.signal(signal.SIGTSTP, self._suspend)
        if hasattr(signal, "SIGXFSZ"):
            self._previous[signal.SIGXFSZ] = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _stop(self, signum, frame) -> None:
        name = signal.Signals(signum).name
        if self.received is None:
            self.received = name
        if self.ctl is not None:
            self.ctl.stop("signal", name)
        if self.interrupt:
            raise KeyboardInterrupt

    def _suspend(self, signum, frame) -> None:
        ctl = self.ctl
        if ctl is not None and ctl.running:
            ctl.stop("signal", "SIGTSTP")
            ctl.wait(2.0)
        signal.signal(signal.SIGTSTP, signal.SIG_DFL)
        try:
            os.kill(os.getpid(), signal.SIGTSTP)  # suspended here until SIGCONT (fg)
        finally:
            signal.signal(signal.SIGTSTP, self._suspend)


#: SCHED_FIFO priority of the main thread while a headless run waits for its end or a
#: signal: that of the console's server (below the loop, 50, and the log writer, 10).
WAIT_PRIORITY = 5


@contextlib.contextmanager
def waiting_priority(realtime: bool):
    """The calling thread at :data:`WAIT_PRIORITY` (where permitted), its own
    scheduling policy back afterwards (``run`` may run in a test's thread)."""
    from ..realtime.osrt import try_realtime_priority

    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0))
    except (AttributeError, OSError):
        before = None
    if realtime and before is not None:
        try_realtime_priority(WAIT_PRIORITY)
    try:
        yield
    finally:
        if realtime and before is not None:
            try:
                os.sched_setscheduler(0, *before)
            except OSError:
                pass


def _run_headless(ctl, args) -> int:
    from ..realtime import RigError

    try:
        try:
            ctl.start()
        except (RigError, OSError) as exc:
            print(f"frictionlab run: error: {exc}", file=sys.stderr)
            return 1
        # block without periodic wake-ups (a woken main thread takes the GIL); signal
        # handlers still run, in this thread, and ask the loop to stop.  At a low
        # SCHED_FIFO priority (below the loop's and the log writer's, as the console's
        # server): on a loaded host a normal thread woke 15-30 ms late for the handler,
        # and the motor ran on for 3-6 ticks after a SIGINT
        with waiting_priority(getattr(ctl, "realtime", False)):
            if not ctl.wait(getattr(args, "bound", None)):  # the serving bound
                args.bound_hit = True
                ctl.stop("signal", SERVE_LIMIT_ENV)
                ctl.wait()
    finally:
        if ctl.running:
            ctl.stop("signal")
            ctl.wait(5.0)
    return _report(ctl.last_stats or {}, args)


def _report(st: dict, args) -> int:
    """Print a headless run's outcome; its exit status."""
    if args.json:
        emit_json(interface_stats(st))
    else:
        j, c = st["jitter_ms"], st["compute_us"]
        print(f"stopped: {st['stop_reason']} ({st.get('stop_detail') or ''})")
        print(f"ticks {st['ticks']}, missed {st['missed']}, overruns {st['overruns']}, "
              f"rig timeouts {st['rig_timeouts']}")
        if j["p50"] is not None:
            print(f"jitter p50 {j['p50']:.3f} ms, p99 {j['p99']:.3f} ms, max {j['max']:.3f} ms;"
                  f" compute p50 {c['p50']:.0f} us, p99 {c['p99']:.0f} us")
        print(f"log: {st['log']}")
    reason = st.get("stop_reason")
    if getattr(args, "bound_hit", False) and reason == "signal":  # not a safety stop first
        return _bound_hit("run", args.bound)
    if reason in _OK_STOPS:
        return 0
    what = ("the log could not be written; the run was stopped with the motor at zero"
            if reason == "log_failed" else "safety stop, the motor was set to zero")
    print(f"frictionlab run: stopped: {reason} ({what}): {st.get('stop_detail') or ''}",
          file=sys.stderr)
    return 1


def cmd_rig_sim(args) -> int:
    from ..realtime.rigsim import FAULTS, run_rig_sim

    cfg = config_from_args(args)
    if args.hanging:
        cfg = cfg.with_values({"sim.initial_angle": math.pi})
    if not 0 <= args.port < 65536:
        raise UsageError(f"--port must be in 0..65535, got {args.port}")
    if not (args.watchdog > 0 and math.isfinite(args.watchdog)):
        raise UsageError(f"--watchdog must be > 0, got {args.watchdog}")
    finite("--fault-after", args.fault_after, 0.0, lo_open=False)
    finite("--duration", args.duration, 0.0)
    limit = None if args.duration is not None else serve_limit()
    faults = {}
    for text in args.fault:
        key, sep, value = text.partition("=")
        if not sep or key not in FAULTS:
            raise UsageError(f"--fault expects KEY=VALUE with KEY one of {', '.join(FAULTS)}; "
                             f"got {text!r}")
        try:
            faults[key] = float(value)
        except ValueError:
            raise UsageError(f"--fault {key}: {value!r} is not a number") from None
        finite(f"--fault {key}", faults[key])
    finite("--hand-after", args.hand_after, 0.0, lo_open=False)
    hand = {}
    for text in args.hand:
        key, sep, value = text.partition("=")
        if not sep:
            raise UsageError(f"--hand expects KEY=VALUE, got {text!r}")
        if key == "lap":
            hand[key] = value
        else:
            try:
                hand[key] = float(value)
            except ValueError:
                raise UsageError(f"--hand {key}: {value!r} is not a number") from None
    if hand:
        from ..realtime.rigsim import hand_error

        error = hand_error(hand)
        if error:
            raise UsageError(f"--hand: {error}")
        hand = {"cmd": "hand", **hand, **({"after": args.hand_after} if args.hand_after
                                          else {})}
    flush_notes(args)

    def announce(info):
        print(f"frictionlab rig-sim: listening on {info['listening']}", file=sys.stderr)
        if args.json:
            emit_json(info)

    ended = run_rig_sim(cfg, args.host, args.port, watchdog=args.watchdog,
                        serial_device=args.serial, faults=faults,
                        fault_after=args.fault_after, realtime=not args.no_realtime,
                        cpu=_resolve_cpu(args.cpu), announce=announce, hand=hand or None,
                        duration=args.duration if limit is None else limit)
    if limit is not None and ended == "duration":
        return _bound_hit("rig-sim", limit)
    return 0
