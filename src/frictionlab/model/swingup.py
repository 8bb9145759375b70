r"""Swing-up: from hanging to balancing by energy control, then the balancing controller.

The thesis's rig had to be balanced by hand before the controller started
(Sec. 8 names a swing-up as the natural extension).  This module adds one,
in the same explicit-state form as the balancing controller
(:mod:`frictionlab.model.controller`): the compiled :func:`swingup_step` runs in
the simulator (:func:`simulate_swingup`) and in the 200 Hz loop alike.

Energy control (Astrom and Furuta 2000) with this plant's input
-----------------------------------------------------------------
Without damping and with the arm at rest, eq. (6) reads
:math:`\ddot\theta = \omega_0^2\sin\theta - (\omega_0^2/g)\,a\cos\theta`, with
a the net arm-tip acceleration.  The pendulum's normalised energy

.. math::

    E = \tfrac12(\dot\theta/\omega_0)^2 + \cos\theta - 1

is 0 upright at rest and -2 hanging at rest.  Its rate of change is

.. math::

    \dot E = \dot\theta\ddot\theta/\omega_0^2 - \dot\theta\sin\theta
           = -\frac{a}{g}\,\dot\theta\cos\theta ,

so the law

.. math::

    u = \mathrm{sat}_{u_s}\bigl(k\,(E - E_0)\,\mathrm{sign}(\dot\theta\cos\theta)\bigr)

gives :math:`\dot E = -(k/g)(E - E_0)|\dot\theta\cos\theta| \le 0` when
:math:`E > E_0` and :math:`\ge 0` when :math:`E < E_0` (before saturation and
friction; with saturation the sign is the same).  The positive sign in front of
k is therefore the one that drives E to :math:`E_0` with this package's
conventions (u positive accelerates the arm positively; theta positive
clockwise as in eq. 6, where u enters with a minus sign).
``sign(0)`` is taken as +1, so a pendulum hanging exactly at rest is kicked.

The command is

.. math::

    u = \mathrm{sat}_{u_s}\bigl((1 - c)^b\,(u_E + F_m\,\mathrm{sign}\,u_E)
        - k_p\Omega - (k_d + k_b c)\dot\Omega\bigr), \qquad c = \max(\cos\theta, 0),

with :math:`u_E` the energy law above (its target :math:`E_t`, see below),
:math:`F_m` the friction margin (``swingup.friction_margin``, or the
compensator's Coulomb level when larger: the arm slides when the law asks,
instead of sticking below the stiction level near the target), the fade
:math:`(1-c)^b` (``swingup.blend``: pumping in the lower half, where it acts),
the arm-centring gains :math:`k_p, k_d` (``swingup.arm_stiffness``,
``swingup.arm_damping``) and the brake :math:`k_b` (``swingup.arm_brake``)
that stops the arm as the pendulum nears upright.  :math:`u_s` is the
smallest of ``swingup.max_acceleration`` and the balancing controller's
saturation (``controller.u_max`` within the DAC's range).

The angular velocity comes from a nonlinear observer on the full model
(:math:`\ddot\theta` of eq. 6 with the design's omega_0, the applied u and
the measured arm velocity), a predictor-corrector at h with both error poles
at :math:`e^{-\omega_s h}` (``swingup.observer_omega``); the linear
balancing observers are only valid near upright.  Angles are wrapped into
[-pi, pi) (the rig's angle channel wraps, App. B.1).

The energy target, swing by swing
---------------------------------
:math:`E_t` starts at ``swingup.energy_target`` and is corrected
(:func:`target_correction`, gain ``swingup.energy_adapt``) whenever the
pendulum leaves the upper half (:math:`\cos\theta > 0`) without a catch: up by
:math:`\cos(\theta_c/2) - \cos\theta_{apex}` after a swing that turned back (at
the apex :math:`\dot\theta = 0`, so its height measures the energy whatever
the plant's omega_0, which the design only assumes), down by the energy over
the top plus :math:`1 - \cos(\theta_c/2)` after one that passed over;
:math:`\theta_c` is ``swingup.catch_angle``.

Hand-over
---------
The balancing controller takes over when the measured angle is in the catch
region (``|theta| < swingup.catch_angle``) and its command, predicted on the
linearised plant (eq. 7, no friction) under its state feedback from the
current state (:func:`predicted_peak`), stays within
``swingup.catch_fraction`` of its saturation for ``swingup.catch_horizon``:
a pendulum arriving fast, or with the arm moving, goes on swinging.  With a
compensator on, its stiction level (or Coulomb level, if larger) is added to
the prediction: at the arm's breakaway after the catch the compensator adds
about that much (its LuGre observer more) to the feedback's command.  The
balancing observers start from the current measurement (theta, the swing-up
observer's theta_dot, the arm at its current position with the measured
velocity).  The arm's reference is the position where it was caught (an
offset subtracted from the arm angle); once balancing it returns to 0
exponentially with the time constant ``swingup.recentre_time``.  A catch
that fails (``|theta| > swingup.release_angle`` before
``swingup.settle_time`` has passed) returns to swinging; one that holds for
``settle_time`` is *balancing*, after which the usual falls and angle limits
apply.

Friction
--------
The arm bearing's friction (any plant model, present throughout) eats into
the net acceleration :math:`a = u - F`; the margin :math:`F_m` puts a level
back in the direction the law asks for, and the target correction makes up
for what is left (and for the pendulum's damping).  docs/swingup.md maps the
success rate over friction levels and plant mismatch on a 10 m/s^2 actuator.

The DC-motor plant
------------------
On the DC-motor plant (:mod:`frictionlab.model.plants.furuta_dc`, u in volts)
the same law runs on the arm tip's acceleration and the motor voltage
realises it: the command above, before the friction margin, is the arm tip's
acceleration a (m/s^2, within ``swingup.max_acceleration``), and the voltage
is the plant's inverse arm dynamics at the current state
(:func:`~frictionlab.model.plants.furuta_dc.arm_voltage` with
:math:`\ddot\phi = a/L_r`: back-EMF, the coupling and the pendulum's
reaction included), plus the faded margin :math:`F_m` in volts, saturated
at the controller's limit (``controller.u_max`` within
``plant.voltage_limit``).  The pendulum's equation of the full model,
:math:`J_p\ddot\theta = c\sin\theta - b\cos\theta\,\ddot\phi + \dots`,
is eq. (6)'s with :math:`\omega_0^2 = c/J_p` and :math:`a = L_r\ddot\phi`,
so E is the pendulum's energy normalised by :math:`c` with that
:math:`\omega_0` (:func:`dc_omega0`; 10.68 rad/s for the QUBE-Servo 2) and
:math:`\dot E = -(a/g)\dot\theta\cos\theta` as above, up to the
centrifugal term :math:`J_p\sin\theta\cos\theta\dot\phi^2`.  The
swing-up observer predicts with the coupled model at the applied voltage
(:func:`~frictionlab.model.plants.furuta_dc.dc_accelerations`), and the
hand-over test with the design's discretised linearisation
(:func:`~frictionlab.model.plants.furuta_dc_design.dc_predicted_peak`).
Where the voltage cannot give the acceleration asked for (the QUBE's
:math:`a_{max}/g` = 0.81 < 4/3) it saturates, and the pendulum gains its
energy over several swings.

Safety (the same checks in the simulator and the loop)
------------------------------------------------------
Every tick checks ``|Omega| <= swingup.arm_limit`` (stop code
``arm_travel``), ``|Omega'| <= swingup.arm_speed_limit`` (``arm_speed``) and,
until balancing, the elapsed time against ``swingup.time_limit``
(``not_caught``); a stop sets the phase to ``stopped`` and u = 0 from then on.

Typed records
-------------
The compiled step reads its settings from :class:`SwingUpRecord` (a
``NamedTuple``, built by :meth:`SwingUpParams.record` for the design's
omega_0, g and h) and updates the working state in place: a numpy structured
record of float64 fields, :data:`SWING_DTYPE`, read and set by field name
(``w.phase``) in compiled code and in Python.

====  =================  =====================================================
pos   field              meaning
====  =================  =====================================================
0     ``phase``          0 swinging, 1 caught, 2 balancing, 3 stopped (:data:`PHASES`)
1     ``tick``           ticks since the start
2     ``phase_ticks``    ticks in the current phase
3     ``theta_hat``      swing-up observer angle (rad, wrapped)
4     ``theta_dot_hat``  swing-up observer angular velocity (rad/s)
5     ``arm_offset``     arm reference offset after a catch (rad)
6     ``energy``         normalised energy E of the estimates
7     ``stop``           stop code (0 none, 1 not_caught, 2 arm_travel, 3 arm_speed;
                         :data:`STOP_CODES`)
8     ``catch_tick``     tick of the last catch (-1: none)
9     ``u``              last applied u (m/s^2)
10    ``catches``        number of catches so far
11    ``target``         energy target E_t (:func:`target_correction`)
12    ``side``           sign of theta when the swing entered the upper half (0: not there)
13    ``top``            largest cos(theta) of that swing
14    ``top_energy``     E where cos(theta) was largest
15    ``crossed``        1 when that swing passed over the top
====  =================  =====================================================

A caller in Python at every tick (the 200 Hz loop) keeps the state as a float
vector (:func:`swing_vector`; positions :func:`swing_index`) and the settings
as a float row (:func:`swingup_row`), and calls :func:`swingup_step_rows`,
which views them as the records inside the compiled code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ._jit import jit, jit_inline
from .controller import (
    Controller,
    Gains,
    controller_step,
    copy_state,
    gains_record,
    new_state,
    state_view,
    zero_state,
)
from .friction import friction_view
from .params import Validated, param
from .plants.furuta_dc import DCRecord, FurutaDCParams, arm_voltage, dc_accelerations
from .plants.furuta_dc_design import DCDesign, dc_predicted_peak
from .records import copy_record, float_record_dtype, new_record, record_row, row_record
from .sensor import wrap_angle

__all__ = [
    "DC_PLANT",
    "PHASES",
    "STOP_CODES",
    "SWING_DTYPE",
    "SWING_FIELDS",
    "SwingUp",
    "SwingUpParams",
    "SwingUpRecord",
    "copy_swing_state",
    "dc_omega0",
    "energy",
    "new_swing_state",
    "predicted_peak",
    "swing_index",
    "swing_record",
    "swing_vector",
    "swing_view",
    "swingup_record",
    "swingup_row",
    "swingup_step",
    "swingup_step_rows",
    "target_correction",
    "wrap_angle",
]

SWINGING, CAUGHT, BALANCING, STOPPED = 0, 1, 2, 3
#: Phase names by code.
PHASES = ("swinging", "caught", "balancing", "stopped")
#: Stop reasons by code (0: not stopped).
STOP_CODES = ("", "not_caught", "arm_travel", "arm_speed")

#: Fields of the swing-up state, in their storage order (module table).
SWING_FIELDS = ("phase", "tick", "phase_ticks", "theta_hat", "theta_dot_hat", "arm_offset",
                "energy", "stop", "catch_tick", "u", "catches", "target", "side", "top",
                "top_energy", "crossed")
#: The swing-up state's record type: one float64 per field of :data:`SWING_FIELDS`.
SWING_DTYPE = float_record_dtype(SWING_FIELDS)


def new_swing_state(**values: float) -> np.record:
    """A zeroed swing-up state record (fields set from ``values``), backed by
    its own one-element array: compiled code updates it in place."""
    return new_record(SWING_DTYPE, **values)


def copy_swing_state(w) -> np.record:
    """An independent copy of a swing-up state record."""
    return copy_record(w)


def swing_vector(w) -> np.ndarray:
    """The swing-up state as a float vector (fields in :data:`SWING_FIELDS` order)."""
    return record_row(w)


def swing_index(name: str) -> int:
    """Position of field ``name`` in :func:`swing_vector` (and in :func:`swing_view`'s vector)."""
    return SWING_FIELDS.index(name)


def swing_record(x) -> np.record:
    """The swing-up state record stored in the float64 vector ``x``
    (:data:`SWING_FIELDS` order), by reference: setting a field, here or in
    compiled code, writes ``x``.  (Python side of :func:`swing_view`.)"""
    return row_record(x, SWING_DTYPE)


@jit_inline
def swing_view(x):
    """The swing-up state record stored in the float vector ``x`` by reference
    (:func:`swing_record` in compiled code)."""
    return x.view(SWING_DTYPE)[0]


class SwingUpRecord(NamedTuple):
    """What the compiled swing-up step reads besides its state (a typed record;
    :meth:`SwingUpParams.record`).

    Attributes
    ----------
    gain, max_acceleration, energy_target : float
        Energy law k (m/s^2), its |u| limit (m/s^2) and the initial target E0.
    catch_angle, release_angle : float
        Hand-over and failed-catch angles (rad).
    settle_ticks, limit_ticks : float
        ``settle_time`` and ``time_limit`` in ticks (rounded).
    arm_stiffness, arm_damping : float
        Arm-centring gains k_p, k_d.
    l1, l2 : float
        Swing-up observer's correction gains (both poles at exp(-omega_s h)).
    omega0, g_inv, h : float
        The design's omega_0 (rad/s), omega_0^2/g (s^2/m... per m/s^2) and h (s).
    arm_limit, arm_speed_limit : float
        Safety limits on |Omega| (rad) and |Omega'| (rad/s).
    decay : float
        Per-tick factor of the arm reference's return to 0 (0: at once).
    catch_fraction, horizon_ticks : float
        Hand-over: the predicted balancing command within this fraction of its
        saturation for this many ticks (:func:`predicted_peak`).
    friction_margin, arm_brake, blend : float
        :math:`F_m` (m/s^2), :math:`k_b` (m/s^2 per rad/s) and the fade exponent b.
    adapt, apex_cos : float
        Gain of the target's correction and cos(catch_angle / 2).
    plant : float
        The plant the law drives: 0 the thesis's (u an arm-tip acceleration),
        1 the DC-motor plant (u a voltage: :data:`DC_PLANT`).
    arm_length : float
        The DC plant's arm length L_r (m): the law's arm-tip acceleration over
        it is the arm's angular acceleration (0 for the thesis plant).
    dc_j_p, dc_j_0, dc_b, dc_c, dc_kv, dc_k_m, dc_d_r, dc_d_p : float
        The DC plant's model (:class:`~frictionlab.model.plants.furuta_dc.DCRecord`)
        that the observer and the voltage law use (zeros for the thesis plant).
    """

    gain: float
    max_acceleration: float
    catch_angle: float
    release_angle: float
    settle_ticks: float
    limit_ticks: float
    arm_stiffness: float
    arm_damping: float
    l1: float
    l2: float
    energy_target: float
    omega0: float
    g_inv: float
    h: float
    arm_limit: float
    arm_speed_limit: float
    decay: float
    catch_fraction: float
    friction_margin: float
    arm_brake: float
    adapt: float
    apex_cos: float
    blend: float
    horizon_ticks: float
    plant: float = 0.0
    arm_length: float = 0.0
    dc_j_p: float = 0.0
    dc_j_0: float = 0.0
    dc_b: float = 0.0
    dc_c: float = 0.0
    dc_kv: float = 0.0
    dc_k_m: float = 0.0
    dc_d_r: float = 0.0
    dc_d_p: float = 0.0


@jit
def swingup_record(row):
    """The :class:`SwingUpRecord` stored as the float row :func:`swingup_row`."""
    return SwingUpRecord(row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7],
                         row[8], row[9], row[10], row[11], row[12], row[13], row[14], row[15],
                         row[16], row[17], row[18], row[19], row[20], row[21],
                         row[22], row[23], row[24], row[25], row[26], row[27], row[28],
                         row[29], row[30], row[31], row[32], row[33])


