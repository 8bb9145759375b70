r"""Will the sampled loop hold?  Controller settings checked against the model before use.

:func:`check_loop` takes a :class:`~frictionlab.model.controller.Controller` (gains
of Sec. 2.2-2.3, compensator of Sec. 6) and the plant it will drive
(:class:`~frictionlab.model.plants.thesis.PlantParams`) and answers, from linear models of
the sampled loop, whether applying it would hurt the motor.  The answer is a
frozen :class:`LoopCheck` with its diagnostics, in the spirit of
:func:`scipy.signal.place_poles`'s result object.

What is checked
---------------
1. **The sampled closed loop at rest** (plant, observers, state feedback).
   The plant of eq. (6) linearised upright (:func:`frictionlab.model.plants.thesis.linearize`,
   with the plant's own :math:`\omega_0`, damping and input gain, which may
   differ from the design's) and sampled with zero-order hold at h; the
   controller is the compiled :func:`~frictionlab.model.controller.controller_step`
   itself, linearised by central differences (no second copy of the observer
   equations), without saturation.  State: the plant's four states and the
   controller's four estimates, u from the predicted estimates as in the
   loop.  The loop is *unstable* when an eigenvalue of this 8 x 8 matrix lies
   outside the unit circle.

2. **The friction compensator along the sliding motion.**  Near rest a
   friction-free linear model says nothing useful about a compensator (the
   arm is held by its own bristles or stiction), so the compensator is
   checked where it acts: with the arm sliding at the speeds of
   :data:`SLIDING_SPEEDS` (the compensated and uncompensated limit cycles'
   arm speeds), the plant's friction being a static level there (its
   bristles at their steady state), and the compensator's step linearised
   at that speed (the LuGre observer's bristle :math:`\hat z` at the steady
   state of eq. (18), the Coulomb relay switched to the sign of the speed).
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
   friction level.

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

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from .controller import (
    Controller,
    Gains,
    compensator_force,
    controller_step,
    new_state,
    state_index,
    state_record,
    state_vector,
)
from .friction import steady_bristle, stribeck_curve
from .plants.furuta_dc import FurutaDCParams
from .plants.furuta_dc import linearization as dc_linearization
from .plants.thesis import PlantParams, linearize, rhs, zoh

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
        speeds checked (None without compensation).
    compensator_speed : float or None
        The arm speed (rad/s) where it is largest.
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


def loop_matrices(controller: Controller, plant: PlantParams | None = None,
                  arm_speed: float = 0.0, *, compensate: bool | None = None):
    """The sampled closed loop linearised: ``X+ = M X + N w``, ``u = K X + D w``.

    Parameters
    ----------
    controller : Controller
    plant : PlantParams, optional
        The plant the controller drives (default: the nominal plant).
    arm_speed : float
        Arm speed (rad/s) of the operating point: 0 is the upright rest;
        otherwise the arm slides at this speed (the compensator linearised
        there, see the module docstring).
    compensate : bool, optional
        Include the compensator (default: when the controller has one and
        ``arm_speed`` is not 0).

    Returns
    -------
    M : ndarray (n, n)
        State: the plant's (theta, theta_dot, Omega, Omega_dot), the
        controller's (theta_hat, theta_dot_hat / omega0, Omega_hat,
        Omega_dot_hat) and, with the LuGre compensator, its z_hat.
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
    states = list(_PEND_ARM)
    if compensate and controller.compensation in ("lugre", "adaptive"):
        states.append(state_index("z_hat"))
    # sliding: the arm's friction is the compensator's own steady-state friction (its
    # premise), a static function of the speed; its slope enters the arm
    slope = (_steady_slope(controller, cp, arm_speed) if compensate and arm_speed != 0.0
             else 0.0)
    Phi, gam = _sampled_plant(plant, controller.design.spec.h, float(slope))

    v = float(arm_speed)
    rec0 = new_state(arm_dot=arm_speed)
    if v != 0.0:
        rec0.relay = math.copysign(1.0, v)
        rec0.z_hat = steady_bristle(v, cp)
    s0 = state_vector(rec0)
    x0 = np.array([0.0, 0.0, 0.0, v])
    c0 = s0[states]
    n_x, n = 4, 4 + len(states)

    def step(dx, dc, w):
        s = s0.copy()
        s[states] = c0 + dc
        x = x0 + dx
        u, _, _ = controller_step(state_record(s), gp, cp, x[0] + w[0], x[2] + w[1],
                                  x[3] + w[2])
        return np.concatenate([Phi @ dx + gam * u, s[states] - c0]), u

    M = np.zeros((n, n))
    K = np.zeros(n)
    N = np.zeros((n, 3))
    D = np.zeros(3)
    zx, zc, zw = np.zeros(n_x), np.zeros(n - n_x), np.zeros(3)
    for j in range(n + 3):
        eps = 1e-6 * max(1.0, abs(c0[j - n_x]) if n_x <= j < n else 1.0)
        e = np.zeros(n + 3)
        e[j] = eps
        (a, ua) = step(zx + e[:n_x], zc + e[n_x:n], zw + e[n:])
        (b, ub) = step(zx - e[:n_x], zc - e[n_x:n], zw - e[n:])
        col, dcol = (a - b) / (2 * eps), (ua - ub) / (2 * eps)
        if j < n:
            M[:, j], K[j] = col, dcol
        else:
            N[:, j - n], D[j - n] = col, dcol
    return M, N, K, D


