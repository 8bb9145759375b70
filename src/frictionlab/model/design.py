r"""Discrete pole-placement state feedback and observer gains (Sec. 2.2-2.4, App. C-D).

The controller is designed on the frictionless, undamped linearisation
eq. (7) sampled with zero-order hold at ``h``: Sec. 2.2's closed form
(:func:`frictionlab.model.plants.thesis.zoh_closed_form`, equal to the matrix exponential of
:func:`frictionlab.model.plants.thesis.zoh` to rounding, tested; it needs no scipy, so a
design loads in milliseconds).
Continuous specifications :math:`(\omega_i, \zeta_i)` map to the discrete
characteristic polynomial eq. (8)

.. math:: (q^2 + p_1 q + p_2)(q^2 + p_3 q + p_4),\quad
          p_1 = -2e^{-\zeta_1\omega_1 h}\cos(\omega_1\sqrt{1-\zeta_1^2}h),\;
          p_2 = e^{-2\zeta_1\omega_1 h}

and the gain row ``L`` (``u = -L x``) is found either by the closed form of
Appendix C or by numerical placement (:func:`scipy.signal.place_poles`); the
two agree to rounding (tested, and cross-checked against python-control).

Observer gains (Sec. 2.3): the nonlinear pendulum observer's
:math:`k_1 = 2\zeta_{o1}\omega_{o1}`, :math:`k_2 = \omega_{o1}^2/\omega_0 + \omega_0`
(continuous-time, from the Jacobian at the upright position in the scaled
state :math:`x_2 = \dot\theta/\omega_0`), and the discrete arm observer's
:math:`k_3 = 2 + p_{o3}`, :math:`k_4 = (1 + p_{o3} + p_{o4})/h` (eq. 11-12).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from .params import Validated, param
from .plants.thesis import PlantParams, zoh_closed_form

__all__ = [
    "PRESETS",
    "Design",
    "DesignSpec",
    "FeedbackDesign",
    "ObserverDesign",
    "char_coefficients",
    "design",
    "discrete_pair",
    "feedback_closed_form",
    "feedback_numeric",
    "gain_path",
    "match_poles",
    "observer_gains",
    "place",
    "preset",
]


#: Smallest pole frequency a design accepts (rad/s): below, the poles sit within 5e-5 of
#: z = 1 at h = 5 ms, the loop at rest takes minutes to recover, and at 1e-300 the pole
#: placement's and the loop check's numbers lose their meaning (a modulus of 1 + 8e-9).
MIN_OMEGA = 0.01


@dataclass(frozen=True)
class DesignSpec(Validated):
    """Controller and observer specifications (keys ``design.*``).

    Defaults are the fast design, eqs. (13)-(14).  ``gains`` replaces the
    pole placement by given state-feedback gains (e.g. an LQR designed with
    python-control, docs/ecosystem.md); the observers are designed from the
    specs as always.
    """

    _prefix = "design."

    omega0: float = param(6.8, "omega_0 assumed by the design and the observers", "rad/s",
                          lo=0.0, hi=100.0, lo_open=True)
    h: float = param(0.005, "sampling period [h]", "s", lo=0.0, hi=1.0, lo_open=True)
    omega1: float = param(6.8, "pendulum closed-loop natural frequency [omega_1]", "rad/s",
                          lo=MIN_OMEGA, hi=1e3)
    zeta1: float = param(0.7, "pendulum closed-loop damping [zeta_1]", "1", lo=0.0, hi=1.0,
                         lo_open=True)
    omega2: float = param(10.0, "arm closed-loop natural frequency [omega_2]", "rad/s",
                          lo=MIN_OMEGA, hi=1e3)
    zeta2: float = param(0.7, "arm closed-loop damping [zeta_2]", "1", lo=0.0, hi=1.0,
                         lo_open=True)
    observer_omega1: float = param(20.0, "pendulum observer natural frequency [omega_o1]",
                                   "rad/s", lo=MIN_OMEGA, hi=1e3)
    observer_zeta1: float = param(0.7, "pendulum observer damping [zeta_o1]", "1", lo=0.0,
                                  hi=1.0, lo_open=True)
    observer_omega2: float = param(10.0, "arm observer natural frequency [omega_o2]", "rad/s",
                                   lo=MIN_OMEGA, hi=1e3)
    observer_zeta2: float = param(0.7, "arm observer damping [zeta_o2]", "1", lo=0.0, hi=1.0,
                                  lo_open=True)
    full_observer: int = param(
        0, "motor plants only: 1 = the 4-state predictor observer on the full linearised "
        "model (needs the motor's constants), 0 = the pendulum observer driven by the "
        "measured arm acceleration (the default: little model, robust to parameter errors); "
        "the thesis plant always uses the observers of Sec. 2.3", "1", lo=0, hi=1,
        integer=True)
    gains: tuple[float, float, float, float] | None = param(
        None, "state-feedback gains L = (l1, l2, l3, l4) of u = -L x (x = theta, theta_dot, "
        "arm, arm_dot; m/s^2 per rad or rad/s), used instead of the "
        "pole placement of omega1, zeta1, omega2, zeta2 (None = place those poles)",
        "m/s^2/state", optional=True, length=4)


#: The two designs of Sec. 2.4: fast (eqs. 13-14) and slow (eqs. 15-16).
PRESETS: dict[str, DesignSpec] = {
    "fast": DesignSpec(),
    "slow": DesignSpec(omega2=3.0, observer_omega2=7.5),
}


def preset(name: str) -> DesignSpec:
    """The ``fast`` or ``slow`` design of Sec. 2.4."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"design must be one of {', '.join(PRESETS)}; got {name!r}") from None


