"""Plant model, linearisation and ZOH discretisation."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.model.plants.thesis import (
    PlantParams,
    linearize,
    linearized_model,
    rhs,
    zoh,
    zoh_closed_form,
)


def test_linearization_equals_eq7():
    p = PlantParams(zeta=0.0)
    A, B = linearize(p)
    A7, B7, _ = linearized_model(p.omega0, p.g, p.arm_length)
    np.testing.assert_allclose(A, A7, atol=1e-6)
    np.testing.assert_allclose(B, B7, atol=1e-6)


def test_linearization_with_damping():
    p = PlantParams()
    A, _ = linearize(p)
    assert abs(A[1, 1] + 2 * p.zeta * p.omega0) < 1e-6


def test_zoh_equals_closed_form():
    p = PlantParams()
    A, B, _ = linearized_model(p.omega0, p.g, p.arm_length)
    Phi, Gamma = zoh(A, B, 0.005)
    Phi_c, Gamma_c = zoh_closed_form(p.omega0, p.g, p.arm_length, 0.005)
    np.testing.assert_allclose(Phi, Phi_c, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(Gamma, Gamma_c, rtol=1e-10, atol=1e-15)


def test_friction_enters_like_negative_control():
    p = PlantParams()
    x = np.array([0.1, 0.2, 0.0, 1.0])
    np.testing.assert_allclose(rhs(0, x, (3.0, 1.0), p), rhs(0, x, 2.0, p))


def test_input_gain_scales_u():
    p = PlantParams(input_gain=1.2)
    x = np.array([0.1, 0.2, 0.0, 1.0])
    np.testing.assert_allclose(rhs(0, x, 2.0, p), rhs(0, x, 2.4, PlantParams()))


def test_upright_and_hanging_equilibria():
    p = PlantParams()
    assert np.allclose(rhs(0, np.zeros(4), 0.0, p), 0)
    assert np.allclose(rhs(0, np.array([np.pi, 0, 0, 0]), 0.0, p), 0, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(
    th=st.floats(-1.5, 1.5), thd=st.floats(-10, 10), ad=st.floats(-10, 10),
    a=st.floats(-20, 20),
)
def test_rhs_matches_eq6(th, thd, ad, a):
    p = PlantParams()
    dx = rhs(0, np.array([th, thd, 0.3, ad]), a, p)
    w0, z, g = p.omega0, p.zeta, p.g
    expected = (-2 * z * w0 * thd + w0**2 * np.sin(th) + ad**2 * np.sin(th) * np.cos(th)
                - w0**2 / g * a * np.cos(th))
    assert np.isclose(dx[1], expected, rtol=1e-12, atol=1e-12)
    assert np.isclose(dx[3], a / p.arm_length)
    assert dx[0] == thd and dx[2] == ad


def test_energy_of_free_swing_decays_with_damping():
    """Downward free oscillation with the arm held loses energy (zeta > 0)."""
    from scipy.integrate import solve_ivp

    p = PlantParams()
    sol = solve_ivp(lambda t, x: rhs(t, x, 0.0, p), (0, 5), [np.pi - 0.2, 0, 0, 0],
                    rtol=1e-9, atol=1e-12)
    th, thd = sol.y[0], sol.y[1]
    energy = 0.5 * thd**2 + p.omega0**2 * (np.cos(th))  # per unit m L2^2
    assert energy[-1] < energy[0]
