"""Faults around the loop, injected on a fake clock: a rig that does not do what it says,
a stale state after a pause, a non-finite u, a stop asked for while the rig is being
opened, a log that cannot be written.

Every test injects the fault and checks that the motor gets u_DA = 0 in the tick the
docs name (``docs/realtime.md``, "Safety guarantees"), that no other command follows,
and that the reason is recorded.
"""

import dataclasses
import errno
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.io.logs import read_log
from frictionlab.realtime import FakeClock, RealtimeController, RigError, Safety, datalog
from frictionlab.realtime import loop as loop_mod
from frictionlab.realtime import protocol as P
from frictionlab.realtime.datalog import LogWriter, read_sidecar
from frictionlab.realtime.rigs import FramedRig, SimRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator
from frictionlab.realtime.samples import STOP, Sample

H_NS = 5_000_000


@pytest.fixture(scope="module")
def cfg():
    return build_config("fast", "classical")


def commands(tx):
    """(seq, u_DA) of every COMMAND the controller sent."""
    return [(f.seq, P.parse_command(f)) for f in tx.sent if f.type == P.MSG_COMMAND]


def run(cfg, tmp_path, *, transport=None, emulator=None, safety=None, duration=2.0,
        clock=None, before=None):
    clock = clock or FakeClock()
    emu = emulator(cfg, clock) if emulator else RigEmulator(cfg, clock)
    tx = transport(emu, clock) if transport else DirectTransport(emu, clock)
    rig = FramedRig(tx, "direct", clock=clock)
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=clock, duration=duration,
                             safety=safety, realtime=False, manage_gc=False)
    if before:
        before(clock, ctl, emu, tx)
    stats = ctl.run()
    return emu, tx, stats


def assert_zero_at_stop(tx, stats, emu=None):
    """The stop tick's command is u = 0 and nothing but zeros follows it."""
    cmds = commands(tx)
    k = stats["stop_tick"]
    at_stop = [u for seq, u in cmds if seq == k]
    assert at_stop and at_stop[-1] == 0.0
    after = [u for seq, u in cmds[cmds.index((k, at_stop[-1])):]]
    assert all(u == 0.0 for u in after)
    if emu is not None:
        assert emu.u_da == 0.0


# --- trust, but verify the rig -------------------------------------------------------


class StickyEmulator(RigEmulator):
    """A rig that keeps its command sequence number across sessions: after an earlier
    session that ended at command 10000, HELLO does not reset it, so every command of
    the new session (numbered from 0) looks stale and is ignored."""

    def _hello(self, t):
        super()._hello(t)
        self.last_command_seq = 10_000


def test_a_rig_that_ignores_the_commands_is_a_rig_fault(cfg, tmp_path):
    emu, tx, stats = run(cfg, tmp_path, emulator=StickyEmulator)
    safety = Safety()
    assert stats["stop_reason"] == "rig_fault"
    # it still reports HELD and applies nothing: caught after echo_ticks ticks of it
    assert stats["stop_tick"] == safety.echo_ticks + 1
    assert "HELD" in stats["stop_detail"] or "applies" in stats["stop_detail"]
    assert emu.counts["commands"] == 0 and emu.held
    assert_zero_at_stop(tx, stats)


@pytest.mark.parametrize("n", [2, 50])
def test_commands_not_applied_for_more_than_echo_ticks_stop_the_run(cfg, tmp_path, n):
    safety = Safety()

    def inject(clock, ctl, emu, tx):
        emu.control({"cmd": "fault", "ignore_commands": n, "after": 1.0})

    _emu, tx, stats = run(cfg, tmp_path, before=inject, safety=safety)
    if n <= safety.echo_ticks:  # a short glitch (u changes little between ticks) is tolerated
        assert stats["stop_reason"] == "duration"
    else:
        assert stats["stop_reason"] == "rig_fault" and "applies u_DA" in stats["stop_detail"]
        k_fault = round(1.0 / 0.005) - 1  # first command at or after the fault time
        # command k_fault is ignored; the replies of k_fault+1 .. k_fault+echo_ticks+1 show it
        assert stats["stop_tick"] == k_fault + safety.echo_ticks + 1
        assert_zero_at_stop(tx, stats)


