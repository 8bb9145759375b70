"""The thesis plant's actuator (App. B.4): input nonlinearity and back-EMF."""

import math

import numpy as np
import pytest

from frictionlab.config import ConfigError, build_config
from frictionlab.model.actuator import (
    B4_BACK_EMF,
    B4_CURVATURE,
    B4_TABLE,
    ActuatorParams,
    actuator_accel,
    fit_input_nonlinearity,
)
from frictionlab.model.friction import KINDS
from frictionlab.model.friction import plant_record as friction_record
from frictionlab.model.params import ParamError
from frictionlab.model.plants import thesis
from frictionlab.runs import loop_spec, simulated_plant


def test_curvature_is_the_fit_of_the_four_points():
    g0, c = fit_input_nonlinearity()
    assert round(c, 3) == B4_CURVATURE
    assert 0.7 < g0 < 0.8
    # the fitted line passes among the four effective gains (none off by > 25 %)
    for u_da, acc, _ in B4_TABLE:
        u = abs(u_da) / 0.022
        gain = (0.21 * acc + 0.035 / 0.022) / u
        assert abs(gain / (g0 * (1 + c * u)) - 1) < 0.25


def test_back_emf_is_the_median_of_the_plateaus():
    rates = sorted(acc / plateau for _, acc, plateau in B4_TABLE)
    assert B4_BACK_EMF == pytest.approx(0.5 * (rates[1] + rates[2]), abs=0.05)


@pytest.mark.parametrize("u", [-7.0, -0.3, 0.0, 2.5, 9.0])
def test_the_law(u):
    assert actuator_accel(0.0, 0.0, u, 3.0, 0.21) == u  # off: u itself
    a = actuator_accel(0.11, 0.0, u, 3.0, 0.21)
    assert a == pytest.approx(u * (1 + 0.11 * abs(u)))
    assert actuator_accel(0.11, 0.0, -u, 3.0, 0.21) == -a  # odd
    assert actuator_accel(0.0, 4.4, u, 2.0, 0.21) == pytest.approx(u - 4.4 * 0.21 * 2.0)


def test_back_emf_levels_the_arm_velocity_off():
    """Free arm, constant u: the velocity rises as u/(b L1) (1 - exp(-b t))."""
    b, u = 4.0, 2.0
    cfg = build_config("fast", "none", sets=(f"actuator.back_emf={b}",))
    plant = simulated_plant(cfg)
    st = plant.init(0.0)
    h = cfg.design.h
    for k in range(1, 201):
        st = plant.step(st, u)
        expected = u / (b * 0.21) * (1 - math.exp(-b * k * h))
        assert st.x[3] == pytest.approx(expected, rel=2e-3)  # first order in the substep


def test_curvature_scales_the_arm_acceleration():
    cfg = build_config("fast", "none", sets=("actuator.curvature=0.2",))
    plant = simulated_plant(cfg)
    st = plant.step(plant.init(0.0), 3.0)
    assert st.x[3] == pytest.approx(3.0 * 1.6 * cfg.design.h / 0.21, rel=1e-9)


def test_off_by_default_and_bit_for_bit():
    cfg = build_config("fast", "classical")
    assert not cfg.actuator.enabled
    on = build_config("fast", "classical", sets=("actuator.curvature=0", "actuator.back_emf=0"))
    a, b = simulated_plant(cfg), simulated_plant(on)
    sa, sb = a.init(0.05), b.init(0.05)
    for k in range(200):
        u = 5.0 * np.sin(0.05 * k)
        sa, sb = a.step(sa, u), b.step(sb, u)
        assert np.array_equal(sa.x, sb.x)


@pytest.mark.parametrize("kind", ["classical", "lugre"])
def test_the_loops_step_is_the_general_step_with_and_without_back_emf(kind):
    """The closed loop's plant step (inlined without the back-EMF, the general
    step called with it) gives the general step's numbers bit for bit."""
    for sets in (("actuator.curvature=0.11",),
                 ("actuator.curvature=0.11", "actuator.back_emf=4.4")):
        cfg = build_config("fast", kind, sets=sets)
        spec = loop_spec(cfg)
        pp, fkind = spec.plant_params.record(), KINDS.index(kind)
        fp = friction_record(kind, spec.friction)
        plant = simulated_plant(cfg)  # the closed loop's dispatch (plants.plant_step)
        st = plant.init(0.05)
        x, mem = st.x.copy(), 0.0
        for k in range(100):
            u = 5.0 * np.sin(0.05 * k)
            st = plant.step(st, u)
            f, mem = thesis.tick(x, u, mem, spec.substeps, spec.ratio, spec.h, pp, fkind, fp)
            assert np.array_equal(st.x, x)
            assert (st.friction, st.memory) == (f, mem)
        assert abs(x[3]) > 0.1  # the arm did move


def test_bad_values_name_the_key():
    with pytest.raises(ParamError) as err:
        ActuatorParams(curvature=-0.1)
    assert err.value.field == "actuator.curvature"
    with pytest.raises(ConfigError, match=r"actuator\.back_emf"):
        build_config("fast", "classical", sets=("actuator.back_emf=-1",))


@pytest.mark.slow  # loads the batch evaluator's kernels
def test_fits_and_sweeps_run_the_same_actuated_plant():
    """The batch evaluator (sweeps, fits) and a single run (simulate, reproduce)
    give the same features with the actuator on, bit for bit."""
    from frictionlab.runs import run_features
    from frictionlab.studies.batch import evaluate_rows

    base = build_config("fast", "classical")
    point = {"actuator.curvature": 0.05, "actuator.back_emf": 1.5}
    row = evaluate_rows(base, [point], 6.0, None)[0]
    single = run_features(base.with_values(point), 6.0)
    assert row["status"] == single.status
    for name in ("peak1", "period", "max_u", "max_arm_velocity"):
        assert row[name] == getattr(single, name)
    plain = evaluate_rows(base, [{}], 6.0, None)[0]
    assert plain["max_u"] != row["max_u"]  # the actuator did act
