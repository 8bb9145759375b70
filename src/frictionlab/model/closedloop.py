r"""The closed loop, one tick at a time: the one compiled kernel of every simulated run.

One tick k (Sec. 7.3, process *Regul*, with the plant of Sec. 5 between
samples): measure the plant (:func:`frictionlab.model.sensor.measure`, App. B),
run the controller (:func:`frictionlab.model.controller.controller_step`) or,
in a swing-up run, the swing-up supervisor that wraps it
(:func:`frictionlab.model.swingup.swingup_step`), record the tick, then
advance the plant over the sample with u held
(:func:`frictionlab.model.plants.plant_step`).  Time is the integer tick k,
t = k h.

:func:`run_loop` runs that tick for ``simulate``, the batch sweeps and fits
(``studies.batch``), the swing-up simulation (``studies.swingup_sim``), and
:func:`step_loop` is the same tick on a packed loop state for the periodic
orbit (:mod:`frictionlab.model.periodic`), and :func:`tick_jacobian` that tick
linearised (the periodic orbit's linear loop, the loop check of
:mod:`frictionlab.model.loopcheck`).  The 200 Hz loop runs the same
controller and swing-up steps on what a rig reports.

Recorded columns
----------------
:data:`COLUMNS`: the ten signals the thesis's controller logs (Sec. 7.1,
:data:`LOGGED`), the true plant signals, then the Coulomb and stiction levels
the compensator used.  In a swing-up run the pendulum angles are wrapped into
[-pi, pi) and, before the catch, the estimates are the swing-up observer's.
"""

from __future__ import annotations

import numpy as np

from ._jit import jit, jit_inline, keep_alive
from .controller import (
    THESIS_OBSERVERS,
    compensator_levels,
    controller_step,
    controller_tick,
    estimates,
    state_record,
    state_vector,
)
from .friction import FRICTION_DTYPE, copy_friction_into, drifted_params, is_drifting
from .plants import inlined_params, inlined_step, inlines_step, plant_step, plant_step_called
from .sensor import ideal_reading, measure, reading
from .swingup import (
    BALANCING,
    CAUGHT,
    STOPPED,
    SWING_FIELDS,
    SwingUpRecord,
    swing_view,
    swingup_record,
    swingup_step,
    wrap_angle,
)

__all__ = [
    "COLUMNS",
    "FELL",
    "LOGGED",
    "NC",
    "OK",
    "SWING_STOPPED",
    "TICK_INPUTS",
    "no_swing",
    "record_tick",
    "run_loop",
    "step_loop",
    "tick_jacobian",
]

#: The ten signals the thesis's controller saves (Sec. 7.1), in its order.
LOGGED = (
    "theta_m", "theta_hat", "theta_dot_hat", "u", "arm_m", "arm_dot_m", "arm_hat",
    "arm_dot_hat", "friction_hat", "z_hat",
)
#: All recorded columns: the ten logged signals, the true plant signals, then the
#: Coulomb and stiction levels the compensator used (the adaptive compensator's
#: estimates; a fixed compensator's own ``compensation.coulomb``/``stiction``; 0
#: without compensation).
COLUMNS = (*LOGGED, "theta", "theta_dot", "arm", "arm_dot", "z", "friction", "coulomb_hat",
           "stiction_hat")
NC = len(COLUMNS)

#: Status codes of :func:`run_loop`: ran to the end, fell (or a non-finite
#: state), the swing-up supervisor stopped the run.
OK, FELL, SWING_STOPPED = 0, 1, 2


@jit_inline
def record_tick(out, k, th_m, th_hat, thd_hat, u, arm_m, armd_m, arm_hat, armd_hat, f_hat,
                z_hat, theta, x, fc_used, fs_used):
    """Write tick ``k``'s signals into row k of ``out`` (columns :data:`COLUMNS`
    but ``friction``, written after the plant step): the measurements and the
    estimates the controller used, the plant state ``x`` with its angle given
    as ``theta``, and the compensator's levels."""
    out[k, 0] = th_m
    out[k, 1] = th_hat
    out[k, 2] = thd_hat
    out[k, 3] = u
    out[k, 4] = arm_m
    out[k, 5] = armd_m
    out[k, 6] = arm_hat
    out[k, 7] = armd_hat
    out[k, 8] = f_hat
    out[k, 9] = z_hat
    out[k, 10] = theta
    out[k, 11] = x[1]
    out[k, 12] = x[2]
    out[k, 13] = x[3]
    out[k, 14] = x[4]
    out[k, 16] = fc_used
    out[k, 17] = fs_used