class StatusTransport(DirectTransport):
    """Sets status bits in the rig's SENSOR replies from ``t_on`` (fake time) on."""

    bits = 0
    t_on = 1_000_000_000_000

    def recv(self, deadline_ns):
        msg = super().recv(deadline_ns)
        if (isinstance(msg, P.Frame) and msg.type == P.MSG_SENSOR
                and self.clock.now_ns() >= self.t_on):
            r = P.parse_sensor(msg)
            payload = P.sensor_payload(r.y, r.x, r.v, r.u_da, r.status | self.bits)
            return P.Frame(msg.type, msg.seq, payload)
        return msg


@pytest.mark.parametrize("bit, ticks", [(P.STATUS_WATCHDOG, 0), (P.STATUS_HELD, None)])
def test_rig_status_watchdog_and_held_are_rig_faults(cfg, tmp_path, bit, ticks):
    safety = Safety()
    ticks = safety.echo_ticks if ticks is None else ticks

    def make(emu, clock):
        tx = StatusTransport(emu, clock)
        tx.bits = bit
        tx.t_on = clock.now_ns() + 1_000_000_000
        return tx

    emu, tx, stats = run(cfg, tmp_path, transport=make, safety=safety)
    assert stats["stop_reason"] == "rig_fault"
    assert ("watchdog" if bit == P.STATUS_WATCHDOG else "HELD") in stats["stop_detail"]
    k_fault = round(1.0 / 0.005) - 1
    assert stats["stop_tick"] == k_fault + ticks
    assert_zero_at_stop(tx, stats, emu)


def test_rig_watchdog_tripped_by_lost_commands_stops_the_run(cfg, tmp_path):
    class LosesCommands(DirectTransport):
        def send(self, data):
            if data[3] == P.MSG_COMMAND and self.clock.now_ns() >= self.t_lost:
                self.sent.append(P.decode(data))  # sent, but never reaches the rig
                return
            super().send(data)

    def make(emu, clock):
        tx = LosesCommands(emu, clock)
        tx.t_lost = clock.now_ns() + 1_000_000_000
        return tx

    # a rig that does not echo u (echo_tolerance 2: any u agrees): only its watchdog speaks
    emu, _tx, stats = run(cfg, tmp_path, transport=make, safety=Safety(echo_tolerance=2.0))
    assert stats["stop_reason"] == "rig_fault" and "watchdog" in stats["stop_detail"]
    k_lost = round(1.0 / 0.005) - 1
    # the rig zeroes the motor 50 ms after the last command it got; the next reply says so
    assert k_lost + 10 <= stats["stop_tick"] <= k_lost + 11
    assert emu.status()["watchdog_tripped"] and emu.status()["u_da"] == 0.0


class _Canned:
    """A transport answering every HELLO with the given frames (bytes)."""

    def __init__(self, clock, replies):
        self.clock, self.replies, self.queue, self.sent = clock, replies, [], []

    def send(self, data):
        frame = P.decode(data)
        self.sent.append(frame)
        if frame.type == P.MSG_HELLO:
            self.queue.extend(self.replies)
        elif frame.type == P.MSG_SAMPLE:  # warm-up exchanges
            self.queue.append(P.encode(P.MSG_SENSOR, frame.seq,
                                       P.sensor_payload(-0.503, 0.0, 0.0, 0.0, 0)))

    def recv(self, deadline_ns):
        if self.queue:
            try:
                return P.decode(self.queue.pop(0))
            except P.FrameError as exc:
                return exc
        if self.clock.now_ns() < deadline_ns:
            self.clock.advance(deadline_ns - self.clock.now_ns())
        return None

    def drain(self):
        self.queue.clear()

    def close(self):
        pass


def hello_ack(adc=12, status=0, watchdog_ms=50, h_tenth_ms=50, payload=None):
    payload = P.hello_ack_payload(adc, status, watchdog_ms, h_tenth_ms) if payload is None \
        else payload
    return P.encode(P.MSG_HELLO_ACK, 0, payload)


