r"""The rotary (Furuta) inverted pendulum with arm friction, eq. (6).

State vector
------------
The plant state is documented here once; every module uses these indices.

=====  ============  ===========================================  =========
index  name          meaning                                      unit
=====  ============  ===========================================  =========
0      ``THETA``     pendulum angle :math:`\theta`, 0 = upright    rad
1      ``THETA_DOT`` pendulum angular velocity :math:`\dot\theta`  rad/s
2      ``ARM``       arm angle :math:`\Omega`                      rad
3      ``ARM_DOT``   arm angular velocity :math:`\dot\Omega`       rad/s
4      ``Z``         LuGre bristle deflection :math:`z` (only for  (m/s^2)/
                     the LuGre friction model; 0 otherwise)        sigma0
=====  ============  ===========================================  =========

The control signal ``u`` is the commanded tangential acceleration of the arm
tip, :math:`u = \ddot\Omega L_1` (eq. 1), in m/s^2.  Friction on the arm
bearing is expressed in the same unit (``F = F_fr/m``), so the *net* arm tip
acceleration is :math:`a = k_u u - F` where :math:`k_u` is
``PlantParams.input_gain`` (the uncertain control scaling of App. B.4, 1 in
the nominal model).  Eq. (6) then reads

.. math::

    \ddot\theta &= -2\zeta\omega_0\dot\theta + \omega_0^2\sin\theta
                   + \dot\Omega^2\sin\theta\cos\theta - \frac{\omega_0^2}{g} a\cos\theta \\
    \ddot\Omega &= a / L_1

:func:`accelerations` is the single implementation of these equations (a
numba-compiled function); :func:`rhs` wraps it in python-control's
``updfcn(t, x, u, params)`` order and is what linearisation, identification
and the tests use, while the compiled simulator and the observers call
:func:`accelerations` directly.

Integration scheme
------------------
The arm and its friction do not depend on the pendulum (except through the
LuGre plant's eq. (19) term, below), so within a sample they are integrated
on their own grid: ``Config.substeps`` equal substeps (``sim.substeps``, by
default 10 for the static friction models and 6 for LuGre).  In a substep
the friction force is evaluated once and held (friction is discontinuous, so
a higher-order integration *through* it gains nothing) and the arm moves
with the resulting constant acceleration (exact).
The LuGre bristle state is advanced with the exact exponential update for
frozen velocity (:func:`frictionlab.model.friction.friction_step`), so a stiff
bristle (``sigma0`` = 1000) stays stable at any substep count; the velocity
it sees is the substep's midpoint velocity predicted with the last friction,
which makes the smooth LuGre model second order in the substep (first order
without the predictor: 3.4 % feature error at 10 substeps for the slow design
with sigma0 = 1000, 0.02 % with it; docs/model.md).

With the LuGre plant's observer gain k > 0 (eq. 19, e = -theta) the bristle
also sees the pendulum angle: at each substep's midpoint, the angle predicted
by the second-order Taylor expansion from the start of the pendulum step (its
acceleration from the current arm state and the last friction).  That keeps
the scheme second order (the features of k = 1 and 2 runs are within 0.04 %
of 20 times finer steps).  With k = 0 nothing of this is evaluated and the
result is plain eq. (18), bit for bit.

The pendulum is smooth and is driven by the arm only through the net arm
acceleration a and the arm velocity squared (eq. 6).  It takes
``sim.pendulum_steps`` velocity-Verlet steps per sample (2 by default), each
driven by the exact means of a and of the squared arm velocity over its
substeps; that keeps the impulse the friction gives the pendulum exact and
costs almost no accuracy against pendulum steps as fine as the arm's (the
features change by at most 0.15 %, the classical model's max u; 0.02 %
otherwise) for a quarter of the pendulum's cost.

Pivot friction (``plant.pivot_friction``, off by default)
---------------------------------------------------------
Eq. (6) damps the pendulum viscously (:math:`-2\zeta\omega_0\dot\theta`), but
App. A blames the spread of its damping estimates on "friction in the pivot
point": the peaks of the free oscillation of Figure 33 (0.21, 0.17, 0.13,
0.09, 0.06, 0.03 rad, one period apart) fall by nearly the same amount each
period (0.04, 0.04, 0.04, 0.03, 0.03), where viscous damping alone would
shrink them by the same *ratio* (App. A.2's per-peak zeta rises from 0.032
to 0.062).  An oscillator :math:`\ddot\theta = -\omega_0^2\theta - 2\zeta
\omega_0\dot\theta - f_p\,\mathrm{sgn}\,\dot\theta` loses
:math:`4f_p/\omega_0^2` of amplitude per period to the Coulomb term and the
fraction :math:`2\pi\zeta` to the viscous one, so the decrements
:math:`d_n = A_n - A_{n+1} = 2\pi\zeta A_n + 4f_p/\omega_0^2`: the least-squares
line through the five gives :math:`\zeta = 0.0125` and :math:`f_p = 0.30`
rad/s^2 at :math:`\omega_0 = 6.8` (:func:`fit_pivot_friction`;
:data:`A2_PIVOT_FRICTION`).  With ``plant.pivot_friction`` = f_p the plant's
pendulum obeys eq. (6) plus :math:`-f_p\,\mathrm{sgn}\,\dot\theta`
(:func:`pivot_accel`), the sign made linear below
:data:`PIVOT_VELOCITY` (0.005 rad/s, so that the explicit pendulum step stays
stable); the friction acts on the pendulum's velocity relative to the arm,
and its reaction on the arm is not modelled (the arm is driven by an
acceleration, eq. 5).  The observers know nothing of it, as the thesis's did
not.  With 0 (the default) nothing of it is evaluated: eq. (6), bit for bit.

Zero-velocity band (classical model)
------------------------------------
As in the thesis's Simnon runs (Sec. 5.2), speeds inside the band count as
rest: friction balances the applied force (the arm's acceleration is zero)
unless that force exceeds the stiction level.  The arm keeps the small speed
it entered the band with until the force breaks it loose; the band must
therefore be wider than the speed change of one substep for sticking to be
seen at all (the thesis needed 0.03 rad/s; with 0.001 the arm skips over it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .._jit import jit, jit_inline
from ..actuator import actuator_accel
from ..friction import LUGRE, NONE, friction_step
from ..params import Validated, param

__all__ = [
    "A2_PEAKS",
    "A2_PIVOT_FRICTION",
    "ARM",
    "ARM_DOT",
    "NX",
    "PIVOT_VELOCITY",
    "SUBSTEPS",
    "THETA",
    "THETA_DOT",
    "PlantParams",
    "PlantRecord",
    "Z",
    "accelerations",
    "accelerations_sc",
    "fit_pivot_friction",
    "linearize",
    "linearized_model",
    "pivot_accel",
    "plant_record",
    "rhs",
    "step_without_back_emf",
    "tick",
    "tick_without_back_emf",
    "zoh",
    "zoh_closed_form",
]

#: App. A.2's peaks of the free oscillation (Figure 33), rad from the hanging
#: position, one period apart.
A2_PEAKS = (0.21, 0.17, 0.13, 0.09, 0.06, 0.03)
#: App. A.2's pivot friction, rad/s^2 (:func:`fit_pivot_friction`, rounded).
A2_PIVOT_FRICTION = 0.30


def fit_pivot_friction(peaks=A2_PEAKS, omega0: float = 6.8) -> tuple[float, float]:
    """``(zeta, f_p)`` of the least-squares line through the decrements of
    successive peaks one period apart, ``d_n = 2 pi zeta A_n + 4 f_p / omega0^2``
    (module docstring, "Pivot friction"); App. A.2's peaks by default."""
    a = np.asarray(peaks, dtype=float)
    d = a[:-1] - a[1:]
    (slope, icpt), *_ = np.linalg.lstsq(np.column_stack([a[:-1], np.ones(len(d))]), d,
                                        rcond=None)
    return float(slope / (2.0 * math.pi)), float(icpt * omega0**2 / 4.0)

