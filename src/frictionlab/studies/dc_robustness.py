r"""Robustness of a motor plant's balancing loop to parameter errors.

The sampled closed loop at upright, linear (no friction, no saturation, no
noise): the drawn plant's ZOH discretisation at the controller's h and the
compiled controller step (:func:`frictionlab.model.controller.controller_step`,
the same code that runs the simulator and the rig), linearised by central
differences in its estimate fields (``x1``, ``x2``, ``arm``, ``arm_dot``).  A
loop is stable when its spectral radius is below 1.  The controller is
designed for the nominal plant and does not know the drawn one; with
``true_state`` the state feedback acts on the plant's true state at the
tick instead (the reference: what no estimator can improve on).

benchmarks/dc_observer.py prints the counts over plants drawn within +-20 %
(docs/model.md, "The controller on a motor plant").
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..model.controller import Controller, controller_step, state_index, state_record
from ..model.plants.furuta_dc import FurutaDCParams, linearization
from ..model.plants.thesis import zoh

__all__ = ["VARIED", "draw_params", "loop_matrix", "spectral_radius"]

#: The parameters drawn (``plant.*`` keys of a motor plant), as in
#: benchmarks/swingup.py's QUBE Monte Carlo.
VARIED = ("arm_mass", "arm_length", "pendulum_mass", "pendulum_length", "resistance",
          "torque_constant", "emf_constant")

_EST = [state_index(f) for f in ("x1", "x2", "arm", "arm_dot")]


def draw_params(nominal: FurutaDCParams, n: int, seed: int,
                spread: float = 0.2) -> list[FurutaDCParams]:
    """``n`` plants with each of :data:`VARIED` uniform within ``+-spread`` of
    ``nominal`` (reproducible from ``seed``)."""
    rng = np.random.default_rng(seed)
    return [dataclasses.replace(nominal, **{f: getattr(nominal, f)
                                            * rng.uniform(1 - spread, 1 + spread)
                                            for f in VARIED})
            for _ in range(n)]


def loop_matrix(controller: Controller, plant: FurutaDCParams,
                true_state: bool = False) -> np.ndarray:
    """The sampled closed loop's matrix, state (plant theta, theta_dot, arm,
    arm_dot, then the controller's four estimate fields), of ``controller``
    (its linear part: no compensator, no saturation) on ``plant``.

    With ``true_state`` the matrix of ``Phi - Gamma L`` alone (4 x 4).
    """
    h = controller.design.spec.h
    Phi, Gam = zoh(*linearization(plant), h)
    Gam = np.asarray(Gam, dtype=float).ravel()
    L = np.asarray(controller.design.L, dtype=float)
    if true_state:
        return Phi - np.outer(Gam, L)
    gp, cp = controller.record()
    gp = gp.linear(saturate=False)
    n = 8

    def step(z):
        s = np.zeros(len(state_record(np.zeros(14)).dtype.names))
        s[_EST] = z[4:]
        x = z[:4]
        u, _, _ = controller_step(state_record(s), gp, cp, x[0], x[2], x[3])
        return np.concatenate([Phi @ x + Gam * u, s[_EST]])

    M = np.zeros((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1e-6
        M[:, j] = (step(e) - step(-e)) / 2e-6
    return M


def spectral_radius(M: np.ndarray) -> float:
    """Largest |eigenvalue| of ``M``."""
    return float(np.max(np.abs(np.linalg.eigvals(M))))
