r"""Conversion between the rig's raw ADC/DAC values and SI units (App. B, Sec. 2.1).

.. math::

    \theta = s_\theta(y + b_\theta),\quad \Omega = s_\Omega(x - x_0),\quad
    \dot\Omega = s_v(v + b_v),\quad u_{DA} = k_u\,u

with App. B.5's values :math:`s_\theta = \pi`, :math:`b_\theta = 0.503`,
:math:`s_\Omega = 25.8`, :math:`s_v = 28.7`, :math:`b_v = 0.02`,
:math:`k_u = -0.022` as the defaults of the ``rig.*`` configuration keys
(:class:`RigScaling`).

**Sign convention.** The biases are *added* to the raw reading before
scaling, as in the thesis's formulas: the upright pendulum reads
:math:`y = -b_\theta` (the thesis measured -0.503, so ``rig.theta_bias`` is
+0.503), the resting arm reads :math:`v = -b_v`.  ``rig.u_scale`` is the
signed DAC value per m/s^2 of u; it is negative on the thesis's rig (a
positive u is a negative DAC voltage).  The arm's :math:`x_0` is not a
parameter: it is the arm reading when control starts.

All raw values live in [-1, 1].  The DAC saturates there, so the largest
control signal is :math:`|u| \le 1/|k_u|` (45.5 m/s^2 by default).  The pendulum
angle and arm position channels *wrap*: passing 1 the reading jumps to -1
(App. B.1-B.2); :func:`wrap_raw` reproduces that and :func:`unwrap_raw`
undoes it sample to sample.  The rig's converters have 12 bits
(:data:`ADC_BITS`); :func:`quantize` rounds a raw value to that grid.

Raw units appear only at the I/O edge (rig backends); everything else in the
package works in SI units.  On an emulated rig (``frictionlab rig-sim``, the
``sim`` backend) the ``rig.*`` values are the rig's *true* factors; on the
controller's side they are its calibration, so running the two with different
values is a calibration error the controller does not know about.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import sensor as _S
from .params import ParamError, Validated, check_range, param
from .sensor import ADC_BITS, ADC_STEP, quantize

__all__ = [
    "ADC_BITS",
    "MOTOR_VELOCITY_SCALE",
    "RigScaling",
    "motor_rig",
    "quantize",
    "unwrap_raw",
    "wrap_raw",
]


@dataclass(frozen=True)
class RigScaling(Validated):
    """Scale factors and biases of App. B (B.5 summary), keys ``rig.*``.

    See the module docstring for the sign convention.  ``arm_bias`` (the
    thesis's :math:`x_0`) is not a configuration key: the real-time loop takes
    it from the first arm reading of a run.
    """

    _prefix = "rig."

    theta_scale: float = param(math.pi, "pendulum angle per ADC unit: theta = "
                               "theta_scale*(y + theta_bias) (App. B.1)", "rad",
                               lo=0.0, hi=100.0, lo_open=True)
    theta_bias: float = param(0.503, "added to the pendulum reading y before scaling "
                              "(the upright pendulum reads y = -theta_bias; App. B.1)", "1",
                              lo=-1.0, hi=1.0)
    arm_scale: float = param(25.8, "arm angle per ADC unit: Omega = arm_scale*(x - x_0) "
                             "(App. B.2)", "rad", lo=0.0, hi=1000.0, lo_open=True)
    velocity_scale: float = param(28.7, "arm velocity per ADC unit: Omega_dot = "
                                  "velocity_scale*(v + velocity_bias) (App. B.3)", "rad/s",
                                  lo=0.0, hi=1000.0, lo_open=True)
    velocity_bias: float = param(0.02, "added to the arm-velocity reading v before scaling "
                                 "(the resting arm reads v = -velocity_bias; App. B.3)", "1",
                                 lo=-1.0, hi=1.0)
    u_scale: float = param(-0.022, "k_u: signed DAC value per unit of u (m/s^2; a volt on a "
                           "motor plant: 1/voltage limit), u_DA = u_scale*u (App. B.4; "
                           "negative on the thesis's rig; not 0)", "1/(m/s^2)",
                           lo=-1.0, hi=1.0)
    arm_sign: int = param(1, "direction of the arm encoder against the arm angle Omega "
                          "(encoder rigs, e.g. the QUBE-Servo: +1 as the maker wires it, "
                          "-1 for an encoder counting the other way)", "1", lo=-1, hi=1,
                          integer=True)
    pendulum_sign: int = param(1, "direction of the pendulum encoder against theta (encoder "
                               "rigs, e.g. the QUBE-Servo: +1 as the maker wires it, -1 for "
                               "an encoder counting the other way)", "1", lo=-1, hi=1,
                               integer=True)
    arm_bias: float = 0.0  # x_0 (not a key): arm reading at Omega = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.u_scale == 0.0:
            raise ParamError("rig.u_scale", 0.0, "[-1, 1] without 0",
                             "rig.u_scale = 0 would give the motor no control signal; "
                             "allowed [-1, 1] without 0")
        for key in ("arm_sign", "pendulum_sign"):
            if getattr(self, key) == 0:
                raise ParamError(f"rig.{key}", 0, "+1 or -1",
                                 f"rig.{key} = 0: the sign must be +1 or -1")
        b = check_range("arm_bias", self.arm_bias, -1.0, 1.0)
        object.__setattr__(self, "arm_bias", b)

    # --- raw -> SI (the laws of frictionlab.model.sensor, element-wise) ------------
    def theta(self, y):
        """Pendulum angle (rad) from the raw reading y."""
        return _S.theta_from_raw.py_func(np.asarray(y, dtype=float), self.theta_scale,
                                         self.theta_bias)

    def arm(self, x):
        """Arm angle (rad) from the raw reading x (unwrapped)."""
        return _S.arm_from_raw.py_func(np.asarray(x, dtype=float), self.arm_bias,
                                       self.arm_scale)

    def arm_velocity(self, v):
        """Arm velocity (rad/s) from the raw reading v."""
        return _S.velocity_from_raw.py_func(np.asarray(v, dtype=float), self.velocity_scale,
                                            self.velocity_bias)

    def u_da(self, u):
        """DAC value for the control signal u (m/s^2), saturated at [-1, 1]
        (:func:`frictionlab.model.sensor.dac`, element-wise)."""
        return _elementwise(_S.dac.py_func, u, self.u_scale)

    # --- SI -> raw (the emulated rig) -------------------------------------
    def raw_theta(self, theta):
        """Raw pendulum reading for angle theta (wrapped into [-1, 1))."""
        return wrap_raw(_S.theta_to_raw.py_func(np.asarray(theta, dtype=float),
                                                self.theta_scale, self.theta_bias))

    def raw_arm(self, arm):
        """Raw arm reading for angle Omega (wrapped into [-1, 1))."""
        return wrap_raw(_S.arm_to_raw.py_func(np.asarray(arm, dtype=float), self.arm_scale,
                                              self.arm_bias))

    def raw_arm_velocity(self, arm_dot):
        """Raw velocity reading (clipped to the ADC range [-1, 1])."""
        return np.clip(_S.velocity_to_raw.py_func(np.asarray(arm_dot, dtype=float),
                                                  self.velocity_scale, self.velocity_bias),
                       -1.0, 1.0)

    def u_from_da(self, u_da):
        """Control signal (m/s^2) the DAC value corresponds to
        (:func:`frictionlab.model.sensor.u_from_dac`, element-wise)."""
        return _elementwise(_S.u_from_dac.py_func, u_da, self.u_scale)

    @property
    def u_max(self) -> float:
        """Largest |u| the DAC can express (m/s^2)."""
        return 1.0 / abs(self.u_scale)

    def quanta(self) -> tuple[float, float, float]:
        """SI size of one ADC step for (theta, Omega, Omega_dot)."""
        q = ADC_STEP
        return self.theta_scale * q, self.arm_scale * q, self.velocity_scale * q


#: ``rig.velocity_scale`` of a motor rig: the tachometer channel's full scale (rad/s).
MOTOR_VELOCITY_SCALE = 50.0


def motor_rig(voltage_limit: float) -> RigScaling:
    r"""The ``rig.*`` defaults of a motor plant (an encoder rig: the QUBE-Servo, a
    home-built rig): u in volts, the angles from encoders.

    * The DAC: :math:`u_{DA} = \mathrm{sat}(u / V_{max})`, ``u_scale`` =
      1/``voltage_limit`` (0.1 per volt on a QUBE: u_DA = 1 is the amplifier's
      full 10 V; at most 1 per volt).
    * The angles: ``theta_scale`` = ``arm_scale`` = :math:`\pi`: the raw
      channel spans one turn; ``theta_bias`` 0.5 puts its wrap a quarter turn
      from both upright (y = -0.5) and hanging (y = 0.5): the pendulum angle is
      read in :math:`[-\pi/2, 3\pi/2)`, continuous through both (a swing about
      hanging, the free oscillation of App. A, does not wrap).  The converter
      is the encoder (:func:`frictionlab.model.sensor.encoder_step`,
      ``Config.sensor_step``).
    * The arm rate (the QUBE's tachometer): ``velocity_scale`` =
      :data:`MOTOR_VELOCITY_SCALE` rad/s full scale, no bias.
    """
    return RigScaling(theta_scale=math.pi, theta_bias=0.5, arm_scale=math.pi,
                      velocity_scale=MOTOR_VELOCITY_SCALE, velocity_bias=0.0,
                      u_scale=min(1.0, 1.0 / float(voltage_limit)))


def _elementwise(law, values, u_scale):
    """``law(value, u_scale)`` for each of ``values`` (a scalar gives a numpy scalar)."""
    a = np.asarray(values, dtype=float)
    out = np.empty_like(a)
    flat = out.reshape(-1)
    for i, v in enumerate(a.reshape(-1).tolist()):
        flat[i] = law(v, u_scale)
    return out[()] if out.ndim == 0 else out


def wrap_raw(r):
    """Wrap raw values into [-1, 1) like the pendulum and arm channels
    (:func:`frictionlab.model.sensor.wrap`)."""
    return _S.wrap.py_func(np.asarray(r, dtype=float))


def unwrap_raw(previous: float, current: float) -> float:
    """Undo a wrap between two consecutive raw samples (jumps of more than 1;
    :func:`frictionlab.model.sensor.unwrap`)."""
    return current + 2.0 * _S.unwrap.py_func(previous, current, 0)