@pytest.mark.parametrize("reply, message", [
    (hello_ack(h_tenth_ms=100), "samples every 10 ms .* period is 5 ms: set design.h=0.01"),
    (hello_ack(watchdog_ms=0), "no watchdog"),
    (hello_ack(watchdog_ms=8), "watchdog of 8 ms, shorter than two periods"),
    (hello_ack(adc=0), "0 ADC bits"),
    (hello_ack()[:-1] + bytes([hello_ack()[-1] ^ 1]), "no valid HELLO_ACK .* bad CRC"),
    (hello_ack(payload=b"\x0c\x00\x32\x00"), "no valid HELLO_ACK .* wrong length: HELLO_ACK "
                                             "with a 4-byte payload"),
    (P.encode(P.MSG_SENSOR, 0, P.sensor_payload(0, 0, 0, 0, 0)),
     "no valid HELLO_ACK .* a SENSOR frame instead of HELLO_ACK"),
])
def test_handshake_refuses_what_does_not_fit_and_says_why(reply, message):
    clock = FakeClock()
    rig = FramedRig(_Canned(clock, [reply]), "test", clock=clock)
    with pytest.raises(RigError, match=message):
        rig.open(h=0.005)


@pytest.mark.parametrize("h_tenth_ms", [50, 0])
def test_handshake_accepts_the_right_period_or_any(h_tenth_ms):
    clock = FakeClock()
    rig = FramedRig(_Canned(clock, [hello_ack(h_tenth_ms=h_tenth_ms)]), "test", clock=clock)
    rig.open(h=0.005)
    assert rig.info.h_tenth_ms == h_tenth_ms and rig.info.watchdog_ms == 50


def test_rig_sim_states_its_period_and_refuses_another_h(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg.with_values({"design.h": 0.01}), clock)
    rig = FramedRig(DirectTransport(emu, clock), "direct", clock=clock)
    with pytest.raises(RigError, match="samples every 10 ms"):
        rig.open(h=0.005)
    rig.open(h=0.01)
    assert rig.info.h_tenth_ms == 100


