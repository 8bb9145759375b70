r"""The sampled loop as a map: its linearisation and its periodic orbits (Sec. 4.1-4.2).

The closed loop of Sec. 5 advances, once per sampling period h, the state

====  ============  ====================================================
idx   name          meaning
====  ============  ====================================================
0-4   plant         ``[theta, theta_dot, arm, arm_dot, z]`` (:mod:`frictionlab.model.plants.thesis`)
5-12  controller    the controller state (:mod:`frictionlab.model.controller`)
13    memory        the friction model's memory (:func:`~frictionlab.model.plants.plant_step`)
====  ============  ====================================================

by one *tick*: measure, :func:`~frictionlab.model.controller.controller_step`,
the plant's step -- the closed loop's own compiled tick
(:func:`frictionlab.model.closedloop.step_loop`, called here through
:func:`loop_tick`; no dynamics are re-implemented).  Measurement noise is left out: the map is
the deterministic loop; quantisation (``sim.quantization``) is kept.

Linearised loop
---------------
:func:`linear_loop` differentiates one tick of the frictionless loop at the
upright equilibrium (central differences of the compiled step; the step is
affine there up to the pendulum's sines, so the differences are exact to
rounding) and returns the closed loop seen from an extra arm acceleration
``w`` that enters beside the control signal, ``a = k_u u + w``, held over
the sample like u.  Friction is ``w = -F``, so the loop with friction is this
linear loop in negative feedback with the friction law -- the block diagram
of the describing-function method (:mod:`frictionlab.studies.predict`).

Period map and its fixed point
------------------------------
A friction limit cycle is a closed orbit of the loop.  Its *period map* is the
return map to the Poincaré section ``theta = 0`` crossed upwards: start from a
loop state on the section, run ticks until the pendulum angle has been below
``-hyst`` and crosses zero upwards again, and interpolate the state linearly
between the two ticks around the crossing.  (The hysteresis keeps a valley of
the angle that dips just below zero, as in the slow design, from counting as
a return.)  A cycle is a fixed point ``y* = P(y*)`` of that map in the
section's coordinates ``y`` (every continuous loop state but theta, which is
0 on the section; relay states are carried along).  When the friction and
the compensator are symmetric the loop is odd (``x -> -x`` maps orbits to
orbits) and a symmetric cycle is a fixed point of the half-period map
``y -> -(state at the next downward crossing)``, found at half the cost.

The fixed point is found by Newton's method on ``P(y) - y`` from a seed, the
state at an upward crossing after a few transient periods (not a long run).
The sampled loop is piecewise smooth: every switch of the friction (Coulomb
sign change, start and end of sticking) happens on the integrator's substep
grid (h/10), so the map has small jumps wherever an event moves from one
substep to the next (about 0.2 % of the arm-velocity amplitude for
F_C = 1.5).  The Jacobian is therefore taken by central differences with steps
of ``rel_step`` (default 1 %) of each coordinate's amplitude on the seed
orbit, far above that quantisation, and Newton stops once the residual stops
falling; ``residual`` reports what it reached (relative to the amplitudes)
and ``found`` requires it below ``tol``.  The Floquet multipliers are the
eigenvalues of that Jacobian (squared for the half-period map: the full map
is the half map applied twice at a symmetric orbit); they are the multipliers
of the sampled loop at the section, the trivial multiplier 1 along the orbit
excluded.  ``stable`` is ``max |mu| < 1``.

The sampling makes the loop time-varying with period h, and a cycle's period
is in general not a whole number of ticks: strictly the attractor is a closed
invariant curve of the one-tick map, along which the phase of the samples
within the cycle drifts.  The orbit found here is the point of that curve
whose section crossing falls on a tick; the features of the other points
differ from it by the sampling phase only (checked against long runs to
< 0.1 % in docs/predict.md).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ._jit import jit
from .closedloop import NC, no_swing, run_loop, step_loop, tick_jacobian
from .controller import (
    NS,
    state_index,
    state_record,
    state_vector,
    state_view,
)
from .friction import KINDS, LUGRE, NONE, VISCOUS, plant_record, without_drift
from .limit_cycles import LimitCycleFeatures, crossings, features
from .sensor import arm_zero
from .simulation import STATUS, LoopSpec, Trajectory

__all__ = [
    "LinearLoop",
    "PeriodicOrbit",
    "linear_loop",
    "loop_tick",
    "orbit_trajectory",
    "periodic_orbit",
]

#: Loop-state layout: plant state, controller state, friction memory.
NX_PLANT = 5
I_S = NX_PLANT  # first controller entry
I_MEM = NX_PLANT + NS
NL = I_MEM + 1


def _entries(*fields: str) -> list[int]:
    """Positions in the loop state of the named controller-state fields."""
    return [I_S + state_index(name) for name in fields]

# return codes of the section kernel
R_OK, R_FELL, R_NO_RETURN = 0, 1, 2


@jit
def loop_tick(X, pcode, gp, cp, sp, x0, substeps, ratio, h, pp, fkind, fp):
    """Advance the loop state ``X`` (:data:`NL`,) in place by one tick; return u.

    The closed loop's own tick (:func:`frictionlab.model.closedloop.step_loop`:
    measure with the simulator's sensor ``sp`` without noise and the arm's zero
    ``x0``, run the controller, then the plant over the sample), exactly as
    :func:`frictionlab.model.simulation.simulate` does.
    """
    u, X[I_MEM] = step_loop(X[:NX_PLANT], state_view(X[I_S:I_MEM]), X[I_MEM], x0, pcode,
                            substeps, ratio, pp, fkind, fp, gp, cp, sp, 0.0, 0.0, 0.0, 0.0)
    return u


@jit
def _section_returns(X0s, direction, hyst, n_min, n_max, fall_angle, pcode, gp, cp, sp, x0,
                     substeps,
                     ratio, h, pp, fkind, fp):
    """Run each row of ``X0s`` to its next ``direction`` crossing of theta = 0.

    ``direction`` is +1 (upward) or -1 (downward); the crossing counts once
    ``direction * theta`` has been below ``-hyst`` and at least ``n_min``
    ticks have passed.  Returns the states at the
    ticks before and after the crossing, the tick index after it, and a code
    (:data:`R_OK`, :data:`R_FELL`, :data:`R_NO_RETURN`) per row.
    """
    n = X0s.shape[0]
    before = np.empty_like(X0s)
    after = np.empty_like(X0s)
    ticks = np.zeros(n, dtype=np.int64)
    codes = np.full(n, R_NO_RETURN, dtype=np.int64)
    X = np.empty(X0s.shape[1])
    prev = np.empty(X0s.shape[1])
    for r in range(n):
        X[:] = X0s[r]
        armed = False
        for k in range(1, n_max + 1):
            prev[:] = X
            loop_tick(X, pcode, gp, cp, sp, x0, substeps, ratio, h, pp, fkind, fp)
            th = direction * X[0]
            if not (abs(X[0]) <= fall_angle) or not np.isfinite(X[1] + X[3] + X[4]):
                codes[r] = R_FELL
                break
            if th < -hyst:
                armed = True
            elif armed and k >= n_min and th >= 0.0 and direction * prev[0] < 0.0:
                before[r] = prev
                after[r] = X
                ticks[r] = k
                codes[r] = R_OK
                break
    return before, after, ticks, codes


@jit
def _record(X, n, pcode, gp, cp, sp, x0, substeps, ratio, h, pp, fkind, fp, fall_angle):
    """Loop states at ticks 0..n (rows), stopping early if the pendulum falls."""
    out = np.empty((n + 1, X.shape[0]))
    out[0] = X
    for k in range(1, n + 1):
        loop_tick(X, pcode, gp, cp, sp, x0, substeps, ratio, h, pp, fkind, fp)
        out[k] = X
        if not (abs(X[0]) <= fall_angle) or not np.isfinite(X[1] + X[3] + X[4]):
            return out[:k + 1]
    return out


class _Loop:
    """A loop's packed form: one-tick map and section returns."""

    def __init__(self, spec: LoopSpec):
        self.spec = spec
        self.h = spec.h
        ctrl = spec.controller
        self.controller = ctrl
        self.gp, self.cp = ctrl.record()
        self.pcode = spec.plant.code
        self.pp = spec.plant_params.record()
        self.fkind = KINDS.index(spec.friction_kind)
        # periodic orbits of the plant at its starting levels
        self.fp = without_drift(plant_record(spec.friction_kind, spec.friction))
        self.sensor = spec.sensor._replace(noise=0.0)
        self.x0 = arm_zero(self.sensor)
        self.substeps, self.ratio = spec.substeps, spec.ratio
        self.fall_angle = spec.fall_angle

    def _args(self):
        return (self.pcode, self.gp, self.cp, self.sensor, self.x0, self.substeps, self.ratio,
                self.h, self.pp, self.fkind, self.fp)

    def initial_state(self) -> np.ndarray:
        """The simulator's initial loop state (``sim.initial_angle``, at rest)."""
        X = np.zeros(NL)
        X[0] = self.spec.initial_angle
        X[I_S:I_MEM] = state_vector(self.controller.init(self.spec.initial_angle))
        return X

    def record(self, X: np.ndarray, n: int) -> np.ndarray:
        return _record(np.array(X, dtype=float), int(n), *self._args(), self.fall_angle)

    def returns(self, X0s: np.ndarray, direction: int, hyst: float, n_min: int, n_max: int):
        X0s = np.ascontiguousarray(np.atleast_2d(X0s), dtype=float)
        return _section_returns(X0s, int(direction), float(hyst), int(n_min), int(n_max),
                                self.fall_angle, self.pcode,
                                self.gp, self.cp, self.sensor, self.x0, self.substeps, self.ratio,
                                self.h, self.pp, self.fkind, self.fp)

    def free_indices(self) -> np.ndarray:
        """Continuous loop-state entries that vary on the section (theta excluded)."""
        idx = [1, 2, 3, *_entries("x1", "x2", "arm", "arm_dot")]
        if self.fkind == LUGRE:
            idx += [4, I_MEM]
        if self.controller.compensation in ("lugre", "adaptive"):
            idx += _entries("z_hat")
        return np.array(sorted(idx))

    def mirror(self, X: np.ndarray) -> np.ndarray:
        """The loop state of the mirrored loop (every signal, relay and memory negated)."""
        return -X

    def symmetric(self) -> bool:
        """Whether the loop is odd in its state (friction and compensator symmetric)."""
        def sym(p):
            return all(getattr(p, n) is None for n in
                       ("stiction_negative", "coulomb_negative", "viscous_negative"))
        return (sym(self.spec.friction)
                and (self.controller.compensation == "none"
                     or sym(self.controller.compensation_params)))


