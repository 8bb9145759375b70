r"""The QUBE-Servo 2 and 3 through Quanser's HIL API (``--backend qube2://ID``, ``qube3://ID``).

The backend speaks to the board with the SDK's *immediate* I/O calls, once per
tick, paced by the loop's own clock (as Quanser's examples for the QUBE do):
``sample`` reloads the board's watchdog and reads the two encoders, the
tachometer and the three status inputs; ``write`` writes the motor voltage
(and, once, the amplifier enable).  The loop, its log, its stops and its
statistics are those of every backend (:mod:`.rigs`).

Channels and conventions (QUBE-Servo 2 documentation)
-----------------------------------------------------

============================  =============================================
analog output 0               motor voltage, V (|V| <= :data:`V_MAX` here)
digital output 0              amplifier enable
encoder input 0, 1            arm, pendulum; :data:`COUNTS` counts/rev each
other input 14000             tachometer: arm speed, counts/s
digital inputs 0, 1, 2        amplifier fault, stall detected, stall error
other outputs 11000-11002     the LED, red, green, blue in [0, 1]
============================  =============================================

A positive voltage turns the arm so that encoder 0 counts up; with the
pendulum hanging, a positive voltage step makes encoder 1 count down at
first.  The encoders are zeroed by :meth:`QubeRig.open` with the pendulum
hanging at rest.  With ``rig.arm_sign`` :math:`s_a` and ``rig.pendulum_sign``
:math:`s_p` (+1 for a QUBE as Quanser wires it, -1 to flip an encoder counting
the other way) the project's angles are

.. math::

    \Omega = s_a \frac{2\pi c_0}{2048},\qquad
    \dot\Omega = s_a \frac{2\pi\,c_{14000}}{2048},\qquad
    \theta = \pi - s_p \frac{2\pi c_1}{2048}

so that, as in eq. (6), a positive u accelerates the arm positively and the
upright pendulum negatively (theta from upright; hanging is +-pi).  The
voltage is the sensor module's inverse DAC law, :math:`V = u_{DA}/k_u`
(:func:`frictionlab.model.sensor.u_from_dac`; ``rig.u_scale`` :math:`k_u` = 0.1
per volt: u in volts, u_DA = 1 is 10 V), clipped to :data:`V_MAX`; a motor wired
the other way is ``rig.u_scale = -0.1``.

These SI signals are handed to the loop as its raw channels through the
sensor module's inverse laws with the run's own ``rig.*`` factors
(:func:`frictionlab.model.sensor.to_raw`, ``arm_to_raw``, ``wrap``), so the
loop's conversion back (the one sensor law) gives them back exactly whatever
those factors are; the factors only set the channels' ranges (the velocity
channel clips at +-``rig.velocity_scale``).  :data:`QUBE_RIG` holds the values
the backend implies (``frictionlab`` applies them with a ``qube`` backend
before ``--config`` and ``--set``).

Safety
------
Before the amplifier is ever enabled, the first tick sets the watchdog's
expiration states (analog output 0 to 0 V, digital output 0 low: amplifier
off) and starts it with a timeout of :data:`WATCHDOG_PERIODS` periods
(``?watchdog=S`` in the backend string to change it); every tick reloads it.
The amplifier is enabled at the first non-zero voltage, never again after a
fault.  A reload that finds the watchdog expired, the amplifier-fault input or
either stall input raises :class:`RigStop`, which stops the loop with reason
``watchdog_expired``, ``amplifier_fault`` or ``motor_stall`` (u = 0 in that
tick); a HIL error on a read stops it as ``rig_fault``.  :meth:`QubeRig.stop_motor`
writes 0 V and turns the amplifier off; :meth:`QubeRig.close` does that, stops
the watchdog and closes the board, each step on its own so that one failing
does not skip the others, and is also registered to run at interpreter exit.
Killed outright (SIGKILL), the board's watchdog zeroes the motor by itself.

A QUBE-Servo 3 is given :data:`QUBE3_OPTIONS` when it is opened (Quanser's card
options for it, deadband compensation off).

The LED: blue, connected with the motor off (before the first tick, while
waiting for the pendulum to be lifted, and after a run that stopped without a
board fault); yellow, the loop drives the motor with the pendulum away from
upright (hanging, swinging up, an experiment); green, the loop drives the
motor with the pendulum within :data:`UPRIGHT_LED` of upright (balancing);
red, the board stopped the run (watchdog expired, amplifier fault, stall): it
stays red after the board is closed.
"""

