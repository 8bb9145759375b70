"""The Coulomb relay with hysteresis as a *plant* is dissipative (docs/model.md,
"Coulomb friction as a plant")."""

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.runs import simulated_plant

#: (plant, Coulomb level, the push the other way) in the units of each plant's u
PLANTS = {"thesis": ("thesis", 1.5, -6.0), "qube2": ("qube2", 0.15, -3.0)}


def _reverse(eps, plant_name="thesis"):
    """The arm moving at +1 rad/s, pushed hard the other way for 0.5 s: the
    friction of every sample and the velocity during it."""
    name, level, push = PLANTS[plant_name]
    cfg = build_config("fast", "coulomb", plant=name,
                       sets=(f"friction.hysteresis={eps}", f"friction.coulomb={level}"))
    plant = simulated_plant(cfg)
    st = plant.init(0.0)
    st.x[3] = 1.0
    st = plant.step(st, 0.0)  # the relay takes the motion's sign
    f, v = [], []
    for _ in range(100):
        v0 = st.x[3]
        st = plant.step(st, push)
        f.append(st.friction)
        v.append(0.5 * (v0 + st.x[3]))
    return np.array(f), np.array(v)


@pytest.mark.parametrize("plant", list(PLANTS))
def test_friction_opposes_the_motion_after_a_reversal(plant):
    f, v = _reverse(0.5, plant)
    assert (v < 0).any() and (v > 0).any()  # the velocity did reverse
    # whole samples on one side of zero: the friction has the velocity's sign
    # (it takes energy from the arm); a relay kept at +F_C inside the
    # hysteresis band would push the reversed arm on
    one_side = (np.abs(v) > 0.05)
    assert np.all(f[one_side] * v[one_side] > 0)
    assert np.all(np.abs(f) <= PLANTS[plant][1] + 1e-12)


@pytest.mark.parametrize("plant", list(PLANTS))
def test_hysteresis_does_not_change_a_plant(plant):
    f0, v0 = _reverse(0.0, plant)
    f1, v1 = _reverse(0.5, plant)
    assert np.array_equal(f0, f1) and np.array_equal(v0, v1)