# --------------------------------------------------------------------------
# linearised loop
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class LinearLoop:
    r"""The frictionless sampled loop linearised at the upright equilibrium.

    ``X[k+1] = Phi X[k] + Gamma w[k]``, ``Y[k] = C X[k] + D w[k]`` with the
    state ``X = [theta, theta_dot, arm, arm_dot, x1_hat, x2_hat, arm_hat,
    arm_dot_hat]`` (plant, then observers; :mod:`frictionlab.model.controller`'s
    scaled ``x2_hat``), the input ``w`` an extra arm acceleration (m/s^2)
    beside ``k_u u``, held over the sample, and the outputs :attr:`outputs`.

    Attributes
    ----------
    Phi, Gamma, C, D : ndarray
        (8, 8), (8, 1), (3, 8), (3, 1).
    h : float
        Sampling period (s).
    outputs : tuple of str
        ``("arm_dot", "theta", "u")``: the arm velocity (the friction's input),
        the pendulum angle and the control signal, at the ticks.
    """

    Phi: np.ndarray
    Gamma: np.ndarray
    C: np.ndarray
    D: np.ndarray
    h: float
    outputs: tuple[str, ...] = ("arm_dot", "theta", "u")

    def frequency_response(self, omega, output: str = "arm_dot") -> np.ndarray:
        r"""``H(e^{j omega h})`` from ``w`` to ``output`` at the frequencies ``omega`` (rad/s)."""
        i = self.outputs.index(output)
        z = np.exp(1j * np.atleast_1d(np.asarray(omega, dtype=float)) * self.h)
        n = self.Phi.shape[0]
        out = np.empty(z.shape, dtype=complex)
        for k, zk in enumerate(z):
            out[k] = (self.C[i] @ np.linalg.solve(zk * np.eye(n) - self.Phi, self.Gamma[:, 0])
                      + self.D[i, 0])
        return out

    def poles(self) -> np.ndarray:
        """Closed-loop poles (z-plane)."""
        return np.linalg.eigvals(self.Phi)


