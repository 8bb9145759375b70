"""The DAC law u_DA = sat(k_u u) and the angle wrap, written once in model/sensor.py and
used by the real-time loop, the emulated rigs, RigScaling and the schedules."""

import math

import numpy as np
import pytest

from frictionlab.model.rig import RigScaling
from frictionlab.model.sensor import dac, u_from_dac, wrap_angle
from frictionlab.realtime.rigs import SimRig

K_U = RigScaling().u_scale  # -0.022, the thesis's rig
VALUES = [0.0, 1.0, -1.0, 20.0, -20.0, 45.0, 46.0, -46.0, 1e6, -1e6, math.inf, -math.inf,
          math.nan]


@pytest.mark.parametrize("u", VALUES)
def test_dac_saturates_and_turns_nan_into_zero(u):
    expected = 0.0 if math.isnan(u) else min(max(K_U * u, -1.0), 1.0)
    assert dac.py_func(u, K_U) == expected
    assert dac(u, K_U) == expected  # the compiled law is the same
    # the rig applies the control signal of the saturated value
    assert u_from_dac.py_func(expected, K_U) == pytest.approx(
        0.0 if math.isnan(u) else expected / K_U)
    assert u_from_dac.py_func(2.0, K_U) == 1.0 / K_U
    assert u_from_dac.py_func(math.nan, K_U) == 0.0


def test_rig_scaling_converts_arrays_with_the_same_law():
    sc = RigScaling()
    u = np.array(VALUES)
    got = sc.u_da(u)
    assert got.shape == u.shape
    assert np.array_equal(got, [dac.py_func(v, K_U) for v in VALUES])
    assert np.array_equal(sc.u_from_da(got), [u_from_dac.py_func(v, K_U) for v in got])
    assert float(sc.u_da(10.0)) == pytest.approx(-0.22)
    assert np.ndim(sc.u_da(10.0)) == 0
    assert sc.u_max == pytest.approx(1.0 / 0.022)


def test_sim_rig_applies_what_the_dac_makes_of_a_command():
    """The in-process rig saturates what it is sent and holds 0 for a NaN."""
    from frictionlab.config import build_config

    rig = SimRig(build_config())
    for sent, applied in ((0.5, 0.5), (3.0, 1.0), (-3.0, -1.0), (math.nan, 0.0)):
        rig.write(0, sent)
        assert rig.u_da == applied
        assert rig._u == applied / rig.scaling.u_scale


@pytest.mark.parametrize("a", [0.0, 1.0, math.pi, -math.pi, 3 * math.pi, -7.5, 100.0])
def test_wrap_angle_into_minus_pi_pi(a):
    w = wrap_angle.py_func(a)
    assert -math.pi <= w < math.pi
    assert math.isclose(math.remainder(w - a, 2 * math.pi), 0.0, abs_tol=1e-9)
    assert wrap_angle(a) == w
    arr = wrap_angle.py_func(np.array([a, a + 2 * math.pi]))
    assert np.allclose(arr, w)
