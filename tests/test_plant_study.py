"""``frictionlab reproduce --plant NAME``: the thesis's limit-cycle study on a motor plant.

The command runs once for the module on a reduced study (three F_C levels of
Table 2 with their predictions, one compensator, 20 s runs, in-process); the
tests read its JSON and its files.  The full study's grids are checked without
running them.
"""

import json
from pathlib import Path

import pytest
from inprocess import run_cli_in_process

from frictionlab.config import ConfigValueError
from frictionlab.model.plants.furuta_dc import PRESET_FRICTION
from frictionlab.studies import plant_study as ps
from frictionlab.studies.plant_report import counts, degrees

#: the reduced study's F_C levels (V): where the fast design's cycle has a stable orbit
LEVELS = (0.1, 0.15, 0.2)


_FULL = ps.study


def _reduced(plant: str) -> ps.PlantStudy:
    full = _FULL(plant)
    table2 = full.tables[0]
    table2 = ps.PlantTable(table2.number, table2.title, table2.setting,
                           (("friction.coulomb", LEVELS),))
    return ps.PlantStudy(plant, (table2,), (0.15,), ("classical",), (), 0.15,
                         duration=20.0, compensators=("classical", "lugre"))


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("plant") / "report"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ps, "study", _reduced)
        proc = run_cli_in_process(["reproduce", "--plant", "qube2", "--out", out, "--json",
                                   "--no-progress", "--workers", "1"])
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1  # exactly one JSON object on stdout
    return json.loads(lines[0]), out, proc.stderr


pytestmark = pytest.mark.xdist_group("plant-study")


@pytest.mark.slow
def test_json_is_the_documented_object(report):
    result, out, err = report
    assert set(result) == {"plant", "out", "seconds", "figures", "tables", "compensators"}
    assert result["plant"] == "qube2" and result["out"] == str(out)
    assert list(result["tables"]) == ["2"]
    rows = result["tables"]["2"]
    assert [r["friction.coulomb"] for r in rows] == list(LEVELS)
    for r in rows:
        assert set(r) == {"friction.coulomb", *ps.TABLE_COLUMNS, "status",
                          "arm_peak_to_peak", "fundamental", "orbit", "describing_function"}
        assert r["status"] == "limit_cycle"
        assert set(r["orbit"]) == {"found", "stable", "period", "peak1", "peak_to_peak"}
        assert set(r["describing_function"]) == {"period", "pendulum_amplitude", "amplitude"}
    comps = result["compensators"]
    assert [c["compensation"] for c in comps] == ["none", "classical", "lugre"]
    assert "6 runs of the plant qube2" in err  # the reduced study's count is stated


@pytest.mark.slow
def test_peak1_grows_with_coulomb_friction(report):
    """As in the thesis's Table 2: the first peak grows with F_C (classical model,
    fast design; with the default pendulum observer less than in proportion: 0.73 of
    it over F_C 0.1-0.2 V); the voltage stays far below its 10 V limit."""
    rows = report[0]["tables"]["2"]
    peak1 = [r["peak1"] for r in rows]
    assert peak1[0] < peak1[1] < peak1[2]
    ratio = (peak1[2] / peak1[0]) / (LEVELS[2] / LEVELS[0])
    assert 0.5 < ratio < 1.3, peak1
    assert all(0 < r["max_u"] < 5.0 for r in rows)


@pytest.mark.slow
def test_predictions_against_the_simulation(report):
    """The stable periodic orbit's period within 2 % of the simulated one and its
    peak1 within 5 %; the describing function (Coulomb relay: stiction never acts
    along a sinusoid) predicts the period within 20 % and the first harmonic within
    40 % (with the default pendulum observer: 1.11 s against 0.94-1.11 s, and
    0.70-1.03 of the simulated first harmonic)."""
    for r in report[0]["tables"]["2"]:
        o, df = r["orbit"], r["describing_function"]
        assert o["found"] and o["stable"], r
        assert o["period"] == pytest.approx(r["period"], rel=0.02)
        assert o["peak1"] == pytest.approx(r["peak1"], rel=0.05)
        assert df["period"] == pytest.approx(r["period"], rel=0.2)
        assert df["pendulum_amplitude"] == pytest.approx(r["fundamental"], rel=0.4)
        assert 0 < r["fundamental"] <= r["peak_to_peak"] / 2 * 1.05


