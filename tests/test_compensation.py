"""Friction compensation (Sec. 6): acceptance of issue 6, compensator API, tuning, CLI."""

import dataclasses
import io
import json
import math
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from frictionlab.cli import main
from frictionlab.config import PLANT_FRICTION_KINDS, ConfigError, build_config
from frictionlab.model.controller import DEFAULT_ERROR_SIGNAL, ERROR_SIGNALS, Controller
from frictionlab.model.design import design as make_design
from frictionlab.model.friction import FrictionParams, stribeck_curve, stribeck_level
from frictionlab.model.limit_cycles import FEATURES
from frictionlab.runs import simulate_config
from frictionlab.studies import compensation as comp
from frictionlab.studies.compensation import (
    ClassicalCompensator,
    CoulombCompensator,
    LuGreCompensator,
    chatter,
    compare,
    make_compensator,
    reversals,
    tune,
)

DUR, WIN = 30.0, 15.0
NOISE = "sim.noise=0.002"
#: the compensator's model equal to the plant's eq. (21) values (k is the observer's own gain)
MATCHED = ["compensation.stiction=2.3", "compensation.coulomb=1.5", "compensation.viscous=0.07",
           "compensation.sigma0=100", "compensation.sigma1=5",
           "compensation.stribeck_velocity=1", "compensation.observer_gain=7"]


def lugre_cfg(*sets, design="fast", friction="lugre", compensation="lugre"):
    return build_config(design, friction, compensation, sets=[NOISE, *sets])


def controller(cfg, error_signal=DEFAULT_ERROR_SIGNAL, feed_net=True):
    return Controller(make_design(cfg.design, cfg.plant), cfg.compensation_kind,
                      cfg.compensation, error_signal=error_signal, feed_net=feed_net)


# ---------------------------------------------------------------------------
# acceptance: reduction of the limit cycle
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def matched():
    return compare(lugre_cfg(*MATCHED), DUR, WIN)


def test_matched_lugre_compensator_reduces_limit_cycle_5x(matched):
    assert matched.baseline_status == "limit_cycle"
    assert matched.status != "fell"
    assert matched.reduction >= 5.0, matched.as_dict()


def test_mismatched_sigma0_300_still_5x():
    sets = [*MATCHED, "compensation.sigma0=300"]
    res = compare(lugre_cfg(*sets), DUR, WIN)
    assert res.status != "fell"
    assert res.reduction >= 5.0, res.as_dict()


def test_classical_plant_lugre_compensator_3x():
    cfg = lugre_cfg("friction.stiction=2.3", "friction.coulomb=1.5", friction="classical")
    res = compare(cfg, DUR, WIN)
    assert res.baseline_status == "limit_cycle"
    assert res.status != "fell"
    assert res.reduction >= 3.0, res.as_dict()


def test_compensation_shrinks_control_and_arm_motion(matched):
    # the compensated loop needs less control and moves the arm less
    assert matched.features["max_u"] < matched.baseline_features["max_u"]
    assert (matched.features["max_arm_velocity"]
            < 0.5 * matched.baseline_features["max_arm_velocity"])


# ---------------------------------------------------------------------------
# the error signal e of eq. (19) and what the observers are fed
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def error_signal_runs():
    cfg = lugre_cfg(*MATCHED, "compensation.sigma0=300")
    base = compare(cfg, DUR, WIN)
    out = {}
    for err in ERROR_SIGNALS:
        out[err] = compare(cfg, DUR, WIN, controller=controller(cfg, err))
    return base, out


def test_default_error_signal_is_the_best_candidate(error_signal_runs):
    _, runs = error_signal_runs
    ok = {k: r.reduction for k, r in runs.items() if r.status != "fell"}
    assert DEFAULT_ERROR_SIGNAL in ok
    assert max(ok, key=ok.get) == DEFAULT_ERROR_SIGNAL


def test_arm_control_errors_destabilise(error_signal_runs):
    _, runs = error_signal_runs
    assert runs["arm_velocity"].status == "fell"
    assert runs["arm_angle"].status == "fell"


def test_observers_must_be_fed_the_net_acceleration():
    cfg = lugre_cfg(*MATCHED)
    net = compare(cfg, DUR, WIN, controller=controller(cfg, feed_net=True))
    raw = compare(cfg, DUR, WIN, controller=controller(cfg, feed_net=False))
    assert net.status != "fell"
    assert raw.status == "fell" or raw.features["peak_to_peak"] > 5 * net.features[
        "peak_to_peak"]


# ---------------------------------------------------------------------------
# the bristle discretisation at sigma0 = 1000, h = 5 ms
# ---------------------------------------------------------------------------


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(v=st.floats(0.05, 5.0), sign=st.sampled_from([-1.0, 1.0]),
       sigma0=st.floats(50.0, 1000.0), z0=st.floats(-0.05, 0.05))
