"""Limit-cycle identification (Sec. 5): synthetic recovery, standard errors,
identifiability warnings, the stiction >= Coulomb constraint, input
validation, evaluation through the sweep engine."""

from __future__ import annotations

import functools
import os

import numpy as np
import pytest

from frictionlab.config import ConfigError, build_config
from frictionlab.runs import run_features
from frictionlab.studies import sweep
from frictionlab.studies.identification.limit_cycle import (
    DEFAULT_BOUNDS,
    LimitCycleProblem,
    fit_limit_cycle,
    identifiability,
    parse_experiments,
)
from frictionlab.studies.identification.uncertainty import covariance

TRUTH = {"friction.coulomb": 1.35, "friction.stiction": 2.1, "plant.omega0": 7.1}
# the command's defaults: 30 s runs, features over the last 20 s, default
# bounds, 40 generations of 8 members per key at most; workers chosen by the fit
DURATION, WINDOW = 30.0, 20.0
FIT = {"duration": DURATION, "window": WINDOW}
#: Noise seeds of the standard-error check: the first three, not picked.
NOISE_SEEDS = (0, 1, 2)


@functools.cache
def _features(truth: tuple) -> dict:
    out = {}
    for design in ("fast", "slow"):
        cfg = build_config(design=design, friction="classical", sets=list(truth))
        feats = run_features(cfg, DURATION, WINDOW)
        assert feats.status == "limit_cycle"
        out[design] = feats.interface_dict()
    return out


def _measured(truth: dict, noise: float = 0.0, seed: int = 0) -> dict:
    """Features simulated by the project at ``truth`` (fast and slow designs),
    optionally with relative Gaussian noise on every feature."""
    rng = np.random.default_rng(seed)
    exps = []
    for design, feats in _features(tuple(truth.items())).items():
        values = {k: v * (1.0 + noise * rng.standard_normal()) for k, v in feats.items()}
        exps.append({"design": design, "features": values})
    return {"experiments": exps}


@pytest.fixture(scope="module")
def clean_fit():
    return fit_limit_cycle(parse_experiments(_measured(TRUTH)), list(TRUTH), **FIT)


@pytest.fixture(scope="module", params=NOISE_SEEDS, ids=lambda s: f"seed{s}")
def noisy_fit(request):
    return fit_limit_cycle(parse_experiments(_measured(TRUTH, noise=0.01, seed=request.param)),
                           list(TRUTH), **FIT)


def _rel(est: dict, key: str) -> float:
    return abs(est[key] - TRUTH[key]) / TRUTH[key]


@pytest.mark.xdist_group("limit-cycle-fits")
@pytest.mark.slow
def test_synthetic_recovery(clean_fit):
    """Acceptance: default bounds and budget, F_C and omega0 within 2 %, F_S within 10 %."""
    assert clean_fit.bounds == {k: DEFAULT_BOUNDS[k] for k in TRUTH}
    assert clean_fit.constraints == ["friction.stiction >= friction.coulomb"]
    assert clean_fit.generations <= 40
    est = clean_fit.estimate
    assert _rel(est, "friction.coulomb") < 0.02
    assert _rel(est, "plant.omega0") < 0.02
    assert _rel(est, "friction.stiction") < 0.10


@pytest.mark.xdist_group("limit-cycle-fits")
@pytest.mark.slow
def test_residuals_cover_every_measured_feature(clean_fit):
    assert set(clean_fit.residuals) == {"fast", "slow"}
    for label, res in clean_fit.residuals.items():
        assert set(res) == set(clean_fit.measured[label])
        assert all(r is not None and abs(r) < 0.01 for r in res.values())
    assert clean_fit.cost == pytest.approx(
        sum(r * r for res in clean_fit.residuals.values() for r in res.values()))
    assert clean_fit.cost <= clean_fit.global_cost + 1e-12


