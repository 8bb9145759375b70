r"""Will the sampled loop hold?  Controller settings checked against the model before use.

:func:`check_loop` takes a :class:`~frictionlab.model.controller.Controller` (gains
of Sec. 2.2-2.3, compensator of Sec. 6) and the plant it will drive
(:class:`~frictionlab.model.plants.thesis.PlantParams`, or a DC-motor plant's
:class:`~frictionlab.model.plants.furuta_dc.FurutaDCParams`) and answers, from linear models of
the sampled loop, whether applying it would hurt the motor.  The answer is a
frozen :class:`LoopCheck` with its diagnostics, in the spirit of
:func:`scipy.signal.place_poles`'s result object.

What is checked
---------------
1. **The sampled closed loop at rest** (plant, observers, state feedback).
   The closed loop's own compiled tick
   (:func:`frictionlab.model.closedloop.step_loop`: the noise-free sensor, the
   compiled :func:`~frictionlab.model.controller.controller_step`, the plant's
   step :func:`frictionlab.model.plants.plant_step` between samples) linearised
   at the upright rest by central differences
   (:func:`~frictionlab.model.closedloop.tick_jacobian`), without saturation
   and without friction; no second copy of the plant or the observer
   equations.  The plant is the one the controller will drive (the thesis's
   eq. (6) with its own :math:`\omega_0`, damping and input gain, which may
   differ from the design's, or the DC-motor Furuta pendulum,
   :mod:`frictionlab.model.plants`), integrated as the simulator integrates
   it.  State: the plant's four states and the controller's four estimates,
   u from the predicted estimates as in the loop.  The loop is *unstable*
   when an eigenvalue of this 8 x 8 matrix lies outside the unit circle.

2. **The friction compensator along the sliding motion.**  Near rest a
   friction-free linear model says nothing useful about a compensator (the
   arm is held by its own bristles or stiction), so the compensator is
   checked where it acts: the same tick linearised with the arm sliding at
   the speeds of :data:`SLIDING_SPEEDS` (the compensated and uncompensated
   limit cycles' arm speeds), the plant's friction being the compensator's
   own law and parameters (its premise: the model is right; the LuGre plant's
   bristle, its observer gain k off, settled at the steady state of eq. (18),
   the Coulomb relay switched to the sign of the speed), and the compensator
   linearised there (the LuGre observer's bristle :math:`\hat z` at its
   steady state, the relay at the sign of the speed).  The tick brings the
   sliding arm's effect on the pendulum with it: the centripetal term
   :math:`\dot\Omega^2\sin\theta\cos\theta` of eq. (6) raises the upright
   pendulum's instability from :math:`\omega_0^2` to
   :math:`\omega_0^2 + \dot\Omega^2` (docs/architecture.md, "The loop check
   through the one tick").  The compensator is found to destabilise the loop
   where the compensated loop's spectral radius exceeds 1 and that of the same
   sliding loop without the compensator: a slow design that the centripetal
   term alone takes past 1 (the QUBE's at 3 rad/s) is no compensator's doing,
   and the simulated fall check of the console judges it.
   The compensator's own update needs no bound of its own: the bristle is
   integrated exactly over the sample (docs/compensation.md: the
   forward-Euler bound :math:`\sigma_0|v|h/s(v) < 2` does not apply to it).
   What can go unstable is the sampled loop through the compensator: the
   velocity innovation enters :math:`\hat F` with the direct gain
   :math:`\sigma_1 k`, and each sample the arm's velocity answers with
   :math:`h/L_1` of it.  This reproduces which of the tuning grid's LuGre
   settings made the simulated pendulum fall (exactly those with k = 15 and
   :math:`\sigma_1 \ge 6`), and that the arm's control errors as the error
   signal (``arm_velocity``, ``arm_angle``) destabilise the loop.

3. **The predicted peak of u** against the DAC limit (saturation): the
   response of the stable loop at rest to a pendulum angle of ``disturbance``
   rad (the observers starting at the measured angle, as the controller
   does), plus three standard deviations of the u that measurement noise of
   ``noise`` (rad, rad, rad/s on the three measured signals) causes in steady
   state (discrete Lyapunov equation), plus the compensator's largest
   friction level (all in the units of u: m/s^2, or volts for a motor plant).

The ``adaptive`` compensator is checked as the LuGre observer at its
starting levels with the adaptation frozen (its own law is stable by the
conditions :func:`frictionlab.model.adaptive.check_gains` enforces, and it moves
the levels slowly), its largest level being the estimates' bound
``adaptation_max``.

The check is linear: it does not predict the limit cycles friction causes
(Sec. 4-5), nor whether such a cycle grows until the pendulum falls.  The
loop's own safety stops (angle limit, non-finite u) stay the last line.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from .closedloop import tick_jacobian
from .controller import (
    ADAPTIVE,
    COMPENSATOR_CODES,
    DC_PENDULUM_OBSERVER,
    Controller,
    Gains,
    new_state,
    state_index,
    state_vector,
)
from .friction import (
    COULOMB,
    LUGRE,
    NONE,
    plant_record,
    steady_bristle,
    steady_state,
)
from .friction import KINDS as FRICTION_KINDS
from .plants import plant_of
from .plants.thesis import PlantParams
from .rig import RigScaling
from .sensor import sensor_params

__all__ = [
    "DEFAULT_DISTURBANCE",
    "DEFAULT_NOISE",
    "NOISE_SIGMAS",
    "SLIDING_SPEEDS",
    "VERDICTS",
    "LoopCheck",
    "check_loop",
    "loop_matrices",
]

#: Arm speeds (rad/s) at which the compensator is checked: the compensated limit
#: cycles' (0.1-1) and the uncompensated ones' (up to 3-6) arm speeds.
SLIDING_SPEEDS = (0.3, 1.0, 3.0)
#: Measurement noise assumed when none is configured (rad, rad, rad/s): the level of
#: docs/compensation.md's studies.
DEFAULT_NOISE = 0.002
#: Pendulum angle (rad) whose recovery gives the predicted peak of u.
DEFAULT_DISTURBANCE = 0.05
#: Standard deviations of noise-driven u counted in the predicted peak.
NOISE_SIGMAS = 3.0
#: Possible verdicts, from the worst.
VERDICTS = ("unstable", "compensator_unstable", "saturating", "ok")
#: An eigenvalue modulus above 1 + this counts as unstable (the compensated loop
#: has neutral modes at exactly 1, e.g. a constant bristle offset).
_TOL = 1e-6
#: Controller states that are linear dynamic states (the relay is discrete).
_PEND_ARM = tuple(state_index(name) for name in ("x1", "x2", "arm", "arm_dot"))
#: Pendulum steps per sample of the thesis plant's integrator (``sim.pendulum_steps``).
_PENDULUM_STEPS = 2
#: The noise-free sensor without a converter the check reads the plant with.
_IDEAL_SENSOR = sensor_params(RigScaling(), quantization=0.0)


@dataclass(frozen=True)
class LoopCheck:
    """Result of :func:`check_loop`.

    Attributes
    ----------
    verdict : str
        ``"ok"``, or the worst finding: ``"unstable"`` (the loop at rest),
        ``"compensator_unstable"`` (the loop with the compensator, sliding),
        ``"saturating"`` (predicted peak of u beyond the DAC limit).
    reasons : tuple of str
        One sentence per finding (empty when ``ok``).
    eigenvalues : ndarray (8,) complex
        Of the sampled loop at rest (plant, observers, state feedback),
        largest modulus first.
    spectral_radius : float
        Their largest modulus.
    compensator_radius : float or None
        Largest spectral radius of the compensated loop over the sliding
        speeds checked (None without compensation); with the verdict
        ``compensator_unstable``, the largest where the compensator takes it
        past 1 and past the sliding loop's own without it.
    compensator_speed : float or None
        The arm speed (rad/s) of that radius.
    peak_u : float
        Predicted largest |u| (m/s^2): ``peak_u_disturbance + NOISE_SIGMAS *
        u_noise_std + compensator_level``; inf for an unstable loop.
    peak_u_disturbance : float
        Largest |u| while recovering from the disturbance (m/s^2).
    u_noise_std : float
        Standard deviation of u caused by the measurement noise (m/s^2).
    compensator_level : float
        Largest friction level the compensator adds (m/s^2; 0 without).
    u_max : float
        The DAC limit of u (m/s^2).
    disturbance, noise : float
        The pendulum angle (rad) and measurement noise assumed.
    """

    verdict: str
    reasons: tuple[str, ...]
    eigenvalues: np.ndarray
    spectral_radius: float
    compensator_radius: float | None
    compensator_speed: float | None
    peak_u: float
    peak_u_disturbance: float
    u_noise_std: float
    compensator_level: float
    u_max: float
    disturbance: float
    noise: float

    @property
    def ok(self) -> bool:
        """True when nothing was found."""
        return self.verdict == "ok"

    def to_json(self) -> dict:
        """JSON-ready diagnostics (eigenvalues as ``[re, im]`` pairs; inf as None)."""

        def num(x):
            return None if x is None or not math.isfinite(x) else float(x)

        return {
            "verdict": self.verdict,
            "ok": self.ok,
            "reasons": list(self.reasons),
            "eigenvalues": [[float(z.real), float(z.imag)] for z in self.eigenvalues],
            "spectral_radius": num(self.spectral_radius),
            "compensator_radius": num(self.compensator_radius),
            "compensator_speed": num(self.compensator_speed),
            "peak_u": num(self.peak_u),
            "peak_u_disturbance": num(self.peak_u_disturbance),
            "u_noise_std": num(self.u_noise_std),
            "compensator_level": num(self.compensator_level),
            "u_max": num(self.u_max),
            "disturbance": self.disturbance,
            "noise": self.noise,
        }


def _analysis_pack(controller: Controller, compensate: bool) -> tuple[Gains, np.record]:
    gp, cp = controller.record()
    gp = gp._replace(u_max=math.inf)  # the linear loop, without saturation
    if not compensate:
        gp = gp.linear()
    return gp, cp


def loop_matrices(controller: Controller, plant=None, arm_speed: float = 0.0, *,
                  compensate: bool | None = None):
    """The sampled closed loop linearised: ``X+ = M X + N w``, ``u = K X + D w``.

    The closed loop's tick (:func:`frictionlab.model.closedloop.tick_jacobian`)
    at the upright rest or with the arm sliding (the module docstring).

    Parameters
    ----------
    controller : Controller
    plant : PlantParams or FurutaDCParams, optional
        The plant the controller drives (default: the thesis's nominal plant).
    arm_speed : float
        Arm speed (rad/s) of the operating point: 0 is the upright rest;
        otherwise the arm slides at this speed (the compensator linearised
        there, the plant's friction the compensator's own law).
    compensate : bool, optional
        Include the compensator (default: when the controller has one and
        ``arm_speed`` is not 0).

    Returns
    -------
    M : ndarray (n, n)
        State: the plant's (theta, theta_dot, Omega, Omega_dot), with a LuGre
        plant friction its bristle z and the friction of its last substep;
        then the controller's (theta_hat, theta_dot_hat / omega0, Omega_hat,
        Omega_dot_hat) and, with the LuGre compensator, its z_hat (with a motor
        plant's pendulum observer also the last tick's u and F_hat, which its
        innovation reads).
    N : ndarray (n, 3)
        Effect of additive errors w on the measured (theta, Omega, Omega_dot).
    K : ndarray (n,)
        u as a function of the state.
    D : ndarray (3,)
        u as a function of w.
    """
    plant = plant or PlantParams()
    if compensate is None:
        compensate = controller.compensation != "none" and arm_speed != 0.0
    gp, cp = _analysis_pack(controller, compensate)
    v = float(arm_speed)
    states = list(_PEND_ARM)
    if compensate and controller.compensation in ("lugre", "adaptive"):
        states.append(state_index("z_hat"))
        if gp.observer == DC_PENDULUM_OBSERVER:
            # the innovation against the model's arm prediction reads the last
            # tick's u and F_hat (controller.arm_prediction): they are states too
            states += [state_index("u"), state_index("f_hat")]
    # sliding: the plant's friction is the compensator's own law (its premise), its
    # bristle or relay settled at the speed; at rest: no friction
    fkind, fp = _plant_friction(controller) if compensate and v != 0.0 else (NONE, cp)
    x = np.array([0.0, 0.0, 0.0, v, 0.0])
    mem = 0.0
    if fkind == LUGRE:
        x[4] = steady_bristle(v, fp)
        mem = steady_state(LUGRE, fp, v)
    elif fkind == COULOMB:
        mem = math.copysign(1.0, v)
    s = new_state(arm_dot=v)
    if v != 0.0:
        s.relay = math.copysign(1.0, v)
        s.z_hat = steady_bristle(v, cp)
    kind = plant_of(plant)
    row = plant.record()
    substeps = kind.substeps[FRICTION_KINDS[fkind]]
    ratio = max(1, -(-substeps // _PENDULUM_STEPS))
    M, G, K, D = tick_jacobian(
        x, s, mem, (0.0, kind.code, substeps, ratio, row, fkind, fp, gp, cp, _IDEAL_SENSOR),
        [0, 1, 2, 3, 4] if fkind == LUGRE else [0, 1, 2, 3], states, mem_coord=fkind == LUGRE)
    return M, G[:, 1:], K, D[1:]


def _plant_friction(controller: Controller) -> tuple[int, np.record]:
    """The plant friction of the sliding check: the compensator's law (the classical
    compensator's implementation form, the adaptive one's LuGre observer at its
    starting levels) with its parameters, as a plant's
    (:func:`~frictionlab.model.friction.plant_record`), without the observer gain k
    (eq. 19's error is the compensator's)."""
    code = COMPENSATOR_CODES[controller.compensation]
    code = LUGRE if code == ADAPTIVE else code
    params = dataclasses.replace(controller.compensation_params, observer_gain=0.0)
    return code, plant_record(FRICTION_KINDS[code], params)


def _radius(M: np.ndarray) -> float:
    ev = np.linalg.eigvals(M)
    return float(np.max(np.abs(ev))) if np.all(np.isfinite(ev)) else math.inf


def _peak_u(M, K, x_init, ticks: int, block: int = 50) -> float:
    """Largest |K M^k x_init| over ``ticks`` steps (in blocks of K M^j, j < block)."""
    rows = [K]
    for _ in range(block - 1):
        rows.append(rows[-1] @ M)
    P = np.array(rows)
    MB = np.linalg.matrix_power(M, block)
    x = x_init.copy()
    peak = 0.0
    for _ in range(-(-ticks // block)):
        peak = max(peak, float(np.max(np.abs(P @ x))))
        x = MB @ x
    return peak


def _compensator_level(controller: Controller) -> float:
    p = controller.compensation_params
    if controller.compensation == "none":
        return 0.0
    levels = [p.coulomb, p.coulomb_negative or 0.0]
    if controller.compensation != "coulomb":
        levels += [p.stiction, p.stiction_negative or 0.0]
    if controller.compensation == "adaptive":
        levels.append(p.adaptation_max)  # the estimates' bound
    return float(max(levels))


def check_loop(controller: Controller, plant=None, *,
               noise: float = DEFAULT_NOISE, disturbance: float = DEFAULT_DISTURBANCE,
               speeds: tuple[float, ...] = SLIDING_SPEEDS, horizon: float = 4.0) -> LoopCheck:
    """Check a controller against the model of the plant it will drive.

    Parameters
    ----------
    controller : Controller
        Gains and compensator to check (its ``u_max`` is the DAC limit).
    plant : PlantParams or FurutaDCParams, optional
        The plant (default: the thesis's nominal plant).  Its parameters may
        differ from the design's (a thesis plant's ``omega0``), as on a real rig.
    noise : float
        Measurement noise standard deviation on each measured signal (SI).
    disturbance : float
        Pendulum angle (rad) the loop recovers from for the peak of u.
    speeds : tuple of float
        Arm speeds (rad/s) of the compensator's check.
    horizon : float
        Seconds of the recovery simulated for the peak of u.

    Returns
    -------
    LoopCheck
    """
    if not (noise >= 0 and math.isfinite(noise)):
        raise ValueError(f"noise must be >= 0, got {noise}")
    if not (disturbance >= 0 and math.isfinite(disturbance)):
        raise ValueError(f"disturbance must be >= 0, got {disturbance}")
    plant = plant or PlantParams()
    h = controller.design.spec.h
    u_max = float(controller.u_max)
    M, N, K, D = loop_matrices(controller, plant, 0.0, compensate=False)
    ev = np.linalg.eigvals(M) if np.all(np.isfinite(M)) else np.full(len(M), np.inf + 0j)
    ev = ev[np.argsort(-np.abs(ev), kind="stable")]
    rho = float(np.max(np.abs(ev)))
    reasons = []

    comp_rho = comp_speed = None
    comp_unstable = False
    if controller.compensation != "none":
        eps = controller.compensation_params.hysteresis
        checked = [v for v in speeds
                   if controller.compensation in ("lugre", "adaptive") or abs(v) > eps]
        fails = []  # (radius, speed) where the compensator takes the loop past 1
        for v in checked:
            r = _radius(loop_matrices(controller, plant, v, compensate=True)[0])
            if comp_rho is None or r > comp_rho:
                comp_rho, comp_speed = r, float(v)
            if r > 1.0 + _TOL:
                # the sliding loop's own radius without the compensator: the centripetal
                # term alone can take a slow design past 1 (that is no compensator's doing,
                # and the fall check simulates it)
                r0 = _radius(loop_matrices(controller, plant, v, compensate=False)[0])
                if r > r0 + _TOL:
                    fails.append((r, float(v)))
        if fails:
            comp_rho, comp_speed = max(fails)
        comp_unstable = bool(fails)

    level = _compensator_level(controller)
    if rho > 1.0 + _TOL:
        peak_d = sigma_u = peak = math.inf
    else:
        x_init = np.zeros(len(M))
        x_init[0] = disturbance
        # the observers start at the measured angle, as the controller does
        x_init[4:] = state_vector(controller.init(disturbance))[list(_PEND_ARM)]
        peak_d = _peak_u(M, K, x_init, max(1, round(horizon / h)))
        if noise > 0:
            P = solve_discrete_lyapunov(M, noise * noise * (N @ N.T))
            sigma_u = math.sqrt(max(float(K @ P @ K + noise * noise * (D @ D)), 0.0))
        else:
            sigma_u = 0.0
        peak = peak_d + NOISE_SIGMAS * sigma_u + level

    if rho > 1.0 + _TOL:
        reasons.append(f"the sampled closed loop (plant, observers, state feedback) is "
                       f"unstable: an eigenvalue has modulus {rho:.4g} > 1")
    if comp_unstable:
        reasons.append(f"the {controller.compensation} compensator makes the loop unstable "
                       f"with the arm sliding at {comp_speed:g} rad/s (spectral radius "
                       f"{comp_rho:.4g} > 1)")
    if math.isfinite(peak) and peak > u_max:
        unit = plant_of(plant).u_unit  # m/s^2, or V for a motor plant
        reasons.append(f"u would saturate: predicted peak |u| {peak:.3g} {unit} > the DAC "
                       f"limit {u_max:.3g} (recovering from {disturbance:g} rad: "
                       f"{peak_d:.3g}; noise {noise:g}: {NOISE_SIGMAS:g} x {sigma_u:.3g}; "
                       f"compensator: {level:.3g})")
    if rho > 1.0 + _TOL:
        verdict = "unstable"
    elif comp_unstable:
        verdict = "compensator_unstable"
    elif peak > u_max:
        verdict = "saturating"
    else:
        verdict = "ok"
    ev.flags.writeable = False
    return LoopCheck(verdict, tuple(reasons), ev, rho, comp_rho, comp_speed, peak, peak_d,
                     sigma_u, level, u_max, float(disturbance), float(noise))