def test_observer_steady_sliding_accurate(v, sign, sigma0, z0):
    c = make_compensator("lugre", sigma0=sigma0)
    p = c.params.record()
    st_ = c.init(z0)
    vv = sign * v
    f_max = 0.0
    for _ in range(2000):  # 10 s of steady sliding
        f, st_ = c.step(st_, vv)
        f_max = max(f_max, abs(f))
    assert math.isfinite(f) and f_max < 1e3
    assert abs(f - stribeck_curve(vv, p)) < 0.05 * c.params.coulomb


def true_lugre_friction(prm, velocity, velocity_integral, h, n):
    """Mean LuGre friction (eq. 18, e = 0) over each of ``n`` samples of length ``h``
    for the velocity ``velocity(t)``: an independent reference, integrated by LSODA
    at tight tolerances with the model written out here.

    F = sigma0 z + sigma1 dz/dt + F_v v, so the sample mean is
    (sigma0 * int z + sigma1 * dz + F_v * int v) / h; int z is a second state.
    """
    fs, fc, fv = prm.stiction, prm.coulomb, prm.viscous
    vs, s0, s1 = prm.stribeck_velocity, prm.sigma0, prm.sigma1

    def a(t):
        v = velocity(t)
        return s0 * abs(v) / (fc + (fs - fc) * math.exp(-((v / vs) ** 2)))

    def rhs(t, y):
        return [velocity(t) - a(t) * y[0], y[0]]

    def jac(t, y):
        return [[-a(t), 0.0], [1.0, 0.0]]

    tk = h * np.arange(n + 1)
    sol = solve_ivp(rhs, (0.0, tk[-1]), [0.0, 0.0], method="LSODA", t_eval=tk, jac=jac,
                    rtol=1e-10, atol=1e-13)
    assert sol.success, sol.message
    z, z_int = sol.y
    return (s0 * np.diff(z_int) + s1 * np.diff(z) + fv * np.diff(velocity_integral(tk))) / h


@pytest.mark.slow
def test_observer_tracks_true_lugre_friction_at_sigma0_1000():
    """Bounded and within 5% of F_C of the true friction (mean over each sample, from
    an independent stiff ODE solution) wherever the arm slides, for a slowly varying
    velocity up to 3 rad/s."""
    h, n, period = 0.005, 4000, 10.0
    w = 2 * math.pi / period
    prm = FrictionParams(sigma0=1000.0)
    f_true = true_lugre_friction(prm, lambda t: 3.0 * math.sin(w * t),
                                 lambda t: -3.0 / w * np.cos(w * t), h, n)
    c = LuGreCompensator(prm, h)
    st_ = c.init()
    errs, fmax = [], 0.0
    for k in range(n):
        v0 = 3.0 * math.sin(w * k * h)
        f_hat, st_ = c.step(st_, v0)
        fmax = max(fmax, abs(f_hat))
        if abs(v0) > 0.3:
            errs.append(abs(f_hat - f_true[k]))
    assert fmax < 2 * prm.stiction + 3 * prm.viscous
    assert max(errs) < 0.05 * prm.coulomb


def test_closed_loop_stays_bounded_with_stiff_bristles():
    cfg = lugre_cfg("friction.sigma0=1000", "compensation.sigma0=1000")
    traj = simulate_config(cfg, 20.0)
    assert traj.status == "ok"
    assert np.all(np.isfinite(traj["friction_hat"]))
    assert np.max(np.abs(traj["friction_hat"])) < 10.0


# ---------------------------------------------------------------------------
# Coulomb hysteresis
# ---------------------------------------------------------------------------


def coulomb_run(eps):
    cfg = build_config("fast", "classical", "coulomb",
                       sets=[NOISE, f"compensation.hysteresis={eps}"])
    res, traj, _ = compare(cfg, DUR, WIN, return_trajectories=True)
    return res, chatter(traj, WIN)


def test_coulomb_without_hysteresis_chatters_and_with_eps_does_not():
    _, ch0 = coulomb_run(0.0)
    res5, ch5 = coulomb_run(0.05)
    print(f"sign reversals of F_hat: eps=0 {ch0.reversals_per_s:.1f}/s, "
          f"eps=0.05 {ch5.reversals_per_s:.1f}/s")
    period = res5.features["period"]
    assert period is not None
    # with the hysteresis the estimate reverses only at the limit cycle's turning
    # points (twice a period); without it, many times more often
    assert ch5.reversals_per_s <= 1.1 * 2.0 / period
    assert ch0.reversals_per_s > 4.0 * ch5.reversals_per_s
    assert ch0.u_roughness > 1.5 * ch5.u_roughness


