"""``frictionlab identify ...`` on the command line: JSON contract, plots,
logs, and exit status 2 on infeasible input."""

from __future__ import annotations

import json

import pytest

from frictionlab.cli import main
from frictionlab.config import build_config
from frictionlab.runs import run_features

DURATION, WINDOW = 16.0, 10.0


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """Features of the fast and slow designs at Coulomb 1.4 (other keys default)."""
    exps = []
    for design in ("fast", "slow"):
        cfg = build_config(design=design, friction="classical",
                           sets=[("friction.coulomb", 1.4)])
        exps.append({"design": design,
                     "features": run_features(cfg, DURATION, WINDOW).interface_dict()})
    path = tmp_path_factory.mktemp("measured") / "m.json"
    path.write_text(json.dumps({"experiments": exps}))
    return path


def _run(capsys, argv):
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.slow
def test_limit_cycle_json_plot_and_report(capsys, tmp_path, measured):
    plot, report = tmp_path / "fit.png", tmp_path / "full.json"
    rc, out, err = _run(capsys, [
        "identify", "limit-cycle", "--measured", str(measured), "--fit", "friction.coulomb",
        "--bounds", "friction.coulomb=1.0:2.0", "--duration", str(DURATION),
        "--window", str(WINDOW), "--maxiter", "12", "--popsize", "8", "--workers", "1",
        "--plot", str(plot), "--report", str(report), "--json"])
    assert rc == 0
    lines = out.strip().splitlines()
    assert len(lines) == 1
    obj = json.loads(lines[0])
    assert list(obj) == ["estimate", "stderr", "residuals", "cost"]
    assert abs(obj["estimate"]["friction.coulomb"] - 1.4) < 0.02
    assert set(obj["residuals"]) == {"fast", "slow"}
    assert obj["cost"] >= 0
    # progress and the summary go to stderr
    assert "identify limit-cycle" in err and "done in" in err
    assert "global search: 100 %" in err and "least-squares polish" in err
    assert plot.read_bytes()[:4] == b"\x89PNG"
    full = json.loads(report.read_text())
    assert full["estimate"] == obj["estimate"]
    assert set(full["simulated"]) == {"fast", "slow"}
    assert "warnings" in full and "singular_values" in full


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_limit_cycle_on_a_dask_localcluster_gives_the_pool_estimate(capsys, measured):
    from frictionlab.studies.sweep import shutdown

    argv = ["identify", "limit-cycle", "--measured", str(measured), "--fit", "friction.coulomb",
            "--bounds", "friction.coulomb=1.2:1.6", "--duration", str(DURATION), "--window",
            str(WINDOW), "--maxiter", "2", "--popsize", "3", "--workers", "2", "--quiet",
            "--json"]
    try:
        rc, out, _ = _run(capsys, argv)
        assert rc == 0
        pool = json.loads(out)
        rc, out, _ = _run(capsys, [*argv, "--dask", "local"])
        assert rc == 0
        dask = json.loads(out)
    finally:
        shutdown()
    assert dask == pool
    assert abs(pool["estimate"]["friction.coulomb"] - 1.4) < 0.05


def test_limit_cycle_text_output(capsys, measured):
    rc, out, _ = _run(capsys, [
        "identify", "limit-cycle", "--measured", str(measured), "--fit", "friction.coulomb",
        "--bounds", "friction.coulomb=1.2:1.6", "--duration", str(DURATION),
        "--window", str(WINDOW), "--maxiter", "2", "--popsize", "3", "--workers", "1",
        "--quiet"])
    assert rc == 0
    assert "friction.coulomb" in out and "residuals" in out


def _write(tmp_path, obj, name="m.json"):
    p = tmp_path / name
    p.write_text(obj if isinstance(obj, str) else json.dumps(obj))
    return str(p)


GOOD = {"experiments": [{"design": "fast", "features": {"period": 1.0, "peak1": 0.1}}]}


