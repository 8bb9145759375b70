r"""Friction models of the arm bearing (Sec. 3, 6.1-6.3).

All friction levels are in the units of the control signal u (m/s^2, i.e.
the thesis's :math:`F_{fr}/m`); velocities are the arm angular velocity
:math:`\dot\Omega` in rad/s.  A positive force opposes a positive velocity;
the plant's net arm acceleration is :math:`k_u u - F` (eq. 5).

Models
------
``none``
    No friction.
``viscous``
    :math:`F = F_v v`.
``coulomb``
    Pure Coulomb relay with hysteresis :math:`\pm\varepsilon` (Sec. 6.1):
    the relay output :math:`s\in\{-1, 0, +1\}` switches to +1 when
    :math:`v > \varepsilon`, to -1 when :math:`v < -\varepsilon`, and keeps its
    previous value in between; :math:`F = F_C s`.  With :math:`\varepsilon = 0`
    it is the ideal relay :math:`F_C\,\mathrm{sgn}(v)`.  ``s`` is memory and
    belongs to the caller's state.
``classical``
    Stiction plus Coulomb friction, eq. (17).  Simulation needs a finite
    "zero velocity" band (Sec. 5.2): speeds with :math:`|v| <` ``zero_velocity_band``
    count as rest, where the friction balances the external force
    :math:`F_e` up to the stiction level :math:`F_S`.
``stribeck``
    The classical model's "implementation form" of Sec. 6.2: outside the band
    the level decays exponentially from :math:`F_S` to :math:`F_C` (the Stribeck
    curve), inside the band the friction balances :math:`F_e`, limited to
    :math:`\pm F_S` (the thesis writes ``F = u``; the limit keeps the friction
    physical and only matters when :math:`|F_e| > F_S`).  The band half-width is
    ``hysteresis`` (:math:`\varepsilon`, as in Sec. 6.2) when given, else
    ``zero_velocity_band``.
``lugre``
    The LuGre model, eq. (18), with the observer correction of eq. (19):

    .. math::

        \dot z = v - \frac{|v|}{g(v)} z - k e,\quad
        g(v) = \frac{F_C + (F_S - F_C) e^{-(v/v_S)^2}}{\sigma_0},\quad
        F = \sigma_0 z + \sigma_1(v)\dot z + F_v v

    ``observer_gain`` is :math:`k` (0 gives the plain eq. 18, bit for bit).
    Eq. (19) names the control error as its :math:`e`.  In the simulated
    plant that is the balancing loop's error, reference minus output,
    :math:`e = 0 - \theta = -\theta` with the true (continuous) pendulum
    angle, so the term :math:`-k e = +k\theta` drives the bristle: that is
    how the thesis's Sec. 5.3 / App. F simulations used k (docs/model.md,
    "The observer gain k in the plant").  In the compensator e is an
    estimation error that the controller feeds (see
    :mod:`frictionlab.model.controller`).  Optional
    variants: direction-dependent :math:`F_S, F_C, F_v` (``*_negative``
    fields, used for :math:`v < 0`) and the velocity-dependent damping
    :math:`\sigma_1(v) = \sigma_1 e^{-(v/v_d)^2}` of Sec. 3.3 (``sigma1_velocity``
    = :math:`v_d`).

Drift
-----
``drift`` (with ``drift_start``, ``drift_time``) makes the *plant's* levels
F_S, F_C, F_v (both directions) change linearly in time, or in a step, over a
run (App. E.1: the friction changes as the rig warms up):
:func:`drift_factor`, applied by the simulator through
:func:`drifted_params`.  The ``adaptation_*`` fields belong to the adaptive
compensator (:mod:`frictionlab.model.adaptive`).

One interface
-------------
Every model is one compiled step, :func:`friction_step` ``(kind, p, state, v,
f_ext, dt, e) -> (F, state)`` over a friction record ``p`` (a numpy
structured record of :data:`FRICTION_DTYPE`, made once by
:meth:`FrictionParams.record` and passed by reference; the laws read its
fields by name, ``p.fc``); it is the only place each law is evaluated:
the simulator's plant (:func:`frictionlab.model.plants.plant_step`), the
compensators (:func:`frictionlab.model.controller.compensator_force`, with the
compensator's own parameters) and the model objects all call it.  The
Stribeck level :math:`F_C + (F_S - F_C)e^{-(v/v_S)^2}` is written once, in
:func:`stribeck_level`.  For interactive use each model is a small frozen
object with the same two methods, ``init() -> state`` and ``step(state, v,
f_ext, dt, e=0.0) -> (F, state)``, plus ``steady_state(v)`` (the compiled
:func:`steady_state` of its law)
(:class:`NoFriction`, :class:`Viscous`, :class:`Coulomb`, :class:`Classical`,
:class:`Stribeck`, :class:`LuGre`; :func:`make_model` builds one).  Their
parameters are one validated :class:`FrictionParams` (the ``friction.*`` /
``compensation.*`` keys); each model reads the fields listed above.

Reads: a law reads every field it may need before it branches.  Numba passes
a record as a pointer, and a read under a condition cannot leave the
simulator's substep loop (the pointer is not known to be readable there),
while an unconditional one can; reading the classical model's levels inside
its branches made a 30 s classical run 16 % slower than with the packed
vector.  The small laws that the substep loop runs (``classical_force``,
``stribeck_classical_force``, ``coulomb_relay``, ``viscous_force``,
``_sgn``) are inlined into their caller (``jit_inline``): called, they left
the classical run 5-9 % slower than with the vector; inlined, 2-4 % faster
(docs/performance.md).

Where parameters have to be a float vector (a batch's per-set rows, a caller
in Python that steps every tick: numba types a record argument from Python
on every call, about 10 us against 1 us for an array), :func:`friction_row`
flattens the record and :func:`friction_view` (compiled) /
:func:`friction_record` (Python) views such a row as the record, once, where
the kernel starts.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ._jit import jit, jit_inline
from .params import Validated, param
from .records import copy_record, float_record_dtype, record_row, row_record

__all__ = [
    "FRICTION_DTYPE",
    "FRICTION_FIELDS",
    "KINDS",
    "MODELS",
    "Classical",
    "Coulomb",
    "FrictionModel",
    "FrictionParams",
    "LuGre",
    "NoFriction",
    "Stribeck",
    "Viscous",
    "adaptation_settings",
    "classical_force",
    "copy_friction",
    "copy_friction_into",
    "coulomb_relay",
    "drift_factor",
    "drifted_params",
    "drifted_rows",
    "friction_record",
    "friction_row",
    "friction_step",
    "friction_view",
    "is_drifting",
    "levels",
    "lugre_dz",
    "lugre_force",
    "lugre_step_exact",
    "make_model",
    "resolve_drift",
    "steady_bristle",
    "steady_state",
    "stribeck_curve",
    "stribeck_level",
    "stribeck_magnitude",
    "stribeck_weight",
    "viscous_force",
    "with_levels",
    "without_drift",
]

#: Integer codes of the friction models (index = code).
KINDS = ("none", "viscous", "coulomb", "classical", "stribeck", "lugre")
NONE, VISCOUS, COULOMB, CLASSICAL, STRIBECK, LUGRE = range(6)

_TINY = 1e-12  # floor of the Stribeck level in divisions (F_S = F_C = 0: no friction)

#: Fields of the friction record :data:`FRICTION_DTYPE`, in storage order, with
#: the :class:`FrictionParams` field each holds (see :meth:`FrictionParams.record`).
FRICTION_FIELDS = (
    "fs",                # stiction
    "fc",                # coulomb
    "fv",                # viscous
    "vs",                # stribeck_velocity
    "sigma0",            # sigma0
    "sigma1",            # sigma1
    "k",                 # observer_gain
    "band",              # zero_velocity_band (0 in a compensator's record)
    "eps",               # hysteresis
    "fs_neg",            # stiction_negative (stiction when None)
    "fc_neg",            # coulomb_negative (coulomb when None)
    "fv_neg",            # viscous_negative (viscous when None)
    "vd",                # sigma1_velocity (inf when None: constant sigma_1)
    "drift",             # drift
    "drift_start",       # drift_start
    "drift_time",        # drift_time (NaN when None: to the end of the run)
    "adapt_gain",        # adaptation_gain
    "adapt_bandwidth",   # adaptation_bandwidth
    "adapt_deadband",    # adaptation_deadband
    "adapt_innovation",  # adaptation_max_innovation
    "adapt_min",         # adaptation_min
    "adapt_max",         # adaptation_max
    "adapt_distance",    # adaptation_distance
)
#: The friction parameters' record type, one float64 per field of
#: :data:`FRICTION_FIELDS`: what the compiled force laws read (``p.fc``).  Its
#: scalar type is ``np.record``, so that in Python too an element of an array
#: of it (a view of a float row) is a record with its fields as attributes.
FRICTION_DTYPE = float_record_dtype(FRICTION_FIELDS)
#: Number of floats in a friction record (its size as a float row).
NP = len(FRICTION_FIELDS)


@dataclass(frozen=True)
class FrictionParams(Validated):
    """Parameters of every friction model (keys ``friction.*`` / ``compensation.*``).

    Each model reads the fields it needs (see the module docstring); the
    defaults are the thesis values (eq. 20, eq. 21, App. E).  Use
    :meth:`defaults` for the per-model defaults of the plant or the
    compensator.
    """

    _prefix = "friction."

    stiction: float = param(2.3, "stiction level [F_S]", "m/s^2", lo=0.0, hi=1e3)
    coulomb: float = param(1.5, "Coulomb friction level [F_C]", "m/s^2", lo=0.0, hi=1e3)
    viscous: float = param(0.07, "viscous coefficient [F_v] (LuGre, viscous)", "m/s^2/(rad/s)",
                           lo=0.0, hi=1e3)
    stribeck_velocity: float = param(1.0, "Stribeck velocity [v_S]", "rad/s", lo=0.0, hi=1e3,
                                     lo_open=True)
    sigma0: float = param(100.0, "LuGre bristle stiffness [sigma_0]", "1/s^2", lo=0.0, hi=1e7,
                          lo_open=True)
    sigma1: float = param(5.0, "LuGre bristle damping [sigma_1]", "1/s", lo=0.0, hi=1e5)
    observer_gain: float = param(0.0, "LuGre observer gain [k] of eq. (19); the plant's "
                                 "error is e = -theta (rad)", "1/s (plant; 1 for a velocity "
                                 "error)", lo=0.0, hi=1e4)
    zero_velocity_band: float = param(0.001, "classical model: |v| below this counts as rest "
                                      "(Sec. 5.2)", "rad/s", lo=0.0, hi=10.0)
    hysteresis: float = param(0.0, "Coulomb/Stribeck-classical hysteresis half-width "
                              "[epsilon] (Sec. 6.1-6.2)", "rad/s", lo=0.0, hi=10.0)
    stiction_negative: float | None = param(None, "F_S for v < 0 (asymmetric variant; None = "
                                            "same as stiction)", "m/s^2", lo=0.0, hi=1e3,
                                            optional=True)
    coulomb_negative: float | None = param(None, "F_C for v < 0 (asymmetric variant)", "m/s^2",
                                           lo=0.0, hi=1e3, optional=True)
    viscous_negative: float | None = param(None, "F_v for v < 0 (asymmetric variant)",
                                           "m/s^2/(rad/s)", lo=0.0, hi=1e3, optional=True)
    sigma1_velocity: float | None = param(None, "v_d of sigma_1(v) = sigma_1 exp(-(v/v_d)^2) "
                                          "(None = constant sigma_1)", "rad/s", lo=0.0,
                                          hi=1e3, lo_open=True, optional=True)
    drift: float = param(0.0, "plant only: relative change of the friction levels F_S, F_C, "
                         "F_v (both directions) over the drift time, linear in time (-0.4 = "
                         "40 % lower at the end; App. E.1: the lubricant warms up)", "1",
                         lo=-1.0, hi=10.0)
    drift_start: float = param(0.0, "plant only: when the drift begins", "s", lo=0.0, hi=1e5)
    drift_time: float | None = param(None, "plant only: how long the drift takes (None = to "
                                     "the end of the run; 0 = a step at drift_start)", "s",
                                     lo=0.0, hi=1e5, optional=True)
    adaptation_gain: float = param(200.0, "adaptive compensator: gradient gain [gamma] of the "
                                   "level estimates (0 = no adaptation); stable for "
                                   "gamma h^2 / L_1 < 4 - 2 lambda h",
                                   "m/(rad s^2)", lo=0.0, hi=1e7)
    adaptation_bandwidth: float = param(20.0, "adaptive compensator: bandwidth [lambda] of its "
                                        "arm-velocity predictor; stable for lambda h < 2",
                                        "1/s", lo=0.0, hi=1e5, lo_open=True)
    adaptation_deadband: float = param(0.1, "adaptive compensator: adaptation frozen while "
                                       "|arm velocity| is below this (stuck arm)", "rad/s",
                                       lo=0.0, hi=100.0)
    adaptation_distance: float = param(0.1, "adaptive compensator: adaptation frozen until "
                                       "the arm has slid this far since it last stopped or "
                                       "reversed (pre-sliding: the bristles settle within a "
                                       "few s(v)/sigma_0)", "rad", lo=0.0, hi=100.0)
    adaptation_max_innovation: float = param(1.0, "adaptive compensator: adaptation frozen "
                                             "while the velocity prediction error exceeds "
                                             "this (a bad signal)", "rad/s", lo=0.0, hi=1e3,
                                             lo_open=True)
    adaptation_min: float = param(0.05, "adaptive compensator: lower bound of the estimated "
                                  "F_C and F_S", "m/s^2", lo=0.0, hi=1e3, lo_open=True)
    adaptation_max: float = param(6.0, "adaptive compensator: upper bound of the estimated "
                                  "F_C and F_S", "m/s^2", lo=0.0, hi=1e3, lo_open=True)

    @staticmethod
    def defaults(kind: str, role: str = "plant") -> FrictionParams:
        """Thesis defaults of ``kind`` for the plant or the compensator.

        Parameters
        ----------
        kind : str
            One of :data:`KINDS`.
        role : {"plant", "compensation"}
            ``compensation`` gives the settings Sec. 6 found best on the rig:
            Coulomb eps 0.05 (F_C 1.5); classical F_S 2.3, F_C 1.55, v_S 1,
            eps 0.08; LuGre F_S 2.3, F_C 1.55, F_v 0.07, sigma0 300, sigma1 6,
            v_S 1, k 7.  ``adaptive`` (compensator only) starts from the
            LuGre settings.
        """
        if kind == "adaptive" and role == "compensation":
            kind = "lugre"
        _check_kind(kind)
        base = FrictionParams()
        if role == "plant":
            return base
        if role != "compensation":
            raise ValueError(f"role must be 'plant' or 'compensation', got {role!r}")
        if kind == "coulomb":
            return dataclasses.replace(base, coulomb=1.5, hysteresis=0.05)
        if kind in ("classical", "stribeck"):
            return dataclasses.replace(base, stiction=2.3, coulomb=1.55, stribeck_velocity=1.0,
                                       hysteresis=0.08)
        if kind == "lugre":
            return dataclasses.replace(base, stiction=2.3, coulomb=1.55, viscous=0.07,
                                       sigma0=300.0, sigma1=6.0, stribeck_velocity=1.0,
                                       observer_gain=7.0)
        return base

    def record(self, zero_velocity_band: float | None = None) -> np.record:
        """The friction record (:data:`FRICTION_DTYPE`) the compiled force laws
        read, backed by its own array (compiled code may write it).

        ``zero_velocity_band``, when given, replaces the field's value
        without a validated copy (the compensators' 0,
        :func:`frictionlab.model.controller.compensator_params`).
        """
        row = (  # in FRICTION_FIELDS order
            self.stiction, self.coulomb, self.viscous, self.stribeck_velocity, self.sigma0,
            self.sigma1, self.observer_gain,
            self.zero_velocity_band if zero_velocity_band is None else zero_velocity_band,
            self.hysteresis,
            self.stiction if self.stiction_negative is None else self.stiction_negative,
            self.coulomb if self.coulomb_negative is None else self.coulomb_negative,
            self.viscous if self.viscous_negative is None else self.viscous_negative,
            math.inf if self.sigma1_velocity is None else self.sigma1_velocity,
            self.drift, self.drift_start,
            math.nan if self.drift_time is None else self.drift_time,
            self.adaptation_gain, self.adaptation_bandwidth, self.adaptation_deadband,
            self.adaptation_max_innovation, self.adaptation_min, self.adaptation_max,
            self.adaptation_distance)
        return friction_record(np.array(row, dtype=np.float64))


def friction_row(p) -> np.ndarray:
    """The friction record ``p`` as a float row (:data:`FRICTION_FIELDS` order; a
    copy): what a batch stores per set and a caller in Python passes at every
    tick (:func:`friction_view` reads it back in compiled code)."""
    return record_row(p)


def friction_record(row) -> np.record:
    """The friction record stored in the float64 row ``row`` (:data:`NP`
    contiguous floats), by reference (Python side of :func:`friction_view`)."""
    return row_record(row, FRICTION_DTYPE)


def copy_friction(p) -> np.record:
    """An independent copy of the friction record ``p``."""
    return copy_record(p)


@jit_inline
def friction_view(row):
    """The friction record stored in the float row ``row`` (:func:`friction_row`),
    by reference; compiled code only.  Made once where a kernel starts from
    float rows (a batch's sets, the ``*_rows`` entry points), never per law call."""
    return row.view(FRICTION_DTYPE)[0]


def _check_kind(kind: str) -> int:
    if kind not in KINDS:
        raise ValueError(f"friction model must be one of {', '.join(KINDS)}; got {kind!r}")
    return KINDS.index(kind)


# --------------------------------------------------------------------------
# compiled force laws
# --------------------------------------------------------------------------


@jit_inline
def _sgn(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@jit
def _stribeck_decay(v, vs):
    r = v / vs
    return np.exp(-r * r)


@jit
def stribeck_magnitude(v, fc, fs, vs):
    """The Stribeck curve :math:`F_C + (F_S - F_C)e^{-(v/v_S)^2}` (eq. 18's
    :math:`\\sigma_0 g(v)`) from its three numbers: the one implementation, for a
    velocity or (from Python) an array of them."""
    return fc + (fs - fc) * _stribeck_decay(v, vs)


@jit
def stribeck_weight(v, p):
    """The Stribeck decay :math:`e^{-(v/v_S)^2}`: the share of the stiction
    excess :math:`F_S - F_C` left at velocity ``v`` (eq. 18's g(v))."""
    return _stribeck_decay(v, p.vs)


@jit
def stribeck_level(v, p):
    """Stribeck level :func:`stribeck_magnitude` with the levels of ``v``'s
    direction (the asymmetric variant's negative levels for v < 0)."""
    return _level(v, p.fs, p.fc, p.fs_neg, p.fc_neg, p.vs)


@jit_inline
def _level(v, fs_pos, fc_pos, fs_neg, fc_neg, vs):
    """:func:`stribeck_level` from the levels of both directions (values read
    by the caller: a law reads every field it may need before it branches,
    so that the reads of a record passed by reference can leave a loop)."""
    if v >= 0.0:
        fs, fc = fs_pos, fc_pos
    else:
        fs, fc = fs_neg, fc_neg
    return stribeck_magnitude(v, fc, fs, vs)


@jit
def stribeck_curve(v, p):
    """Steady-state (Stribeck) friction :math:`s(v)\\,\\mathrm{sgn}(v) + F_v v`."""
    return stribeck_level(v, p) * _sgn(v) + viscous_force(v, p)


@jit_inline
def coulomb_relay(v, s_prev, p):
    """Coulomb relay with hysteresis (Sec. 6.1).

    Returns
    -------
    (F, s) : the friction and the new relay state (-1, 0 or +1).
    """
    eps, fc_pos, fc_neg = p.eps, p.fc, p.fc_neg
    s = s_prev
    if v > eps:
        s = 1.0
    elif v < -eps:
        s = -1.0
    fc = fc_pos if s >= 0.0 else fc_neg
    return fc * s, s


@jit_inline
def _stuck(fe, fs_pos, fs_neg):
    """Friction at rest: it balances the external force ``fe`` up to the
    stiction level ``fs_pos`` (``fs_neg`` for fe < 0) (eq. 17's
    :math:`|F_e| < F_S` branch, Sec. 5.2, 6.2)."""
    fs = fs_pos if fe >= 0.0 else fs_neg
    if abs(fe) < fs:
        return fe
    return fs * _sgn(fe)


@jit_inline
def classical_force(v, fe, p):
    """Stiction + Coulomb friction, eq. (17), with a zero-velocity band.

    Parameters
    ----------
    v : float
        Arm velocity, rad/s.
    fe : float
        External force on the arm in units of u (the applied :math:`k_u u`).
    p : record of :data:`FRICTION_DTYPE`
        Friction parameters.
    """
    # every field read before the branches (module docstring, "Reads")
    band, fc, fc_neg, fs, fs_neg = p.band, p.fc, p.fc_neg, p.fs, p.fs_neg
    if abs(v) >= band and v != 0.0:
        return fc * _sgn(v) if v > 0.0 else fc_neg * _sgn(v)
    return _stuck(fe, fs, fs_neg)


@jit_inline
def stribeck_classical_force(v, fe, p):
    """The classical model's implementation form with Stribeck decay (Sec. 6.2)."""
    eps, band0, fs, fc, fs_neg, fc_neg, vs = p.eps, p.band, p.fs, p.fc, p.fs_neg, p.fc_neg, p.vs
    band = eps if eps > 0.0 else band0
    if abs(v) < band or v == 0.0:
        return _stuck(fe, fs, fs_neg)
    return _level(v, fs, fc, fs_neg, fc_neg, vs) * _sgn(v)


@jit
def _sigma1(v, p):
    vd = p.vd
    if np.isinf(vd):
        return p.sigma1
    r = v / vd
    return p.sigma1 * np.exp(-r * r)


@jit
def lugre_dz(v, z, e, p):
    """Bristle rate :math:`\\dot z` of eq. (18)/(19) (``e`` enters with gain k)."""
    return v - abs(v) * p.sigma0 / max(stribeck_level(v, p), _TINY) * z - p.k * e


@jit
def lugre_force(v, z, dz, p):
    """LuGre friction :math:`\\sigma_0 z + \\sigma_1(v)\\dot z + F_v v`."""
    return p.sigma0 * z + _sigma1(v, p) * dz + viscous_force(v, p)


@jit
def lugre_step_exact(v, z, e, dt, p):
    """Advance the bristle state over ``dt`` with ``v`` and ``e`` held constant.

    The bristle equation is linear in z for frozen v,
    :math:`\\dot z = b - a z` with :math:`a = \\sigma_0|v|/s(v) \\ge 0`,
    :math:`b = v - k e`, so it is integrated exactly (exponential update);
    this is unconditionally stable however stiff :math:`\\sigma_0|v|/F_C`
    is, unlike forward Euler which diverges once ``a*dt > 2``.

    Returns
    -------
    (z_new, z_mean, dz_mean)
        The new state, the mean of z over the interval and the mean rate
        ``(z_new - z)/dt``; ``lugre_force(v, z_mean, dz_mean, p)`` is then the
        mean friction over the interval.
    """
    a = abs(v) * p.sigma0 / max(stribeck_level(v, p), _TINY)
    b = v - p.k * e
    x = a * dt
    if x < 1e-9:
        dz = b - a * z
        return z + dz * dt, z + 0.5 * dz * dt, dz
    # written so that one division (by the Stribeck level) is on the critical
    # path of the simulator's substep chain: 1/x runs alongside exp(-x), and
    # 1/dt is loop-invariant
    inv_x = 1.0 / x
    z_ss = b * dt * inv_x  # b / a
    q = (z - z_ss) * (1.0 - np.exp(-x))  # z - z_new
    return z - q, z_ss + q * inv_x, -q * (1.0 / dt)


@jit_inline
def viscous_force(v, p):
    """Viscous friction :math:`F_v v` (:math:`F_v^-` for v < 0)."""
    fv = p.fv if v >= 0.0 else p.fv_neg
    return fv * v


@jit_inline
def friction_step(kind, p, state, v, f_ext, dt, e):
    r"""One step of any friction model: the one law the simulator, the
    compensators and the model objects run.

    Parameters
    ----------
    kind : int
        Model code (index in :data:`KINDS`).
    p : record of :data:`FRICTION_DTYPE`
        Friction parameters (:meth:`FrictionParams.record`), by reference.
    state : float
        The model's memory: the relay output :math:`s \in \{-1, 0, 1\}`
        (``coulomb``, Sec. 6.1), the bristle deflection z (``lugre``,
        eq. 18); passed through unchanged by the memoryless models.
    v : float
        Arm velocity (rad/s), held over the step.
    f_ext : float
        External force on the arm in units of u (:math:`k_u u` in the plant,
        the feedback signal :math:`u_{fb}` in the classical compensator): the
        force that friction balances at rest (eq. 17, Sec. 6.2); read by
        ``classical`` and ``stribeck`` only.
    dt : float
        Length of the step (s); read by ``lugre`` only.
    e : float
        The error signal of eq. (19), held over the step; read by ``lugre``
        only (0 gives plain eq. 18).  It is an argument rather than part of
        the parameters because it is a signal that changes every step and
        whose meaning the caller chooses: the plant's balancing error
        :math:`-	heta`, or an estimation error in the compensator
        (:data:`frictionlab.model.controller.ERROR_SIGNALS`).

    Returns
    -------
    (F, state)
        The friction (units of u; for ``lugre`` the exact mean over the step
        of :func:`lugre_step_exact`, else the value at ``v``) and the new
        memory.
    """
    if kind == LUGRE:
        z_new, z_mean, dz_mean = lugre_step_exact(v, state, e, dt, p)
        return lugre_force(v, z_mean, dz_mean, p), z_new
    if kind == COULOMB:
        return coulomb_relay(v, state, p)
    if kind == CLASSICAL:
        return classical_force(v, f_ext, p), state
    if kind == STRIBECK:
        return stribeck_classical_force(v, f_ext, p), state
    if kind == VISCOUS:
        return viscous_force(v, p), state
    return 0.0, state


@jit_inline
def copy_friction_into(p, out):
    """Copy every field of the friction record ``p`` into ``out``."""
    out.fs = p.fs
    out.fc = p.fc
    out.fv = p.fv
    out.vs = p.vs
    out.sigma0 = p.sigma0
    out.sigma1 = p.sigma1
    out.k = p.k
    out.band = p.band
    out.eps = p.eps
    out.fs_neg = p.fs_neg
    out.fc_neg = p.fc_neg
    out.fv_neg = p.fv_neg
    out.vd = p.vd
    out.drift = p.drift
    out.drift_start = p.drift_start
    out.drift_time = p.drift_time
    out.adapt_gain = p.adapt_gain
    out.adapt_bandwidth = p.adapt_bandwidth
    out.adapt_deadband = p.adapt_deadband
    out.adapt_innovation = p.adapt_innovation
    out.adapt_min = p.adapt_min
    out.adapt_max = p.adapt_max
    out.adapt_distance = p.adapt_distance


@jit
def with_levels(p, fc, fs, out):
    """Write ``p`` with the Coulomb and stiction levels (both directions)
    replaced by ``fc`` and ``fs`` into the record ``out`` (the adaptive
    compensator's estimates, :mod:`frictionlab.model.adaptive`); returns ``out``."""
    copy_friction_into(p, out)
    out.fc = fc
    out.fc_neg = fc
    out.fs = fs
    out.fs_neg = fs
    return out


@jit
def drift_factor(t, p):
    r"""Factor on the plant's friction levels at time ``t`` (``friction.drift``).

    :math:`1 + d\,\min(1, \max(0, (t - t_0)/T))` with d = ``drift``,
    :math:`t_0` = ``drift_start`` and T = ``drift_time`` (a NaN T must have
    been replaced by the run's duration; T = 0 is a step at :math:`t_0`).
    """
    d = p.drift
    if d == 0.0:
        return 1.0
    t0 = p.drift_start
    span = p.drift_time
    if t < t0:
        return 1.0
    if not span > 0.0:
        return 1.0 + d
    r = (t - t0) / span
    return 1.0 + d * min(r, 1.0)


@jit
def drifted_params(p, t, out):
    """Write ``p`` with its levels (F_S, F_C, F_v, both directions) scaled by
    :func:`drift_factor` at time ``t`` into the (scratch) record ``out``;
    returns ``out``."""
    c = drift_factor(t, p)
    copy_friction_into(p, out)
    if c != 1.0:
        out.fs = p.fs * c
        out.fc = p.fc * c
        out.fv = p.fv * c
        out.fs_neg = p.fs_neg * c
        out.fc_neg = p.fc_neg * c
        out.fv_neg = p.fv_neg * c
    return out


@jit
def drifted_rows(p, t, out):
    """:func:`drifted_params` on records stored as float rows (:func:`friction_row`):
    the form for a caller in Python at every tick (the emulated plant)."""
    drifted_params(friction_view(p), t, friction_view(out))


@jit
def is_drifting(p):
    """Whether ``p`` has a drift with a resolved drift time (:func:`resolve_drift`;
    an unresolved one, NaN, is ignored)."""
    return p.drift != 0.0 and not np.isnan(p.drift_time)


def without_drift(p: np.record) -> np.record:
    """A copy of ``p`` without drift (the plant at its starting levels)."""
    q = copy_friction(p)
    q["drift"] = 0.0
    return q


@jit_inline
def levels(p):
    """``(F_C, F_S)``, the Coulomb and stiction levels for v >= 0."""
    return p.fc, p.fs


@jit_inline
def adaptation_settings(p):
    """The adaptive compensator's law settings (:mod:`frictionlab.model.adaptive`):
    ``(gain, bandwidth, deadband, max_innovation, min, max, distance)``, the
    ``adaptation_*`` fields."""
    return (p.adapt_gain, p.adapt_bandwidth, p.adapt_deadband, p.adapt_innovation,
            p.adapt_min, p.adapt_max, p.adapt_distance)


@jit
def steady_bristle(v, p):
    """The bristle deflection of steady sliding at ``v``, :math:`z = s(v)\\,
    \\mathrm{sgn}(v)/\\sigma_0` (eq. 18 with :math:`\\dot z = 0`)."""
    return math.copysign(1.0, v) * stribeck_level(v, p) / p.sigma0


@jit
def steady_state(kind, p, v):
    """The friction of law ``kind`` (a code, index in :data:`KINDS`) with the
    parameters ``p`` in steady sliding at the constant velocity ``v`` with no
    external force: the relay switched to the direction of ``v``, the LuGre
    bristle settled (:math:`\\dot z = 0`: the Stribeck curve :func:`stribeck_curve`)."""
    if kind == LUGRE:
        return stribeck_curve(v, p)
    f, _ = friction_step(kind, p, _sgn(v), v, 0.0, 0.0, 0.0)
    return f


def resolve_drift(p: np.record, duration: float) -> np.record:
    """``p`` (a copy if changed) with an unset drift time (NaN: to the end of
    the run) set to the time from ``drift_start`` to ``duration``, the run's
    length in s."""
    # (items, not attributes: numpy reads a record's attribute in Python code)
    if math.isnan(p["drift_time"]):
        p = copy_friction(p)
        p["drift_time"] = max(float(duration) - p["drift_start"], 0.0)
    return p


# --------------------------------------------------------------------------
# Python objects: one small frozen object per model
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class FrictionModel:
    """Base of the friction models: a kind and its (validated) parameters.

    Every model has the same interface, ``init() -> state`` and
    ``step(state, v, f_ext, dt, e=0.0) -> (F, state)``, both running the
    compiled :func:`friction_step` that the simulator and the compensators
    run; a model keeps no state inside (the Coulomb relay output and the
    LuGre bristle deflection are the ``state`` passed in and returned; the
    memoryless models return it unchanged).  Build one with
    :func:`make_model`.
    """

    params: FrictionParams = dataclasses.field(default_factory=FrictionParams)
    kind: ClassVar[str] = "none"
    has_state: ClassVar[bool] = False

    @property
    def code(self) -> int:
        """The model's integer code (index in :data:`KINDS`)."""
        return KINDS.index(self.kind)

    def _p(self) -> np.record:
        return self.params.record()

    def init(self) -> float:
        """Initial state: relay undecided (0), bristle relaxed (z = 0)."""
        return 0.0

    def step(self, state: float, v: float, f_ext: float, dt: float,
             e: float = 0.0) -> tuple[float, float]:
        """``(F, next_state)`` over ``dt`` s with ``v``, ``f_ext`` and ``e`` held.

        See :func:`friction_step` for the arguments (``f_ext`` is read by the
        classical models at rest, ``dt`` and ``e`` by LuGre, eq. 19).
        """
        f, state = friction_step(self.code, self._p(), float(state), float(v), float(f_ext),
                                 float(dt), float(e))
        return float(f), float(state)

    def steady_state(self, v: float) -> float:
        """Friction in steady sliding at constant velocity ``v`` with no external
        force (the relay switched to the direction of ``v``)."""
        return float(steady_state(self.code, self._p(), float(v)))


@dataclass(frozen=True)
class NoFriction(FrictionModel):
    """No friction (``none``): F = 0."""


@dataclass(frozen=True)
class Viscous(FrictionModel):
    """Viscous friction :math:`F = F_v v` (``F_v^-`` for v < 0 when given)."""

    kind: ClassVar[str] = "viscous"


@dataclass(frozen=True)
class Coulomb(FrictionModel):
    """Coulomb relay with hysteresis :math:`\\pm\\varepsilon` (Sec. 6.1); state: the relay."""

    kind: ClassVar[str] = "coulomb"
    has_state: ClassVar[bool] = True


@dataclass(frozen=True)
class Classical(FrictionModel):
    """Stiction + Coulomb friction, eq. (17), with a zero-velocity band."""

    kind: ClassVar[str] = "classical"


@dataclass(frozen=True)
class Stribeck(FrictionModel):
    """The classical model's implementation form with Stribeck decay (Sec. 6.2)."""

    kind: ClassVar[str] = "stribeck"


@dataclass(frozen=True)
class LuGre(FrictionModel):
    """The LuGre model, eq. (18), with the observer correction of eq. (19);
    state: the bristle deflection z."""

    kind: ClassVar[str] = "lugre"
    has_state: ClassVar[bool] = True


#: The model class of each kind.
MODELS: dict[str, type[FrictionModel]] = {
    m.kind: m for m in (NoFriction, Viscous, Coulomb, Classical, Stribeck, LuGre)}


def make_model(kind: str, params: FrictionParams | None = None, **overrides) -> FrictionModel:
    """Build a friction model, e.g. ``make_model("lugre", sigma0=300)``.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    params : FrictionParams, optional
        Base parameters (default: the thesis values).
    **overrides
        Fields of :class:`FrictionParams` to change (validated).
    """
    _check_kind(kind)
    base = params if params is not None else FrictionParams()
    if overrides:
        base = dataclasses.replace(base, **overrides)
    return MODELS[kind](base)
