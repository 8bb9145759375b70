"""Rig backends: one small interface, four implementations.

A rig is what the loop reads the raw signals (y, x, v of App. B) from and
writes the DAC value u_DA to.  The interface (:class:`Rig`):

``open(h=None, cancel=None) -> None``
    Connect and start a session (protocol ``HELLO``); the motor is off.  A
    rig whose ``HELLO_ACK`` does not fit the controller (another period h,
    no watchdog) is refused; ``cancel()`` returning True (a stop requested
    while waiting) ends the attempt early.
``sample(k, deadline_ns) -> SensorReading | None``
    The raw reading for tick ``k``; ``None`` if the rig did not answer by
    ``deadline_ns`` (monotonic clock); raises :class:`BadReading` for a
    corrupted frame or a duplicated/out-of-order sequence number.
``write(k, u_da) -> None``
    Output the DAC value (already saturated to [-1, 1] by the loop).
``stop_motor() -> None``
    Best-effort ``u_DA = 0``; never raises.
``close() -> None``
    Stop the motor and release the connection.
``push(kick) -> None``
    Emulated rigs only: add ``kick`` rad/s to the pendulum's velocity.
``hand(action) -> None``
    ``rig-sim`` over UDP only: the operator's hand (a lap of the pendulum or
    the arm, App. B.1/B.2; :data:`.rigsim.HAND`).

Backends (:func:`open_rig` parses the ``--backend`` string):

``sim``
    :class:`SimRig`: the simulated plant in-process
    (:class:`frictionlab.model.simulation.SimulatedPlant`, the simulator's own
    integrator).  Paced in real time by the loop: reading tick k first
    advances the plant to step k with the last u held, so after missed
    deadlines the plant has moved on as a real one would.  Readings go
    through :class:`AdcModel` (:mod:`frictionlab.model.sensor`: App. B scaling,
    arm offset, wrap-around, optional 12-bit quantisation and noise per
    ``sim.quantization``, ``sim.noise`` and ``sim.seed``), so the loop's
    raw-to-SI conversion is exercised.
``udp://HOST:PORT``
    :class:`FramedRig` over :class:`UdpTransport`: the protocol of
    ``docs/protocol.md`` to ``frictionlab rig-sim`` or a real rig.
``serial://DEVICE[?baud=N]``
    :class:`FramedRig` over :class:`SerialTransport` (pyserial; DEVICE may
    also be a pyserial URL such as ``loop://``).
``qube2://ID``, ``qube3://ID``
    :class:`.qube.QubeRig`: a Quanser QUBE-Servo 2 or 3 through Quanser's HIL
    API (the SDK's ``quanser.hardware``; docs/qube.md).

The interface and its errors live in :mod:`.rigbase` (re-exported here).
"""

from __future__ import annotations

import math
import select
import socket
import time
from collections import deque
from collections.abc import Callable
from urllib.parse import parse_qs, urlsplit

from ..config import Config
from ..model.params import ParamError
from ..model.rig import RigScaling
from ..model.sensor import ADC_STEP, ARM_START, adc, dac, sensor_params, u_from_dac
from ..runs import simulated_plant
from . import protocol as P
from .protocol import Frame, FrameError, SensorReading
from .qube import QubeRig, parse_qube
from .rigbase import BadReading, Rig, RigError

__all__ = [
    "ARM_START",
    "AdcModel",
    "BadReading",
    "FramedRig",
    "QubeRig",
    "Rig",
    "RigError",
    "SerialTransport",
    "SimRig",
    "UdpTransport",
    "open_rig",
    "parse_backend",
    "send_control",
    "serial_settings",
]

#: How often :meth:`FramedRig.open` looks at its ``cancel`` callable while waiting (ns).
CANCEL_POLL_NS = 10_000_000
_MASK = 0xFFFFFFFF


