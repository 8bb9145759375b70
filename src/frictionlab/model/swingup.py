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

To that is added an arm-centring term :math:`-k_p\Omega - k_d\dot\Omega`
(``swingup.arm_stiffness``, ``swingup.arm_damping``) that keeps the arm near
its start; the sum is saturated at ``swingup.max_acceleration``.

The angular velocity comes from a nonlinear observer on the full model
(:math:`\ddot\theta` of eq. 6 with the design's omega_0, the applied u and
the measured arm velocity), a predictor-corrector at h with both error poles
at :math:`e^{-\omega_s h}` (``swingup.observer_omega``); the linear
balancing observers are only valid near upright.  Angles are wrapped into
[-pi, pi) (the rig's angle channel wraps, App. B.1).

Hand-over
---------
When the measured angle enters the catch region (``|theta| <
swingup.catch_angle``) the balancing controller takes over: its observers
start from the current measurement (theta, the swing-up observer's
theta_dot, the arm at its current position with the measured velocity).  The
arm's reference is the position where it was caught (an offset
subtracted from the arm angle) and returns to 0 exponentially with the time
constant ``swingup.recentre_time``, so the balancing controller does not
react to an arm error of several radians the moment it takes over.  A catch
that fails (``|theta| > swingup.release_angle`` before ``swingup.settle_time``
has passed) returns to swinging; one that holds for ``settle_time`` is
*balancing*, after which the usual falls and angle limits apply.