def test_hello_resets_the_rig_s_command_sequence(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    tx = DirectTransport(emu, clock)
    for session in range(2):
        rig = FramedRig(tx, "direct", clock=clock)
        rig.open(h=0.005)
        first = 5000 if session == 0 else 0
        for k in range(first, first + 3):
            assert rig.sample(k, clock.now_ns() + 2_500_000) is not None
            rig.write(k, 0.1 * (k - first + 1))
            clock.advance(H_NS)
        # every command of the session was applied, those of the second one too
        assert emu.last_command_seq == first + 2 and emu.u_da == pytest.approx(0.3)
        rig.write(first + 3, 0.0)


# --- a non-finite u ------------------------------------------------------------------


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_a_non_finite_u_stops_in_the_tick_that_computes_it(cfg, tmp_path, monkeypatch, bad):
    real_step = loop_mod.controller_step_rows
    calls = []

    def step(x, g, cp, theta, arm, arm_dot):
        u, u_fb, f_hat = real_step(x, g, cp, theta, arm, arm_dot)
        calls.append(u)
        return (bad if len(calls) == 300 else u), u_fb, f_hat

    monkeypatch.setattr(loop_mod, "controller_step_rows", step)
    emu, tx, stats = run(cfg, tmp_path)
    assert stats["stop_reason"] == "nonfinite_u" and repr(bad) in stats["stop_detail"]
    # the controller ran once before the loop (compilation), then once per tick
    assert stats["stop_tick"] == 298
    assert_zero_at_stop(tx, stats, emu)
    cmds = commands(tx)
    assert all(np.isfinite(u) for _, u in cmds) and max(abs(u) for _, u in cmds) < 1.0


def test_an_unstable_lugre_compensator_ends_in_nonfinite_u_not_a_write(cfg, tmp_path):
    # the console's "sigma1 1e5" case: the compensator's state blows up within a few
    # ticks (angle limit widened so that it gets there); no NaN or inf is ever written
    lugre = build_config("fast", "classical", compensation="lugre").with_values(
        {"compensation.sigma1": 1e5})
    emu, tx, stats = run(lugre, tmp_path, safety=Safety(angle_limit=3.0))
    assert stats["stop_reason"] == "nonfinite_u" and "u = nan" in stats["stop_detail"]
    assert all(np.isfinite(u) and abs(u) <= 1.0 for _, u in commands(tx))
    assert_zero_at_stop(tx, stats, emu)


# --- a stale state after a pause -----------------------------------------------------


@pytest.mark.parametrize("pause_ms, stops", [(15.0, False), (45.0, False), (55.0, True),
                                             (400.0, True)])
def test_a_pause_longer_than_max_pause_stops_before_acting(cfg, tmp_path, pause_ms, stops):
    clock = FakeClock()
    start = clock.now_ns()
    t_pause = start + H_NS + 300 * H_NS  # the deadline of tick 300

    def latency(deadline):
        return int(pause_ms * 1e6) if deadline == t_pause else 0

    clock._latency = latency
    _emu, tx, stats = run(cfg, tmp_path, clock=clock)
    if not stops:  # a host stall: skipped ahead, carried on
        assert stats["stop_reason"] == "duration" and stats["missed"] == pause_ms // 5
        return
    assert stats["stop_reason"] == "paused" and f"{pause_ms:.1f} ms" in stats["stop_detail"]
    k = 300 + int(pause_ms * 1e6) // H_NS
    assert stats["stop_tick"] == k
    # the tick after the pause wrote only the zero: no u computed from the stale state
    cmds = commands(tx)
    assert [c for c in cmds if c[0] < k][-1][0] == 299
    assert {c for c in cmds if c[0] >= k} == {(k, 0.0)}
    log = read_log(stats["log_files"]["csv"], partial=True)
    assert int(log["tick"][-2]) == 299 and int(log["flags"][-1]) & STOP


def test_the_lockstep_simulation_waits_for_the_loop_and_does_not_go_stale(cfg, tmp_path):
    clock = FakeClock()
    t_pause = clock.now_ns() + H_NS + 300 * H_NS
    clock._latency = lambda deadline: 400_000_000 if deadline == t_pause else 0
    ctl = RealtimeController(cfg, SimRig(cfg, lockstep=True), log_dir=tmp_path, clock=clock,
                             duration=2.0, realtime=False, manage_gc=False)
    stats = ctl.run()
    assert stats["stop_reason"] == "duration" and stats["missed"] == 80


def test_a_pause_inside_a_tick_does_not_write_the_stale_u(cfg, tmp_path):
    class SuspendedInTheRead(SimRig):
        def sample(self, k, deadline_ns):
            r = super().sample(k, deadline_ns)
            if k == 250:
                self.clock.advance(200_000_000)  # SIGSTOP ... SIGCONT after the read
            return r

        def write(self, k, u_da):
            self.writes.append((k, u_da))
            super().write(k, u_da)

    clock = FakeClock()
    rig = SuspendedInTheRead(cfg)
    rig.clock, rig.writes = clock, []
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=clock, duration=2.0,
                             realtime=False, manage_gc=False)
    stats = ctl.run()
    assert stats["stop_reason"] == "paused" and stats["stop_tick"] == 250
    assert rig.writes[-1] == (250, 0.0) and rig.writes[-2][0] == 249


# --- stop requests while the rig is being opened ---------------------------------------


class SlowToAnswer(DirectTransport):
    """A rig that answers only HELLOs sent after ``t_ready`` (still booting before)."""

    t_ready = 0

    def send(self, data):
        if data[3] == P.MSG_HELLO and self.clock.now_ns() < self.t_ready:
            self.sent.append(P.decode(data))
            return
        super().send(data)


@pytest.mark.parametrize("t_signal_ms", [100, 390])
def test_a_signal_while_the_rig_is_being_opened_ends_the_run(cfg, tmp_path, t_signal_ms):
    """SIGINT/SIGTERM handlers call ctl.stop('signal'): during HELLO it must not be lost."""

    def make(emu, clock):
        tx = SlowToAnswer(emu, clock)
        tx.t_ready = clock.now_ns() + 400_000_000  # answers the third HELLO (400 ms)
        return tx

    def before(clock, ctl, emu, tx):
        clock.call_at(clock.now_ns() + t_signal_ms * 1_000_000,
                      lambda: ctl.stop("signal", "SIGINT"))

    emu, tx, stats = run(cfg, tmp_path, transport=make, before=before, duration=10.0)
    assert stats["stop_reason"] == "signal" and stats["stop_detail"] == "SIGINT"
    assert stats["stop_tick"] == 0 and stats["ticks"] == 0
    # the HELLO wait ended within one poll of the signal; no HELLO after it
    hellos = [f for f in tx.sent if f.type == P.MSG_HELLO]
    assert len(hellos) == 1 + t_signal_ms // 200
    # the only command the rig ever got is the zero (from the stop, and again on closing)
    assert set(commands(tx)) == {(0, 0.0)} and emu.u_da == 0.0
    with open(stats["log_files"]["json"]) as fh:
        meta = json.load(fh)
    assert meta["stop_reason"] == "signal" and not meta["running"]


