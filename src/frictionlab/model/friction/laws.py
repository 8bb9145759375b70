"""The friction laws (eqs. 17-21) and their one dispatch, :func:`friction_step`
(:mod:`frictionlab.model.friction`)."""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from .params import CLASSICAL, COULOMB, LUGRE, STRIBECK, VISCOUS

_TINY = 1e-12  # floor of the Stribeck level in divisions (F_S = F_C = 0: no friction)


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
