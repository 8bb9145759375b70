r"""The sampled controller: observers, state feedback and friction compensation.

One tick (Sec. 7.3, process *Regul*): read the measurements, compute
:math:`u = -L\hat x + \hat F` from the *predicted* estimates, saturate it to
the DAC range, output it, then update the observers.  The same compiled
:func:`controller_step` runs inside the simulator and in the 200 Hz loop, so
a logged run can be replayed exactly.

What the observers are fed
--------------------------
The observers model the plant without friction.  Without compensation they
receive the applied u.  With compensation the applied signal is
:math:`u = u_{fb} + \hat F`, and the plant's net acceleration is
:math:`u - F \approx u - \hat F`, so the observers receive
:math:`u - \hat F` (the best available estimate of the net acceleration)
rather than u, which would make them predict an acceleration the
compensation spends on friction.

Controller state (explicit, a numpy structured record of float64 fields)
-------------------------------------------------------------------------
:data:`STATE_DTYPE`; compiled code and Python read and set it by field name
(``s.x1``); numba passes the record by reference, so the compiled step
updates it in place.

====  =============  ==================================================
pos   field          meaning
====  =============  ==================================================
0     ``x1``         pendulum observer :math:`\hat\theta` (rad)
1     ``x2``         pendulum observer :math:`\hat{\dot\theta}/\omega_0`
2     ``arm``        arm observer :math:`\hat\Omega` (rad)
3     ``arm_dot``    arm observer :math:`\hat{\dot\Omega}` (rad/s)
4     ``relay``      compensator relay state (Coulomb) or stick flag
5     ``z_hat``      compensator LuGre bristle estimate :math:`\hat z`
6     ``f_hat``      last friction estimate :math:`\hat F` (m/s^2)
7     ``u``          last applied u (m/s^2)
8     ``v_hat``      adaptive law: predicted arm velocity (rad/s)
9     ``v_prev``     adaptive law: last measured arm velocity (rad/s)
10    ``fc_hat``     adaptive law: estimated Coulomb level (m/s^2)
11    ``fs_hat``     adaptive law: estimated stiction level (m/s^2)
12    ``adapt``      adaptive law: status (:data:`frictionlab.model.adaptive.ADAPT_STATES`;
                     0 = not started: the next tick starts it)
13    ``slide``      adaptive law: distance slid since the arm last stopped (rad)
====  =============  ==================================================

Compensator ``adaptive``: the LuGre observer run with the levels that the
law of :mod:`frictionlab.model.adaptive` estimates from the applied u and the
measured arm velocity (one tick of the law, then the observer, in the same
compiled step).  Zeroing the fields ``relay``, ``z_hat`` and ``v_hat`` to
``slide`` (:func:`reset_compensator`) restarts a compensator from its
parameters.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ._jit import jit, jit_inline, keep_alive
from .adaptive import adaptation_step, check_gains
from .design import Design
from .friction import (
    CLASSICAL,
    COULOMB,
    FRICTION_DTYPE,
    LUGRE,
    STRIBECK,
    FrictionParams,
    friction_step,
    friction_view,
    levels,
    with_levels,
)
from .observers import arm_observer_step, pendulum_observer_step
from .params import ParamError
from .plants.furuta_dc_design import (
    DCDesign,
    dc_observer_update,
    observer_row,
    pendulum_observer_update,
)
from .plants.thesis import PlantParams
from .records import copy_record, float_record_dtype, new_record, record_row, row_record
from .rig import RigScaling

__all__ = [
    "ADAPTIVE",
    "COMPENSATORS",
    "COMPENSATOR_CODES",
    "COMPENSATOR_FIELDS",
    "COMPENSATOR_KINDS",
    "DC_OBSERVER",
    "DC_PENDULUM_OBSERVER",
    "DEFAULT_ERROR_SIGNAL",
    "ERROR_SIGNALS",
    "NS",
    "STATE_DTYPE",
    "STATE_FIELDS",
    "THESIS_OBSERVERS",
    "Controller",
    "ControllerOutput",
    "Gains",
    "arm_prediction",
    "check_compensator",
    "compensator_levels",
    "compensator_params",
    "controller_step",
    "controller_step_rows",
    "controller_tick",
    "copy_state",
    "estimates",
    "gains_record",
    "gains_row",
    "new_state",
    "reset_compensator",
    "state_index",
    "state_record",
    "state_vector",
    "state_view",
    "zero_state",
]

_NEG = {"stiction_negative", "coulomb_negative", "viscous_negative"}
#: The adaptive compensator's law (:mod:`frictionlab.model.adaptive`).
_ADAPT = {"adaptation_gain", "adaptation_bandwidth", "adaptation_deadband", "adaptation_distance",
          "adaptation_max_innovation", "adaptation_min", "adaptation_max"}
#: The friction fields (of :class:`FrictionParams`) each compensator reads.
COMPENSATOR_FIELDS = {
    "none": set(),
    "coulomb": {"coulomb", "coulomb_negative", "hysteresis"},
    "classical": {"stiction", "coulomb", "stribeck_velocity", "hysteresis"}
    | _NEG - {"viscous_negative"},
    "lugre": {"stiction", "coulomb", "viscous", "stribeck_velocity", "sigma0", "sigma1",
              "sigma1_velocity", "observer_gain"} | _NEG,
    "adaptive": {"stiction", "coulomb", "viscous", "stribeck_velocity", "sigma0", "sigma1",
                 "sigma1_velocity", "observer_gain", "viscous_negative"} | _ADAPT,
}

#: Fields of the controller state, in their storage order (see the module table).
STATE_FIELDS = ("x1", "x2", "arm", "arm_dot", "relay", "z_hat", "f_hat", "u",
                "v_hat", "v_prev", "fc_hat", "fs_hat", "adapt", "slide")
#: The controller state's record type: one float64 per field of :data:`STATE_FIELDS`.
STATE_DTYPE = float_record_dtype(STATE_FIELDS)
#: Number of floats in a controller state (its size as a float vector).
NS = len(STATE_FIELDS)
#: The compensator's fields (:func:`reset_compensator` zeroes them).
_COMPENSATOR_STATE = ("relay", "z_hat", "v_hat", "v_prev", "fc_hat", "fs_hat", "adapt", "slide")


def new_state(**values: float) -> np.record:
    """A zeroed controller state record (fields set from ``values``), backed
    by its own one-element array: compiled code updates it in place."""
    return new_record(STATE_DTYPE, **values)


def copy_state(s) -> np.record:
    """An independent copy of a controller state record."""
    return copy_record(s)


def state_vector(s) -> np.ndarray:
    """The controller state as a float vector (fields in :data:`STATE_FIELDS` order)."""
    return record_row(s)


def state_index(name: str) -> int:
    """Position of field ``name`` in :func:`state_vector` (and in :func:`state_view`'s vector)."""
    return STATE_FIELDS.index(name)


@jit_inline
def state_view(x):
    """The controller state record stored in the float vector ``x``
    (:data:`NS` contiguous floats, :data:`STATE_FIELDS` order), by reference:
    setting a field writes ``x``.  Compiled code only."""
    return x.view(STATE_DTYPE)[0]


@jit_inline
def zero_state(s):
    """Zero every field of the controller state record ``s`` in place (compiled
    code too)."""
    s.x1 = 0.0
    s.x2 = 0.0
    s.arm = 0.0
    s.arm_dot = 0.0
    s.relay = 0.0
    s.z_hat = 0.0
    s.f_hat = 0.0
    s.u = 0.0
    s.v_hat = 0.0
    s.v_prev = 0.0
    s.fc_hat = 0.0
    s.fs_hat = 0.0
    s.adapt = 0.0
    s.slide = 0.0


def state_record(x) -> np.record:
    """The controller state record stored in the float64 vector ``x`` (:data:`NS`
    contiguous floats, :data:`STATE_FIELDS` order), by reference: setting a
    field, here or in compiled code, writes ``x``.  (Python side of
    :func:`state_view`; pass a copy for an independent record.)"""
    return row_record(x, STATE_DTYPE)

#: Compensator code of ``adaptive`` (after the friction model codes).
ADAPTIVE = 6
#: Compensator codes by ``--compensation`` name: the one list of compensators.
COMPENSATOR_CODES = {"none": 0, "coulomb": COULOMB, "classical": STRIBECK, "lugre": LUGRE,
                     "adaptive": ADAPTIVE}
#: ``--compensation`` values.
COMPENSATOR_KINDS = tuple(COMPENSATOR_CODES)
#: The compensators of Sec. 6 and the adaptive one (``--compensation`` values
#: other than ``none``).
COMPENSATORS = COMPENSATOR_KINDS[1:]


class Gains(NamedTuple):
    """What the compiled controller step reads besides its state (a typed
    record; :meth:`Controller.record`).

    Attributes
    ----------
    l1, l2, l3, l4 : float
        State feedback :math:`u_{fb} = -(l_1\\hat\\theta + l_2\\hat{\\dot\\theta}
        + l_3\\hat\\Omega + l_4\\hat{\\dot\\Omega})` (the design's L).
    k1, k2, k3, k4 : float
        Observer gains: pendulum (k1, k2) and arm (k3, k4) (the design's K).
    omega0, g, arm_length : float
        The plant parameters the observers model (rad/s, m/s^2, m).
    h : float
        Sampling period (s).
    u_max : float
        Saturation of u (m/s^2).
    compensator : int
        Compensator code (:data:`COMPENSATOR_CODES`; 0 none).
    error_signal : int
        Index in :data:`ERROR_SIGNALS` of the LuGre observer's error e.
    feed_net : float
        1.0: the observers receive :math:`u - \\hat F` (module docstring), 0.0: u.
    comp_weight : float
        The share of the compensator's estimate that is applied (and fed to the
        observers): 1 but while a compensator is being ramped in after a switch
        (:class:`frictionlab.model.switching.Transition`).
    error_weight : float
        The share of the error signal e that the LuGre observer receives: 1 but
        while it is being ramped in after a switch
        (:class:`frictionlab.model.switching.Transition`).
    observer : int
        Which observers: :data:`THESIS_OBSERVERS` (0, the thesis's pendulum
        and arm observers, gains k1..k4) or :data:`DC_OBSERVER` (the DC-motor
        plant's 4-state predictor,
        :func:`frictionlab.model.plants.furuta_dc_design.dc_observer_step`,
        its matrices in ``obs``; the state's ``x2`` then holds
        :math:`\\hat{\\dot\\theta}` itself, ``omega0`` = 1) or
        :data:`DC_PENDULUM_OBSERVER` (the DC-motor plant's pendulum observer
        driven by the measured arm acceleration,
        :func:`~frictionlab.model.plants.furuta_dc_design.pendulum_observer_update`:
        u from this tick's estimate and the measured angles and arm rate; the
        state then holds this tick's estimate and measurements, ``omega0`` = 1).
    obs : tuple of 32 floats
        The DC observer's row (:func:`~frictionlab.model.plants.furuta_dc_design.observer_row`;
        zeros for the thesis's observers).
    """

    l1: float
    l2: float
    l3: float
    l4: float
    k1: float
    k2: float
    k3: float
    k4: float
    omega0: float
    g: float
    arm_length: float
    h: float
    u_max: float
    compensator: int
    error_signal: int
    feed_net: float
    comp_weight: float = 1.0
    error_weight: float = 1.0
    observer: int = 0
    obs: tuple = (0.0,) * 32

    @property
    def feedback(self) -> np.ndarray:
        """The state feedback L = (l1, l2, l3, l4)."""
        return np.array(self[:4])

    @property
    def gains8(self) -> np.ndarray:
        """The state feedback and the observer gains (l1, l2, l3, l4, k1, k2, k3, k4)."""
        return np.array(self[:8])

    def with_gains8(self, g) -> Gains:
        """These gains with L and K replaced by ``g`` (as :attr:`gains8`)."""
        return self._replace(l1=float(g[0]), l2=float(g[1]), l3=float(g[2]), l4=float(g[3]),
                             k1=float(g[4]), k2=float(g[5]), k3=float(g[6]), k4=float(g[7]))

    def with_feedback(self, L) -> Gains:
        """These gains with the state feedback L replaced."""
        return self._replace(l1=float(L[0]), l2=float(L[1]), l3=float(L[2]), l4=float(L[3]))

    def linear(self, saturate: bool = True) -> Gains:
        """These gains without compensator (the observers fed u) and, unless
        ``saturate``, without the saturation of u: the linear loop."""
        return self._replace(compensator=0, feed_net=0.0,
                             u_max=self.u_max if saturate else math.inf)


#: :attr:`Gains.observer` codes: the thesis's pendulum and arm observers; the
#: DC-motor plant's 4-state predictor; its pendulum observer.
THESIS_OBSERVERS, DC_OBSERVER, DC_PENDULUM_OBSERVER = 0, 1, 2
#: Length of :attr:`Gains.obs`.
OBS_LEN = 32


@jit
def gains_record(row):
    """The :class:`Gains` stored as the float row :func:`gains_row`."""
    r = row
    obs = (r[19], r[20], r[21], r[22], r[23], r[24], r[25], r[26], r[27], r[28], r[29],
           r[30], r[31], r[32], r[33], r[34], r[35], r[36], r[37], r[38], r[39], r[40],
           r[41], r[42], r[43], r[44], r[45], r[46], r[47], r[48], r[49], r[50])
    return Gains(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11],
                 r[12], int(r[13]), int(r[14]), r[15], r[16], r[17], int(r[18]), obs)