#: :attr:`SwingUpRecord.plant` of the DC-motor plant (the thesis plant's is 0).
DC_PLANT = 1.0


@jit_inline
def dc_model(sp):
    """The DC plant's :class:`~frictionlab.model.plants.furuta_dc.DCRecord` that
    the swing-up record ``sp`` carries."""
    return DCRecord(sp.dc_j_p, sp.dc_j_0, sp.dc_b, sp.dc_c, sp.dc_kv, sp.dc_k_m, sp.dc_d_r,
                    sp.dc_d_p)


def swingup_row(rec: SwingUpRecord) -> np.ndarray:
    """The :class:`SwingUpRecord` as the float row :func:`swingup_record` reads back."""
    return np.array(rec, dtype=float)


@dataclass(frozen=True)
class SwingUpParams(Validated):
    """Swing-up settings (keys ``swingup.*``); see the module docstring."""

    _prefix = "swingup."

    gain: float = param(100.0, "energy-control gain k of u = k (E - E0) sign(theta' cos theta)",
                        "m/s^2", lo=0.0, hi=1e4, lo_open=True)
    max_acceleration: float = param(10.0, "|u| limit while swinging", "m/s^2", lo=0.0,
                                    hi=1e3, lo_open=True)
    energy_target: float = param(0.0, "target normalised energy E0 (0 = upright at rest)",
                                 "1", lo=-1.0, hi=2.0)
    catch_angle: float = param(0.3, "hand over to the balancing controller when |theta| is "
                               "below this", "rad", lo=0.0, hi=1.0, lo_open=True)
    release_angle: float = param(0.6, "a catch fails (back to swinging) when |theta| exceeds "
                                 "this before settle_time", "rad", lo=0.0, hi=math.pi,
                                 lo_open=True)
    settle_time: float = param(1.0, "time a catch must hold before the phase is balancing",
                               "s", lo=0.0, hi=60.0)
    time_limit: float = param(20.0, "stop (not_caught) when not balancing after this long",
                              "s", lo=0.0, hi=1e4, lo_open=True)
    arm_stiffness: float = param(2.0, "arm-centring gain k_p on the arm angle while swinging",
                                 "m/s^2/rad", lo=0.0, hi=1e3)
    arm_damping: float = param(1.0, "arm-centring gain k_d on the arm velocity while swinging",
                               "m/s^2/(rad/s)", lo=0.0, hi=1e3)
    recentre_time: float = param(3.0, "time constant of the arm reference's return from the "
                                 "catch position to 0 (0 = at once)", "s", lo=0.0, hi=1e3)
    observer_omega: float = param(80.0, "swing-up angle observer's error pole frequency",
                                  "rad/s", lo=0.0, hi=1e3, lo_open=True)
    arm_limit: float = param(6.0, "stop (arm_travel) when |Omega| exceeds this", "rad",
                             lo=0.0, hi=1e3, lo_open=True)
    arm_speed_limit: float = param(25.0, "stop (arm_speed) when |Omega'| exceeds this",
                                   "rad/s", lo=0.0, hi=1e3, lo_open=True)
    catch_fraction: float = param(0.5, "hand over only when the balancing controller's "
                                  "predicted command stays within this fraction of the |u| "
                                  "limit (controller.u_max, or the DAC's range) for "
                                  "catch_horizon", "1", lo=0.0, hi=1.0, lo_open=True)
    catch_horizon: float = param(0.5, "how far ahead the hand-over test predicts the "
                                 "balancing controller's command (linear, no friction)", "s",
                                 lo=0.0, hi=5.0)
    friction_margin: float = param(3.0, "arm friction level added to the energy law's "
                                   "command in its direction (the compensator's Coulomb "
                                   "level instead when compensation is on)", "units of u",
                                   lo=0.0, hi=1e3)
    arm_brake: float = param(8.0, "extra arm damping in the upper half, k_b cos(theta) on "
                             "Omega', so that the arm is near rest when the pendulum arrives",
                             "m/s^2/(rad/s)", lo=0.0, hi=1e3)
    blend: float = param(1.0, "the energy law is weighted by (1 - max(cos theta, 0))^blend: "
                         "full in the lower half, fading out towards upright (0 = no fade)",
                         "1", lo=0.0, hi=10.0)
    energy_adapt: float = param(0.5, "gain of the target's correction after each swing "
                                "into the upper half that falls short of or passes over the "
                                "catch region (0 = a fixed target)", "1", lo=0.0, hi=2.0)

    def record(self, omega0: float, g: float, h: float,
               dc: FurutaDCParams | None = None) -> SwingUpRecord:
        """The :class:`SwingUpRecord` for :func:`swingup_step` (design omega_0, g and h).

        With ``dc`` (the DC-motor plant's parameters as the design knows them)
        the law drives that plant in volts (module docstring, "The DC-motor
        plant"); ``omega0`` and ``g`` are then the pendulum's own
        :func:`dc_omega0` and the plant's g.
        """
        pole = math.exp(-self.observer_omega * h)
        extra = {}
        if dc is not None:
            extra = dict(zip(("dc_j_p", "dc_j_0", "dc_b", "dc_c", "dc_kv", "dc_k_m", "dc_d_r",
                              "dc_d_p"), (float(v) for v in dc.record()), strict=True))
            extra.update(plant=DC_PLANT, arm_length=float(dc.arm_length))
        return SwingUpRecord(
            gain=float(self.gain),
            max_acceleration=float(self.max_acceleration),
            catch_angle=float(self.catch_angle),
            release_angle=float(self.release_angle),
            settle_ticks=float(round(self.settle_time / h)),
            limit_ticks=float(round(self.time_limit / h)),
            arm_stiffness=float(self.arm_stiffness),
            arm_damping=float(self.arm_damping),
            l1=1.0 - pole * pole,
            l2=(1.0 - pole) ** 2 / h,
            energy_target=float(self.energy_target),
            omega0=float(omega0),
            g_inv=float(omega0 * omega0 / g),
            h=float(h),
            arm_limit=float(self.arm_limit),
            arm_speed_limit=float(self.arm_speed_limit),
            decay=0.0 if self.recentre_time == 0 else math.exp(-h / self.recentre_time),
            catch_fraction=float(self.catch_fraction),
            friction_margin=float(self.friction_margin),
            arm_brake=float(self.arm_brake),
            adapt=float(self.energy_adapt),
            apex_cos=math.cos(0.5 * self.catch_angle),
            blend=float(self.blend),
            horizon_ticks=float(max(1, round(self.catch_horizon / h))),
            **extra,
        )