@pytest.mark.parametrize("measured, extra, match", [
    ({"experiments": []}, [], "non-empty"),
    ({"experiments": [{"design": "fast", "features": {"peak9": 0.1}}]}, [], "unknown feature"),
    (GOOD, ["--bounds", "friction.coulomb=2:1"], "below upper"),
    (GOOD, ["--bounds", "friction.coulomb=1"], "KEY=LO:HI"),
    (GOOD, ["--bounds", "plant.omega0=6:7"], "not fitted"),
    (GOOD, ["--fit", "friction.nonsense"], "not a parameter"),
    (GOOD, ["--fit", "sim.substeps"], "real-valued"),
    (GOOD, ["--weights", "peak7=2"], "unknown feature"),
    (GOOD, ["--set", "plant.omega0=-3"], "omega0"),
    (GOOD, ["--fit", "friction.coulomb,friction.stiction", "--bounds",
            "friction.coulomb=2:3", "--bounds", "friction.stiction=0.5:1.5"],
     "no stiction >= Coulomb"),
    ("{not json", [], "not valid JSON"),
    (GOOD, ["--search-duration", "0"], "--search-duration must be > 0"),
    (GOOD, ["--search-duration", "15", "--search-window", "20"], "--search-window"),
    # the plant the files name (docs/identification.md)
    ({**GOOD, "plant": "qube9"}, [], "\"plant\" 'qube9' is not one of"),
    ({**GOOD, "plant": "qube2"}, ["--plant", "thesis"],
     "--plant thesis: the measured experiments are of the qube2 plant"),
    ({"plant": "qube2", "experiments": [{**GOOD["experiments"][0], "plant": "thesis"}]}, [],
     "an experiment of the thesis plant in a file of the qube2 plant"),
    ({"experiments": [{**GOOD["experiments"][0], "plant": "qube2"},
                      {**GOOD["experiments"][0], "plant": "qube3", "name": "b"}]}, [],
     "different plants"),
])
def test_limit_cycle_infeasible_input_exits_2(capsys, tmp_path, measured, extra, match):
    argv = ["identify", "limit-cycle", "--measured", _write(tmp_path, measured),
            "--workers", "1", "--quiet"]
    if "--fit" not in extra:
        argv += ["--fit", "friction.coulomb"]
    rc, out, err = _run(capsys, argv + extra)
    assert rc == 2
    assert out == ""
    msg = err.strip().splitlines()
    assert len(msg) == 1 and match in msg[0]


def test_limit_cycle_fits_on_the_plant_its_file_names(capsys, tmp_path, monkeypatch):
    """``"plant"`` in an experiments file (or in each experiment): the fit's plant
    without --plant, its keys checked on that plant (a motor plant's own keys)."""
    from frictionlab.studies.identification import limit_cycle

    asked = []

    def fit(experiments, keys, **kwargs):  # the work itself: not run here
        asked.append((keys, kwargs["plant"]))
        raise KeyboardInterrupt

    monkeypatch.setattr(limit_cycle, "fit_limit_cycle", fit)
    exp = GOOD["experiments"][0]
    for measured in ({**GOOD, "plant": "qube2"}, {"experiments": [{**exp, "plant": "qube2"}]}):
        rc, _, err = _run(capsys, ["identify", "limit-cycle", "--measured",
                                   _write(tmp_path, measured), "--quiet",
                                   "--fit", "friction.coulomb,plant.resistance"])
        assert rc == 130 and "on the qube2 plant (from the measured files)" in err
        assert asked[-1] == (["friction.coulomb", "plant.resistance"], "qube2")


def test_limit_cycle_missing_file_exits_2(capsys, tmp_path):
    rc, _, err = _run(capsys, ["identify", "limit-cycle", "--measured",
                               str(tmp_path / "none.json"), "--fit", "friction.coulomb"])
    assert rc == 2 and "cannot read" in err