def test_a_stop_between_the_handshake_and_the_first_tick_is_kept(cfg, tmp_path):
    class StopsDuringWarmUp(SimRig):
        def open(self, h=None, cancel=None):
            super().open(h, cancel)
            self.ctl.stop("signal", "SIGTERM")   # the signal arrives right after HELLO_ACK

        def write(self, k, u_da):
            self.writes.append(u_da)
            super().write(k, u_da)

    rig = StopsDuringWarmUp(cfg)
    rig.writes = []
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=FakeClock(), duration=5.0,
                             realtime=False, manage_gc=False)
    rig.ctl = ctl
    stats = ctl.run()
    assert (stats["stop_reason"], stats["stop_tick"], rig.writes) == ("signal", 0, [0.0])
    # a stop asked for while nothing runs is not kept for the next run
    ctl.stop("user")
    rig.ctl = type("NoStop", (), {"stop": lambda *a: None})()
    assert ctl.run()["stop_reason"] == "duration"


# --- a log that cannot be written --------------------------------------------------------


class FullDisk:
    """Fault injection for the log writer's raw writes: the disk fills after ``free``
    bytes (a write then writes what fits and fails with ENOSPC, as the kernel does);
    the space set aside by the writer counts as used while its file exists."""

    def __init__(self, free):
        self.free = free
        self.reserved = {}

    def write(self, fd, data):
        n = min(len(data), self.free - sum(
            size for path, size in self.reserved.items() if os.path.exists(path)))
        if n <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = os.write(fd, bytes(data[:n]))
        self.free -= n
        return n

    def fallocate(self, fd, offset, size):
        self.reserved[os.readlink(f"/proc/self/fd/{fd}")] = size


def sample(k):
    return Sample(k, k * 0.005, 0, *[0.001 * k + i for i in range(10)], 0.1, -0.2, 0.3,
                  -0.0123, 12.5, 40.0, 30.0)


@pytest.mark.slow
def test_a_failing_write_cuts_the_files_to_complete_rows_and_reports_once(tmp_path, monkeypatch):
    disk = FullDisk(free=20_000 + datalog.RESERVE_BYTES)
    monkeypatch.setattr(datalog, "_write", disk.write)
    monkeypatch.setattr(datalog, "_fallocate", disk.fallocate)
    errors = []
    w = LogWriter(tmp_path, "run1", on_error=errors.append)
    w.write_meta({"running": True})
    w.start()
    for k in range(400):
        w.put(sample(k))
        if k % 20 == 19:
            time.sleep(0.06)  # several flushes
    w.close({"running": False, "stop_reason": "log_failed"})
    assert len(errors) == 1 and "No space left on device" in errors[0] and w.failed
    assert 0 < w.written < 400 and w.written + w.dropped == 400
    dat = (tmp_path / "run1.dat").read_bytes()
    csv = (tmp_path / "run1.csv").read_bytes()
    assert dat.endswith(b"\n") and csv.endswith(b"\n")  # never cut mid-line
    assert dat.count(b"\n") == w.written == csv.count(b"\n") - 1  # the same rows in both
    np.testing.assert_array_equal(read_log(tmp_path / "run1.csv", partial=True)["tick"],
                                  np.arange(w.written))
    # the disk is full, yet the final sidecar was written, from the space set aside
    assert json.loads((tmp_path / "run1.json").read_text())["stop_reason"] == "log_failed"
    assert not (tmp_path / ".run1.reserve").exists()


