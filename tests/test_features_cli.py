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


def _copy_log(log, folder, name, **sidecar):
    """The run's .csv and .dat as ``folder/name.*``; its sidecar with ``sidecar``'s
    fields replaced (None: no sidecar)."""
    base = log.removesuffix(".csv")
    for ext in ("csv", "dat"):
        shutil.copy(f"{base}.{ext}", folder / f"{name}.{ext}")
    if sidecar.get("drop"):
        return str(folder / f"{name}.csv")
    with open(f"{base}.json") as fh:
        meta = json.load(fh)
    meta.update(sidecar)
    (folder / f"{name}.json").write_text(json.dumps(meta))
    return str(folder / f"{name}.csv")


@pytest.mark.slow
def test_features_name_the_plant_and_the_unit_of_u(run_log, tmp_path, capsys):
    """The sidecar's plant and u's unit, in the JSON and in the text (max_u in volts
    on a motor plant); a log without a sidecar: unknown, unless --plant says."""
    _, log = run_log
    rc, got, _ = _features(capsys, log)
    assert rc == 0 and (got["plant"], got["u_unit"]) == ("thesis", "m/s^2")
    qube = _copy_log(log, tmp_path, "qube", plant="qube2", u_unit="V")
    rc, got, _ = _features(capsys, qube)
    assert rc == 0 and (got["plant"], got["u_unit"]) == ("qube2", "V")
    assert main(["features", qube]) == 0
    text = capsys.readouterr().out.splitlines()
    assert "qube2 plant, u in V" in text[0]
    assert [ln.split()[-1] for ln in text if ln.split()[0] == "max_u"] == ["V"]
    # a sidecar without u_unit (a plant name only): the plant's unit
    rc, got, _ = _features(capsys, _copy_log(log, tmp_path, "old", plant="qube3",
                                             u_unit=None))
    assert rc == 0 and (got["plant"], got["u_unit"]) == ("qube3", "V")
    bare = _copy_log(log, tmp_path, "bare", drop=True)
    rc, got, _ = _features(capsys, bare, "--design", "slow")
    assert rc == 0 and got["plant"] is None and got["u_unit"] is None
    assert main(["features", bare, "--design", "slow"]) == 0
    assert "plant not recorded" in capsys.readouterr().out
    rc, got, _ = _features(capsys, bare, "--design", "slow", "--plant", "furuta-dc")
    assert rc == 0 and (got["plant"], got["u_unit"]) == ("furuta-dc", "V")


@pytest.mark.parametrize("sidecar, argv, message", [
    ({"plant": "qube2", "u_unit": "V"}, ["--plant", "thesis"], "says the qube2 plant"),
    ({"plant": "qube9"}, [], "plant 'qube9'"),
])
def test_a_plant_that_contradicts_the_sidecar_exits_2(run_log, tmp_path, capsys, sidecar,
                                                       argv, message):
    path = _copy_log(run_log[1], tmp_path, "run", **sidecar)
    rc, _, err = _features(capsys, path, *argv)
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_identify_limit_cycle_takes_the_plant_of_its_measured_files(run_log, tmp_path,
                                                                     capsys, monkeypatch):
    """Without --plant the fit runs on the plant the files name (a QUBE log, its
    features object); files of two plants, or a --plant against them, exit 2."""
    from frictionlab.studies.identification import limit_cycle

    _, log = run_log
    qube = _copy_log(log, tmp_path, "qube", plant="qube2", u_unit="V", run_id="qube")
    rc, feats, _ = _features(capsys, qube)
    (tmp_path / "qube-features.json").write_text(json.dumps({**feats, "name": "again"}))
    (tmp_path / "table.json").write_text(json.dumps(
        {"experiments": [{"design": "fast", "features": {"peak1": 0.17, "period": 0.93}}]}))
    (tmp_path / "thesis.json").write_text(json.dumps(
        {"plant": "thesis", "experiments": [{"design": "fast", "features": {"peak1": 0.1}}]}))
    asked = []

    def fit(experiments, keys, **kwargs):  # the work itself: not run here
        asked.append((len(experiments), kwargs["plant"]))
        raise KeyboardInterrupt

    monkeypatch.setattr(limit_cycle, "fit_limit_cycle", fit)

    def identify(*measured, extra=()):
        argv = ["identify", "limit-cycle", "--fit", "friction.coulomb", "--quiet", *extra]
        for m in measured:
            argv += ["--measured", str(m)]
        rc = main(argv)
        return rc, capsys.readouterr().err

    rc, err = identify(qube, tmp_path / "qube-features.json", tmp_path / "table.json")
    assert rc == 130 and asked[-1] == (3, "qube2"), err  # a file naming no plant: any
    assert "on the qube2 plant (from the measured files)" in err
    rc, err = identify(qube, extra=["--plant", "qube2"])
    assert rc == 130 and asked[-1] == (1, "qube2")
    rc, err = identify(tmp_path / "table.json")
    assert rc == 130 and asked[-1] == (1, "thesis")  # nothing says: the thesis plant
    n = len(asked)
    for measured, extra, message in [
        ((qube, log), (), "different plants"),
        ((tmp_path / "qube-features.json", tmp_path / "thesis.json"), (), "different plants"),
        ((qube,), ("--plant", "thesis"), "--plant thesis: the measured experiments are of "
                                         "the qube2 plant"),
    ]:
        rc, err = identify(*measured, extra=extra)
        assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert len(asked) == n  # refused before any work
