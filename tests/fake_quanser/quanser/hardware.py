r"""An emulated ``quanser.hardware``: a QUBE-Servo 2 / 3 on a HIL board, for tests.

The API is that of Quanser's HIL SDK for Python (``quanser.hardware.HIL``,
``HILError``, ``DigitalState``): the immediate I/O calls, encoder counts, the
watchdog, with the SDK's argument conventions (channel arrays of unsigned
32-bit integers, ``num_channels``, a buffer of the channel type: int32 counts,
float64 volts and other values, int8 digital states).  A wrong type or length
raises ``TypeError``/``ValueError`` here, where the real library would read
garbage.

The board
---------
Board types ``qube_servo2_usb`` and ``qube_servo3_usb`` (the same plant here),
identifiers from ``FAKE_QUANSER_BOARDS`` (comma separated, default ``"0"``).
Channels: analog output 0 the motor voltage (clipped to +-15 V, the amplifier's
range; the tests check the controller never asks more than 10 V); digital output 0
enables the amplifier; encoder inputs 0 (arm) and 1 (pendulum), 2048 counts per
revolution, counting from 0 at ``open`` (the pendulum hanging at rest);
other input 14000 the tachometer (arm speed, counts/s); digital inputs 0, 1, 2
amplifier fault, stall detected, stall error; other outputs 11000-11002 the
LED (red, green, blue in [0, 1]).

The board keeps its own time (``CLOCK``, default ``time.monotonic_ns``): the
plant and the watchdog are advanced to "now" at every call, so a process that
was stopped (SIGSTOP) finds on its next call a watchdog that expired while it
was stopped, at the moment it expired, and a plant that moved on with the
expiration states applied from that moment.  Tests in one process replace
``CLOCK`` by their fake clock's ``now_ns``.

The watchdog: ``watchdog_start(timeout)`` after the expiration states were
set; when a reload does not come within ``timeout``, the board sets analog
output 0 and digital output 0 to their expiration states and refuses every
write until ``watchdog_clear`` (reads still work), as the SDK documents.

The plant (written afresh for the tests, independent of frictionlab's model)
---------------------------------------------------------------------------
Two uniform rods: the arm (mass ``M_R``, length ``L_R``) turning about the
motor axis, the pendulum (``M_P``, ``L_P``) about the arm's tip.  Quanser's
coordinates: arm angle :math:`\theta` (encoder 0's direction), pendulum angle
:math:`\alpha` from upright, positive so that an arm accelerating positively
accelerates the upright pendulum positively.  With
:math:`J_r = M_R L_R^2/3`, :math:`J_p = M_P L_P^2/3` (about the pivots),
:math:`a = M_P L_R L_P/2`:

.. math::

    (J_r + M_P L_R^2 + J_p\sin^2\alpha)\ddot\theta - a\cos\alpha\,\ddot\alpha
      + 2 J_p \sin\alpha\cos\alpha\,\dot\theta\dot\alpha + a\sin\alpha\,\dot\alpha^2
      = \tau - D_r\dot\theta

    -a\cos\alpha\,\ddot\theta + J_p\ddot\alpha - J_p\sin\alpha\cos\alpha\,\dot\theta^2
      - \tfrac12 M_P g L_P \sin\alpha = -D_p\dot\alpha

with the motor torque :math:`\tau = k_t (V - k_m\dot\theta)/R_m` while the
amplifier is enabled (and 0 while it is off: an open circuit).  Encoder 1 reads
:math:`\alpha - \pi` (zero hanging), so hanging, a positive voltage step makes
it count down at first.  Integrated by RK4 in steps of at most 1 ms.

Faults (``FAKE_QUANSER_FAULTS``, a JSON object; or :meth:`Board.inject`):
``amplifier_fault_at`` (s of board time after ``open``: digital input 0 goes
high and the amplifier turns off), ``stall_at`` (digital input 1),
``stall_error_at`` (input 2, amplifier off); ``lift_at`` (the operator's hand puts
the pendulum :data:`LIFT_ANGLE` from upright and holds it there, the arm free, until
the motor is driven: a start by hand).  A real stall is detected too: the
motor at more than ``STALL_VOLTS`` with the arm slower than ``STALL_SPEED`` for
``STALL_TIME`` (input 1), and for ``STALL_ERROR_TIME`` more (input 2, amplifier off).
``FAKE_QUANSER_STATE`` (JSON: ``arm``, ``arm_rate``, ``pendulum``,
``pendulum_rate`` in rad and rad/s, the pendulum from hanging) sets the start;
``"pendulum_module": false`` takes the pendulum off (it is held by magnets on a
real QUBE): the arm turns alone; ``"arm_blocked": true`` holds the arm still (an
obstacle: a stall under voltage).

Every call is recorded (:attr:`Board.calls`: ``(t_s, name, args)``, board time
in seconds) and, with ``FAKE_QUANSER_LOG=PATH``, appended to PATH as JSON
lines (flushed every 0.1 s of board time, at ``close`` and at exit), with the
board's own events (``watchdog_expired``, ``amplifier_fault``...) as calls
named ``event``.
"""