THETA, THETA_DOT, ARM, ARM_DOT, Z = 0, 1, 2, 3, 4
NX = 5

#: Default arm substeps per sample of :func:`tick` by friction law (``KINDS``
#: names; the integration scheme above): 10 for the static laws, 6 for LuGre,
#: whose bristle's velocity predictor makes it second order.
SUBSTEPS: dict[str, int] = {"none": 10, "viscous": 10, "coulomb": 10, "classical": 10,
                            "stribeck": 10, "lugre": 6}


@dataclass(frozen=True)
class PlantParams(Validated):
    """Physical parameters of the pendulum (Sec. 2.1, App. A; keys ``plant.*``)."""

    _prefix = "plant."

    omega0: float = param(6.8, "natural frequency of the pendulum [omega_0]", "rad/s",
                          lo=0.0, hi=100.0, lo_open=True)
    zeta: float = param(0.04, "relative damping of the pendulum [zeta]", "1", lo=0.0, hi=1.0)
    arm_length: float = param(0.21, "arm length [L_1]", "m", lo=0.0, hi=10.0, lo_open=True)
    g: float = param(9.82, "gravitational acceleration [g]", "m/s^2", lo=0.0, hi=100.0,
                     lo_open=True)
    input_gain: float = param(1.0, "multiplier on the u the plant receives (App. B.4's k_u "
                              "uncertainty)", "1", lo=0.0, hi=10.0, lo_open=True)
    pivot_friction: float = param(0.0, "Coulomb friction of the pendulum's pivot, as the "
                                  "angular deceleration it gives (App. A.2's decay: "
                                  f"{A2_PIVOT_FRICTION}; 0 = none, eq. 6)", "rad/s^2",
                                  lo=0.0, hi=100.0)

    @property
    def pendulum_length(self) -> float:
        """Equivalent pendulum length :math:`L_2 = g/\\omega_0^2` in m."""
        return self.g / self.omega0**2

    def record(self, actuator: np.ndarray | None = None) -> np.ndarray:
        """The float row the compiled integrator reads (:class:`PlantRecord`'s
        fields in order; :func:`plant_record` views it as the record), with the
        actuator's row (:meth:`frictionlab.model.actuator.ActuatorParams.record`;
        default: the ideal input)."""
        act = (0.0, 0.0) if actuator is None else tuple(actuator)
        return np.array([self.omega0, self.zeta, self.g, self.arm_length, self.input_gain,
                         *act, self.pivot_friction], dtype=float)


