r"""The rotary (Furuta) inverted pendulum with arm friction, eq. (6).

State vector
------------
The plant state is documented here once; every module uses these indices.

=====  ============  ===========================================  =========
index  name          meaning                                      unit
=====  ============  ===========================================  =========
0      ``THETA``     pendulum angle :math:`\theta`, 0 = upright    rad
1      ``THETA_DOT`` pendulum angular velocity :math:`\dot\theta`  rad/s
2      ``ARM``       arm angle :math:`\Omega`                      rad
3      ``ARM_DOT``   arm angular velocity :math:`\dot\Omega`       rad/s
4      ``Z``         LuGre bristle deflection :math:`z` (only for  (m/s^2)/
                     the LuGre friction model; 0 otherwise)        sigma0
=====  ============  ===========================================  =========

The control signal ``u`` is the commanded tangential acceleration of the arm
tip, :math:`u = \ddot\Omega L_1` (eq. 1), in m/s^2.  Friction on the arm
bearing is expressed in the same unit (``F = F_fr/m``), so the *net* arm tip
acceleration is :math:`a = k_u u - F` where :math:`k_u` is
``PlantParams.input_gain`` (the uncertain control scaling of App. B.4, 1 in
the nominal model).  Eq. (6) then reads

.. math::

    \ddot\theta &= -2\zeta\omega_0\dot\theta + \omega_0^2\sin\theta
                   + \dot\Omega^2\sin\theta\cos\theta - \frac{\omega_0^2}{g} a\cos\theta \\
    \ddot\Omega &= a / L_1

:func:`accelerations` is the single implementation of these equations (a
numba-compiled function); :func:`rhs` wraps it in python-control's
``updfcn(t, x, u, params)`` order and is what linearisation, identification
and the tests use, while the compiled simulator and the observers call
:func:`accelerations` directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ._jit import jit
from .params import Validated, param

__all__ = [
    "ARM",
    "ARM_DOT",
    "NX",
    "THETA",
    "THETA_DOT",
    "PlantParams",
    "PlantRecord",
    "Z",
    "accelerations",
    "accelerations_sc",
    "linearize",
    "linearized_model",
    "plant_record",
    "rhs",
    "zoh",
    "zoh_closed_form",
]

THETA, THETA_DOT, ARM, ARM_DOT, Z = 0, 1, 2, 3, 4
NX = 5


@dataclass(frozen=True)
class PlantParams(Validated):
    """Physical parameters of the pendulum (Sec. 2.1, App. A; keys ``plant.*``)."""

    _prefix = "plant."

    omega0: float = param(6.8, "natural frequency of the pendulum [omega_0]", "rad/s",
                          lo=0.0, hi=100.0, lo_open=True)
    zeta: float = param(0.04, "relative damping of the pendulum [zeta]", "1", lo=0.0, hi=1.0)
    arm_length: float = param(0.21, "arm length [L_1]", "m", lo=0.0, hi=10.0, lo_open=True)
    g: float = param(9.82, "gravitational acceleration [g]", "m/s^2", lo=0.0, hi=100.0,
                     lo_open=True)
    input_gain: float = param(1.0, "multiplier on the u the plant receives (App. B.4's k_u "
                              "uncertainty)", "1", lo=0.0, hi=10.0, lo_open=True)

    @property
    def pendulum_length(self) -> float:
        """Equivalent pendulum length :math:`L_2 = g/\\omega_0^2` in m."""
        return self.g / self.omega0**2

    def record(self) -> PlantRecord:
        """The typed record the compiled integrator reads."""
        return PlantRecord(float(self.omega0), float(self.zeta), float(self.g),
                           float(self.arm_length), float(self.input_gain))


class PlantRecord(NamedTuple):
    """The plant parameters as the compiled code reads them (a float record;
    :meth:`PlantParams.record`; ``np.array(record)`` is a row of a batch,
    :func:`plant_record` reads it back)."""

    omega0: float
    zeta: float
    g: float
    arm_length: float
    input_gain: float


@jit
def plant_record(row):
    """The :class:`PlantRecord` stored as the float row ``np.array(record)``."""
    return PlantRecord(row[0], row[1], row[2], row[3], row[4])


@jit
def accelerations_sc(sin_theta, cos_theta, theta_dot, arm_dot, a, omega0, zeta, g, arm_length):
    r""":func:`accelerations` with :math:`\sin\theta, \cos\theta` supplied (the
    integrator reuses them between evaluations)."""
    theta_ddot = (
        -2.0 * zeta * omega0 * theta_dot
        + omega0 * omega0 * sin_theta
        + arm_dot * arm_dot * sin_theta * cos_theta
        - omega0 * omega0 / g * a * cos_theta
    )
    return theta_ddot, a * (1.0 / arm_length)  # the reciprocal is hoisted out of loops


@jit
def accelerations(theta, theta_dot, arm_dot, a, omega0, zeta, g, arm_length):
    r"""Pendulum and arm angular accelerations of eq. (6).

    Parameters
    ----------
    theta, theta_dot, arm_dot : float
        :math:`\theta` (rad), :math:`\dot\theta`, :math:`\dot\Omega` (rad/s).
    a : float
        Net arm tip acceleration :math:`k_u u - F_{fr}/m` in m/s^2.
    omega0, zeta, g, arm_length : float
        Plant parameters.

    Returns
    -------
    (theta_ddot, arm_ddot) : tuple of float
    """
    return accelerations_sc(np.sin(theta), np.cos(theta), theta_dot, arm_dot, a, omega0, zeta,
                            g, arm_length)


def rhs(t: float, x, u, params: PlantParams) -> np.ndarray:
    """Time derivative of the mechanical state, eq. (6).

    Signature follows python-control's ``updfcn(t, x, u, params)``.

    Parameters
    ----------
    t : float
        Time in s (the model is time invariant; unused).
    x : array_like, shape (4,) or (5,)
        State, see the module table.  A 5th entry (LuGre ``z``) is carried
        through with zero derivative: the bristle dynamics live in
        :mod:`frictionlab.model.friction`.
    u : float or array_like of length 2
        Control signal u in m/s^2, or ``(u, F)`` with the arm friction F in
        units of u (m/s^2).
    params : PlantParams

    Returns
    -------
    numpy.ndarray
        dx/dt with the shape of ``x``.
    """
    x = np.asarray(x, dtype=float)
    u_arr = np.atleast_1d(np.asarray(u, dtype=float))
    friction = float(u_arr[1]) if u_arr.size > 1 else 0.0
    a = params.input_gain * float(u_arr[0]) - friction
    th_dd, arm_dd = accelerations(
        x[THETA], x[THETA_DOT], x[ARM_DOT], a, params.omega0, params.zeta, params.g,
        params.arm_length,
    )
    dx = np.zeros_like(x)
    dx[THETA] = x[THETA_DOT]
    dx[THETA_DOT] = th_dd
    dx[ARM] = x[ARM_DOT]
    dx[ARM_DOT] = arm_dd
    return dx


def linearize(params: PlantParams, eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Numerical Jacobian of :func:`rhs` at the upright equilibrium.

    Central differences on the 4 mechanical states and the control input.

    Returns
    -------
    A : ndarray (4, 4)
    B : ndarray (4, 1)
    """
    x0 = np.zeros(4)
    A = np.zeros((4, 4))
    for j in range(4):
        dx = np.zeros(4)
        dx[j] = eps
        A[:, j] = (rhs(0.0, x0 + dx, 0.0, params) - rhs(0.0, x0 - dx, 0.0, params)) / (2 * eps)
    B = ((rhs(0.0, x0, eps, params) - rhs(0.0, x0, -eps, params)) / (2 * eps)).reshape(4, 1)
    return A, B


