r"""Adaptive friction compensation: LuGre levels adapted online (Sec. 8's proposal).

The thesis closes by proposing an adaptive friction estimator, because the
friction of the arm bearing changes with the operating conditions (App. E.1:
it falls as the rig runs and the lubricant warms up).  This module holds the
adaptation law of ``--compensation adaptive``; the compensation itself is the
LuGre observer of eq. (19) (:func:`frictionlab.model.friction.lugre_step_exact`),
run with the *adapted* Coulomb and stiction levels :math:`\hat F_C, \hat F_S`
in place of the fixed ``compensation.coulomb`` / ``compensation.stiction``
(which are the starting values).

The law: a series-parallel identifier with a gradient update
--------------------------------------------------------------
The arm is acceleration-driven, :math:`L_1\dot\Omega = u - F` (eq. 5, k_u = 1),
and in steady sliding the LuGre friction is its Stribeck curve, linear in the
two levels,

.. math::

    F = \theta^T\varphi(v) + F_v v,\quad \theta = (F_C, F_S),\quad
    \varphi(v) = \mathrm{sgn}(v)\,(1 - e^{-(v/v_S)^2},\; e^{-(v/v_S)^2}).

A velocity predictor runs beside the arm, fed with the applied u, the
friction the current estimates predict, and the measured velocity v,

.. math::

    L_1\dot{\hat v} = u - \hat\theta^T\varphi(v) - F_v v + \lambda L_1 (v - \hat v),

so the prediction error :math:`\tilde v = v - \hat v` obeys
:math:`\dot{\tilde v} = -\lambda\tilde v - \varphi^T\tilde\theta / L_1`
(:math:`\tilde\theta = \theta - \hat\theta`): u cancels, so the error
dynamics do not depend on the controller (the certainty-equivalence
property of identifier-based adaptive control).  With the gradient law

.. math::

    \dot{\hat\theta} = -\gamma\,\varphi(v)\,\tilde v

the function :math:`V = \tfrac12\tilde v^2 + \tilde\theta^T\tilde\theta/(2\gamma L_1)`
has :math:`\dot V = -\lambda\tilde v^2 \le 0` for constant levels: the
errors stay bounded, :math:`\tilde v \to 0`, and :math:`\hat\theta \to
\theta` when the arm's motion excites both regressors (it slides through
the Stribeck region and beyond it, as in the limit cycles of Sec. 5).  This
is the Lyapunov design of adaptive friction compensation of Canudas de Wit,
Olsson, Astrom and Lischinsky ("A new model for control of systems with
friction", IEEE TAC 40(3), 1995) written as a series-parallel identifier
with a gradient law and projection (Ioannou and Sun, *Robust Adaptive
Control*, 1996, ch. 4); slowly drifting levels give a tracking error of the
order of the drift rate over the adaptation rate.

Sampled at h (as the controller runs it): the prediction and the update at
tick k are

.. math::

    \hat v_k = \hat v_{k-1} + h\,[(u_{k-1} - \hat\theta_{k-1}^T\varphi_{k-1}
               - F_v v_{k-1})/L_1 + \lambda\tilde v_{k-1}],\qquad
    \hat\theta_k = \Pi[\hat\theta_{k-1} - \gamma h\,\varphi_{k-1}\tilde v_k]

with :math:`\varphi_{k-1} = \varphi(v_{k-1})` and :math:`\Pi` the projection on
the box ``[adaptation_min, adaptation_max]``.  For a frozen regressor the pair
:math:`(\tilde v, \varphi^T\tilde\theta)` then has the characteristic
polynomial :math:`z^2 - (2 - a - g)z + (1 - a)` with :math:`a = \lambda h`,
:math:`g = \gamma h^2|\varphi|^2/L_1`; the Jury conditions give the
stability conditions

.. math::

    0 < \lambda h < 2,\qquad \gamma h^2 |\varphi|^2 / L_1 < 4 - 2\lambda h,

and since :math:`|\varphi|^2 \le 1`, :math:`0 \le \gamma < (4 - 2\lambda h)
L_1/h^2` suffices.  :func:`check_gains` refuses anything else.  The slow
root is :math:`1 - g/a` for small g: the estimates converge at the rate
:math:`\gamma|\varphi|^2/(\lambda L_1)` per second while the arm slides.

Safety
------
* The estimates are projected on ``[adaptation_min, adaptation_max]``
  (bounded; the projection keeps the Lyapunov property when the true levels
  lie inside, and it is what prevents windup: nothing integrates beyond a
  bound).
* The adaptation is frozen (the estimates held, the predictor still
  running) while the arm is stuck or reverses (:math:`|v|` below
  ``adaptation_deadband`` at the start or the end of the interval, or the
  sign changed: the noise would bias the regressor's sign), in pre-sliding
  (until the arm has slid ``adaptation_distance`` since it last stopped: the
  LuGre bristles settle within a few :math:`s(v)/\sigma_0` of travel, and
  before that the friction is not the Stribeck curve the regressor
  describes), while the signals are bad (a non-finite reading or
  prediction, or a prediction error larger than
  ``adaptation_max_innovation``; also the interval that starts at such a
  reading, and until the arm has slid ``adaptation_distance`` again), and
  when the control was saturated over the interval (the applied
  acceleration is not what the law assumes on a rig).

The law's state lives in the controller's state record (fields ``v_hat``,
``v_prev``, ``fc_hat``, ``fs_hat``, ``adapt`` of
:mod:`frictionlab.model.controller`), so the simulator and the 200 Hz loop run it
as part of the same compiled :func:`~frictionlab.model.controller.controller_step`.
"""