@pytest.mark.slow
@pytest.mark.parametrize("name, sets, expect", [
    ("stiction", ["friction.stiction=2.1", "friction.coulomb=1.35"],
     {"stiction": (2.1, 0.05), "coulomb": (1.35, 0.05)}),
    ("free-oscillation", ["plant.omega0=7.1", "plant.zeta=0.06"],
     {"omega0": (7.1, 0.02), "zeta": (0.06, 0.2)}),
    ("control-scaling", ["plant.input_gain=0.8"], {"input_gain": (0.8, 0.05)}),
])
def test_experiment_simulate_save_then_log(capsys, tmp_path, name, sets, expect):
    save = tmp_path / "log.csv"
    argv = ["identify", "experiment", name, "--simulate", "--json"]
    for s in sets:
        argv += ["--set", s]
    rc, out, _ = _run(capsys, [*argv, "--save", str(save)])
    assert rc == 0
    sim = json.loads(out)
    for key, (truth, rel) in expect.items():
        assert abs(sim[key] - truth) <= rel * truth, (key, sim[key])
    assert sim["source"] == "simulated"
    # the same analysis on the saved log (the plant's assumed settings given again)
    plot = tmp_path / "fig.png"
    rc, out, _ = _run(capsys, ["identify", "experiment", name, "--log", str(save),
                               *[x for s in sets for x in ("--set", s)],
                               "--plot", str(plot), "--json"])
    assert rc == 0
    logged = json.loads(out)
    for key in expect:
        assert logged[key] == pytest.approx(sim[key], rel=1e-5)
    assert plot.read_bytes()[:4] == b"\x89PNG"


def test_stribeck_experiment_cli_and_its_log(capsys, tmp_path):
    """--simulate --save, then --log on the saved file: the same estimates."""
    save = tmp_path / "stribeck.csv"
    argv = ["identify", "experiment", "stribeck", "--json", "--references",
            "0.3,0.6,1,2,4,8,12", "--hold", "1", "--set", "friction.coulomb=1.4",
            "--set", "friction.viscous=0.06"]
    rc, out, _ = _run(capsys, [*argv, "--save", str(save)])
    assert rc == 0
    r = json.loads(out)
    assert abs(r["coulomb"] - 1.4) < 0.05 * 1.4
    assert abs(r["viscous"] - 0.06) < 0.2 * 0.06
    assert {"coulomb", "viscous", "stribeck_velocity"} <= set(r)
    rc, out, _ = _run(capsys, ["identify", "experiment", "stribeck", "--log", str(save),
                               "--json"])
    assert rc == 0
    logged = json.loads(out)
    assert logged["source"] == str(save)
    for key in ("coulomb", "viscous", "stribeck_velocity", "stiction"):
        assert logged[key] == pytest.approx(r[key], rel=1e-5), key
    assert len(logged["points"]) == len(r["points"])


def test_free_oscillation_dat_log_round_trip_and_missed_ticks(capsys, tmp_path):
    """A .dat log (no time column) gives the simulated estimates; when its
    run's sidecar reports missed ticks the command warns and says use .csv."""
    dat = tmp_path / "swing.dat"
    sets = ["--set", "plant.omega0=7.1", "--set", "plant.zeta=0.06"]
    rc, out, _ = _run(capsys, ["identify", "experiment", "free-oscillation", *sets,
                               "--save", str(dat), "--json"])
    assert rc == 0
    sim = json.loads(out)
    rc, out, err = _run(capsys, ["identify", "experiment", "free-oscillation", "--log",
                                 str(dat), "--json"])
    assert rc == 0 and "warning" not in err
    logged = json.loads(out)
    for key in ("omega0", "zeta", "omega0_peaks", "zeta_peaks"):
        assert logged[key] == pytest.approx(sim[key], rel=1e-5), key
    assert logged["warnings"] == []
    # the sidecar --save wrote (the experiment's marks), now with a run's missed ticks
    sidecar = tmp_path / "swing.json"
    meta = json.loads(sidecar.read_text())
    assert meta["experiment"]["marks"]["free"] > 0
    sidecar.write_text(json.dumps({**meta, "stats": {"missed": 4}}))
    rc, out, err = _run(capsys, ["identify", "experiment", "free-oscillation", "--log",
                                 str(dat), "--json"])
    assert rc == 0
    assert "warning: swing.dat: its run reports 4 missed tick(s)" in err and ".csv" in err
    assert len(json.loads(out)["warnings"]) == 1


