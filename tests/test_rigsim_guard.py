"""The serving bound (``FRICTIONLAB_SERVE_LIMIT``, docs/development.md): ``rig-sim``,
``run --headless`` without ``--duration`` and the console, run in-process as a test
whose expected refusal went away would run them, end after the bound with exit
status 1 and a line saying so, and give the test's thread back its signal handlers,
scheduling policy and CPUs.  ``rig-sim --duration S`` serves S seconds and exits 0.
"""

from __future__ import annotations

import os
import signal
import sys
import time

import pytest

STOPS = (signal.SIGINT, signal.SIGTERM)


def _thread_state():
    tid = 0  # the calling thread (sched_* take a thread id on Linux)
    return (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority,
            os.sched_getaffinity(tid), {s: signal.getsignal(s) for s in STOPS})


@pytest.mark.slow  # the emulator's kernels loaded (seconds on a busy machine)
def test_rig_sim_in_process_stops_at_the_bound_and_restores_the_thread(cli):
    """At SCHED_FIFO where permitted, pinned to a CPU: both undone on the way out."""
    before = _thread_state()
    res = cli("rig-sim", "--port", "0", "--cpu", str(max(os.sched_getaffinity(0))),
              env={"FRICTIONLAB_SERVE_LIMIT": "0.3"})
    assert res.returncode == 1
    line = res.stderr.strip().splitlines()[-1]
    assert "stopped after 0.3 s, the serving bound FRICTIONLAB_SERVE_LIMIT" in line
    assert "listening on udp://127.0.0.1:" in res.stderr
    assert _thread_state() == before


@pytest.mark.slow
def test_rig_sim_duration_serves_then_exits_0_whatever_the_bound(cli):
    res = cli("rig-sim", "--port", "0", "--no-realtime", "--duration", "0.2",
              env={"FRICTIONLAB_SERVE_LIMIT": "0.01"})
    assert res.returncode == 0 and "serving bound" not in res.stderr
    res = cli("rig-sim", "--duration", "-1")
    assert res.returncode == 2 and "--duration must be > 0" in res.stderr


@pytest.mark.parametrize("value", ["abc", "0", "-5", "inf"])
def test_a_bad_bound_is_bad_input(cli, value):
    res = cli("rig-sim", "--port", "0", "--no-realtime", env={"FRICTIONLAB_SERVE_LIMIT": value})
    assert res.returncode == 2
    assert "FRICTIONLAB_SERVE_LIMIT" in res.stderr and len(res.stderr.splitlines()) == 1


@pytest.mark.slow  # the loop's start-up and a second of real time
def test_a_headless_run_without_duration_stops_at_the_bound_with_the_motor_zeroed(cli,
                                                                                  tmp_path):
    import json

    from frictionlab.io.logs import read_log

    # the sim backend's slack for a loaded host (docs/development.md): not a safety stop
    res = cli("run", "--headless", "--json", "--no-realtime", "--sim-lockstep",
              "--angle-limit", "1.2", "--log-dir", tmp_path,
              env={"FRICTIONLAB_SERVE_LIMIT": "1"})
    assert res.returncode == 1
    assert "stopped after 1 s, the serving bound FRICTIONLAB_SERVE_LIMIT" in res.stderr
    st = json.loads(res.stdout)
    assert st["stop_reason"] == "signal"  # stopped as a signal does
    if st["ticks"]:  # the stop's tick writes u = 0
        assert read_log(st["log"])["u"][-1] == 0.0
    else:  # the bound came before the first tick (a stalled host): no command at all
        assert st["log"] is None or not any(read_log(st["log"])["u"])


@pytest.mark.slow  # the controller built for the console
def test_the_console_stops_at_the_bound(cli, monkeypatch, tmp_path):
    """The bound ends the console as SIGTERM does (the console catches it and returns);
    a console that is not stopped by it would fail the test at its own deadline."""
    seen = {}

    class Console:  # serves until a stop signal, as frictionlab.console.serve does
        @staticmethod
        def serve(ctl, host, port, token):
            got = []
            previous = signal.signal(signal.SIGTERM, lambda s, f: got.append(s))
            try:
                end = time.monotonic() + 30.0
                while not got and time.monotonic() < end:
                    time.sleep(0.01)
            finally:
                signal.signal(signal.SIGTERM, previous)
            seen["signals"] = got

    monkeypatch.setitem(sys.modules, "frictionlab.console", Console)
    before = {s: signal.getsignal(s) for s in STOPS}
    res = cli("run", "--port", "0", "--no-realtime", "--log-dir", tmp_path,
              env={"FRICTIONLAB_SERVE_LIMIT": "0.2"})
    assert seen["signals"] == [signal.SIGTERM]
    assert res.returncode == 1 and "serving bound" in res.stderr
    assert {s: signal.getsignal(s) for s in STOPS} == before


def test_a_headless_run_waits_for_its_signals_at_a_low_real_time_priority():
    """The main thread of ``run --headless`` runs the stop signals' handler: it waits at
    SCHED_FIFO 5 where permitted (a loaded host woke it 15-30 ms late at normal
    priority, 3-6 ticks of motor), and gets its own policy back afterwards."""
    from frictionlab.cli.run import WAIT_PRIORITY, waiting_priority

    before = _thread_state()
    with waiting_priority(True):
        policy = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(WAIT_PRIORITY))
            permitted = True
        except PermissionError:
            permitted = False
    assert policy == ((os.SCHED_FIFO, WAIT_PRIORITY) if permitted else before[:2])
    assert _thread_state() == before
    with waiting_priority(False):  # --no-realtime: nothing changes
        assert _thread_state() == before
