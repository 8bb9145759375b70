"""The emulated rig (``frictionlab rig-sim``): the plant behind the raw protocol.

:class:`RigEmulator` answers protocol frames the way the rig's
microcontroller would, in front of :class:`frictionlab.model.simulation.SimulatedPlant`
running in real time:

* **Real time, lazily.**  The plant is integrated in quanta of
  ``h / substeps`` (the simulator's own arm substep) with the commanded u
  held; whenever a frame arrives the plant is first brought up to the last
  quantum boundary before the current time, in one compiled call of the
  simulator's integrator.  A SAMPLE therefore reads the plant as it was at
  most one quantum (0.5 ms) ago, and a COMMAND acts from the quantum in
  which it arrives.
* **Raw signals.**  Readings are App. B raw values: the angle and arm
  channels wrap around at +-1, the velocity channel clips, all three are
  quantised to 12 bits and carry ``sim.noise`` (SI units) of Gaussian noise,
  through the one sensor model :mod:`frictionlab.model.sensor` with the ``rig.*``
  factors as the rig's true ones; the noise of a reading is that of the
  request's sequence number (the loop's tick), so a reading at tick k is the
  simulator's at tick k for the same state and ``sim.seed``.
  The arm starts at the raw reading :data:`~frictionlab.model.sensor.ARM_START`
  (the controller captures it as x_0).
* **Sessions.**  ``HELLO`` starts a session: the "operator" balances the
  pendulum upright (``sim.initial_angle``, at rest; the arm stays where it
  is) and holds it there until the first COMMAND arrives.  With
  ``sim.initial_angle`` = pi (3.14159; ``rig-sim --hanging``) the pendulum
  hangs at rest instead, as the identification experiments and
  ``run --swing-up`` want it.
* **The operator's hand.**  CONTROL frames ``{"cmd": "hand", ...}``
  (:data:`HAND`) turn the pendulum or the arm one full lap by hand (App.
  B.1, B.2: the hand sets that angle and its velocity along a smooth lap of
  ``seconds``, then lets go at rest) or push them, at once or ``after``
  seconds; ``identify experiment ... --backend udp://...`` sends them when
  it asks the operator for a lap and the rig is this emulator.
  ``HELLO`` also forgets the last command's sequence number, so the new
  session's commands (numbered from 0 again) are applied.
* **Watchdog.**  When no COMMAND has arrived for ``watchdog`` seconds
  (50 ms), the motor is zeroed (SENSOR status bit ``STATUS_WATCHDOG``).  The
  timer starts with the session's first COMMAND (while the pendulum is held
  the motor is off anyway).
* **Fault injection (a test and teaching feature).**  CONTROL frames with a
  JSON object ``{"cmd": "fault", ...}`` make the next replies carry NaN or
  out-of-range values, fail their CRC, repeat or skew their sequence
  numbers, drop or silence replies, or push the pendulum; see
  :meth:`RigEmulator.control` and ``docs/protocol.md``.  ``{"cmd":
  "status"}`` reports the emulator's state (last command, faults applied).
  A real rig ignores CONTROL frames.

Transports: :func:`serve_udp` (``frictionlab rig-sim --port P``) and
:func:`serve_stream` (a serial device or one end of a pty pair).
"""

from __future__ import annotations

import dataclasses
import math
import os
import select
import socket
import sys
import threading
import time
from collections import deque

from ..config import Config
from ..model.rig import ADC_BITS, RigScaling
from ..model.sensor import dac, u_from_dac
from ..model.simulation import SimulatedPlant
from ..runs import simulated_plant
from . import protocol as P
from .clock import MonotonicClock
from .osrt import try_realtime_priority
from .protocol import Frame, FrameError
from .rigs import ARM_START, AdcModel, send_control, serial_settings

__all__ = ["FAULTS", "HAND", "DirectTransport", "RigEmulator", "hand_error", "send_control",
           "serve_stream", "serve_udp"]