class AdcModel:
    """SI plant signals to raw ADC values as the rig's converters produce them.

    A runner of :func:`frictionlab.model.sensor.adc` (the one sensor model).  The
    noise of a reading is that of its sample number: the tick (``SimRig``) or
    the request's sequence number (``rig-sim``; the loop asks for tick k with
    sequence number k), so tick k of a run carries the noise the simulator
    adds at its tick k for the same seed.  Readings given no number are
    numbered 0, 1, 2, ... in order.

    Parameters
    ----------
    scaling : RigScaling
        App. B factors (the rig's true ones).
    arm_offset : float
        Raw arm reading at Omega = 0 (the bias x_0 the loop captures).
    quantize : bool
        Round to the converter's grid ``step``.
    step : float
        The grid in raw units: the thesis rig's 12 bits (2/4096 per step over
        [-1, 1)), or a motor rig's encoder (``Config.sensor_step``).
    noise : float
        Standard deviation of Gaussian noise added to each signal in its SI
        unit before conversion (``sim.noise``).
    seed : int
        Seed of the noise stream (``sim.seed``).
    """

    def __init__(self, scaling: RigScaling, arm_offset: float = ARM_START,
                 quantize: bool = True, noise: float = 0.0, seed: int = 0,
                 step: float = ADC_STEP):
        self.sensor = sensor_params(scaling, 1.0 if quantize else 0.0, noise, seed, arm_offset,
                                    step)
        self.arm_offset = float(arm_offset)
        self.noise = float(noise)
        self.n = 0
        # compile (or load) the converter now, not in the loop's first tick
        adc(self.sensor, 0.0, 0.0, 0.0, 0)

    def read(self, theta: float, arm: float, arm_dot: float, n: int | None = None,
             count: bool = True) -> tuple[float, float, float]:
        """Raw ``(y, x, v)`` for the plant signals (wrapped, clipped, quantised) as
        sample ``n`` (default: the next in order; ``count=False`` leaves the order
        alone, e.g. to warm caches)."""
        if n is None:
            n = self.n
        if count:
            self.n = n + 1
        return adc(self.sensor, theta, arm, arm_dot, n)


class SimRig(Rig):
    """The simulated plant in-process, stepped once per tick (``--backend sim``).

    Parameters
    ----------
    cfg : Config
        Plant, friction and ``sim.*`` settings (``sim.initial_angle`` is the
        start; ``sim.noise``/``sim.quantization``/``sim.seed`` shape the readings).
    lockstep : bool
        Advance the plant one step per *executed* tick: missed deadlines (a
        pause of the host) then pause the simulated world too, and a run
        reproduces the simulator's whatever the machine's load.  Default
        False: the plant moves on in real time with u held, as a real one
        would.
    duration : float, optional
        The run's length (s): the time over which ``friction.drift`` acts
        when ``friction.drift_time`` is unset (default ``sim.duration``).
    """

    name = "sim"
    emulated = True

    def __init__(self, cfg: Config, scaling: RigScaling | None = None,
                 arm_offset: float = ARM_START, lockstep: bool = False,
                 duration: float | None = None):
        self.cfg = cfg
        self.lockstep = lockstep
        self.realtime_plant = not lockstep  # in lockstep the plant waits for the loop
        self.scaling = scaling or cfg.rig
        self.plant = simulated_plant(cfg, duration)
        self.plant_friction = cfg.friction_kind
        self._arm_offset = arm_offset
        self._kicks: deque[float] = deque()
        self.state = None

    def open(self, h: float | None = None, cancel: Callable[[], bool] | None = None) -> None:
        cfg = self.cfg
        self.adc = AdcModel(self.scaling, self._arm_offset, bool(cfg.sim.quantization),
                            cfg.sim.noise, cfg.sim.seed, cfg.sensor_step)
        self.state = self.plant.init()
        self.plant.step(self.state, 0.0)  # compile before the loop starts
        u_from_dac.py_func(0.0, 1.0)  # and the DAC law (it calls the compiled dac)
        self._k: int | None = None
        self.u_da = 0.0
        self._u = 0.0

    def sample(self, k: int, deadline_ns: int) -> SensorReading:
        if self._k is None:
            self._k = k
        st = self.state
        step = self.plant.step
        u = self._u
        if self.lockstep and self._k < k:
            self._k = k - 1
        while self._k < k:
            st = step(st, u)
            self._k += 1
        while self._kicks:
            st = self.plant.push(st, self._kicks.popleft())
        self.state = st
        self.rx_frames += 1
        x = st.x
        y, xr, v = self.adc.read(x[0], x[2], x[3], k)
        return SensorReading(y, xr, v, self.u_da, P.STATUS_EMULATED)

    def warm(self) -> None:
        self.plant.step(self.state, self._u)
        if not self.adc.noise:
            x = self.state.x
            self.adc.read(x[0], x[2], x[3], count=False)

    def write(self, k: int, u_da: float) -> None:
        u_da = dac.py_func(u_da, 1.0)
        self.u_da = u_da
        self._u = u_from_dac.py_func(u_da, self.scaling.u_scale)

    def stop_motor(self) -> None:
        self.u_da = 0.0
        self._u = 0.0

    def push(self, kick: float) -> None:
        if not math.isfinite(kick):
            raise ValueError(f"kick must be finite, got {kick}")
        self._kicks.append(float(kick))

    @property
    def theta(self) -> float:
        """True pendulum angle of the simulated plant (rad)."""
        return float(self.state.x[0])


