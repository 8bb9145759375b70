"""The compiled batch evaluator: the features of single runs, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.model.limit_cycles import FEATURES, _pairwise_sum
from frictionlab.runs import run_features
from frictionlab.studies import batch

# (design, plant friction, compensation, sets): every plant friction model, both
# designs, measurement noise on, a compensator, drifting friction with the
# adaptive compensator, and a run that falls (at tick 363, in its second chunk);
# the 8 s runs (1,600 ticks) are recorded in chunks of batch.CHUNK_TICKS, the
# last one partial
CASES = [
    ("fast", "none", "none", {}),
    ("fast", "coulomb", "none", {"sim.noise": 0.002, "sim.seed": 3}),
    ("slow", "classical", "none", {"friction.zero_velocity_band": 0.03}),
    ("fast", "classical", "classical", {"sim.noise": 0.001}),
    ("slow", "lugre", "none", {"friction.observer_gain": 1.0, "sim.noise": 0.002}),
    ("fast", "lugre", "lugre", {}),
    ("slow", "lugre", "adaptive", {"friction.drift": -0.3}),
    ("slow", "coulomb", "none", {"sim.fall_angle": 0.1}),  # falls
]


def _single_row(cfg, duration, window):
    f = run_features(cfg, duration, window)
    row = {name: getattr(f, name) for name in FEATURES}
    return {k: (None if v is None or not np.isfinite(v) else v) for k, v in row.items()}, \
        f.status


@pytest.mark.slow
@pytest.mark.parametrize("window", [None, 4.0])
def test_batch_features_equal_single_runs_exactly(window):
    """One batch of mixed configurations gives each run's features and status
    exactly as run_features (simulate_config + trajectory_features) does."""
    base = build_config("fast", "classical")
    points, expected = [], []
    for design, fric, comp, sets in CASES:
        cfg = build_config(design, fric, comp, sets=list(sets.items()))
        points.append({})
        expected.append(_single_row(cfg, 8.0, window))
        rows = batch.evaluate_rows(cfg, points[-1:], 8.0, window)
        (row,) = rows
        feats, status = expected[-1]
        assert row["status"] == status, (design, fric, comp, sets)
        assert {k: row[k] for k in FEATURES} == feats, (design, fric, comp, sets)
        assert row["error"] is None
    assert any(s == "fell" for _, s in expected)
    assert any(s == "limit_cycle" for _, s in expected)
    # several sets of one base in one batch, in order
    pts = [{"friction.coulomb": c, "sim.noise": n} for c in (1.2, 1.6) for n in (0.0, 0.002)]
    rows = batch.evaluate_rows(base, pts, 8.0, window)
    for p, row in zip(pts, rows, strict=True):
        feats, status = _single_row(base.with_values(p), 8.0, window)
        assert {k: row[k] for k in p} == p
        assert row["status"] == status and {k: row[k] for k in FEATURES} == feats


def test_points_that_cannot_run_are_error_rows_in_place():
    base = build_config("fast", "classical")
    pts = [{"friction.coulomb": 1e9}, {"friction.coulomb": 1.3}, {"design.h": 0.5}]
    rows = batch.evaluate_rows(base, pts, 0.2, None)
    assert [r["status"] for r in rows] == [
        "error", run_features(base.with_values(pts[1]), 0.2).status, "error"]
    assert "out of range" in rows[0]["error"] or "friction.coulomb" in rows[0]["error"]
    assert "shorter than one sampling period" in rows[2]["error"]
    assert all(rows[i][f] is None for i in (0, 2) for f in FEATURES)
    assert rows[1]["error"] is None and rows[1]["friction.coulomb"] == 1.3


def test_a_non_positive_window_is_an_error_row():
    base = build_config("fast", "classical")
    (row,) = batch.evaluate_rows(base, [{}], 1.0, -1.0)
    assert row["status"] == "error" and "window must be > 0 s" in row["error"]


def test_pairwise_sum_is_numpys_sum_bit_for_bit():
    rng = np.random.default_rng(0)
    for n in (0, 1, 7, 8, 9, 127, 128, 129, 255, 1000, 4099):
        a = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n)
        assert _pairwise_sum(a) == a.sum()


def test_sets_that_change_the_shared_sections_get_their_own_rows():
    """Points that change the plant, the compensator, the sensor or the design
    between points that do not (the packing reuses the rows of unchanged
    sections) give each run's features exactly as single runs do."""
    base = build_config("fast", "classical", "lugre",
                        sets=[("friction.zero_velocity_band", 0.03)])
    pts = [{}, {"friction.coulomb": 1.2}, {"compensation.coulomb": 1.2},
           {"compensation.coulomb": 1.2}, {"plant.input_gain": 0.9}, {},
           {"sim.noise": 0.002}, {"design.h": 0.004}, {"friction.coulomb": 1.7}]
    rows = batch.evaluate_rows(base, pts, 2.0, None)
    for p, row in zip(pts, rows, strict=True):
        feats, status = _single_row(base.with_values(p), 2.0, None)
        assert row["status"] == status and {k: row[k] for k in FEATURES} == feats, p
