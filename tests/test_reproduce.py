"""``frictionlab reproduce``: the thesis's simulation studies in one report folder.

The command runs once for the whole module (a few seconds); the tests read its
JSON and its files.
"""

import io
import json
import random
from contextlib import redirect_stdout
from pathlib import Path

import pytest

from frictionlab.cli import main
from frictionlab.studies import reproduce as rp
from frictionlab.studies.reference import TABLE2, TABLE3, TABLE_COLUMNS

FEATURE_COLS = set(TABLE_COLUMNS)
THESIS = {"2": ("friction.coulomb", TABLE2), "3": ("friction.stiction", TABLE3)}
APPENDIX_F_KEYS = {"friction.stiction", "friction.coulomb", "friction.viscous",
                   "friction.stribeck_velocity", "friction.sigma0", "friction.sigma1",
                   "friction.observer_gain"}


def _json_of(args):
    buf = io.StringIO()
    with redirect_stdout(buf):
        rc = main(args)
    assert rc == 0
    lines = buf.getvalue().strip().splitlines()
    assert len(lines) == 1  # exactly one JSON object on stdout
    return json.loads(lines[0])


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce") / "report"
    result = _json_of(["reproduce", "--out", str(out), "--json", "--no-progress"])
    return result, out


def _varied(row):
    keys = [k for k in row if k not in FEATURE_COLS]
    assert len(keys) == 1, row
    return keys[0], row[keys[0]]


@pytest.mark.xdist_group("reproduce-report")
@pytest.mark.slow
def test_json_is_the_documented_object(report):
    result, out = report
    assert set(result) == {"out", "seconds", "figures", "tables", "table1"}
    assert result["out"] == str(out) and result["seconds"] > 0
    assert set(result["tables"]) == {"2", "3", "4", "5", "6", "7"}
    for number, rows in result["tables"].items():
        assert rows, number
        for row in rows:
            key, value = _varied(row)
            assert set(row) == {key} | FEATURE_COLS
            assert isinstance(value, float)
    # Tables 6 and 7 vary every LuGre parameter, one key per row
    lugre = {_varied(r)[0] for n in ("6", "7") for r in result["tables"][n]}
    assert lugre == APPENDIX_F_KEYS


@pytest.mark.xdist_group("reproduce-report")
@pytest.mark.slow
@pytest.mark.parametrize("number", ["2", "3"])
def test_tables_2_and_3_within_5_percent_of_the_thesis(report, number):
    key, thesis = THESIS[number]
    rows = report[0]["tables"][number]
    assert [_varied(r) for r in rows] == [(key, v) for v in thesis]
    for row in rows:
        for name, expected in zip(TABLE_COLUMNS, thesis[row[key]], strict=True):
            assert row[name] == pytest.approx(expected, rel=0.05), (row[key], name)


@pytest.mark.slow
@pytest.mark.xdist_group("reproduce-report")
def test_slow_tables_vary_the_same_grids(report):
    tables = report[0]["tables"]
    for fast, slow in (("2", "4"), ("3", "5")):
        assert [_varied(r) for r in tables[slow]] == [_varied(r) for r in tables[fast]]
        # a different cycle: the slow design's period is about 3.3 s (Sec. 5.2)
        assert all(r["period"] > 3.0 for r in tables[slow])


@pytest.mark.slow
@pytest.mark.xdist_group("reproduce-report")
def test_lugre_rows_follow_the_observer_gain(report):
    """Table 7's k rows (0 to 2, eq. 19 with e = -theta acting in the plant): the
    cycle quickens and grows with k; sigma0 = 100 is extremal (App. F)."""
    rows = report[0]["tables"]["7"]
    ks = [r for r in rows if _varied(r)[0] == "friction.observer_gain"]
    assert [r["friction.observer_gain"] for r in ks] == [0.25 * i for i in range(9)]
    periods = [r["period"] for r in ks]
    peaks = [r["peak1"] for r in ks]
    assert periods == sorted(periods, reverse=True) and peaks == sorted(peaks)
    sig = {r["friction.sigma0"]: r for r in rows if _varied(r)[0] == "friction.sigma0"}
    assert sig[100.0]["period"] > max(sig[50.0]["period"], sig[200.0]["period"])
    assert sig[100.0]["peak1"] < min(sig[50.0]["peak1"], sig[200.0]["peak1"])


@pytest.mark.slow
@pytest.mark.xdist_group("reproduce-report")
def test_report_files(report):
    result, out = report
    md = (out / "report.md").read_text(encoding="utf-8")
    for number in "234567":
        assert f"## Table {number}:" in md
    assert "## Sec. 5.2-5.3: the plant's omega0 against the rig (Table 1)" in md
    names = [Path(p).name for p in result["figures"]]
    assert names == [f"fig{n}.png" for n in range(17, 25)] + [
        "lugre_angle_velocity.png", "lugre_control_friction.png", "table1.png"]
    for path in result["figures"]:
        data = Path(path).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
        assert f"({Path(path).name})" in md  # shown in the report
    full = json.loads((out / "report.json").read_text(encoding="utf-8"))
    for number, rows in result["tables"].items():
        detail = full["tables"][number]["rows"]
        assert [{r["key"]: r["value"], **{c: r[c] for c in TABLE_COLUMNS}} for r in detail] \
            == rows
    # the checked statements: every one that can be decided holds
    verdicts = {s["statement"]: s["agrees"] for s in full["statements"]}
    assert verdicts and all(v is not False for v in verdicts.values()), verdicts
    assert len(full["omega0_studies"]) == len(rp.CASES)