# --- transports -------------------------------------------------------------


class UdpTransport:
    """One frame per datagram to ``host:port`` (a connected UDP socket)."""

    def __init__(self, host: str, port: int):
        self.addr = (host, int(port))
        infos = socket.getaddrinfo(host, int(port), type=socket.SOCK_DGRAM)
        if not infos:
            raise RigError(f"cannot resolve {host}")
        family, _, _, _, sockaddr = infos[0]
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sock.connect(sockaddr)
        self._poll = select.poll()
        self._poll.register(self.sock, select.POLLIN)
        self.refused = 0

    def send(self, data: bytes) -> None:
        try:
            self.sock.send(data)
        except (ConnectionRefusedError, BlockingIOError):
            self.refused += 1

    def recv(self, deadline_ns: int) -> Frame | FrameError | None:
        poll = self._poll.poll
        recv = self.sock.recv
        while True:
            rest = deadline_ns - time.monotonic_ns()
            # poll's timeout is in ms (rounded up); a last look when the time is up, as
            # the wait may have been cut short by a host pause
            if poll(rest / 1e6 if rest > 0 else 0):
                try:
                    data = recv(4096)
                except BlockingIOError:
                    continue
                except ConnectionRefusedError:
                    # ICMP port unreachable from an earlier send: nobody is listening
                    self.refused += 1
                    continue
                try:
                    return P.decode(data)
                except FrameError as exc:
                    return exc
            if rest <= 0:
                return None

    def drain(self) -> None:
        """Discard anything queued (stale replies of an earlier session)."""
        while True:
            try:
                self.sock.recv(4096)
            except (BlockingIOError, ConnectionRefusedError):
                return

    def close(self) -> None:
        self.sock.close()


def serial_settings(baudrate: int = 1_000_000) -> dict:
    """The protocol's line settings as pyserial arguments: 8N1, no flow control.

    pyserial opens a POSIX device in raw mode (no echo, no line editing, no
    translation of bytes), which the byte stream needs.
    """
    import serial

    return {"baudrate": baudrate, "bytesize": serial.EIGHTBITS, "parity": serial.PARITY_NONE,
            "stopbits": serial.STOPBITS_ONE, "xonxoff": False, "rtscts": False,
            "dsrdtr": False}


