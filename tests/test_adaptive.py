"""friction.drift and the adaptive compensator (--compensation adaptive).

Oracles: the drift factor in closed form; the adaptation law against an arm
that obeys exactly the law's model (L_1 v' = u - theta^T phi(v) - F_v v),
where the gradient identifier must find the true levels; the law's discrete
stability bound against the 2x2 error dynamics; and the safety rules
(bounds, freezing on a stuck arm, bad signals and saturation) with the fault
injected into the compiled step.
"""

import math

import numpy as np
import pytest

from frictionlab.config import ConfigValueError, build_config
from frictionlab.model.adaptive import (
    A_ADAPTING,
    A_BAD,
    A_PRESLIDING,
    A_SATURATED,
    A_STUCK,
    adaptation_step,
    max_gain,
    regressor,
)
from frictionlab.model.controller import (
    controller_step,
)
from frictionlab.model.friction import (
    FRICTION_FIELDS,
    FrictionParams,
    copy_friction,
    drift_factor,
    drifted_params,
    resolve_drift,
)
from frictionlab.runs import make_controller, simulate_config, simulated_plant

H = 0.005
L1 = 0.21


# --------------------------------------------------------------------------
# drift
# --------------------------------------------------------------------------


def test_drift_factor_is_linear_over_the_drift_time_then_holds():
    p = FrictionParams(drift=-0.4, drift_start=10.0, drift_time=20.0).record()
    for t, c in ((0.0, 1.0), (10.0, 1.0), (15.0, 0.9), (20.0, 0.8), (30.0, 0.6), (99.0, 0.6)):
        assert drift_factor(t, p) == pytest.approx(c, abs=1e-12), t


def test_drift_time_zero_is_a_step_and_unset_runs_to_the_end():
    p = FrictionParams(drift=0.5, drift_start=3.0, drift_time=0.0).record()
    assert drift_factor(2.999, p) == 1.0 and drift_factor(3.0, p) == 1.5
    q = resolve_drift(FrictionParams(drift=-0.4, drift_start=10.0).record(), 60.0)
    assert drift_factor(35.0, q) == pytest.approx(0.8) and drift_factor(60.0, q) == 0.6


def test_drifted_params_scale_the_levels_only():
    p = FrictionParams(drift=-0.5, drift_time=10.0, coulomb_negative=1.0).record()
    out = copy_friction(p)
    out.fs = out.drift_start = math.nan  # written by drifted_params
    drifted_params(p, 10.0, out)  # writes out in place
    for name in FRICTION_FIELDS:
        if name in ("fs", "fc", "fv", "fs_neg", "fc_neg", "fv_neg"):  # both directions' levels
            assert out[name] == pytest.approx(0.5 * p[name]), name
        else:
            assert out[name] == p[name], name


def test_the_simulated_plant_friction_follows_a_step_drift():
    """Coulomb plant, level 1.5 falling to 0.75 at 4 s: the true friction the
    simulator records is the relay level times the factor."""
    cfg = build_config("fast", "coulomb", sets=["friction.drift=-0.5", "friction.drift_start=4",
                                                  "friction.drift_time=0"])
    tr = simulate_config(cfg, 8.0)
    f, t = np.abs(tr["friction"]), tr.t
    assert np.max(f[t < 4.0 - 1e-9]) == pytest.approx(1.5)
    assert np.max(f[t >= 4.0 - 1e-9]) == pytest.approx(0.75)
    # the same plant stepped one sample at a time (the loop's sim backend)
    plant = simulated_plant(cfg, duration=8.0)
    st = plant.init()
    levels = set()
    for _ in range(round(6.0 / H)):
        st = plant.step(st, 3.0 * math.sin(st.tick * H * 6.0))
        levels.add(round(abs(st.friction), 9))
    assert max(levels) == 1.5 and 0.75 in levels


def test_drift_zero_is_bit_for_bit_the_plain_plant():
    a = simulate_config(build_config("fast", "lugre", "lugre"), 3.0)
    b = simulate_config(build_config("fast", "lugre", "lugre",
                                     sets=["friction.drift=0", "friction.drift_time=1"]), 3.0)
    np.testing.assert_array_equal(a.data, b.data)


# --------------------------------------------------------------------------
# the adaptation law
# --------------------------------------------------------------------------