@pytest.mark.slow
@pytest.mark.xdist_group("reproduce-report")
def test_table1_by_one_plausible_set(report):
    """Table 1 (the rig) by one set in the plausible box; its RMS is that of the
    12 relative errors of the two runs, which `simulate` repeats."""
    from frictionlab.studies.reference import TABLE1

    result, out = report
    t1 = result["table1"]
    assert set(t1) == {"rms", "set"} and t1["set"] == rp.TABLE1_SET
    assert 6.5 <= t1["set"]["plant.omega0"] <= 7.1
    assert 0.8 <= t1["set"]["plant.input_gain"] <= 1.25
    full = json.loads((out / "report.json").read_text(encoding="utf-8"))
    errs = []
    for rig in ("fast", "slow"):
        sets = [a for k, v in t1["set"].items() for a in ("--set", f"{k}={v}")]
        sim = _json_of(["simulate", "--design", rig, "--friction", "classical", "--duration",
                        str(rp.DURATION), *sets, "--json"])["features"]
        row = full["table1"]["rows"][rig]
        for name, ref in zip(TABLE_COLUMNS, TABLE1[rig], strict=True):
            assert row["features"][name] == sim[name]
            v = sim[name]
            if v is None and name == "valley":
                v = sim["peak2"]
            if v is None:
                v = sim["peak1"]
            errs.append((v - ref) / ref)
    assert len(errs) == 12
    assert t1["rms"] == pytest.approx((sum(e * e for e in errs) / 12) ** 0.5, rel=1e-12)


@pytest.mark.slow
@pytest.mark.xdist_group("reproduce-report")
def test_rows_match_simulate(report):
    """A sampled row of every table equals a `simulate` run of the same settings
    (the command report.json gives for it)."""
    _result, out = report
    full = json.loads((out / "report.json").read_text(encoding="utf-8"))
    rng = random.Random(13)
    for number in "234567":
        row = rng.choice(full["tables"][number]["rows"])
        args = row["command"].split()[1:]
        assert args[0] == "simulate"
        sim = _json_of(args)
        for name in TABLE_COLUMNS:
            assert sim["features"][name] == row[name], (number, row["key"], name)


@pytest.mark.slow
def test_every_run_goes_through_the_sweep_engine(monkeypatch):
    from frictionlab import runs
    from frictionlab.studies import batch, sweep

    points, sims = [], []
    evaluate, run_batch = sweep.evaluate, batch.run
    simulate_config = runs.simulate_config

    def counting_evaluate(base, pts, **kw):
        points.extend(pts)
        assert kw["workers"] == 1 and kw["duration"] == rp.DURATION
        return evaluate(base, pts, **kw)

    def counting_run(b, *a, **kw):  # the compiled batch (features): a simulation per set
        sims.extend([1] * len(b.index))
        return run_batch(b, *a, **kw)

    def counting_simulate(*a, **kw):  # the runs whose traces are kept (a custom reduce)
        sims.append(1)
        return simulate_config(*a, **kw)

    monkeypatch.setattr(sweep, "evaluate", counting_evaluate)
    monkeypatch.setattr(batch, "run", counting_run)
    monkeypatch.setattr(runs, "simulate_config", counting_simulate)
    results = rp.run(workers=1)
    assert len(points) == len(sims) == rp.count_runs()
    # the tables share runs: Table 2's F_C = 1.5 is Table 3's F_S = 2.3
    n_rows = sum(len(rows) for rows in results.tables.values())
    assert rp.count_runs() < n_rows + len(rp.CASES)


@pytest.mark.parametrize("args,message", [
    (["--workers", "0"], "--workers"),
    (["--dask", "bogus"], "--dask"),
])
def test_bad_options_exit_2(tmp_path, capsys, args, message):
    assert main(["reproduce", "--out", str(tmp_path / "r"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()  # nothing written


def test_bad_out_folder_exit_2(tmp_path, capsys):
    afile = tmp_path / "f.txt"
    afile.write_text("x")
    assert main(["reproduce", "--out", str(afile)]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["reproduce", "--out", str(tmp_path / "no" / "such")]) == 2
    assert "does not exist" in capsys.readouterr().err


def _failing_reduce(cfg, duration, window):
    """reduce_with_trace, except that the slow design's omega0 = 6.1 run raises."""
    if cfg.plant.omega0 == 6.1 and cfg.friction.zero_velocity_band == 0.001:
        raise RuntimeError("injected failure")
    return _REAL_REDUCE(cfg, duration, window)


_REAL_REDUCE = rp.reduce_with_trace


@pytest.mark.slow
def test_a_failed_run_is_a_row_not_a_crash(tmp_path, monkeypatch):
    """A run that raises becomes an error row; the report is still written, without
    the figures of that run."""
    monkeypatch.setattr(rp, "reduce_with_trace", _failing_reduce)
    results = rp.run(workers=1)
    row = next(r for c, r in results.cases if c.name == "slow_w61")
    assert row["status"] == "error" and "injected failure" in row["error"]
    figures = rp.write_report(results, str(tmp_path), 1.0)
    names = {Path(p).name for p in figures}
    assert "fig23.png" not in names and "fig24.png" not in names and len(names) == 9
    md = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "slow, plant omega0 6.1, F_C 1.3 (Figs. 23-24) [error]" in md