class SerialTransport:
    """Frames on a byte stream (pyserial), resynchronised by :class:`FrameDecoder`.

    Parameters
    ----------
    device : str
        Device path (``/dev/ttyACM0``) or pyserial URL (``loop://``).
    baudrate : int
        Line speed.  A tick exchanges 14 + 31 + 18 = 63 bytes, so a UART needs
        at least 230400 baud at h = 5 ms; USB CDC devices ignore the setting.
    """

    def __init__(self, device: str, baudrate: int = 1_000_000):
        import serial  # pyserial

        try:
            self.port = serial.serial_for_url(device, timeout=0, write_timeout=0.1,
                                              **serial_settings(baudrate))
        except (serial.SerialException, ValueError) as exc:
            raise RigError(f"cannot open serial device {device}: {exc}") from None
        self.decoder = P.FrameDecoder()
        self._pending: deque = deque()
        try:
            self._fd = self.port.fileno()
        except (AttributeError, OSError, NotImplementedError, ValueError):
            self._fd = None

    def send(self, data: bytes) -> None:
        self.port.write(data)

    def recv(self, deadline_ns: int) -> Frame | FrameError | None:
        while not self._pending:
            n = self.port.in_waiting
            if n:
                self._pending.extend(self.decoder.feed(self.port.read(n)))
                continue
            rest = deadline_ns - time.monotonic_ns()
            if rest <= 0:
                n = self.port.in_waiting
                if not n:
                    return None
                continue
            if self._fd is not None:
                select.select((self._fd,), (), (), rest / 1e9)
            else:
                time.sleep(min(rest / 1e9, 1e-4))
        return self._pending.popleft()

    def drain(self) -> None:
        self.port.reset_input_buffer()
        self._pending.clear()
        self.decoder = P.FrameDecoder()

    def close(self) -> None:
        self.port.close()


#: How many timed-out requests a :class:`FramedRig` remembers, to recognise their
#: late replies: at least the longest run of ticks without a timely reading that the
#: loop lets pass (``Safety.unread_limit``, at most 1000).
LATE_MEMORY = 1024