def test_reversals_count_only_full_swings():
    x = np.array([0.0, 1.0, 0.1, -0.1, 0.2, -1.0, -0.2, 1.0, 1.0])
    assert reversals(x, 0.5) == 2
    assert reversals(np.full(5, 0.3), 0.5) == 0
    with pytest.raises(ValueError, match="threshold"):
        reversals(x, 0.0)


# ---------------------------------------------------------------------------
# compensator API = the controller's compiled path
# ---------------------------------------------------------------------------


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(vs=st.lists(st.floats(-0.2, 0.2), min_size=1, max_size=30),
       eps=st.floats(0.0, 0.1))
def test_coulomb_relay_hysteresis(vs, eps):
    c = make_compensator("coulomb", hysteresis=eps)
    s = c.init()
    prev = 0.0
    for v in vs:
        f, s = c.step(s, v)
        if v > eps:
            assert f == c.params.coulomb
        elif v < -eps:
            assert f == -c.params.coulomb
        else:
            assert f == prev  # inside the band the relay keeps its value
        prev = f


@settings(max_examples=60, deadline=None)
@given(v=st.floats(-5.0, 5.0), u_fb=st.floats(-10.0, 10.0))
def test_classical_implementation_form(v, u_fb):
    c = ClassicalCompensator()
    p = c.params
    f, _ = c.step(c.init(), v, u_fb=u_fb)
    if abs(v) < p.hysteresis:
        assert f == pytest.approx(min(max(u_fb, -p.stiction), p.stiction))
    else:
        assert f == pytest.approx(math.copysign(stribeck_level(v, p.record()), v))


def test_api_matches_controller_tick(fast_design):
    """The public compensators reproduce the controller's estimates tick by tick."""
    rng = np.random.default_rng(3)
    for kind in ("coulomb", "classical", "lugre"):
        prm = FrictionParams.defaults(kind, "compensation")
        ctrl = Controller(fast_design, kind, prm)
        cmp_ = make_compensator(kind, prm, h=fast_design.spec.h)
        s, cs = ctrl.init(0.02), cmp_.init()
        for _ in range(200):
            th, arm, ad = rng.normal(0, [0.02, 0.1, 0.5])
            out, s_next = ctrl.step(s, th, arm, ad)
            f, cs = cmp_.step(cs, ad, u_fb=out.u_feedback, e=ad - out.arm_dot_hat)
            assert f == out.friction_estimate
            assert cs.z_hat == s_next[5]
            s = s_next


def test_step_does_not_mutate_state():
    c = make_compensator("lugre")
    s0 = c.init(0.001)
    _, s1 = c.step(s0, 1.0)
    assert s0.z_hat == 0.001 and s1.z_hat != 0.001


# ---------------------------------------------------------------------------
# invalid parameters are rejected before anything runs
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind,field,value", [
    ("lugre", "sigma0", -300.0), ("lugre", "observer_gain", -1.0),
    ("classical", "stribeck_velocity", 0.0), ("coulomb", "hysteresis", -0.05),
    ("coulomb", "coulomb", float("nan")),
])
def test_invalid_compensator_params_rejected(kind, field, value):
    with pytest.raises(ValueError, match=field):
        make_compensator(kind, **{field: value})
    with pytest.raises(ConfigError, match=f"compensation.{field}"):
        build_config("fast", "lugre", kind, sets=[f"compensation.{field}={value}"])


def test_invalid_override_is_named_by_its_compensation_key():
    with pytest.raises(ValueError, match=r"^compensation\.sigma0 = inf is out of range"):
        make_compensator("lugre", sigma0=math.inf)
    with pytest.raises(ValueError, match=r"^compensation\.hysteresis = -0\.1 is out of range"):
        make_compensator("coulomb", hysteresis=-0.1)


@pytest.mark.parametrize("levels,keys", [
    ({"stiction": 0.0, "coulomb": 0.0}, "compensation.stiction and compensation.coulomb"),
    ({"stiction_negative": 0.0, "coulomb_negative": 0.0},
     "compensation.stiction_negative and compensation.coulomb_negative"),
])
def test_lugre_compensator_without_friction_levels_is_rejected(levels, keys):
    # g(v) = s(v)/sigma0 = 0 for every v (on one side): eq. (19) is singular
    with pytest.raises(ConfigError, match=keys) as info:
        make_compensator("lugre", **levels)
    assert "\n" not in str(info.value) and "singular" in str(info.value)
    with pytest.raises(ConfigError, match=keys):
        LuGreCompensator(dataclasses.replace(FrictionParams(), **levels))
    # one level left is a usable model; the static compensators need neither
    make_compensator("lugre", stiction=0.0)
    make_compensator("lugre", coulomb=0.0)
    make_compensator("classical", **levels)


