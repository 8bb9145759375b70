r"""State observers (Sec. 2.3): nonlinear pendulum observer and linear arm observer.

Pendulum observer: derivation and deviations from the printed text
--------------------------------------------------------------------
With damping and friction disregarded the pendulum obeys eq. (3),
:math:`\ddot\theta = \omega_0^2\sin\theta + \dot\Omega^2\sin\theta\cos\theta
- (\omega_0^2/g)u\cos\theta`.  In the scaled state :math:`x_1 = \theta`,
:math:`x_2 = \dot\theta/\omega_0` this is

.. math::

    \dot x_1 = \omega_0 x_2,\qquad
    \dot x_2 = \ddot\theta/\omega_0 = \omega_0\sin x_1
        + \frac{\dot\Omega^2}{\omega_0}\sin x_1\cos x_1 - \frac{\omega_0}{g}u\cos x_1 .

The thesis prints eq. (10) without the factor :math:`1/\omega_0` on the
centripetal term, and its observer with the signs of the centripetal and
the control terms reversed (:math:`-\hat\Omega^2\ldots + \omega_0 u/g\ldots`).
Both are inconsistent with eq. (3); this module follows the derivation:

.. math::

    \dot{\hat x}_1 &= \omega_0\hat x_2 + k_1(\theta_m - \hat x_1)\\
    \dot{\hat x}_2 &= \ddot\theta_{\rm model}(\hat x_1, \omega_0\hat x_2,
        \hat{\dot\Omega}, u)/\omega_0 + k_2(\theta_m - \hat x_1)

where :math:`\ddot\theta_{\rm model}` is :func:`frictionlab.model.plants.thesis.accelerations`
(the plant's own equation, with :math:`\zeta = 0` and no friction, as the
thesis's design model), :math:`\hat{\dot\Omega}` is the arm observer's
velocity estimate, and :math:`\omega_0` is the *design* value.  The gains
:math:`k_1, k_2` (:func:`frictionlab.model.design.observer_gains`) place the
poles of :math:`A - KC`, which neither printed sign touches, which is why the
errors are invisible in the gain formulas.  They are not alike, though.  The
centripetal term is quadratic in :math:`\dot\Omega` and vanishes in the
linearisation.  The control term :math:`(\omega_0/g)\,u\cos x_1` is a
*linear input* term: it is the input column :math:`B = (0, -\omega_0/g)^T`
of the linearisation, and the printed sign makes it :math:`+\omega_0/g`.  The
estimation error would then obey
:math:`\dot e = (A - KC)e + (0, -2\omega_0 u/g)^T`: driven by the control
signal, not decaying to zero, even for the linear model
(``tests/test_observers.py``).  The filter is implemented, as in the
thesis, with forward differences at the sampling period h.

Arm observer
------------
The discrete observer of Sec. 2.3 on the double integrator,
:math:`\hat x(k+1) = \Phi_2\hat x(k) + \Gamma_2 u(k) + K_2(\Omega_m(k) - \hat\Omega(k))`.

Both observers are *predictors*: the estimate used at tick k was formed at
tick k-1, which is what the controller of Sec. 7.3 does (read, compute and
output u, then update the filters).  Each is an ``init`` / ``step`` pair with
explicit state, shared by the simulator and the real-time loop.
"""

from __future__ import annotations

from dataclasses import dataclass

from ._jit import jit
from .plants.thesis import PlantParams, accelerations

__all__ = [
    "ArmObserver",
    "PendulumObserver",
    "arm_observer_step",
    "pendulum_observer_step",
]


@jit
def pendulum_observer_step(x1, x2, theta_m, arm_dot_hat, u, k1, k2, omega0, g, h):
    """One forward-difference step of the nonlinear pendulum observer.

    Parameters
    ----------
    x1, x2 : float
        Current estimates :math:`\\hat\\theta` and :math:`\\hat{\\dot\\theta}/\\omega_0`.
    theta_m : float
        Measured pendulum angle (rad).
    arm_dot_hat : float
        Arm velocity used in the centripetal term (rad/s).
    u : float
        Arm acceleration the model assumes over the sample (m/s^2).
    k1, k2, omega0, g, h : float
        Gains, design natural frequency, gravity, sampling period.

    Returns
    -------
    (x1_next, x2_next)
    """
    e = theta_m - x1
    # arm_length only scales the (unused) arm acceleration: pass 1.0
    th_dd, _ = accelerations(x1, omega0 * x2, arm_dot_hat, u, omega0, 0.0, g, 1.0)
    return x1 + h * (omega0 * x2 + k1 * e), x2 + h * (th_dd / omega0 + k2 * e)


@jit
def arm_observer_step(arm, arm_dot, arm_m, u, k3, k4, h, arm_length):
    """One step of the discrete arm observer (Sec. 2.3).

    Returns
    -------
    (arm_next, arm_dot_next)
    """
    e = arm_m - arm
    arm_n = arm + h * arm_dot + 0.5 * h * h / arm_length * u + k3 * e
    arm_dot_n = arm_dot + h / arm_length * u + k4 * e
    return arm_n, arm_dot_n


@dataclass(frozen=True)
class PendulumObserver:
    """Nonlinear pendulum observer with explicit state ``(x1, x2)``.

    Examples
    --------
    >>> obs = PendulumObserver(k1=28.0, k2=65.6235, omega0=6.8)
    >>> s = obs.init(0.01)
    >>> (theta_hat, theta_dot_hat), s = obs.step(s, theta_m=0.01, arm_dot_hat=0.0, u=0.0)
    """

    k1: float
    k2: float
    omega0: float
    g: float = 9.82
    h: float = 0.005

    def init(self, theta0: float = 0.0, theta_dot0: float = 0.0) -> tuple[float, float]:
        return (float(theta0), float(theta_dot0) / self.omega0)

    def estimate(self, state) -> tuple[float, float]:
        """(theta_hat, theta_dot_hat) in rad, rad/s."""
        return state[0], self.omega0 * state[1]

    def step(self, state, theta_m: float, arm_dot_hat: float, u: float):
        """Return the current estimate and the next state."""
        est = self.estimate(state)
        nxt = pendulum_observer_step(state[0], state[1], theta_m, arm_dot_hat, u, self.k1,
                                     self.k2, self.omega0, self.g, self.h)
        return est, (float(nxt[0]), float(nxt[1]))


@dataclass(frozen=True)
class ArmObserver:
    """Linear arm observer with explicit state ``(Omega_hat, Omega_dot_hat)``."""

    k3: float
    k4: float
    h: float = 0.005
    arm_length: float = PlantParams().arm_length

    def init(self, arm0: float = 0.0, arm_dot0: float = 0.0) -> tuple[float, float]:
        return (float(arm0), float(arm_dot0))

    def step(self, state, arm_m: float, u: float):
        """Return the current estimate and the next state."""
        nxt = arm_observer_step(state[0], state[1], arm_m, u, self.k3, self.k4, self.h,
                                self.arm_length)
        return (state[0], state[1]), (float(nxt[0]), float(nxt[1]))