from __future__ import annotations

import atexit
import dataclasses
import math
import time
from collections.abc import Callable
from urllib.parse import parse_qs, urlsplit

import numpy as np

from ..config import Config
from ..model import sensor
from ..model.params import ParamError
from ..model.rig import motor_rig
from .protocol import SensorReading
from .rigbase import BadReading, Rig, RigError

__all__ = ["BOARD_TYPES", "COUNTS", "QUBE_RIG", "V_MAX", "QubeRig", "RigStop", "parse_qube"]

#: Backend scheme -> Quanser board type.
BOARD_TYPES = {"qube2": "qube_servo2_usb", "qube3": "qube_servo3_usb"}
#: Encoder counts per revolution (arm and pendulum).
COUNTS = 2048
#: Largest |V| the backend writes (the QUBE's motor rating).
V_MAX = 10.0
#: Default watchdog timeout in periods h.
WATCHDOG_PERIODS = 5
#: |theta| below which the LED shows balancing (rad).
UPRIGHT_LED = 0.3
#: ``?wait=upright``: the run starts once the pendulum is lifted within this of upright (rad).
WAIT_UPRIGHT = 0.1
#: The QUBE-Servo 3's card-specific options: those Quanser's own Python module gives it
#: (``pwm_en=0``, encoder velocity and diode settings) except its deadband compensation,
#: off: the friction the controller sees and compensates is then the rig's own.
QUBE3_OPTIONS = ("deadband_compensation=0;pwm_en=0;enc0_velocity=3.0;enc1_velocity=3.0;"
                 "min_diode_compensation=0.3;max_diode_compensation=1.5")

#: The ``rig.*`` values the backend implies: a motor rig's
#: (:func:`frictionlab.model.rig.motor_rig`) at the QUBE's 10 V, u in volts (see the
#: module docstring).
QUBE_RIG = {f"rig.{k}": v for k, v in dataclasses.asdict(motor_rig(V_MAX)).items()
            if k in ("theta_scale", "theta_bias", "arm_scale", "velocity_scale",
                     "velocity_bias", "u_scale")}

INSTALL_HINT = ("the {scheme} backend needs Quanser's HIL API for Python (module "
                "quanser.hardware), which is not installed: install the Quanser SDK (Linux: "
                "sudo apt-get install quanser-sdk from Quanser's repository) and its Python "
                "package into frictionlab's environment (pip install --find-links "
                "SDK_PYTHON_FOLDER quanser_api); see docs/qube.md")

_FORMS = "qube2://ID or qube3://ID[?watchdog=S][&wait=upright] (ID usually 0)"

_TWO_PI = 2.0 * math.pi
_ENC = np.array([0, 1], dtype=np.uint32)
_TACH = np.array([14000], dtype=np.uint32)
_DIN = np.array([0, 1, 2], dtype=np.uint32)
_AOUT = np.array([0], dtype=np.uint32)
_DOUT = np.array([0], dtype=np.uint32)
_LED = np.array([11000, 11001, 11002], dtype=np.uint32)
_COLOURS = {"blue": (0.0, 0.0, 1.0), "yellow": (1.0, 1.0, 0.0), "green": (0.0, 1.0, 0.0),
            "red": (1.0, 0.0, 0.0)}


class RigStop(BadReading):
    """The board stopped the run: ``reason`` is the loop's stop reason
    (``watchdog_expired``, ``amplifier_fault``, ``motor_stall``, ``rig_fault``)."""

    def __init__(self, reason: str, detail: str):
        super().__init__(detail)
        self.reason = reason