def comp_params(**kw):
    base = dict(FrictionParams.defaults("adaptive", "compensation").__dict__)
    base.update(kw)
    return FrictionParams(**base).record()


def identify(p, true_fc, true_fs, ticks, fv=0.07, amp=8.0, start=(0.0, 0.0, 0.0)):
    """Drive an arm that obeys the law's model with a sliding sinusoidal u;
    ``start`` = (status, fc, fs) of the law (status 0: start it from ``p``)."""
    status, fc, fs = start
    vh, vp, slide, u_prev = 0.5, 0.5, 0.0, 0.0
    v = 0.5
    hist = []
    for k in range(ticks):
        status, fc, fs, vh, slide = adaptation_step(status, fc, fs, vh, vp, slide, u_prev, v,
                                                    p, H, L1, 1e3)
        vp = v
        u = amp * math.sin(2 * math.pi * 0.5 * k * H)
        phc, phs = regressor(v, p)
        f_true = true_fc * phc + true_fs * phs + fv * v
        v = v + H * (u - f_true) / L1
        u_prev = u
        hist.append((status, fc, fs))
    return np.array(hist)


def test_regressor_splits_the_sign_between_the_levels():
    p = comp_params()
    for v in (-3.0, -0.4, 0.2, 1.0, 5.0):
        phc, phs = regressor(v, p)
        assert phc + phs == pytest.approx(math.copysign(1.0, v))
        assert phs == pytest.approx(math.copysign(math.exp(-v * v), v))


def test_the_law_finds_the_true_levels_from_35_percent_off():
    p = comp_params(coulomb=1.0, stiction=2.3)
    hist = identify(p, 1.55, 2.3, round(20.0 / H))
    fc, fs = hist[-1, 1], hist[-1, 2]
    assert fc == pytest.approx(1.55, rel=0.02) and fs == pytest.approx(2.3, rel=0.02)
    assert set(hist[:, 0]) >= {A_ADAPTING, A_STUCK, A_PRESLIDING}


def test_zero_gain_keeps_the_start_values():
    hist = identify(comp_params(coulomb=1.0, adaptation_gain=0.0), 1.55, 2.3, 2000)
    assert np.all(hist[:, 1] == 1.0) and np.all(hist[:, 2] == 2.3)


def test_estimates_stay_in_their_bounds_and_do_not_wind_up():
    """A plant far outside the bounds pins the estimate at the bound; once the
    plant is back inside, the estimate leaves the bound within a second."""
    p = comp_params(adaptation_max=3.0, coulomb=1.5)
    hist = identify(p, 10.0, 10.0, round(10.0 / H), amp=40.0)
    assert np.all(hist[:, 1:] <= 3.0) and np.all(hist[:, 1:] >= 0.05)
    assert hist[-1, 1] == 3.0
    after = identify(p, 1.0, 1.0, round(5.0 / H), amp=40.0, start=tuple(hist[-1]))
    first_below = np.argmax(after[:, 1] < 2.9)
    assert after[first_below, 1] < 2.9 and first_below * H < 1.0
    assert after[-1, 1] == pytest.approx(1.0, rel=0.05)


def step1(v, v_prev=1.0, u_prev=0.0, slide=1.0, u_max=1e3):
    """One tick of the law from estimates (1.5, 2.3), the predictor at v_prev."""
    return adaptation_step(1.0, 1.5, 2.3, v_prev, v_prev, slide, u_prev, v, comp_params(),
                           H, L1, u_max)


@pytest.mark.parametrize("v, v_prev, why", [
    (0.05, 0.5, A_STUCK),       # stopped
    (0.5, 0.05, A_STUCK),       # starting
    (-0.5, 0.5, A_STUCK),       # reversing
    (math.nan, 0.5, A_BAD),     # a bad reading
    (0.5 + 5.0, 0.5, A_BAD),    # a glitch: prediction error far beyond the limit
])
def test_adaptation_freezes_on_a_stuck_arm_and_on_bad_signals(v, v_prev, why):
    st, fc, fs, vh, _ = step1(v, v_prev=v_prev)
    assert st == why and fc == 1.5 and fs == 2.3
    assert math.isfinite(vh)


