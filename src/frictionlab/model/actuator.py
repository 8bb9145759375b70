r"""The thesis plant's actuator: what the arm receives for a commanded u (App. B.4).

The thesis's plant takes u as an ideal arm-tip acceleration (eq. 6).  App. B.4
says the rig's motor does not deliver one: the relation between the DAC's
voltage and the arm's acceleration "is not linear", and the arm's velocity
levels off.  This module is the compiled law that turns the commanded u into
the acceleration the motor gives, applied to :math:`k_u u` before the plant's
friction and dynamics; keys ``actuator.*``, off by default (every field 0:
the ideal input, bit for bit).

Input nonlinearity (``actuator.curvature``, c)
----------------------------------------------
With :math:`u_{DA} = \hat k_u u` and :math:`\hat k_u = -0.022` (App. B.5),
the thesis measured the arm's acceleration :math:`\ddot\Omega` for four
constant :math:`u_{DA}` and solved eq. (26),
:math:`\ddot\Omega = (u_{DA} - u_{fr}\,{\rm sgn}\,\dot\Omega)/(0.21 k_u)`,
for a local :math:`k_u` (Figure 37's table):

==========  ===============================  ==============
u_DA        :math:`\ddot\Omega` (rad/s^2)     k_u
==========  ===============================  ==============
-0.05       3.1                              -0.023
-0.075      11                               -0.018
-0.1        13                               -0.024
-0.2        60                               -0.013
==========  ===============================  ==============

In SI units the commanded u is :math:`|u_{DA}|/0.022` and the acceleration
the motor gave is the arm's plus the Coulomb level it overcame,
:math:`a = L_1\ddot\Omega + u_{fr}/0.022` (:math:`u_{fr} = 0.035`, App. E).
Their ratio :math:`G = a/u` (0.99, 1.14, 0.95, 1.56 at u = 2.3, 3.4, 4.5,
9.1 m/s^2) is the effective gain; its least-squares line in :math:`|u|`,
:math:`G = g_0(1 + c|u|)`, has :math:`g_0 = 0.758` and
:math:`c = 0.110` per m/s^2 (:func:`fit_input_nonlinearity`, which
recomputes them from the table).  The law is

.. math::

    a(u) = u\,(1 + c\,|u|),

odd in u (only negative :math:`u_{DA}` were measured; App. B.4 expected the
same for positive ones); the overall scale :math:`g_0` is the plant's
:math:`k_u` (``plant.input_gain``), fitted with the rest.  Four points with
the scatter of the table (the third below the second) determine c only
roughly: the data say that the gain rises with the amplitude, about 50 %
from 2 to 9 m/s^2.

Velocity limit, back-EMF (``actuator.back_emf``, b)
---------------------------------------------------
A DC motor driven by a voltage gives the torque :math:`k_t(V - k_e\omega)/R`:
the acceleration falls with the speed, :math:`J\dot\omega = (k_t/R)V -
(k_t k_e/R)\omega - \ldots`.  In the units of u this is

.. math::

    a = a(u) - b\,L_1\dot\Omega, \qquad b = k_t k_e/(R J) = 1/\tau_m,

with :math:`\tau_m` the mechanical time constant.  From rest under a
constant u the arm's velocity rises as :math:`\dot\Omega_p(1 - e^{-bt})`
toward the plateau :math:`\dot\Omega_p = (a(u) - F_C)/(b L_1)`, with initial
acceleration :math:`b\dot\Omega_p`.  App. B.4 saw such plateaus "after about
0.2 s": at 0.7, 2.5, 3.5 and about 6 rad/s for the four :math:`u_{DA}`;
divided into the measured accelerations they give b = 4.4, 4.4, 3.7 and
10 1/s.  The first three agree (:math:`\tau_m` about 0.23 s); the last, at
twice the voltage, was probably limited by the amplifier.  The median,
4.4 1/s, is :data:`B4_BACK_EMF`.

The law is evaluated at every integration substep with the substep's arm
velocity (:mod:`frictionlab.model.plants.thesis`), and only for the thesis
plant: a motor plant (``--plant furuta-dc``) models its motor itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ._jit import jit_inline
from .params import Validated, param

__all__ = [
    "B4_BACK_EMF",
    "B4_CURVATURE",
    "B4_TABLE",
    "ActuatedPlant",
    "ActuatorParams",
    "actuator_accel",
    "fit_input_nonlinearity",
]

#: App. B.4, Figure 37's table: (u_DA, measured arm acceleration rad/s^2, plateau
#: velocity rad/s read from Figure 37's text).
B4_TABLE = ((-0.05, 3.1, 0.7), (-0.075, 11.0, 2.5), (-0.1, 13.0, 3.5), (-0.2, 60.0, 6.0))
#: App. B.5's control scaling and App. E's Coulomb level in DAC units.
B4_KU, B4_UFR, B4_ARM_LENGTH = 0.022, 0.035, 0.21


def fit_input_nonlinearity() -> tuple[float, float]:
    """``(g0, c)`` of the least-squares line ``G = g0 (1 + c |u|)`` through App. B.4's
    four effective gains (module docstring)."""
    u = np.array([abs(r[0]) / B4_KU for r in B4_TABLE])
    a = np.array([B4_ARM_LENGTH * r[1] + B4_UFR / B4_KU for r in B4_TABLE])
    (g0, g1), *_ = np.linalg.lstsq(np.column_stack([np.ones_like(u), u]), a / u, rcond=None)
    return float(g0), float(g1 / g0)


#: c of App. B.4's four points (:func:`fit_input_nonlinearity`), per m/s^2.
B4_CURVATURE = 0.110
#: b of App. B.4's plateaus (median of acceleration / plateau velocity), 1/s.
B4_BACK_EMF = 4.4


@dataclass(frozen=True)
class ActuatorParams(Validated):
    """The thesis plant's actuator (App. B.4; keys ``actuator.*``); all 0: the ideal
    acceleration input of eq. (6)."""

    _prefix = "actuator."

    curvature: float = param(0.0, "input nonlinearity: the gain grows as 1 + c|u| "
                             f"(App. B.4's four points: {B4_CURVATURE})", "1/(m/s^2)",
                             lo=0.0, hi=10.0)
    back_emf: float = param(0.0, "velocity limit: the motor's acceleration falls by "
                            f"b L_1 times the arm velocity (App. B.4's plateaus: {B4_BACK_EMF})",
                            "1/s", lo=0.0, hi=100.0)

    @property
    def enabled(self) -> bool:
        return self.curvature != 0.0 or self.back_emf != 0.0

    def record(self) -> np.ndarray:
        """The float row ``[curvature, back_emf]`` the thesis plant's row carries."""
        return np.array([self.curvature, self.back_emf], dtype=float)


@jit_inline
def actuator_accel(curvature, back_emf, u, arm_dot, arm_length):
    """The acceleration the motor gives for the command ``u`` at arm velocity
    ``arm_dot``: :math:`u(1 + c|u|) - b L_1\\dot\\Omega` (module docstring);
    ``u`` itself, bit for bit, when both terms are off."""
    a = u
    if curvature != 0.0:
        a = u * (1.0 + curvature * abs(u))
    if back_emf != 0.0:
        a = a - back_emf * arm_length * arm_dot
    return a


@dataclass(frozen=True)
class ActuatedPlant:
    """The thesis plant's parameters with its actuator: what a closed loop's
    ``plant_params`` is when ``actuator.*`` is on.  ``record()`` is the plant's
    float row carrying the actuator's; every other attribute is the plant's."""

    plant: Any
    actuator: ActuatorParams

    def record(self) -> np.ndarray:
        return self.plant.record(self.actuator.record())

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name == "plant":  # copies and pickles: not delegated
            raise AttributeError(name)
        return getattr(self.plant, name)