def test_a_full_disk_stops_the_run_with_the_motor_at_zero(cfg, tmp_path, monkeypatch):
    disk = FullDisk(free=150_000 + datalog.RESERVE_BYTES)
    monkeypatch.setattr(datalog, "_write", disk.write)
    monkeypatch.setattr(datalog, "_fallocate", disk.fallocate)
    # the loop runs in fake time; let each tick take 0.2 ms of real time so the writer
    # thread (50 ms real-time flushes) meets the full disk while the run goes on
    clock = FakeClock(wake_latency=lambda d: time.sleep(0.0002) or 0)
    emu, tx, stats = run(cfg, tmp_path, clock=clock, duration=60.0)
    assert stats["stop_reason"] == "log_failed"
    assert "No space left on device" in stats["stop_detail"]
    assert stats["stop_tick"] < 12_000
    assert_zero_at_stop(tx, stats, emu)
    log = read_log(stats["log_files"]["csv"], partial=True)
    assert 0 < len(log["tick"]) == stats["log_written"] <= stats["stop_tick"]
    meta = read_sidecar(stats["log_files"]["json"])
    assert meta["state"] == "finished" and meta["stop_reason"] == "log_failed"


def test_rows_lost_after_the_stop_still_make_the_run_a_failed_log(cfg, tmp_path,
                                                                  monkeypatch):
    disk = FullDisk(free=20_000 + datalog.RESERVE_BYTES)
    monkeypatch.setattr(datalog, "_write", disk.write)
    monkeypatch.setattr(datalog, "_fallocate", disk.fallocate)
    # no writer thread: everything is written when the log is closed, after the stop
    monkeypatch.setattr(LogWriter, "start", lambda self, on_thread_start=None: None)
    emu, tx, stats = run(cfg, tmp_path, duration=1.0)
    assert stats["stop_reason"] == "log_failed" and stats["stop_tick"] == 200
    assert "after the run had stopped: duration" in stats["stop_detail"]
    assert_zero_at_stop(tx, stats, emu)
    meta = read_sidecar(stats["log_files"]["json"])
    assert (meta["state"], meta["stop_reason"]) == ("finished", "log_failed")
    # one write held every row; it failed, and the files were cut back to what they held
    assert stats["log_written"] == 0 and stats["dropped_log_samples"] == 201
    assert open(stats["log_files"]["csv"]).read() == datalog.CSV_HEADER


def test_nothing_existing_is_overwritten_by_a_run_or_a_recording(cfg, tmp_path):
    ctl = RealtimeController(cfg, "sim", log_dir=tmp_path, clock=FakeClock(), duration=0.5,
                             realtime=False, manage_gc=False)
    ctl._new_run_id = lambda n=1: "run-x" if n == 1 else f"run-x-{n}"
    (tmp_path / "run-x.dat").write_text("a simulate --save of the user\n")
    (tmp_path / "run-x-2.json").write_text("{}")
    stats = ctl.run()
    assert ctl.run_id == "run-x-3" and stats["log"].endswith("run-x-3.csv")
    assert (tmp_path / "run-x.dat").read_text() == "a simulate --save of the user\n"
    assert (tmp_path / "run-x-2.json").read_text() == "{}"
    # a recording named like the next recording's automatic file keeps its data
    w = LogWriter(tmp_path, "run3")
    w.start()
    w.record_start()
    for k in range(5):
        w.put(sample(k))
    assert w.record_stop("run3-save2")["rows"] == 5
    w.record_start()
    for k in range(5, 8):
        w.put(sample(k))
    second = w.record_stop()
    w.close()
    assert second["csv"].endswith("run3-save3.csv") and second["rows"] == 3
    np.testing.assert_array_equal(read_log(tmp_path / "run3-save2.csv", partial=True)["tick"],
                                  np.arange(5))
    # and a rename onto an existing name is refused
    with pytest.raises(FileExistsError):
        datalog.link_no_clobber(tmp_path / "run3-save3.csv", tmp_path / "run3-save2.csv")


@pytest.mark.slow
def test_a_sidecar_tells_a_finished_run_from_a_dead_one(tmp_path):
    path = tmp_path / "run.json"
    identity = datalog.writer_identity()
    datalog.write_json_atomic(path, {"running": False, "writer": identity})
    assert read_sidecar(path)["state"] == "finished"
    datalog.write_json_atomic(path, {"running": True, "writer": identity,
                                     "updated": time.time()})
    assert read_sidecar(path)["state"] == "running"
    # written by a process that has ended (killed, crashed)
    out = subprocess.run([sys.executable, "-c", "import json; from frictionlab.realtime "
                          "import datalog; print(json.dumps(datalog.writer_identity()))"],
                         capture_output=True, text=True, check=True)
    gone = json.loads(out.stdout)
    datalog.write_json_atomic(path, {"running": True, "writer": gone, "updated": time.time()})
    assert read_sidecar(path)["state"] == "interrupted"
    # written on another host: judged by its last refresh
    other = dict(identity, host="elsewhere")
    datalog.write_json_atomic(path, {"running": True, "writer": other,
                                     "updated": time.time() - 60})
    assert read_sidecar(path)["state"] == "interrupted"


