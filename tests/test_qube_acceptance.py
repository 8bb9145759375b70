"""Acceptance of the QUBE-Servo backend against the emulated board (docs/qube.md).

``frictionlab run --backend qube2://0 --swing-up --headless --duration 12 --json``
in a real process, the emulated ``quanser.hardware`` (tests/fake_quanser: an
independent QUBE-Servo 2 model keeping its own time, its watchdog, a record of
every call) first on its ``PYTHONPATH``:

* it swings up and balances (|theta| < 0.2 rad over the last 3 s), keeping
  the safe sequence on the motor (qube_helpers.check_safe_sequence);
* SIGINT while balancing: no non-zero voltage after the two writes following
  the signal, stop reason ``signal``, the board closed within 1 s;
* an amplifier fault: the run stops, nothing but 0 V from the tick that reads it;
* the process stopped (SIGSTOP) for 0.6 s: the board's watchdog zeroes the
  motor while it is stopped, and after SIGCONT the controller stops within
  2 s without enabling the amplifier again.

Every run uses the QUBE-Servo 2 plant's own controller and swing-up within 10 V
(``--plant qube2``, which ``qube2://`` implies): the swing-up run from hanging;
the others from a start by hand (``?wait=upright`` and the emulated operator
lifting the pendulum, ``lift_at``).
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from qube_helpers import (
    FAKE,
    calls_of,
    check_safe_sequence,
    index,
    load_fake,
    read_record,
    unload_fake,
    voltages,
)

#: The operator lifts the pendulum this long after the board opens (board time, s).
LIFT_AT = 0.3
#: Slack for a loaded machine where the stop itself is not under test (docs/development.md):
#: the board's watchdog and the loop's pause limit at half a second.
SLACK = ["--max-pause", "0.5", "--silent-periods", "100"]


def start(tmp_path: Path, backend: str, duration: float, *extra: str, faults=None,
          swing_up: bool = True):
    """``frictionlab run --backend ... --headless --json`` in a process of its own (the
    ``qube2`` plant): with the swing-up, or started by hand (``?wait=upright`` and the
    emulated hand's ``lift_at``)."""
    if not swing_up:
        faults = {"lift_at": LIFT_AT, **(faults or {})}
        backend += "&wait=upright" if "?" in backend else "?wait=upright"
        # slack for a stalled host, the angle limit not being under test (a 0.3 s stall
        # with the plant moving on threw the 0.1 rad cycle past 0.35 rad at a load of 18)
        extra = ("--angle-limit", "1.2", *extra)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([FAKE, *filter(None, [env.get("PYTHONPATH")])])
    env["FAKE_QUANSER_LOG"] = str(tmp_path / "board.jsonl")
    env.pop("FAKE_QUANSER_STATE", None)
    if faults:
        env["FAKE_QUANSER_FAULTS"] = json.dumps(faults)
    else:
        env.pop("FAKE_QUANSER_FAULTS", None)
    how = ["--swing-up"] if swing_up else []
    cmd = [sys.executable, "-m", "frictionlab", "run", "--backend", backend, *how,
           "--headless", "--duration", str(duration), "--json", "--log-dir",
           str(tmp_path / "logs"), *extra]
    return subprocess.Popen(cmd, env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, process_group=0)


def log_rows(tmp_path: Path) -> list[dict]:
    files = sorted((tmp_path / "logs").glob("run-*.csv"))
    if not files:
        return []
    with open(files[0], newline="") as fh:
        return list(csv.DictReader(fh))


def thetas(rows) -> list[tuple[float, float]]:
    return [(float(r["t"]), float(r["theta_m"])) for r in rows
            if r["theta_m"] not in ("", "nan")]


#: Stop reasons a stalled host (not the backend) causes before the test's own event.
LOAD_STOPS = ("paused", "rig_silent", "watchdog_expired")


class HostStalled(Exception):
    """The run stopped on a stalled host before the test could act (run it again)."""


class TimingMiss(HostStalled):
    """A timing statistic a loaded host missed (the signal's handler ran late): the
    one kind of assertion that may be retried (docs/development.md)."""


def wait_balancing(tmp_path: Path, proc, timeout: float = 60.0) -> None:
    """Until the log shows the pendulum within 0.2 rad of upright for 1 s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        th = thetas(log_rows(tmp_path))
        if len(th) > 200 and all(abs(math.remainder(v, 2 * math.pi)) < 0.2
                                 for _t, v in th[-200:]):
            return
        if proc.poll() is not None:
            out, err = proc.communicate()
            reason = json.loads(out).get("stop_reason") if out.strip() else None
            if reason in LOAD_STOPS:
                raise HostStalled(reason)
            raise AssertionError(f"the run ended before balancing ({reason}): {err}")
        time.sleep(0.05)
    raise AssertionError("not balancing in time")


def with_retries(test, tmp_path: Path, attempts: int = 3):
    """Run ``test(folder)``; a run a stalled host stopped before the test's event
    (:data:`LOAD_STOPS`) is run again in a fresh folder, with a warning, at most
    twice (docs/development.md, "A busy machine")."""
    for n in range(attempts):
        folder = tmp_path / f"try{n}"
        folder.mkdir()
        try:
            return test(folder)
        except HostStalled as exc:
            if n == attempts - 1:
                raise AssertionError(f"a stalled host stopped every attempt: {exc}") from None
            warnings.warn(f"a stalled host stopped the run ({exc}), run again", stacklevel=2)


def finish(proc, timeout: float = 30.0) -> dict:
    out, err = proc.communicate(timeout=timeout)
    assert out.strip(), err
    return json.loads(out)


@pytest.mark.slow
@pytest.mark.realtime
def test_swings_up_and_balances_on_the_emulated_qube(tmp_path):
    def attempt(folder):
        st = finish(start(folder, "qube2://0?watchdog=0.5", 12, *SLACK), timeout=120)
        if st["stop_reason"] in LOAD_STOPS:
            raise HostStalled(st["stop_reason"])
        return folder, st

    tmp_path, st = with_retries(attempt, tmp_path)
    assert st["stop_reason"] == "duration", st
    assert st["swing_up"]["phase"] == "balancing"
    th = thetas(log_rows(tmp_path))
    t_end = th[-1][0]
    last = [abs(math.remainder(v, 2 * math.pi)) for t, v in th if t >= t_end - 3.0]
    assert len(last) > 500 and max(last) < 0.2
    calls = read_record(tmp_path / "board.jsonl")
    check_safe_sequence(calls)
    assert any(abs(v) > 5.0 for _i, _m, v in voltages(calls))  # it did drive the motor


@pytest.mark.slow
@pytest.mark.realtime
def test_sigint_while_balancing_zeroes_the_motor_and_closes_the_board(tmp_path):
    def attempt(folder):
        proc = start(folder, "qube2://0?watchdog=0.5", 60, *SLACK, swing_up=False)
        wait_balancing(folder, proc)
        t_sig = time.monotonic()
        os.kill(proc.pid, signal.SIGINT)
        st = finish(proc)
        assert st["stop_reason"] == "signal"
        calls = read_record(folder / "board.jsonl")
        check_safe_sequence(calls)
        assert any(v != 0.0 for _i, m, v in voltages(calls) if m < t_sig)
        after = [v for _i, m, v in voltages(calls) if m > t_sig]
        assert after and after[-1] == 0.0
        closed = next(m for _t, m, n, _a in calls if n == "close")
        # timing: the handler runs in the main thread, which a loaded host may
        # schedule late (the loop ticks on meanwhile): measured, retried
        if any(v != 0.0 for v in after[2:]) or not closed - t_sig < 1.0:
            raise TimingMiss(f"writes after the signal {after[:8]}, closed after "
                             f"{closed - t_sig:.3f} s")

    with_retries(attempt, tmp_path)


@pytest.mark.slow
@pytest.mark.realtime
def test_sigstop_the_board_watchdog_zeroes_the_motor(tmp_path):
    """Stopped for 0.6 s: the board's watchdog (0.2 s here) expires while the process
    cannot run; after SIGCONT the run stops within 2 s, never enabling again."""
    def attempt(folder):
        proc = start(folder, "qube2://0?watchdog=0.2", 60, "--max-pause", "0.15",
                     "--silent-periods", "30", swing_up=False)
        wait_balancing(folder, proc)
        t_stop = time.monotonic()
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(0.6)
        t_cont = time.monotonic()
        os.kill(proc.pid, signal.SIGCONT)
        return folder, t_stop, t_cont, finish(proc)

    tmp_path, t_stop, t_cont, st = with_retries(attempt, tmp_path)
    assert st["stop_reason"] in ("paused", "watchdog_expired"), st
    calls = read_record(tmp_path / "board.jsonl")
    expired = index(calls, "event", lambda a: a[0] == "watchdog_expired")
    assert expired is not None
    t_exp = calls[expired][1]
    assert t_stop < t_exp < t_cont  # the board's own time, while the process was stopped
    assert calls[expired][3][1] == {"voltage": 0.0, "enabled": False}
    assert index(calls[expired:], "write_digital", lambda a: a[1][0] == 1) is None
    closed = next(m for _t, m, n, _a in calls if n == "close")
    assert closed - t_cont < 2.0
    check_safe_sequence(calls)


@pytest.mark.slow
def test_an_amplifier_fault_while_the_qube2_controller_balances_stops_the_run(tmp_path,
                                                                              monkeypatch):
    """In-process on a fake clock (the board's time too): the QUBE-Servo 2 plant's own
    controller (``qube2://`` implies ``--plant qube2``), started by hand (the pendulum
    lifted at 0.3 s), balances within 10 V; the fault at 6 s stops the run, nothing
    but 0 V from the tick that reads it."""
    from frictionlab.cli.common import plant_from_args
    from frictionlab.config import build_config
    from frictionlab.realtime import FakeClock, RealtimeController
    from frictionlab.realtime.qube import QUBE_RIG

    what = "amplifier_fault"
    monkeypatch.setenv("FAKE_QUANSER_FAULTS", json.dumps({"lift_at": LIFT_AT,
                                                          f"{what}_at": 6.0}))
    monkeypatch.delenv("FAKE_QUANSER_LOG", raising=False)
    monkeypatch.delenv("FAKE_QUANSER_STATE", raising=False)
    clock = FakeClock()
    monkeypatch.setattr("frictionlab.realtime.qube.time.sleep",
                        lambda s: clock.advance(round(s * 1e9)))
    hw = load_fake(clock)
    backend = "qube2://0?wait=upright"
    plant = plant_from_args(type("Args", (), {"plant": None, "backend": backend})())
    try:
        cfg = build_config(plant=plant, sets=list(QUBE_RIG.items()))
        ctl = RealtimeController(cfg, backend, log_dir=tmp_path, clock=clock, realtime=False,
                                 duration=6.2)
        st = ctl.run()
        board = hw.BOARDS[-1]
    finally:
        unload_fake()
    assert plant == "qube2" and cfg.u_limit == 10.0
    assert st["stop_reason"] == what, st
    calls = calls_of(board)
    t_fault = next(c[0] for c in calls if c[2] == "event" and c[3][0] == what)
    volts = voltages(calls)
    # balancing in its friction limit cycle before the fault: within 0.2 rad, |V| < 10
    th = thetas(log_rows_in(tmp_path))
    assert max(abs(v) for t, v in th if 2.0 <= t < 6.0) < 0.2
    assert 0.1 < max(abs(v) for _i, m, v in volts if m < t_fault) < 10.0
    assert all(v == 0.0 for _i, m, v in volts if m >= t_fault)
    writes_after = [m for _i, m, _v in volts if m >= t_fault]
    assert writes_after and writes_after[0] - t_fault <= 0.005 + 1e-9  # the next tick
    check_safe_sequence(calls)
    # the LED: blue (open, waiting), green (balancing), red (the board's fault)
    leds = [tuple(c[3][1]) for c in calls if c[2] == "write_other"]
    assert leds[0] == (0.0, 0.0, 1.0) and leds[-1] == (1.0, 0.0, 0.0)
    assert (0.0, 1.0, 0.0) in leds


def log_rows_in(folder: Path) -> list[dict]:
    """The run log's rows of a run logged straight into ``folder``."""
    files = sorted(folder.glob("run-*.csv"))
    with open(files[0], newline="") as fh:
        return list(csv.DictReader(fh))