@pytest.mark.slow
def test_compensator_shrinks_the_cycle(report):
    """With the default pendulum observer the classical compensator halves the cycle
    (2.2x measured) and the LuGre one, its innovation against the model's arm
    prediction, shrinks it 6.7 times (docs/qube.md)."""
    none, *comps = report[0]["compensators"]
    assert [c["compensation"] for c in comps] == ["classical", "lugre"]
    assert none["reduction"] == pytest.approx(1.0)
    for comp, least in zip(comps, (1.5, 4.0), strict=True):
        assert comp["baseline_peak_to_peak"] == none["peak_to_peak"]
        assert comp["reduction"] == pytest.approx(none["peak_to_peak"] / comp["peak_to_peak"])
        assert comp["reduction"] > least, comp


@pytest.mark.slow
def test_report_files(report):
    result, out, _ = report
    names = [Path(p).name for p in result["figures"]]
    assert names == ["qube2_cycle.png", "qube2_tables.png", "qube2_predictions.png",
                     "qube2_compensators.png"]
    for p in result["figures"]:
        assert Path(p).stat().st_size > 10_000
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "## Table 2: fast design, classical model, F_C varied (F_S = 0.2 V)" in md
    assert "| peak1 grows with F_C" in md.replace("fast design, classical friction: ", "")
    data = json.loads((out / "report.json").read_text(encoding="utf-8"))
    row = data["tables"]["2"]["rows"][1]
    assert row["command"] == ("frictionlab simulate --plant qube2 --design fast --friction "
                              "classical --duration 40 --set friction.stiction=0.2 "
                              "--set friction.coulomb=0.15 --json")
    assert {f["statement"] for f in data["findings"]} >= {
        "fast design, classical friction: peak1 grows with F_C (Table 2)",
        "the periodic orbit predicts the period, fast design"}
    assert all(f["holds"] is not False for f in data["findings"]), data["findings"]


def test_full_study_grids():
    """The full study: Tables 2-9 (fast/slow x classical/LuGre x F_C/F_S), grids
    around the preset's levels; the slow design's grids start lower."""
    st = ps.study("qube3")
    assert [t.number for t in st.tables] == [str(n) for n in range(2, 10)]
    pf = PRESET_FRICTION["qube3"]
    for t in st.tables:
        ((key, values),) = t.varies
        assert key == ("friction.coulomb" if int(t.number) % 2 == 0 else "friction.stiction")
        assert list(values) == sorted(values) and len(values) >= 7
        fixed = dict(t.setting.sets)
        if t.setting.design == "fast":
            assert fixed == {k: pf[k] for k in ("friction.stiction", "friction.coulomb")}
            assert pf[key] in values
        else:
            assert fixed["friction.coulomb"] < pf["friction.coulomb"] / 2
    assert {(t.setting.design, t.setting.friction) for t in st.tables} == {
        (d, f) for d in ("fast", "slow") for f in ("classical", "lugre")}
    assert st.figure_fc in st.compensator_levels
    # Table 2's preset F_C is Table 3's preset F_S (one run), likewise Tables 6 and 7
    assert ps.count_runs(st) == sum(len(t.varies[0][1]) for t in st.tables) - 2 + 5 * (
        len(st.compensator_levels) * 2 + 1)


def test_thesis_plant_is_not_a_motor_plant():
    with pytest.raises(ConfigValueError) as exc:
        ps.study("thesis")
    assert exc.value.field == "plant"


def test_unit_conversions():
    assert degrees(0.202) == pytest.approx(11.574, abs=1e-3)
    assert counts(0.202, 2048) == pytest.approx(65.84, abs=1e-2)
    assert degrees(None) is None and counts(None, 2048) is None


@pytest.mark.parametrize("args,message", [
    (["--plant", "bogus"], "--plant"),
    (["--plant", "qube2", "--workers", "0"], "--workers"),
])
def test_bad_options_exit_2(tmp_path, args, message):
    proc = run_cli_in_process(["reproduce", "--out", tmp_path / "r", *args])
    assert proc.returncode == 2
    assert message in proc.stderr
    assert not (tmp_path / "r").exists()  # nothing written
