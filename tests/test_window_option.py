"""``--window`` longer than the run it analyses is refused on every command that takes
it: exit status 2, one line naming both values, before any work."""

from __future__ import annotations

from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.parametrize("args, duration", [
    (["simulate", "--duration", "2"], "--duration 2 s"),
    (["simulate", "--set", "sim.duration=2"], "sim.duration 2 s"),
    (["simulate", "--swing-up", "--duration", "2"], "--duration 2 s"),
    (["sweep", "--vary", "friction.coulomb=1,2", "--duration", "2", "--out", "{tmp}/s.csv"],
     "--duration 2 s"),
    (["sweep", "--vary", "sim.duration=2,4", "--out", "{tmp}/s.csv"],
     "--vary sim.duration, shortest 2 s"),
    (["compensate", "compare", "--duration", "2"], "--duration 2 s"),
    (["compensate", "tune", "--duration", "2"], "--duration 2 s"),
    (["identify", "limit-cycle", "--measured", str(EXAMPLES / "table1.json"), "--fit",
      "friction.coulomb", "--duration", "2"], "--duration 2 s"),
])
def test_a_window_longer_than_the_run_is_refused(cli, tmp_path, args, duration):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    res = cli(*args, "--window", "3", "--json")
    assert res.returncode == 2 and res.stdout == ""
    line, = res.stderr.strip().splitlines()
    assert "--window 3 s is longer than the run" in line and duration in line
    assert not list(tmp_path.iterdir())  # refused before any output


def test_a_window_within_the_run_is_accepted(cli):
    res = cli("simulate", "--duration", "2", "--window", "2", "--json")
    assert res.returncode == 0, res.stderr


def test_features_refuses_a_window_longer_than_the_log(cli, tmp_path):
    log = tmp_path / "run.csv"
    assert cli("simulate", "--duration", "2", "--save", str(log), "--json").returncode == 0
    res = cli("features", str(log), "--design", "fast", "--window", "5", "--json")
    assert res.returncode == 2 and res.stdout == ""
    line, = res.stderr.strip().splitlines()
    assert "--window 5 s is longer than the run" in line and str(log) in line
    assert cli("features", str(log), "--design", "fast", "--window", "1",
               "--json").returncode == 0