#: Candidate error signals e for the LuGre compensator's observer, eq. (19):
#: ``none`` (e = 0, the plain model driven by the measured velocity),
#: ``velocity_innovation`` (measured minus predicted arm velocity),
#: ``position_innovation`` (measured minus predicted arm angle),
#: ``arm_velocity`` and ``arm_angle`` (the arm's control errors, the latter the
#: position error of Canudas de Wit et al. 1995).  docs/compensation.md
#: compares them; only the innovations keep the loop up, and the velocity
#: innovation is best on reduction, robustness and chatter, hence the default.
ERROR_SIGNALS = ("none", "velocity_innovation", "position_innovation", "arm_velocity",
                 "arm_angle")
E_NONE, E_VEL_INNOV, E_POS_INNOV, E_ARM_VEL, E_ARM_ANGLE = range(5)
#: The error signal chosen by the comparison in docs/compensation.md.
DEFAULT_ERROR_SIGNAL = "velocity_innovation"


@jit
def compensator_force(kind, s, cp, v, u_fb, e, h):
    """Friction estimate of the compensator (Sec. 6.1-6.3) for the coming sample.

    The compensators are the plant's friction laws
    (:func:`frictionlab.model.friction.friction_step`) run with the
    compensator's own parameters on the measured arm velocity: ``COULOMB``
    the relay (state ``relay``  ), ``STRIBECK`` the classical model's
    implementation form of Sec. 6.2 (the external force it balances inside
    the band is the feedback signal ``u_fb``; memoryless), ``LUGRE`` the
    observer of eq. (19) over the sample (state ``z_hat`` ).

    Parameters
    ----------
    kind : int
        Compensator code (0 none, ``COULOMB``, ``STRIBECK`` for the classical
        implementation form, ``LUGRE``).
    s : record of :data:`STATE_DTYPE`
        Controller state (fields ``relay`` and ``z_hat`` are updated in place).
    cp : record of :data:`~frictionlab.model.friction.FRICTION_DTYPE`
        The compensator's friction parameters (:func:`compensator_params`).
    v : float
        Measured arm velocity (rad/s).
    u_fb : float
        Feedback control signal (the external force the classical form uses
        inside the band).
    e : float
        Error signal of the LuGre observer.
    h : float
        Sampling period.
    """
    if kind == CLASSICAL:
        kind = STRIBECK
    if kind == LUGRE:
        f, s.z_hat = friction_step(LUGRE, cp, s.z_hat, v, u_fb, h, e)
        return f
    if kind == COULOMB:
        f, s.relay = friction_step(COULOMB, cp, s.relay, v, u_fb, h, e)
        return f
    if kind == STRIBECK:
        f, _ = friction_step(STRIBECK, cp, 0.0, v, u_fb, h, e)
        return f
    return 0.0