from __future__ import annotations

import math

from ._jit import jit
from .friction import adaptation_settings, levels, stribeck_weight, viscous_force
from .params import ParamError

__all__ = [
    "ADAPT_STATES",
    "adaptation_step",
    "check_gains",
    "max_gain",
    "regressor",
]

#: Meaning of the adaptation status (controller state field ``adapt``), index = code.
ADAPT_STATES = ("off", "adapting", "stuck", "presliding", "bad_signal", "saturated")
A_OFF, A_ADAPTING, A_STUCK, A_PRESLIDING, A_BAD, A_SATURATED = range(6)


def max_gain(bandwidth: float, h: float, arm_length: float) -> float:
    """The largest stable adaptation gain, :math:`(4 - 2\\lambda h)L_1/h^2` (1/s units
    as ``adaptation_gain``); 0 when the bandwidth itself is unstable."""
    return max(0.0, (4.0 - 2.0 * bandwidth * h) * arm_length / (h * h))


def check_gains(params, h: float, arm_length: float) -> None:
    """Refuse adaptation gains outside the law's stability conditions.

    Parameters
    ----------
    params : FrictionParams
        The compensator's model (``compensation.*``).
    h : float
        Sampling period (``design.h``), s.
    arm_length : float
        :math:`L_1` (``plant.arm_length``), m.

    Raises
    ------
    ParamError
        Naming ``compensation.adaptation_bandwidth`` (needs
        :math:`0 < \\lambda h < 2`), ``compensation.adaptation_gain`` (needs
        :math:`\\gamma < (4 - 2\\lambda h)L_1/h^2`), the bounds (``adaptation_min``
        below ``adaptation_max``) or a starting level outside them.
    """
    lam = params.adaptation_bandwidth
    if not lam * h < 2.0:
        raise ParamError("compensation.adaptation_bandwidth", lam, f"(0, {2.0 / h:g})",
                         f"compensation.adaptation_bandwidth = {lam:g} is out of range; allowed "
                         f"(0, {2.0 / h:g}) 1/s: the adaptive law's predictor is stable for "
                         f"lambda h < 2 (design.h = {h:g} s)")
    gmax = max_gain(lam, h, arm_length)
    gam = params.adaptation_gain
    if not gam < gmax:
        raise ParamError("compensation.adaptation_gain", gam, f"[0, {gmax:.6g})",
                         f"compensation.adaptation_gain = {gam:g} is out of range; allowed "
                         f"[0, {gmax:.6g}): the adaptive law is stable for gamma h^2 / L_1 < "
                         f"4 - 2 lambda h (design.h = {h:g} s, plant.arm_length = "
                         f"{arm_length:g} m, adaptation_bandwidth = {lam:g} 1/s)")
    lo, hi = params.adaptation_min, params.adaptation_max
    if not lo < hi:
        raise ParamError("compensation.adaptation_max", hi, f"({lo:g}, 1000]",
                         f"compensation.adaptation_max = {hi:g} is out of range; allowed "
                         f"({lo:g}, 1000] (above compensation.adaptation_min = {lo:g})")
    for name in ("coulomb", "stiction"):
        v = getattr(params, name)
        if not lo <= v <= hi:
            raise ParamError(f"compensation.{name}", v, f"[{lo:g}, {hi:g}]",
                             f"compensation.{name} = {v:g} is out of range; allowed "
                             f"[{lo:g}, {hi:g}]: the adaptive compensator starts from it and "
                             "keeps its estimate within compensation.adaptation_min/max")
    for name in ("stiction_negative", "coulomb_negative"):
        if getattr(params, name) is not None:
            raise ParamError(f"compensation.{name}", getattr(params, name), "None",
                             f"compensation.{name} must be unset for the adaptive "
                             "compensator: it adapts one level for both directions")


