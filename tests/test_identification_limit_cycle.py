"""Limit-cycle identification (Sec. 5): synthetic recovery, standard errors,
identifiability warnings, input validation, evaluation through the sweep engine."""

from __future__ import annotations

import numpy as np
import pytest

import frictionlab.sweep as sweep
from frictionlab.config import ConfigError, build_config
from frictionlab.identification.limit_cycle import (
    fit_limit_cycle,
    identifiability,
    parse_experiments,
)
from frictionlab.simulation import run_features

TRUTH = {"friction.coulomb": 1.35, "friction.stiction": 2.1, "plant.omega0": 7.1}
# short runs: the slow design's limit cycle (~3.3 s) has settled after 6 s
DURATION, WINDOW = 16.0, 10.0
BOUNDS = {"friction.coulomb": (0.8, 2.2), "friction.stiction": (1.5, 3.2),
          "plant.omega0": (6.3, 7.8)}
FIT = {"duration": DURATION, "window": WINDOW, "workers": 1, "maxiter": 12, "popsize": 5,
       "bounds": BOUNDS}


def _measured(truth: dict, noise: float = 0.0, seed: int = 0) -> dict:
    """Features simulated by the project at ``truth`` (fast and slow designs),
    optionally with relative Gaussian noise on every feature."""
    rng = np.random.default_rng(seed)
    exps = []
    for design in ("fast", "slow"):
        cfg = build_config(design=design, friction="classical", sets=list(truth.items()))
        feats = run_features(cfg, DURATION, WINDOW)
        assert feats.status == "limit_cycle"
        values = {k: v * (1.0 + noise * rng.standard_normal())
                  for k, v in feats.interface_dict().items()}
        exps.append({"design": design, "features": values})
    return {"experiments": exps}


@pytest.fixture(scope="module")
def clean_fit():
    return fit_limit_cycle(parse_experiments(_measured(TRUTH)), list(TRUTH), **FIT)


@pytest.fixture(scope="module")
def noisy_fit():
    return fit_limit_cycle(parse_experiments(_measured(TRUTH, noise=0.01, seed=3)),
                           list(TRUTH), **FIT)


def _rel(est: dict, key: str) -> float:
    return abs(est[key] - TRUTH[key]) / TRUTH[key]


def test_synthetic_recovery(clean_fit):
    est = clean_fit.estimate
    assert _rel(est, "friction.coulomb") < 0.02
    assert _rel(est, "plant.omega0") < 0.02
    assert _rel(est, "friction.stiction") < 0.10


def test_residuals_cover_every_measured_feature(clean_fit):
    assert set(clean_fit.residuals) == {"fast", "slow"}
    for label, res in clean_fit.residuals.items():
        assert set(res) == set(clean_fit.measured[label])
        assert all(r is not None and abs(r) < 0.01 for r in res.values())
    assert clean_fit.cost == pytest.approx(
        sum(r * r for res in clean_fit.residuals.values() for r in res.values()))
    assert clean_fit.cost <= clean_fit.global_cost + 1e-12


def test_stderr_reported_and_no_flat_direction(clean_fit):
    assert set(clean_fit.stderr) == set(TRUTH)
    assert all(se is not None and 0 < se < 0.05 * TRUTH[k]
               for k, se in clean_fit.stderr.items())
    assert not [w for w in clean_fit.warnings if "not identifiable" in w]


def test_noisy_features_truth_within_three_stderr(noisy_fit):
    for key, value in TRUTH.items():
        se = noisy_fit.stderr[key]
        assert se is not None and se > 0
        assert abs(noisy_fit.estimate[key] - value) < 3.0 * se, (key, noisy_fit.estimate, se)


def test_json_fields(clean_fit):
    out = clean_fit.to_json()
    assert {"estimate", "stderr", "residuals", "cost"} <= set(out)
    assert out["estimate"] == clean_fit.estimate


def test_evaluates_generations_through_the_sweep_engine(monkeypatch):
    """Every evaluation goes through frictionlab.sweep.evaluate, one call per
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