#: Fault-injection keys of ``{"cmd": "fault", ...}`` (plus ``"after": seconds``).
FAULTS = {
    "nan": "the next N replies carry y = NaN",
    "out_of_range": "the next N replies carry v = 1.5 (outside [-1, 1])",
    "corrupt": "the next N replies fail their CRC (a payload byte is flipped)",
    "duplicate": "the next N replies are sent twice",
    "seq_offset": "the next reply's sequence number is off by this integer",
    "drop": "the next N replies are not sent",
    "silent": "ignore every frame for this many seconds (-1: until cleared)",
    "push": "add this many rad/s to the pendulum's velocity now",
    "ignore_commands": "the next N COMMANDs are not applied (as by a rig that kept an old "
                       "command sequence number across sessions)",
}
_COUNTED = ("nan", "out_of_range", "corrupt", "duplicate", "drop", "ignore_commands")

#: Keys of ``{"cmd": "hand", ...}``: the operator's hand (plus ``"after": seconds``).
HAND = {
    "lap": "'pendulum' or 'arm': turn it one full lap by hand (the pendulum from hanging "
           "to hanging, App. B.1; the arm exactly one lap, App. B.2), then let go at rest",
    "seconds": "how long the lap takes (default 2 s)",
    "direction": "+1 or -1: the lap's direction (default +1)",
    "push": "add this many rad/s to the pendulum's velocity",
    "push_arm": "add this many rad/s to the arm's velocity",
    "hang": "true: let the pendulum hang at rest (the arm stays where it is), as a session "
            "of rig-sim --hanging starts; the console's Swing up sends it",
}


def hand_error(msg: dict) -> str | None:
    """What is wrong with a ``{"cmd": "hand", ...}`` object (:data:`HAND`), or None."""
    keys = {k: v for k, v in msg.items() if k not in ("cmd", "after")}
    unknown = sorted(set(keys) - set(HAND))
    if unknown:
        return f"unknown hand key {unknown[0]!r}; known: {', '.join(HAND)}"
    if not keys:
        return f"hand: say what to do ({', '.join(HAND)})"
    if "hang" in keys and keys["hang"] is not True:
        return f"hand hang: true, got {keys['hang']!r}"
    if "lap" in keys and keys["lap"] not in ("pendulum", "arm"):
        return f"hand lap: 'pendulum' or 'arm', got {keys['lap']!r}"
    for k in ("seconds", "direction", "push", "push_arm"):
        if k in keys:
            v = keys[k]
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                return f"hand {k}: {v!r} is not a finite number"
    if "seconds" in keys and not 0.05 <= keys["seconds"] <= 60:
        return f"hand seconds: must be in [0.05, 60], got {keys['seconds']!r}"
    if "direction" in keys and keys["direction"] == 0:
        return "hand direction: +1 or -1"
    return None