from __future__ import annotations

import array
import atexit
import json
import math
import os
import time

__all__ = ["BOARDS", "CLOCK", "HIL", "MAX_STRING_LENGTH", "Board", "DigitalState", "HILError"]

# --- Quanser's published QUBE-Servo 2 parameters ----------------------------------
R_M = 8.4          # armature resistance, ohm
K_T = 0.042        # torque constant, N m/A
K_M = 0.042        # back-EMF constant, V s/rad
M_R = 0.095        # arm mass, kg
L_R = 0.085        # arm length, m
M_P = 0.024        # pendulum mass, kg
L_P = 0.129        # pendulum length, m
D_R = 0.00027      # arm viscous damping, N m s/rad
D_P = 0.00005      # pendulum viscous damping, N m s/rad
G = 9.81
COUNTS = 2048      # encoder counts per revolution
V_RANGE = 15.0     # the amplifier's output range, V
DT_MAX = 0.001     # largest integration step, s
#: Stall detection: more than 5 V with the arm (nearly) still for STALL_TIME gives "stall
#: detected"; that for STALL_ERROR_TIME more, "stall error" (Quanser: about 3 s), the
#: amplifier then off.
STALL_VOLTS, STALL_SPEED, STALL_TIME, STALL_ERROR_TIME = 5.0, 0.5, 0.5, 3.0
#: Where the operator's hand puts the pendulum (``lift``), rad from upright.
LIFT_ANGLE = 0.05

TACH = 14000
LED = (11000, 11001, 11002)
BOARD_TYPES = ("qube_servo2_usb", "qube_servo3_usb")

#: The board's time source (integer ns).  Tests in one process set their fake clock's.
CLOCK = time.monotonic_ns
#: Every board opened in this process, in order.
BOARDS: list = []

QERR_NO_BOARD = -43          # codes of this emulation (the messages say what they mean)
QERR_NOT_OPEN = -44
QERR_WATCHDOG_EXPIRED = -1073
QERR_BAD_CHANNEL = -45
QERR_NO_EXPIRATION_STATE = -46


#: The SDK's "use the whole string" length for string arguments.
MAX_STRING_LENGTH = 2147483647


class HILError(Exception):
    """A hardware error (the SDK's ``HILError``): ``error_code`` and
    ``get_error_message()``."""

    def __init__(self, error_code: int, message: str = ""):
        super().__init__(message or f"HIL error {error_code}")
        self.error_code = error_code
        self._message = message or f"HIL error {error_code}"

    def get_error_message(self) -> str:
        return self._message


class DigitalState:
    LOW = 0
    HIGH = 1
    TRISTATE = 2
    NO_CHANGE = 3


class Clock:
    SYSTEM_CLOCK_1 = -1
    HARDWARE_CLOCK_0 = 0


_J_R = M_R * L_R**2 / 3.0
_J_P = M_P * L_P**2 / 3.0
_A = M_P * L_R * L_P / 2.0
_J0 = _J_R + M_P * L_R**2
_GP = 0.5 * M_P * G * L_P