class PlantRecord(NamedTuple):
    """The plant parameters as the compiled code reads them: :func:`plant_record`
    of the float row :meth:`PlantParams.record`."""

    omega0: float
    zeta: float
    g: float
    arm_length: float
    input_gain: float
    #: the actuator (:mod:`frictionlab.model.actuator`): curvature c, back-EMF b
    act_curvature: float
    act_back_emf: float
    #: the pendulum pivot's Coulomb friction (rad/s^2; :func:`pivot_accel`)
    pivot_friction: float


@jit
def plant_record(row):
    """The :class:`PlantRecord` stored as the float row ``np.array(record)``."""
    return PlantRecord(row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7])


#: The pivot friction's velocity scale: below it the friction is proportional to
#: the pendulum's velocity (a regularised sign, rad/s; :func:`pivot_accel`).
PIVOT_VELOCITY = 0.005


@jit_inline
def pivot_accel(theta_dot, level):
    r"""The pendulum pivot's Coulomb friction, in :math:`\ddot\theta` (rad/s^2):
    :math:`-f_p\,\mathrm{sgn}(\dot\theta)`, the sign regularised below
    :data:`PIVOT_VELOCITY` (module docstring, "Pivot friction")."""
    return -level * theta_dot / max(abs(theta_dot), PIVOT_VELOCITY)


@jit
def accelerations_sc(sin_theta, cos_theta, theta_dot, arm_dot, a, omega0, zeta, g, arm_length):
    r""":func:`accelerations` with :math:`\sin\theta, \cos\theta` supplied (the
    integrator reuses them between evaluations)."""
    theta_ddot = (
        -2.0 * zeta * omega0 * theta_dot
        + omega0 * omega0 * sin_theta
        + arm_dot * arm_dot * sin_theta * cos_theta
        - omega0 * omega0 / g * a * cos_theta
    )
    return theta_ddot, a * (1.0 / arm_length)  # the reciprocal is hoisted out of loops