def test_cli_rejects_singular_lugre_compensator_before_running(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("a simulation started")

    monkeypatch.setattr("frictionlab.runs.simulate_config", boom)
    monkeypatch.setattr("frictionlab.studies.sweep.evaluate", boom)
    zero = ["--set", "compensation.stiction=0", "--set", "compensation.coulomb=0"]
    rc, out, err = run_cli("compensate", "compare", "--compensation", "lugre", *zero, "--json")
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1
    assert "compensation.stiction and compensation.coulomb" in err
    # one grid point of a tuning is enough
    rc, out, err = run_cli("compensate", "tune", "--set", "compensation.coulomb=0", "--vary",
                           "compensation.stiction=2.3,0", "--json")
    assert rc == 2 and out == "" and "compensation.stiction and compensation.coulomb" in err


def test_invalid_compensator_options_rejected():
    with pytest.raises(ValueError, match="error_signal"):
        LuGreCompensator(error_signal="pendulum")
    with pytest.raises(ValueError, match="h must"):
        CoulombCompensator(h=0.0)
    with pytest.raises(ValueError, match="compensator must be"):
        make_compensator("viscous")


def run_cli(*args):
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        rc = main(list(args))
    return rc, out.getvalue(), err.getvalue()


def test_cli_rejects_bad_compensator_before_running(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("a simulation started")

    monkeypatch.setattr("frictionlab.runs.simulate_config", boom)
    monkeypatch.setattr("frictionlab.studies.sweep.evaluate", boom)
    rc, out, err = run_cli("simulate", "--compensation", "lugre", "--set",
                           "compensation.sigma0=-5", "--json")
    assert rc == 2 and out == "" and "compensation.sigma0" in err
    rc, out, err = run_cli("compensate", "tune", "--vary", "compensation.sigma0=100,-5",
                           "--json")
    assert rc == 2 and out == "" and "compensation.sigma0" in err
    rc, out, err = run_cli("compensate", "tune", "--vary", "friction.coulomb=1,2", "--json")
    assert rc == 2 and "compensation.*" in err
    rc, out, err = run_cli("compensate", "tune", "--compensation", "coulomb", "--vary",
                           "compensation.sigma0=100,300", "--json")
    assert rc == 2 and "no effect" in err
    rc, out, err = run_cli("compensate", "tune", "--compensation", "none", "--json")
    assert rc == 2 and "--compensation" in err


def test_tune_validates_before_evaluating(monkeypatch):
    called = []
    monkeypatch.setattr("frictionlab.studies.sweep.evaluate", lambda *a, **k: called.append(1))
    cfg = lugre_cfg()
    with pytest.raises(ConfigError, match="sigma1"):
        tune(cfg, [("compensation.sigma1", [5.0, -1.0])])
    with pytest.raises(ConfigError, match="chatter"):
        tune(cfg, [("compensation.sigma1", [5.0])], chatter_weight=-1.0)
    assert not called


# ---------------------------------------------------------------------------
# tuning
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_tune():
    cfg = build_config("fast", "classical", "coulomb", sets=[NOISE])
    grid = [("compensation.hysteresis", [0.0, 0.05])]
    return cfg, tune(cfg, grid, duration=20.0, workers=1)


def test_tune_picks_the_best_penalised_point(small_tune):
    _, res = small_tune
    assert res.evaluated == 2
    assert len(res.candidates) == 2
    scores = [c["score"] for c in res.candidates]
    assert scores == sorted(scores)
    for c in res.candidates:
        assert c["score"] == pytest.approx(
            c["peak_to_peak"] * (1 + 0.05 * c["chatter"]["reversals_per_s"]))
    assert res.best == res.candidates[0]["values"]
    assert res.reduction == pytest.approx(res.baseline_peak_to_peak / res.peak_to_peak)
    # the penalty matters: eps = 0 has the smaller limit cycle but chatters
    ptp = {c["values"]["compensation.hysteresis"]: c for c in res.candidates}
    assert ptp[0.0]["chatter"]["reversals_per_s"] > ptp[0.05]["chatter"]["reversals_per_s"]


def test_tune_without_penalty_prefers_smallest_limit_cycle(small_tune):
    cfg, _ = small_tune
    res = tune(cfg, [("compensation.hysteresis", [0.0, 0.05])], duration=20.0, workers=1,
               chatter_weight=0.0)
    best = min(res.candidates, key=lambda c: c["peak_to_peak"])
    assert res.best == best["values"]


@pytest.mark.slow
def test_tune_matches_an_independent_computation():
    """Every grid point and the baseline computed here with simulate_config and
    chatter (what tune re-ran in-process before the engine carried chatter):
    tune's result is the same, exactly."""
    from frictionlab.model.limit_cycles import trajectory_features

    cfg = build_config("fast", "classical", "coulomb", sets=[NOISE])
    grid = [("compensation.hysteresis", [0.0, 0.02, 0.05]), ("compensation.coulomb", [1.3, 1.7])]
    dur, win = 20.0, 8.0

    def run(c):
        traj = simulate_config(c, dur)
        feats = trajectory_features(traj, win)
        status = "fell" if traj.status == "fell" else feats.status
        return status, feats.peak_to_peak, chatter(traj, win)

    expected = []
    for eps in (0.0, 0.02, 0.05):
        for fc in (1.3, 1.7):
            values = {"compensation.hysteresis": eps, "compensation.coulomb": fc}
            status, ptp, ch = run(cfg.with_values(values))
            assert status in ("limit_cycle", "settled") and ptp is not None
            expected.append({"values": values, "status": status, "peak_to_peak": ptp,
                             "chatter": ch.as_dict(),
                             "score": ptp * (1 + 0.05 * ch.reversals_per_s)})
    expected.sort(key=lambda c: c["score"])
    b_status, b_ptp, b_ch = run(dataclasses.replace(cfg, compensation_kind="none"))

    res = tune(cfg, grid, duration=dur, window=win, workers=1)
    assert res.candidates == expected
    assert res.best == expected[0]["values"]
    assert (res.peak_to_peak, res.score) == (expected[0]["peak_to_peak"], expected[0]["score"])
    assert res.chatter.as_dict() == expected[0]["chatter"]
    assert (res.baseline_status, res.baseline_peak_to_peak) == (b_status, b_ptp)
    assert res.baseline_chatter == b_ch
    assert (res.evaluated, res.failed) == (6, 0)
    # the pool gives the same result
    assert tune(cfg, grid, duration=dur, window=win, workers=2) == res


def test_tune_ranks_the_grid_and_the_baseline_from_the_engine_rows(monkeypatch):
    """Two calls of frictionlab.studies.sweep.evaluate (the grid, then the loop without
    compensation), both with the caller's workers/dask and reduced by
    features_and_chatter; the ranking, the chatter and the baseline come from
    their rows (here doctored) and nothing is simulated outside them."""
    import frictionlab.runs
    from frictionlab.studies import sweep

    real_eval, real_sim = sweep.evaluate, frictionlab.runs.simulate_config
    calls, outside = [], []
    inside = [False]

    def spy(base, points, **kw):
        calls.append((base, [dict(p) for p in points], kw))
        inside[0] = True
        try:
            rows = real_eval(base, points, **kw)
        finally:
            inside[0] = False
        for r in rows:
            if r.get("compensation.hysteresis") == 0.0:
                r["status"] = "fell"  # the smaller limit cycle, reported as fallen: it loses
            elif "compensation.hysteresis" in r:
                r["reversals_per_s"], r["u_roughness"] = 40.0, 0.5
            else:
                r["peak_to_peak"], r["reversals_per_s"], r["u_roughness"] = 1.25, 7.0, 0.25
        return rows

    def counting_simulate(*a, **k):
        if not inside[0]:
            outside.append(a)
        return real_sim(*a, **k)

    monkeypatch.setattr(sweep, "evaluate", spy)
    monkeypatch.setattr(frictionlab.runs, "simulate_config", counting_simulate)
    cfg = build_config("fast", "classical", "coulomb", sets=[NOISE])
    progress = []
    res = tune(cfg, [("compensation.hysteresis", [0.0, 0.05])], duration=20.0, workers=1,
               progress=lambda d, n: progress.append((d, n)))
    assert not outside
    (grid_base, grid_points, grid_kw), (b_base, b_points, b_kw) = calls
    assert grid_base == cfg
    assert grid_points == [{"compensation.hysteresis": 0.0}, {"compensation.hysteresis": 0.05}]
    assert b_base == dataclasses.replace(cfg, compensation_kind="none") and b_points == [{}]
    for kw in (grid_kw, b_kw):
        assert kw["workers"] == 1 and kw["dask"] is None and kw["duration"] == 20.0
        assert kw["reduce"] is comp.features_and_chatter
    assert res.evaluated == 2 and res.failed == 1
    assert [c["values"] for c in res.candidates] == [{"compensation.hysteresis": 0.05}]
    assert res.best == {"compensation.hysteresis": 0.05}
    assert res.chatter == comp.ChatterMetrics(40.0, 0.5)
    assert res.score == pytest.approx(res.peak_to_peak * (1 + 0.05 * 40.0))
    assert res.baseline_peak_to_peak == 1.25
    assert res.baseline_chatter == comp.ChatterMetrics(7.0, 0.25)
    assert progress[-1] == (3, 3) and [d for d, _ in progress] == sorted(d for d, _ in progress)


def test_tune_returns_the_winners_and_the_baselines_runs(small_tune):
    cfg, res = small_tune
    again, traj_on, traj_off = tune(cfg, [("compensation.hysteresis", [0.0, 0.05])],
                                    duration=20.0, workers=1, return_trajectories=True)
    assert again == res
    best = cfg.with_values(res.best)
    np.testing.assert_array_equal(traj_on["u"], simulate_config(best, 20.0)["u"])
    off = dataclasses.replace(cfg, compensation_kind="none")
    np.testing.assert_array_equal(traj_off["u"], simulate_config(off, 20.0)["u"])
    assert np.all(traj_off["friction_hat"] == 0.0)
    assert chatter(traj_on).as_dict() == res.candidates[0]["chatter"]


def test_features_and_chatter_is_the_default_row_plus_chatter():
    from frictionlab.studies.sweep import reduce_features

    cfg = build_config("fast", "lugre", "lugre", sets=[NOISE])
    row = comp.features_and_chatter(cfg, 10.0, None)
    assert {k: row[k] for k in ("status", *FEATURES)} == reduce_features(cfg, 10.0, None)
    traj = simulate_config(cfg, 10.0)
    assert {k: row[k] for k in ("reversals_per_s", "u_roughness")} == chatter(traj).as_dict()


@pytest.mark.slow
def test_tune_cli_json_and_plot(tmp_path):
    png = tmp_path / "ba.png"
    rc, out, err = run_cli("compensate", "tune", "--friction", "lugre", "--compensation",
                           "lugre", "--set", NOISE, "--vary", "compensation.observer_gain=3,7",
                           "--duration", "16", "--workers", "1", "--no-progress",
                           "--plot", str(png), "--json")
    assert rc == 0, err
    lines = out.strip().splitlines()
    assert len(lines) == 1
    res = json.loads(lines[0])
    assert res["best"]["compensation.observer_gain"] in (3.0, 7.0)
    assert res["reduction"] == pytest.approx(res["baseline_peak_to_peak"]
                                             / res["peak_to_peak"])
    assert res["reduction"] > 1.0
    assert set(res["chatter"]) == {"reversals_per_s", "u_roughness"}
    assert png.stat().st_size > 10_000
    # the fields docs/compensation.md lists; candidates: every point that stayed up
    assert list(res) == ["compensation", "design", "friction", "best", "peak_to_peak", "score",
                         "status", "chatter", "baseline_status", "baseline_peak_to_peak",
                         "baseline_chatter", "reduction", "candidates", "evaluated", "failed",
                         "seconds", "plot"]
    assert len(res["candidates"]) == res["evaluated"] - res["failed"] == 2
    assert res["plot"] == str(png)


@pytest.mark.slow
@pytest.mark.parametrize("plant", PLANT_FRICTION_KINDS)
def test_simulate_cli_runs_every_compensator_against_every_plant(plant):
    statuses = {}
    for kind in comp.COMPENSATORS:
        rc, out, err = run_cli("simulate", "--friction", plant, "--compensation", kind,
                               "--duration", "6", "--json")
        assert rc == 0, err
        statuses[kind] = json.loads(out)["status"]
    assert set(statuses.values()) <= {"limit_cycle", "settled"}, statuses
    if plant in ("none", "viscous"):
        # nothing to compensate: the static compensators' relay makes a limit cycle
        # (overcompensation), the LuGre observer's estimate stays small
        assert statuses == {"coulomb": "limit_cycle", "classical": "limit_cycle",
                            "lugre": "settled", "adaptive": "settled"}


@pytest.mark.parametrize("kind", ["coulomb", "classical"])
def test_static_compensators_overcompensate_a_friction_free_plant(kind):
    res = compare(build_config("fast", "none", kind, sets=[NOISE]), DUR, WIN)
    assert res.baseline_status == "settled"
    assert res.baseline_features["peak_to_peak"] < 0.02
    assert res.status == "limit_cycle"
    assert res.features["peak_to_peak"] > 0.2
    assert res.reduction < 0.1


def test_compare_needs_a_compensator():
    with pytest.raises(ConfigError):
        compare(build_config("fast", "lugre", "none"), 2.0)
    cfg = dataclasses.replace(lugre_cfg(), compensation_kind="coulomb")
    assert compare(cfg, 4.0).baseline_status in ("limit_cycle", "settled")


@pytest.mark.slow
def test_compare_cli_reports_chatter_and_reduction(tmp_path):
    rc, out, err = run_cli("compensate", "compare", "--friction", "classical",
                           "--compensation", "coulomb", "--set", NOISE, "--set",
                           "compensation.hysteresis=0", "--duration", "12",
                           "--plot", str(tmp_path / "c.png"), "--json")
    assert rc == 0, err
    res = json.loads(out)
    assert res["reduction"] == pytest.approx(res["baseline_features"]["peak_to_peak"]
                                             / res["features"]["peak_to_peak"])
    # the hysteresis-free relay toggles far more often than the limit cycle reverses
    assert res["chatter"]["reversals_per_s"] > 3 * 2.0 / res["features"]["period"]
    assert res["baseline_chatter"]["reversals_per_s"] == 0.0
    assert (tmp_path / "c.png").exists()
    rc, out, err = run_cli("compensate", "compare", "--compensation", "lugre",
                           "--duration", "-1", "--json")
    assert rc == 2 and out == "" and "--duration" in err


def test_reduction_divides_by_at_least_one_adc_quantum():
    ch = comp.ChatterMetrics(0.0, 0.0)
    base = {"peak_to_peak": 0.3}

    def ratio(pp, status="limit_cycle"):
        return comp.Comparison(status, {"peak_to_peak": pp}, ch, "limit_cycle", base,
                               ch).reduction

    assert ratio(0.03) == pytest.approx(10.0)
    # a cycle that died out completely: limited by what the rig could measure
    assert ratio(0.0) == pytest.approx(0.3 / comp.PEAK_TO_PEAK_FLOOR)
    assert ratio(1e-18) == ratio(0.0) < 300
    assert ratio(math.nan) is None and ratio(0.03, "fell") is None


# ---------------------------------------------------------------------------
# motor plants: the innovation with the pendulum observer, the derived defaults
# ---------------------------------------------------------------------------


def _motor_innovations(friction, compensation):
    """A simulated QUBE-Servo 2 run of 1.5 s from 0.05 rad, per tick from the
    second: the innovation of the measured arm rate against the linear model's
    one-tick prediction from the last tick's state and net voltage (computed
    here from the recorded estimates and the design's Phi and Gamma), the change
    of the measured rate over the tick, the plant's mean friction and F_hat over
    the tick before, the recorded F_hat and the LuGre compensator object's
    F_hat for that innovation (NaN without the LuGre compensator); and Gamma's
    arm-rate entry."""
    from frictionlab.runs import plant_design

    cfg = build_config("fast", friction, compensation, plant="qube2",
                       sets=["sim.initial_angle=0.05"])
    tr = simulate_config(cfg, 1.5)
    d = plant_design(cfg)
    phi3, gamma3 = np.asarray(d.Phi)[3], float(np.asarray(d.Gamma)[3, 0])
    last = np.column_stack([tr[c] for c in ("theta_hat", "theta_dot_hat", "arm_hat",
                                            "arm_dot_hat")])[1:]
    u, f_hat, rate = tr["u"], tr["friction_hat"], tr["arm_dot_m"]
    e = rate[1:] - (last @ phi3 + gamma3 * (u[:-1] - f_hat[:-1]))
    f_obj = np.full(len(e), math.nan)
    if compensation == "lugre":
        lugre = make_compensator("lugre", cfg.compensation)
        for k, (z, v, ek) in enumerate(zip(tr["z_hat"][1:], rate[1:], e, strict=True)):
            f_obj[k], _ = lugre.step(comp.CompensatorState(0.0, z, 0.0), v, e=ek)
    rows = np.column_stack([e, rate[1:] - rate[:-1], tr["friction"][:-1], f_hat[:-1],
                            f_hat[1:], f_obj])
    return rows, gamma3


@pytest.mark.slow  # the file's first motor-plant loop: loads its kernels (about 2 s)
def test_motor_plant_innovation_is_the_friction_error():
    """With the pendulum observer nothing predicts the arm, so the compensators'
    innovation is the measured rate minus the linear model's one-tick prediction
    from the last state and net voltage: ~0 without friction (not the rate's change,
    the former signal), -Gamma_3 F with friction and no compensator, and
    -Gamma_3 (F - F_hat) with the LuGre compensator."""
    rows, gamma3 = _motor_innovations("none", "lugre")
    assert np.abs(rows[:, 0]).max() < 0.1 * np.abs(rows[:, 1]).max()
    # the compiled step's LuGre observer ran on this innovation (eq. 19)
    np.testing.assert_allclose(rows[:, 4], rows[:, 5], rtol=1e-9, atol=1e-12)
    rows, _ = _motor_innovations("coulomb", "none")
    sliding = np.abs(rows[:, 2]) > 0.1  # Coulomb level 0.15 V
    assert sliding.sum() > 100
    np.testing.assert_allclose(rows[sliding, 0], -gamma3 * rows[sliding, 2],
                               atol=0.05 * gamma3 * 0.15)
    rows, _ = _motor_innovations("coulomb", "lugre")
    err = -gamma3 * (rows[:, 2] - rows[:, 3])
    assert np.abs(rows[:, 3]).max() > 0.1  # the compensator is on
    np.testing.assert_allclose(rows[:, 0], err, atol=0.05 * np.abs(err).max())
    np.testing.assert_allclose(rows[:, 4], rows[:, 5], rtol=1e-9, atol=1e-12)


def test_motor_plant_lugre_gains_follow_the_correction_rate():
    """k and sigma_1 of a motor plant's LuGre compensator are derived: the
    innovation corrects MOTOR_CORRECTION of a level error per tick through the
    bristle (k sigma_0 h^2 / L) and the damping term kicks MOTOR_KICK of it in
    (sigma_1 k h / L); the thesis plant keeps Sec. 6.3's k 7, sigma_1 6."""
    from frictionlab.config import MOTOR_CORRECTION, MOTOR_KICK

    for plant in ("qube2", "qube3", "furuta-dc"):
        for kind in ("lugre", "adaptive"):
            cfg = build_config("fast", "classical", kind, plant=plant)
            p, h, L = cfg.compensation, cfg.design.h, cfg.input_length
            assert p.observer_gain * p.sigma0 * h * h / L == pytest.approx(MOTOR_CORRECTION,
                                                                           rel=1e-3)
            assert p.sigma1 * p.observer_gain * h / L == pytest.approx(MOTOR_KICK, rel=1e-3)
    p = build_config("fast", "classical", "lugre").compensation
    assert (p.observer_gain, p.sigma1) == (7.0, 6.0)


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["qube2", "qube3"])
def test_motor_plant_compensators_shrink_the_cycle(plant):
    """On the nominal motor plants (classical friction at the preset's levels, the
    default pendulum observer) every compensator shrinks the cycle: classical 2.0x,
    LuGre 6.7x, adaptive 6.8x measured (benchmarks/motor_compensators.py)."""
    least = {"classical": 1.5, "lugre": 4.0, "adaptive": 4.0}
    for kind, factor in least.items():
        res = compare(build_config("fast", "classical", kind, plant=plant), DUR, WIN)
        assert res.status != "fell" and res.baseline_status == "limit_cycle"
        assert res.reduction > factor, (kind, res.reduction)


@pytest.mark.slow
def test_motor_plant_lugre_over_compensating_does_not_enlarge_the_cycle():
    """A QUBE-Servo 2 with no Coulomb friction (F_S 0.05 V) and the LuGre
    compensator at its default 0.155 V: the innovation corrects the level, and the
    cycle still shrinks (3.4x measured; the memoryless classical compensator makes
    it 4 times larger)."""
    sets = ["friction.coulomb=0", "friction.stiction=0.05"]
    res = compare(build_config("fast", "classical", "lugre", sets=sets, plant="qube2"),
                  DUR, WIN)
    assert res.status != "fell" and res.reduction > 1.5


@pytest.mark.slow
def test_the_loop_check_sees_the_motor_innovation():
    """The loop check (the console's, before a compensator is switched on) linearises
    the tick with the last tick's u and F_hat as states, which the motor plant's
    innovation reads: it passes the LuGre and adaptive defaults, and flags a damping
    kick sigma_1 k h / L above 1 (k 20, sigma_1 0.6: 1.1), with which the simulated
    pendulum falls."""
    from frictionlab.model.loopcheck import check_loop
    from frictionlab.runs import make_controller

    for kind in ("lugre", "adaptive"):
        cfg = build_config("fast", "classical", kind, plant="qube2")
        assert check_loop(make_controller(cfg), cfg.plant).ok
    kick = ["compensation.observer_gain=20", "compensation.sigma1=0.6"]
    cfg = build_config("fast", "classical", "lugre", sets=kick, plant="qube2")
    assert check_loop(make_controller(cfg), cfg.plant).verdict == "compensator_unstable"
    assert simulate_config(cfg, 10.0).status == "fell"


def test_the_default_tuning_grid_of_a_motor_plant_spans_the_thesis_ratios():
    """compensate tune's default grid: the thesis's on the thesis plant; on a motor
    plant each level or gain scaled by the plant's default over the thesis's
    (volts), velocities and bandwidths kept."""
    thesis = build_config("fast", "classical", "lugre")
    assert comp.default_grid(thesis) == comp.DEFAULT_GRIDS["lugre"]
    for kind in ("classical", "lugre", "adaptive"):
        cfg = build_config("fast", "classical", kind, plant="qube2")
        ref = FrictionParams.defaults(kind, "compensation")
        for (key, values), (tkey, tvalues) in zip(comp.default_grid(cfg),
                                                  comp.DEFAULT_GRIDS[kind], strict=True):
            field = key.split(".", 1)[1]
            assert key == tkey
            if field in ("stribeck_velocity", "hysteresis", "adaptation_bandwidth"):
                assert values == tvalues
            else:  # the motor default sits where the thesis default sat
                ratio = getattr(cfg.compensation, field) / getattr(ref, field)
                np.testing.assert_allclose(values, np.array(tvalues) * ratio, rtol=1e-3)
        assert comp.check_grid(cfg, comp.default_grid(cfg))  # every point is valid