@pytest.mark.slow
@pytest.mark.xdist_group("limit-cycle-fits")
def test_stderr_reported_and_no_flat_direction(clean_fit):
    assert set(clean_fit.stderr) == set(TRUTH)
    assert all(se is not None and 0 < se < 0.05 * TRUTH[k]
               for k, se in clean_fit.stderr.items())
    assert not [w for w in clean_fit.warnings if "not identifiable" in w]
    # without noise the estimate's error is the simulator's own feature jitter,
    # which the standard errors include: the truth is within them too
    for key, value in TRUTH.items():
        assert abs(clean_fit.estimate[key] - value) < 3.0 * clean_fit.stderr[key]


@pytest.mark.xdist_group("limit-cycle-fits")
@pytest.mark.slow
def test_noisy_features_truth_within_three_stderr(noisy_fit):
    """Acceptance: with 1 % feature noise the true values lie within 3
    reported standard errors, for each of the first three noise seeds."""
    for key, value in TRUTH.items():
        se = noisy_fit.stderr[key]
        assert se is not None and se > 0
        assert abs(noisy_fit.estimate[key] - value) < 3.0 * se, (key, noisy_fit.estimate, se)
    assert noisy_fit.estimate["friction.stiction"] >= noisy_fit.estimate["friction.coulomb"]


def test_covariance_is_the_student_t_one_with_the_jitter_added():
    rng = np.random.default_rng(4)
    J = rng.standard_normal((12, 3))
    cost, jitter = 0.018, 1e-4
    cov, why = covariance(J, cost, 12, 3, jitter)
    assert why is None
    nu = 12 - 3
    expect = nu / (nu - 2) * (cost / nu + jitter) * np.linalg.inv(J.T @ J)
    assert cov == pytest.approx(expect, rel=1e-10)
    # a Student t with nu <= 2 has no finite variance: no standard errors
    for m in (3, 4, 5):
        cov, why = covariance(J[:m], cost, m, 3)
        assert cov is None and "degree" in why


@pytest.mark.slow
@pytest.mark.xdist_group("limit-cycle-fits")
def test_json_fields(clean_fit):
    out = clean_fit.to_json()
    assert {"estimate", "stderr", "residuals", "cost"} <= set(out)
    assert out["estimate"] == clean_fit.estimate


@pytest.mark.slow
def test_evaluates_generations_through_the_sweep_engine(monkeypatch):
    """Every evaluation goes through frictionlab.studies.sweep.evaluate, one call per
    generation (population x experiments points), and a parameter with no
    effect on the features is reported as not identifiable."""
    calls = []
    real = sweep.evaluate

    def spy(base, points, **kw):
        calls.append(len(points))
        return real(base, points, **kw)

    monkeypatch.setattr(sweep, "evaluate", spy)
    exps = parse_experiments(_measured({"friction.coulomb": 1.4}))
    # sigma0 belongs to the LuGre model: with classical friction it changes nothing
    res = fit_limit_cycle(exps, ["friction.coulomb", "friction.sigma0"], duration=DURATION,
                          window=WINDOW, workers=1, maxiter=2, popsize=3,
                          bounds={"friction.coulomb": (1.2, 1.6)})
    assert calls, "sweep.evaluate was not used"
    assert calls[0] == 3 * 2 * 2  # popsize * keys members, two experiments each
    assert all(n % 2 == 0 for n in calls)
    assert res.evaluations == sum(calls) // 2
    flat = [w for w in res.warnings if "friction.sigma0" in w]
    assert flat and "not identifiable" in flat[0]
    assert res.stderr["friction.sigma0"] is None


# ---------------------------------------------------------------------------
# a fake model (no simulation): features linear in F_C and F_S
# ---------------------------------------------------------------------------


def _linear_rows(base, points, **kw):
    """Rows of a model whose features are linear in the Coulomb and stiction levels."""
    rows = []
    for p in points:
        c, s = p["friction.coulomb"], p["friction.stiction"]
        rows.append({**p, "period": 1.0 + c, "peak1": 0.1 * s, "max_u": 2.0 + c + s,
                     "status": "limit_cycle", "error": None})
    return rows