def dc_omega0(p: FurutaDCParams) -> float:
    r"""The DC plant's pendulum frequency with the arm held,
    :math:`\sqrt{c/J_p} = \sqrt{m_p g l_p/J_p}` (rad/s; 10.68 for the
    QUBE-Servo 2): the omega_0 of the swing-up's normalised energy."""
    return math.sqrt(p.pendulum_mass * p.g * 0.5 * p.pendulum_length / p.j_p)


@jit
def energy(theta, theta_dot, omega0):
    """Normalised pendulum energy E = (theta'/omega0)^2/2 + cos(theta) - 1."""
    r = theta_dot / omega0
    return 0.5 * r * r + math.cos(theta) - 1.0


@jit
def energy_law(theta, theta_dot, e, k, e0, umax):
    """The saturated energy-control term ``sat(k (E - E0) sign(theta' cos theta))``."""
    sg = 1.0 if theta_dot * math.cos(theta) >= 0.0 else -1.0
    u = k * (e - e0) * sg
    return min(max(u, -umax), umax)


@jit
def predicted_peak(gp, theta, theta_dot, arm_dot, n):
    """Largest |u| of the balancing controller over the next ``n`` ticks, predicted
    on the linearised plant (eq. 7 at upright, no friction) under its state
    feedback from (theta, theta', arm 0, arm'): the hand-over test."""
    w2 = gp.omega0 * gp.omega0
    b = w2 / gp.g
    il = 1.0 / gp.arm_length
    hs = 0.5 * gp.h
    x1, x2, x3, x4 = theta, theta_dot, 0.0, arm_dot
    peak = 0.0
    for _ in range(int(n)):
        u = -(gp.l1 * x1 + gp.l2 * x2 + gp.l3 * x3 + gp.l4 * x4)
        peak = max(peak, abs(u))
        for _ in range(2):  # two semi-implicit Euler substeps per tick, u held
            x2 += hs * (w2 * x1 - b * u)
            x1 += hs * x2
            x4 += hs * u * il
            x3 += hs * x4
    return peak