#: The sensor inlined into the loop (with a noisy converter its call every
#: tick cost about 10 % of a run): the same Python function, compiled in place.
_measure_inline = jit_inline(measure.py_func)


@jit
def run_loop(x, mem, n_ticks, pcode, substeps, ratio, pp, fkind, fp, gp, cp, s, sp, n0, x0,
             fall_angle, out, record, swing, sup_row, wx, phase_out):
    """The closed loop for ``n_ticks`` ticks; returns (ticks done, status, mem, x0).

    Parameters
    ----------
    x : ndarray (5,)
        Plant state ``[theta, theta_dot, arm, arm_dot, z]``, advanced in place.
    mem : float
        The plant's friction memory (:func:`frictionlab.model.plants.plant_step`)
        at the start; returned at the end.
    n_ticks : int
    pcode, substeps, ratio, pp : int, int, int, ndarray
        Plant code (:data:`frictionlab.model.plants.PLANTS`), integration steps,
        the plant's parameter row.
    fkind, fp
        Plant friction model code and record (by reference).  Its levels drift
        with the time ``(n0 + k) h`` when it has a resolved drift
        (:func:`frictionlab.model.friction.resolve_drift`).
    gp, cp, s
        Controller gains, the compensator's friction record and the controller
        state (updated in place).
    sp : SensorParams
        The sensor; samples are numbered ``n0, n0 + 1, ...`` (its noise is a
        function of the sample number, so a run continued in chunks is the
        single run bit for bit).
    x0 : float
        The arm's zero (taken at sample 0; returned for a continuation chunk).
    fall_angle : float
        ``|theta|`` beyond which the pendulum has fallen (swing-up: once balancing).
    out : ndarray (n_ticks, NC)
        Row k receives tick k's signals when ``record`` is true.
    swing : bool
        Run the swing-up supervisor (settings row ``sup_row``, state vector
        ``wx``, updated in place; ``phase_out[k]`` receives the phase of tick
        k) instead of the balancing controller alone.

    Returns
    -------
    (ticks done, status, mem, x0) with status :data:`OK`, :data:`FELL` or
    :data:`SWING_STOPPED`.
    """
    # one loop per kind of plant step, chosen once per call: with the thesis plant's
    # step inlined (no call in the tick), or with every step called
    if inlines_step(pcode, pp) and gp.observer == THESIS_OBSERVERS:
        return _ticks(x, mem, n_ticks, pcode, substeps, ratio, pp, fkind, fp, gp, cp, s, sp, n0,
                      x0, fall_angle, out, record, swing, sup_row, wx, phase_out,
                      inlined_params(pp))
    return _ticks(x, mem, n_ticks, pcode, substeps, ratio, pp, fkind, fp, gp, cp, s, sp, n0, x0,
                  fall_angle, out, record, swing, sup_row, wx, phase_out, None)


