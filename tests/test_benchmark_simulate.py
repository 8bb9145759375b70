"""The simulator benchmark's scipy reference loop, cross-validating the compiled integrator.

``benchmarks/simulate.py`` times :func:`simulate_config` against a plain
``solve_ivp`` closed loop; these tests check that the two implement the same
loop (same controller, plant, friction, zero-order hold) on short runs.
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.runs import simulate_config

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "simulate.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_simulate", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _max_diff(ref, traj, name, seconds):
    n = round(seconds / traj.h)
    assert len(ref[name]) >= n and len(traj) >= n
    return float(np.max(np.abs(ref[name][:n] - traj[name][:n])))


@pytest.mark.slow
def test_frictionless_loop_matches_compiled(bench):
    cfg = build_config("fast", "none")
    ref = bench.scipy_closed_loop(cfg, 2.0)
    traj = simulate_config(cfg, 2.0)
    assert ref["status"] == traj.status == "ok"
    assert ref["ticks"] == len(traj) == 400
    np.testing.assert_array_equal(ref["t"], traj.t)
    # both integrate smooth dynamics accurately: agreement far below the 0.05 rad swing
    assert _max_diff(ref, traj, "theta_m", 2.0) < 1e-5
    assert _max_diff(ref, traj, "arm_dot_m", 2.0) < 1e-4
    assert _max_diff(ref, traj, "u", 2.0) < 1e-3


def test_comparison_is_sensitive_to_the_plant(bench):
    """A 5% error in the scipy loop's plant would be caught by the tolerance above."""
    cfg = build_config("fast", "none")
    ref = bench.scipy_closed_loop(cfg.with_values({"plant.input_gain": 1.05}), 2.0)
    traj = simulate_config(cfg, 2.0)
    assert _max_diff(ref, traj, "theta_m", 2.0) > 1e-4


@pytest.mark.slow
def test_classical_friction_loop_close_to_compiled(bench):
    cfg = bench.classical_config()
    assert cfg.friction.zero_velocity_band == 0.03
    ref = bench.scipy_closed_loop(cfg, 0.6)
    traj = simulate_config(cfg, 0.6)
    swing = float(np.max(np.abs(traj["theta_m"][:100])))
    assert swing > 0.05  # friction drives the angle away from its start
    # the compiled integrator holds friction over each substep, scipy evaluates it
    # continuously: close, not identical
    assert _max_diff(ref, traj, "theta_m", 0.5) < 1e-3
    assert _max_diff(ref, traj, "arm_dot_m", 0.5) < 1e-2


def test_lugre_loop_close_to_compiled(bench):
    cfg = bench.lugre_config()
    ref = bench.scipy_closed_loop(cfg, 1.0)
    traj = simulate_config(cfg, 1.0)
    assert _max_diff(ref, traj, "theta_m", 1.0) < 1e-3
    assert _max_diff(ref, traj, "arm_dot_m", 1.0) < 1e-2


@pytest.mark.slow
def test_lugre_observer_term_loop_close_to_compiled(bench):
    """eq. (19) with e = -theta: scipy evaluates the term with the continuous angle
    inside the right-hand side, the compiled loop with the predicted midpoint angle."""
    cfg = bench.lugre_config("fast", ("friction.observer_gain=2",))
    ref = bench.scipy_closed_loop(cfg, 1.0)
    traj = simulate_config(cfg, 1.0)
    assert _max_diff(ref, traj, "theta_m", 1.0) < 1e-3
    assert _max_diff(ref, traj, "arm_dot_m", 1.0) < 1e-2
    # and the term matters at this tolerance: k = 0 is far off the k = 2 reference
    plain = simulate_config(bench.lugre_config("fast"), 1.0)
    assert _max_diff(ref, plain, "arm_dot_m", 1.0) > 0.1


def test_sampled_angle_variant_is_close_but_not_the_same(bench):
    """The benchmark's sampled-angle variant of eq. (19) (the angle held over the
    sample) differs from the continuous one by far less than the swing."""
    cfg = bench.lugre_config("fast", ("friction.observer_gain=2",))
    cont = bench.scipy_closed_loop(cfg, 1.0)
    samp = bench.scipy_closed_loop(cfg, 1.0, angle="sampled")
    assert cont["ticks"] == samp["ticks"] == 200
    d = float(np.max(np.abs(cont["theta_m"] - samp["theta_m"])))
    swing = float(np.max(np.abs(cont["theta_m"])))
    assert 0.0 < d < 0.02 * swing
    with pytest.raises(ValueError, match="angle"):
        bench.scipy_closed_loop(cfg, 0.1, angle="measured")


def test_baseline_rejects_what_it_does_not_model(bench):
    with pytest.raises(ValueError, match="coulomb"):
        bench.scipy_closed_loop(build_config("fast", "coulomb"), 0.1)
    with pytest.raises(ValueError, match="noise"):
        bench.scipy_closed_loop(build_config("fast", "none", sets=["sim.noise=0.01"]), 0.1)


def test_feature_errors_relative_to_fine(bench):
    from frictionlab.model.limit_cycles import FEATURES, LimitCycleFeatures

    fine = LimitCycleFeatures("limit_cycle", *[2.0] * len(FEATURES))
    coarse = LimitCycleFeatures("limit_cycle", 2.01, *[2.0] * (len(FEATURES) - 2), None)
    err = bench._rel_errors(coarse, fine)
    assert err["peak1"] == pytest.approx(0.005)
    assert err["peak2"] == 0.0
    assert err["peak_to_peak"] == float("inf")  # a feature missing in one run only