@functools.lru_cache(maxsize=64)
def _sampled_plant(plant: PlantParams, h: float, slope: float):
    """ZOH of the plant linearised upright, with a friction slope dF/dv on the arm (cached:
    a search over controller settings samples the same plant again and again).  A
    motor plant (:class:`~frictionlab.model.plants.furuta_dc.FurutaDCParams`): its
    linearisation in volts."""
    A, B = dc_linearization(plant) if isinstance(plant, FurutaDCParams) else linearize(plant)
    if slope:
        A = A + np.outer(_friction_input(plant), [0.0, 0.0, 0.0, slope])
    Phi, Gam = zoh(A, B, h)
    Phi.flags.writeable = False
    gam = Gam[:, 0].copy()
    gam.flags.writeable = False
    return Phi, gam


def _friction_input(plant: PlantParams) -> np.ndarray:
    """d(rhs)/dF at rest: how the arm friction (units of u) enters eq. (6); on a motor
    plant as the opposite of the voltage (u - F)."""
    if isinstance(plant, FurutaDCParams):
        return -dc_linearization(plant)[1][:, 0]
    x0 = np.zeros(4)
    return (rhs(0.0, x0, (0.0, 1.0), plant) - rhs(0.0, x0, (0.0, -1.0), plant)) / 2.0


def _steady_slope(controller: Controller, cp: np.record, v: float) -> float:
    """Slope dF/dv (m/s^2 per rad/s) of the compensator's steady-state estimate at ``v``.

    LuGre: the Stribeck curve with viscous friction (where its exactly
    integrated bristle settles in steady sliding); classical: the Stribeck
    level outside the band; Coulomb: a constant level.
    """
    dv = 1e-6 * max(1.0, abs(v))
    if controller.compensation in ("lugre", "adaptive"):
        return (stribeck_curve(v + dv, cp) - stribeck_curve(v - dv, cp)) / (2 * dv)
    code, h = controller.compensator_code, controller.design.spec.h
    relay = math.copysign(1.0, v)
    hi = compensator_force(code, new_state(relay=relay), cp, v + dv, 0.0, 0.0, h)
    lo = compensator_force(code, new_state(relay=relay), cp, v - dv, 0.0, 0.0, h)
    return (hi - lo) / (2 * dv)


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


def check_loop(controller: Controller, plant: PlantParams | None = None, *,
               noise: float = DEFAULT_NOISE, disturbance: float = DEFAULT_DISTURBANCE,
               speeds: tuple[float, ...] = SLIDING_SPEEDS, horizon: float = 4.0) -> LoopCheck:
    """Check a controller against the model of the plant it will drive.

    Parameters
    ----------
    controller : Controller
        Gains and compensator to check (its ``u_max`` is the DAC limit).
    plant : PlantParams, optional
        The plant (default: nominal).  Its ``omega0`` may differ from the
        design's, as on a real rig.
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
    if controller.compensation != "none":
        eps = controller.compensation_params.hysteresis
        checked = [v for v in speeds
                   if controller.compensation in ("lugre", "adaptive") or abs(v) > eps]
        for v in checked:
            r = _radius(loop_matrices(controller, plant, v, compensate=True)[0])
            if comp_rho is None or r > comp_rho:
                comp_rho, comp_speed = r, float(v)

    level = _compensator_level(controller)
    if rho > 1.0 + _TOL:
        peak_d = sigma_u = peak = math.inf
    else:
        x_init = np.zeros(len(M))
        x_init[0] = disturbance
        x_init[4] = disturbance  # the observer starts at the measured angle
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
    if comp_rho is not None and comp_rho > 1.0 + _TOL:
        reasons.append(f"the {controller.compensation} compensator makes the loop unstable "
                       f"with the arm sliding at {comp_speed:g} rad/s (spectral radius "
                       f"{comp_rho:.4g} > 1)")
    if math.isfinite(peak) and peak > u_max:
        unit = "V" if isinstance(plant, FurutaDCParams) else "m/s^2"
        reasons.append(f"u would saturate: predicted peak |u| {peak:.3g} {unit} > the DAC "
                       f"limit {u_max:.3g} (recovering from {disturbance:g} rad: "
                       f"{peak_d:.3g}; noise {noise:g}: {NOISE_SIGMAS:g} x {sigma_u:.3g}; "
                       f"compensator: {level:.3g})")
    if rho > 1.0 + _TOL:
        verdict = "unstable"
    elif comp_rho is not None and comp_rho > 1.0 + _TOL:
        verdict = "compensator_unstable"
    elif peak > u_max:
        verdict = "saturating"
    else:
        verdict = "ok"
    ev.flags.writeable = False
    return LoopCheck(verdict, tuple(reasons), ev, rho, comp_rho, comp_speed, peak, peak_d,
                     sigma_u, level, u_max, float(disturbance), float(noise))