def linearized_model(omega0: float, g: float, arm_length: float, zeta: float = 0.0):
    """Closed-form linearisation around the upright position, eq. (7).

    The thesis's eq. (7) neglects damping (``zeta = 0``, the design model);
    a nonzero ``zeta`` adds ``-2 zeta omega0`` in ``A[1, 1]``.

    Returns
    -------
    A, B, C : ndarray
        ``C`` selects the measured signals (theta, Omega, Omega_dot).
    """
    A = np.array(
        [[0.0, 1.0, 0.0, 0.0],
         [omega0**2, -2.0 * zeta * omega0, 0.0, 0.0],
         [0.0, 0.0, 0.0, 1.0],
         [0.0, 0.0, 0.0, 0.0]]
    )
    B = np.array([[0.0], [-(omega0**2) / g], [0.0], [1.0 / arm_length]])
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    return A, B, C


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation (matrix exponential of the augmented system)."""
    from scipy.linalg import expm  # heavy import, only when used

    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * h)
    return E[:n, :n], E[:n, n:]


def zoh_closed_form(omega0: float, g: float, arm_length: float, h: float):
    """Phi and Gamma of Sec. 2.2 in closed form (hyperbolic functions)."""
    ch, sh = np.cosh(omega0 * h), np.sinh(omega0 * h)
    Phi = np.array(
        [[ch, sh / omega0, 0.0, 0.0],
         [omega0 * sh, ch, 0.0, 0.0],
         [0.0, 0.0, 1.0, h],
         [0.0, 0.0, 0.0, 1.0]]
    )
    Gamma = np.array(
        [[-(ch - 1.0) / g], [-omega0 * sh / g], [h * h / (2.0 * arm_length)], [h / arm_length]]
    )
    return Phi, Gamma
