"""``frictionlab run`` / ``rig-sim`` end to end, in real time (a few short runs).

These are the tests that cannot use a fake clock: a 10 s headless run on the
``sim`` backend compared with ``frictionlab simulate``, SIGKILL of a run
against ``rig-sim`` over UDP (the log on disk must hold all but the last
100 ms), and SIGINT/SIGTERM, headless and in console mode.  They assert on
what was logged and on the rig's state, never on wall-clock timings.
"""

import json
import re
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from frictionlab.cli import main
from frictionlab.config import build_config
from frictionlab.io.logs import read_log
from frictionlab.model.limit_cycles import FEATURES, features
from frictionlab.realtime.datalog import read_sidecar
from frictionlab.realtime.rigsim import send_control
from frictionlab.realtime.samples import MISSED, STOP

RUN_JSON_KEYS = {"ticks", "missed", "overruns", "jitter_ms", "compute_us", "stop_reason", "log"}
CLI = [sys.executable, "-m", "frictionlab"]


@pytest.fixture(scope="module")
def rig_sim():
    """A ``frictionlab rig-sim`` process on a free UDP port."""
    proc = subprocess.Popen([*CLI, "rig-sim", "--port", "0", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        info = json.loads(line)
        yield info["host"], info["port"]
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(10)


def wait_for(pred, timeout=60.0, proc=None):
    """The first true value of ``pred()``, polled; fails at once if ``proc`` ended."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            value = pred()
        except OSError:  # a server not answering yet
            value = None
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the process ended (status {proc.returncode}) while "
                                 f"waiting: {proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.02)
    raise AssertionError("timed out waiting")


def logged_rows(csv: Path) -> int:
    try:
        return csv.read_bytes().count(b"\n") - 1
    except OSError:
        return 0


def wait_running(log_dir: Path, proc, rows: int = 100):
    """(csv, sidecar) of the run once ``rows`` ticks are in its log: it is controlling
    (a condition, not a sleep: a busy machine takes as long as it takes)."""
    csv, meta = wait_for(lambda: started_log(log_dir), proc=proc)
    wait_for(lambda: logged_rows(csv) >= rows, proc=proc)
    return csv, meta


def popen(args, **kw):
    """``frictionlab ARGS`` in its own process group (a signal meant for it reaches
    nothing else; its Ctrl-Z suspends it wherever the test runs), pipes as text."""
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.Popen([*CLI, *args], text=True, process_group=0, **kw)


def started_log(log_dir: Path):
    """The run's CSV once its loop has started (the sidecar names t0)."""
    for js in log_dir.glob("run-*.json"):
        try:
            meta = json.loads(js.read_text())
        except (OSError, ValueError):
            continue
        if meta.get("t0_monotonic_ns"):
            return Path(meta["files"]["csv"]), meta
    return None


@pytest.mark.slow
def test_headless_sim_run_balances_in_the_limit_cycle_simulate_predicts(tmp_path):
    # lockstep: a pause of this shared machine pauses the simulated plant too (in the
    # default mode it would act as a disturbance and change the cycle)
    out = subprocess.run([*CLI, "run", "--headless", "--duration", "10", "--json",
                          "--sim-lockstep", "--log-dir", str(tmp_path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    st = json.loads(out.stdout)
    assert set(st) == RUN_JSON_KEYS
    assert set(st["jitter_ms"]) == {"p50", "p99", "max"} and set(st["compute_us"]) == {
        "p50", "p99"}
    # lockstep: the ticks cover the 10 s of simulated time, stalls only count as missed
    assert st["stop_reason"] == "duration" and st["ticks"] == 2000 and st["missed"] >= 0
    log = read_log(st["log"], partial=True)
    assert int(log["flags"][-1]) & STOP
    rows = slice(0, -1)
    t, theta = log["t"][rows], log["theta_m"][rows]
    assert np.all(np.abs(theta) < 0.35)
    rt = features(t, theta, log["u"][rows], log["arm_dot_m"][rows], window=5.0)
    from frictionlab.cli import simulate_result

    _traj, sim, status = simulate_result(build_config("fast", "classical"), 10.0, 5.0)
    assert status == rt.status == "limit_cycle"
    for name in FEATURES:
        a, b = getattr(rt, name), getattr(sim, name)
        assert a == pytest.approx(b, rel=0.10), name
    meta = json.loads(Path(st["log"]).with_suffix(".json").read_text())
    assert meta["stop_reason"] == "duration" and meta["dropped_log_samples"] == 0
    assert meta["stats"]["ticks"] == st["ticks"]


@pytest.mark.slow
def test_sigkill_loses_at_most_the_last_100_ms(tmp_path, rig_sim):
    host, port = rig_sim
    # a wide angle limit: a pause of this shared machine must not end the run early
    proc = popen(["run", "--headless", "--duration", "60", "--backend",
                  f"udp://{host}:{port}", "--angle-limit", "1.2", "--silent-periods", "100",
                  "--max-pause", "0.5", "--log-dir", str(tmp_path)],
                 stdout=subprocess.DEVNULL)
    try:
        csv, _meta = wait_running(tmp_path, proc, rows=300)
        assert proc.poll() is None, proc.stderr.read()
        proc.kill()
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    # the last tick the controller executed is the last command the rig received
    rig = send_control(host, port, {"cmd": "status"})
    last = rig["last_command_seq"]
    assert last >= 200  # it was running
    log = read_log(csv, partial=True)
    ticks = log["tick"].astype(int)
    flags = log["flags"].astype(int)
    assert ticks[0] == 0 and np.all(np.diff(ticks) >= 1)
    # no row missing before the end: every gap is a flagged skip-ahead after a stall
    gaps = np.nonzero(np.diff(ticks) > 1)[0]
    assert all(flags[i + 1] & MISSED for i in gaps)
    assert ticks[-1] >= last - 20, f"log ends at tick {ticks[-1]}, rig saw {last}"
    dat = [ln for ln in csv.with_suffix(".dat").read_text().splitlines(keepends=True)
           if ln.endswith("\n")]
    assert len(dat) >= len(ticks) - 1 and all(len(ln.split()) == 10 for ln in dat)
    assert json.loads(csv.with_suffix(".json").read_text())["running"] is True
    # ... and a reader can tell that the run did not finish
    assert read_sidecar(csv.with_suffix(".json"))["state"] == "interrupted"
    # and the rig's own watchdog zeroes the motor
    rig = wait_for(lambda: (r := send_control(host, port, {"cmd": "status"}))[
        "watchdog_tripped"] and r)
    assert rig["u_da"] == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP,
                                 signal.SIGQUIT])
def test_sigint_and_sigterm_stop_the_motor_and_report(tmp_path, rig_sim, sig):
    host, port = rig_sim
    proc = popen(["run", "--headless", "--duration", "60", "--json", "--backend",
                  f"udp://{host}:{port}", "--angle-limit", "1.2", "--silent-periods", "100",
                  "--max-pause", "0.5", "--log-dir", str(tmp_path)])
    try:
        wait_running(tmp_path, proc)
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    st = json.loads(stdout)
    assert set(st) == RUN_JSON_KEYS and st["stop_reason"] == "signal"
    log = read_log(st["log"], partial=True)
    assert int(log["flags"][-1]) & STOP and log["u_da"][-1] == 0.0
    meta = json.loads(Path(st["log"]).with_suffix(".json").read_text())
    assert meta["stop_reason"] == "signal" and not meta["running"]
    assert meta["stop_detail"] == signal.Signals(sig).name
    rig = send_control(host, port, {"cmd": "status"})
    assert rig["u_da"] == 0.0 and rig["last_command_seq"] == meta["stop_tick"]


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_console_mode_stops_on_a_signal(tmp_path, sig):
    # console mode (no --headless) on a free port; lockstep and a wide angle limit: a pause
    # of this shared machine must not end the run before the signal does
    proc = popen(["run", "--port", "0", "--sim-lockstep", "--angle-limit", "1.2",
                  "--log-dir", str(tmp_path)])
    try:
        first = proc.stdout.readline()
        m = re.search(r"frictionlab console: (http://127\.0\.0\.1:(\d+)/)", first)
        assert m and int(m.group(2)) > 0, first + proc.stderr.read()

        def ticking():
            with urllib.request.urlopen(m.group(1) + "api/status", timeout=10) as resp:
                st = json.loads(resp.read())
            return st["running"] and st["ticks"] >= 100

        wait_for(ticking, proc=proc)
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0, stderr
    closing = stdout.strip().splitlines()[-1]
    assert closing.startswith("frictionlab console: stopped (signal; "), closing
    csv, _ = started_log(tmp_path)
    assert f"log {csv}" in closing
    meta = json.loads(csv.with_suffix(".json").read_text())
    assert meta["stop_reason"] == "signal" and not meta["running"]
    log = read_log(csv, partial=True)
    assert int(log["flags"][-1]) & STOP and log["u_da"][-1] == 0.0
    assert int(log["tick"][-1]) == meta["stop_tick"] >= 100
    assert not np.any(log["flags"][:-1].astype(int) & STOP)
    assert meta["stop_detail"] == signal.Signals(sig).name


def test_the_console_s_signal_handler_stops_the_loop_itself():
    """A signal zeroes the motor at the loop's next tick, as Exit does, instead of after
    the server's shutdown (100-200 ms later)."""
    import uvicorn

    from frictionlab.console.server import _Server

    stops = []

    class Controller:
        def stop(self, reason="user", detail=None):
            stops.append((reason, detail, server.should_exit))

    server = _Server(uvicorn.Config(lambda scope, receive, send: None))
    server.controller = Controller()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
        server.should_exit = False
        server._on_signal(sig, None)
        assert server.should_exit and server.signalled
    assert stops == [("signal", name, False) for name in
                                ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")]


@pytest.mark.parametrize("argv, message", [
    (["run", "--headless", "--duration", "-1"], "--duration"),
    (["run", "--headless", "--backend", "tcp://x:1"], "backend"),
    (["run", "--headless", "--set", "design.omega1=-3"], "design.omega1"),
    (["run", "--headless", "--angle-limit", "0"], "angle-limit"),
    (["run", "--headless", "--silent-periods", "0"], "--silent-periods = 0"),
    (["run", "--headless", "--max-pause", "-1"], "--max-pause = -1"),
    (["rig-sim", "--fault", "meteor=1"], "--fault"),
    (["run", "--json"], "--json needs --headless"),
    (["run", "--duration", "1", "--json"], "--json needs --headless"),
])
def test_bad_input_exits_2_with_a_message(argv, message, cli, tmp_path):
    # in-process with its serving bound: were a refusal gone, the test fails, not serves
    res = cli(*([*argv, "--log-dir", str(tmp_path)] if argv[0] == "run" else argv))
    err = res.stderr
    assert res.returncode == 2 and message in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow  # waits for the handshake's timeout
def test_unreachable_rig_exits_1(tmp_path, capsys):
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code = main(["run", "--headless", "--duration", "1", "--backend",
                 f"udp://127.0.0.1:{port}", "--log-dir", str(tmp_path)])
    assert code == 1
    assert "no answer from the rig" in capsys.readouterr().err


def test_run_without_headless_hands_over_to_the_console(monkeypatch, tmp_path):
    from frictionlab.cli import run as realtime_cli

    served = {}

    class FakeConsole:
        @staticmethod
        def serve(ctl, host, port, token):
            served.update(ctl=ctl, host=host, port=port, token=token)

    monkeypatch.setitem(sys.modules, "frictionlab.console", FakeConsole)
    token = "x" * 32
    assert main(["run", "--port", "8123", "--token", token, "--log-dir", str(tmp_path)]) == 0
    assert served == {"ctl": served["ctl"], "host": "127.0.0.1", "port": 8123, "token": token}
    assert served["ctl"].backend_name == "sim" and not served["ctl"].running
    # the hook reports a missing console instead of serving
    monkeypatch.setitem(sys.modules, "frictionlab.console", None)
    assert realtime_cli.start_console(served["ctl"], "127.0.0.1", 0) is False


def _proc_state(pid: int) -> str:
    with open(f"/proc/{pid}/stat") as fh:
        return fh.read().rpartition(")")[2].split()[0]


@pytest.mark.slow
def test_a_signal_during_the_handshake_ends_the_run_with_only_a_zero_command(tmp_path):
    """SIGINT while the controller waits for the rig's HELLO_ACK (a rig still booting)."""
    import threading

    from frictionlab.realtime import protocol as P
    from frictionlab.realtime.clock import MonotonicClock
    from frictionlab.realtime.rigsim import RigEmulator, serve_udp

    class Watching(RigEmulator):
        def handle_frame(self, frame):
            if isinstance(frame, P.Frame):
                self.seen.append(frame.type)
                if frame.type == P.MSG_COMMAND:
                    self.commands.append(P.parse_command(frame))
            return super().handle_frame(frame)

    emu = Watching(build_config("fast", "classical"), MonotonicClock())
    emu.seen, emu.commands = [], []
    emu.control({"cmd": "fault", "silent": -1})  # not answering yet
    stop, addr = threading.Event(), []
    server = threading.Thread(target=serve_udp, args=(emu, "127.0.0.1", 0, stop),
                              kwargs={"ready": addr.append, "prewarm_us": 0}, daemon=True)
    server.start()
    try:
        wait_for(lambda: addr)
        proc = popen(["run", "--headless", "--json", "--duration", "30", "--backend",
                      f"udp://127.0.0.1:{addr[0][1]}", "--log-dir", str(tmp_path)])
        try:
            # the controller waits for HELLO_ACK
            wait_for(lambda: P.MSG_HELLO in emu.seen, proc=proc)
            proc.send_signal(signal.SIGINT)
            emu.control({"cmd": "clear"})  # and the rig answers from now on
            stdout, stderr = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
    finally:
        stop.set()
        server.join(10)
    assert proc.returncode == 0, stderr
    st = json.loads(stdout)
    assert st["stop_reason"] == "signal" and st["ticks"] == 0
    # the rig was never sampled and never got anything but u = 0
    assert P.MSG_SAMPLE not in emu.seen
    assert emu.commands and set(emu.commands) == {0.0}
    meta = json.loads(Path(st["log"]).with_suffix(".json").read_text())
    assert meta["stop_reason"] == "signal" and meta["stop_detail"] == "SIGINT"


@pytest.mark.slow
def test_ctrl_z_stops_the_run_then_suspends(tmp_path, rig_sim):
    host, port = rig_sim
    proc = popen(["run", "--headless", "--duration", "60", "--json", "--backend",
                  f"udp://{host}:{port}", "--angle-limit", "1.2", "--silent-periods", "100",
                  "--max-pause", "0.5", "--log-dir", str(tmp_path)])
    try:
        csv, _ = wait_running(tmp_path, proc)
        proc.send_signal(signal.SIGTSTP)
        wait_for(lambda: _proc_state(proc.pid) == "T", proc=proc)
        # suspended after the run was stopped: the motor at zero, the final sidecar written
        meta = json.loads(csv.with_suffix(".json").read_text())
        assert (meta["stop_reason"], meta["stop_detail"], meta["running"]) == (
            "signal", "SIGTSTP", False)
        rig = send_control(host, port, {"cmd": "status"})
        assert rig["u_da"] == 0.0 and rig["last_command_seq"] == meta["stop_tick"]
        proc.send_signal(signal.SIGCONT)  # fg: it reports and exits
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0, stderr
    assert json.loads(stdout)["stop_reason"] == "signal"


@pytest.mark.slow
def test_a_suspended_controller_stops_on_resume_without_acting(tmp_path, rig_sim):
    """SIGSTOP (not catchable) for 300 ms: the rig's watchdog zeroes the motor meanwhile,
    and on SIGCONT the loop stops (reason paused) without acting on its stale state."""
    host, port = rig_sim
    proc = popen(["run", "--headless", "--duration", "60", "--json", "--backend",
                  f"udp://{host}:{port}", "--angle-limit", "1.2", "--silent-periods", "40",
                  "--max-pause", "0.15", "--log-dir", str(tmp_path)])
    try:
        csv, meta = wait_running(tmp_path, proc)
        proc.send_signal(signal.SIGSTOP)
        wait_for(lambda: _proc_state(proc.pid) == "T", proc=proc)
        t_stopped = time.monotonic_ns()  # it is suspended by now
        # the rig's watchdog zeroes the motor meanwhile (at least 300 ms suspended)
        rig = wait_for(lambda: (r := send_control(host, port, {"cmd": "status"}))[
            "watchdog_tripped"] and r)
        assert rig["u_da"] == 0.0
        while time.monotonic_ns() < t_stopped + 300_000_000:
            time.sleep(0.01)
        t_cont = time.monotonic_ns()  # it is still suspended now
        proc.send_signal(signal.SIGCONT)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 1, stderr
    st = json.loads(stdout)
    assert st["stop_reason"] == "paused" and "paused" in stderr
    log = read_log(csv, partial=True)
    t0, h = meta["t0_monotonic_ns"], 5_000_000
    # every tick that acted came before the suspension; the first one after it stopped
    assert t0 + int(log["tick"][-2]) * h < t_stopped
    # the stop is the first tick after the gap, or the tick the suspension interrupted
    # while it waited for the rig's reply (docs/realtime.md, the safety table)
    last = t0 + int(log["tick"][-1]) * h
    assert last > t_cont - h or last < t_stopped
    assert int(log["flags"][-1]) & STOP and log["u_da"][-1] == 0.0
    rig = send_control(host, port, {"cmd": "status"})
    assert rig["u_da"] == 0.0 and rig["last_command_seq"] == int(log["tick"][-1])


@pytest.mark.slow
def test_a_log_that_cannot_be_written_stops_the_run(tmp_path, rig_sim):
    """A file-size limit (ulimit -f) makes the log writes fail, as a full disk does."""
    import resource

    def limit():
        # about 280 rows of CSV (1.4 s): the run lasts no longer than the test needs
        resource.setrlimit(resource.RLIMIT_FSIZE, (40_000, 40_000))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # numba's cache writes too

    host, port = rig_sim
    proc = subprocess.run([*CLI, "run", "--headless", "--duration", "60", "--json",
                           "--backend", f"udp://{host}:{port}", "--angle-limit", "1.2",
                           # a rig silent for 0.5 s (a stalled host) tolerated, as a pause
                           "--silent-periods", "100", "--max-pause", "0.5",
                           "--log-dir", str(tmp_path)],
                          capture_output=True, text=True, timeout=120, preexec_fn=limit)
    assert proc.returncode == 1, proc.stderr
    st = json.loads(proc.stdout)
    assert st["stop_reason"] == "log_failed" and st["ticks"] < 12_000
    assert "the log could not be written" in proc.stderr and "File too large" in proc.stderr
    csv = Path(st["log"])
    dat = csv.with_suffix(".dat").read_text()
    assert csv.read_text().endswith("\n") and dat.endswith("\n")
    rows = read_log(csv, partial=True)
    assert len(rows["tick"]) == len(dat.splitlines()) > 100
    meta = read_sidecar(csv.with_suffix(".json"))
    assert meta["state"] == "finished" and meta["stop_reason"] == "log_failed"
    rig = send_control(host, port, {"cmd": "status"})
    assert rig["u_da"] == 0.0 and rig["last_command_seq"] == meta["stop_tick"]


def test_run_s_signal_handling_before_and_after_the_run(tmp_path):
    from frictionlab.cli.run import RunSignals
    from frictionlab.realtime import FakeClock, RealtimeController
    from frictionlab.realtime.osrt import STOP_SIGNALS

    before = {sig: signal.getsignal(sig) for sig in (*STOP_SIGNALS, signal.SIGXFSZ)}
    with RunSignals() as sigs:
        assert signal.getsignal(signal.SIGXFSZ) == signal.SIG_IGN
        assert all(signal.getsignal(sig) == sigs._stop for sig in STOP_SIGNALS)
        signal.raise_signal(signal.SIGHUP)  # no controller yet: remembered
        assert sigs.received == "SIGHUP"
        # during the shutdown (the run has ended): nothing changes, nothing raises
        ctl = RealtimeController(build_config("fast", "classical"), "sim",
                                 log_dir=tmp_path, clock=FakeClock(), duration=0.2,
                                 realtime=False, manage_gc=False)
        sigs.ctl = ctl
        stats = ctl.run()
        for sig in STOP_SIGNALS:
            signal.raise_signal(sig)
        assert stats["stop_reason"] == ctl.status()["stop_reason"] == "duration"
    assert {sig: signal.getsignal(sig) for sig in before} == before


def test_a_signal_before_the_run_starts_means_no_run(monkeypatch, capsys, tmp_path):
    from frictionlab.realtime import api

    class Signalled(api.RealtimeController):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            signal.raise_signal(signal.SIGTERM)  # while the controller is being built

        def start(self):
            raise AssertionError("must not start")

    monkeypatch.setattr(api, "RealtimeController", Signalled)
    monkeypatch.setattr("frictionlab.realtime.RealtimeController", Signalled)
    assert main(["run", "--headless", "--json", "--log-dir", str(tmp_path)]) == 0
    st = json.loads(capsys.readouterr().out)
    assert st["stop_reason"] == "signal" and st["ticks"] == 0 and st["log"] is None


def test_a_signal_while_the_console_is_being_set_up_ends_run(monkeypatch, capsys, tmp_path):
    """Before the console serves (and takes the signals over) nothing runs: a signal ends
    `frictionlab run` there and then."""
    served = {}

    class SlowConsole:
        @staticmethod
        def serve(ctl, host, port, token):
            signal.raise_signal(signal.SIGHUP)  # the terminal closed during the set-up
            served["after"] = True

    monkeypatch.setitem(sys.modules, "frictionlab.console", SlowConsole)
    assert main(["run", "--port", "0", "--log-dir", str(tmp_path)]) == 0
    assert "after" not in served and "stopped by SIGHUP" in capsys.readouterr().err