def accelerations(alpha, theta_dot, alpha_dot, torque):
    """(theta'', alpha'') of the equations in the module docstring."""
    s, c = math.sin(alpha), math.cos(alpha)
    m11 = _J0 + _J_P * s * s
    m12 = -_A * c
    m22 = _J_P
    f1 = torque - D_R * theta_dot - 2.0 * _J_P * s * c * theta_dot * alpha_dot \
        - _A * s * alpha_dot * alpha_dot
    f2 = -D_P * alpha_dot + _J_P * s * c * theta_dot * theta_dot + _GP * s
    det = m11 * m22 - m12 * m12
    return (m22 * f1 - m12 * f2) / det, (m11 * f2 - m12 * f1) / det


def energy(x):
    """Total mechanical energy of the state (theta, alpha, theta', alpha') (J; zero
    hanging at rest), for the tests of the emulation itself."""
    _, al, thd, ald = x
    s, c = math.sin(al), math.cos(al)
    kin = 0.5 * (_J0 + _J_P * s * s) * thd * thd - _A * c * thd * ald + 0.5 * _J_P * ald * ald
    return kin + _GP * (c + 1.0)


def rk4(x, v_motor, dt, pendulum=True, blocked=False):
    """One RK4 step of (theta, alpha, theta', alpha') with motor voltage ``v_motor``
    (None: the amplifier is off, no current); ``pendulum`` False: the pendulum
    module taken off (the arm alone, alpha frozen); ``blocked``: the arm held still
    (an obstacle; the pendulum swings about the still arm)."""

    def f(s):
        _, al, thd, ald = s
        tau = 0.0 if v_motor is None else K_T * (v_motor - K_M * thd) / R_M
        if blocked:
            return (0.0, ald, 0.0, (_GP * math.sin(al) - D_P * ald) / _J_P)
        if not pendulum:
            return (thd, 0.0, (tau - D_R * thd) / _J_R, 0.0)
        a1, a2 = accelerations(al, thd, ald, tau)
        return (thd, ald, a1, a2)

    k1 = f(x)
    k2 = f(tuple(xi + 0.5 * dt * ki for xi, ki in zip(x, k1, strict=True)))
    k3 = f(tuple(xi + 0.5 * dt * ki for xi, ki in zip(x, k2, strict=True)))
    k4 = f(tuple(xi + dt * ki for xi, ki in zip(x, k3, strict=True)))
    return tuple(xi + dt / 6.0 * (a + 2 * b + 2 * c + d)
                 for xi, a, b, c, d in zip(x, k1, k2, k3, k4, strict=True))


def _values(buf, n, kind):
    """Check an SDK buffer (numpy array or array.array) of ``n`` items of ``kind``."""
    sizes = {"u32": (4, "ui"), "i32": (4, "i"), "f64": (8, "f"), "i8": (1, "ib")}
    size, kinds = sizes[kind]
    if isinstance(buf, array.array):
        code = buf.typecode
        ok = buf.itemsize == size and ((kind == "f64" and code == "d")
                                       or (kind != "f64" and code not in "fd"))
    else:
        dtype = getattr(buf, "dtype", None)
        if dtype is None:
            raise TypeError(f"expected a numpy array or array.array of {kind}, got "
                            f"{type(buf).__name__}")
        ok = dtype.itemsize == size and dtype.kind in kinds
    if not ok:
        raise TypeError(f"buffer of the wrong type for {kind}: {buf!r}")
    if not hasattr(n, "__index__") or len(buf) < n:
        raise ValueError(f"num_channels {n} but the buffer holds {len(buf)}")
    return buf