def parse_qube(spec: str) -> tuple[str, str, dict]:
    """``(scheme, board identifier, options)`` of ``qube2://ID[?watchdog=S&wait=upright]``.

    Raises
    ------
    ParamError
        (field ``backend``) A malformed string.
    """
    parts = urlsplit(spec)
    scheme = parts.scheme
    ident = parts.netloc
    if scheme not in BOARD_TYPES or not ident or parts.path.strip("/"):
        raise ParamError("backend", spec, _FORMS, f"{spec!r}: expected {_FORMS}")
    options: dict = {}
    for key, values in parse_qs(parts.query, keep_blank_values=True).items():
        value = values[-1]
        if key == "watchdog":
            try:
                s = float(value)
            except ValueError:
                s = math.nan
            if not (0.0 < s <= 10.0):
                raise ParamError("backend", spec, _FORMS,
                                 f"{spec!r}: watchdog must be a time in (0, 10] s")
            options["watchdog"] = s
        elif key == "wait" and value == "upright":
            options["wait"] = value
        else:
            raise ParamError("backend", spec, _FORMS,
                             f"{spec!r}: unknown option {key}={value} (watchdog=S, "
                             "wait=upright)")
    return scheme, ident, options


def _hil_module(scheme: str):
    """``quanser.hardware``, or a :class:`RigError` saying what to install."""
    try:
        from quanser import hardware  # Quanser's SDK: optional, imported only here
    except ImportError:
        raise RigError(INSTALL_HINT.format(scheme=scheme)) from None
    return hardware