@jit
def adaptive_force(s, cp, v, e, h, arm_len, u_max):
    """The ``adaptive`` compensator's estimate for the coming sample.

    One tick of :func:`frictionlab.model.adaptive.adaptation_step` (its state in
    ``s``, with the last applied u in ``u``  ), then the LuGre observer of
    eq. (19) (:func:`frictionlab.model.friction.friction_step`) with the adapted
    levels (both directions) in place of the compensator's
    ``coulomb``/``stiction``.  Updates ``s`` in place.
    """
    st, fc, fs, vh, slide = adaptation_step(s.adapt, s.fc_hat, s.fs_hat, s.v_hat,
                                            s.v_prev, s.slide, s.u, v, cp, h,
                                            arm_len, u_max)
    s.slide = slide
    s.adapt = st
    s.fc_hat = fc
    s.fs_hat = fs
    s.v_hat = vh
    s.v_prev = v
    # the adapted law's parameters, in a scratch record (as the copy it replaced)
    adapted = np.empty(1, FRICTION_DTYPE)
    f, s.z_hat = friction_step(LUGRE, with_levels(cp, fc, fs, adapted[0]), s.z_hat, v, 0.0, h,
                               e)
    keep_alive(adapted)  # a record does not hold its array
    return f


@jit_inline
def estimates(s, gp):
    """The estimates the controller state ``s`` holds before its tick:
    :math:`(\\hat\\theta, \\hat{\\dot\\theta}, \\hat\\Omega,
    \\hat{\\dot\\Omega}, \\hat z)` (rad, rad/s, rad, rad/s, the LuGre
    compensator's bristle)."""
    return s.x1, gp.omega0 * s.x2, s.arm, s.arm_dot, s.z_hat