def test_adaptation_freezes_in_presliding_and_when_saturated():
    st, fc, fs, _, slide = step1(0.52, v_prev=0.5, slide=0.0)
    assert st == A_PRESLIDING and (fc, fs) == (1.5, 2.3) and 0 < slide < 0.1
    st, fc, fs, _, _ = step1(0.52, v_prev=0.5, u_prev=50.0, u_max=45.0)
    assert st == A_SATURATED and (fc, fs) == (1.5, 2.3)
    st, fc, fs, _, _ = step1(0.52, v_prev=0.5)
    assert st == A_ADAPTING and (fc, fs) != (1.5, 2.3)


@pytest.mark.slow
@pytest.mark.parametrize("factor, grows", [(0.9, False), (1.1, True)])
def test_discrete_stability_bound(factor, grows):
    """Arm sliding at a constant 6 rad/s (|phi| = 1): the error of the law's
    linear dynamics decays below the bound gamma < (4 - 2 lambda h) L1/h^2
    and grows above it."""
    lam = 20.0
    g = factor * max_gain(lam, H, L1)
    p = comp_params(coulomb=1.5, adaptation_gain=g, adaptation_max_innovation=1e3,
                    adaptation_max=1e3,
                    adaptation_min=1e-3)
    v = 6.0
    status, fc, fs, vh, slide = adaptation_step(0.0, 0, 0, 0, 0, 0, 0, v, p, H, L1, 1e9)
    true_fc = 1.55  # the arm's friction (the law starts at 1.5); u holds the speed
    phc, phs = regressor(v, p)
    u = true_fc * phc + fs * phs + 0.07 * v
    errs = []
    for _ in range(300):
        status, fc, fs, vh, slide = adaptation_step(status, fc, fs, vh, v, slide, u, v, p, H,
                                                    L1, 1e9)
        errs.append(abs(fc - true_fc))
    assert (errs[-1] > 10 * errs[0]) == grows, errs[-5:]
    if not grows:
        assert errs[-1] < 1e-3 * 0.05


# --------------------------------------------------------------------------
# configuration: gains outside the stability conditions are refused
# --------------------------------------------------------------------------


@pytest.mark.parametrize("key, value, match", [
    ("compensation.adaptation_gain", 4e4, r"compensation.adaptation_gain = 40000 is out of "
                                          r"range; allowed \[0, 31920\)"),
    ("compensation.adaptation_bandwidth", 400, r"compensation.adaptation_bandwidth = 400 is "
                                               r"out of range; allowed \(0, 400\)"),
    ("compensation.coulomb", 7.0, r"compensation.coulomb = 7 is out of range; allowed "
                                  r"\[0.05, 6\]"),
    ("compensation.adaptation_min", 6.0, r"compensation.adaptation_max = 6 is out of range"),
    ("compensation.coulomb_negative", 1.0, r"compensation.coulomb_negative must be unset"),
])
def test_unstable_or_inconsistent_adaptation_settings_are_refused(key, value, match):
    with pytest.raises(ConfigValueError, match=match) as exc:
        build_config("fast", "lugre", "adaptive", sets=[f"{key}={value}"])
    assert exc.value.field.startswith("compensation.")


def test_the_bound_follows_the_sampling_period():
    build_config("fast", "lugre", "adaptive", sets=["compensation.adaptation_gain=3e4"])
    with pytest.raises(ConfigValueError, match=r"design\.h = 0\.01"):
        build_config("fast", "lugre", "adaptive", sets=["design.h=0.01",
                                                         "compensation.adaptation_gain=3e4"])


# --------------------------------------------------------------------------
# in the controller: faults injected into the compiled step
# --------------------------------------------------------------------------


def test_controller_step_freezes_the_estimates_on_an_injected_nan_and_recovers():
    cfg = build_config("fast", "lugre", "adaptive", sets=["compensation.coulomb=1.0"])
    ctrl = make_controller(cfg)
    gp, cp = ctrl.record()
    s = ctrl.init(0.0)
    for k in range(50):
        controller_step(s, gp, cp, 0.0, 0.0, 1.0 + 0.01 * k)
    before = s.fc_hat, s.fs_hat
    controller_step(s, gp, cp, 0.0, 0.0, math.nan)
    assert s.adapt == A_BAD and (s.fc_hat, s.fs_hat) == before
    for _ in range(5):
        controller_step(s, gp, cp, 0.0, 0.0, 1.5)
    assert np.all(np.isfinite([s.fc_hat, s.fs_hat]))
    assert 0.05 <= s.fc_hat <= 6.0


