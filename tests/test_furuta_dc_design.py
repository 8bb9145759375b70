"""The DC-motor Furuta plant's balancing design and observer
(model/plants/furuta_dc_design.py), and a closed loop on the QUBE-Servo 2."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from frictionlab.model.design import discrete_pair
from frictionlab.model.design import preset as thesis_preset
from frictionlab.model.friction import KINDS, FrictionParams
from frictionlab.model.plants.furuta_dc import (
    HOMEBUILT,
    PRESET_FRICTION,
    QUBE2,
    QUBE3,
    SUBSTEPS,
    linearization,
    tick,
)
from frictionlab.model.plants.furuta_dc_design import (
    OBSERVER_RATIO,
    dc_design,
    dc_observer_step,
    dc_spec,
    observer_row,
)
from frictionlab.model.plants.thesis import zoh


@pytest.mark.parametrize("name", ["fast", "slow"])
@pytest.mark.parametrize("plant", [QUBE2, QUBE3, HOMEBUILT], ids=["qube2", "qube3", "home"])
def test_the_design_places_the_section_2_4_pattern(name, plant):
    # the full-model predictor (design.full_observer 1): its four poles are checked
    d = dc_design(dataclasses.replace(dc_spec(name, plant), full_observer=1), plant)
    spec, base = d.spec, thesis_preset(name)
    # the pattern: pendulum poles at the plant's unstable rate, arm poles as in the thesis
    A, B = linearization(plant)
    w0 = float(np.max(np.linalg.eigvals(A).real))
    assert spec.omega1 == pytest.approx(w0) and spec.omega0 == pytest.approx(w0)
    assert (spec.omega2, spec.zeta1, spec.zeta2) == (base.omega2, base.zeta1, base.zeta2)
    assert spec.observer_omega1 == pytest.approx(OBSERVER_RATIO * w0)
    Phi, Gamma = zoh(A, B, spec.h)
    eig = np.linalg.eigvals(Phi - Gamma @ d.L.reshape(1, 4))
    want = np.concatenate([discrete_pair(spec.omega1, spec.zeta1, spec.h),
                           discrete_pair(spec.omega2, spec.zeta2, spec.h)])
    np.testing.assert_allclose(np.sort_complex(eig), np.sort_complex(want), atol=1e-9)
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    eig_o = np.linalg.eigvals(Phi - d.K @ C)
    want_o = np.concatenate([discrete_pair(spec.observer_omega1, spec.observer_zeta1, spec.h),
                             discrete_pair(spec.observer_omega2, spec.observer_zeta2, spec.h)])
    np.testing.assert_allclose(np.sort_complex(eig_o), np.sort_complex(want_o), atol=1e-9)
    assert d.max_pole_error < 1e-9
    assert d.method == "numeric"
    out = d.to_json()
    np.testing.assert_array_equal(out["linearization"]["A"], A)
    assert out["linearization"]["states"] == ["theta", "theta_dot", "arm", "arm_dot"]


@pytest.mark.slow  # python-control's import: 3 s of CPU
def test_given_gains_replace_the_placement_for_example_an_lqr():
    import control as ct  # python-control: 3 s to import, only here
    A, B = linearization(QUBE2)
    Phi, Gamma = zoh(A, B, 0.005)
    L, _, _ = ct.dlqr(Phi, Gamma, np.diag([50.0, 1.0, 5.0, 1.0]), np.array([[1.0]]))
    spec = dataclasses.replace(thesis_preset("fast"), gains=tuple(np.ravel(L)))
    d = dc_design(spec, QUBE2)
    assert d.method == "given"
    np.testing.assert_array_equal(d.L, np.ravel(L))
    assert np.all(np.abs(d.poles) < 1.0)
    np.testing.assert_allclose(np.sort_complex(d.poles),
                               np.sort_complex(np.linalg.eigvals(Phi - Gamma @ L)), atol=1e-12)
    with pytest.raises(ValueError, match="fast"):
        dc_spec("medium")


def test_the_observer_step_is_the_predictor_and_converges_on_the_linear_model():
    d = dc_design(dataclasses.replace(dc_spec("fast", QUBE2), full_observer=1), QUBE2)
    row = observer_row(d)
    rng = np.random.default_rng(7)
    # one step is Phi xhat + Gamma u + K (y - C xhat)
    xhat = rng.normal(size=4)
    y, u = rng.normal(size=3), 1.7
    want = d.Phi @ xhat + d.Gamma.ravel() * u + d.K @ (y - d.C @ xhat)
    dc_observer_step(xhat, y[0], y[1], y[2], u, row)
    np.testing.assert_allclose(xhat, want, rtol=1e-13, atol=1e-13)
    # the estimate used at tick k was formed at k-1; on the ZOH model its error
    # decays as (Phi - K C)^k, theta_dot (not measured) included
    x = np.array([0.05, -0.2, 0.1, 0.3])
    xhat = np.zeros(4)
    e0 = x - xhat
    M = d.Phi - d.K @ d.C
    for k in range(1, 301):
        u = float(np.sin(0.1 * k))
        dc_observer_step(xhat, x[0], x[2], x[3], u, row)
        x = d.Phi @ x + d.Gamma.ravel() * u
        if k in (1, 10, 300):
            np.testing.assert_allclose(x - xhat, np.linalg.matrix_power(M, k) @ e0,
                                       atol=1e-8)  # rounding through 300 steps
    assert np.abs(x - xhat).max() < 1e-3 * np.abs(e0).max()


def _balance(design, fkind, fp, duration=10.0, theta0=0.1, u_max=10.0):
    """A test-only closed loop: the tick, the observer and u = -L xhat saturated;
    y = (theta, arm, arm_dot) exact.  Returns theta and u per tick."""
    h = design.spec.h
    pp, row = QUBE2.record(), observer_row(design)
    x = np.array([theta0, 0.0, 0.0, 0.0, 0.0])
    xhat = np.zeros(4)
    mem = 0.0
    n = round(duration / h)
    theta, us = np.empty(n), np.empty(n)
    code = KINDS.index(fkind)
    for k in range(n):
        u = min(u_max, max(-u_max, -float(design.L @ xhat)))  # from the estimate formed at k-1
        dc_observer_step(xhat, x[0], x[2], x[3], u, row)
        _, mem = tick(x, u, mem, SUBSTEPS[fkind], 1, h, pp, code, fp)
        theta[k], us[k] = x[0], u
    return theta, us


def test_the_qube2_balances_in_a_friction_limit_cycle_within_10_volts():
    # the full-model predictor's loop written here (the default observer's: test_dc_observer)
    d = dc_design(dataclasses.replace(dc_spec("fast", QUBE2), full_observer=1), QUBE2)
    f = PRESET_FRICTION["qube2"]
    fp = FrictionParams(coulomb=f["friction.coulomb"], stiction=f["friction.coulomb"]).record()
    theta, u = _balance(d, "coulomb", fp)
    assert np.max(np.abs(u)) <= 10.0
    assert np.max(np.abs(theta)) < 0.2  # balanced for 10 s
    late = theta[len(theta) // 2:]
    # a sustained oscillation: it neither settles nor grows
    assert np.ptp(late) > 0.02
    first, last = late[: len(late) // 2], late[len(late) // 2:]
    assert np.ptp(last) == pytest.approx(np.ptp(first), rel=0.2)
    # without friction the same loop settles
    theta0, u0 = _balance(d, "none", FrictionParams().record())
    assert np.max(np.abs(theta0[-200:])) < 1e-6
    assert np.max(np.abs(u0)) <= 10.0