@jit
def compensator_levels(s, gp, cp):
    """The Coulomb and stiction levels the compensator uses: the adaptive
    compensator's estimates (state ``fc_hat``  , ``fs_hat``  ), a fixed
    compensator's own ``coulomb``/``stiction``, (0, 0) without compensation."""
    if gp.compensator == ADAPTIVE:
        return s.fc_hat, s.fs_hat
    if gp.compensator == 0:
        return 0.0, 0.0
    return levels(cp)


def compensator_params(params: FrictionParams) -> np.record:
    """The friction record a compensator runs with (:func:`compensator_force`).

    Those of ``params``, except that the classical compensator's band is its
    hysteresis :math:`\\varepsilon` alone (Sec. 6.2): the plant's
    ``zero_velocity_band`` (Sec. 5.2) is not a compensator setting and is
    set to 0, so that with :math:`\\varepsilon = 0` only v = 0 counts as rest.
    """
    # (not a replaced, re-validated copy: a sweep packs every set)
    return params.record(zero_velocity_band=0.0)


def reset_compensator(s: np.record) -> None:
    """Zero the compensator's entries of a controller state (relay, bristle,
    adaptive law): the next tick starts the compensator afresh."""
    for name in _COMPENSATOR_STATE:
        setattr(s, name, 0.0)