#: The controller-state entries of the linear loop's state (after the plant's four).
_LIN_STATE = [state_index(name) for name in ("x1", "x2", "arm", "arm_dot")]


def linear_loop(spec: LoopSpec, eps: float = 1e-7) -> LinearLoop:
    """The loop ``spec`` without friction, linearised at the upright equilibrium.

    Central differences of one compiled tick
    (:func:`frictionlab.model.closedloop.tick_jacobian` with the friction
    switched off and no quantisation); the extra acceleration input
    ``w`` enters as ``w / k_u`` added to the controller's u, which the plant
    receives as ``k_u u + w``.  Saturation of u is outside the linear range
    and the compensator is not part of it.

    Parameters
    ----------
    spec : LoopSpec
    eps : float
        Difference step (rad, rad/s, m/s^2).
    """
    loop = _Loop(spec)
    # the thesis plant's k_u; a motor plant receives u itself (its friction,
    # in volts, enters where u does)
    ku = getattr(spec.plant_params, "input_gain", 1.0)
    gp = loop.gp.linear()  # no compensator in the linear loop
    ideal = loop.sensor._replace(step=0.0)  # the true signals (no converter, no noise)
    # the closed loop's own tick, differenced (its input disturbance du is w / k_u)
    Phi, G, K, _ = tick_jacobian(
        np.zeros(NX_PLANT), state_record(np.zeros(NS)), 0.0,
        (0.0, loop.pcode, loop.substeps, loop.ratio, loop.pp, NONE, loop.fp, gp, loop.cp, ideal),
        range(4), _LIN_STATE, eps=eps)
    Gamma = G[:, :1] / ku
    C = np.zeros((3, len(K)))
    C[0, 3] = 1.0
    C[1, 0] = 1.0
    C[2] = K
    return LinearLoop(Phi, Gamma, C, np.zeros((3, 1)), loop.h)


