"""``scripts/run``, the README's main job, end to end: it installs into the
repository's .venv and serves the console with the controller running until
a signal stops it.  ``scripts/test`` is the test suite itself (CI runs it);
its phases are tested here with a fake pytest: phase 1 at nice 19 beside phase
2, phase 3 after both, and Ctrl-C stopping the background phase and its
workers.  Both install through ``scripts/ensure-venv``: pip runs on a fresh
clone and when pyproject.toml changes, never on a start where nothing
changed."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_scripts_run_installs_and_serves_the_console(tmp_path):
    if Path(sys.prefix).resolve() != (ROOT / ".venv").resolve():
        # scripts/run (re)installs into ROOT/.venv: only from that environment (as
        # scripts/test and CI run the suite) does it not build a second one
        pytest.skip(f"the suite runs from {sys.prefix}, not {ROOT / '.venv'}")
    proc = subprocess.Popen(
        [str(ROOT / "scripts" / "run"), "--port", "0", "--sim-lockstep", "--angle-limit", "1.2",
         "--log-dir", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()  # after the install, the console's address
        m = re.search(r"frictionlab console: (http://127\.0\.0\.1:(\d+)/)", first)
        assert m, first + proc.stderr.read()
        end = time.monotonic() + 60
        status = {}
        while time.monotonic() < end:
            with urllib.request.urlopen(m.group(1) + "api/status", timeout=10) as resp:
                status = json.loads(resp.read())
            if status.get("running") and status.get("ticks", 0) >= 100:
                break
            time.sleep(0.1)
        assert status.get("running") and status["ticks"] >= 100, status
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0, stderr
    assert stdout.strip().splitlines()[-1].startswith("frictionlab console: stopped (signal")
    assert list(tmp_path.glob("run-*.csv"))


#: Stands in for .venv/bin/python: records pip calls, creates the entry point.
FAKE_PYTHON = """#!/usr/bin/env bash
here=$(cd "$(dirname "$0")" && pwd)
if [ "$1" = "-VV" ]; then echo "Python 3.11.7 (fake)"; exit 0; fi
if [ "$1 $2" = "-m pip" ]; then
  echo "pip $*" >> "$here/../../pip.log"
  [ -n "${FAIL_PIP:-}" ] && exit 1
  printf '#!/bin/sh\\n' > "$here/frictionlab"; chmod +x "$here/frictionlab"
  echo "Collecting numpy"; exit 0
fi
exit 0
"""


@pytest.fixture
def clone(tmp_path):
    """A copy of the scripts and pyproject.toml with a fake, existing .venv."""
    (tmp_path / "scripts").mkdir()
    shutil.copy(ROOT / "scripts" / "ensure-venv", tmp_path / "scripts")
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    bin_ = tmp_path / ".venv" / "bin"
    bin_.mkdir(parents=True)
    (bin_ / "python").write_text(FAKE_PYTHON)
    (bin_ / "python").chmod(0o755)
    return tmp_path


def _ensure(clone, *extras, **env):
    res = subprocess.run(["bash", str(clone / "scripts" / "ensure-venv"), *extras],
                         capture_output=True, text=True, timeout=60,
                         env={"PATH": "/usr/bin:/bin", **env})
    calls = (clone / "pip.log").read_text().splitlines() if (clone / "pip.log").exists() else []
    return res, [c for c in calls if "install" in c and "--upgrade" not in c]


def test_installs_once_then_only_when_pyproject_changes(clone):
    res, calls = _ensure(clone)
    assert res.returncode == 0, res.stderr
    assert len(calls) == 1 and calls[0].endswith("-e .")
    assert "installing . into .venv" in res.stderr and "Collecting numpy" in res.stderr
    res, calls = _ensure(clone)  # nothing changed: no pip, no output
    assert res.returncode == 0 and len(calls) == 1 and res.stderr == ""
    (clone / "pyproject.toml").write_text((clone / "pyproject.toml").read_text() + "\n# x\n")
    res, calls = _ensure(clone)
    assert len(calls) == 2
    res, calls = _ensure(clone, FRICTIONLAB_REINSTALL="1")
    assert len(calls) == 3


def test_dev_install_serves_the_base_one_but_not_the_reverse(clone):
    _ensure(clone)
    res, calls = _ensure(clone, "dev")  # the base install lacks the test extras
    assert len(calls) == 2 and calls[1].endswith("-e .[dev]")
    (clone / ".venv" / ".installed-base").unlink()
    res, calls = _ensure(clone)  # .[dev] includes everything scripts/run needs
    assert len(calls) == 2 and res.stderr == ""


def test_a_failed_install_is_not_recorded(clone):
    res, calls = _ensure(clone, FAIL_PIP="1")
    assert res.returncode != 0 and len(calls) == 1
    res, calls = _ensure(clone)
    assert res.returncode == 0 and len(calls) == 2


def test_run_and_test_use_it():
    for script in ("run", "test"):
        text = (ROOT / "scripts" / script).read_text()
        assert "scripts/ensure-venv" in text and "pip install" not in text


#: Stands in for .venv/bin/python under scripts/test: pip as FAKE_PYTHON; ``-m pytest``
#: records its phase, niceness, process group and session in phases.log, then behaves
#: as the test asks (environment): phase 2 ends once phase 1 has started, phase 1 once
#: phase 2 has ended (each waits up to 30 s: run one after the other, the order of the
#: log shows it), with a "worker" child; PHASE2_HANG / PHASE1_FAIL: a phase hangs, fails.
FAKE_PYTEST = r"""#!/usr/bin/env bash
here=$(cd "$(dirname "$0")" && pwd)
root=$here/../..
if [ "$1" = "-VV" ] || [ "$1 $2" = "-m pip" ]; then exec "$here/python-pip" "$@"; fi
case "$*" in
  *"not realtime"*) phase=1 ;;
  *"realtime and not alone"*) phase=2 ;;
  *alone*) phase=3 ;;