@jit_inline
def arm_prediction(s, gp):
    """The arm's angle and rate this tick as the plant's linear model predicts
    them from the last tick's state in ``s`` (its estimate of theta and
    theta_dot, the measured arm angle and rate) and the net voltage applied
    since (u - F_hat with a compensator): rows 2 and 3 of Phi and Gamma in
    ``gp.obs`` (:func:`~frictionlab.model.plants.furuta_dc_design.observer_row`).

    The pendulum observer predicts no arm motion, so this is what the
    compensators' innovations compare the measurements with: the arm gets
    u - F, the prediction u - F_hat, and the difference is the friction's
    estimation error (the role the thesis's arm observer plays, Sec. 6.3).
    """
    o = gp.obs
    un = s.u - s.f_hat if gp.feed_net != 0.0 else s.u
    a = o[8] * s.x1 + o[9] * s.x2 + o[10] * s.arm + o[11] * s.arm_dot + o[18] * un
    ad = o[12] * s.x1 + o[13] * s.x2 + o[14] * s.arm + o[15] * s.arm_dot + o[19] * un
    return a, ad


@jit
def controller_step(s, gp, cp, theta_m, arm_m, arm_dot_m):
    """One controller tick; updates the state record ``s`` in place.

    Parameters
    ----------
    s : record of :data:`STATE_DTYPE`
        Controller state (see the module table).
    gp : Gains
        Gains (:meth:`Controller.record`).
    cp : record of :data:`~frictionlab.model.friction.FRICTION_DTYPE`
        The compensator's friction parameters (:func:`compensator_params`), by
        reference.
    theta_m, arm_m, arm_dot_m : float
        Measured pendulum angle, arm angle (rad) and arm velocity (rad/s).

    Returns
    -------
    (u, u_fb, F_hat) : applied control, feedback part, friction estimate.
    """
    return controller_tick(s, gp, cp, theta_m, arm_m, arm_dot_m, gp.observer)