# --------------------------------------------------------------------------
# periodic orbit
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class PeriodicOrbit:
    """A limit cycle as a fixed point of the period map.

    Attributes
    ----------
    found : bool
        Newton reached a residual below the tolerance.
    stable : bool or None
        All Floquet multipliers inside the unit circle (None when not found).
    features : LimitCycleFeatures or None
        The features of :func:`frictionlab.model.limit_cycles.features` on the
        measured signals of a run of the simulator from the orbit's state,
        over two whole periods (None when not found); ``period`` is the
        orbit's period per upward zero crossing.
    floquet_multipliers : ndarray of complex
        Nontrivial multipliers of the full period, largest modulus first.
    period : float or None
        Return time of the period map (s).
    state : ndarray or None
        Loop state at the upward crossing (layout: module docstring).
    residual : float
        Final ``max |P(y) - y|`` over the coordinates' amplitudes.
    iterations : int
        Newton iterations.
    half_period : bool
        The symmetric half-period map was used.
    ticks : int
        Loop ticks computed in all (seed, map evaluations, features).
    message : str
        Why it was not found, or a note.
    history : list of float
        Newton's residual after each iteration.
    """

    found: bool
    stable: bool | None
    features: LimitCycleFeatures | None
    floquet_multipliers: np.ndarray
    period: float | None
    state: np.ndarray | None
    residual: float
    iterations: int
    half_period: bool
    ticks: int
    message: str = ""
    history: list = field(default_factory=list)

    def interface_dict(self) -> dict:
        """The ``periodic_orbit`` object of ``frictionlab predict --json``."""
        mult = [[float(m.real), float(m.imag)] for m in self.floquet_multipliers]
        return {
            "found": self.found,
            "stable": self.stable,
            "features": (self.features.interface_dict() if self.features is not None
                         else None),
            "floquet_multipliers": mult,
            "period": self.period,
            "residual": self.residual,
            "iterations": self.iterations,
            "half_period_map": self.half_period,
            "ticks": self.ticks,
            "message": self.message,
        }


