"""scripts/stress: the load it adds lasts exactly as long as the command it runs."""

import os
import re
import subprocess
from pathlib import Path

import pytest

STRESS = Path(__file__).resolve().parents[1] / "scripts" / "stress"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rpartition(")")[2].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.parametrize("command, status", [("true", 0), ("false", 1)])
def test_stress_runs_the_command_under_load_and_ends_the_load(command, status):
    res = subprocess.run([str(STRESS), "--cpus", "2", "--repeat", "3", command],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == status, res.stderr
    pids = [int(p) for p in re.search(r"busy process\(es\) on \d+ CPUs: ([\d ]+)",
                                      res.stderr).group(1).split()]
    assert len(pids) == 2 and not any(_alive(p) for p in pids)
    runs = re.findall(r"stress: run (\d)/3 exit (\d+)", res.stderr)
    # every run while it passes; the first failure ends the series
    assert runs == ([("1", "0"), ("2", "0"), ("3", "0")] if status == 0 else [("1", "1")])


def test_stress_the_command_sees_the_busy_processes():
    res = subprocess.run([str(STRESS), "--cpus", "1", "bash", "-c",
                          "ps -o args= --ppid $PPID"], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    assert "while :; do :; done" in res.stdout
    assert os.access(STRESS, os.X_OK)


def test_stress_without_a_command_is_a_usage_error():
    res = subprocess.run([str(STRESS)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "usage" in res.stderr