#: Features of the fake model at F_C 1.0, F_S 0.5: stiction below Coulomb.
BELOW = {"experiments": [{"design": "fast",
                          "features": {"period": 2.0, "peak1": 0.05, "max_u": 3.5}}]}


@pytest.mark.slow
def test_fit_keeps_stiction_above_coulomb_unless_told_not_to():
    exps = parse_experiments(BELOW)
    keys = ["friction.coulomb", "friction.stiction"]
    kw = {"evaluate": _linear_rows, "maxiter": 30, "popsize": 8}
    free = fit_limit_cycle(exps, keys, stiction_above_coulomb=False, **kw)
    assert free.constraints == []
    assert free.estimate["friction.coulomb"] == pytest.approx(1.0, abs=1e-3)
    assert free.estimate["friction.stiction"] == pytest.approx(0.5, abs=1e-3)
    held = fit_limit_cycle(exps, keys, **kw)
    assert held.constraints == ["friction.stiction >= friction.coulomb"]
    fc, fs = held.estimate["friction.coulomb"], held.estimate["friction.stiction"]
    assert fs >= fc and fs - fc < 1e-2
    assert held.cost > free.cost
    # the warning names the argument that lifts the constraint (no command-line option)
    assert any("constraint" in w and w.hints == ("stiction_above_coulomb",)
               for w in held.warnings)
    assert not [w for w in held.warnings if "--" in w]
    assert not [w for w in held.warnings if "search bound" in w]


def test_constrained_coordinates_cover_only_stiction_above_coulomb():
    exps = parse_experiments(BELOW)
    keys = ["plant.omega0", "friction.stiction", "friction.coulomb"]
    prob = LimitCycleProblem(exps, keys, evaluate=_linear_rows, bounds={
        "friction.coulomb": (0.5, 3.0), "friction.stiction": (0.2, 2.5)})
    # bounds implied by F_C <= F_S: F_C up to 2.5, F_S from 0.5
    assert list(prob.lo) == [5.0, 0.5, 0.5] and list(prob.hi) == [9.0, 2.5, 2.5]
    assert prob.pairs == [(2, 1)]
    x = np.random.default_rng(0).uniform(0.0, 1.0, (500, 3))
    p = prob.to_params(x)
    assert np.all(p[:, 1] >= p[:, 2]) and np.all(p >= prob.lo) and np.all(p <= prob.hi)
    assert prob.to_unit(p) == pytest.approx(x, abs=1e-12)
    # the chain rule of the polish: d(params)/d(unit) matches finite differences
    for xi in x[:20]:
        D = prob.unit_jacobian(xi)
        h = 1e-7
        num = np.column_stack([(prob.to_params(xi + h * e) - prob.to_params(xi - h * e)) / (2 * h)
                               for e in np.eye(3)])
        assert D == pytest.approx(num, rel=1e-5, abs=1e-6)
    # the opt-out leaves the box as given
    free = LimitCycleProblem(exps, keys, evaluate=_linear_rows, stiction_above_coulomb=False,
                             bounds={"friction.coulomb": (0.5, 3.0),
                                     "friction.stiction": (0.2, 2.5)})
    assert free.pairs == [] and list(free.hi) == [9.0, 2.5, 3.0]


def test_bounds_that_leave_no_stiction_above_coulomb_are_refused():
    exps = parse_experiments(BELOW)
    bounds = {"friction.coulomb": (2.0, 3.0), "friction.stiction": (0.5, 1.5)}
    with pytest.raises(ConfigError, match="no stiction >= Coulomb"):
        fit_limit_cycle(exps, ["friction.coulomb", "friction.stiction"], bounds=bounds,
                        evaluate=_linear_rows)
    res = fit_limit_cycle(exps, ["friction.coulomb", "friction.stiction"], bounds=bounds,
                          evaluate=_linear_rows, stiction_above_coulomb=False, maxiter=2,
                          popsize=3)
    assert res.constraints == []