@jit_inline
def controller_tick(s, gp, cp, theta_m, arm_m, arm_dot_m, observer):
    """:func:`controller_step` with the observers' code ``observer`` (``gp.observer``)
    given: a loop that passes a constant (:data:`THESIS_OBSERVERS`) compiles the
    other observers' branches out of its tick."""
    w0 = gp.omega0
    h = gp.h
    th_hat = s.x1
    thd_hat = w0 * s.x2
    arm_hat = s.arm
    armd_hat = s.arm_dot
    current = observer == DC_PENDULUM_OBSERVER
    if current:
        # this tick's estimate first (the arm's acceleration over the last tick
        # from its measured rate); the compensator's innovations below compare
        # with the last tick's measurements (s.arm, s.arm_dot)
        th_hat, thd_hat = pendulum_observer_update(th_hat, thd_hat, theta_m,
                                                   (arm_dot_m - armd_hat) / h, gp.obs)
        u_fb = -(gp.l1 * theta_m + gp.l2 * thd_hat + gp.l3 * arm_m + gp.l4 * arm_dot_m)
    else:
        u_fb = -(gp.l1 * th_hat + gp.l2 * thd_hat + gp.l3 * arm_hat + gp.l4 * armd_hat)
    kind = gp.compensator
    f_hat = 0.0
    if kind != 0:
        err = gp.error_signal
        e = 0.0
        if current and (err == E_VEL_INNOV or err == E_POS_INNOV):
            # no observer predicts the arm: the innovations against the
            # model's one-tick prediction from the last tick's state and net
            # voltage (arm_prediction)
            arm_hat, armd_hat = arm_prediction(s, gp)
        if err == E_VEL_INNOV:
            e = arm_dot_m - armd_hat
        elif err == E_POS_INNOV:
            e = arm_m - arm_hat
        elif err == E_ARM_VEL:
            e = arm_dot_m
        elif err == E_ARM_ANGLE:
            e = arm_m
        e *= gp.error_weight  # ramped in after a switch (model.switching)
        if kind == ADAPTIVE:
            f_hat = adaptive_force(s, cp, arm_dot_m, e, h, gp.arm_length, gp.u_max)
        else:
            f_hat = compensator_force(kind, s, cp, arm_dot_m, u_fb, e, h)
        f_hat *= gp.comp_weight
    u = u_fb + f_hat
    umax = gp.u_max
    if u > umax:
        u = umax
    elif u < -umax:
        u = -umax
    u_obs = u - f_hat if gp.feed_net != 0.0 else u
    if current:
        x1n, x2n, an, adn = th_hat, thd_hat, arm_m, arm_dot_m
    elif observer == DC_OBSERVER:
        x1n, x2n, an, adn = dc_observer_update(th_hat, thd_hat, arm_hat, armd_hat, theta_m,
                                               arm_m, arm_dot_m, u_obs, gp.obs)
    else:
        x1n, x2n = pendulum_observer_step(s.x1, s.x2, theta_m, armd_hat, u_obs, gp.k1,
                                          gp.k2, w0, gp.g, h)
        an, adn = arm_observer_step(arm_hat, armd_hat, arm_m, u_obs, gp.k3, gp.k4, h,
                                    gp.arm_length)
    s.x1 = x1n
    s.x2 = x2n
    s.arm = an
    s.arm_dot = adn
    s.f_hat = f_hat
    s.u = u
    return u, u_fb, f_hat