@jit_inline
def catch_peak(gp, dc, theta, theta_dot, arm_dot, n):
    """The hand-over test's predicted peak |u| (:func:`predicted_peak`; on the
    DC plant its design's discretised linearisation,
    :func:`~frictionlab.model.plants.furuta_dc_design.dc_predicted_peak`)."""
    if dc:
        return dc_predicted_peak(gp.l1, gp.l2, gp.l3, gp.l4, gp.obs, theta, theta_dot,
                                 arm_dot, n)
    return predicted_peak(gp, theta, theta_dot, arm_dot, n)


@jit
def dc_swing_voltage(sp, a_e, f_m, th, thd, arm_m, arm_dot_m, up):
    """The DC plant's swing-up voltage: the arm-tip acceleration of the law
    (the faded energy term ``a_e`` with the arm-centring and brake terms,
    within ``swingup.max_acceleration``) made a voltage by the plant's inverse
    arm dynamics (:func:`~frictionlab.model.plants.furuta_dc.arm_voltage`),
    plus the faded friction margin ``f_m`` (V) in the energy term's direction."""
    a = a_e - (sp.arm_stiffness * arm_m + (sp.arm_damping + sp.arm_brake * up) * arm_dot_m)
    a = min(max(a, -sp.max_acceleration), sp.max_acceleration)
    v = arm_voltage(math.sin(th), math.cos(th), thd, arm_dot_m, a / sp.arm_length,
                    dc_model(sp))
    return v + f_m