Friction
--------
The arm bearing's friction (any plant model, present throughout) eats into
the net acceleration :math:`a = u - F`: while the law is saturated at
``max_acceleration`` (4-5 times the thesis's stiction level 2.3 m/s^2), the
arm moves and friction only reduces the pumping rate by
:math:`F_C/u_s`; near the target energy the command falls below the
stiction level, the arm sticks (at the pendulum's turning points, where
``sign`` flips and the arm reverses), and the pendulum swings freely with
the energy it has - which is what the law wants there.  The catch happens
at whatever energy is left; :math:`E_0` slightly above 0
(``swingup.energy_target``) makes up for the damping and friction losses of
the last swing.  docs/swingup.md maps the success rate over friction levels.

Safety (the same checks in the simulator and the loop)
------------------------------------------------------
Every tick checks ``|Omega| <= swingup.arm_limit`` (stop code
``arm_travel``), ``|Omega'| <= swingup.arm_speed_limit`` (``arm_speed``) and,
until balancing, the elapsed time against ``swingup.time_limit``
(``not_caught``); a stop sets the phase to ``stopped`` and u = 0 from then on.

State vector (float64, explicit)
--------------------------------
====  ============  =====================================================
idx   name          meaning
====  ============  =====================================================
0     ``W_PHASE``   0 swinging, 1 caught, 2 balancing, 3 stopped
1     ``W_T``       ticks since the start
2     ``W_PT``      ticks in the current phase
3     ``W_TH``      swing-up observer angle (rad, wrapped)
4     ``W_THD``     swing-up observer angular velocity (rad/s)
5     ``W_OFF``     arm reference offset after a catch (rad)
6     ``W_E``       normalised energy E of the estimates
7     ``W_STOP``    stop code (0 none, 1 not_caught, 2 arm_travel, 3 arm_speed)
8     ``W_CATCH``   tick of the last catch (-1: none)
9     ``W_U``       last applied u (m/s^2)
10    ``W_NCATCH``  number of catches so far
====  ============  =====================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._jit import jit
from .controller import (
    Controller,
    controller_step,
    copy_state,
    gains_record,
    new_state,
    state_view,
    zero_state,
)
from .params import Validated, param

__all__ = [
    "PHASES",
    "STOP_CODES",
    "SwingUp",
    "SwingUpParams",
    "energy",
    "swingup_step",
    "swingup_step_rows",
    "wrap_angle",
]

SWINGING, CAUGHT, BALANCING, STOPPED = 0, 1, 2, 3
#: Phase names by code.
PHASES = ("swinging", "caught", "balancing", "stopped")
#: Stop reasons by code (0: not stopped).
STOP_CODES = ("", "not_caught", "arm_travel", "arm_speed")

W_PHASE, W_T, W_PT, W_TH, W_THD, W_OFF, W_E, W_STOP, W_CATCH, W_U, W_NCATCH = range(11)
NW = 11

(P_K, P_UMAX, P_CATCH, P_RELEASE, P_SETTLE, P_LIMIT, P_KP, P_KD, P_L1, P_L2, P_E0, P_W0,
 P_GINV, P_H, P_ARM, P_SPEED, P_DECAY) = range(17)
NSP = 17


@dataclass(frozen=True)
class SwingUpParams(Validated):
    """Swing-up settings (keys ``swingup.*``); see the module docstring."""

    _prefix = "swingup."

    gain: float = param(100.0, "energy-control gain k of u = k (E - E0) sign(theta' cos theta)",
                        "m/s^2", lo=0.0, hi=1e4, lo_open=True)
    max_acceleration: float = param(10.0, "|u| limit while swinging", "m/s^2", lo=0.0,
                                    hi=1e3, lo_open=True)
    energy_target: float = param(0.5, "target normalised energy E0 (0 = upright at rest)",
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
    observer_omega: float = param(40.0, "swing-up angle observer's error pole frequency",
                                  "rad/s", lo=0.0, hi=1e3, lo_open=True)
    arm_limit: float = param(6.0, "stop (arm_travel) when |Omega| exceeds this", "rad",
                             lo=0.0, hi=1e3, lo_open=True)
    arm_speed_limit: float = param(25.0, "stop (arm_speed) when |Omega'| exceeds this",
                                   "rad/s", lo=0.0, hi=1e3, lo_open=True)

    def pack(self, omega0: float, g: float, h: float) -> np.ndarray:
        """Packed vector for :func:`swingup_step` (design omega_0, g and h)."""
        p = np.zeros(NSP)
        p[P_K] = self.gain
        p[P_UMAX] = self.max_acceleration
        p[P_CATCH] = self.catch_angle
        p[P_RELEASE] = self.release_angle
        p[P_SETTLE] = round(self.settle_time / h)
        p[P_LIMIT] = round(self.time_limit / h)
        p[P_KP] = self.arm_stiffness
        p[P_KD] = self.arm_damping
        pole = math.exp(-self.observer_omega * h)
        p[P_L1] = 1.0 - pole * pole
        p[P_L2] = (1.0 - pole) ** 2 / h
        p[P_E0] = self.energy_target
        p[P_W0] = omega0
        p[P_GINV] = omega0 * omega0 / g
        p[P_H] = h
        p[P_ARM] = self.arm_limit
        p[P_SPEED] = self.arm_speed_limit
        p[P_DECAY] = 0.0 if self.recentre_time == 0 else math.exp(-h / self.recentre_time)
        return p


@jit
def wrap_angle(a):
    """``a`` wrapped into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


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
def swingup_step(w, s, gp, cp, sp, theta_m, arm_m, arm_dot_m):
    """One tick of the swing-up controller; updates ``w`` and ``s`` in place.

    Parameters
    ----------
    w : ndarray (NW,)
        Swing-up state (module table).
    s : record
        The balancing controller's state record (:mod:`frictionlab.model.controller`),
        initialised here at a catch.
    gp, cp : ndarray
        The balancing controller's packed gains and compensator parameters.
    sp : ndarray (NSP,)
        :meth:`SwingUpParams.pack`.
    theta_m, arm_m, arm_dot_m : float
        Measured pendulum angle (any multiple of 2 pi), arm angle, arm velocity.

    Returns
    -------
    (u, u_fb, F_hat) as :func:`~frictionlab.model.controller.controller_step`.
    """
    h = sp[P_H]
    w0 = sp[P_W0]
    th_m = wrap_angle(theta_m)
    # swing-up observer: predict with eq. (6) and the u held, correct with theta_m
    th = w[W_TH]
    thd = w[W_THD]
    sn = math.sin(th)
    cs = math.cos(th)
    acc = w0 * w0 * sn - sp[P_GINV] * w[W_U] * cs + arm_dot_m * arm_dot_m * sn * cs
    thp = th + h * (thd + 0.5 * h * acc)
    thdp = thd + h * acc
    err = wrap_angle(th_m - thp)
    th = wrap_angle(thp + sp[P_L1] * err)
    thd = thdp + sp[P_L2] * err
    w[W_TH] = th
    w[W_THD] = thd
    w[W_T] += 1.0
    w[W_PT] += 1.0
    phase = int(w[W_PHASE])
    if phase == STOPPED:
        w[W_U] = 0.0
        return 0.0, 0.0, 0.0
    stop = 0
    if not abs(arm_m) <= sp[P_ARM]:
        stop = 2
    elif not abs(arm_dot_m) <= sp[P_SPEED]:
        stop = 3
    elif phase != BALANCING and w[W_T] > sp[P_LIMIT]:
        stop = 1
    if stop != 0:
        w[W_PHASE] = STOPPED
        w[W_STOP] = stop
        w[W_PT] = 0.0
        w[W_U] = 0.0
        return 0.0, 0.0, 0.0
    e = energy(th, thd, w0)
    w[W_E] = e
    if phase == CAUGHT and abs(th_m) > sp[P_RELEASE]:
        phase = SWINGING
        w[W_PT] = 0.0
    if phase == SWINGING and abs(th_m) < sp[P_CATCH]:
        phase = CAUGHT
        w[W_PT] = 0.0
        w[W_CATCH] = w[W_T] - 1.0
        w[W_NCATCH] += 1.0
        w[W_OFF] = arm_m
        zero_state(s)
        s.x1 = th_m
        s.x2 = thd / gp.omega0
        s.arm_dot = arm_dot_m
    if phase == CAUGHT and w[W_PT] >= sp[P_SETTLE]:
        phase = BALANCING
        w[W_PT] = 0.0
    w[W_PHASE] = phase
    if phase == SWINGING:
        u = energy_law(th, thd, e, sp[P_K], sp[P_E0], sp[P_UMAX])
        u -= sp[P_KP] * arm_m + sp[P_KD] * arm_dot_m
        umax = min(sp[P_UMAX], gp.u_max)  # and the DAC range
        u = min(max(u, -umax), umax)
        w[W_U] = u
        return u, u, 0.0
    w[W_OFF] *= sp[P_DECAY]
    u, u_fb, f_hat = controller_step(s, gp, cp, th_m, arm_m - w[W_OFF], arm_dot_m)
    w[W_U] = u
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

    def pack(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(gains, compensator parameters, swing-up parameters) for the compiled step."""
        gp, cp = self.controller.record()
        d = self.controller.design
        return gp, cp, self.params.pack(d.spec.omega0, d.g, d.spec.h)

    def init(self, theta0: float = math.pi) -> tuple[np.ndarray, np.record]:
        """Initial ``(w, s)``: swinging, the observer at the first measured angle, at rest."""
        w = np.zeros(NW)
        w[W_TH] = wrap_angle(float(theta0))
        w[W_CATCH] = -1.0
        return w, new_state()

    def step(self, state, theta_m: float, arm_m: float, arm_dot_m: float):
        """One tick: ``(output, next_state)``; ``state`` (w, s) is not modified."""
        w = np.array(state[0], dtype=float, copy=True)
        s = copy_state(state[1])
        gp, cp, sp = self.pack()
        u, _, _ = swingup_step(w, s, gp, cp, sp, theta_m, arm_m, arm_dot_m)
        out = SwingUpOutput(float(u), PHASES[int(w[W_PHASE])], float(w[W_E]), float(w[W_TH]),
                            float(w[W_THD]), STOP_CODES[int(w[W_STOP])])
        return out, (w, s)


@jit
def swingup_step_rows(w, x, g, cp, sp, theta_m, arm_m, arm_dot_m):
    """:func:`swingup_step` with the balancing controller's state as a float
    vector ``x`` and its gains as a float row ``g``
    (:func:`~frictionlab.model.controller.controller_step_rows`: the form for a
    caller in Python at every tick)."""
    return swingup_step(w, state_view(x), gains_record(g), cp, sp, theta_m, arm_m, arm_dot_m)