class FramedRig(Rig):
    """A rig speaking the frame protocol over a transport (UDP or serial).

    Sequence numbers: the SAMPLE request of tick k carries ``k mod 2**32``
    and the SENSOR reply must echo it.  A reply to a request that already
    timed out (it arrives late, after a host pause) is discarded and counted
    in ``late_replies``; any other mismatch - a sequence number already
    answered (duplicate, stale) or one never requested (out of order) - is a
    :class:`BadReading`, as is a frame failing its CRC or length checks.

    Host pauses: when the wait for a reply ends more than ``pause_ns`` after
    its deadline, the process was not running when the deadline passed (the
    host paused the virtual CPU, or a higher-priority thread held it), and
    the rig - an emulator sharing the CPU, or the kernel's receive path - had
    no chance to answer in the meantime.  Such a wait gets ``grace_ns`` more
    (once) before it counts as no reply, so that one pause is not mistaken
    for a silent rig.  A rig that really is silent still times out, only
    ``grace_ns`` later.

    Parameters
    ----------
    transport : UdpTransport or SerialTransport or DirectTransport
    name : str
        The backend as the user wrote it (for messages).
    hello_timeout : float
        Seconds to wait for the rig's HELLO_ACK in :meth:`open`.
    clock : object with ``now_ns()``, optional
        The time source (default the monotonic clock).
    pause_ns, grace_ns : int
        See "Host pauses" above (defaults 1 ms and 1 ms).
    """

    def __init__(self, transport, name: str, hello_timeout: float = 1.0, clock=None,
                 pause_ns: int = 1_000_000, grace_ns: int = 1_000_000):
        self.tx = transport
        self.name = name
        self._now = time.monotonic_ns if clock is None else clock.now_ns
        self.pause_ns = pause_ns
        self.grace_ns = grace_ns
        self.paused_waits = 0
        self.hello_timeout = hello_timeout
        self.late_replies = 0
        self.ignored = 0
        # the requests that timed out, so that their late replies are recognised (and
        # dropped) rather than taken for a broken rig: as many as the loop may go
        # without a timely reading (Safety.unread_limit <= 1000)
        self._timed_out: deque[int] = deque(maxlen=LATE_MEMORY)
        self._last_seq = 0
        self.info: P.HelloInfo | None = None

    def open(self, h: float | None = None, cancel: Callable[[], bool] | None = None) -> None:
        """Start a session: ``HELLO`` until a valid ``HELLO_ACK``, check it, warm up.

        Parameters
        ----------
        h : float, optional
            The controller's sampling period (s).  A ``HELLO_ACK`` stating
            another period (other than 0, "any") is refused.
        cancel : callable, optional
            Polled at least every :data:`CANCEL_POLL_NS`; when it returns True
            (a stop was requested, e.g. by a signal) ``open`` returns at once,
            with or without a session (:attr:`info` None without).

        Raises
        ------
        RigError
            No valid ``HELLO_ACK`` within ``hello_timeout`` (the message says
            what came instead: bad CRC, wrong length, another message type),
            or one the controller cannot work with: a period other than h, no
            watchdog or one shorter than 2 h, an impossible ADC resolution.
        """
        self.info = None
        self.tx.drain()
        now = self._now
        end = now() + int(self.hello_timeout * 1e9)
        problems: dict[str, int] = {}
        while now() < end:
            if cancel is not None and cancel():
                return
            self.tx.send(P.encode(P.MSG_HELLO, 0))
            attempt_end = min(end, now() + 200_000_000)
            while True:
                msg = self.tx.recv(min(attempt_end, now() + CANCEL_POLL_NS))
                if msg is None:
                    if cancel is not None and cancel():
                        return
                    if now() >= attempt_end:
                        break
                    continue
                if isinstance(msg, FrameError):
                    problem = str(msg)
                elif msg.type != P.MSG_HELLO_ACK:
                    problem = f"a {msg.name} frame instead of HELLO_ACK"
                else:
                    try:
                        info = P.parse_hello_ack(msg)
                    except FrameError as exc:
                        problem = str(exc)
                    else:
                        self._check_hello(info, h)
                        self.info = info
                        self.emulated = bool(info.status & P.STATUS_EMULATED)
                        self._warm_up(cancel=cancel)
                        return
                problems[problem] = problems.get(problem, 0) + 1
        if not problems:
            raise RigError(f"no answer from the rig at {self.name} (HELLO timed out after "
                           f"{self.hello_timeout:g} s)")
        what = "; ".join(f"{problem} ({n} {'frame' if n == 1 else 'frames'})"
                         for problem, n in problems.items())
        raise RigError(f"no valid HELLO_ACK from the rig at {self.name} within "
                       f"{self.hello_timeout:g} s: {what}")

    def _check_hello(self, info: P.HelloInfo, h: float | None) -> None:
        """Refuse a session the controller cannot run safely (see :meth:`open`)."""
        where = f"the rig at {self.name}"
        if h is not None and info.h_tenth_ms and abs(info.h_tenth_ms - h * 1e4) >= 0.5:
            raise RigError(f"{where} samples every {info.h_tenth_ms / 10:g} ms (HELLO_ACK) but "
                           f"the controller's period is {h * 1e3:g} ms: set "
                           f"design.h={info.h_tenth_ms / 1e4:g} or configure the rig for "
                           f"{h * 1e3:g} ms")
        if info.watchdog_ms == 0:
            raise RigError(f"{where} reports no watchdog (0 ms in HELLO_ACK): if the "
                           "controller died the motor would keep its last command; a rig "
                           "must zero the motor by itself (docs/protocol.md)")
        if h is not None and info.watchdog_ms < 2e3 * h:
            raise RigError(f"{where} has a watchdog of {info.watchdog_ms} ms, shorter than two "
                           f"periods ({2e3 * h:g} ms): one late command would zero the motor")
        if not 1 <= info.adc_bits <= 24:
            raise RigError(f"{where} reports {info.adc_bits} ADC bits (HELLO_ACK); expected "
                           "1 to 24 (float32 readings in [-1, 1])")

    _CANNED = P.encode(P.MSG_SENSOR, 0, P.sensor_payload(0.0, 0.0, 0.0, 0.0, 0))

    def warm(self) -> None:
        P.parse_sensor(P.decode(self._CANNED))
        P.sample_frame(0)
        P.command_frame(0, 0.0)

    def _warm_up(self, n: int = 5, cancel: Callable[[], bool] | None = None) -> None:
        """A few SAMPLE exchanges before the first tick (warms both ends' code paths)."""
        now = self._now
        for i in range(n):
            if cancel is not None and cancel():
                return
            seq = _MASK - n + 1 + i
            deadline = now() + 50_000_000
            self.tx.send(P.sample_frame(seq))
            while True:
                msg = self.tx.recv(deadline)
                if msg is None:
                    self._timed_out.append(seq)
                    break
                if isinstance(msg, Frame) and msg.seq == seq:
                    break

    def sample(self, k: int, deadline_ns: int) -> SensorReading | None:
        seq = k & _MASK
        self.tx.send(P.sample_frame(seq))
        recv = self.tx.recv
        graced = False
        while True:
            msg = recv(deadline_ns)
            if msg is None:
                now = self._now()
                if not graced and now - deadline_ns > self.pause_ns:
                    # the wait outlived its deadline: a pause, not the rig (see class doc)
                    graced = True
                    self.paused_waits += 1
                    deadline_ns = now + self.grace_ns
                    continue
                self._timed_out.append(seq)
                return None
            if isinstance(msg, FrameError):
                raise BadReading(f"corrupted frame: {msg}")
            self.rx_frames += 1
            if msg.type != P.MSG_SENSOR:
                if msg.type in (P.MSG_HELLO_ACK, P.MSG_CONTROL_ACK):
                    self.ignored += 1
                    continue
                raise BadReading(f"unexpected {msg.name} frame from the rig")
            s = msg.seq
            if s == seq:
                try:
                    reading = P.parse_sensor(msg)
                except FrameError as exc:
                    raise BadReading(f"corrupted frame: {exc}") from None
                self._last_seq = seq
                return reading
            if s in self._timed_out:
                self._timed_out.remove(s)
                self.late_replies += 1
                continue
            ahead = (s - seq) & _MASK
            if 0 < ahead < 0x80000000:
                raise BadReading(f"out-of-order sequence number {s} (expected {seq})")
            raise BadReading(f"duplicated or stale sequence number {s} (expected {seq})")

    def write(self, k: int, u_da: float) -> None:
        self._last_seq = k & _MASK
        self.tx.send(P.command_frame(self._last_seq, u_da))

    def stop_motor(self) -> None:
        try:
            self.tx.send(P.command_frame(self._last_seq, 0.0))
        except Exception:
            pass

    def close(self) -> None:
        self.stop_motor()
        self.tx.close()

    def push(self, kick: float) -> None:
        if not self.emulated or not isinstance(self.tx, UdpTransport):
            raise RigError(f"push needs an emulated rig over UDP; {self.name} is not one")
        reply = send_control(self.tx.addr[0], self.tx.addr[1], {"cmd": "fault", "push": kick})
        if not reply.get("ok"):
            raise RigError(f"rig refused the push: {reply.get('error')}")

    def hand(self, action: dict) -> None:
        if not self.emulated or not isinstance(self.tx, UdpTransport):
            return super().hand(action)
        reply = send_control(self.tx.addr[0], self.tx.addr[1], {"cmd": "hand", **action})
        if not reply.get("ok"):
            raise RigError(f"rig refused the hand: {reply.get('error')}")

    def counters(self) -> dict:
        return {"late_replies": self.late_replies, "ignored_frames": self.ignored,
                "paused_waits": self.paused_waits}


