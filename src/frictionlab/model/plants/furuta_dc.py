r"""The full Furuta pendulum driven by a DC motor (plant ``furuta-dc``: the
QUBE-Servo 2 and 3, a home-built rig).

Two rigid links: the arm turns about the vertical motor axis, the pendulum
about the arm's tip (an axis along the arm).  Both are thin rods; unlike the
thesis's eq. (6), the arm is not an ideal acceleration source: the input is
the motor voltage, and the two links are fully coupled (inertia coupling,
centrifugal and Coriolis terms, gravity; Cazzolato and Prime, "On the
dynamics of the Furuta pendulum", J. Control Sci. Eng. 2011, with the
pendulum's inertia about its own long axis set to zero: thin rods).

State vector
------------
The same order and signs as the thesis plant (:mod:`frictionlab.model.plants.thesis`):

=====  ===========  ===============================================  ======
index  name         meaning                                          unit
=====  ===========  ===============================================  ======
0      theta        pendulum angle from UPRIGHT                      rad
1      theta_dot    its rate                                         rad/s
2      arm          arm angle                                        rad
3      arm_dot      arm rate                                         rad/s
4      z            LuGre bristle state (0 for the other laws)       V/sigma0
=====  ===========  ===============================================  ======

A positive voltage accelerates the arm positively and, near upright, the
pendulum negatively (:math:`\partial\ddot\theta/\partial u < 0`, as in the
thesis's eq. (6)); with the pendulum hanging, a positive voltage step makes
theta increase at first (the pendulum lags behind the arm).

Quanser's QUBE model measures the pendulum angle :math:`\alpha_Q` from
HANGING, and its arm equation's coupling term is
:math:`-\tfrac12 m_p L_p L_r\cos\alpha_Q\,\ddot\alpha_Q`.  Its equations are
these with :math:`\theta = \pi + \alpha_Q` (mod :math:`2\pi`) and its arm
angle unchanged.  On the board, a positive voltage step with the pendulum
hanging makes encoder 1 count DOWN at first (as reported for the QUBE), so
from the counts :math:`\theta = \pi - 2\pi n_1/2048` (:math:`n_1` zeroed
hanging) and the arm :math:`2\pi n_0/2048`: Quanser's model angle runs
opposite to encoder 1's count.  The rig backend owns that sign
(``rig.pendulum_sign``); the check on any rig is the step above.

Equations
---------
With :math:`J_p` the pendulum's inertia about its pivot, :math:`J_0 = J_r +
J_m + m_p L_r^2` the arm's (rod, rotor, and the pendulum's mass at the tip)
about the motor axis, :math:`b = m_p l_p L_r`, :math:`c = m_p g l_p`
(:math:`l_p = L_p/2`), :math:`s = \sin\theta`, :math:`k = \cos\theta`:

.. math::

    \begin{pmatrix} J_p & b k \\ b k & J_0 + J_p s^2 \end{pmatrix}
    \begin{pmatrix}\ddot\theta \\ \ddot\phi\end{pmatrix} =
    \begin{pmatrix} J_p s k\dot\phi^2 + c s - D_p\dot\theta \\
    \frac{k_t}{R_m}(u - F - k_m\dot\phi) - D_r\dot\phi
    - 2J_p s k\dot\theta\dot\phi + b s\dot\theta^2 \end{pmatrix}

The motor's torque is :math:`k_t(u - k_m\dot\phi)/R_m` (armature inductance
neglected: its electrical time constant L_m/R_m = 0.14 ms is 35 times
shorter than the 5 ms sample).  The arm bearing's friction F is in VOLTS, the
units of u: the voltage whose stall torque equals the friction torque,
:math:`\tau_F = k_t F/R_m`.  :func:`dc_mass_forcing` is the one
implementation of the mass matrix and forcing; :func:`rhs` and :func:`tick`
both call it.

The classical model's "external force"
--------------------------------------
Stiction is a constraint force: inside the zero-velocity band the classical
model (eq. 17) holds the arm still against whatever would accelerate it, up
to F_S.  For the thesis plant that is the applied k_u u; here it is
everything on the arm's right-hand side once the pendulum's reaction is
included: the voltage :math:`F_e` that makes :math:`\ddot\phi = 0` in the
coupled equations (the input, the back-EMF, the arm's damping, the
centrifugal and Coriolis terms and the pendulum's reaction through the mass
matrix), in volts.  With the links at rest and the pendulum upright,
:math:`F_e = u`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .._jit import jit
from ..friction import LUGRE, NONE, friction_step
from ..params import ParamError, Validated, param

__all__ = [
    "HOMEBUILT",
    "PRESETS",
    "PRESET_FRICTION",
    "PRESET_SWINGUP",
    "QUBE2",
    "QUBE2_WORKBOOK",
    "QUBE3",
    "SUBSTEPS",
    "DCRecord",
    "FurutaDCParams",
    "arm_voltage",
    "dc_accelerations",
    "dc_mass_forcing",
    "dc_record",
    "linearization",
    "max_arm_acceleration",
    "mechanical_energy",
    "pendulum_energy",
    "preset",
    "rhs",
    "swing_ratio",
    "tick",
]


@dataclass(frozen=True)
class FurutaDCParams(Validated):
    """Physical parameters of the DC-motor Furuta pendulum (keys ``plant.*``).

    The defaults are the QUBE-Servo 2 (:data:`QUBE2`).  The inertias are
    those of uniform thin rods about their pivots, :math:`J = m L^2/3`, unless
    given.
    """

    _prefix = "plant."

    resistance: float = param(8.4, "motor terminal resistance [R_m]", "ohm", lo=0.0, hi=1e3,
                              lo_open=True)
    torque_constant: float = param(0.042, "motor torque constant [k_t] (at the arm shaft)",
                                   "N m/A", lo=0.0, hi=100.0, lo_open=True)
    emf_constant: float = param(0.042, "motor back-EMF constant [k_m] (at the arm shaft)",
                                "V s/rad", lo=0.0, hi=100.0)
    arm_mass: float = param(0.095, "arm mass [m_r]", "kg", lo=0.0, hi=100.0)
    arm_length: float = param(0.085, "arm length, motor axis to pendulum pivot [L_r]", "m",
                              lo=0.0, hi=10.0, lo_open=True)
    arm_inertia: float | None = param(None, "arm inertia about the motor axis, without the "
                                      "pendulum [J_r] (None = m_r L_r^2/3)", "kg m^2",
                                      lo=0.0, hi=100.0, optional=True)
    rotor_inertia: float = param(0.0, "motor rotor, hub and gearbox inertia at the arm shaft "
                                 "[J_m]", "kg m^2", lo=0.0, hi=100.0)
    pendulum_mass: float = param(0.024, "pendulum mass [m_p]", "kg", lo=0.0, hi=100.0,
                                 lo_open=True)
    pendulum_length: float = param(0.129, "pendulum length, pivot to tip [L_p] (its centre "
                                   "of mass at L_p/2)", "m", lo=0.0, hi=10.0, lo_open=True)
    pendulum_inertia: float | None = param(None, "pendulum inertia about its pivot [J_p] "
                                           "(None = m_p L_p^2/3)", "kg m^2", lo=0.0,
                                           hi=100.0, lo_open=True, optional=True)
    g: float = param(9.81, "gravitational acceleration [g]", "m/s^2", lo=0.0, hi=100.0,
                     lo_open=True)
    arm_damping: float = param(0.00027, "viscous damping of the arm joint [D_r]",
                               "N m s/rad", lo=0.0, hi=100.0)
    pendulum_damping: float = param(0.00005, "viscous damping of the pendulum joint [D_p]",
                                    "N m s/rad", lo=0.0, hi=100.0)
    voltage_limit: float = param(10.0, "the amplifier's voltage limit [V_max]", "V", lo=0.0,
                                 hi=1e3, lo_open=True)
    arm_counts: int = param(2048, "arm encoder counts per revolution", "1/rev", lo=1,
                            hi=1e9, integer=True)
    pendulum_counts: int = param(2048, "pendulum encoder counts per revolution", "1/rev",
                                 lo=1, hi=1e9, integer=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.pendulum_inertia is not None:
            lp = 0.5 * self.pendulum_length
            if self.pendulum_inertia < self.pendulum_mass * lp * lp * (1.0 - 1e-12):
                # the inertia about the pivot is at least the centre of mass's m l^2
                raise ParamError("plant.pendulum_inertia", self.pendulum_inertia,
                                 f"[m_p (L_p/2)^2 = {self.pendulum_mass * lp * lp:g}, 100]")

    @property
    def j_p(self) -> float:
        """Pendulum inertia about its pivot (kg m^2)."""
        if self.pendulum_inertia is not None:
            return float(self.pendulum_inertia)
        return self.pendulum_mass * self.pendulum_length**2 / 3.0

    @property
    def j_0(self) -> float:
        """Arm-side inertia about the motor axis: arm, rotor and the pendulum's
        mass at the tip, :math:`J_r + J_m + m_p L_r^2` (kg m^2)."""
        j_r = (self.arm_mass * self.arm_length**2 / 3.0 if self.arm_inertia is None
               else float(self.arm_inertia))
        return j_r + self.rotor_inertia + self.pendulum_mass * self.arm_length**2

    def record(self) -> np.ndarray:
        """The float row the compiled code reads (:class:`DCRecord`'s order:
        ``j_p, j_0, b, c, kv, k_m, d_r, d_p``; :func:`dc_record` reads it)."""
        lp = 0.5 * self.pendulum_length
        return np.array([
            self.j_p,
            self.j_0,
            self.pendulum_mass * lp * self.arm_length,   # b = m_p l_p L_r
            self.pendulum_mass * self.g * lp,            # c = m_p g l_p
            self.torque_constant / self.resistance,      # kv: N m per V
            self.emf_constant,
            self.arm_damping,
            self.pendulum_damping,
        ], dtype=float)

    @property
    def omega0(self) -> float:
        """Rate of the upright's unstable mode (rad/s): the positive eigenvalue
        of :func:`linearization`'s A (the design's omega_0, Sec. 2.4)."""
        A, _ = linearization(self)
        return float(np.max(np.linalg.eigvals(A).real))


class DCRecord(NamedTuple):
    """The plant as the compiled code reads it (:meth:`FurutaDCParams.record`,
    a float row in this order; :func:`dc_record` builds it inside a kernel)."""

    j_p: float  #: pendulum inertia about its pivot, kg m^2
    j_0: float  #: arm, rotor and pendulum-mass inertia about the motor axis, kg m^2
    b: float    #: m_p l_p L_r, kg m^2
    c: float    #: m_p g l_p, N m
    kv: float   #: k_t / R_m, N m per V
    k_m: float  #: back-EMF constant, V s/rad
    d_r: float  #: arm damping, N m s/rad
    d_p: float  #: pendulum damping, N m s/rad


@jit
def dc_record(row):
    """The :class:`DCRecord` stored as the float row ``row``."""
    return DCRecord(row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7])


@jit
def dc_mass_forcing(sn, cs, thd, ad, volts, r):
    r"""The mass matrix and the forcing of the two links (module docstring).

    Parameters
    ----------
    sn, cs : float
        :math:`\sin\theta, \cos\theta`.
    thd, ad : float
        :math:`\dot\theta, \dot\phi` (rad/s).
    volts : float
        The net motor voltage :math:`u - F` (V).
    r : DCRecord

    Returns
    -------
    (m11, m12, m22, f1, f2)
    """
    m11 = r.j_p
    m12 = r.b * cs
    m22 = r.j_0 + r.j_p * sn * sn
    jsc = r.j_p * sn * cs
    f1 = jsc * ad * ad + r.c * sn - r.d_p * thd
    f2 = (r.kv * (volts - r.k_m * ad) - r.d_r * ad - 2.0 * jsc * thd * ad
          + r.b * sn * thd * thd)
    return m11, m12, m22, f1, f2


@jit
def dc_accelerations(sn, cs, thd, ad, volts, r):
    r"""The links' accelerations and their sensitivities to the voltage.

    Returns
    -------
    (theta_ddot, arm_ddot, g_theta, g_arm)
        At the net voltage ``volts``; a friction F (volts) changes them by
        ``-g_theta F`` and ``-g_arm F`` (the forcing is linear in the voltage).
    """
    m11, m12, m22, f1, f2 = dc_mass_forcing(sn, cs, thd, ad, volts, r)
    inv = 1.0 / (m11 * m22 - m12 * m12)
    return ((m22 * f1 - m12 * f2) * inv, (m11 * f2 - m12 * f1) * inv,
            -m12 * r.kv * inv, m11 * r.kv * inv)


@jit
def arm_voltage(sn, cs, thd, ad, arm_dd, r):
    r"""The voltage that gives the arm the angular acceleration ``arm_dd`` (rad/s^2)
    in the state (theta, theta', arm') with no friction: the coupled equations
    solved for u (the swing-up's inverse of the arm's dynamics).

    Eliminating :math:`\ddot\theta` with the pendulum's row,

    .. math::

        k_v u = \Bigl(m_{22} - \frac{m_{12}^2}{m_{11}}\Bigr)\ddot\phi
                + \frac{m_{12}}{m_{11}} f_1 - f_2\big|_{u=0},

    :math:`k_v = k_t/R_m` (the forcing is linear in u: :func:`dc_mass_forcing`).

    Parameters
    ----------
    sn, cs : float
        :math:`\sin\theta, \cos\theta`.
    thd, ad : float
        :math:`\dot\theta, \dot\phi` (rad/s).
    arm_dd : float
        The arm's angular acceleration asked for (rad/s^2).
    r : DCRecord
    """
    m11, m12, m22, f1, f2 = dc_mass_forcing(sn, cs, thd, ad, 0.0, r)
    q = m12 / m11
    return ((m22 - q * m12) * arm_dd + q * f1 - f2) / r.kv


def _record(params: FurutaDCParams) -> DCRecord:
    return DCRecord(*(float(v) for v in params.record()))


def rhs(t: float, x, u, params: FurutaDCParams) -> np.ndarray:
    """Time derivative of the state (python-control's ``updfcn(t, x, u, params)``).

    Parameters
    ----------
    t : float
        Time (s; unused: the plant is time invariant).
    x : array_like, shape (4,) or (5,)
        State (module table); a 5th entry (LuGre z) is carried with zero
        derivative: the bristle lives in :mod:`frictionlab.model.friction`.
    u : float or array_like of length 2
        Motor voltage u (V), or ``(u, F)`` with the arm friction F in volts.
    params : FurutaDCParams

    Returns
    -------
    numpy.ndarray
        dx/dt, the shape of ``x``.
    """
    x = np.asarray(x, dtype=float)
    u_arr = np.atleast_1d(np.asarray(u, dtype=float))
    volts = float(u_arr[0]) - (float(u_arr[1]) if u_arr.size > 1 else 0.0)
    th = float(x[0])
    th_dd, arm_dd, _, _ = dc_accelerations(math.sin(th), math.cos(th), float(x[1]),
                                           float(x[3]), volts, _record(params))
    dx = np.zeros_like(x)
    dx[0] = x[1]
    dx[1] = th_dd
    dx[2] = x[3]
    dx[3] = arm_dd
    return dx


@jit
def tick(x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """Advance the state ``x`` (5,) in place over one sample h with the voltage u held.

    ``substeps`` equal substeps; in each the friction is evaluated once at
    the substep's start and held (it is discontinuous: a higher order
    *through* it gains nothing), and the smooth two-link dynamics take one
    classical Runge-Kutta (RK4) step with the net voltage u - F.  The
    classical and Stribeck laws see the voltage that would hold the arm
    (module docstring) as their external force, evaluated at the substep's
    start, so inside the zero-velocity band the arm stops accelerating as in
    the thesis plant (docs/model.md).  LuGre's bristle takes the exact update
    at the substep's midpoint velocity predicted with the last friction, and
    with k > 0 the error e = -theta at the predicted midpoint (eq. 19), as in
    :func:`frictionlab.model.plants.thesis.tick`.

    Parameters
    ----------
    x : ndarray (5,)
        ``[theta, theta_dot, arm, arm_dot, z]``, advanced in place.
    u : float
        Motor voltage (V).
    mem : float
        The friction's memory (Coulomb relay state; LuGre: the last friction).
    substeps : int
        Substeps per sample.
    ratio : int
        Unused (the thesis plant's pendulum-step ratio; both links step together here).
    h : float
        Sampling period (s).
    pp : ndarray
        The plant row (:meth:`FurutaDCParams.record`).
    fkind : int
        Friction code (:data:`frictionlab.model.friction.KINDS`).
    fp : record of :data:`frictionlab.model.friction.FRICTION_DTYPE`
        Friction parameters in volts, by reference.

    Returns
    -------
    (mean friction over the sample (V), mem)
    """
    r = dc_record(pp)
    dt = h / substeps
    half = 0.5 * dt
    th, thd, arm, ad, z = x[0], x[1], x[2], x[3], x[4]
    k = fp.k  # read unconditionally (model.friction's docstring, "Reads")
    kgain = k if fkind == LUGRE else 0.0
    f_sum = 0.0
    for _ in range(substeps):
        a1, b1, gth, garm = dc_accelerations(math.sin(th), math.cos(th), thd, ad, u, r)
        if fkind == LUGRE:
            v = ad + half * (b1 - garm * mem)
            e = 0.0
            if kgain != 0.0:
                e = -(th + half * (thd + 0.5 * half * (a1 - gth * mem)))
            f, z = friction_step(LUGRE, fp, z, v, 0.0, dt, e)
            mem = f
        elif fkind == NONE:
            f = 0.0
        else:
            # the voltage that would hold the arm still (b1 - garm F = 0)
            f, mem = friction_step(fkind, fp, mem, ad, b1 / garm, dt, 0.0)
        f_sum += f
        vn = u - f
        k1t, k1d = a1 - gth * f, b1 - garm * f
        t2, td2, ad2 = th + half * thd, thd + half * k1t, ad + half * k1d
        k2t, k2d, _, _ = dc_accelerations(math.sin(t2), math.cos(t2), td2, ad2, vn, r)
        t3, td3, ad3 = th + half * td2, thd + half * k2t, ad + half * k2d
        k3t, k3d, _, _ = dc_accelerations(math.sin(t3), math.cos(t3), td3, ad3, vn, r)
        t4, td4, ad4 = th + dt * td3, thd + dt * k3t, ad + dt * k3d
        k4t, k4d, _, _ = dc_accelerations(math.sin(t4), math.cos(t4), td4, ad4, vn, r)
        s6 = dt / 6.0
        th = th + s6 * (thd + 2.0 * td2 + 2.0 * td3 + td4)
        arm = arm + s6 * (ad + 2.0 * ad2 + 2.0 * ad3 + ad4)
        thd = thd + s6 * (k1t + 2.0 * k2t + 2.0 * k3t + k4t)
        ad = ad + s6 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
    x[0], x[1], x[2], x[3], x[4] = th, thd, arm, ad, z
    return f_sum / substeps, mem


#: Default substeps per sample of :func:`tick` by friction law (``KINDS`` names):
#: at h = 5 ms, 2 keep a classical/Coulomb limit cycle's features within 0.3 %
#: of 100 substeps and the free swing's energy within 1e-8 over 10 s; the LuGre
#: bristle's velocity predictor wants the thesis plant's 6 (docs/model.md).
SUBSTEPS: dict[str, int] = {"none": 2, "viscous": 2, "coulomb": 2, "classical": 2,
                            "stribeck": 2, "lugre": 6}


def linearization(params: FurutaDCParams) -> tuple[np.ndarray, np.ndarray]:
    r"""The continuous linearisation at upright, in closed form.

    States (theta, theta_dot, arm, arm_dot), input u in volts.  With
    :math:`\Delta = J_p J_0 - b^2` and :math:`B_{eq} = D_r + k_t k_m/R_m`:

    .. math::

        A = \frac{1}{\Delta}\begin{pmatrix} 0 & \Delta & 0 & 0 \\
            J_0 c & -J_0 D_p & 0 & b B_{eq} \\ 0 & 0 & 0 & \Delta \\
            -b c & b D_p & 0 & -J_p B_{eq} \end{pmatrix},\quad
        B = \frac{k_t}{R_m\Delta}\begin{pmatrix} 0 \\ -b \\ 0 \\ J_p \end{pmatrix}

    Returns
    -------
    A : ndarray (4, 4)
    B : ndarray (4, 1)
    """
    j_p, j_0, b, c, kv, k_m, d_r, d_p = (float(v) for v in params.record())
    det = j_p * j_0 - b * b
    beq = d_r + kv * k_m
    A = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [j_0 * c / det, -j_0 * d_p / det, 0.0, b * beq / det],
        [0.0, 0.0, 0.0, 1.0],
        [-b * c / det, b * d_p / det, 0.0, -j_p * beq / det],
    ])
    B = np.array([[0.0], [-b * kv / det], [0.0], [j_p * kv / det]])
    return A, B


def pendulum_energy(theta, theta_dot, params: FurutaDCParams):
    r"""The pendulum's energy with the arm at rest,
    :math:`\tfrac12 J_p\dot\theta^2 + c(\cos\theta - 1)` (J): 0 upright at
    rest, :math:`-2c = -m_p g L_p` hanging at rest (the swing-up's target is 0)."""
    lp = 0.5 * params.pendulum_length
    c = params.pendulum_mass * params.g * lp
    return 0.5 * params.j_p * np.square(theta_dot) + c * (np.cos(theta) - 1.0)


def mechanical_energy(x, params: FurutaDCParams) -> float:
    r"""Total mechanical energy of both links (J), 0 upright at rest:
    :math:`\tfrac12\dot q^T M(\theta)\dot q + c(\cos\theta - 1)`.  Conserved
    without damping, friction, back-EMF current or input."""
    th, thd, ad = float(x[0]), float(x[1]), float(x[3])
    m11, m12, m22, _, _ = dc_mass_forcing(math.sin(th), math.cos(th), 0.0, 0.0, 0.0,
                                          _record(params))
    c = params.pendulum_mass * params.g * 0.5 * params.pendulum_length
    return (0.5 * (m11 * thd * thd + 2.0 * m12 * thd * ad + m22 * ad * ad)
            + c * (math.cos(th) - 1.0))


def max_arm_acceleration(params: FurutaDCParams, theta: float = math.pi,
                         volts: float | None = None) -> float:
    """The arm's angular acceleration (rad/s^2) from rest at ``volts``
    (default the voltage limit) with the pendulum at rest at ``theta``
    (default hanging).  It depends on the pendulum's angle through the
    coupling: the voltage's part is largest hanging or upright, smallest with
    the pendulum horizontal (QUBE-Servo 2 at 10 V: 184 and 93 rad/s^2); away
    from those angles gravity's reaction through the coupling adds to it."""
    v = params.voltage_limit if volts is None else volts
    _, arm_dd, _, _ = dc_accelerations(math.sin(theta), math.cos(theta), 0.0, 0.0, float(v),
                                       _record(params))
    return float(arm_dd)


def swing_ratio(params: FurutaDCParams) -> float:
    r"""The swing-up's :math:`n = a_{max}/g`: the arm tip's acceleration from
    rest that the voltage limit gives at every pendulum angle (the voltage's
    part at its minimum, pendulum horizontal: :math:`L_r k_t V_{max}/(R_m (J_0 + J_p))`),
    over g.  Below 4/3 a swing-up needs more than one swing (QUBE-Servo 2:
    0.81; docs/model.md)."""
    a = params.arm_length * params.torque_constant * params.voltage_limit / (
        params.resistance * (params.j_0 + params.j_p))
    return a / params.g


#: Quanser QUBE-Servo 2 (the defaults): the lighter damping of published
#: simulation models (docs/model.md).
QUBE2 = FurutaDCParams()
#: QUBE-Servo 2 with the damping of Quanser's workbook (0.0015 / 0.0005 N m s/rad).
QUBE2_WORKBOOK = dataclasses.replace(QUBE2, arm_damping=0.0015, pendulum_damping=0.0005)
#: Quanser QUBE-Servo 3 (User Manual, Table 2.2: R_m 7.5 ohm, k_t = k_m = 0.0422; the
#: same rotary-pendulum module; damping as QUBE2, an estimate).
QUBE3 = dataclasses.replace(QUBE2, resistance=7.5, torque_constant=0.0422,
                            emf_constant=0.0422)
#: A home-built rig (docs/build-a-rig.md: an Arduino, a 12 V 30:1 gear motor on an
#: H-bridge, 600-line encoders on both axes): an ESTIMATE, not a measured rig.  The
#: motor is Pololu's 37D 30:1 12 V gear motor (items 4742/4752; "37D Metal Gearmotors"
#: datasheet, Rev 1.2: 330 rpm and 0.2 A without load, 140 kg mm and 5.5 A stalled, at
#: 12 V): R_m = 12 V / 5.5 A, k_m = (12 V - 0.2 A R_m) / 34.6 rad/s, k_t = 1.37 N m /
#: (5.5 - 0.2) A at the output shaft (the gearbox's losses in it); the rotor's inertia
#: through the gearbox is not in the datasheet (4e-4 kg m^2: a 10 ms mechanical time
#: constant); links of a 0.15 m arm and a 0.25 m, 30 g rod (docs/model.md, "Presets").
HOMEBUILT = FurutaDCParams(
    resistance=2.2, torque_constant=0.26, emf_constant=0.335, arm_mass=0.06,
    arm_length=0.15, rotor_inertia=4e-4, pendulum_mass=0.03, pendulum_length=0.25,
    arm_damping=0.002, pendulum_damping=0.00005, voltage_limit=12.0, arm_counts=2400,
    pendulum_counts=2400)

#: The presets by name.
PRESETS: dict[str, FurutaDCParams] = {
    "furuta-dc": QUBE2,
    "qube2": QUBE2,
    "qube2-workbook": QUBE2_WORKBOOK,
    "qube3": QUBE3,
    "homebuilt": HOMEBUILT,
}

_QUBE_FRICTION = {"friction.stiction": 0.2, "friction.coulomb": 0.15,
                  "friction.viscous": 0.0, "friction.zero_velocity_band": 0.02}
#: Default friction of each preset (``friction.*`` keys, levels in volts):
#: documented estimates (docs/model.md, "Presets").
PRESET_FRICTION: dict[str, dict[str, float]] = {
    "furuta-dc": dict(_QUBE_FRICTION),
    "qube2": dict(_QUBE_FRICTION),
    "qube2-workbook": dict(_QUBE_FRICTION),
    "qube3": dict(_QUBE_FRICTION),
    # the gear motor's no-load current times R_m (0.2 A x 2.2 ohm), stiction 1.3 times it
    "homebuilt": {"friction.stiction": 0.57, "friction.coulomb": 0.44, "friction.viscous": 0.0,
                  "friction.zero_velocity_band": 0.02},
}


#: The swing-up's defaults on a motor plant (``swingup.*`` keys that differ
#: from the thesis plant's; docs/swingup.md, "The DC-motor plant"): the
#: friction margin in volts (the QUBE's F_C is estimated at 0.15 V; 0.3 V
#: covers the range the Monte Carlo draws), the arm travel the cable to the
#: pendulum module allows (about half a turn either way: 3 rad).
PRESET_SWINGUP: dict[str, float] = {"swingup.friction_margin": 0.3, "swingup.arm_limit": 3.0}


def preset(name: str) -> FurutaDCParams:
    """The preset ``name`` (:data:`PRESETS`)."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"plant must be one of {', '.join(PRESETS)}; got {name!r}") from None
