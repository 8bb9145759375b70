r"""Switching the controller while it runs, bumpless (docs/compensation.md and
docs/realtime.md, "Switching while running").

The operator turns a compensator on or off, picks another kind, changes its
parameters or the design while the loop balances.  :func:`switch_controller`
makes such a change on the controller state and returns the
:class:`Transition` that gives the gains of the ticks after it; the 200 Hz
loop (:mod:`frictionlab.realtime.loop`) and the simulator
(:func:`frictionlab.model.simulation.simulate` with ``switches``) both run it,
so that the loop's log through a switch is the simulator's run tick for tick.
"""

from __future__ import annotations

import math

import numpy as np

from .controller import ADAPTIVE, Gains, reset_compensator
from .friction import (
    COULOMB,
    FRICTION_FIELDS,
    LUGRE,
    friction_record,
    friction_row,
    steady_bristle,
)

__all__ = ["Transition", "carry_compensator", "start_compensator", "switch_controller"]

#: Positions of sigma_0 and of the observer gain k in a friction row.
_SIGMA0, _K = FRICTION_FIELDS.index("sigma0"), FRICTION_FIELDS.index("k")


def start_compensator(s: np.record, kind: int, cp, v: float) -> None:
    r"""Start compensator ``kind`` on a running controller state ``s`` as if it
    had been running: its memory set to the steady value for the measured arm
    velocity ``v`` (rad/s), so that its first estimate is the steady friction
    :math:`F_{ss}(v)` of its model rather than a transient.

    The LuGre observer (``lugre``, ``adaptive``): the bristle of steady
    sliding, :math:`\dot z = 0` in eq. (18), :math:`\hat z = s(v)\,
    \mathrm{sgn}(v)/\sigma_0` (:func:`~frictionlab.model.friction.steady_bristle`),
    for which :math:`\hat F = \sigma_0\hat z + F_v v = s(v)\mathrm{sgn}(v) + F_v v`,
    the Stribeck curve; 0 at v = 0 (at rest the bristle's value is not
    known: 0 is no estimate).  The Coulomb relay: the direction of ``v``
    outside its hysteresis, else 0.  The adaptive law restarts from the
    compensator's levels.  The classical form has no memory.  See
    docs/compensation.md, "Switching while running".

    Parameters
    ----------
    s : record of :data:`STATE_DTYPE`
        Updated in place (the compensator's fields only).
    kind : int
        The new compensator's code (:data:`COMPENSATOR_CODES`).
    cp : record or float row of :data:`~frictionlab.model.friction.FRICTION_DTYPE`
        The new compensator's friction parameters.
    v : float
        The last measured arm velocity (rad/s); NaN counts as 0.
    """
    reset_compensator(s)
    p = cp if isinstance(cp, np.record) else friction_record(_friction_row(cp))
    v = float(v) if math.isfinite(v) else 0.0
    if kind == COULOMB and abs(v) > p.eps:
        s.relay = math.copysign(1.0, v)
    elif kind in (LUGRE, ADAPTIVE) and v != 0.0:
        s.z_hat = float(steady_bristle(v, p))


def _friction_row(cp) -> np.ndarray:
    """A compensator's friction parameters as a float row (from a record or a row)."""
    return friction_row(cp) if isinstance(cp, np.record) else np.asarray(cp, dtype=float)


def carry_compensator(s: np.record, cp_old, cp_new) -> None:
    r"""Keep the LuGre observer's spring force :math:`\sigma_0\hat z` continuous
    across a change of its :math:`\sigma_0` (the bristle rescaled by
    :math:`\sigma_0/\sigma_0'`); the bristle then relaxes to the new steady
    value at the rate :math:`\sigma_0'|v|/s(v)` of eq. (18)."""
    old, new = float(_friction_row(cp_old)[_SIGMA0]), float(_friction_row(cp_new)[_SIGMA0])
    if old != new:
        s.z_hat = s.z_hat * old / new


