"""The pendulum pivot's Coulomb friction (App. A.2; ``plant.pivot_friction``)."""

import math

import numpy as np
import pytest

from frictionlab.config import ConfigError, build_config
from frictionlab.model.params import ParamError
from frictionlab.model.plants import thesis
from frictionlab.runs import simulated_plant


def _free_peaks(sets, a0=0.21, seconds=5.0):
    """Peaks (rad from hanging) of the free oscillation with the arm at rest, App.
    A.1's experiment: the pendulum released at ``a0`` from hanging, u = 0."""
    cfg = build_config("fast", "none", sets=sets)
    plant = simulated_plant(cfg)
    st = plant.init(math.pi + a0)
    phi = [a0]
    for _ in range(int(seconds / cfg.design.h)):
        st = plant.step(st, 0.0)
        phi.append(st.x[0] - math.pi)
        assert st.x[3] == 0.0  # the arm stays put: the friction acts on the pendulum
    p = np.asarray(phi)
    inner = np.flatnonzero((p[1:-1] > p[:-2]) & (p[1:-1] >= p[2:])) + 1
    return np.concatenate([[a0], p[inner]])


def test_the_fit_of_app_a2s_peaks():
    zeta, fp = thesis.fit_pivot_friction()
    assert zeta == pytest.approx(0.0125, abs=5e-4)
    assert round(fp, 2) == thesis.A2_PIVOT_FRICTION
    # the decrements are nearly constant, as Coulomb friction gives: the line
    # explains them better than a viscous decay through the origin
    a = np.array(thesis.A2_PEAKS)
    d = a[:-1] - a[1:]
    line = 2 * math.pi * zeta * a[:-1] + 4 * fp / 6.8**2
    ratio = d @ a[:-1] / (a[:-1] @ a[:-1])
    assert np.sum((d - line) ** 2) < 0.1 * np.sum((d - ratio * a[:-1]) ** 2)


def test_coulomb_decay_is_linear_with_the_derived_decrement():
    fp = 0.3
    peaks = _free_peaks((f"plant.pivot_friction={fp}", "plant.zeta=0"))
    d = -np.diff(peaks)
    assert len(d) >= 4
    # 4 f_p / omega0^2 per period (within the large-amplitude correction, < 1 %)
    assert d == pytest.approx(np.full(len(d), 4 * fp / 6.8**2), rel=0.03)


def test_the_fit_recovers_a_simulated_pivot():
    peaks = _free_peaks(("plant.pivot_friction=0.3", "plant.zeta=0.0125"), seconds=6.0)
    zeta, fp = thesis.fit_pivot_friction(peaks)
    assert fp == pytest.approx(0.3, rel=0.1)
    assert zeta == pytest.approx(0.0125, rel=0.25)


def test_rhs_carries_the_same_law():
    p = thesis.PlantParams(pivot_friction=0.4)
    p0 = thesis.PlantParams()
    for thd in (-2.0, -0.001, 0.0, 0.002, 1.0):
        x = np.array([0.1, thd, 0.0, 0.5])
        diff = thesis.rhs(0, x, 1.0, p)[1] - thesis.rhs(0, x, 1.0, p0)[1]
        assert diff == pytest.approx(thesis.pivot_accel(thd, 0.4))
        assert diff * thd <= 0.0  # it opposes the motion
    assert thesis.pivot_accel(1.0, 0.4) == -0.4
    assert thesis.pivot_accel(-0.5 * thesis.PIVOT_VELOCITY, 0.4) == pytest.approx(0.2)


def test_off_by_default_and_bit_for_bit():
    a = simulated_plant(build_config("fast", "classical"))
    b = simulated_plant(build_config("fast", "classical", sets=("plant.pivot_friction=0",)))
    c = simulated_plant(build_config("fast", "classical", sets=("plant.pivot_friction=0.3",)))
    sa, sb, sc = a.init(0.05), b.init(0.05), c.init(0.05)
    for k in range(100):
        u = 5.0 * np.sin(0.05 * k)
        sa, sb, sc = a.step(sa, u), b.step(sb, u), c.step(sc, u)
        assert np.array_equal(sa.x, sb.x)
    assert sc.x[0] != sa.x[0]


def test_bad_values_name_the_key():
    with pytest.raises(ParamError) as err:
        thesis.PlantParams(pivot_friction=-0.1)
    assert err.value.field == "plant.pivot_friction"
    with pytest.raises(ConfigError, match=r"plant\.pivot_friction"):
        build_config("fast", "classical", sets=("plant.pivot_friction=-1",))


@pytest.mark.slow  # four closed-loop runs
def test_it_lengthens_the_fast_cycle_and_shortens_the_slow_one():
    """The rig's difference from the model (Table 1): its fast cycle is slower and
    its slow cycle faster than the nominal model's; the pivot friction moves both
    periods that way (docs/identification.md)."""
    from frictionlab.runs import run_features

    period = {}
    for design in ("fast", "slow"):
        for fp in (0.0, 0.6):
            cfg = build_config(design, "classical", sets=(f"plant.pivot_friction={fp}",))
            f = run_features(cfg, 30.0, 20.0)
            assert f.status == "limit_cycle"
            period[design, fp] = f.period
    assert period["fast", 0.6] > 1.01 * period["fast", 0.0]
    assert period["slow", 0.6] < 0.9 * period["slow", 0.0]
