r"""The sensor model: the rig's converters and measurement noise (App. B, Sec. 2.1).

One law, many runners: the simulator (compiled), the in-process rig and
``frictionlab rig-sim`` (the emulated rig's ADC), the identification
experiments' recorder and the real-time loop (raw to SI) all measure through
the functions of this module.

What a measurement is
---------------------
For a true state :math:`(\theta, \Omega, \dot\Omega)` and sample number
:math:`n`:

1. **noise**: Gaussian noise of standard deviation ``sim.noise`` is added to
   each signal in its SI unit (:func:`noise`, channel 0, 1, 2);
2. **to raw** (the rig's side, App. B.5 inverted):
   :math:`y = \theta/s_\theta - b_\theta`, :math:`x = \Omega/s_\Omega + x_{off}`,
   :math:`v = \dot\Omega/s_v - b_v` (:func:`theta_to_raw`, :func:`arm_to_raw`,
   :func:`velocity_to_raw`), where :math:`x_{off}` is the arm's raw reading
   at :math:`\Omega = 0` (:data:`ARM_START`, App. B.2's measured
   :math:`x_0`);
3. **the converter**: each raw value is rounded to the 12-bit grid of
   :math:`2/4096` (:func:`quantize`) *in raw units, bias included*; the
   pendulum and arm channels wrap into [-1, 1) (:func:`wrap`), the velocity
   channel clips to [-1, 1 - step] (its largest code);
4. **to SI** (the controller's side, App. B.5): :math:`\theta = s_\theta(y +
   b_\theta)`, :math:`\Omega = s_\Omega(x - x_0)` with :math:`x_0` the first
   arm reading and the arm channel unwrapped sample to sample
   (:func:`unwrap`), :math:`\dot\Omega = s_v(v + b_v)`.

The actuator's side is one law too: the DAC value of a control signal u is
:math:`u_{DA} = \mathrm{sat}(k_u u)`, saturated to [-1, 1] (App. B.4,
:func:`dac`), and a rig applies the control signal
:math:`\mathrm{sat}(u_{DA})/k_u` (:func:`u_from_dac`; a value that is not a
number counts as 0).  The real-time loop writes :func:`dac`, the emulated
rigs apply :func:`u_from_dac`, :class:`~frictionlab.model.rig.RigScaling`
converts arrays with both.  An angle is wrapped into
:math:`[-\pi, \pi)` by :func:`wrap_angle` (the swing-up's angles, a
pendulum's deflection from its rest).

The rig emulators do 1-3 (:func:`adc`), the real-time loop 4; the simulator
does 1-4 in one call (:func:`measure`) and so reads, for the same true state,
sample number and seed, exactly what the loop reads from an emulated rig
(12-bit values are exact in the protocol's float32, and wrap/unwrap are exact
on the grid).  An *ideal* sensor (``sim.quantization = 0``: step 0) has no
converter: the simulator then measures the true signal plus noise (the arm
relative to its first reading), which is what 1-4 give up to rounding.

The noise stream
----------------
:func:`noise` is counter based: the value for (seed, sample n, channel c) is
a fixed function of the three (SplitMix64 hashing, Box-Muller), so it needs
no generator state, is the same in compiled and plain Python code, and a
simulation split into chunks draws exactly what an unsplit one does.

Each function is a compiled kernel (:func:`frictionlab.model._jit.jit`);
``f.py_func`` is the same law as plain Python, which also works element-wise
on numpy arrays for the conversions (used by :class:`~frictionlab.model.rig.RigScaling`
and by the real-time loop, where calling it costs less than a dispatch).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._jit import jit

__all__ = [
    "ADC_BITS",
    "ADC_STEP",
    "ARM_START",
    "SensorParams",
    "adc",
    "arm_from_raw",
    "arm_to_raw",
    "arm_zero",
    "dac",
    "encoder_step",
    "from_raw",
    "ideal_reading",
    "measure",
    "noise",
    "quantize",
    "reading",
    "sensor_params",
    "sensor_record",
    "theta_from_raw",
    "theta_to_raw",
    "to_raw",
    "u_from_dac",
    "unwrap",
    "velocity_from_raw",
    "velocity_to_raw",
    "wrap",
    "wrap_angle",
]

#: Bits of the rig's converters.
ADC_BITS = 12
#: One ADC step in raw units (the range [-1, 1] in 2**ADC_BITS codes).
ADC_STEP = 2.0 / 2**ADC_BITS
#: Raw arm reading at Omega = 0 of an emulated rig (App. B.2's measured x_0).
ARM_START = -0.0699


class SensorParams(NamedTuple):
    """Everything a measurement needs (a typed record the compiled code accepts).

    Attributes
    ----------
    theta_scale, theta_bias, arm_scale, velocity_scale, velocity_bias : float
        App. B.5 factors (``rig.*``; see :mod:`frictionlab.model.rig` for the signs).
    arm_offset : float
        Raw arm reading at Omega = 0 (the rig's side; :data:`ARM_START`).
    step : float
        Raw grid (:data:`ADC_STEP`), or 0 for an ideal sensor.
    noise : float
        Standard deviation of the noise on each signal in its SI unit (rad,
        rad, rad/s).
    seed : int
        Seed of the noise stream.
    """

    theta_scale: float
    theta_bias: float
    arm_scale: float
    velocity_scale: float
    velocity_bias: float
    arm_offset: float
    step: float
    noise: float
    seed: int


@jit
def sensor_record(row):
    """The :class:`SensorParams` stored as the float row ``np.array(record, dtype=float)``
    (a batch's row; the seed is whole)."""
    return SensorParams(row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7],
                        int(row[8]))


def sensor_params(rig, quantization: float = 1.0, noise: float = 0.0, seed: int = 0,
                  arm_offset: float = ARM_START, step: float = ADC_STEP) -> SensorParams:
    """The :class:`SensorParams` of a rig (``rig`` a :class:`~frictionlab.model.rig.RigScaling`),
    ``quantization`` 1 (the converter's grid ``step``: the 12-bit :data:`ADC_STEP`, or
    an encoder's, :func:`encoder_step`) or 0 (ideal), ``sim.noise`` and ``sim.seed``."""
    return SensorParams(float(rig.theta_scale), float(rig.theta_bias), float(rig.arm_scale),
                        float(rig.velocity_scale), float(rig.velocity_bias),
                        float(arm_offset), float(step) if quantization else 0.0, float(noise),
                        int(seed))


def encoder_step(counts: int, scale: float) -> float:
    r"""The raw grid of an encoder of ``counts`` per turn read on a channel of
    ``scale`` rad per raw unit (``rig.theta_scale``): one count,
    :math:`2\pi/(counts\cdot scale)` (2/2048 for a QUBE's 2048 counts at
    :math:`\pi`).  A motor rig's converter: the grid of its three raw channels
    (the tachometer's step is then ``rig.velocity_scale`` times it)."""
    return 2.0 * math.pi / (int(counts) * float(scale))


# --- App. B.5 both ways (plain arithmetic: scalars and arrays) ---------------------


@jit
def from_raw(r, scale, bias):
    """SI value of a biased channel's raw reading ``r``: ``scale (r + bias)``
    (App. B.5; the pendulum angle and the arm velocity)."""
    return scale * (r + bias)


@jit
def to_raw(value, scale, bias):
    """Raw reading (unwrapped, unclipped) of a biased channel for the SI ``value``:
    the inverse of :func:`from_raw`."""
    return value / scale - bias


#: Pendulum angle (rad) from its raw reading, and back (App. B.5).
theta_from_raw = from_raw
theta_to_raw = to_raw
#: Arm velocity (rad/s) from its raw reading, and back (App. B.5).
velocity_from_raw = from_raw
velocity_to_raw = to_raw


@jit
def arm_from_raw(x, x0, scale):
    """Arm angle (rad) from the unwrapped raw reading ``x``: ``scale (x - x0)``."""
    return scale * (x - x0)


@jit
def arm_to_raw(arm, scale, offset):
    """Raw arm reading (unwrapped) for the arm angle, ``offset`` the reading at 0."""
    return arm / scale + offset


@jit
def wrap(r):
    """Wrap a raw value into [-1, 1) like the pendulum and arm channels."""
    return (r + 1.0) % 2.0 - 1.0


@jit
def unwrap(previous, current, wraps):
    """Wrap count after the raw arm reading ``current`` followed ``previous``
    (a jump of more than 1 is a wrap); the unwrapped reading is
    ``current + 2 * wraps``."""
    d = current - previous
    if d > 1.0:
        return wraps - 1
    if d < -1.0:
        return wraps + 1
    return wraps


@jit
def wrap_angle(a):
    """The angle ``a`` (rad) wrapped into [-pi, pi) (element-wise on arrays as
    ``wrap_angle.py_func``)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@jit
def dac(u, u_scale):
    """The DAC value :math:`u_{DA} = \\mathrm{sat}(k_u u)` of the control signal ``u``
    (m/s^2), ``u_scale`` the signed :math:`k_u` (``rig.u_scale``; App. B.4):
    saturated to [-1, 1]; a value that is not a number gives 0 (the motor off).
    ``dac(u_da, 1.0)`` is what the DAC makes of a value it is sent."""
    d = u_scale * u
    if d > 1.0:
        return 1.0
    if d < -1.0:
        return -1.0
    if d == d:
        return d
    return 0.0


@jit
def u_from_dac(u_da, u_scale):
    """The control signal (m/s^2) a rig applies for the DAC value ``u_da``: the
    inverse of :func:`dac` on the DAC's range (saturated first)."""
    return dac(u_da, 1.0) / u_scale


@jit
def quantize(value, step):
    """Round ``value`` to a multiple of ``step`` (``step <= 0``: unchanged)."""
    if step <= 0.0:
        return value
    return np.floor(value / step + 0.5) * step


# --- the noise stream --------------------------------------------------------------

_GOLDEN = 0x9E3779B97F4A7C15
_M1 = 0xBF58476D1CE4E5B9
_M2 = 0x94D049BB133111EB


@jit
def _mix(z):
    """SplitMix64's finaliser (uint64 in, uint64 out)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(_M1)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(_M2)
    return z ^ (z >> np.uint64(31))


@jit
def noise(seed, n, c):
    """Standard normal value number ``c`` (0, 1, 2: theta, Omega, Omega_dot) of sample
    ``n`` of the stream ``seed`` (a fixed function of the three, see the module
    docstring)."""
    base = _mix(np.uint64(seed) + np.uint64(_GOLDEN))
    k = np.uint64(6) * np.uint64(n) + np.uint64(2) * np.uint64(c)
    h1 = _mix(base + (k + np.uint64(1)) * np.uint64(_GOLDEN))
    h2 = _mix(base + (k + np.uint64(2)) * np.uint64(_GOLDEN))
    u1 = (float(h1 >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)
    u2 = float(h2 >> np.uint64(11)) * (1.0 / 9007199254740992.0)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


# --- the two sides of the converter -------------------------------------------------


@jit
def _raw(sp, theta, arm, arm_dot):
    """Quantised raw values, pendulum wrapped, arm *unwrapped*, velocity clipped."""
    q = sp.step
    y = wrap(quantize(theta_to_raw(theta, sp.theta_scale, sp.theta_bias), q))
    x = quantize(arm_to_raw(arm, sp.arm_scale, sp.arm_offset), q)
    v = quantize(velocity_to_raw(arm_dot, sp.velocity_scale, sp.velocity_bias), q)
    top = 1.0 - q
    v = min(max(v, -1.0), top)
    return y, x, v


@jit
def adc(sp, theta, arm, arm_dot, n):
    """What the rig's converters send for the true signals at sample ``n``:
    raw ``(y, x, v)``, noisy, on the grid, wrapped / clipped into [-1, 1]."""
    if sp.noise > 0.0:
        theta += sp.noise * noise(sp.seed, n, 0)
        arm += sp.noise * noise(sp.seed, n, 1)
        arm_dot += sp.noise * noise(sp.seed, n, 2)
    y, x, v = _raw(sp, theta, arm, arm_dot)
    return y, wrap(x), v


@jit
def reading(sp, theta, arm, arm_dot, first, x0):
    """The SI reading ``(theta_m, arm_m, arm_dot_m, x0)`` of signals that already
    carry their noise (steps 2-4 of the module docstring; ``first``: take the
    arm's zero ``x0`` from this sample, else use the one given)."""
    if sp.step > 0.0:
        y, x, v = _raw(sp, theta, arm, arm_dot)
        if first:
            x0 = x
        return (theta_from_raw(y, sp.theta_scale, sp.theta_bias),
                arm_from_raw(x, x0, sp.arm_scale),
                velocity_from_raw(v, sp.velocity_scale, sp.velocity_bias), x0)
    return ideal_reading(theta, arm, arm_dot, first, x0)


@jit
def ideal_reading(theta, arm, arm_dot, first, x0):
    """The SI reading ``(theta_m, arm_m, arm_dot_m, x0)`` of an ideal sensor (no
    converter, ``sp.step == 0``): the signals as they are, the arm relative to
    its first reading ``x0`` (taken from this sample when ``first``).  What
    :func:`reading` and, without noise, :func:`measure` return for such a sensor."""
    if first:
        x0 = arm
    return theta, arm - x0, arm_dot, x0


@jit
def measure(sp, theta, arm, arm_dot, n, x0):
    """The measured ``(theta_m, arm_m, arm_dot_m, x0)`` in SI units at sample ``n``.

    ``x0`` is the first arm reading (the loop's zero of the arm; taken at
    ``n == 0`` and returned, pass it back on later samples).  With a converter
    (``sp.step > 0``) this is :func:`adc` followed by the loop's conversion,
    bit for bit; an ideal sensor returns the true signals plus noise (the arm
    relative to its first reading).
    """
    if sp.noise > 0.0:
        theta += sp.noise * noise(sp.seed, n, 0)
        arm += sp.noise * noise(sp.seed, n, 1)
        arm_dot += sp.noise * noise(sp.seed, n, 2)
    return reading(sp, theta, arm, arm_dot, n == 0, x0)


def arm_zero(sp: SensorParams) -> float:
    """The arm's zero ``x0`` of a noise-free start at Omega = 0 (what :func:`measure`
    takes at sample 0), for runs that start from a given state."""
    if sp.step > 0.0:
        return float(quantize(arm_to_raw(0.0, sp.arm_scale, sp.arm_offset), sp.step))
    return 0.0
