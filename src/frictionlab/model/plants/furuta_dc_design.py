r"""The balancing design for the DC-motor Furuta pendulum (Sec. 2.2-2.4 on its
linearisation).

State feedback ``u = -L x`` (u in volts, x = theta, theta_dot, arm, arm_dot)
by discrete pole placement at h on the zero-order-hold discretisation of
:func:`frictionlab.model.plants.furuta_dc.linearization` (back-EMF and
viscous damping included: they are part of this plant's linear dynamics),
with the pole pattern of Sec. 2.4: the pendulum pair at
:math:`(\omega_1, \zeta_1)`, the arm pair at :math:`(\omega_2, \zeta_2)`,
mapped by eq. (8).  The thesis's presets (eqs. 13-16) are carried over by
their pattern: :math:`\omega_1 = \omega_0`, the rate of this plant's unstable
upright mode (12.5 rad/s for the QUBE-Servo 2 against the thesis rig's 6.8),
the arm's frequencies (10 and 3 rad/s, observer 10 and 7.5) unchanged; the
pendulum observer's :math:`\omega_{o1}` is :data:`OBSERVER_RATIO` times
:math:`\omega_0` (80 rad/s on the QUBE-Servo 2; below).  Given
gains (``design.gains``: e.g. an LQR from python-control, docs/model.md)
replace the placement.

Not everything is measured: the QUBE gives theta and the arm angle from its
encoders and the arm rate from its tachometer, but not theta_dot.

The pendulum observer (the default, ``design.full_observer`` 0)
---------------------------------------------------------------
Only theta_dot is estimated, and from the pendulum's own equation, as the
thesis's pendulum observer (Sec. 2.3) does: the linearised coupled equations
give, whatever the arm and the motor,

.. math:: J_p\ddot\theta = c\,\theta - D_p\dot\theta - b\,\ddot\phi,

(:math:`c = m_p g l_p`, :math:`b = m_p l_p L_r`; the thesis's
:math:`\ddot\theta = \omega_0^2\theta - (\omega_0^2/g)\,u` with u the arm
tip's acceleration :math:`L_r\ddot\phi`), so the arm's acceleration,
measured as the difference of the measured arm rate over the last tick,
drives it and the motor's constants, the arm's inertia and the viscous arm
damping drop out.  Exact ZOH discretisation (the difference is the mean
acceleration over the tick), then a *current* correction with this tick's
theta (no prediction: the voltage law needs no model):

.. math:: \bar x = F\hat x_{k-1} + g\,(\dot\phi_k - \dot\phi_{k-1})/h,\quad
          \hat x_k = \bar x + K(\theta_k - \bar x_1),\quad
          u_k = -L(\theta_k, \hat{\dot\theta}_k, \phi_k, \dot\phi_k)

with the poles of :math:`(I - K e_1^T)F` at the z-images of
:math:`(\omega_{o1}, \zeta_{o1})`; the measured angles and arm rate are
used as measured (``observer_omega2``/``observer_zeta2`` are not used).  On
300 QUBE-Servo 2 linearisations drawn within +-20 % the loop with this
observer is stable wherever the true-state feedback is, but for one or two
(benchmarks/dc_observer.py, docs/model.md); the predictor below fails on
about 70 %.

The full-model predictor (``design.full_observer`` 1)
-----------------------------------------------------
A discrete linear predictor on the same 4-state model,

.. math:: \hat x_{k+1} = \Phi\hat x_k + \Gamma u_k + K(y_k - C\hat x_k),
          \quad y = (\theta, \phi, \dot\phi)

with its four poles at the z-images of the design's observer specs
(:math:`(\omega_{o1}, \zeta_{o1})` and :math:`(\omega_{o2}, \zeta_{o2})`),
placed on :math:`(\Phi^T, C^T)`. It needs the motor's constants: with them 20 % off
the loop is unstable on most plants.  As the thesis's controller does, the
estimate used at tick k was formed at tick k-1 (read, compute u from
:math:`\hat x_k`, output, then update: :func:`dc_observer_step`).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from .._jit import jit
from ..design import DesignSpec, discrete_pair, match_poles, place, requested_poles
from ..design import preset as design_preset
from .furuta_dc import QUBE2, FurutaDCParams, linearization
from .thesis import zoh

__all__ = [
    "MEASURED",
    "OBSERVER_RATIO",
    "DCDesign",
    "dc_design",
    "dc_observer_step",
    "dc_observer_update",
    "dc_predicted_peak",
    "dc_spec",
    "observer_row",
    "pendulum_model",
    "pendulum_observer_update",
]

#: Rows of C: what the rig measures (theta, arm, arm_dot).
MEASURED = ("theta", "arm", "arm_dot")
_C = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


#: The presets' pendulum observer frequency over the plant's omega0 (80 rad/s on
#: the QUBE-Servo 2): on +-20 % plants the loop's robustness grows with it up to
#: about 80 rad/s (benchmarks/dc_observer.py) while the encoder's quantisation
#: in theta_dot grows with it too.  (The thesis's pattern, 20/6.8, gave 36.6 rad/s:
#: the former full-model predictor's default.)
OBSERVER_RATIO = 6.4


def dc_spec(spec: DesignSpec | str = "fast", params: FurutaDCParams = QUBE2,
            h: float | None = None) -> DesignSpec:
    """The design's specifications for this plant.

    A preset name (``fast``, ``slow``) gives the thesis's Sec. 2.4 pattern on
    this plant: ``omega0`` and ``omega1`` the plant's unstable rate
    :attr:`FurutaDCParams.omega0`, ``observer_omega1`` :data:`OBSERVER_RATIO`
    times it (the pendulum observer's pair), the arm's frequencies as in the
    thesis.  A
    :class:`DesignSpec` is used as given, its ``omega0`` set to the plant's.
    ``h`` replaces the sampling period.
    """
    w0 = params.omega0
    if isinstance(spec, str):
        base = design_preset(spec)
        scale = w0 / base.omega0
        spec = dataclasses.replace(base, omega1=base.omega1 * scale,
                                   observer_omega1=OBSERVER_RATIO * w0)
    spec = dataclasses.replace(spec, omega0=w0)
    if h is not None:
        spec = dataclasses.replace(spec, h=h)
    return spec


@dataclass(frozen=True)
class DCDesign:
    """A balancing design for the DC-motor plant (arrays read-only).

    Attributes
    ----------
    spec : DesignSpec
        The specifications used (:func:`dc_spec`).
    params : FurutaDCParams
    A, B : ndarray
        The continuous linearisation at upright (input in volts).
    Phi, Gamma : ndarray
        Its ZOH discretisation at ``spec.h``.
    C : ndarray (3, 4)
        The measured states (:data:`MEASURED`).
    L : ndarray (4,)
        ``u = -L x`` (V per rad, V per rad/s).
    K : ndarray (4, 3), or (2, 1) for the pendulum observer
        The observer's gain.
    requested_poles, poles : ndarray (4,) complex
        z-plane poles of ``Phi - Gamma L`` asked for and achieved (paired);
        with given gains both are the achieved ones.
    requested_observer_poles, observer_poles : ndarray complex
        z-plane poles of the observer's error asked for and achieved (4 of
        ``Phi - K C``; 2 of ``(I - K e_1^T) F`` for the pendulum observer).
    method : str
        ``"numeric"`` (pole placement) or ``"given"`` (``spec.gains``).
    F, g : ndarray (2, 2), (2,)
        The pendulum observer's model, :func:`pendulum_model` at ``spec.h``.
    """

    spec: DesignSpec
    params: FurutaDCParams
    A: np.ndarray
    B: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray
    C: np.ndarray
    L: np.ndarray
    K: np.ndarray
    requested_poles: np.ndarray
    poles: np.ndarray
    requested_observer_poles: np.ndarray
    observer_poles: np.ndarray
    method: str
    F: np.ndarray
    g: np.ndarray

    @property
    def full_observer(self) -> bool:
        """The 4-state predictor (``design.full_observer`` 1), else the pendulum observer."""
        return bool(self.spec.full_observer)

    @property
    def max_pole_error(self) -> float:
        """Largest distance between a requested and an achieved pole (both loops)."""
        return float(max(np.max(np.abs(self.poles - self.requested_poles)),
                         np.max(np.abs(self.observer_poles - self.requested_observer_poles))))

    def to_json(self) -> dict:
        """The design as JSON (poles as ``[re, im]`` pairs; ``linearization`` the
        continuous A and B at upright, input in volts)."""

        def pairs(z):
            return [[float(np.real(v)), float(np.imag(v))] for v in z]

        return {
            "L": [float(v) for v in self.L],
            "K": [[float(v) for v in row] for row in self.K],
            "poles": pairs(self.poles),
            "observer_poles": pairs(self.observer_poles),
            "requested_poles": pairs(self.requested_poles),
            "requested_observer_poles": pairs(self.requested_observer_poles),
            "spec": dataclasses.asdict(self.spec),
            "method": self.method,
            "observer": "full" if self.full_observer else "pendulum",
            "linearization": {
                "A": [[float(v) for v in row] for row in self.A],
                "B": [[float(v) for v in row] for row in self.B],
                "states": ["theta", "theta_dot", "arm", "arm_dot"],
                "input": "u (V)",
            },
        }


def dc_design(spec: DesignSpec | str = "fast", params: FurutaDCParams = QUBE2,
              h: float | None = None) -> DCDesign:
    """Design the state feedback and the observer (module docstring).

    Parameters
    ----------
    spec : DesignSpec or {"fast", "slow"}
        Specifications (:func:`dc_spec`); ``spec.gains`` (V per state unit)
        replaces the placement.
    params : FurutaDCParams
        The plant (default the QUBE-Servo 2).
    h : float, optional
        Sampling period (s); default ``spec.h``.

    Returns
    -------
    DCDesign
        Frozen, its arrays read-only (cached: the same arguments give the same
        object).
    """
    return _dc_design(dc_spec(spec, params, h), params)


@functools.lru_cache(maxsize=256)
def _dc_design(spec: DesignSpec, params: FurutaDCParams) -> DCDesign:
    A, B = linearization(params)
    Phi, Gamma = zoh(A, B, spec.h)
    if spec.gains is not None:
        L = np.array(spec.gains, dtype=float)
        req = np.sort_complex(np.linalg.eigvals(Phi - Gamma @ L.reshape(1, 4)))
        method = "given"
    else:
        req = requested_poles(spec)
        L = place(Phi, Gamma, req)
        method = "numeric"
    ach = match_poles(np.linalg.eigvals(Phi - Gamma @ L.reshape(1, 4)), req)

    from scipy.signal import place_poles  # heavy import, only when used

    F, g = pendulum_model(params, spec.h)
    if spec.full_observer:
        obs_req = np.concatenate([
            discrete_pair(spec.observer_omega1, spec.observer_zeta1, spec.h),
            discrete_pair(spec.observer_omega2, spec.observer_zeta2, spec.h),
        ])
        K = np.asarray(place_poles(Phi.T, _C.T, obs_req).gain_matrix, dtype=float).T
        obs_ach = match_poles(np.linalg.eigvals(Phi - K @ _C), obs_req)
    else:
        # current observer: error dynamics (I - K e1^T) F, placed on (F^T, (e1^T F)^T)
        obs_req = discrete_pair(spec.observer_omega1, spec.observer_zeta1, spec.h)
        cF = F[:1, :]
        K = np.asarray(place_poles(F.T, cF.T, obs_req).gain_matrix, dtype=float).T
        obs_ach = match_poles(np.linalg.eigvals((np.eye(2) - K @ np.array([[1.0, 0.0]])) @ F),
                              obs_req)
    C = _C.copy()
    for arr in (A, B, Phi, Gamma, C, L, K, req, ach, obs_req, obs_ach, F, g):
        arr.flags.writeable = False
    return DCDesign(spec, params, A, B, Phi, Gamma, C, L, K, req, ach, obs_req, obs_ach,
                    method, F, g)


def pendulum_model(params: FurutaDCParams, h: float) -> tuple[np.ndarray, np.ndarray]:
    r"""The pendulum's own linearised equation, discretised: ``(F, g)`` with
    :math:`x_{k+1} = F x_k + g\,a_k`, x = (theta, theta_dot), a the arm's mean
    angular acceleration over the tick (rad/s^2), held (ZOH).

    From :math:`J_p\ddot	heta = c\,	heta - D_p\dot	heta - b\,\ddot\phi`
    (module docstring): only the pendulum's mass, length, inertia and damping
    and the arm's length enter, not the motor or the arm's inertia.
    """
    j_p, _j0, b, c, _kv, _km, _dr, d_p = (float(v) for v in params.record())
    Ap = np.array([[0.0, 1.0], [c / j_p, -d_p / j_p]])
    Bp = np.array([[0.0], [-b / j_p]])
    F, g = zoh(Ap, Bp, h)
    return np.asarray(F, dtype=float), np.asarray(g, dtype=float).ravel()


def observer_row(result: DCDesign) -> np.ndarray:
    """The float row the controller step reads, 32 floats: Phi (16, row by
    row), Gamma (4), then for the full-model predictor
    (:func:`dc_observer_step`) K (12, row by row: 4 rows of 3), for the
    pendulum observer (:func:`pendulum_observer_update`) F (4, row by row),
    g (2), K (2) and 4 zeros."""
    if result.full_observer:
        tail = result.K.ravel()
    else:
        tail = np.concatenate([result.F.ravel(), result.g, result.K.ravel(), np.zeros(4)])
    return np.concatenate([result.Phi.ravel(), result.Gamma.ravel(), tail])


@jit
def pendulum_observer_update(x0, x1, theta_m, accel, o):
    """One tick of the pendulum observer (module docstring): the estimate
    (theta, theta_dot) of the last tick ``(x0, x1)``, this tick's measured
    angle and the arm's mean angular acceleration over the last tick ``accel``
    (rad/s^2) give this tick's estimate (two floats); ``o`` the row of
    :func:`observer_row` (F at 20-23, g at 24-25, K at 26-27)."""
    p0 = o[20] * x0 + o[21] * x1 + o[24] * accel
    p1 = o[22] * x0 + o[23] * x1 + o[25] * accel
    e = theta_m - p0
    return p0 + o[26] * e, p1 + o[27] * e


@jit
def dc_observer_update(x0, x1, x2, x3, theta_m, arm_m, arm_dot_m, u, o):
    """:func:`dc_observer_step` on the estimate ``(x0, x1, x2, x3)`` given and
    returned as four floats; ``o`` the row of :func:`observer_row` (an array
    or a tuple of its 32 floats: the controller's gains carry it as one)."""
    e0 = theta_m - x0
    e1 = arm_m - x2
    e2 = arm_dot_m - x3
    n0 = (o[0] * x0 + o[1] * x1 + o[2] * x2 + o[3] * x3 + o[16] * u
          + o[20] * e0 + o[21] * e1 + o[22] * e2)
    n1 = (o[4] * x0 + o[5] * x1 + o[6] * x2 + o[7] * x3 + o[17] * u
          + o[23] * e0 + o[24] * e1 + o[25] * e2)
    n2 = (o[8] * x0 + o[9] * x1 + o[10] * x2 + o[11] * x3 + o[18] * u
          + o[26] * e0 + o[27] * e1 + o[28] * e2)
    n3 = (o[12] * x0 + o[13] * x1 + o[14] * x2 + o[15] * x3 + o[19] * u
          + o[29] * e0 + o[30] * e1 + o[31] * e2)
    return n0, n1, n2, n3


@jit
def dc_observer_step(xhat, theta_m, arm_m, arm_dot_m, u, obs_row):
    """One step of the predictor observer: ``xhat`` (4,) becomes the estimate
    for the next tick, in place, from this tick's measurements and the
    voltage u applied over it.

    ``xhat <- Phi xhat + Gamma u + K (y - C xhat)``, y = (theta_m, arm_m,
    arm_dot_m); ``obs_row`` from :func:`observer_row`
    (:func:`dc_observer_update` computes it).
    """
    xhat[0], xhat[1], xhat[2], xhat[3] = dc_observer_update(
        xhat[0], xhat[1], xhat[2], xhat[3], theta_m, arm_m, arm_dot_m, u, obs_row)


@jit
def dc_predicted_peak(l1, l2, l3, l4, o, theta, theta_dot, arm_dot, n):
    """Largest |u| (V) of the state feedback ``u = -L x`` over the next ``n``
    ticks, predicted on the design's discretised linearisation (``Phi``,
    ``Gamma`` of :func:`observer_row`'s row ``o``) from (theta, theta', arm 0,
    arm'): the swing-up's hand-over test on this plant (no friction, no
    saturation)."""
    x0, x1, x2, x3 = theta, theta_dot, 0.0, arm_dot
    peak = 0.0
    for _ in range(int(n)):
        u = -(l1 * x0 + l2 * x1 + l3 * x2 + l4 * x3)
        peak = max(peak, abs(u))
        n0 = o[0] * x0 + o[1] * x1 + o[2] * x2 + o[3] * x3 + o[16] * u
        n1 = o[4] * x0 + o[5] * x1 + o[6] * x2 + o[7] * x3 + o[17] * u
        n2 = o[8] * x0 + o[9] * x1 + o[10] * x2 + o[11] * x3 + o[18] * u
        n3 = o[12] * x0 + o[13] * x1 + o[14] * x2 + o[15] * x3 + o[19] * u
        x0, x1, x2, x3 = n0, n1, n2, n3
    return peak