@jit
def accelerations(theta, theta_dot, arm_dot, a, omega0, zeta, g, arm_length):
    r"""Pendulum and arm angular accelerations of eq. (6).

    Parameters
    ----------
    theta, theta_dot, arm_dot : float
        :math:`\theta` (rad), :math:`\dot\theta`, :math:`\dot\Omega` (rad/s).
    a : float
        Net arm tip acceleration :math:`k_u u - F_{fr}/m` in m/s^2.
    omega0, zeta, g, arm_length : float
        Plant parameters.

    Returns
    -------
    (theta_ddot, arm_ddot) : tuple of float
    """
    return accelerations_sc(np.sin(theta), np.cos(theta), theta_dot, arm_dot, a, omega0, zeta,
                            g, arm_length)


def rhs(t: float, x, u, params: PlantParams) -> np.ndarray:
    """Time derivative of the mechanical state, eq. (6).

    Signature follows python-control's ``updfcn(t, x, u, params)``.

    Parameters
    ----------
    t : float
        Time in s (the model is time invariant; unused).
    x : array_like, shape (4,) or (5,)
        State, see the module table.  A 5th entry (LuGre ``z``) is carried
        through with zero derivative: the bristle dynamics live in
        :mod:`frictionlab.model.friction`.
    u : float or array_like of length 2
        Control signal u in m/s^2, or ``(u, F)`` with the arm friction F in
        units of u (m/s^2).
    params : PlantParams

    Returns
    -------
    numpy.ndarray
        dx/dt with the shape of ``x``.
    """
    x = np.asarray(x, dtype=float)
    u_arr = np.atleast_1d(np.asarray(u, dtype=float))
    friction = float(u_arr[1]) if u_arr.size > 1 else 0.0
    a = params.input_gain * float(u_arr[0]) - friction
    th_dd, arm_dd = accelerations(
        x[THETA], x[THETA_DOT], x[ARM_DOT], a, params.omega0, params.zeta, params.g,
        params.arm_length,
    )
    if params.pivot_friction != 0.0:
        th_dd += pivot_accel(float(x[THETA_DOT]), params.pivot_friction)
    dx = np.zeros_like(x)
    dx[THETA] = x[THETA_DOT]
    dx[THETA_DOT] = th_dd
    dx[ARM] = x[ARM_DOT]
    dx[ARM_DOT] = arm_dd
    return dx


def linearize(params: PlantParams, eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Numerical Jacobian of :func:`rhs` at the upright equilibrium.

    Central differences on the 4 mechanical states and the control input.

    Returns
    -------
    A : ndarray (4, 4)
    B : ndarray (4, 1)
    """
    x0 = np.zeros(4)
    A = np.zeros((4, 4))
    for j in range(4):
        dx = np.zeros(4)
        dx[j] = eps
        A[:, j] = (rhs(0.0, x0 + dx, 0.0, params) - rhs(0.0, x0 - dx, 0.0, params)) / (2 * eps)
    B = ((rhs(0.0, x0, eps, params) - rhs(0.0, x0, -eps, params)) / (2 * eps)).reshape(4, 1)
    return A, B


def linearized_model(omega0: float, g: float, arm_length: float, zeta: float = 0.0):
    """Closed-form linearisation around the upright position, eq. (7).

    The thesis's eq. (7) neglects damping (``zeta = 0``, the design model);
    a nonzero ``zeta`` adds ``-2 zeta omega0`` in ``A[1, 1]``.

    Returns
    -------
    A, B, C : ndarray
        ``C`` selects the measured signals (theta, Omega, Omega_dot).
    """
    A = np.array(
        [[0.0, 1.0, 0.0, 0.0],
         [omega0**2, -2.0 * zeta * omega0, 0.0, 0.0],
         [0.0, 0.0, 0.0, 1.0],
         [0.0, 0.0, 0.0, 0.0]]
    )
    B = np.array([[0.0], [-(omega0**2) / g], [0.0], [1.0 / arm_length]])
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    return A, B, C


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation (matrix exponential of the augmented system)."""
    from scipy.linalg import expm  # heavy import, only when used

    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * h)
    return E[:n, :n], E[:n, n:]


