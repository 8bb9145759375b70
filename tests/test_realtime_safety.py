"""Safety stops by fault injection through the emulated rig (fake clock, no sleeping).

Each fault is injected by the emulator (``{"cmd": "fault", ...}``, as over the
protocol's CONTROL frames) at a known time; the loop must stop, write
u_DA = 0 within 2 ticks of the first tick that saw the fault, and record the
reason in the log (CSV flags and the JSON sidecar).
"""

import json

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.io.logs import read_log
from frictionlab.realtime import FakeClock, RealtimeController, Safety
from frictionlab.realtime import protocol as P
from frictionlab.realtime.rigs import FramedRig, SimRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator
from frictionlab.realtime.samples import NO_READING, STOP

H_NS = 5_000_000
T_FAULT = 1.0


@pytest.fixture(scope="module")
def cfg():
    return build_config("fast", "classical")


def run_with_emulator(cfg, tmp_path, faults=None, *, after=T_FAULT, transport=None,
                      safety=None, duration=3.0, on_clock=None):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    tx = transport(emu, clock) if transport else DirectTransport(emu, clock)
    rig = FramedRig(tx, "direct", clock=clock)
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=clock, duration=duration,
                             safety=safety, realtime=False, manage_gc=False)
    if faults:
        reply = emu.control({"cmd": "fault", "after": after, **faults})
        assert reply == {"ok": True}
    if on_clock:
        on_clock(clock, ctl)
    stats = ctl.run()
    log = read_log(stats["log_files"]["csv"], partial=True)
    with open(stats["log_files"]["json"]) as fh:
        meta = json.load(fh)
    return ctl, emu, tx, stats, log, meta


def fault_tick(stats, when=T_FAULT):
    """The first tick whose deadline is at or after the fault's time."""
    return int(np.ceil(when / 0.005 - 1))  # t0 = start + h


def last_command(tx):
    cmd = [f for f in tx.sent if f.type == P.MSG_COMMAND]
    return cmd[-1].seq, P.parse_command(cmd[-1])


def check_stopped(emu, tx, stats, log, meta, reason, k_fault):
    assert stats["stop_reason"] == reason
    assert meta["stop_reason"] == reason and meta["stop_detail"]
    k_stop = stats["stop_tick"]
    assert k_fault <= k_stop <= k_fault + 2
    # the loop's first COMMAND after the fault that is not the held u: u_DA = 0 in the stop
    # tick, and nothing else after it
    seq, u_da = last_command(tx)
    assert (seq, u_da) == (k_stop, 0.0)
    if reason != "rig_silent":
        assert emu.u_da == 0.0 and emu.last_command_seq == k_stop
    # the log ends with the stop row: flag STOP, u_da 0, the stop tick
    assert int(log["flags"][-1]) & STOP and log["u_da"][-1] == 0.0
    assert int(log["tick"][-1]) == k_stop
    assert not np.any(log["flags"][:-1].astype(int) & STOP)
    return k_stop


@pytest.mark.parametrize("faults, reason", [
    ({"nan": 1}, "bad_reading"),
    ({"out_of_range": 1}, "bad_reading"),
    ({"corrupt": 1}, "bad_reading"),
    ({"duplicate": 1}, "bad_reading"),
    ({"seq_offset": 1}, "bad_reading"),    # a reply from the future: out of order
    ({"seq_offset": -3}, "bad_reading"),   # an old sequence number: stale
    ({"silent": 1.0}, "rig_silent"),
])
def test_rig_faults_stop_the_motor_within_two_ticks(cfg, tmp_path, faults, reason):
    _ctl, emu, tx, stats, log, meta = run_with_emulator(cfg, tmp_path, faults)
    k_fault = fault_tick(stats)
    k_stop = check_stopped(emu, tx, stats, log, meta, reason, k_fault)
    # the run was healthy up to the fault
    assert np.all(log["tick"][:-1] < k_stop) and len(log["tick"]) == k_stop + 1
    assert np.all(np.abs(log["theta_m"][:k_fault]) < 0.35)
    if "silent" in faults:
        assert k_stop == k_fault + 1  # 2 sample periods without anything from the rig
        assert stats["rig_timeouts"] == 2
        # the silent rig did not hear the zero command: its own watchdog zeroes the motor
        emu.clock.advance(60_000_000)
        st = emu.status()
        assert st["watchdog_tripped"] and st["u_da"] == 0.0


def test_pendulum_pushed_over_stops_at_the_angle_limit(cfg, tmp_path):
    safety = Safety(angle_limit=0.3)
    _ctl, emu, tx, stats, log, meta = run_with_emulator(cfg, tmp_path, {"push": 4.0},
                                                        safety=safety)
    theta_stop = np.pi * (log["y"][-1] + 0.503)
    assert abs(theta_stop) > 0.3
    # the first reading beyond the limit is the stop tick: zero there, not later
    assert np.all(np.abs(log["theta_m"][:-1]) <= 0.3)
    check_stopped(emu, tx, stats, log, meta, "angle_limit", int(log["tick"][-1]))
    assert stats["stop_tick"] > fault_tick(stats)