class Board:
    """The emulated QUBE: plant, amplifier, watchdog, faults and the call record."""

    def __init__(self, card_type: str, identifier: str):
        self.card_type = card_type
        self.identifier = identifier
        self.t0 = CLOCK()
        self.t = self.t0  # the board's time up to which the plant has been advanced (ns)
        st = json.loads(os.environ.get("FAKE_QUANSER_STATE") or "{}")
        self.x = (float(st.get("arm", 0.0)), math.pi + float(st.get("pendulum", 0.0)),
                  float(st.get("arm_rate", 0.0)), float(st.get("pendulum_rate", 0.0)))
        self.pendulum = bool(st.get("pendulum_module", True))
        self.blocked = bool(st.get("arm_blocked", False))
        self.holding = False  # the hand holds the pendulum (lift) until the motor drives
        self.counts0 = [self._counts()[0], self._counts()[1]]
        self.voltage = 0.0        # analog output 0 as last written (V)
        self.enabled = False      # digital output 0
        self.led = [0.0, 0.0, 0.0]
        self.options: dict = {}
        self.faults = {k: float(v) for k, v in
                       json.loads(os.environ.get("FAKE_QUANSER_FAULTS") or "{}").items()}
        self.amp_fault = self.stall = self.stall_error = False
        self.stall_since: float | None = None
        self.exp_analog: float | None = None
        self.exp_digital: int | None = None
        self.wd_timeout: float | None = None  # s, while the watchdog runs
        self.wd_last = 0
        self.expired = False
        self.closed = False
        self.calls: list = []
        self._log = None
        self._flushed = self.t0
        path = os.environ.get("FAKE_QUANSER_LOG")
        if path:
            self._log = open(path, "a")
            atexit.register(self._flush)
        BOARDS.append(self)
        self._record("open", card_type, identifier)

    # --- time --------------------------------------------------------------------
    def seconds(self, t_ns: int | None = None) -> float:
        return ((self.t if t_ns is None else t_ns) - self.t0) / 1e9

    def _motor(self):
        if not self.enabled or self.amp_fault or self.stall_error:
            return None
        return max(-V_RANGE, min(V_RANGE, self.voltage))

    def _integrate(self, t_end: int) -> None:
        while self.t < t_end:
            dt = min(DT_MAX, (t_end - self.t) / 1e9)
            if self.holding and self._motor():
                self.holding = False  # the controller drives the motor: the hand lets go
            self.x = rk4(self.x, self._motor(), dt, self.pendulum, self.blocked)
            if self.holding:
                self.x = (self.x[0], LIFT_ANGLE, self.x[2], 0.0)
            self.t = min(t_end, self.t + max(1, round(dt * 1e9)))
            self._stall_check()

    def _stall_check(self) -> None:
        v = self._motor()
        if v is not None and abs(v) > STALL_VOLTS and abs(self.x[2]) < STALL_SPEED:
            if self.stall_since is None:
                self.stall_since = self.seconds()
            held = self.seconds() - self.stall_since
            if held >= STALL_TIME and not self.stall:
                self.stall = True
                self._event("stall_detected")
            if held >= STALL_TIME + STALL_ERROR_TIME and not self.stall_error:
                self.stall_error = True
                self._event("stall_error")
        else:
            self.stall_since = None

    def advance(self) -> None:
        """Bring the board up to now: plant, scheduled faults, watchdog expiry."""
        now = CLOCK()
        events = []
        for name, at in self.faults.items():
            events.append((self.t0 + round(at * 1e9), name))
        if self.wd_timeout is not None and not self.expired:
            events.append((self.wd_last + round(self.wd_timeout * 1e9), "watchdog"))
        for when, name in sorted(events):
            if when > now:
                break
            self._integrate(max(when, self.t))
            if name == "watchdog":
                self.expired = True
                if self.exp_analog is not None:
                    self.voltage = self.exp_analog
                if self.exp_digital is not None and self.exp_digital != DigitalState.NO_CHANGE:
                    self.enabled = self.exp_digital == DigitalState.HIGH
                self._event("watchdog_expired", voltage=self.voltage, enabled=self.enabled)
            else:
                self.faults.pop(name)
                self.inject(name.removesuffix("_at"))
        self._integrate(now)

    def inject(self, fault: str) -> None:
        """Make a fault happen now: ``amplifier_fault``, ``stall``, ``stall_error``; or
        ``lift``: the operator's hand puts the pendulum 0.05 rad from upright, at rest,
        and holds it there until the motor is driven (the thesis's start by hand)."""
        if fault == "lift":
            self.x = (self.x[0], LIFT_ANGLE, 0.0, 0.0)
            self.holding = True
        elif fault == "amplifier_fault":
            self.amp_fault = True
        elif fault == "stall":
            self.stall = True
        elif fault == "stall_error":
            self.stall = self.stall_error = True
        else:
            raise ValueError(f"unknown fault {fault!r}")
        self._event(fault)

    # --- the record --------------------------------------------------------------
    def _record(self, name: str, *args, t_ns: int | None = None) -> None:
        t_ns = CLOCK() if t_ns is None else t_ns
        entry = (self.seconds(t_ns), name, args)
        self.calls.append(entry)
        if self._log is not None:
            self._log.write(json.dumps({"t": entry[0], "mono": t_ns / 1e9, "call": name,
                                        "args": list(args)}) + "\n")
            if self.t - self._flushed > 100_000_000:
                self._flush()

    def _event(self, name: str, **info) -> None:
        """A board event, at the board time it happened (the plant's time)."""
        self._record("event", name, info, t_ns=self.t)

    def _flush(self) -> None:
        if self._log is not None and not self._log.closed:
            self._flushed = self.t
            self._log.flush()

    # --- readings ------------------------------------------------------------------
    def _counts(self):
        th, al = self.x[0], self.x[1]
        return (math.floor(th / (2 * math.pi) * COUNTS + 0.5),
                math.floor((al - math.pi) / (2 * math.pi) * COUNTS + 0.5))

    def encoder(self, ch: int) -> int:
        if ch not in (0, 1):
            raise HILError(QERR_BAD_CHANNEL, f"no encoder channel {ch}")
        return self._counts()[ch] - self.counts0[ch]

    def digital_in(self, ch: int) -> int:
        if ch not in (0, 1, 2):
            raise HILError(QERR_BAD_CHANNEL, f"no digital input {ch}")
        return int((self.amp_fault, self.stall, self.stall_error)[ch])

    def other_in(self, ch: int) -> float:
        if ch != TACH:
            raise HILError(QERR_BAD_CHANNEL, f"no other input {ch}")
        return self.x[2] / (2 * math.pi) * COUNTS

    def write_guard(self, what: str) -> None:
        if self.expired:
            raise HILError(QERR_WATCHDOG_EXPIRED, f"{what}: the watchdog has expired; the "
                           "outputs are protected until watchdog_clear")