class RigEmulator:
    """The rig's I/O in front of a simulated plant (see the module docstring).

    Parameters
    ----------
    cfg : Config
        Plant, friction, ``design.h``, ``sim.substeps`` (integration quantum
        ``h / substeps``; the pendulum steps every ``Config.pendulum_ratio``
        quanta, as in the simulator), ``sim.initial_angle``, ``sim.noise``,
        ``sim.seed``, ``rig.*`` (the rig's true conversion factors).
    clock : object with ``now_ns()``
        Time source (the monotonic clock, or a fake one in tests).
    watchdog : float
        Seconds without a COMMAND after which the motor is zeroed.
    arm_offset : float
        Raw arm reading at the start.
    """

    def __init__(self, cfg: Config, clock, *, watchdog: float = 0.05,
                 arm_offset: float = ARM_START, scaling: RigScaling | None = None):
        if not watchdog > 0:
            raise ValueError(f"watchdog must be > 0 s, got {watchdog}")
        self.cfg = cfg
        self.clock = clock
        self.scaling = scaling or cfg.rig
        self.h = cfg.design.h
        self.dt_ns = max(1, round(self.h / cfg.substeps * 1e9))
        self._ratio = cfg.pendulum_ratio
        self._chunk_max = max(1, 1_000_000_000 // self.dt_ns)   # <= 1 s per call
        self._plants: dict[int, SimulatedPlant] = {}
        # the rig's converters: 12 bits, or a motor rig's encoders (Config.sensor_step)
        self.adc = AdcModel(self.scaling, arm_offset, True, cfg.sim.noise, cfg.sim.seed,
                            cfg.sensor_step)
        self.watchdog_ns = int(watchdog * 1e9)
        self.max_catchup_ns = 2_000_000_000
        self._lock = threading.Lock()
        self._faults: dict[str, float] = {}
        self._armed: list[tuple[int, dict]] = []
        self._silent_until: int | None = None
        self.applied: deque[dict] = deque(maxlen=32)
        self.counts = {"samples": 0, "commands": 0, "bad_frames": 0, "watchdog_trips": 0,
                       "sessions": 0}
        self.last_command_seq: int | None = None
        self._t0 = clock.now_ns()
        self.state = self._plant(1).init()
        for n in range(1, 2 * cfg.substeps + 1):  # compile and cache the usual chunks
            self._plant(n).step(self.state, 0.0)
        u_from_dac.py_func(0.0, 1.0)  # and the DAC law (it calls the compiled dac)
        self.t_state = self._t0
        self.u_da = 0.0
        self._u = 0.0
        self._t_cmd = self._t0
        self.held = True
        self.tripped = False
        self.saturated = False
        self._hand: dict | None = None

    # --- plant in real time --------------------------------------------------

    def _plant(self, n: int) -> SimulatedPlant:
        """The plant stepping ``n`` quanta in one compiled call (cached per n)."""
        p = self._plants.get(n)
        if p is None:
            cfg = self.cfg.with_values({"design.h": n * self.dt_ns / 1e9, "sim.substeps": n,
                                        "sim.pendulum_steps": -(-n // self._ratio)})
            p = self._plants[n] = simulated_plant(cfg)
        return p

    def _advance(self, t: int) -> None:
        """Bring the plant to the last quantum boundary <= t with u held."""
        if self.held:
            self.t_state = t
            return
        dt = self.dt_ns
        n = (t - self.t_state) // dt
        if n <= 0:
            return
        if n * dt > self.max_catchup_ns:  # nobody talked to us for a long time: skip
            skip = n - self.max_catchup_ns // dt
            self.t_state += skip * dt
            n -= skip
        st = self.state
        t_wd = self._t_cmd + self.watchdog_ns
        if self._hand is not None:
            st, n = self._advance_hand(st, n, t_wd)
        while n > 0:
            if self.t_state < t_wd:
                m = min(n, self._chunk_max, -(-(t_wd - self.t_state) // dt))
                u = self._u
            else:
                m = min(n, self._chunk_max)
                u = 0.0
                if not self.tripped:
                    self.tripped = True
                    self.counts["watchdog_trips"] += 1
            st = self._plant(m).step(st, u)
            self.t_state += m * dt
            n -= m
        self.state = st

    def _advance_hand(self, st, n: int, t_wd: int):
        """Step quantum by quantum while the operator's hand turns the pendulum or the
        arm through its lap (the hand sets that angle and its velocity; everything
        else moves as the plant does)."""
        hand = self._hand
        dt = self.dt_ns
        one = self._plant(1)
        i = 0 if hand["lap"] == "pendulum" else 2
        while n > 0 and hand is not None:
            st = one.step(st, self._u if self.t_state < t_wd else 0.0)
            self.t_state += dt
            n -= 1
            frac = (self.t_state - hand["t0"]) / hand["T"]
            x = st.x.copy()
            if frac >= 1.0:
                x[i] = hand["a0"] + hand["dir"] * 2.0 * math.pi
                x[i + 1] = 0.0
                self._hand = hand = None
            else:
                x[i] = hand["a0"] + hand["dir"] * math.pi * (1.0 - math.cos(math.pi * frac))
                x[i + 1] = (hand["dir"] * math.pi * math.pi * math.sin(math.pi * frac)
                            / (hand["T"] / 1e9))
            st = dataclasses.replace(st, x=x)
        return st, n

    def _apply_hand(self, msg: dict, t: int) -> None:
        self._advance(t)
        if msg.get("hang"):
            x = self.state.x.copy()
            x[0], x[1], x[3] = math.pi, 0.0, 0.0
            self.state = dataclasses.replace(self.state, x=x, memory=0.0)
            self._hand = None
            self._applied("hand_hang", -1, math.pi)
        if "push" in msg:
            self.state = self._plant(1).push(self.state, float(msg["push"]))
            self._applied("hand_push", -1, float(msg["push"]))
        if "push_arm" in msg:
            x = self.state.x.copy()
            x[3] += float(msg["push_arm"])
            self.state = dataclasses.replace(self.state, x=x)
            self._applied("hand_push_arm", -1, float(msg["push_arm"]))
        if "lap" in msg:
            i = 0 if msg["lap"] == "pendulum" else 2
            self._hand = {"lap": msg["lap"], "t0": self.t_state,
                          "T": int(float(msg.get("seconds", 2.0)) * 1e9),
                          "dir": 1.0 if msg.get("direction", 1) > 0 else -1.0,
                          "a0": float(self.state.x[i])}
            self._applied(f"hand_lap_{msg['lap']}", -1, float(msg.get("seconds", 2.0)))

    # --- frames --------------------------------------------------------------

    def handle(self, data: bytes) -> list[bytes]:
        """Handle one datagram; return the reply frames."""
        try:
            frame = P.decode(data)
        except FrameError:
            self.counts["bad_frames"] += 1
            return []
        return self.handle_frame(frame)

    def handle_frame(self, frame: Frame | FrameError) -> list[bytes]:
        """Handle one decoded frame; return the reply frames."""
        if isinstance(frame, FrameError):
            self.counts["bad_frames"] += 1
            return []
        with self._lock:
            t = self.clock.now_ns()
            self._arm_due(t)
            if frame.type == P.MSG_CONTROL:
                try:
                    reply = self.control(P.parse_control(frame), _locked=True)
                except FrameError as exc:
                    reply = {"ok": False, "error": str(exc)}
                return [P.control_frame(frame.seq, reply, ack=True)]
            if self._silent_until is not None:
                if self._silent_until < 0 or t < self._silent_until:
                    return []
                self._silent_until = None
            if frame.type == P.MSG_SAMPLE:
                return self._sample(frame.seq, t)
            if frame.type == P.MSG_COMMAND:
                self._command(frame, t)
                return []
            if frame.type == P.MSG_HELLO:
                self._hello(t)
                status = P.STATUS_EMULATED | P.STATUS_HELD
                return [P.encode(P.MSG_HELLO_ACK, frame.seq, P.hello_ack_payload(
                    ADC_BITS, status, self.watchdog_ns // 1_000_000, round(self.h * 1e4)))]
            self.counts["bad_frames"] += 1
            return []

    def _hello(self, t: int) -> None:
        self._advance(t)
        st = self.state
        x = st.x.copy()
        x[0] = self.cfg.sim.initial_angle
        x[1] = 0.0
        x[3] = 0.0
        x[4] = 0.0
        self.state = dataclasses.replace(st, x=x, memory=0.0)
        self.t_state = t
        self.held = True
        self.tripped = False
        self._hand = None
        self.u_da = 0.0
        self._u = 0.0
        self._t_cmd = t
        self.last_command_seq = None
        self.counts["sessions"] += 1

    def _command(self, frame: Frame, t: int) -> None:
        try:
            u_da = P.parse_command(frame)
        except FrameError:
            self.counts["bad_frames"] += 1
            return
        last = self.last_command_seq
        if last is not None and 0x80000000 <= ((frame.seq - last) & 0xFFFFFFFF):
            return  # older than the last command: a stale datagram
        if self._faults and self._take("ignore_commands", frame.seq):
            return
        self.counts["commands"] += 1
        self.saturated = not (-1.0 <= u_da <= 1.0)
        u_da = dac.py_func(u_da, 1.0)
        if self.held:
            self.held = False
            self.t_state = t
        else:
            self._advance(t)
        self.u_da = u_da
        self._u = u_from_dac.py_func(u_da, self.scaling.u_scale)
        self._t_cmd = t
        self.tripped = False
        # last: a thread that sees this command's number (without the lock) sees it applied
        self.last_command_seq = frame.seq

    def _sample(self, seq: int, t: int) -> list[bytes]:
        self._advance(t)
        self.counts["samples"] += 1
        x = self.state.x
        y, xr, v = self.adc.read(x[0], x[2], x[3], seq)
        status = P.STATUS_EMULATED
        if self.held:
            status |= P.STATUS_HELD
        if self.tripped:
            status |= P.STATUS_WATCHDOG
        if self.saturated:
            status |= P.STATUS_SATURATED
        u_da = 0.0 if self.tripped else self.u_da
        f = self._faults
        copies = 1
        corrupt = False
        if f:
            if self._take("drop", seq):
                return []
            if self._take("nan", seq):
                y = math.nan
            if self._take("out_of_range", seq):
                v = 1.5
            if "seq_offset" in f:
                off = int(f.pop("seq_offset"))
                self._applied("seq_offset", seq, off)
                seq = (seq + off) & 0xFFFFFFFF
            if self._take("duplicate", seq):
                copies = 2
            corrupt = self._take("corrupt", seq)
        frame = P.encode(P.MSG_SENSOR, seq, P.sensor_payload(y, xr, v, u_da, status))
        if corrupt:
            b = bytearray(frame)
            b[P.HEADER] ^= 0x40
            frame = bytes(b)
        return [frame] * copies

    def _take(self, name: str, seq: int) -> bool:
        n = self._faults.get(name)
        if not n:
            return False
        if n <= 1:
            del self._faults[name]
        else:
            self._faults[name] = n - 1
        self._applied(name, seq)
        return True

    def _applied(self, name: str, seq: int, value=None) -> None:
        rec = {"fault": name, "seq": seq, "t": (self.clock.now_ns() - self._t0) / 1e9}
        if value is not None:
            rec["value"] = value
        self.applied.append(rec)

    def prewarm(self) -> None:
        """Catch the plant up to now and run the reply's code on scratch data.

        Called by the servers shortly before the next SAMPLE is due, so that
        the reply is computed from warm caches and a short integration.
        """
        with self._lock:
            self._advance(self.clock.now_ns())
            x = self.state.x
            if not self.adc.noise:
                y, xr, v = self.adc.read(x[0], x[2], x[3], count=False)
                P.encode(P.MSG_SENSOR, 0, P.sensor_payload(y, xr, v, self.u_da, 0))

    # --- fault injection and status -------------------------------------------

    def _arm_due(self, t: int) -> None:
        if self._armed and self._armed[0][0] <= t:
            due = [f for when, f in self._armed if when <= t]
            self._armed = [(w, f) for w, f in self._armed if w > t]
            for faults in due:
                self._apply_faults(faults, t)

    def _apply_faults(self, faults: dict, t: int) -> None:
        for key, value in faults.items():
            if key == "hand":
                self._apply_hand(value, t)
            elif key == "push":
                self._advance(t)
                self.state = self._plant(1).push(self.state, float(value))
                self._applied("push", -1, float(value))
            elif key == "silent":
                s = float(value)
                self._silent_until = -1 if s < 0 else t + int(s * 1e9)
                self._applied("silent", -1, s)
            elif key == "seq_offset":
                self._faults["seq_offset"] = int(value)
            else:
                self._faults[key] = self._faults.get(key, 0) + int(value)

    def control(self, msg: dict, _locked: bool = False) -> dict:
        """Handle a CONTROL object: ``fault``, ``hand`` (:data:`HAND`: the operator's
        hand turning the pendulum or the arm a lap, or pushing them), ``clear`` or
        ``status``."""
        if not _locked:
            with self._lock:
                return self.control(msg, _locked=True)
        cmd = msg.get("cmd")
        t = self.clock.now_ns()
        if cmd == "status":
            return self.status(t)
        if cmd == "clear":
            self._faults.clear()
            self._armed.clear()
            self._silent_until = None
            return {"ok": True}
        if cmd == "hand":
            error = hand_error(msg)
            if error:
                return {"ok": False, "error": error}
            after = msg.get("after", 0)
            if isinstance(after, bool) or not isinstance(after, int | float) or after < 0:
                return {"ok": False, "error": f"after must be a number >= 0, got {after!r}"}
            hand = {k: v for k, v in msg.items() if k not in ("cmd", "after")}
            if after:
                self._armed.append((t + int(after * 1e9), {"hand": hand}))
                self._armed.sort(key=lambda a: a[0])
            else:
                self._apply_hand(hand, t)
            return {"ok": True}
        if cmd == "fault":
            faults = {k: v for k, v in msg.items() if k not in ("cmd", "after")}
            unknown = sorted(set(faults) - set(FAULTS))
            if unknown:
                return {"ok": False, "error": f"unknown fault {unknown[0]!r}; "
                        f"known: {', '.join(FAULTS)}"}
            for k, v in faults.items():
                if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                    return {"ok": False, "error": f"fault {k}: {v!r} is not a finite number"}
                if k in _COUNTED and not (v >= 1 and float(v).is_integer()):
                    return {"ok": False, "error": f"fault {k}: count must be an integer >= 1"}
            after = msg.get("after", 0)
            if isinstance(after, bool) or not isinstance(after, int | float) or after < 0:
                return {"ok": False, "error": f"after must be a number >= 0, got {after!r}"}
            if after:
                self._armed.append((t + int(after * 1e9), faults))
                self._armed.sort(key=lambda a: a[0])
            else:
                self._apply_faults(faults, t)
            return {"ok": True}
        return {"ok": False, "error": f"unknown cmd {cmd!r}; known: fault, hand, clear, status"}

    def status(self, t: int | None = None) -> dict:
        t = self.clock.now_ns() if t is None else t
        self._advance(t)
        st = self.state
        return {
            "ok": True,
            "t": (t - self._t0) / 1e9,
            "held": self.held,
            "theta": float(st.x[0]),
            "arm": float(st.x[2]),
            "u_da": 0.0 if self.tripped else self.u_da,
            "watchdog_tripped": self.tripped,
            "hand": None if self._hand is None else self._hand["lap"],
            "last_command_seq": self.last_command_seq,
            "applied": list(self.applied)[-12:],
            **self.counts,
        }


# --- transports ---------------------------------------------------------------


def serve_udp(emulator: RigEmulator, host: str = "127.0.0.1", port: int = 0,
              stop: threading.Event | None = None, ready=None, prewarm_us: float = 300.0) -> None:
    """Answer UDP datagrams until ``stop`` is set.

    ``ready((host, port))`` is called once the socket is bound (port 0
    picks a free port).  ``prewarm_us`` before the next SAMPLE is expected
    (one period after the last), :meth:`RigEmulator.prewarm` runs and the
    server then polls the socket without sleeping until the request comes
    (at most a quarter period longer), so the reply leaves quickly; 0
    disables this.
    """
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((host, port))
    sock.setblocking(False)
    poll = select.poll()
    poll.register(sock, select.POLLIN)
    if ready is not None:
        ready(sock.getsockname()[:2])
    h_ns = round(emulator.h * 1e9)
    warm_ns = int(prewarm_us * 1000)
    now = time.monotonic_ns
    next_warm = None
    try:
        while stop is None or not stop.is_set():
            timeout = 200.0
            if next_warm is not None:
                timeout = max(0.0, (next_warm - now()) / 1e6)
            if not poll.poll(timeout):
                if next_warm is not None and now() >= next_warm:
                    # the next SAMPLE is due in warm_ns: warm up, then poll without
                    # sleeping until it arrives (a sleeping CPU wakes up slowly)
                    emulator.prewarm()
                    end = next_warm + warm_ns + h_ns // 4
                    next_warm = None
                    while now() < end and not poll.poll(0):
                        pass
                continue
            try:
                data, addr = sock.recvfrom(4096)
            except (BlockingIOError, ConnectionResetError):
                continue
            t = now()
            for reply in emulator.handle(data):
                try:
                    sock.sendto(reply, addr)
                except OSError:
                    pass
            if warm_ns and len(data) > 3 and data[3] == P.MSG_SAMPLE:
                next_warm = t + h_ns - warm_ns
    finally:
        sock.close()


class DirectTransport:
    """A transport handing frames straight to an in-process :class:`RigEmulator`.

    No sockets and no threads: :meth:`send` runs the emulator on the frame
    and queues its replies, :meth:`recv` returns them.  With a
    :class:`~.clock.FakeClock` shared by the loop and the emulator, a
    :class:`~.rigs.FramedRig` over this transport runs the whole protocol
    (sequence numbers, CRC, faults, watchdog) deterministically and without
    sleeping: a :meth:`recv` that finds no reply lets the fake time run to
    its deadline, as waiting would.

    Parameters
    ----------
    emulator : RigEmulator
    clock : FakeClock, optional
        Advanced to the deadline when no reply is queued.
    """

    def __init__(self, emulator: RigEmulator, clock=None):
        self.emulator = emulator
        self.clock = clock
        self._replies: deque[bytes] = deque()
        self.sent: list[Frame] = []

    def send(self, data: bytes) -> None:
        self.sent.append(P.decode(data))
        self._replies.extend(self.emulator.handle(data))

    def recv(self, deadline_ns: int) -> Frame | FrameError | None:
        if not self._replies:
            clock = self.clock
            if clock is not None and clock.now_ns() < deadline_ns:
                clock.advance(deadline_ns - clock.now_ns())
            return None
        try:
            return P.decode(self._replies.popleft())
        except FrameError as exc:
            return exc

    def drain(self) -> None:
        self._replies.clear()

    def close(self) -> None:
        self._replies.clear()


def serve_stream(emulator: RigEmulator, fd: int, stop: threading.Event | None = None) -> None:
    """Answer frames on a byte stream (file descriptor ``fd``) until ``stop`` is set."""
    decoder = P.FrameDecoder()
    while stop is None or not stop.is_set():
        r, _, _ = select.select((fd,), (), (), 0.1)
        if not r:
            continue
        try:
            data = os.read(fd, 4096)
        except OSError:
            return
        if not data:
            return
        out = []
        for frame in decoder.feed(data):
            out.extend(emulator.handle_frame(frame))
        if out:
            os.write(fd, b"".join(out))


def run_rig_sim(cfg: Config, host: str, port: int, *, watchdog: float = 0.05,
                serial_device: str | None = None, faults: dict | None = None,
                fault_after: float = 0.0, realtime: bool = True, cpu: int | None = None,
                announce=None, hand: dict | None = None,
                duration: float | None = None) -> str:
    """The ``frictionlab rig-sim`` process: serve until SIGINT/SIGTERM, or for
    ``duration`` seconds when given.

    Returns ``"signal"`` or ``"duration"``: what ended it.  On the way out the
    calling thread gets back its signal handlers, scheduling policy and CPUs
    (called in-process, by a test, the caller's thread is not left at SCHED_FIFO
    priority, pinned, with SIGINT caught).
    """
    import signal

    stop = threading.Event()
    ended = ["signal"]

    def _stop(signum, frame):
        stop.set()

    def _time_up():
        ended[0] = "duration"
        stop.set()

    tid = threading.get_native_id()
    try:
        cpus = os.sched_getaffinity(tid)
        policy = (os.sched_getscheduler(tid), os.sched_getparam(tid))
    except (AttributeError, OSError):
        cpus = policy = None
    previous = {sig: signal.signal(sig, _stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    timer = None
    try:
        emulator = RigEmulator(cfg, MonotonicClock(), watchdog=watchdog)
        if faults:
            msg = {"cmd": "fault", **faults}
            if fault_after:
                msg["after"] = fault_after
            reply = emulator.control(msg)
            if not reply.get("ok"):
                raise ValueError(reply.get("error"))
        if hand:
            reply = emulator.control(hand)  # {"cmd": "hand", ...} (``after`` from start-up)
            if not reply.get("ok"):
                raise ValueError(reply.get("error"))
        # serve in the main thread: a single-threaded process never waits for the GIL
        # (another thread holding it on a busy or paused CPU would silence the rig)
        if realtime:
            note = try_realtime_priority(40, cpu)
            if note:
                print(f"frictionlab rig-sim: {note}", file=sys.stderr)
        if duration is not None:
            timer = threading.Timer(duration, _time_up)
            timer.daemon = True
            timer.start()
        if serial_device:
            import serial

            port_ = serial.serial_for_url(serial_device, timeout=0, **serial_settings())
            if announce:
                announce({"listening": f"serial://{serial_device}"})
            serve_stream(emulator, port_.fileno(), stop)
        else:
            serve_udp(emulator, host, port, stop,
                      ready=lambda a: announce and announce(
                          {"listening": f"udp://{a[0]}:{a[1]}", "host": a[0], "port": a[1]}))
    finally:
        if timer is not None:
            timer.cancel()
        if realtime and cpus is not None:
            try:
                os.sched_setscheduler(tid, *policy)
                os.sched_setaffinity(tid, cpus)
            except (OSError, ValueError):
                pass
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return ended[0]