def open_rig(spec: str, cfg: Config, *, lockstep: bool = False,
             duration: float | None = None) -> Rig:
    """The rig a ``--backend`` string names (not yet opened).

    ``lockstep`` applies to ``sim`` (see :class:`SimRig`).

    Raises
    ------
    ParamError
        (a ``ValueError``, field ``backend``) For an unknown scheme or a
        malformed address (:func:`parse_backend`).
    """
    scheme, where, arg = parse_backend(spec)
    if scheme == "sim":
        return SimRig(cfg, lockstep=lockstep, duration=duration)
    if scheme in ("qube2", "qube3"):
        return QubeRig(spec, cfg)
    if scheme == "udp":
        return FramedRig(UdpTransport(where, arg), spec)
    return FramedRig(SerialTransport(where, arg), spec)


#: The backends a rig string may name (the ``allowed`` of a refused one, field ``backend``).
BACKEND_FORMS = ("sim, udp://HOST:PORT, serial://DEVICE[?baud=N], qube2://ID or "
                 "qube3://ID")


def parse_backend(spec: str) -> tuple[str, str | None, int | None]:
    """``(scheme, host or device, port or baud)`` of a backend string, checked
    without connecting: ``("sim", None, None)``, ``("udp", HOST, PORT)``,
    ``("serial", DEVICE, BAUD)`` (baud 1 000 000 unless ``?baud=N``),
    ``("qube2", ID, None)`` and ``("qube3", ID, None)`` (options checked by
    :func:`.qube.parse_qube`).

    Raises
    ------
    ParamError
        (field ``backend``) An unknown scheme or a malformed address.
    """
    if spec == "sim":
        return "sim", None, None
    parts = urlsplit(spec)
    if parts.scheme == "udp":
        try:
            port = parts.port
        except ValueError:
            port = None
        if not parts.hostname or port is None:
            raise ParamError("backend", spec, BACKEND_FORMS,
                             f"{spec!r}: expected udp://HOST:PORT")
        return "udp", parts.hostname, port
    if parts.scheme == "serial":
        rest = spec[len("serial://"):]
        device, _, query = rest.partition("?")
        if not device:
            raise ParamError("backend", spec, BACKEND_FORMS,
                             f"{spec!r}: expected serial://DEVICE[?baud=N]")
        baud = 1_000_000
        if query:
            q = parse_qs(query)
            try:
                baud = int(q.get("baud", [baud])[0])
            except ValueError:
                raise ParamError("backend", spec, BACKEND_FORMS,
                                 f"{spec!r}: baud must be an integer") from None
        return "serial", device, baud
    if parts.scheme in ("qube2", "qube3"):
        scheme, ident, _options = parse_qube(spec)
        return scheme, ident, None
    raise ParamError("backend", spec, BACKEND_FORMS,
                     f"{spec!r}: expected sim, udp://HOST:PORT, serial://DEVICE, qube2://ID "
                     "or qube3://ID")


def send_control(host: str, port: int, message: dict, timeout: float = 1.0) -> dict:
    """Send a CONTROL object to a rig-sim and return its answer (a dict)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        sock.settimeout(timeout)
        seq = int(time.monotonic_ns() & 0xFFFFFFFF)
        sock.sendto(P.control_frame(seq, message), (host, port))
        end = time.monotonic() + timeout
        while True:
            sock.settimeout(max(1e-3, end - time.monotonic()))
            try:
                data = sock.recv(4096)
            except TimeoutError:
                raise TimeoutError(f"rig-sim at {host}:{port} did not answer") from None
            try:
                frame = P.decode(data)
            except FrameError:
                continue
            if frame.type == P.MSG_CONTROL_ACK and frame.seq == seq:
                return P.parse_control(frame)