def discrete_pair(omega: float, zeta: float, h: float) -> np.ndarray:
    """z-plane images :math:`e^{sh}` of the roots of :math:`s^2 + 2\\zeta\\omega s + \\omega^2`."""
    s = np.roots([1.0, 2.0 * zeta * omega, omega * omega]).astype(complex)
    return np.sort_complex(np.exp(s * h))


def _pq(omega: float, zeta: float, h: float, dtype=float) -> tuple[float, float]:
    """Coefficients (p, q) of :math:`z^2 + p z + q`, eq. (8) (valid for zeta <= 1)."""
    omega, zeta, h = dtype(omega), dtype(zeta), dtype(h)
    wd = omega * np.sqrt(max(dtype(1) - zeta * zeta, dtype(0)))
    p = -2 * np.exp(-omega * zeta * h) * np.cos(wd * h)
    q = np.exp(-2 * omega * zeta * h)
    return p, q


def char_coefficients(spec: DesignSpec, dtype=float) -> tuple[float, float, float, float]:
    """(p1, p2, p3, p4) of eq. (8)."""
    p1, p2 = _pq(spec.omega1, spec.zeta1, spec.h, dtype)
    p3, p4 = _pq(spec.omega2, spec.zeta2, spec.h, dtype)
    return p1, p2, p3, p4