@jit
def _ticks(x, mem, n_ticks, pcode, substeps, ratio, pp, fkind, fp, gp, cp, s, sp, n0, x0,
           fall_angle, out, record, swing, sup_row, wx, phase_out, inline):
    """The ticks of :func:`run_loop`, compiled once per type of ``inline``.

    ``inline`` the thesis plant's record
    (:func:`frictionlab.model.plants.inlined_params`, read once, by value): its
    step without the back-EMF (:func:`frictionlab.model.plants.inlined_step`),
    the controller step with the thesis's observers
    (:func:`frictionlab.model.controller.controller_tick`) and the sensor
    inlined into the tick, which then calls nothing but the swing-up
    supervisor, and the plant's parameters and what the step derives from
    them stay out of the ticks.  ``inline`` None: the plant's step called
    (:func:`frictionlab.model.plants.plant_step_called`), the controller step
    and the sensor inlined, the controller with any observers: the loop of
    the plants whose step costs far more than a call (the DC plant, the thesis
    plant with the actuator's back-EMF), quicker to compile than one with a
    second plant step inlined.  numba prunes
    the branches on ``inline is None`` where ``inline`` is None before it
    compiles the rest.
    """
    h = gp.h
    drifting = is_drifting(fp)
    # the plant's levels at the tick, in a scratch record (kept alive to the end:
    # a record does not hold its array)
    buf = np.empty(1, FRICTION_DTYPE)
    fpt = buf[0]
    copy_friction_into(fp, fpt)
    sup = swingup_record(sup_row)
    w = swing_view(wx)
    # an ideal noise-free sensor measures the true signals: its (inlined) reading
    # saves the call of measure every tick; the same values bit for bit
    ideal = not (sp.noise > 0.0) and not (sp.step > 0.0)
    for k in range(n_ticks):
        if ideal:
            th_m, arm_m, armd_m, x0 = ideal_reading(x[0], x[2], x[3], n0 + k == 0, x0)
        else:
            th_m, arm_m, armd_m, x0 = _measure_inline(sp, x[0], x[2], x[3], n0 + k, x0)
        th_hat, thd_hat, arm_hat, armd_hat, z_hat = estimates(s, gp)
        if swing:
            th_m = wrap_angle(th_m)
            u, _u_fb, f_hat = swingup_step(w, s, gp, cp, sup, th_m, arm_m, armd_m)
        else:
            # inlined in both loops (its call cost a DC plant's run about 10 %)
            u, _u_fb, f_hat = controller_tick(s, gp, cp, th_m, arm_m, armd_m,
                                              gp.observer if inline is None else THESIS_OBSERVERS)
        if record:
            theta = x[0]
            if swing:
                theta = wrap_angle(theta)
                phase_out[k] = w.phase
                if not (CAUGHT <= w.phase <= BALANCING):
                    th_hat, thd_hat = w.theta_hat, w.theta_dot_hat
            fc_used, fs_used = compensator_levels(s, gp, cp)
            record_tick(out, k, th_m, th_hat, thd_hat, u, arm_m, armd_m, arm_hat, armd_hat,
                        f_hat, z_hat, theta, x, fc_used, fs_used)
        if drifting:
            drifted_params(fp, (n0 + k) * h, fpt)
        if inline is None:
            f_mean, mem = plant_step_called(pcode, x, u, mem, substeps, ratio, h, pp, fkind, fpt)
        else:
            f_mean, mem = inlined_step(x, u, mem, substeps, ratio, h, inline, fkind, fpt)
        if record:
            out[k, 15] = f_mean
        if swing:
            if w.phase == STOPPED:
                keep_alive(buf)
                return k + 1, SWING_STOPPED, mem, x0
            if not np.isfinite(x[0] + x[1] + x[3] + x[4]):
                keep_alive(buf)
                return k + 1, FELL, mem, x0
            if w.phase == BALANCING and not abs(wrap_angle(x[0])) <= fall_angle:
                keep_alive(buf)
                return k + 1, FELL, mem, x0
        elif not (abs(x[0]) <= fall_angle) or not np.isfinite(x[1] + x[3] + x[4]):
            keep_alive(buf)
            return k + 1, FELL, mem, x0
    keep_alive(buf)
    return n_ticks, OK, mem, x0