def test_new_safety_limits_are_validated():
    with pytest.raises(ValueError, match=r"safety\.max_pause"):
        Safety(max_pause=0.0)
    with pytest.raises(ValueError, match=r"safety\.echo_ticks"):
        Safety(echo_ticks=0)
    assert dataclasses.asdict(Safety())["max_pause"] == 0.05


# --- the stop branches that had no fault of their own (docs/realtime.md, "Safety guarantees")


class FailingSends(DirectTransport):
    """A link whose ``send`` raises (ENOBUFS) for the COMMAND frames ``fail(seq, u_DA)``
    picks; every attempt is recorded in ``attempts`` as (seq, u_DA, delivered)."""

    fail = staticmethod(lambda seq, u: False)

    def send(self, data):
        frame = P.decode(data)
        if frame.type == P.MSG_COMMAND:
            u = P.parse_command(frame)
            if self.fail(frame.seq, u):
                self.attempts.append((frame.seq, u, False))
                raise OSError(errno.ENOBUFS, "No buffer space available")
            self.attempts.append((frame.seq, u, True))
        super().send(data)


def test_a_failing_zero_write_at_the_stop_falls_back_to_stop_motor(cfg, tmp_path):
    """The stop's own u_DA = 0 write fails (a full socket buffer, once): the loop's
    fallback, the rig's best-effort ``stop_motor``, sends the zero, and the motor stops."""

    def transport(emu, clock):
        tx = FailingSends(emu, clock)
        tx.attempts = []
        tx.fail = lambda seq, u: seq == 200 and u == 0.0 and not any(
            not ok for _s, _u, ok in tx.attempts)
        return tx

    emu, tx, stats = run(cfg, tmp_path, transport=transport, duration=1.0)
    assert stats["stop_reason"] == "duration" and stats["stop_tick"] == 200
    failed = [(s, u) for s, u, ok in tx.attempts if not ok]
    assert failed == [(200, 0.0)]  # the stop's write, and only it, failed ...
    # ... and the next command the rig got is stop_motor's zero, for the same tick
    after = tx.attempts[tx.attempts.index((200, 0.0, False)) + 1:]
    assert after and after[0] == (200, 0.0, True) and all(u == 0.0 for _s, u, _ok in after)
    assert emu.u_da == 0.0
    assert any(u != 0.0 for _s, u in commands(tx))  # the motor was driven before


def test_a_link_that_fails_in_the_tick_stops_and_still_tries_the_zero(cfg, tmp_path):
    """The tick's own write fails (the link is gone): the run stops (``exception``) and the
    loop tries the zero, then ``stop_motor``, both of which must not raise again."""

    def transport(emu, clock):
        tx = FailingSends(emu, clock)
        tx.attempts = []
        tx.fail = lambda seq, u: seq >= 150
        return tx

    _emu, tx, stats = run(cfg, tmp_path, transport=transport, duration=1.0)
    assert stats["stop_reason"] == "exception" and "No buffer space" in stats["stop_detail"]
    assert stats["stop_tick"] == 150
    tried = [(s, u) for s, u, ok in tx.attempts if not ok]
    # the tick's u, then the stop's zero, then stop_motor's zero (halt's fallback) and the
    # run's last stop_motor: nothing but zeros after the failed command
    assert tried[0][0] == 150 and tried[1:] and all(u == 0.0 for _s, u in tried[1:])
    assert len(tried) >= 3