def test_controller_output_reports_the_adapted_levels():
    cfg = build_config("fast", "lugre", "adaptive", sets=["compensation.coulomb=1.2"])
    ctrl = make_controller(cfg)
    out, s = ctrl.step(ctrl.init(0.0), 0.0, 0.0, 0.0)
    assert (out.coulomb_hat, out.stiction_hat) == (1.2, 2.3)
    out, _ = make_controller(build_config("fast", "lugre", "lugre")).step(s, 0.0, 0.0, 0.0)
    assert math.isnan(out.coulomb_hat)


# --------------------------------------------------------------------------
# closed loop
# --------------------------------------------------------------------------


def test_adaptation_follows_a_drifting_plant_in_closed_loop():
    """Plain eq. (18) compensation (k = 0), plant levels falling 40 % over 40 s:
    the adapted stiction level falls with them, and the limit cycle at the end
    is smaller than the fixed compensator's."""
    sets = ["sim.noise=0.002", "friction.drift=-0.4", "compensation.coulomb=1.5",
            "compensation.observer_gain=0"]
    ad = simulate_config(build_config("fast", "lugre", "adaptive", sets=sets), 40.0)
    fx = simulate_config(build_config("fast", "lugre", "lugre", sets=sets), 40.0)
    assert ad.status == fx.status == "ok"
    assert ad["stiction_hat"][-1] < 2.0 and np.all(fx["stiction_hat"] == 2.3)
    last = ad.t >= 30.0
    assert np.ptp(ad["theta"][last]) < 0.7 * np.ptp(fx["theta"][last])


def test_python_api_runs_the_same_law_as_the_controller():
    """make_compensator("adaptive"): init/step with explicit state, the same compiled
    law; its gains are checked for its own h."""
    from frictionlab.studies.compensation import AdaptiveCompensator, make_compensator

    c = make_compensator("adaptive", coulomb=1.0, adaptation_distance=0.0)
    assert isinstance(c, AdaptiveCompensator)
    st = c.init()
    v, vs = 1.0, []
    for _ in range(400):
        f, st = c.step(st, v, u_prev=4.0)
        # an arm whose friction is 1.55 + 0.07 v at v ~ 1 (beyond the Stribeck hump)
        phc, phs = regressor(v, c._cp)
        v += H * (4.0 - (1.55 * phc + 2.3 * phs + 0.07 * v)) / L1
        vs.append(st.adaptation[2])
    assert vs[0] == 1.0 and abs(vs[-1] - 1.55) < abs(vs[0] - 1.55)
    assert math.isfinite(f) and st.z_hat != 0.0
    make_compensator("adaptive", h=0.001, adaptation_bandwidth=1000.0)
    with pytest.raises(ConfigValueError, match="adaptation_bandwidth"):
        make_compensator("adaptive", h=0.005, adaptation_bandwidth=1000.0)


def test_a_glitch_in_the_velocity_reading_does_not_move_the_estimates():
    """One reading 3 rad/s off (inside the ADC's range, so the loop runs on): the
    law freezes at the glitch and on the interval that starts at it, so the
    estimates end where the clean run's do."""
    p = comp_params(coulomb=1.2)

    def run(glitch_at):
        status, fc, fs, vh, vp, slide, u_prev = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        v = 0.5
        states = []
        for k in range(1200):
            meas = v + (3.0 if k == glitch_at else 0.0)
            status, fc, fs, vh, slide = adaptation_step(status, fc, fs, vh, vp, slide, u_prev,
                                                        meas, p, H, L1, 1e3)
            states.append(status)
            vp = meas
            u = 8.0 * math.sin(2 * math.pi * 0.5 * k * H)
            phc, phs = regressor(v, p)
            v = v + H * (u - (1.55 * phc + 2.3 * phs + 0.07 * v)) / L1
            u_prev = u
        return fc, fs, states

    k = 150  # sliding, adapting
    clean = run(None)
    assert clean[2][k] == A_ADAPTING
    fc, fs, states = run(k)
    assert states[k] == A_BAD and states[k + 1] in (A_BAD, A_PRESLIDING)
    assert fc == pytest.approx(clean[0], abs=0.02) and fs == pytest.approx(clean[1], abs=0.02)