def zoh_closed_form(omega0: float, g: float, arm_length: float, h: float):
    """Phi and Gamma of Sec. 2.2 in closed form (hyperbolic functions)."""
    ch, sh = np.cosh(omega0 * h), np.sinh(omega0 * h)
    Phi = np.array(
        [[ch, sh / omega0, 0.0, 0.0],
         [omega0 * sh, ch, 0.0, 0.0],
         [0.0, 0.0, 1.0, h],
         [0.0, 0.0, 0.0, 1.0]]
    )
    Gamma = np.array(
        [[-(ch - 1.0) / g], [-omega0 * sh / g], [h * h / (2.0 * arm_length)], [h / arm_length]]
    )
    return Phi, Gamma


@jit
def tick(x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """Advance the plant state ``x`` (5,) in place over one sample with u held.

    The arm and its friction take ``substeps`` substeps: friction from the
    substep's initial state (LuGre: at the predicted midpoint velocity and,
    with k > 0, the error e = -theta at the pendulum's predicted midpoint
    angle, eq. 19), held;
    the arm moves with the resulting constant acceleration (exact).  The
    pendulum takes one velocity-Verlet step per ``ratio`` substeps, driven by
    the mean net acceleration and the mean squared arm velocity over them (both
    exact for the piecewise-linear arm velocity); its sin/cos are rotated
    through the angle increment and recomputed at the start of every sample.

    Parameters
    ----------
    x : ndarray (5,)
        Plant state ``[theta, theta_dot, arm, arm_dot, z]`` (advanced in place).
    u : float
        Control signal held over the sample (m/s^2).
    mem : float
        The friction model's memory: the Coulomb relay state, or the LuGre
        friction of the last substep (for the velocity predictor); else unused.
    substeps, ratio : int
        Arm substeps per sample and arm substeps per pendulum step.
    h : float
        Sampling period (s).
    pp : ndarray
        Plant parameters as the float row :meth:`PlantParams.record`.
    fkind, fp
        Friction model code, the plant's friction record
        (:func:`frictionlab.model.friction.plant_record`), by reference.

    Returns
    -------
    (mean friction over the sample, mem)

    Notes
    -----
    The actuator's back-EMF (``actuator.back_emf``) makes the arm's
    acceleration depend on its velocity in every substep; without it the
    acceleration the motor gives is the same for the whole sample.  The step is
    therefore compiled in two forms of one body: this one, for any actuator,
    and :func:`tick_without_back_emf`, which the closed loop inlines when the
    back-EMF is off (the same numbers bit for bit).
    """
    p = plant_record(pp)
    return _step(x, u, mem, substeps, ratio, h, p, fkind, fp, p.act_back_emf != 0.0)


@jit
def tick_without_back_emf(x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """:func:`tick` for a plant whose actuator has no back-EMF
    (``actuator.back_emf`` = 0; the curvature may be on).

    The same body with the back-EMF's line compiled out: the acceleration the
    motor gives is then constant over the sample, and the arm's velocity
    update in each substep no longer waits for a product and a difference on
    the velocity just computed (a third of a cheap run's time; docs/performance.md).
    """
    return _step(x, u, mem, substeps, ratio, h, plant_record(pp), fkind, fp, False)


@jit
def step_without_back_emf(x, u, mem, substeps, ratio, h, p, fkind, fp):
    """:func:`tick_without_back_emf` on the plant's :class:`PlantRecord` ``p`` (by
    value) in place of its row: a loop that reads the record once, before its
    ticks, keeps the parameters and what the step derives from them (the
    reciprocals of eq. 6's divisions) out of every tick; read from the row in
    each tick, they are not (the row may share memory with the state the step
    writes), which cost a cheap run 10-15 % (docs/performance.md)."""
    return _step(x, u, mem, substeps, ratio, h, p, fkind, fp, False)


@jit_inline
def _step(x, u, mem, substeps, ratio, h, p, fkind, fp, back_emf):
    """The body of :func:`tick` on the plant's record ``p``; ``back_emf`` (bool)
    says whether the actuator's back-EMF is evaluated in the substeps, a
    constant where the caller passes one."""
    omega0, zeta, g, arm_len, ku = p.omega0, p.zeta, p.g, p.arm_length, p.input_gain
    pivot = p.pivot_friction
    dt = h / substeps
    # the actuator (App. B.4): the acceleration the motor gives for k_u u, at the
    # substep's arm velocity when it has a back-EMF
    fe_cmd = actuator_accel(p.act_curvature, 0.0, ku * u, 0.0, arm_len)
    # its back-EMF, b L_1 times the arm velocity, taken off at each substep
    emf = p.act_back_emf * arm_len
    fe = fe_cmd
    half_dt_over_l = 0.5 * dt / arm_len
    f_sum = 0.0
    th, thd, arm, ad, z = x[0], x[1], x[2], x[3], x[4]
    sn = np.sin(th)
    cs = np.cos(th)
    k = fp.k  # read unconditionally (model.friction's docstring, "Reads")
    kgain = k if fkind == LUGRE else 0.0
    done = 0
    while done < substeps:
        m = min(ratio, substeps - done)
        a_sum = 0.0
        v2_sum = 0.0
        th_acc = 0.0
        tau = 0.0
        if kgain != 0.0:
            # eq. (19)'s error e = -theta at each substep's midpoint, from the
            # pendulum's Taylor prediction over this pendulum step
            th_acc, _ = accelerations_sc(sn, cs, thd, ad, fe - mem, omega0, zeta, g, arm_len)
            tau = 0.5 * dt
        for _ in range(m):
            if back_emf:
                fe = fe_cmd - emf * ad
            if fkind == LUGRE:
                # the bristle sees the velocity at the substep's midpoint, predicted
                # with the last friction: second order for this smooth model
                v = ad + (fe - mem) * half_dt_over_l
                e = 0.0
                if kgain != 0.0:
                    e = -(th + tau * (thd + 0.5 * tau * th_acc))
                    tau += dt
                f, z = friction_step(LUGRE, fp, z, v, fe, dt, e)
                mem = f
            elif fkind == NONE:
                f = 0.0
            else:
                # (a Coulomb plant's record has no hysteresis: its relay follows
                # the velocity's sign, :func:`frictionlab.model.friction.plant_record`)
                f, mem = friction_step(fkind, fp, mem, ad, fe, dt, 0.0)
            f_sum += f
            a = fe - f
            _, arm_acc = accelerations_sc(sn, cs, thd, ad, a, omega0, zeta, g, arm_len)
            ad_new = ad + dt * arm_acc
            v2_sum += ad * ad + ad * ad_new + ad_new * ad_new  # 3 x mean of ad^2
            arm = arm + dt * (ad + 0.5 * dt * arm_acc)
            ad = ad_new
            a_sum += a
        done += m
        # pendulum: one velocity-Verlet step over the m substeps
        dtp = m * dt
        a_m = a_sum / m
        v_rms = math.sqrt(v2_sum / (3.0 * m))
        acc0, _ = accelerations_sc(sn, cs, thd, v_rms, a_m, omega0, zeta, g, arm_len)
        if pivot != 0.0:
            acc0 += pivot_accel(thd, pivot)
        dth = dtp * (thd + 0.5 * dtp * acc0)
        th = th + dth
        if abs(dth) < 1e-2:
            # rotate (sin, cos) by the increment: the truncated series are exact
            # to rounding for |dth| < 1e-2 (next terms below 2e-18)
            d2 = dth * dth
            sd = dth * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0)))
            cd = 1.0 - 0.5 * d2 * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0)))
            sn, cs = sn * cd + cs * sd, cs * cd - sn * sd
        else:
            sn = np.sin(th)
            cs = np.cos(th)
        acc1, _ = accelerations_sc(sn, cs, thd + dtp * acc0, v_rms, a_m, omega0, zeta, g,
                                   arm_len)
        if pivot != 0.0:
            acc1 += pivot_accel(thd + dtp * acc0, pivot)
        thd = thd + 0.5 * dtp * (acc0 + acc1)
    x[0], x[1], x[2], x[3], x[4] = th, thd, arm, ad, z
    return f_sum / substeps, mem