class QubeRig(Rig):
    """A QUBE-Servo on Quanser's HIL API (see the module docstring).

    Parameters
    ----------
    spec : str
        ``qube2://ID`` or ``qube3://ID``, options ``watchdog=S`` (the board
        watchdog's timeout; default :data:`WATCHDOG_PERIODS` periods) and
        ``wait=upright`` (:meth:`open` returns once the pendulum is lifted by
        hand within :data:`WAIT_UPRIGHT` of upright: the thesis's start).
    cfg : Config
        The run's configuration: ``rig.*`` (the raw channels' factors, the
        encoder signs) and ``design.h``.
    """

    realtime_plant = True

    def __init__(self, spec: str, cfg: Config):
        self.scheme, self.ident, self.options = parse_qube(spec)
        self.name = spec
        self.board_type = BOARD_TYPES[self.scheme]
        self.cfg = cfg
        sc = cfg.rig
        self._ts, self._tb = sc.theta_scale, sc.theta_bias
        self._as, self._vs, self._vb = sc.arm_scale, sc.velocity_scale, sc.velocity_bias
        self._k_arm = sc.arm_sign * _TWO_PI / COUNTS
        self._k_pend = sc.pendulum_sign * _TWO_PI / COUNTS
        self._us = sc.u_scale
        self._dac = sensor.dac.py_func
        self._u_from_dac = sensor.u_from_dac.py_func
        self.card = None
        self.hw = None
        self._reset()

    def _reset(self) -> None:
        self.armed = False        # watchdog expiration states set and watchdog started
        self.enabled = False      # amplifier enabled by us
        self.fault: str | None = None  # a board fault seen (latched: no more output)
        self._refused = None  # the HILError of a refused write, reported by the next sample
        self.u_da = 0.0
        self.voltage = 0.0
        self.led: str | None = None
        self.theta = math.nan
        self.reloads = 0
        self.timeout = None
        self._closed = True

    # --- session -------------------------------------------------------------------
    def open(self, h: float | None = None, cancel: Callable[[], bool] | None = None) -> None:
        """Open the board with the amplifier off and 0 V, zero the encoders (the
        pendulum must hang at rest), light the LED blue.

        Raises
        ------
        RigError
            The SDK is not installed (the message says what to install), the
            board cannot be opened or answers with an error, or it reports an
            amplifier fault or a stall already.
        """
        hw = _hil_module(self.scheme)
        self.hw = hw
        self._reset()
        # compile (or load) the DAC law now: the first write must not wait for it
        self._u_from_dac(0.0, 1.0)
        h = self.cfg.design.h if h is None else h
        self.timeout = self.options.get("watchdog", WATCHDOG_PERIODS * h)
        if self.timeout < 2 * h:
            raise RigError(f"{self.name}: a watchdog of {self.timeout * 1e3:g} ms is shorter "
                           f"than two periods ({2e3 * h:g} ms): one late tick would zero the "
                           "motor")
        self._counts = np.zeros(2, dtype=np.int32)
        self._tach = np.zeros(1, dtype=np.float64)
        self._din = np.zeros(3, dtype=np.int8)
        self._volts = np.zeros(1, dtype=np.float64)
        self._digital = np.zeros(1, dtype=np.int8)
        card = hw.HIL()
        try:
            card.open(self.board_type, self.ident)
        except hw.HILError as exc:
            raise RigError(f"cannot open the {self.board_type} board {self.ident!r} "
                           f"({self.name}): {_message(exc)}") from None
        self.card = card
        self._closed = False
        atexit.register(self.close)
        try:
            if self.scheme == "qube3":
                card.set_card_specific_options(QUBE3_OPTIONS, hw.MAX_STRING_LENGTH)
            self._output(0.0, False)
            self._digital[0] = 0
            card.write_digital(_DOUT, 1, self._digital)
            card.set_encoder_counts(_ENC, 2, np.zeros(2, dtype=np.int32))
            self._set_led("blue")
            card.read_digital(_DIN, 3, self._din)
        except hw.HILError as exc:
            self.close()
            raise RigError(f"{self.name}: the board failed at set-up: {_message(exc)}") from None
        bad = self._status_fault()
        if bad is not None:
            self.close()
            raise RigError(f"{self.name}: {bad[1]} before the run (power the QUBE off and on; "
                           "docs/qube.md)")
        if self.options.get("wait") == "upright":
            try:
                self._wait_upright(cancel)
            except hw.HILError as exc:
                self.close()
                raise RigError(f"{self.name}: the board failed while waiting for the "
                               f"pendulum: {_message(exc)}") from None

    def _wait_upright(self, cancel) -> None:
        """Read the pendulum (motor off) until it is lifted within WAIT_UPRIGHT."""
        card = self.card
        while cancel is None or not cancel():
            card.read_encoder(_ENC, 2, self._counts)
            theta = math.remainder(math.pi - self._k_pend * float(self._counts[1]), _TWO_PI)
            if abs(theta) <= WAIT_UPRIGHT:
                return
            time.sleep(0.01)

    def _arm(self) -> None:
        """Expiration states (0 V, amplifier off), then start the watchdog."""
        hw, card = self.hw, self.card
        card.watchdog_set_analog_expiration_state(_AOUT, 1, np.zeros(1, dtype=np.float64))
        card.watchdog_set_digital_expiration_state(
            _DOUT, 1, np.array([hw.DigitalState.LOW], dtype=np.int32))
        card.watchdog_start(self.timeout)
        self.armed = True

    # --- the tick --------------------------------------------------------------------
    def sample(self, k: int, deadline_ns: int) -> SensorReading:
        card = self.card
        if self._refused is not None:
            self._stop_after_refusal()
        try:
            if not self.armed:
                self._arm()
            elif not card.watchdog_reload():
                self._latch("watchdog_expired", "the board's watchdog expired: no tick "
                            f"reloaded it within {self.timeout * 1e3:g} ms, and the board set "
                            "0 V with the amplifier off")
            else:
                self.reloads += 1
            card.read_encoder(_ENC, 2, self._counts)
            card.read_other(_TACH, 1, self._tach)
            card.read_digital(_DIN, 3, self._din)
        except self.hw.HILError as exc:
            self._latch("rig_fault", f"the board failed: {_message(exc)}")
        bad = self._status_fault()
        if bad is not None:
            self._latch(*bad)
        self.rx_frames += 1
        c = self._counts
        arm = self._k_arm * float(c[0])
        theta = math.pi - self._k_pend * float(c[1])
        arm_dot = self._k_arm * float(self._tach[0])
        self.theta = theta
        wrap = sensor.wrap.py_func
        y = wrap(sensor.theta_to_raw.py_func(theta, self._ts, self._tb))
        x = wrap(sensor.arm_to_raw.py_func(arm, self._as, 0.0))
        v = sensor.velocity_to_raw.py_func(arm_dot, self._vs, self._vb)
        v = 1.0 if v > 1.0 else (-1.0 if v < -1.0 else v)
        return SensorReading(y, x, v, self.u_da, 0)

    def _stop_after_refusal(self) -> None:
        """The board refused the last write: say why (its watchdog, or an error)."""
        exc = self._refused
        try:
            expired = bool(self.card.watchdog_is_expired())
        except Exception:
            expired = False
        self.fault = None
        if expired:
            self._latch("watchdog_expired", "the board's watchdog expired (no reload within "
                        f"{self.timeout * 1e3:g} ms) and refused the tick's output: it had "
                        "set 0 V with the amplifier off")
        self._latch("rig_fault", f"the board refused the motor command: {_message(exc)}")

    def _status_fault(self) -> tuple[str, str] | None:
        d = self._din
        if d[0]:
            return "amplifier_fault", "the QUBE reports an amplifier fault (digital input 0)"
        if d[2]:
            return "motor_stall", ("the QUBE reports a motor stall error (digital input 2): "
                                   "the arm was blocked under voltage")
        if d[1]:
            return "motor_stall", ("the QUBE reports a motor stall (digital input 1): the arm "
                                   "does not turn under voltage")
        return None

    def _latch(self, reason: str, detail: str) -> None:
        """A board fault: no more output from this session; stop the loop."""
        if self.fault is None:
            self.fault = reason
        self.stop_motor()
        raise RigStop(reason, detail)

    def write(self, k: int, u_da: float) -> None:
        if self.fault is not None or self.card is None:
            return  # after a board fault nothing but the stop (stop_motor) is written
        # the DAC law of the sensor module and its inverse: u_DA saturated, the
        # voltage u = u_DA / rig.u_scale, clipped to the QUBE's rating
        u_da = self._dac(u_da, 1.0)
        volts = self._u_from_dac(u_da, self._us)
        volts = V_MAX if volts > V_MAX else (-V_MAX if volts < -V_MAX else volts)
        self.u_da = u_da
        enable = self.enabled or (volts != 0.0 and self.armed)
        if not enable:
            volts = 0.0
        try:
            self._output(volts, enable)
            colour = ("green" if abs(math.remainder(self.theta, _TWO_PI)) < UPRIGHT_LED
                      else "yellow")
            if colour != self.led and self.armed:
                self._set_led(colour)
        except self.hw.HILError as exc:
            # refused (the watchdog expired in the meantime) or lost: nothing more is
            # written, and the next tick's sample stops the run with the reason
            self._refused = exc
            self.fault = "rig_fault"

    def _output(self, volts: float, enable: bool) -> None:
        """Enable the amplifier first if asked (it is off from :meth:`open` on), then
        write the voltage; disabling is :meth:`stop_motor`'s."""
        card = self.card
        if enable and not self.enabled:
            self._digital[0] = 1
            card.write_digital(_DOUT, 1, self._digital)
            self.enabled = True
        self._volts[0] = volts
        card.write_analog(_AOUT, 1, self._volts)
        self.voltage = volts

    def _set_led(self, colour: str) -> None:
        self.card.write_other(_LED, 3, np.array(_COLOURS[colour], dtype=np.float64))
        self.led = colour

    def stop_motor(self) -> None:
        """0 V and the amplifier off, each on its own; never raises."""
        card = self.card
        if card is None:
            return
        self.u_da = 0.0
        try:
            card.write_analog(_AOUT, 1, np.zeros(1, dtype=np.float64))
            self.voltage = 0.0
        except Exception:
            pass
        try:
            card.write_digital(_DOUT, 1, np.zeros(1, dtype=np.int8))
            self.enabled = False
        except Exception:
            pass

    def close(self) -> None:
        """0 V, amplifier off, watchdog stopped, LED (red after a board fault, else
        blue), board closed; every step tried whatever the others did."""
        card = self.card
        if card is None or self._closed:
            return
        self._closed = True
        try:
            atexit.unregister(self.close)
        except Exception:
            pass
        self.stop_motor()
        try:
            card.watchdog_stop()
        except Exception:
            pass
        try:
            self._set_led("red" if self.fault is not None else "blue")
        except Exception:
            pass
        try:
            card.close()
        except Exception:
            pass
        self.card = None

    def warm(self) -> None:
        sensor.wrap.py_func(sensor.theta_to_raw.py_func(0.0, self._ts, self._tb))

    def counters(self) -> dict:
        return {"board": self.board_type, "watchdog_s": self.timeout,
                "watchdog_reloads": self.reloads, "board_fault": self.fault}


def _message(exc) -> str:
    get = getattr(exc, "get_error_message", None)
    try:
        return get() if get is not None else str(exc)
    except Exception:
        return str(exc)
