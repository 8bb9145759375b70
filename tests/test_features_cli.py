"""``frictionlab features``: limit-cycle features of a run log, for ``identify limit-cycle``."""

import json
import shutil

import pytest

from frictionlab.cli import main
from frictionlab.cli.identify import load_measured
from frictionlab.config import build_config
from frictionlab.model.limit_cycles import FEATURES, trajectory_features
from frictionlab.realtime import FakeClock, RealtimeController
from frictionlab.realtime.rigs import SimRig
from frictionlab.runs import simulate_config

DURATION = 20.0


def _features(capsys, *argv):
    rc = main(["features", *argv, "--json"])
    out, err = capsys.readouterr()
    return rc, (json.loads(out) if rc == 0 else None), err


@pytest.fixture(scope="module")
def run_log(tmp_path_factory):
    """A 20 s run of the simulated rig through the real-time loop (fake clock, so
    the loop and its log are those of ``run --headless``, without waiting)."""
    cfg = build_config("slow", "classical")
    d = tmp_path_factory.mktemp("runs")
    ctl = RealtimeController(cfg, SimRig(cfg, lockstep=True), log_dir=d, clock=FakeClock(),
                             duration=DURATION, realtime=False, manage_gc=False)
    stats = ctl.run()
    assert stats["stop_reason"] == "duration" and stats["missed"] == 0
    return cfg, stats["log"]


def test_features_of_a_run_log_agree_with_simulate(run_log, capsys):
    cfg, log = run_log
    rc, got, _ = _features(capsys, log)
    assert rc == 0
    assert got["design"] == "slow" and got["status"] == "limit_cycle"
    assert set(got["features"]) == set(FEATURES)
    want = trajectory_features(simulate_config(cfg, DURATION)).interface_dict()
    for name in FEATURES:
        if want[name] is None:
            assert got["features"][name] is None, name
        else:
            assert got["features"][name] == pytest.approx(want[name], rel=0.05), name
    # the .dat (time from the sidecar's h; no missed ticks) gives the same
    rc, dat, _ = _features(capsys, log.removesuffix(".csv") + ".dat", "--window", "5")
    rc2, csv, _ = _features(capsys, log, "--window", "5")
    assert rc == rc2 == 0 and dat["window"] == 5
    for name in FEATURES:
        if csv["features"][name] is not None:
            assert dat["features"][name] == pytest.approx(csv["features"][name], rel=1e-6)


def test_without_sidecar_the_design_and_the_period_must_be_given(run_log, tmp_path, capsys):
    _, log = run_log
    for ext in ("csv", "dat"):
        shutil.copy(log.removesuffix(".csv") + f".{ext}", tmp_path / f"bare.{ext}")
    rc, _, err = _features(capsys, str(tmp_path / "bare.csv"))
    assert rc == 2 and "--design" in err
    rc, _, err = _features(capsys, str(tmp_path / "bare.dat"), "--design", "slow")
    assert rc == 2 and "design.h" in err
    rc, got, _ = _features(capsys, str(tmp_path / "bare.dat"), "--design", "slow",
                           "--set", "design.h=0.005")
    assert rc == 0 and got["design"] == "slow" and got["status"] == "limit_cycle"
    rc, _, err = _features(capsys, str(tmp_path / "bare.dat"), "--design", "slow",
                           "--set", "design.h=0.01")
    assert rc == 0  # a .dat's time axis is the period given
    rc, _, err = _features(capsys, str(tmp_path / "missing.csv"), "--design", "fast")
    assert rc == 2 and "missing.csv" in err
    rc, _, err = _features(capsys, log, "--set", "plant.omega0=7")
    assert rc == 2 and "design.h" in err


def test_the_library_names_what_a_bare_log_lacks_by_field(run_log, tmp_path):
    """run_log_features raises ParamError naming its argument (no option); the
    command line names the option (above)."""
    from frictionlab.io.runlog import run_log_features
    from frictionlab.model.params import ParamError

    _, log = run_log
    for ext in ("csv", "dat"):
        shutil.copy(log.removesuffix(".csv") + f".{ext}", tmp_path / f"bare.{ext}")
    with pytest.raises(ParamError) as info:
        run_log_features(tmp_path / "bare.csv")
    assert info.value.field == "design" and "--" not in str(info.value)
    with pytest.raises(ParamError) as info:
        run_log_features(tmp_path / "bare.dat", design="slow")
    assert info.value.field == "h" and "--" not in str(info.value)
    with pytest.raises(ParamError) as info:
        run_log_features(tmp_path / "bare.dat", design="slow", h=-1.0)
    assert info.value.field == "h"
    got = run_log_features(tmp_path / "bare.csv", design="slow", window=1e3)
    assert any("window" in n and "--" not in n for n in got["notes"])


def test_identify_limit_cycle_takes_run_logs_and_features_objects(run_log, tmp_path,
                                                                   capsys):
    _, log = run_log
    rc, feats, _ = _features(capsys, log)
    (tmp_path / "f.json").write_text(json.dumps({**feats, "name": "again"}))
    (tmp_path / "table.json").write_text(json.dumps(
        {"experiments": [{"design": "fast", "features": {"peak1": 0.17, "period": 0.93}}]}))
    exps = load_measured([log, str(tmp_path / "f.json"), str(tmp_path / "table.json")])
    assert [e.design for e in exps] == ["slow", "slow", "fast"]
    assert exps[0].features == exps[1].features
    assert exps[0].features["period"] == feats["features"]["period"]
    # the command line reads the log, then validates the rest (here: a bad key)
    rc = main(["identify", "limit-cycle", "--measured", log, "--fit", "plant.omga0",
               "--json"])
    err = capsys.readouterr().err
    assert rc == 2 and "plant.omga0" in err and "measured" not in err