class Transition:
    """The gains of the ticks that follow a change of controller while it runs.

    Over ``n_gain`` ticks (the loop's ``safety.gain_transition``) the state
    feedback L and the observer gains K move from ``l_from``, the gains in use
    (L and K, 8 numbers), to the target's: linearly, or piecewise linearly
    along ``l_path`` (rows of L and K from the old design to the new one,
    :func:`frictionlab.model.design.gain_path`; its first row is replaced by
    ``l_from``, its last by the target's).
    Over ``n_comp`` ticks (``safety.compensation_transition``) the
    weight of the compensator's estimate (:attr:`Gains.comp_weight`) rises
    linearly from ``comp_from`` to 1, and that of the LuGre observer's error
    signal (:attr:`Gains.error_weight`) from ``error_from`` with the cube of
    the ramp's progress, :math:`r^3`: it reaches a tenth at :math:`r = 0.46`,
    once the observers' bias from the friction they did not model before the
    switch has decayed (docs/compensation.md, "Switching while running").
    :meth:`advance` gives the gains of the next tick: the j-th tick after the
    change is at r = j/n.  Written once for every runner: the 200 Hz loop and
    :func:`frictionlab.model.simulation.simulate_config` with ``switches``.
    """

    def __init__(self, target: Gains, l_from, n_gain: int, n_comp: int,
                 comp_from: float = 1.0, error_from: float = 1.0, l_path=None):
        self.target = target
        path = np.array([l_from, target.gains8] if l_path is None else l_path, dtype=float)
        path[0], path[-1] = l_from, target.gains8
        self.l_path = path
        self.n_gain = int(n_gain) if (path[0] != path[-1]).any() else 0
        self.comp_from = float(comp_from)
        self.error_from = float(error_from)
        self.n_comp = int(n_comp) if (self.comp_from, self.error_from) != (1.0, 1.0) else 0
        self.n = max(self.n_gain, self.n_comp)
        self.k = 0

    @property
    def done(self) -> bool:
        """True once the target gains are reached."""
        return self.k >= self.n

    def current(self) -> Gains:
        """The gains of the tick :meth:`advance` last gave (the start's before the first)."""
        k = self.k
        if k >= self.n:
            return self.target
        g = self.target
        if k < self.n_gain:
            pos = k / self.n_gain * (len(self.l_path) - 1)
            i = int(pos)
            a, b = self.l_path[i], self.l_path[i + 1]
            g = g.with_gains8(a + (pos - i) * (b - a))
        if k < self.n_comp:
            r = k / self.n_comp
            g = g._replace(comp_weight=self.comp_from + r * (1.0 - self.comp_from),
                           error_weight=self.error_from + r * r * r * (1.0 - self.error_from))
        return g

    def advance(self) -> Gains:
        """The gains of the next tick."""
        self.k += 1
        return self.current()


def switch_controller(s: np.record | None, old: Gains, cp_old, new: Gains, cp_new, v: float,
                      n_gain: int, n_comp: int, l_path=None) -> Transition:
    """Make a change of controller while it runs bumpless; returns its :class:`Transition`.

    ``old``/``cp_old`` are the gains and compensator parameters in use (in the
    middle of an earlier transition too), ``new``/``cp_new`` the target, ``v``
    the last measured arm velocity, ``s`` the controller state (None before
    the first tick: nothing to carry, the change is made at once).

    * A compensator of another kind is started at its steady value
      (:func:`start_compensator`) and ramped in over ``n_comp`` ticks, its
      estimate and its error signal (:class:`Transition`).
    * The LuGre observer kept (``lugre`` to or from ``adaptive``, or new
      parameters) keeps its spring force (:func:`carry_compensator`); the
      adaptive law restarts from its new parameters when they changed; a new
      observer gain k moves from the old one to the new one, a new error signal
      is ramped in from 0.
    * Switching compensation off removes the estimate at once: a step of its
      level at most, which the compensated cycle itself makes at every reversal.
    * New gains L ramp over ``n_gain`` ticks (along ``l_path`` when given:
      :func:`frictionlab.model.design.gain_path`); a new omega_0 keeps the
      pendulum observer's estimate of theta' (its state is theta'/omega_0).
    """
    kind, was = new.compensator, old.compensator
    cp_old, cp_new = _friction_row(cp_old), _friction_row(cp_new)
    comp_from, error_from = old.comp_weight, old.error_weight
    if s is None:
        return Transition(new, new.feedback, 0, 0)
    if old.omega0 != new.omega0:
        # the pendulum observer's state is theta'/omega_0: keep theta'-hat, not x2
        s.x2 = s.x2 * old.omega0 / new.omega0
    if kind != 0 and kind in (LUGRE, ADAPTIVE) and was in (LUGRE, ADAPTIVE):
        z = s.z_hat
        if kind != was or (kind == ADAPTIVE and not (cp_old == cp_new).all()):
            reset_compensator(s)  # the adaptive law restarts from the new levels
            s.z_hat = z
        carry_compensator(s, cp_old, cp_new)
        k_old, k_new = cp_old[_K], cp_new[_K]
        if old.error_signal != new.error_signal:
            error_from = 0.0
        elif k_old != k_new and k_new > 0.0:
            # from the gain in use (k_old e) to the new one (k_new e)
            error_from = old.error_weight * k_old / k_new
    elif kind != 0 and kind != was:
        start_compensator(s, kind, cp_new, v)
        comp_from = error_from = 0.0
    return Transition(new, old.gains8, n_gain, n_comp, comp_from, error_from, l_path)