@jit
def regressor(v, p):
    """:math:`\\varphi(v)`: the Stribeck curve's sensitivities to (F_C, F_S)."""
    e = stribeck_weight(v, p)
    sg = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
    return sg * (1.0 - e), sg * e


@jit
def adaptation_step(status, fc, fs, v_hat, v_prev, slide, u_prev, v, p, h, arm_len, u_max):
    """One tick of the adaptation law (see the module docstring).

    Parameters
    ----------
    status : float
        The law's status code (:data:`ADAPT_STATES`); 0 (``off``) starts it:
        the estimates from the compensator's levels in ``p``, the predictor
        at ``v``.
    fc, fs : float
        The estimates :math:`\\hat F_C, \\hat F_S` of the last tick (m/s^2).
    v_hat, v_prev : float
        The predictor's and the measured arm velocity of the last tick (rad/s).
    slide : float
        How far the arm has slid (rad) since it last stopped or reversed
        (-1 after a bad signal: the next interval does not adapt either).
    u_prev : float
        The control applied over the last interval (m/s^2).
    v : float
        This tick's measured arm velocity (rad/s).
    p : record of :data:`~frictionlab.model.friction.FRICTION_DTYPE`
        The compensator's friction record (``v_S``, ``F_v``, the ``adaptation_*``
        fields).
    h, arm_len, u_max : float
        Sampling period, :math:`L_1`, saturation of u.

    Returns
    -------
    (status, fc, fs, v_hat, slide)
        The new status, estimates, this tick's predicted velocity and slid distance.
    """
    gain, lam, dead, max_innov, lo, hi, distance = adaptation_settings(p)
    if status == 0.0 or not (math.isfinite(fc) and math.isfinite(fs)):
        v0 = v if math.isfinite(v) else 0.0
        fc0, fs0 = levels(p)
        return (float(A_ADAPTING), min(max(fc0, lo), hi), min(max(fs0, lo), hi), v0, 0.0)
    # after a bad signal ``slide`` is -1: the next interval starts at a reading
    # that was not trusted, so it does not adapt either
    if not (math.isfinite(v_hat) and math.isfinite(v_prev)):
        v0 = v if math.isfinite(v) else 0.0
        return float(A_BAD), fc, fs, v0, -1.0
    # the Stribeck curve of friction.stribeck_curve in its linear-in-(F_C, F_S) form
    phc, phs = regressor(v_prev, p)
    f_model = fc * phc + fs * phs + viscous_force(v_prev, p)
    pred = v_hat + h * ((u_prev - f_model) / arm_len + lam * (v_prev - v_hat))
    if not math.isfinite(v):
        return float(A_BAD), fc, fs, pred, -1.0
    if not math.isfinite(pred):
        return float(A_BAD), fc, fs, v, -1.0
    innov = v - pred
    if abs(u_prev) >= u_max:
        return float(A_SATURATED), fc, fs, pred, slide
    if not abs(innov) <= max_innov:
        return float(A_BAD), fc, fs, pred, -1.0
    if abs(v_prev) < dead or abs(v) < dead or v * v_prev <= 0.0:
        return float(A_STUCK), fc, fs, pred, 0.0
    if slide < 0.0:
        return float(A_PRESLIDING), fc, fs, pred, 0.0
    slide += 0.5 * h * (abs(v) + abs(v_prev))
    if slide < distance:
        return float(A_PRESLIDING), fc, fs, pred, slide
    step = gain * h * innov
    fc = min(max(fc - step * phc, lo), hi)
    fs = min(max(fs - step * phs, lo), hi)
    return float(A_ADAPTING), fc, fs, pred, slide
