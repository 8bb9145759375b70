"""The motor plant's pendulum observer (model/plants/furuta_dc_design.py,
design.full_observer 0): its step, its place in the controller step, and its
robustness to +-20 % parameter errors against the full-model predictor
(studies/dc_robustness.py, benchmarks/dc_observer.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import expm

from frictionlab.config import build_config
from frictionlab.model.controller import DC_OBSERVER, DC_PENDULUM_OBSERVER
from frictionlab.model.design import discrete_pair
from frictionlab.model.plants.furuta_dc import QUBE2, linearization
from frictionlab.model.plants.furuta_dc_design import (
    dc_design,
    observer_row,
    pendulum_model,
    pendulum_observer_update,
)
from frictionlab.runs import make_controller
from frictionlab.studies.dc_robustness import draw_params, loop_matrix, spectral_radius


def test_the_pendulum_model_is_the_pendulum_row_of_the_full_linearisation():
    # J_p theta'' = c theta - D_p theta' - b arm'': the full model's theta row with its
    # arm row substituted, whatever the motor and the arm's inertia
    h = 0.005
    for p in (QUBE2, dataclasses.replace(QUBE2, resistance=5.0, torque_constant=0.03,
                                         arm_mass=0.2)):
        A, B = linearization(p)
        F, g = pendulum_model(p, h)
        # continuous: theta'' = A[1] x + B[1] u, arm'' = A[3] x + B[3] u; eliminate u
        r = B[1, 0] / B[3, 0]
        a_th = A[1] - r * A[3]
        np.testing.assert_allclose(a_th[[2, 3]], 0.0, atol=1e-9)
        Fc = np.array([[0.0, 1.0], a_th[:2]])
        np.testing.assert_allclose(F, expm(h * Fc), rtol=1e-12)
        np.testing.assert_allclose(g[1] / h, -r * -1.0, rtol=1e-2)
    q = dataclasses.replace(QUBE2, resistance=5.0, torque_constant=0.03, arm_mass=0.2)
    np.testing.assert_array_equal(pendulum_model(q, h)[0], pendulum_model(QUBE2, h)[0])


def test_the_observer_error_decays_at_its_poles_on_the_pendulum_model():
    d = dc_design("fast", QUBE2)
    assert not d.full_observer and d.K.shape == (2, 1)
    row = observer_row(d)
    M = (np.eye(2) - d.K @ np.array([[1.0, 0.0]])) @ d.F
    want = discrete_pair(d.spec.observer_omega1, d.spec.observer_zeta1, d.spec.h)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(M)), want, atol=1e-9)
    x, xhat = np.array([0.05, -0.4]), np.zeros(2)
    e0 = x - xhat
    for k in range(1, 201):
        a = 30.0 * np.sin(0.2 * k)  # the arm's mean acceleration over the tick
        x = d.F @ x + d.g * a
        xhat = np.array(pendulum_observer_update(xhat[0], xhat[1], x[0], a, row))
        if k in (1, 20, 200):
            np.testing.assert_allclose(x - xhat, np.linalg.matrix_power(M, k) @ e0,
                                       atol=1e-9)
    assert np.abs(x - xhat).max() < 1e-6


def test_the_controller_feeds_back_the_measurements_and_the_estimate():
    c = make_controller(build_config(plant="qube2", compensation="none"))
    gp, _ = c.record()
    assert gp.observer == DC_PENDULUM_OBSERVER
    s = c.init(0.02)
    s.x2, s.arm, s.arm_dot = 0.3, 0.01, 0.5
    out, s2 = c.step(s, 0.03, 0.05, 0.7)
    th, thd = pendulum_observer_update(0.02, 0.3, 0.03, (0.7 - 0.5) / gp.h, gp.obs)
    L = c.design.L
    assert out.u == pytest.approx(-(L[0] * 0.03 + L[1] * thd + L[2] * 0.05 + L[3] * 0.7))
    assert (s2.x1, s2.x2, s2.arm, s2.arm_dot) == pytest.approx((th, thd, 0.05, 0.7))
    full = make_controller(build_config(plant="qube2", sets=[("design.full_observer", 1)]))
    assert full.record()[0].observer == DC_OBSERVER


@pytest.mark.slow  # 90 loop linearisations: about 2 s
def test_stable_on_drawn_plants_where_the_full_model_predictor_is_not():
    # the nominal fast design on 30 QUBE-Servo 2 linearisations within +-20 %
    nominal = build_config(plant="qube2")
    plants = draw_params(nominal.plant, 30, seed=3)
    pend = make_controller(nominal)
    full = make_controller(build_config(plant="qube2", sets=[("design.full_observer", 1)]))
    rho = {name: np.array([spectral_radius(loop_matrix(c, p, true)) for p in plants])
           for name, c, true in (("true", pend, True), ("pend", pend, False),
                                 ("full", full, False))}
    assert np.sum(rho["full"] >= 1.0) >= 15
    # the pendulum observer costs little against the true state: where the state
    # feedback itself has a margin the loop with the observer is stable
    margin = rho["true"] < 0.98
    assert margin.sum() >= 12
    assert np.all(rho["pend"][margin] < 1.0)
    assert np.sum(rho["pend"] >= 1.0) <= 2
    assert np.max(rho["pend"] - rho["true"]) < 0.02