def test_late_replies_are_life_signs_but_not_readings(cfg, tmp_path):
    class OneTickLate(DirectTransport):
        """After the fault time, every reply is held back until the next request."""

        def __init__(self, emu, clock):
            super().__init__(emu, clock)
            self.held = []

        def send(self, data):
            late = self.clock.now_ns() >= self.t_late
            n = len(self._replies)
            super().send(data)
            if late:
                new = [self._replies.pop() for _ in range(len(self._replies) - n)]
                self._replies.extend(self.held)
                self.held = new

    def make(emu, clock):
        tx = OneTickLate(emu, clock)
        tx.t_late = clock.now_ns() + int(T_FAULT * 1e9)
        return tx

    safety = Safety(unread_limit=6)
    _ctl, emu, _tx, stats, log, _meta = run_with_emulator(cfg, tmp_path, transport=make,
                                                         safety=safety)
    k_fault = fault_tick(stats)
    assert stats["stop_reason"] == "rig_silent" and "too late" in stats["stop_detail"]
    # from the fault on, each tick's reply comes during the next tick: never a reading,
    # but never 2 periods of silence either; the 6th tick without a reading stops
    assert stats["stop_tick"] == k_fault + 5
    assert stats["late_replies"] == 5 and stats["rig_timeouts"] == 6
    flags = log["flags"].astype(int)
    assert np.all(flags[-6:-1] & NO_READING) and not flags[-7] & NO_READING
    # the held ticks kept u and were flagged, the stop wrote 0
    assert emu.u_da == 0.0 and emu.last_command_seq == stats["stop_tick"]


def test_exception_in_the_tick_stops_the_motor(cfg, tmp_path):
    class Broken(SimRig):
        def sample(self, k, deadline_ns):
            if k == 150:
                raise RuntimeError("encoder cable unplugged")
            return super().sample(k, deadline_ns)

    rig = Broken(cfg)
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=FakeClock(), duration=2.0,
                             realtime=False, manage_gc=False)
    stats = ctl.run()
    assert stats["stop_reason"] == "exception" and stats["stop_tick"] == 150
    assert "encoder cable unplugged" in stats["stop_detail"]
    assert rig.u_da == 0.0
    with open(stats["log_files"]["json"]) as fh:
        meta = json.load(fh)
    assert "RuntimeError" in meta["traceback"]
    log = read_log(stats["log_files"]["csv"], partial=True)
    assert int(log["flags"][-1]) & STOP and int(log["tick"][-1]) == 150


@pytest.mark.parametrize("how", ["request", "keyboard_interrupt"])
def test_signal_stops_within_one_tick(cfg, tmp_path, how):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    ctl = RealtimeController(cfg, FramedRig(DirectTransport(emu, clock), "direct", clock=clock),
                             log_dir=tmp_path, clock=clock, duration=3.0, realtime=False,
                             manage_gc=False)

    def deliver():
        if how == "request":
            ctl.stop("signal")  # what the SIGINT/SIGTERM handler of `frictionlab run` does
        else:
            raise KeyboardInterrupt  # Python's default SIGINT handler, inside the loop

    t_sig = clock.now_ns() + H_NS + 200 * H_NS + H_NS // 3
    clock.call_at(t_sig, deliver)
    stats = ctl.run()
    assert stats["stop_reason"] == "signal"
    # the signal arrived while sleeping before tick 201: a stop request is served by tick
    # 201 (u = 0 written there); an exception raised in the sleep zeroes the motor at once,
    # under the number of the last tick
    k_stop = 201 if how == "request" else 200
    assert stats["stop_tick"] == k_stop
    assert emu.u_da == 0.0 and emu.last_command_seq == k_stop


def test_normal_end_zeroes_the_motor(cfg, tmp_path):
    _ctl, emu, _tx, stats, log, meta = run_with_emulator(cfg, tmp_path, duration=1.0)
    assert stats["stop_reason"] == "duration" and stats["stop_tick"] == 200
    assert emu.u_da == 0.0 and emu.last_command_seq == 200
    assert meta["stop_reason"] == "duration" and not meta["running"]
    assert len(log["tick"]) == 201 and int(log["flags"][-1]) & STOP


def test_no_swing_up_start_needs_the_pendulum_upright(cfg, tmp_path):
    tilted = cfg.with_values({"sim.initial_angle": 0.3})
    _ctl, emu, _tx, stats, _log, _meta = run_with_emulator(tilted, tmp_path,
                                                           safety=Safety(start_tolerance=0.2))
    assert stats["stop_reason"] == "not_upright" and stats["stop_tick"] == 0
    assert emu.u_da == 0.0


def test_dac_output_saturates(cfg, tmp_path):
    # a huge gain pushes u_DA to its limits; the loop writes at most |1|
    hot = cfg.with_values({"design.omega1": 60.0, "sim.initial_angle": 0.12})
    _ctl, _emu, _tx, _stats, log, _meta = run_with_emulator(hot, tmp_path, duration=0.2,
                                                           safety=Safety(angle_limit=3.0))
    uda = log["u_da"][np.isfinite(log["u_da"])]
    assert np.max(np.abs(uda)) == 1.0
    assert np.all(np.abs(uda) <= 1.0)