@jit
def controller_step_rows(x, g, cp, theta_m, arm_m, arm_dot_m):
    """:func:`controller_step` on the state stored in the float vector ``x``
    (:func:`state_vector`; updated in place) and the gains stored as the float
    row ``g`` (:func:`gains_row`) and the compensator's friction record stored
    as the float row ``cp`` (:func:`frictionlab.model.friction.friction_row`):
    the form for a caller in Python at every tick (the 200 Hz loop).  Numba
    takes float arrays from Python in about 1 us; typing a state record and a
    :class:`Gains` argument costs about ten per call, and reading a record's
    field from Python about seven."""
    return controller_step(state_view(x), gains_record(g), friction_view(cp), theta_m, arm_m,
                           arm_dot_m)


def gains_row(gains: Gains) -> np.ndarray:
    """The :class:`Gains` as the float row :func:`gains_record` reads back (its
    fields in order, :attr:`Gains.obs` spread over the last 32)."""
    return np.array([*gains[:-1], *gains.obs], dtype=float)


@dataclass(frozen=True)
class ControllerOutput:
    """What one tick produced (all SI); ``coulomb_hat``/``stiction_hat`` are the
    adaptive compensator's estimates (NaN for the others)."""

    u: float
    u_feedback: float
    friction_estimate: float
    theta_hat: float
    theta_dot_hat: float
    arm_hat: float
    arm_dot_hat: float
    z_hat: float
    coulomb_hat: float = float("nan")
    stiction_hat: float = float("nan")


@dataclass(frozen=True)
class Controller:
    """State feedback with observers and an optional friction compensator.

    Parameters
    ----------
    design : Design or DCDesign
        Gains from :func:`frictionlab.model.design.design`, or for the DC-motor
        plant :func:`frictionlab.model.plants.furuta_dc_design.dc_design`
        (u in volts; its pendulum observer, or with ``design.full_observer``
        its 4-state predictor, in place of the thesis's pendulum and arm
        observers).
    compensation : str
        ``none``, ``coulomb``, ``classical`` (Sec. 6.2's implementation form),
        ``lugre`` (the observer eq. 19) or ``adaptive`` (eq. 19 with levels
        adapted online, :mod:`frictionlab.model.adaptive`).
    compensation_params : FrictionParams
        The compensator's own friction model.
    error_signal : str
        The LuGre observer's error e (one of :data:`ERROR_SIGNALS`).
    u_max : float
        Saturation of u (default the DAC's range with the default ``rig.u_scale``,
        App. B: 1/0.022 m/s^2).
    feed_net : bool
        Feed the observers ``u - F_hat`` (see the module docstring).
    """

    design: Design | DCDesign
    compensation: str = "none"
    compensation_params: FrictionParams = dataclasses.field(
        default_factory=lambda: FrictionParams.defaults("lugre", "compensation"))
    error_signal: str = DEFAULT_ERROR_SIGNAL
    u_max: float = dataclasses.field(default_factory=lambda: RigScaling().u_max)
    feed_net: bool = True

    def __post_init__(self) -> None:
        if self.compensation not in COMPENSATOR_KINDS:
            raise ValueError(f"compensation must be one of {', '.join(COMPENSATOR_KINDS)}; "
                             f"got {self.compensation!r}")
        if self.error_signal not in ERROR_SIGNALS:
            raise ValueError(f"error_signal must be one of {', '.join(ERROR_SIGNALS)}; "
                             f"got {self.error_signal!r}")
        if not self.u_max > 0:
            raise ValueError(f"u_max must be > 0, got {self.u_max}")

    @property
    def compensator_code(self) -> int:
        return COMPENSATOR_CODES[self.compensation]

    def record(self) -> tuple[Gains, np.record]:
        """The compiled step's arguments: the :class:`Gains` record and the
        compensator's friction record (:func:`compensator_params`)."""
        d = self.design
        L = [float(x) for x in d.L]
        feed_net = 1.0 if (self.feed_net and self.compensation != "none") else 0.0
        if isinstance(d, DCDesign):
            # the 4-state predictor (its matrices in obs); theta_dot_hat held as
            # itself (omega0 1); arm_length the input length of the adaptive
            # law's velocity predictor (arm acceleration = (u - F)/length)
            gains = Gains(*L, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0 / float(d.B[3, 0]),
                          float(d.spec.h), float(self.u_max), int(self.compensator_code),
                          ERROR_SIGNALS.index(self.error_signal), feed_net,
                          observer=DC_OBSERVER if d.full_observer else DC_PENDULUM_OBSERVER,
                          obs=tuple(float(v) for v in observer_row(d)))
            return gains, compensator_params(self.compensation_params)
        K = [float(x) for x in d.K]
        gains = Gains(*L, *K, float(d.spec.omega0), float(d.g), float(d.arm_length),
                      float(d.spec.h), float(self.u_max), int(self.compensator_code),
                      ERROR_SIGNALS.index(self.error_signal), feed_net)
        return gains, compensator_params(self.compensation_params)

    def init(self, theta0: float = 0.0) -> np.record:
        """Initial state (a :data:`STATE_DTYPE` record): the observers start
        at the first measured angle, at rest."""
        return new_state(x1=theta0)

    def step(self, state: np.record, theta_m: float, arm_m: float, arm_dot_m: float):
        """One tick: ``(output, next_state)``; ``state`` is not modified."""
        s = copy_state(state)
        gp, cp = self.record()
        est = (s.x1, gp.omega0 * s.x2, s.arm, s.arm_dot)
        u, u_fb, f_hat = controller_step(s, gp, cp, theta_m, arm_m, arm_dot_m)
        adapted = ((float(s.fc_hat), float(s.fs_hat)) if self.compensation == "adaptive"
                   else (float("nan"), float("nan")))
        out = ControllerOutput(float(u), float(u_fb), float(f_hat), *map(float, est),
                               float(s.z_hat), *adapted)
        return out, s


