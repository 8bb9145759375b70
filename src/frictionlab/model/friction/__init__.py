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

from .drift import (
    copy_friction_into,
    drift_factor,
    drifted_params,
    drifted_rows,
    is_drifting,
    resolve_drift,
    with_levels,
    without_drift,
)
from .laws import (
    adaptation_settings,
    classical_force,
    coulomb_relay,
    friction_step,
    levels,
    lugre_dz,
    lugre_force,
    lugre_step_exact,
    steady_bristle,
    steady_state,
    stribeck_classical_force,
    stribeck_curve,
    stribeck_level,
    stribeck_magnitude,
    stribeck_weight,
    viscous_force,
)
from .models import (
    MODELS,
    Classical,
    Coulomb,
    FrictionModel,
    LuGre,
    NoFriction,
    Stribeck,
    Viscous,
    make_model,
)
from .params import (
    CLASSICAL,
    COULOMB,
    FRICTION_DTYPE,
    FRICTION_FIELDS,
    KINDS,
    LUGRE,
    NONE,
    NP,
    STRIBECK,
    VISCOUS,
    FrictionParams,
    check_kind,
    copy_friction,
    friction_record,
    friction_row,
    friction_view,
    plant_record,
)

__all__ = [
    "CLASSICAL",
    "COULOMB",
    "FRICTION_DTYPE",
    "FRICTION_FIELDS",
    "KINDS",
    "LUGRE",
    "MODELS",
    "NONE",
    "NP",
    "STRIBECK",
    "VISCOUS",
    "Classical",
    "Coulomb",
    "FrictionModel",
    "FrictionParams",
    "LuGre",
    "NoFriction",
    "Stribeck",
    "Viscous",
    "adaptation_settings",
    "check_kind",
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
    "plant_record",
    "resolve_drift",
    "steady_bristle",
    "steady_state",
    "stribeck_classical_force",
    "stribeck_curve",
    "stribeck_level",
    "stribeck_magnitude",
    "stribeck_weight",
    "viscous_force",
    "with_levels",
    "without_drift",
]
