"""The Coulomb relay with hysteresis as a *plant* is dissipative (docs/model.md,
"Coulomb friction as a plant")."""

import numpy as np

from frictionlab.config import build_config
from frictionlab.runs import simulated_plant


def _reverse(eps):
    """The arm moving at +1 rad/s, pushed hard the other way for 0.5 s: the
    friction of every sample and the velocity during it."""
    cfg = build_config("fast", "coulomb", sets=(f"friction.hysteresis={eps}",
                                                "friction.coulomb=1.5"))
    plant = simulated_plant(cfg)
    st = plant.init(0.0)
    st.x[3] = 1.0
    st = plant.step(st, 0.0)  # the relay takes the motion's sign
    f, v = [], []
    for _ in range(100):
        v0 = st.x[3]
        st = plant.step(st, -6.0)
        f.append(st.friction)
        v.append(0.5 * (v0 + st.x[3]))
    return np.array(f), np.array(v)


def test_friction_opposes_the_motion_after_a_reversal():
    f, v = _reverse(0.5)
    assert (v < 0).any() and (v > 0).any()  # the velocity did reverse
    # whole samples on one side of zero: the friction has the velocity's sign
    # (it takes energy from the arm); a relay kept at +F_C inside the
    # hysteresis band would push the reversed arm on
    one_side = (np.abs(v) > 0.05)
    assert np.all(f[one_side] * v[one_side] > 0)
    assert np.all(np.abs(f) <= 1.5 + 1e-12)


def test_hysteresis_does_not_change_a_plant():
    f0, v0 = _reverse(0.0)
    f1, v1 = _reverse(0.5)
    assert np.array_equal(f0, f1) and np.array_equal(v0, v1)