@jit
def target_correction(w, th, e, sp):
    """Track a swing into the upper half (``cos theta > 0``) and, when it leaves
    that half without a catch, correct the energy target ``w.target``: by the
    shortfall ``cos(catch_angle/2) - max cos(theta)`` of a swing that turned back
    (at the apex theta' = 0, so its height measures the energy whatever the
    plant's omega_0), or by minus the energy over the top plus
    ``1 - cos(catch_angle/2)`` of one that passed over; times ``sp.adapt``."""
    c = math.cos(th)
    if c > 0.0:
        if w.side == 0.0:
            w.side = 1.0 if th >= 0.0 else -1.0
            w.top = c
            w.top_energy = e
            w.crossed = 0.0
        else:
            if th * w.side < 0.0:
                w.crossed = 1.0
            if c > w.top:
                w.top = c
                w.top_energy = e
    elif w.side != 0.0:
        if w.crossed != 0.0:
            w.target -= sp.adapt * (max(w.top_energy, 0.0) + 1.0 - sp.apex_cos)
        else:
            w.target += sp.adapt * (sp.apex_cos - w.top)
        w.target = min(max(w.target, sp.energy_target - 1.0), sp.energy_target + 1.0)
        w.side = 0.0


@jit
def swingup_step(w, s, gp, cp, sp, theta_m, arm_m, arm_dot_m):
    """One tick of the swing-up controller; updates ``w`` and ``s`` in place.

    Parameters
    ----------
    w : record
        Swing-up state, a :data:`SWING_DTYPE` record (module table).
    s : record
        The balancing controller's state record (:mod:`frictionlab.model.controller`),
        initialised here at a catch.
    gp, cp : Gains, ndarray
        The balancing controller's gains record and compensator parameters
        (:meth:`~frictionlab.model.controller.Controller.record`).
    sp : SwingUpRecord
        :meth:`SwingUpParams.record`.
    theta_m, arm_m, arm_dot_m : float
        Measured pendulum angle (any multiple of 2 pi), arm angle, arm velocity.

    Returns
    -------
    (u, u_fb, F_hat) as :func:`~frictionlab.model.controller.controller_step`.
    """
    h = sp.h
    w0 = sp.omega0
    th_m = wrap_angle(theta_m)
    # swing-up observer: predict with eq. (6) and the u held, correct with theta_m
    th = w.theta_hat
    thd = w.theta_dot_hat
    sn = math.sin(th)
    cs = math.cos(th)
    dc = sp.plant == DC_PLANT
    if dc:  # the coupled links at the voltage applied (friction unknown: none)
        acc = dc_accelerations(sn, cs, thd, arm_dot_m, w.u, dc_model(sp))[0]
    else:
        acc = w0 * w0 * sn - sp.g_inv * w.u * cs + arm_dot_m * arm_dot_m * sn * cs
    thp = th + h * (thd + 0.5 * h * acc)
    thdp = thd + h * acc
    err = wrap_angle(th_m - thp)
    th = wrap_angle(thp + sp.l1 * err)
    thd = thdp + sp.l2 * err
    w.theta_hat = th
    w.theta_dot_hat = thd
    w.tick += 1.0
    w.phase_ticks += 1.0
    phase = int(w.phase)
    if phase == STOPPED:
        w.u = 0.0
        return 0.0, 0.0, 0.0
    stop = 0
    if not abs(arm_m) <= sp.arm_limit:
        stop = 2
    elif not abs(arm_dot_m) <= sp.arm_speed_limit:
        stop = 3
    elif phase != BALANCING and w.tick > sp.limit_ticks:
        stop = 1
    if stop != 0:
        w.phase = STOPPED
        w.stop = stop
        w.phase_ticks = 0.0
        w.u = 0.0
        return 0.0, 0.0, 0.0
    e = energy(th, thd, w0)
    w.energy = e
    if phase == CAUGHT and abs(th_m) > sp.release_angle:
        phase = SWINGING
        w.phase_ticks = 0.0
    # the compensator may add up to its stiction level to the feedback's command
    share = 0.0 if gp.compensator == 0 else max(cp.fs, cp.fc)
    if phase == SWINGING and abs(th_m) < sp.catch_angle and catch_peak(
            gp, dc, th_m, thd, arm_dot_m, sp.horizon_ticks) + share <= (
                sp.catch_fraction * gp.u_max):
        phase = CAUGHT
        w.phase_ticks = 0.0
        w.catch_tick = w.tick - 1.0
        w.catches += 1.0
        w.arm_offset = arm_m
        zero_state(s)
        s.x1 = th_m
        s.x2 = thd / gp.omega0
        s.arm_dot = arm_dot_m
    if phase == SWINGING:
        target_correction(w, th, e, sp)
    else:
        w.side = 0.0
    if phase == CAUGHT and w.phase_ticks >= sp.settle_ticks:
        phase = BALANCING
        w.phase_ticks = 0.0
    w.phase = phase
    if phase == SWINGING:
        up = max(math.cos(th), 0.0)  # 0 in the lower half, 1 upright
        u = energy_law(th, thd, e, sp.gain, w.target, sp.max_acceleration)
        fm = 0.0
        if u != 0.0:
            fm = sp.friction_margin if gp.compensator == 0 else max(sp.friction_margin, cp.fc)
            if u < 0.0:
                fm = -fm
        fade = (1.0 - up) ** sp.blend
        if dc:
            u = dc_swing_voltage(sp, fade * u, fade * fm, th, thd, arm_m, arm_dot_m, up)
            u = min(max(u, -gp.u_max), gp.u_max)  # controller.u_max, the voltage limit
            w.u = u
            return u, u, 0.0
        u = fade * (u + fm) - (sp.arm_stiffness * arm_m
                               + (sp.arm_damping + sp.arm_brake * up) * arm_dot_m)
        umax = min(sp.max_acceleration, gp.u_max)  # and the DAC range
        u = min(max(u, -umax), umax)
        w.u = u
        return u, u, 0.0
    if phase == BALANCING:
        w.arm_offset *= sp.decay
    u, u_fb, f_hat = controller_step(s, gp, cp, th_m, arm_m - w.arm_offset, arm_dot_m)
    w.u = u
    return u, u_fb, f_hat