esac
read -r -a st < /proc/$$/stat   # pid (comm) state ppid pgrp session ... nice = field 19
echo "start $phase nice=${st[18]} pgrp=${st[4]} sid=${st[5]} pid=$$" >> "$root/phases.log"
if [ "$phase" = 1 ]; then
  touch "$root/phase1.started"
  sleep 300 & echo "worker $!" >> "$root/phases.log"
  for _ in $(seq 300); do [ -e "$root/phase2.done" ] && break; sleep 0.1; done
  kill $! 2>/dev/null
  echo "end 1" >> "$root/phases.log"
  [ -n "${PHASE1_FAIL:-}" ] && exit 1
  exit 0
fi
if [ "$phase" = 2 ]; then
  [ -n "${PHASE2_HANG:-}" ] && exec sleep 300
  for _ in $(seq 300); do [ -e "$root/phase1.started" ] && break; sleep 0.1; done
  touch "$root/phase2.done"
fi
echo "end $phase" >> "$root/phases.log"
"""

#: Records the arguments of ``nice`` before running the command with the real one.
FAKE_NICE = """#!/usr/bin/env bash
echo "nice $*" >> "$(dirname "$0")/../phases.log"
exec {real} "$@"
"""


@pytest.fixture
def test_clone(clone):
    """``clone`` with scripts/test, fake ruff/lint-imports and a fake pytest."""
    shutil.copy(ROOT / "scripts" / "test", clone / "scripts")
    bin_ = clone / ".venv" / "bin"
    (bin_ / "python").rename(bin_ / "python-pip")
    for name, text in (("python", FAKE_PYTEST), ("ruff", "#!/bin/sh\n"),
                       ("lint-imports", "#!/bin/sh\n")):
        (bin_ / name).write_text(text)
        (bin_ / name).chmod(0o755)
    (clone / "fakebin").mkdir()
    (clone / "fakebin" / "nice").write_text(FAKE_NICE.format(real=shutil.which("nice")))
    (clone / "fakebin" / "nice").chmod(0o755)
    return clone


def _scripts_test(clone, **env) -> subprocess.Popen:
    return subprocess.Popen(
        ["bash", str(clone / "scripts" / "test")], stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True,  # its own terminal group
        env={"PATH": f"{clone / 'fakebin'}:/usr/bin:/bin", **env})


def _log(clone) -> list[str]:
    return (clone / "phases.log").read_text().splitlines()


def _starts(clone) -> dict:
    out = {}
    for line in _log(clone):
        if line.startswith("start "):
            words = line.split()
            out[words[1]] = dict(w.split("=") for w in words[2:])
    return out


def test_scripts_test_runs_phase_1_at_nice_19_beside_phase_2_then_phase_3(test_clone):
    proc = _scripts_test(test_clone)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    log = _log(test_clone)
    # phase 1 through nice -n 19, and phase 2 ran (and ended) while phase 1 was waiting
    assert any(line.startswith("nice -n 19") and "not realtime" in line for line in log)
    order = [line.split()[0] + line.split()[1] for line in log
             if line.startswith(("start", "end"))]
    assert order.index("end2") < order.index("end1") < order.index("start3"), order
    assert order.index("start1") < order.index("end2")
    st = _starts(test_clone)
    base = os.getpriority(os.PRIO_PROCESS, 0)
    assert int(st["1"]["nice"]) == min(19, base + 19)
    assert int(st["2"]["nice"]) == base and int(st["3"]["nice"]) == base
    # a process group of its own (to be stopped with its workers), in the same session:
    # a new session would be a scheduling group of its own (autogroup), nice or not
    assert st["1"]["pgrp"] != st["2"]["pgrp"]
    assert st["1"]["sid"] == st["2"]["sid"] == str(proc.pid)
    assert "phase 1 done" in out and "its report follows" in out


def test_scripts_test_reports_a_failed_phase_1_and_still_runs_phase_3(test_clone):
    proc = _scripts_test(test_clone, PHASE1_FAIL="1")
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err
    assert "end 3" in _log(test_clone)


def _gone(pid: int, timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_ctrl_c_in_scripts_test_stops_the_background_phase_and_its_workers(test_clone):
    proc = _scripts_test(test_clone, PHASE2_HANG="1")
    try:
        end = time.monotonic() + 60
        while time.monotonic() < end and not ("1" in (st := _starts_or_none(test_clone))
                                               and "2" in st and _worker(test_clone)):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        st = _starts(test_clone)
        phase1, worker = int(st["1"]["pid"]), _worker(test_clone)
        os.killpg(proc.pid, signal.SIGINT)  # the terminal's Ctrl-C: its foreground group
        _out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    assert proc.returncode == 130, err
    assert _gone(phase1) and _gone(worker)
    assert "end 3" not in _log(test_clone) and "start 3" not in " ".join(_log(test_clone))


def _starts_or_none(clone) -> dict:
    return _starts(clone) if (clone / "phases.log").exists() else {}


def _worker(clone) -> int | None:
    if not (clone / "phases.log").exists():
        return None
    pids = [int(line.split()[1]) for line in _log(clone) if line.startswith("worker ")]
    return pids[0] if pids else None