def test_a_stall_after_the_controller_step_does_not_write_its_u(cfg, tmp_path, monkeypatch):
    """The process is suspended between the controller step and the write (the third
    ``paused`` check, on the tick's output): the u computed before the stall is stale and
    is not written; the stop's zero is."""
    real_step = loop_mod.controller_step_rows
    clock = FakeClock()
    calls = []

    def step(*args):
        out = real_step(*args)
        calls.append(out[0])
        if len(calls) == 301:  # tick 299 (the first call compiles, before the run)
            clock.advance(200_000_000)  # SIGSTOP ... SIGCONT
        return out

    monkeypatch.setattr(loop_mod, "controller_step_rows", step)
    _emu, tx, stats = run(cfg, tmp_path, clock=clock)
    assert stats["stop_reason"] == "paused" and stats["stop_tick"] == 299
    assert "output was due" in stats["stop_detail"]
    cmds = commands(tx)
    assert [c for c in cmds if c[0] < 299][-1][0] == 298
    assert {c for c in cmds if c[0] >= 299} == {(299, 0.0)}
    assert calls[-1] != 0.0  # a u was computed, and it was not the one written
    assert_zero_at_stop(tx, stats)


class BadExperiment:
    """An identification experiment (``step`` -> u, m/s^2) that drives the arm for 1 s and
    then computes ``bad``."""

    phase = "running"
    progress = 0.5

    def __init__(self, bad):
        self.bad = bad
        self.steps = 0

    def describe(self):
        return {"name": "bad-experiment"}

    def step(self, t, theta, arm, arm_dot, y, x, v):
        self.steps += 1
        return self.bad if t >= 1.0 else 2.0


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_an_experiment_computing_a_non_finite_u_stops_with_the_motor_at_zero(cfg, tmp_path,
                                                                            bad):
    exp = BadExperiment(bad)
    clock = FakeClock()
    emu = RigEmulator(cfg.with_values({"sim.initial_angle": math.pi}), clock)
    tx = DirectTransport(emu, clock)
    ctl = RealtimeController(cfg, FramedRig(tx, "direct", clock=clock), log_dir=tmp_path,
                             clock=clock, duration=3.0, realtime=False, manage_gc=False,
                             experiment=exp)
    stats = ctl.run()
    assert stats["stop_reason"] == "nonfinite_u" and stats["stop_tick"] == 200
    assert f"the experiment computed u = {bad!r}" in stats["stop_detail"]
    cmds = commands(tx)
    assert all(math.isfinite(u) for _s, u in cmds)
    driven = [u for s, u in cmds if s < 200]  # u_DA = k_u u, as float32
    assert len(driven) == 200 and driven == pytest.approx([2.0 * cfg.rig.u_scale] * 200)
    assert_zero_at_stop(tx, stats, emu)


def _tampered(seq_bad, frame):
    """A transport that replaces the rig's SENSOR reply to SAMPLE ``seq_bad`` by ``frame``."""

    class Tampered(DirectTransport):
        def send(self, data):
            super().send(data)
            f = P.decode(data)
            if f.type == P.MSG_SAMPLE and f.seq == seq_bad:
                self._replies.pop()
                self._replies.append(frame)

    return Tampered


@pytest.mark.parametrize("frame, detail", [
    (P.encode(P.MSG_SAMPLE, 300), "unexpected SAMPLE frame"),
    (P.command_frame(300, 0.5), "unexpected COMMAND frame"),
    (P.encode(P.MSG_SENSOR, 300, b"\x00" * 7), "corrupted frame: wrong length"),
    (P.encode(P.MSG_SENSOR, 300, b""), "corrupted frame: wrong length"),
], ids=["sample_frame", "command_frame", "short_sensor_payload", "empty_sensor_payload"])
def test_an_unexpected_frame_type_or_bad_payload_from_the_rig_stops_it(cfg, tmp_path, frame,
                                                                       detail):
    """The rig's backend (``FramedRig.sample``): a frame of a type the rig must not send,
    or a SENSOR reply whose payload is not one (a well-formed frame: the CRC holds), is a
    ``bad_reading``; the tick writes the zero and nothing else follows."""
    emu, tx, stats = run(cfg, tmp_path, transport=_tampered(300, frame))
    assert stats["stop_reason"] == "bad_reading" and stats["stop_tick"] == 300
    assert detail in stats["stop_detail"]
    cmds = commands(tx)
    assert [c for c in cmds if c[0] < 300][-1][0] == 299
    assert_zero_at_stop(tx, stats, emu)