@dataclass(frozen=True)
class SwingUpOutput:
    """What one swing-up tick produced."""

    u: float
    phase: str
    energy: float
    theta_hat: float
    theta_dot_hat: float
    stop_reason: str


@dataclass(frozen=True)
class SwingUp:
    """Energy-control swing-up in front of a balancing :class:`Controller`.

    Parameters
    ----------
    controller : Controller
        The balancing controller that takes over at the catch.
    params : SwingUpParams
    """

    controller: Controller
    params: SwingUpParams = SwingUpParams()

    def record(self) -> tuple[Gains, np.ndarray, SwingUpRecord]:
        """(gains, compensator parameters, swing-up record) for the compiled step."""
        gp, cp = self.controller.record()
        d = self.controller.design
        if isinstance(d, DCDesign):
            p = d.params
            return gp, cp, self.params.record(dc_omega0(p), p.g, d.spec.h, dc=p)
        return gp, cp, self.params.record(d.spec.omega0, d.g, d.spec.h)

    def init(self, theta0: float = math.pi) -> tuple[np.record, np.record]:
        """Initial ``(w, s)`` (:data:`SWING_DTYPE` and controller state records):
        swinging, the observer at the first measured angle, at rest."""
        return (new_swing_state(theta_hat=wrap_angle(float(theta0)), catch_tick=-1.0,
                                target=float(self.params.energy_target)),
                new_state())

    def step(self, state, theta_m: float, arm_m: float, arm_dot_m: float):
        """One tick: ``(output, next_state)``; ``state`` (w, s) is not modified."""
        w = copy_swing_state(state[0])
        s = copy_state(state[1])
        gp, cp, sp = self.record()
        u, _, _ = swingup_step(w, s, gp, cp, sp, theta_m, arm_m, arm_dot_m)
        # fields read as items: about 1 us each from Python against 4 for an attribute
        out = SwingUpOutput(float(u), PHASES[int(w["phase"])], float(w["energy"]),
                            float(w["theta_hat"]), float(w["theta_dot_hat"]),
                            STOP_CODES[int(w["stop"])])
        return out, (w, s)


@jit
def swingup_step_rows(w, x, g, cp, sp, theta_m, arm_m, arm_dot_m):
    """:func:`swingup_step` with the records as float vectors, viewed once at
    entry: the swing-up state ``w`` (:func:`swing_vector`) and the balancing
    controller's state ``x`` (updated in place), the gains row ``g`` and the
    swing-up row ``sp`` (:func:`swingup_row`) and the compensator's friction
    row ``cp`` (:func:`~frictionlab.model.friction.friction_row`)
    (:func:`~frictionlab.model.controller.controller_step_rows`: the form for a
    caller in Python at every tick)."""
    return swingup_step(swing_view(w), state_view(x), gains_record(g), friction_view(cp),
                        swingup_record(sp), theta_m, arm_m, arm_dot_m)