def feedback_closed_form(spec: DesignSpec, g: float, arm_length: float) -> np.ndarray:
    """State-feedback gains ``L`` from the closed form of Appendix C."""
    # Evaluated in extended precision: the formulas cancel heavily for small w0*h.
    ld = np.longdouble
    p1, p2, p3, p4 = (ld(v) for v in char_coefficients(spec, dtype=ld))
    w0, h, L1, g = ld(spec.omega0), ld(spec.h), ld(arm_length), ld(g)
    c = np.cosh(w0 * h)
    s = np.sinh(w0 * h)
    cm1 = 2.0 * np.sinh(0.5 * w0 * h) ** 2  # cosh(w0 h) - 1 without cancellation
    l1 = -0.25 * (
        4 * c**2 - 2 * c + 2 * p2 * p4 * c + 2 * c * p1 + 2 * c * p3 - p1 + p2 * p3 + p1 * p4
        + p4 - p3 - 1 + p2 - p2 * p4 + p1 * p3
    ) * g / cm1**2
    l2 = -0.25 * (
        4 * c**2 + 2 * c * p1 + 2 * c * p3 + 2 * c - 2 * p2 * p4 * c - p2 * p3 - 1 + p4
        - p2 * p4 + p2 - p1 * p4 + p1 * p3 + p1 + p3
    ) * g / (cm1 * w0 * s)
    l3 = -0.5 * (
        p2 * p3 + p2 + p1 * p4 + 1 + p1 * p3 + p2 * p4 + p4 + p1 + p3
    ) * L1 / (h**2 * cm1)
    l4 = -0.25 * (
        5 + 3 * p1 + 3 * p3 + p2 + p4 - 3 * p2 * p4 + p1 * p3 - p1 * p4 - p2 * p3
    ) * L1 / (h * cm1)
    return np.array([l1, l2, l3, l4], dtype=float)


def _design_matrices(spec: DesignSpec, g: float, arm_length: float):
    return zoh_closed_form(spec.omega0, g, arm_length, spec.h)


def feedback_numeric(spec: DesignSpec, g: float, arm_length: float) -> np.ndarray:
    """State-feedback gains ``L`` by numerical pole placement on (Phi, Gamma)."""
    Phi, Gamma = _design_matrices(spec, g, arm_length)
    return place(Phi, Gamma, requested_poles(spec))


def place(Phi: np.ndarray, Gamma: np.ndarray, poles) -> np.ndarray:
    """The gain row ``L`` giving ``Phi - Gamma L`` the eigenvalues ``poles`` (one
    input): :func:`scipy.signal.place_poles`, or Ackermann's formula when a pole
    repeats (a damping of exactly 1)."""
    poles = np.asarray(poles)
    if len(np.unique(np.round(poles, 12))) == len(poles):
        from scipy.signal import place_poles  # heavy import, only when used

        res = place_poles(Phi, Gamma, poles)
        return np.asarray(res.gain_matrix, dtype=float).ravel()
    n = Phi.shape[0]
    coeffs = np.real(np.poly(poles))
    phi = sum(c * np.linalg.matrix_power(Phi, n - i) for i, c in enumerate(coeffs))
    ctrb = np.hstack([np.linalg.matrix_power(Phi, i) @ Gamma for i in range(n)])
    e_n = np.zeros((1, n))
    e_n[0, -1] = 1.0
    return (e_n @ np.linalg.solve(ctrb, phi)).ravel()


def requested_poles(spec: DesignSpec) -> np.ndarray:
    """The four requested closed-loop poles in the z-plane."""
    return np.concatenate([
        discrete_pair(spec.omega1, spec.zeta1, spec.h),
        discrete_pair(spec.omega2, spec.zeta2, spec.h),
    ])


def observer_gains(spec: DesignSpec) -> np.ndarray:
    """Observer gains ``[k1, k2, k3, k4]`` of Sec. 2.3."""
    k1 = 2.0 * spec.observer_zeta1 * spec.observer_omega1
    k2 = spec.observer_omega1**2 / spec.omega0 + spec.omega0
    po3, po4 = (float(v) for v in _pq(spec.observer_omega2, spec.observer_zeta2, spec.h))
    k3 = 2.0 + po3
    k4 = (1.0 + po3 + po4) / spec.h
    return np.array([k1, k2, k3, k4])


def match_poles(achieved: np.ndarray, requested: np.ndarray) -> np.ndarray:
    """Order ``achieved`` to pair with ``requested`` (greedy nearest)."""
    left = list(achieved)
    out = []
    for r in requested:
        i = int(np.argmin([abs(a - r) for a in left]))
        out.append(left.pop(i))
    return np.array(out)


