"""Simple identification experiments (App. A.1-A.2, B.4, E.1, E.2) against the
simulated rig, on saved logs, and on synthetic signals."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.config import build_config
from frictionlab.io.logs import log_warnings, read_log
from frictionlab.studies.identification import experiments as ex
from frictionlab.studies.identification.experiments import IdentificationError

# a plant whose parameters all differ from the thesis defaults
TRUE = {"friction.stiction": 2.1, "friction.coulomb": 1.35, "friction.viscous": 0.05,
        "plant.omega0": 7.1, "plant.zeta": 0.06, "plant.input_gain": 1.2}
NOISE = 0.002  # rad, rad, rad/s on the measured signals


def _cfg(friction: str, noise: float = NOISE):
    return build_config(friction=friction, sets=[*TRUE.items(), ("sim.noise", noise),
                                                 ("sim.seed", 5)])


def _close(value, truth, rel):
    return abs(value - truth) <= rel * abs(truth)


@pytest.fixture(scope="module")
def stiction_log():
    return ex.simulate_stiction(_cfg("classical"))


@pytest.fixture(scope="module")
def stribeck_log():
    return ex.simulate_stribeck(_cfg("lugre"))


@pytest.fixture(scope="module")
def oscillation_log():
    return ex.simulate_free_oscillation(_cfg("classical"))


@pytest.fixture(scope="module")
def free_decay(oscillation_log):
    """The free decay of the simulated free-oscillation run (from its mark ``free``:
    before it, the arm's square wave sets the pendulum swinging)."""
    log = oscillation_log
    free = log["t"] >= log.meta["marks"]["free"]
    assert 0.5 < free.mean() < 1.0  # excitation first, then the decay
    return {"t": log["t"][free], "theta_m": log["theta_m"][free]}


@pytest.fixture(scope="module")
def scaling_log():
    return ex.simulate_control_scaling(_cfg("classical"))


def test_stiction_and_coulomb_recovered(stiction_log):
    r = ex.analyse_stiction(stiction_log, input_gain=TRUE["plant.input_gain"])
    assert r["warnings"] == []
    for d in ("", "_positive", "_negative"):
        assert _close(r["stiction" + d], TRUE["friction.stiction"], 0.05), r
        assert _close(r["coulomb" + d], TRUE["friction.coulomb"], 0.05), r
    assert r["breakaway_time_positive"] < r["breakaway_time_negative"]
    assert {s["direction"] for s in r["segments"]} == {"positive", "negative"}


def test_stiction_staircase_broken_at_its_first_level_is_an_upper_bound():
    """One level (the step is larger than the stiction): the log only bounds
    the stiction from above; the estimate is half the level, with a warning."""
    cfg = build_config(friction="classical", sets=[("friction.stiction", 0.1),
                                                   ("friction.coulomb", 0.08)])
    r = ex.analyse_stiction(ex.simulate_stiction(cfg, step=0.5))
    assert r["stiction_positive"] == pytest.approx(0.25)
    assert r["stiction_negative"] == pytest.approx(0.25)
    assert len(r["warnings"]) == 2
    assert all("first level" in w and "at most 0.5" in w for w in r["warnings"])
    # it names the argument that addresses it, never a command-line option
    assert all(w.hints == ("step",) and "--" not in w for w in r["warnings"])
    # the Coulomb runs (30-90 % of the breakaway u) still count
    assert _close(r["coulomb"], 0.08, 0.05)


def test_stiction_sees_asymmetric_friction():
    cfg = build_config(friction="classical", sets=[
        ("friction.stiction", 2.3), ("friction.coulomb", 1.6),
        ("friction.stiction_negative", 1.9), ("friction.coulomb_negative", 1.3)])
    r = ex.analyse_stiction(ex.simulate_stiction(cfg))
    assert _close(r["stiction_positive"], 2.3, 0.05)
    assert _close(r["stiction_negative"], 1.9, 0.05)
    assert _close(r["coulomb_positive"], 1.6, 0.05)
    assert _close(r["coulomb_negative"], 1.3, 0.05)


def test_stribeck_curve_recovered(stribeck_log):
    r = ex.analyse_stribeck(stribeck_log, input_gain=TRUE["plant.input_gain"])
    assert _close(r["coulomb"], TRUE["friction.coulomb"], 0.05), r
    assert _close(r["viscous"], TRUE["friction.viscous"], 0.20), r
    assert _close(r["stiction"], TRUE["friction.stiction"], 0.05), r
    assert _close(r["stribeck_velocity"], 1.0, 0.20), r
    pts = np.array(r["points"])
    assert (pts[:, 0] > 0).any() and (pts[:, 0] < 0).any()
    # friction opposes motion in both directions
    assert np.all(np.sign(pts[:, 1]) == np.sign(pts[:, 0]))


def test_stribeck_without_rise_reports_unidentifiable_stribeck_part():
    # classical friction: no Stribeck rise at speed, only a Coulomb level
    cfg = build_config(friction="classical", sets=[("friction.coulomb", 1.4)])
    r = ex.analyse_stribeck(ex.simulate_stribeck(cfg, references=(1.0, 2.0, 4.0, 8.0)))
    assert _close(r["coulomb"], 1.4, 0.02)
    assert r["stiction"] is None and r["stribeck_velocity"] is None
    assert any("not identifiable" in w for w in r["warnings"])


def test_free_oscillation_recovered(free_decay):
    r = ex.analyse_free_oscillation(free_decay)
    assert _close(r["omega0"], TRUE["plant.omega0"], 0.02), r
    assert _close(r["zeta"], TRUE["plant.zeta"], 0.20), r
    # the thesis's peak method alone is also within the acceptance bounds
    assert _close(r["omega0_peaks"], TRUE["plant.omega0"], 0.02), r
    assert _close(r["zeta_peaks"], TRUE["plant.zeta"], 0.20), r
    assert len(r["peaks"]) >= 3
    assert all(h <= 0.15 for _, h in r["peaks"])


def test_control_scaling_recovered(scaling_log):
    r = ex.analyse_control_scaling(scaling_log, coulomb=TRUE["friction.coulomb"])
    assert _close(r["input_gain"], TRUE["plant.input_gain"], 0.05), r
    assert _close(r["input_gain_free"], TRUE["plant.input_gain"], 0.05), r
    assert _close(r["coulomb_free"], TRUE["friction.coulomb"], 0.10), r
    assert r["u_scale"] == pytest.approx(-0.022 / r["input_gain"])
    assert len(r["levels"]) == len(ex.SCALING_LEVELS)


@settings(max_examples=25, deadline=None)
@given(omega0=st.floats(4.0, 9.0), zeta=st.floats(0.01, 0.1),
       amp=st.floats(0.08, 0.14), phase=st.floats(0.0, 2 * math.pi))
def test_free_oscillation_analysis_on_eq22(omega0, zeta, amp, phase):
    """The analysis inverts eq. (22) for any natural frequency and damping."""
    h = 0.005
    t = np.arange(0, 10.0, h)
    wd = omega0 * math.sqrt(1 - zeta * zeta)
    theta = 3.18 + amp * np.exp(-zeta * omega0 * t) * np.cos(wd * t + phase)
    r = ex.analyse_free_oscillation({"t": t, "theta_m": theta})
    assert _close(r["omega0"], omega0, 0.01)
    assert _close(r["zeta"], zeta, 0.05)
    assert r["rest_angle"] == pytest.approx(3.18, abs=1e-3)


def test_free_oscillation_ignores_a_lone_noise_peak_after_the_decay():
    """A peak of the noise seconds after the swing died away is not a period: the
    consecutive peaks alone give omega_d (with it, the mean spacing was 1.5 periods)."""
    h = 0.005
    t = np.arange(0, 12.0, h)
    theta = 3.14 + 0.1 * np.exp(-0.43 * t) * np.cos(7.05 * t)
    theta[(t > 10.5) & (t < 10.6)] += 0.009 * np.sin(np.pi * (t[(t > 10.5) & (t < 10.6)] - 10.5)
                                                     / 0.1)
    r = ex.analyse_free_oscillation({"t": t, "theta_m": theta})
    assert _close(r["omega0_peaks"], math.hypot(7.05, 0.43), 0.01)
    assert all(pt < 10.0 for pt, _ in r["peaks"])


def test_free_oscillation_that_grows_warns_instead_of_clipping_silently():
    h = 0.005
    t = np.arange(0, 10.0, h)
    theta = 3.18 + 0.03 * np.exp(0.05 * t) * np.cos(7.0 * t)
    r = ex.analyse_free_oscillation({"t": t, "theta_m": theta})
    assert r["zeta_peaks"] == 0.0
    assert len(r["warnings"]) == 1 and "grows" in r["warnings"][0]
    decaying = 3.18 + 0.03 * np.exp(-0.3 * t) * np.cos(7.0 * t)
    assert ex.analyse_free_oscillation({"t": t, "theta_m": decaying})["warnings"] == []


@pytest.mark.parametrize("ext", [".csv", ".dat"])
def test_saved_log_gives_the_same_estimates(tmp_path, stiction_log, scaling_log, ext):
    for log, analyse in ((stiction_log, ex.analyse_stiction),
                         (scaling_log, ex.analyse_control_scaling)):
        path = tmp_path / f"log{ext}"
        log.save(path)
        direct = ex.estimates_only(analyse(log))
        again = ex.estimates_only(analyse(read_log(path, h=0.005)))
        assert again.keys() == direct.keys()
        for k in direct:
            assert again[k] == pytest.approx(direct[k], rel=1e-5, abs=1e-6), k


def test_log_without_the_needed_signal(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("t,theta_m,u\n0,3.1,0\n0.005,3.1,0\n0.01,3.1,0\n0.015,3.1,0\n")
    with pytest.raises(IdentificationError, match="arm_dot_m"):
        ex.analyse_stiction(read_log(path))
    with pytest.raises(IdentificationError, match="peak"):
        ex.analyse_free_oscillation(read_log(path))


def test_dat_log_warns_when_its_run_missed_ticks(tmp_path, oscillation_log):
    import json

    dat = tmp_path / "run1.dat"
    oscillation_log.save(dat)
    assert log_warnings(dat) == []  # no sidecar: nothing known
    sidecar = tmp_path / "run1.json"
    sidecar.write_text(json.dumps({"stats": {"missed": 0}, "dropped_log_samples": 0}))
    assert log_warnings(dat) == []
    sidecar.write_text(json.dumps({"stats": {"missed": 3}, "dropped_log_samples": 0}))
    (w,) = log_warnings(dat)
    assert "3 missed tick(s)" in w and "run1.csv" in w
    sidecar.write_text(json.dumps({"stats": {"missed": 2}, "dropped_log_samples": 5}))
    (w,) = log_warnings(dat)
    assert "2 missed tick(s) and 5 dropped log sample(s)" in w
    sidecar.write_text("{not json")
    assert log_warnings(dat) == []
    # a .csv has its time column
    oscillation_log.save(tmp_path / "run1.csv")
    assert log_warnings(tmp_path / "run1.csv") == []


@pytest.mark.parametrize("text, match", [
    ("", "empty"),
    ("t,u\n", "no samples"),
    ("t,u\n1,2,3\n", "columns"),
    ("t,u\n1,a\n", "malformed"),
])
def test_read_log_rejects(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the error alone, no numpy warning before it
        with pytest.raises(ValueError, match=match):
            read_log(path)
    with pytest.raises(ValueError, match="extension"):
        read_log(tmp_path / "bad.txt")


@pytest.mark.slow
def test_plots(tmp_path, stiction_log, stribeck_log, free_decay, scaling_log):
    from frictionlab.studies.identification import plots

    cases = [
        (plots.plot_stiction, stiction_log, ex.analyse_stiction(stiction_log)),
        (plots.plot_free_oscillation, free_decay, ex.analyse_free_oscillation(free_decay)),
        (plots.plot_control_scaling, scaling_log, ex.analyse_control_scaling(scaling_log)),
    ]
    for i, (fn, log, res) in enumerate(cases):
        out = tmp_path / f"p{i}.png"
        fn(log, res, str(out))
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = tmp_path / "stribeck.png"
    plots.plot_stribeck(ex.analyse_stribeck(stribeck_log), str(out))
    assert out.stat().st_size > 1000