def test_stiction_with_one_staircase_level_warns(capsys):
    rc, out, err = _run(capsys, ["identify", "experiment", "stiction", "--simulate",
                                 "--step", "0.5", "--set", "friction.stiction=0.1",
                                 "--set", "friction.coulomb=0.08", "--json"])
    assert rc == 0
    r = json.loads(out)
    assert r["stiction"] == pytest.approx(0.25)
    assert err.count("warning: the arm broke away at the first level") == 2
    assert len(r["warnings"]) == 2
    assert all(w.endswith("smaller staircase step (--step)") for w in r["warnings"])


@pytest.mark.parametrize("argv, match", [
    (["stiction", "--log", "nothere.csv"], "cannot read"),
    (["stiction", "--save", "x.txt"], "extension"),
    (["stribeck", "--references", "a,b"], "not a number"),
    (["stiction", "--hold", "0"], "--hold"),
    (["stiction", "--set", "friction.coulomb=-1"], "coulomb"),
    (["free-oscillation", "--duration", "-1"], "--duration must be > 0"),
    (["free-oscillation", "--duration", "0"], "--duration must be > 0"),
])
def test_experiment_bad_input_exits_2(capsys, argv, match):
    rc, out, err = _run(capsys, ["identify", "experiment", *argv, "--json"])
    assert rc == 2 and out == ""
    assert match in err and len(err.strip().splitlines()) == 1


def test_empty_log_is_one_line(capsys, tmp_path):
    p = tmp_path / "empty.csv"
    p.write_text("t,u,arm_dot_m\n")
    rc, out, err = _run(capsys, ["identify", "experiment", "stiction", "--log", str(p)])
    assert rc == 2 and out == ""
    assert err.strip().splitlines() == [
        f"frictionlab identify experiment: error: {p}: the log has no samples"]


def test_experiment_log_lacking_a_signal_exits_2(capsys, tmp_path):
    p = tmp_path / "l.csv"
    p.write_text("t,theta_m\n0,3.1\n0.005,3.1\n0.01,3.1\n")
    rc, _, err = _run(capsys, ["identify", "experiment", "control-scaling", "--log", str(p)])
    assert rc == 2 and "'u'" in err


def test_library_notes_and_refusals_get_their_options_from_the_command_line():
    """The library names arguments (``hints``, ``field``); only the command line
    names options."""
    import pickle

    from frictionlab.cli.common import error_message, note_text
    from frictionlab.io.notes import Note
    from frictionlab.studies.identification.limit_cycle import LimitCycleProblem, parse_experiments

    note = Note("friction.coulomb = 4 is at its search bound [0.2, 4]: widen its bounds",
                "bounds")
    assert note_text(note) == f"{note} (--bounds)"
    assert note_text("no hints") == "no hints"
    again = pickle.loads(pickle.dumps(note))
    assert again == note and again.hints == ("bounds",)
    exps = parse_experiments(GOOD)
    with pytest.raises(ValueError) as info:
        LimitCycleProblem(exps, ["friction.coulomb", "friction.stiction"],
                          bounds={"friction.coulomb": (2.0, 3.0),
                                  "friction.stiction": (0.5, 1.5)})
    assert "--" not in str(info.value)
    assert info.value.field == "bounds" and info.value.hints == ("stiction_above_coulomb",)
    assert error_message(info.value).startswith("--bounds: ")
    assert error_message(info.value).endswith("(--allow-stiction-below-coulomb)")


@pytest.mark.parametrize("extra, message", [
    (["--max-pause", "-1"], "--max-pause = -1"),
    (["--silent-periods", "0"], "--silent-periods = 0"),
    (["--max-speed", "-1"], "--max-speed = -1"),
    (["--max-u-da", "2"], "--max-u-da = 2"),
])
def test_experiment_on_a_rig_names_a_refused_limit_by_its_option(capsys, tmp_path, extra,
                                                                message):
    """The loop's limits are the run command's (one parser and check for both)."""
    rc, out, err = _run(capsys, ["identify", "experiment", "stiction", "--backend", "sim",
                                 "--log-dir", str(tmp_path), *extra])
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err