@dataclass(frozen=True)
class FeedbackDesign:
    """Result of the state-feedback design.

    Attributes
    ----------
    L : ndarray (4,)
        Gains of ``u = -L x`` for ``x = (theta, theta_dot, Omega, Omega_dot)``.
    requested_poles, achieved_poles : ndarray (4,) complex
        z-plane poles asked for and eigenvalues of ``Phi - Gamma L`` (paired).
        With given gains (``design.gains``) nothing is asked for: both are
        the poles those gains place on the design model.
    Phi, Gamma : ndarray
        The ZOH design model.
    method : str
        ``"closed_form"`` (Appendix C), ``"numeric"``, or ``"given"``
        (``design.gains``).
    """

    L: np.ndarray
    requested_poles: np.ndarray
    achieved_poles: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray
    method: str

    @property
    def max_pole_error(self) -> float:
        return float(np.max(np.abs(self.achieved_poles - self.requested_poles)))


@dataclass(frozen=True)
class ObserverDesign:
    """Result of the observer design.

    Attributes
    ----------
    K : ndarray (4,)
        ``[k1, k2, k3, k4]``.
    requested_continuous : ndarray (2,) complex
        Requested pendulum-observer poles (s-plane).
    achieved_continuous : ndarray (2,) complex
        Eigenvalues of the linearised pendulum observer ``A - K C``.
    requested_discrete, achieved_discrete : ndarray (4,) complex
        z-plane poles: the pendulum observer as implemented (forward
        differences, ``I + h(A - KC)``) and the arm observer
        (``Phi_2 - K_2 C_2``); requested = ``1 + h s`` resp. eq. (11).
    """

    K: np.ndarray
    requested_continuous: np.ndarray
    achieved_continuous: np.ndarray
    requested_discrete: np.ndarray
    achieved_discrete: np.ndarray


@dataclass(frozen=True)
class Design:
    """A complete controller design: specs, feedback and observers."""

    spec: DesignSpec
    g: float
    arm_length: float
    feedback: FeedbackDesign
    observer: ObserverDesign

    @property
    def L(self) -> np.ndarray:
        return self.feedback.L

    @property
    def K(self) -> np.ndarray:
        return self.observer.K

    def to_json(self) -> dict:
        """The ``frictionlab design --json`` object (poles as ``[re, im]`` pairs)."""

        def pairs(z):
            return [[float(np.real(v)), float(np.imag(v))] for v in z]

        return {
            "L": [float(v) for v in self.L],
            "K": [float(v) for v in self.K],
            "poles": pairs(self.feedback.achieved_poles),
            "observer_poles": pairs(self.observer.achieved_discrete),
            "requested_poles": pairs(self.feedback.requested_poles),
            "requested_observer_poles": pairs(self.observer.requested_discrete),
            "observer_poles_continuous": pairs(self.observer.achieved_continuous),
            "spec": dataclasses.asdict(self.spec),
            "method": self.feedback.method,
        }


def design(
    spec: DesignSpec | str = "fast",
    plant: PlantParams | None = None,
    method: str = "closed_form",
) -> Design:
    """Design the state feedback and the observers (cached; see :func:`_design`).

    Parameters
    ----------
    spec : DesignSpec or {"fast", "slow"}
        Specifications (a preset name selects Sec. 2.4's designs).
    plant : PlantParams, optional
        Supplies the arm length and g (``omega0`` comes from ``spec.omega0``,
        which may differ from the simulated plant's).
    method : {"closed_form", "numeric"}
        Appendix C's formulas or numerical placement (``spec.gains``, when
        given, is used instead of either).

    Returns
    -------
    Design
        Frozen; its arrays are read-only.
    """
    if isinstance(spec, str):
        spec = preset(spec)
    plant = plant or PlantParams()
    return _design(spec, plant.g, plant.arm_length, method)


