"""Appendix B conversions."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from frictionlab.model.rig import RigScaling, quantize, unwrap_raw, wrap_raw


def test_appendix_b_factors():
    r = RigScaling()
    assert r.theta(-0.503) == 0.0
    assert np.isclose(r.theta(0.497), np.pi)
    assert np.isclose(r.arm_velocity(0.2801 - 0.02), 28.7 * 0.2801)
    assert np.isclose(r.u_da(1.0), -0.022)
    assert r.u_da(100.0) == -1.0 and r.u_da(-100.0) == 1.0
    assert np.isclose(r.u_max, 1 / 0.022)


@pytest.mark.slow
@given(theta=st.floats(-1.5, 1.5), arm=st.floats(-20, 20), v=st.floats(-25, 25))
def test_round_trip(theta, arm, v):
    r = RigScaling(arm_bias=-0.0699)
    assert np.isclose(r.theta(r.raw_theta(theta)), theta, atol=1e-12)
    assert np.isclose(r.arm(r.raw_arm(arm)), arm, atol=1e-9)
    assert np.isclose(r.arm_velocity(r.raw_arm_velocity(v)), v, atol=1e-9)


def test_wraparound_and_unwrap():
    assert np.isclose(wrap_raw(1.02), -0.98)
    assert np.isclose(wrap_raw(-1.01), 0.99)
    assert np.isclose(unwrap_raw(0.99, -0.99), 1.01)
    assert np.isclose(unwrap_raw(-0.99, 0.99), -1.01)
    r = RigScaling()
    # one full arm lap is 2*pi/25.8 = 0.2435 raw units (App. B.2: measured 0.2433)
    assert np.isclose(r.raw_arm(2 * np.pi) - r.raw_arm(0.0), 2 * np.pi / 25.8)


def test_quantize_12_bit():
    r = RigScaling()
    qt, _qa, _qv = r.quanta()
    assert np.isclose(qt, np.pi * 2 / 4096)
    assert quantize(0.0123, qt) % qt < 1e-12 or abs(quantize(0.0123, qt) % qt - qt) < 1e-12
    assert abs(quantize(0.0123, qt) - 0.0123) <= qt / 2
    assert quantize(0.5, 0.0) == 0.5