class HIL:
    """The SDK's board handle (immediate I/O and watchdog calls of the QUBE)."""

    def __init__(self, card_type=None, card_identifier=None):
        self._board: Board | None = None
        if card_type is not None or card_identifier is not None:
            self.open(card_type, card_identifier)

    # --- life cycle ------------------------------------------------------------------
    def open(self, card_type, card_identifier):
        self.close()
        ids = os.environ.get("FAKE_QUANSER_BOARDS", "0").split(",")
        if card_type not in BOARD_TYPES or str(card_identifier) not in ids:
            raise HILError(QERR_NO_BOARD, f"no {card_type} board {card_identifier!r} found")
        self._board = Board(card_type, str(card_identifier))

    def is_valid(self):
        return self._board is not None

    def close(self):
        b = self._board
        if b is None:
            return
        b.advance()
        b._record("close")
        b.closed = True
        # the amplifier of a closed board is off (the USB link's end disables it)
        b.enabled = False
        b.voltage = 0.0
        b._flush()
        self._board = None

    def _b(self) -> Board:
        if self._board is None:
            raise HILError(QERR_NOT_OPEN, "the board is not open")
        self._board.advance()
        return self._board

    # --- immediate I/O ----------------------------------------------------------------
    def read_encoder(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        _values(buffer, num_channels, "i32")
        for i, ch in enumerate(chans):
            buffer[i] = b.encoder(ch)
        b._record("read_encoder", chans, [int(buffer[i]) for i in range(num_channels)])

    def read_digital(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        _values(buffer, num_channels, "i8")
        for i, ch in enumerate(chans):
            buffer[i] = b.digital_in(ch)
        b._record("read_digital", chans, [int(buffer[i]) for i in range(num_channels)])

    def read_other(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        _values(buffer, num_channels, "f64")
        for i, ch in enumerate(chans):
            buffer[i] = b.other_in(ch)
        b._record("read_other", chans, [float(buffer[i]) for i in range(num_channels)])

    def write_analog(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        vals = [float(v) for v in _values(buffer, num_channels, "f64")[:num_channels]]
        b._record("write_analog", chans, vals)
        b.write_guard("write_analog")
        for ch, v in zip(chans, vals, strict=True):
            if ch != 0:
                raise HILError(QERR_BAD_CHANNEL, f"no analog output {ch}")
            if not math.isfinite(v):
                raise ValueError(f"analog output {v!r}")
            b.voltage = v

    def write_digital(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        vals = [int(v) for v in _values(buffer, num_channels, "i8")[:num_channels]]
        b._record("write_digital", chans, vals)
        b.write_guard("write_digital")
        for ch, v in zip(chans, vals, strict=True):
            if ch != 0:
                raise HILError(QERR_BAD_CHANNEL, f"no digital output {ch}")
            b.enabled = bool(v)

    def write_other(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        vals = [float(v) for v in _values(buffer, num_channels, "f64")[:num_channels]]
        b._record("write_other", chans, vals)
        b.write_guard("write_other")
        for ch, v in zip(chans, vals, strict=True):
            if ch not in LED:
                raise HILError(QERR_BAD_CHANNEL, f"no other output {ch}")
            b.led[LED.index(ch)] = v

    def set_card_specific_options(self, options, size):
        b = self._b()
        b._record("set_card_specific_options", str(options), int(size))
        if not isinstance(options, str) or b.card_type != "qube_servo3_usb":
            raise HILError(QERR_BAD_CHANNEL, f"options {options!r} not supported by "
                           f"{b.card_type}")
        b.options = dict(item.split("=", 1) for item in options.split(";") if item)

    def set_encoder_counts(self, channels, num_channels, buffer):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        vals = [int(v) for v in _values(buffer, num_channels, "i32")[:num_channels]]
        b._record("set_encoder_counts", chans, vals)
        raw = b._counts()
        for ch, v in zip(chans, vals, strict=True):
            b.encoder(ch)  # channel check
            b.counts0[ch] = raw[ch] - v

    # --- watchdog -----------------------------------------------------------------------
    def watchdog_set_analog_expiration_state(self, channels, num_channels, voltages):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        vals = [float(v) for v in _values(voltages, num_channels, "f64")[:num_channels]]
        b._record("watchdog_set_analog_expiration_state", chans, vals)
        for ch, v in zip(chans, vals, strict=True):
            if ch != 0:
                raise HILError(QERR_BAD_CHANNEL, f"no analog output {ch}")
            b.exp_analog = v

    def watchdog_set_digital_expiration_state(self, channels, num_channels, states):
        b = self._b()
        chans = [int(c) for c in _values(channels, num_channels, "u32")[:num_channels]]
        vals = [int(v) for v in _values(states, num_channels, "i32")[:num_channels]]
        b._record("watchdog_set_digital_expiration_state", chans, vals)
        for ch, v in zip(chans, vals, strict=True):
            if ch != 0:
                raise HILError(QERR_BAD_CHANNEL, f"no digital output {ch}")
            b.exp_digital = v

    def watchdog_start(self, timeout):
        b = self._b()
        b._record("watchdog_start", float(timeout))
        if b.exp_analog is None and b.exp_digital is None:
            raise HILError(QERR_NO_EXPIRATION_STATE, "watchdog_start before any expiration "
                           "state was set")
        if not timeout > 0:
            raise ValueError(f"timeout {timeout!r}")
        b.wd_timeout = float(timeout)
        b.wd_last = CLOCK()

    def watchdog_reload(self):
        b = self._b()
        ok = b.wd_timeout is not None and not b.expired
        b._record("watchdog_reload", ok)
        if ok:
            b.wd_last = CLOCK()
        return ok

    def watchdog_is_expired(self):
        b = self._b()
        b._record("watchdog_is_expired", b.expired)
        return b.expired

    def watchdog_stop(self):
        b = self._b()
        b._record("watchdog_stop")
        b.wd_timeout = None

    def watchdog_clear(self):
        b = self._b()
        b._record("watchdog_clear")
        b.expired = False