def gain_path(spec_from: DesignSpec, spec_to: DesignSpec, plant: PlantParams | None = None,
              steps: int = 10) -> np.ndarray:
    r"""The gains along the straight line between two designs' specifications.

    Row i holds the state feedback L and the observer gains K (App. C) of the
    specification i/steps of the way from ``spec_from`` to ``spec_to`` (every
    field but ``h``): each row places the closed-loop and the observer poles of
    an intermediate design, whereas a straight line in L itself can pass
    through gains that place them badly.  From the fast design to the slow
    one, with K switched at once, a straight line in L left the pendulum
    swinging up to 0.27 rad, against 0.19 rad along this path
    (docs/realtime.md, "Switching while running").  A gain transition moves
    the gains piecewise linearly along these rows.  With given gains
    (``spec.gains``) at either end, only the two ends.

    Returns
    -------
    ndarray (steps + 1, 8)
        ``(l1, l2, l3, l4, k1, k2, k3, k4)``, of ``spec_from`` first, of
        ``spec_to`` last.
    """
    plant = plant or PlantParams()

    def row(sp):
        d = design(sp, plant)
        return np.concatenate([d.L, d.K])

    if spec_from.gains is not None or spec_to.gains is not None or steps < 2:
        return np.array([row(spec_from), row(spec_to)])
    names = [f.name for f in dataclasses.fields(DesignSpec) if f.name not in ("h", "gains")]
    rows = [row(spec_from)]
    for i in range(1, steps):
        r = i / steps
        rows.append(row(dataclasses.replace(spec_from, **{
            f: getattr(spec_from, f) + r * (getattr(spec_to, f) - getattr(spec_from, f))
            for f in names})))
    rows.append(row(spec_to))
    return np.array(rows, dtype=float)


@functools.lru_cache(maxsize=256)
def _design(spec: DesignSpec, g: float, arm_length: float, method: str) -> Design:
    L1 = arm_length
    Phi, Gamma = _design_matrices(spec, g, L1)
    if method not in ("closed_form", "numeric"):
        raise ValueError(f"method must be 'closed_form' or 'numeric'; got {method!r}")
    if spec.gains is not None:
        L = np.array(spec.gains, dtype=float)
        req = np.sort_complex(np.linalg.eigvals(Phi - Gamma @ L.reshape(1, 4)))
        method = "given"
    else:
        L = (feedback_closed_form(spec, g, L1) if method == "closed_form"
             else feedback_numeric(spec, g, L1))
        req = requested_poles(spec)
    ach = match_poles(np.linalg.eigvals(Phi - Gamma @ L.reshape(1, 4)), req)
    fb = FeedbackDesign(L, req, ach, Phi, Gamma, method)

    K = observer_gains(spec)
    w0, h = spec.omega0, spec.h
    A1 = np.array([[0.0, w0], [w0, 0.0]])
    AK = A1 - np.array([[K[0]], [K[1]]]) @ np.array([[1.0, 0.0]])
    s_req = np.sort_complex(np.roots([1.0, 2 * spec.observer_zeta1 * spec.observer_omega1,
                                      spec.observer_omega1**2]).astype(complex))
    s_ach = match_poles(np.linalg.eigvals(AK), s_req)
    Phi2 = np.array([[1.0, h], [0.0, 1.0]])
    AK2 = Phi2 - np.array([[K[2]], [K[3]]]) @ np.array([[1.0, 0.0]])
    z_req = np.concatenate([1.0 + h * s_req,
                            discrete_pair(spec.observer_omega2, spec.observer_zeta2, h)])
    z_ach = np.concatenate([
        match_poles(np.linalg.eigvals(np.eye(2) + h * AK), z_req[:2]),
        match_poles(np.linalg.eigvals(AK2), z_req[2:]),
    ])
    obs = ObserverDesign(K, s_req, s_ach, z_req, z_ach)
    for arr in (L, req, ach, Phi, Gamma, K, s_req, s_ach, z_req, z_ach):
        arr.flags.writeable = False
    return Design(spec, g, L1, fb, obs)