def no_swing() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`run_loop`'s swing-up arguments ``(sup_row, wx, phase_out)`` for a
    run without the swing-up supervisor."""
    return np.zeros(len(SwingUpRecord._fields)), np.zeros(len(SWING_FIELDS)), np.zeros(0)


@jit
def step_loop(x, s, mem, x0, pcode, substeps, ratio, pp, fkind, fp, gp, cp, sp, du, w_theta,
              w_arm, w_arm_dot):
    """One tick of :func:`run_loop` (measure, controller, plant) on a plant state
    ``x`` and a controller state ``s`` (both updated in place), not the first
    sample (the arm's zero ``x0`` is given), noise-free; the controller reads the
    measurements plus the errors ``w_theta``, ``w_arm``, ``w_arm_dot`` and the
    plant receives the controller's u plus ``du`` (an input disturbance): the
    inputs of a linearisation (:func:`tick_jacobian`).  Returns (u, mem)."""
    th_m, arm_m, armd_m, _ = reading(sp, x[0], x[2], x[3], False, x0)
    u, _u_fb, _f_hat = controller_step(s, gp, cp, th_m + w_theta, arm_m + w_arm,
                                       armd_m + w_arm_dot)
    u_in = u + du if du != 0.0 else u
    _f, mem = plant_step(pcode, x, u_in, mem, substeps, ratio, gp.h, pp, fkind, fp)
    return u, mem


#: The inputs of :func:`tick_jacobian`, in its columns' order: an input
#: disturbance added to u, then errors on the three measured signals.
TICK_INPUTS = ("du", "theta_m", "arm_m", "arm_dot_m")


def tick_jacobian(x, s, mem, loop, plant_coords, state_coords, mem_coord=False, eps=1e-6):
    r"""The closed-loop tick (:func:`step_loop`) linearised at a point, by central differences.

    The loop's coordinates X are the plant state's entries ``plant_coords``
    (of ``[theta, theta_dot, arm, arm_dot, z]``), the controller state's
    entries ``state_coords`` (positions in
    :func:`~frictionlab.model.controller.state_vector`) and, with
    ``mem_coord``, the plant's friction memory; the other entries of the
    controller state are held at the point's values (a discrete relay, an
    adaptation frozen).  The tick, differenced, is

    .. math::  \delta X^+ = M\,\delta X + G\,d, \qquad \delta u = K\,\delta X + D\,d

    with the inputs d of :data:`TICK_INPUTS` (an input disturbance, errors on
    the measured theta, arm angle and arm velocity).  The point need not be an
    equilibrium (a sliding arm): the matrices are those of the tick there.

    Parameters
    ----------
    x : ndarray (5,)
        The plant state at the point.
    s : record of :data:`~frictionlab.model.controller.STATE_DTYPE`
        The controller state at the point.
    mem : float
        The plant's friction memory at the point.
    loop : tuple
        :func:`step_loop`'s arguments after ``mem``: ``(x0, pcode, substeps,
        ratio, pp, fkind, fp, gp, cp, sp)``.
    plant_coords, state_coords : sequence of int
    mem_coord : bool
    eps : float
        Difference step, scaled by ``max(1, |coordinate|)``.

    Returns
    -------
    M : ndarray (n, n)
    G : ndarray (n, 4)
    K : ndarray (n,)
    D : ndarray (4,)
    """
    plant_coords = list(plant_coords)
    state_coords = list(state_coords)
    sv = state_vector(s)
    X0 = np.concatenate([np.asarray(x, dtype=float)[plant_coords], sv[state_coords],
                         [mem] if mem_coord else []])
    n_p, n_s = len(plant_coords), len(state_coords)
    n, n_in = len(X0), len(TICK_INPUTS)

    def tick(X, d):
        xe = np.array(x, dtype=float)
        xe[plant_coords] = X[:n_p]
        se = sv.copy()
        se[state_coords] = X[n_p:n_p + n_s]
        me = X[-1] if mem_coord else mem
        u, me = step_loop(xe, state_record(se), me, *loop, *d)
        out = np.concatenate([xe[plant_coords], se[state_coords], [me] if mem_coord else []])
        return out, u

    J = np.zeros((n, n + n_in))
    row = np.zeros(n + n_in)
    for j in range(n + n_in):
        step = eps * max(1.0, abs(X0[j])) if j < n else eps
        e = np.zeros(n + n_in)
        e[j] = step
        (a, ua), (b, ub) = tick(X0 + e[:n], e[n:]), tick(X0 - e[:n], -e[n:])
        J[:, j] = (a - b) / (2 * step)
        row[j] = (ua - ub) / (2 * step)
    return J[:, :n], J[:, n:], row[:n], row[n:]