def _not_found(message, ticks, half, residual=math.inf, iterations=0):
    return PeriodicOrbit(False, None, None, np.zeros(0, dtype=complex), None, None, residual,
                         iterations, half, ticks, message)


def _interp_crossing(before, after, fkind):
    """State at the crossing (linear between the ticks) and the tick fraction."""
    a = -before[0] / (after[0] - before[0])
    X = before + a * (after - before)
    X[0] = 0.0
    # relay states do not interpolate: take the nearer tick's
    near = after if a >= 0.5 else before
    (i_relay,) = _entries("relay")
    X[i_relay] = near[i_relay]
    if fkind != LUGRE:
        X[I_MEM] = near[I_MEM]
    return X, a


@dataclass(frozen=True)
class _Seed:
    X: np.ndarray  # loop state at an upward crossing
    hyst: float  # section hysteresis (rad)
    scale: np.ndarray  # amplitude of each free coordinate on the last period
    period: float  # last period of the transient (s)
    ticks: int


def _seed(loop: _Loop, periods: int, max_time: float, settle_tol: float = 2e-3):
    """A few transient periods from the initial state; a :class:`_Seed` or a message.

    The transient is run in 1 s chunks until it shows ``periods`` upward
    crossings of theta = 0 (with a hysteresis of 30 % of its amplitude over
    the second half of the run so far), settles (peak-to-peak below
    ``settle_tol``, the features' ``settled``, over the second half of a run
    of at least 10 s: a slow cycle can rest for seconds while the arm sticks)
    or falls.
    """
    h = loop.h
    chunk = max(1, round(1.0 / h))
    n_max = max(1, round(max_time / h))
    rec = loop.record(loop.initial_state(), chunk)
    while True:
        n = len(rec) - 1
        if rec.shape[0] - 1 < min(chunk, n_max) or not np.isfinite(rec[-1]).all() or \
                abs(rec[-1, 0]) > loop.fall_angle:
            return "the pendulum fell in the transient run", n
        th = rec[:, 0]
        if n * h >= 10.0 and np.ptp(th[len(th) // 2:]) < settle_tol:
            return "no cycle: the transient run from sim.initial_angle settles", n
        amp = float(np.abs(th[len(th) // 2:]).max())
        t = np.arange(len(th)) * h
        up_t, up_i, _dt, _di = crossings(t, th, 0.3 * amp)
        if len(up_i) >= periods + 1:
            break
        if n >= n_max:
            return (f"no cycle: fewer than {periods + 1} crossings of theta = 0 in the first "
                    f"{n * h:g} s", n)
        more = loop.record(rec[-1], chunk)
        if len(more) - 1 < chunk:
            return "the pendulum fell in the transient run", n + len(more) - 1
        rec = np.concatenate([rec, more[1:]])
    k = int(up_i[-1])
    seg = rec[int(up_i[-2]):k + 1]
    X, _ = _interp_crossing(rec[k - 1], rec[k], loop.fkind)
    scale = np.maximum(np.abs(seg[:, loop.free_indices()]).max(axis=0), 1e-9)
    return _Seed(X, 0.3 * float(np.abs(seg[:, 0]).max()), scale,
                 float(up_t[-1] - up_t[-2]), len(rec) - 1)


def periodic_orbit(
    spec: LoopSpec,
    *,
    symmetric: bool | None = None,
    seed_periods: int = 3,
    seed_time: float = 200.0,
    rel_step: float = 0.05,
    tol: float = 2e-3,
    max_iter: int = 10,
) -> PeriodicOrbit:
    """Find the loop's limit cycle as a fixed point of its period map.

    Parameters
    ----------
    spec : LoopSpec
        The loop; the sensor's noise is ignored (the map is the noise-free loop).
    symmetric : bool, optional
        Use the half-period map (True) or the full one (False).  Default:
        the half-period map when the loop is symmetric, and the full map if
        that finds no fixed point (a symmetric loop can cycle asymmetrically).
    seed_periods : int
        Periods of the transient run from ``sim.initial_angle`` that seeds
        Newton (the seed is the state at the last upward crossing).
    seed_time : float
        Longest transient run (s) while waiting for those periods.
    rel_step : float
        Difference step of the Jacobian, relative to each coordinate's
        amplitude on the seed's last period.
    tol : float
        Accept the orbit when ``max |P(y) - y| / amplitude`` is below this.
    max_iter : int
        Newton iterations at most.

    Returns
    -------
    PeriodicOrbit
    """
    loop = _Loop(spec)
    half = loop.symmetric() if symmetric is None else bool(symmetric)
    if loop.fkind in (NONE, VISCOUS):
        return _not_found(f"no friction limit cycle: the {spec.friction_kind!r} plant friction "
                          "has no switching", 0, half)
    seed = _seed(loop, seed_periods, seed_time)
    if not isinstance(seed, _Seed):
        return _not_found(seed[0], seed[1], half)
    orbit = _solve(loop, seed, half, seed.ticks, rel_step, tol, max_iter)
    if half and symmetric is None and not orbit.found:
        # a symmetric loop may still cycle asymmetrically (a pair of mirror
        # cycles): then there is no fixed point of the half-period map
        full = _solve(loop, seed, False, orbit.ticks, rel_step, tol, max_iter)
        if full.found or full.residual < orbit.residual:
            return full
    return orbit


def _solve(loop: _Loop, seed: _Seed, half: bool, ticks: int, rel_step: float, tol: float,
           max_iter: int) -> PeriodicOrbit:
    """Newton on the (half-)period map from ``seed`` (see :func:`periodic_orbit`)."""
    h = loop.h
    fkind = loop.fkind
    free = loop.free_indices()
    m = len(free)
    scale = seed.scale
    n_max = math.ceil(2.0 * seed.period / h) + 10
    # a return needs 3/4 of the (half) period: a valley of the angle that dips
    # below zero inside a half-cycle is no return
    n_min = int(0.75 * seed.period / h / (2 if half else 1))
    direction = -1 if half else 1

    def evaluate(Ys, base):
        """P(y) for each row of Ys (None where the return failed) and the return times."""
        nonlocal ticks
        X0s = np.repeat(base[None], len(Ys), axis=0)
        X0s[:, free] = Ys
        X0s[:, 0] = 0.0
        before, after, k, codes = loop.returns(X0s, direction, seed.hyst, n_min, n_max)
        ticks += int(np.where(codes == R_OK, k, n_max).sum())
        outs, times = [], []
        for r in range(len(Ys)):
            if codes[r] != R_OK:
                outs.append(None)
                times.append(None)
                continue
            X, a = _interp_crossing(before[r], after[r], fkind)
            outs.append(loop.mirror(X) if half else X)
            times.append((k[r] - 1 + a) * h)
        return outs, times

    def residual(y, base):
        outs, times = evaluate(y[None], base)
        if outs[0] is None:
            return None
        return float(np.abs((outs[0][free] - y) / scale).max()), outs[0], times[0]

    def jacobian(y, base, factors=(1.0, 0.2)):
        """Central differences at several scales, per column the smallest one
        (a jump of the map inside a difference step inflates that column); a
        scale whose perturbed runs do not return (near a fall) is skipped."""
        Ys = []
        for f in factors:
            Ys += [y + f * np.diag(steps), y - f * np.diag(steps)]
        outs, _ = evaluate(np.vstack(Ys), base)
        cols = []
        for j in range(m):
            best = None
            for i, f in enumerate(factors):
                hi, lo = outs[2 * i * m + j], outs[(2 * i + 1) * m + j]
                if hi is None or lo is None:
                    continue
                col = (hi[free] - lo[free]) / (2.0 * f * steps[j])
                if best is None or np.abs(col / scale).max() < np.abs(best / scale).max():
                    best = col
            if best is None:
                return None
            cols.append(best)
        return np.column_stack(cols)

    steps = rel_step * scale
    y = seed.X[free].copy()
    first = residual(y, seed.X)
    if first is None:
        return _not_found("the loop did not return to the section from the seed", ticks, half)
    res, P_y, t_ret = first
    base = seed.X
    history = [res]
    J, J_at = None, None
    iterations = 0
    message = ""
    while True:
        J = jacobian(y, base)
        J_at = y.copy()
        if J is None:
            message = "a difference step of the Jacobian left the cycle"
            break
        if res < 0.01 * tol or iterations == max_iter:
            break
        G = P_y[free] - y
        try:
            dy = -np.linalg.solve(J - np.eye(m), G)
        except np.linalg.LinAlgError:
            message = "singular Newton matrix"
            break
        # at most half the orbit's size per step, halved until the residual falls
        f = min(1.0, float(np.min(0.5 * scale / np.maximum(np.abs(dy), 1e-300))))
        accepted = None
        for _ in range(4):
            trial = residual(y + f * dy, P_y)
            if trial is not None and trial[0] < res:
                accepted = trial
                break
            f *= 0.5
        if accepted is None:
            break  # the floor the map's jumps leave
        iterations += 1
        y = y + f * dy
        base = P_y  # relay states of the latest return
        res, P_y, t_ret = accepted
        history.append(res)
        if res < tol and np.abs(y - J_at).max() <= np.abs(steps).max():
            # the last Jacobian was taken within one difference step: keep it
            break
    if J is None:
        return _not_found(message, ticks, half, res, iterations)
    lam = np.linalg.eigvals(J)
    mult = lam**2 if half else lam
    mult = mult[np.argsort(-np.abs(mult))]
    if res >= tol:
        return PeriodicOrbit(False, None, None, mult, None, None, res, iterations, half, ticks,
                             f"Newton stopped at residual {res:.2g} (tolerance {tol:g}): no "
                             "fixed point of the period map near the seed", history)
    X_star = base.copy()
    X_star[free] = y
    X_star[0] = 0.0
    period = 2.0 * t_ret if half else t_ret
    feats, n = _orbit_features(loop, X_star, period)
    ticks += n
    stable = bool(np.abs(mult).max() < 1.0)
    if not stable:
        # a jump of the map inside a difference step fakes a large multiplier:
        # differences on a finer scale as well, then runs from nearby states
        J3 = jacobian(y, base, (1.0, 0.2, 0.04))
        if J3 is not None:
            lam = np.linalg.eigvals(J3)
            mult = lam**2 if half else lam
            mult = mult[np.argsort(-np.abs(mult))]
            stable = bool(np.abs(mult).max() < 1.0)
    if not stable:
        d0 = _perturbed_runs(loop, X_star, free, scale, seed.hyst, period)
        ticks += 2 * math.ceil(4.2 * period / h)
        if d0 is not None:
            stable = True
            message = (f"the differences give |mu| up to {np.abs(mult).max():.3g}, but runs "
                       f"from states {d0:.1%} (of the amplitudes) off the orbit come back to "
                       "it: the map jumps inside the difference steps, so the multipliers "
                       "are unreliable here; stable by the runs")
    return PeriodicOrbit(True, stable, feats, mult, period, X_star, res, iterations, half,
                         ticks, message, history)


def _perturbed_runs(loop: _Loop, X: np.ndarray, free: np.ndarray, scale: np.ndarray,
                    hyst: float, period: float):
    """Whether the loop, run from states near the orbit, comes back to it.

    Plain runs (no restarts on the section) over four periods from
    ``X`` + d0 * scale * (random signs), d0 = 1 % and 0.2 %; the state at the
    last upward crossing must be within d0 / 2 of the orbit's.  Returns the
    d0 that came back, or None.
    """
    rng = np.random.default_rng(0)
    n = math.ceil(4.2 * period / loop.h)
    t = np.arange(n + 1) * loop.h
    for d0 in (1e-2, 2e-3):
        Y = X.copy()
        Y[free] += d0 * scale * rng.choice([-1.0, 1.0], size=len(free))
        rec = loop.record(Y, n)
        if len(rec) < n + 1:
            continue
        _ut, up_i, _dt, _di = crossings(t, rec[:, 0], hyst)
        if len(up_i) < 4:
            continue
        k = int(up_i[-1])
        Z, _ = _interp_crossing(rec[k - 1], rec[k], loop.fkind)
        if float(np.abs((Z[free] - X[free]) / scale).max()) < 0.5 * d0:
            return d0
    return None


def orbit_trajectory(spec: LoopSpec, state: np.ndarray, duration: float) -> Trajectory:
    """The simulator's run from the loop state ``state`` over ``duration`` seconds.

    The same compiled loop as :func:`frictionlab.model.simulation.simulate`
    (without noise), started from a loop state in this module's layout
    instead of the initial angle: run it from :attr:`PeriodicOrbit.state`
    to see the cycle.
    """
    return _trajectory(_Loop(spec), state, duration)


def _trajectory(loop: _Loop, state: np.ndarray, duration: float) -> Trajectory:
    n = max(1, round(duration / loop.h))
    x = np.array(state[:NX_PLANT], dtype=float)
    s = state_record(np.array(state[I_S:I_MEM], dtype=float))
    out = np.zeros((n, NC))
    done, status, _, _ = run_loop(x, float(state[I_MEM]), n, loop.pcode, loop.substeps,
                                  loop.ratio, loop.pp, loop.fkind, loop.fp, loop.gp, loop.cp, s,
                                  loop.sensor, 1, loop.x0, loop.fall_angle, out, True, False,
                                  *no_swing())
    return Trajectory(np.arange(done), loop.h, out[:done], STATUS[status], loop.spec.source,
                      noise=float(loop.spec.sensor.noise))


def _orbit_features(loop: _Loop, X: np.ndarray, period: float):
    """Features of the simulator's run from the orbit state over two whole periods.

    The window runs from the cycle's lowest angle to the same point two
    periods later, so it holds the half-cycles of exactly two periods, none
    cut.  ``period`` is the orbit's period over the number of upward
    crossings per period: the limit of a long run's mean crossing spacing,
    also when the angle crosses zero more than twice per period (several
    humps), where a finite window's mean depends on where it starts.
    """
    traj = _trajectory(loop, X, (math.ceil(3.1 * period / loop.h) + 1) * loop.h)
    t = traj.t
    th = traj["theta_m"]
    first = t < period
    start = t[np.argmin(np.where(first, th, np.inf))]
    m = (t >= start) & (t <= start + 2.0 * period)
    f = features(t[m], th[m], traj["u"][m], traj["arm_dot_m"][m], window=2.0 * period,
                 fell=traj.status == "fell")
    if f.cycles > 0 and f.status == "limit_cycle":
        f = dataclasses.replace(f, period=2.0 * period / f.cycles)
    return f, len(traj)