def test_line_fit_slope_and_jitter():
    exps = parse_experiments(BELOW)
    keys = ["friction.coulomb", "friction.stiction"]
    prob = LimitCycleProblem(exps, keys, evaluate=_linear_rows)
    p = np.array([1.2, 1.9])
    J, jitter = prob.line_fit(p, 0.01)
    # residuals (sim - meas)/meas of period, peak1, max_u (FEATURES order: peak1 first)
    expect = np.array([[0.0, 0.1 / 0.05], [1.0 / 2.0, 0.0], [1.0 / 3.5, 1.0 / 3.5]])
    assert J == pytest.approx(expect, rel=1e-9)
    assert jitter == pytest.approx(0.0, abs=1e-20)
    assert prob.jacobian(p, 0.01) == pytest.approx(expect, rel=1e-9)

    def stepped(base, points, **kw):  # features that move in steps, like a sampled loop
        rows = _linear_rows(base, points)
        for r in rows:
            r["period"] = round(r["period"] * 50) / 50
        return rows

    J, jitter = LimitCycleProblem(exps, keys, evaluate=stepped).line_fit(p, 0.01)
    assert J[1, 0] == pytest.approx(0.5, rel=0.2)
    assert 1e-7 < jitter < (0.02 / 2.0) ** 2  # below the step's own square


def test_fit_chooses_the_workers_once_for_the_whole_fit(monkeypatch):
    """A default fit is run on a pool of all cores though each generation
    alone is below the sweep engine's in-process threshold; a tiny fit runs
    in-process."""
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    seen = []

    def spy(base, points, **kw):
        seen.append(kw["workers"])
        return _linear_rows(base, points)

    exps = parse_experiments(BELOW)
    keys = ["friction.coulomb", "friction.stiction"]
    fit_limit_cycle(exps, keys, evaluate=spy, maxiter=40, popsize=8)
    assert set(seen) == {2}
    generation = 8 * len(keys) * len(exps)
    base = build_config()
    assert sweep.auto_workers(base, generation, 30.0) == 1
    seen.clear()
    fit_limit_cycle(exps, keys, evaluate=spy, maxiter=1, popsize=2, duration=1.0, window=0.5)
    assert set(seen) == {1}
    seen.clear()
    fit_limit_cycle(exps, keys, evaluate=spy, maxiter=2, popsize=2, workers=3)
    assert set(seen) == {3}


def test_identifiability_names_a_combination():
    rng = np.random.default_rng(1)
    a = rng.standard_normal(10)
    b = rng.standard_normal(10)
    # columns 0 and 2 act only through their sum: a flat direction
    J = np.column_stack([a, b, a])
    _, warns = identifiability(J, np.ones(3), ["k.one", "k.two", "k.three"])
    assert len(warns) == 1
    assert "k.one" in warns[0] and "k.three" in warns[0] and "k.two" not in warns[0]
    assert "combination" in warns[0]
    _, warns = identifiability(np.column_stack([a, b]), np.ones(2), ["k.one", "k.two"])
    assert warns == []


def test_identifiability_weak_parameter_is_flat_strong_one_is_not():
    rng = np.random.default_rng(2)
    a, b = rng.standard_normal(12), rng.standard_normal(12)
    weak = 0.001 * b / np.linalg.norm(b)
    sv, warns = identifiability(np.column_stack([50 * a, weak]), np.ones(2), ["w0", "fs"])
    assert len(sv) == 2
    assert len(warns) == 1 and "fs" in warns[0] and "w0" not in warns[0]
    # moderately sensitive next to a very sensitive one: both identifiable
    _, warns = identifiability(np.column_stack([50 * a, 0.5 * b]), np.ones(2), ["w0", "fs"])
    assert warns == []


