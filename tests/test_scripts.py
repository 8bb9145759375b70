"""``scripts/run``, the README's main job, end to end: it installs into the
repository's .venv and serves the console with the controller running until
a signal stops it.  (``scripts/test`` is the test suite itself: CI runs it.)
Both install through ``scripts/ensure-venv``: pip runs on a fresh clone and
when pyproject.toml changes, never on a start where nothing changed."""

from __future__ import annotations

import json
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
if [ "$1 $2" = "-m compileall" ]; then echo "compileall $*" >> "$here/../../pip.log"; exit 0; fi
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
    # pip installs without byte-compiling; compileall compiles on every CPU after it
    log = (clone / "pip.log").read_text().splitlines()
    assert "--no-compile" in calls[0].split()
    assert "-j 0" in log[log.index(calls[0]) + 1] and log[log.index(calls[0]) + 1].startswith(
        "compileall")
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