def check_compensator(kind: str, params: FrictionParams, *, h: float | None = None,
                      arm_length: float | None = None) -> None:
    """Reject a compensator model that the compensator cannot run.

    The LuGre observer of eq. (19) divides by :math:`g(v) = s(v)/\\sigma_0`
    with the Stribeck level :math:`s(v) = F_C + (F_S - F_C)e^{-(v/v_S)^2}`.
    With :math:`F_S = F_C = 0` (for :math:`v \\ge 0`, or with the
    ``*_negative`` levels for :math:`v < 0`) :math:`s` vanishes for every v
    and the observer is singular.  The ``adaptive`` compensator must also
    meet its law's stability conditions
    (:func:`frictionlab.model.adaptive.check_gains`, with ``h`` and
    ``arm_length``: default the thesis's 5 ms and 0.21 m).  The other
    compensators accept any valid :class:`FrictionParams`.

    Parameters
    ----------
    kind : str
        ``none`` or one of :data:`COMPENSATORS`.
    params : FrictionParams
        The compensator's model (keys ``compensation.*``).
    h : float, optional
        Sampling period (``design.h``), s; read by ``adaptive`` only.
    arm_length : float, optional
        :math:`L_1` (``plant.arm_length``), m; read by ``adaptive`` only.

    Raises
    ------
    ParamError
        Naming the ``compensation.*`` key at fault (``field``) and what is
        allowed; the message of a vanishing level names both levels.
    """
    if kind == "adaptive":
        check_gains(params, 0.005 if h is None else h,
                    PlantParams().arm_length if arm_length is None else arm_length)
    if kind not in ("lugre", "adaptive"):
        return
    fs_neg = params.stiction if params.stiction_negative is None else params.stiction_negative
    fc_neg = params.coulomb if params.coulomb_negative is None else params.coulomb_negative
    for side, fs, fc in (("", params.stiction, params.coulomb), ("_negative", fs_neg, fc_neg)):
        if fs == 0 and fc == 0:
            raise ParamError(
                f"compensation.stiction{side}", fs,
                f"> 0 when compensation.coulomb{side} is 0",
                f"compensation.stiction{side} and compensation.coulomb{side} are both 0: "
                f"the LuGre compensator's g(v) = s(v)/sigma0 vanishes and eq. (19) is "
                f"singular; set at least one of them > 0")