@pytest.mark.parametrize("obj, match", [
    ({"experiments": []}, "non-empty"),
    ({}, "experiments"),
    ({"experiments": [{"design": "fast", "features": {"peak3": 0.1}}]}, "unknown feature"),
    ({"experiments": [{"design": "medium", "features": {"peak1": 0.1}}]}, "design"),
    ({"experiments": [{"design": "fast", "features": {"peak1": -0.1}}]}, "positive"),
    ({"experiments": [{"design": "fast", "features": {"peak1": None}}]}, "no known feature"),
    ({"experiments": [{"design": "fast", "features": {"peak1": "a"}}]}, "not a number"),
    ({"experiments": [{"design": "fast", "set": {"plant.bogus": 1},
                       "features": {"peak1": 0.1}}]}, "unknown key"),
    ({"experiments": [{"design": "fast", "feature": {"peak1": 0.1}}]}, "unknown field"),
])
def test_parse_experiments_rejects(obj, match):
    with pytest.raises(ConfigError, match=match):
        parse_experiments(obj)


def test_parse_experiments_labels_and_nulls():
    exps = parse_experiments({"experiments": [
        {"design": "fast", "features": {"peak1": 0.1, "period": None}},
        {"design": "fast", "features": {"period": 1.0}},
        {"design": "slow", "name": "mine", "features": {"max_u": 5}},
    ]})
    assert [e.label for e in exps] == ["fast", "fast#2", "mine"]
    assert exps[0].features == {"peak1": 0.1}


@pytest.mark.parametrize("keys, kw, match", [
    (["friction.coulomb"], {"bounds": {"friction.coulomb": (2.0, 1.0)}}, "below upper"),
    (["friction.coulomb"], {"bounds": {"plant.omega0": (6.0, 7.0)}}, "not fitted"),
    (["friction.coulomb"], {"bounds": {"friction.coulomb": (-1.0, 1.0)}}, "allowed range"),
    (["friction.bogus"], {}, "not a parameter"),
    (["sim.seed"], {}, "real-valued"),
    (["friction.coulomb", "friction.coulomb"], {}, "twice"),
    ([], {}, "at least one"),
])
def test_fit_rejects_infeasible_input_before_simulating(keys, kw, match):
    exps = parse_experiments({"experiments": [{"design": "fast",
                                               "features": {"period": 1.0}}]})

    def no_eval(*a, **k):
        raise AssertionError("simulated despite bad input")

    with pytest.raises(ConfigError, match=match):
        fit_limit_cycle(exps, keys, evaluate=no_eval, **kw)


def test_experiment_may_not_set_a_fitted_key():
    exps = parse_experiments({"experiments": [{"design": "fast",
                                               "set": {"friction.coulomb": 1.2},
                                               "features": {"period": 1.0}}]})
    with pytest.raises(ConfigError, match="being fitted"):
        fit_limit_cycle(exps, ["friction.coulomb"], evaluate=lambda *a, **k: [])


def test_a_broken_backend_raises_instead_of_fitting_penalties():
    exps = parse_experiments({"experiments": [{"design": "fast",
                                               "features": {"period": 1.0}}]})

    def broken(base, points, **kw):
        return [{**p, "status": "error", "error": "worker failed: boom"} for p in points]

    with pytest.raises(RuntimeError, match="boom"):
        fit_limit_cycle(exps, ["friction.coulomb"], evaluate=broken, maxiter=1, popsize=2)


# ---------------------------------------------------------------------------
# a shorter global search (search_duration / search_window)
# ---------------------------------------------------------------------------


@pytest.mark.slow
def test_short_search_runs_reach_the_optimum_of_the_full_search():
    """Two keys from two experiments: the search on 15 s runs (10 s window), polished
    on 30 s runs, lands on the optimum of the 30 s search (the truth) at the same
    cost, and every run of the polish and of the reported cost is 30 s long."""
    truth = {"friction.coulomb": 1.35, "plant.omega0": 7.1}
    exps = parse_experiments(_measured(truth))
    keys = list(truth)
    durations = []

    def spy(base, points, **kw):
        durations.append(kw["duration"])
        return sweep.evaluate(base, points, **kw)

    kw = {"duration": DURATION, "window": WINDOW, "maxiter": 8, "popsize": 5, "seed": 0}
    full = fit_limit_cycle(exps, keys, **kw)
    short = fit_limit_cycle(exps, keys, search_duration=15.0, evaluate=spy, **kw)
    assert set(durations) == {15.0, DURATION}
    assert durations[-1] == DURATION  # the final evaluation and line fit: full runs
    for k, v in truth.items():
        assert short.estimate[k] == pytest.approx(v, rel=0.01)
        assert short.estimate[k] == pytest.approx(full.estimate[k], rel=0.01)
    assert short.cost <= 1.01 * full.cost + 1e-6


def test_the_search_problem_is_the_fit_s_problem_with_other_runs():
    """with_runs: the same keys, bounds and weights, runs of another length, its
    own cache and count; the fit's problem is untouched; a bad length is refused."""
    seen = []

    def spy(base, points, **kw):
        seen.append((kw["duration"], kw["window"]))
        return _linear_rows(base, points, **kw)

    prob = LimitCycleProblem(parse_experiments(BELOW), ["friction.coulomb",
                                                        "friction.stiction"],
                             duration=30.0, window=20.0, evaluate=spy)
    short = prob.with_runs(15.0, 10.0)
    assert (short.duration, short.window) == (15.0, 10.0)
    assert (prob.duration, prob.window) == (30.0, 20.0)
    assert short.keys == prob.keys and short.pairs == prob.pairs
    assert np.array_equal(short.lo, prob.lo) and np.array_equal(short.hi, prob.hi)
    x = prob.current()
    res_short, _ = short.evaluate_batch(x)
    res_full, _ = prob.evaluate_batch(x)
    assert seen == [(15.0, 10.0), (30.0, 20.0)]  # separate caches
    assert np.array_equal(res_short, res_full)  # the fake model ignores the run length
    assert short.nfev == prob.nfev == 1
    with pytest.raises(ConfigError):
        prob.with_runs(15.0, 20.0)


def test_search_settings_default_and_validation():
    from frictionlab.studies.identification.limit_cycle import search_settings

    assert search_settings(30.0, 20.0, None, None) == (30.0, 20.0)
    assert search_settings(30.0, 20.0, 15.0, None) == (15.0, 10.0)
    assert search_settings(30.0, None, 15.0, None) == (15.0, None)
    assert search_settings(30.0, 20.0, 15.0, 12.0) == (15.0, 12.0)
    assert search_settings(30.0, 20.0, None, 5.0) == (30.0, 5.0)
    for bad, field in (((-1.0, None), "search_duration"), ((float("nan"), None),
                                                            "search_duration"),
                       ((15.0, 16.0), "search_window"), ((15.0, 0.0), "search_window")):
        with pytest.raises(ConfigError, match=field) as info:
            search_settings(30.0, 20.0, *bad)
        assert info.value.field == field and "--" not in str(info.value)


def test_the_fit_takes_the_problem_s_keywords_and_refuses_others():
    """fit_limit_cycle passes the problem's keywords to LimitCycleProblem (written
    once there): they act, and a misspelt one is refused."""
    exps = parse_experiments(BELOW)
    keys = ["friction.coulomb", "friction.stiction"]
    seen = []

    def spy(base, points, **kw):
        seen.append((kw["duration"], kw["window"], kw["workers"]))
        return _linear_rows(base, points, **kw)

    res = fit_limit_cycle(exps, keys, evaluate=spy, maxiter=1, popsize=2, duration=4.0,
                          window=2.0, workers=1, stiction_above_coulomb=False)
    assert res.constraints == [] and set(seen) == {(4.0, 2.0, 1)}
    with pytest.raises(TypeError):
        fit_limit_cycle(exps, keys, evaluate=spy, maxiter=1, popsize=2, windw=2.0)
