"""Rig backends and the emulated rig: raw signals, watchdog, faults, UDP and serial (pty)."""

import math
import os
import threading
import time
import tty

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.config import build_config
from frictionlab.model.rig import RigScaling
from frictionlab.realtime import FakeClock, RigError, open_rig
from frictionlab.realtime import protocol as P
from frictionlab.realtime.rigs import ARM_START, AdcModel, BadReading, FramedRig, SimRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator, serve_stream, serve_udp

Q = 2.0 / 4096


@pytest.fixture(scope="module")
def cfg():
    return build_config("fast", "classical")


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(theta=st.floats(-1.2, 1.2), arm=st.floats(-200.0, 200.0), arm_dot=st.floats(-25, 25))
def test_adc_model_is_app_b_with_12_bit_quantisation(theta, arm, arm_dot):
    sc = RigScaling()
    adc = AdcModel(sc, arm_offset=ARM_START, quantize=True)
    y, x, v = adc.read(theta, arm, arm_dot)
    for r in (y, x, v):
        assert -1.0 <= r <= 1.0
        assert abs(r / Q - round(r / Q)) < 1e-6        # on the 12-bit grid
    # App. B inverse, up to half a quantum, the pendulum/arm channels wrapped into [-1, 1)
    th = np.pi * (y + 0.503)
    assert math.remainder(th - theta, 2 * np.pi) == pytest.approx(0.0, abs=np.pi * Q / 2 + 1e-9)
    om = 25.8 * (x - ARM_START)
    assert math.remainder(om - arm, 2 * 25.8) == pytest.approx(0.0, abs=25.8 * Q / 2 + 1e-9)
    v_true = arm_dot / 28.7 - 0.02
    if -1.0 <= v_true <= 1.0 - Q:
        assert 28.7 * (v - v_true) == pytest.approx(0.0, abs=28.7 * Q / 2 + 1e-9)
    else:  # the velocity channel clips at the ends of the ADC's range
        assert v in (-1.0, 1.0 - Q)


def test_emulator_watchdog_zeroes_the_motor_after_50_ms(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock, watchdog=0.05)
    emu.handle(P.encode(P.MSG_HELLO, 0))
    emu.handle(P.command_frame(1, 0.2))
    clock.advance(49_000_000)
    st_ = emu.status()
    assert st_["u_da"] == pytest.approx(0.2) and not st_["watchdog_tripped"]
    arm_dot_49 = emu.state.x[3]
    clock.advance(2_000_000)
    st_ = emu.status()
    assert st_["watchdog_tripped"] and st_["u_da"] == 0.0 and st_["watchdog_trips"] == 1
    (reply,) = emu.handle(P.sample_frame(2))
    r = P.parse_sensor(P.decode(reply))
    assert r.status & P.STATUS_WATCHDOG and r.u_da == 0.0
    # the plant got no drive after the trip: the arm only decelerates under friction
    clock.advance(100_000_000)
    emu.status()
    assert abs(emu.state.x[3]) < abs(arm_dot_49)
    # a new command re-arms it
    emu.handle(P.command_frame(3, 0.1))
    assert not emu.status()["watchdog_tripped"]


def test_emulator_holds_the_pendulum_upright_until_the_first_command(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    (ack,) = emu.handle(P.encode(P.MSG_HELLO, 0))
    info = P.parse_hello_ack(P.decode(ack))
    assert info.adc_bits == 12 and info.watchdog_ms == 50 and info.status & P.STATUS_HELD
    clock.advance(1_000_000_000)
    st_ = emu.status()
    assert st_["held"] and st_["theta"] == pytest.approx(cfg.sim.initial_angle)
    emu.handle(P.command_frame(1, 0.0))
    clock.advance(300_000_000)
    assert emu.status()["theta"] > cfg.sim.initial_angle  # now it falls


def test_emulator_rejects_unknown_faults(cfg):
    emu = RigEmulator(cfg, FakeClock())
    assert not emu.control({"cmd": "fault", "meteor": 1})["ok"]
    assert not emu.control({"cmd": "fault", "nan": 0.5})["ok"]
    assert not emu.control({"cmd": "reboot"})["ok"]
    assert emu.control({"cmd": "fault", "nan": 2})["ok"]
    assert emu.control({"cmd": "clear"})["ok"]


def test_framed_rig_checks_sequence_numbers(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    rig = FramedRig(DirectTransport(emu, clock), "direct", clock=clock)
    rig.open()
    assert rig.sample(0, clock.now_ns() + 2_500_000) is not None
    emu.control({"cmd": "fault", "drop": 1})
    assert rig.sample(1, clock.now_ns() + 2_500_000) is None      # timed out ...
    assert rig.sample(2, clock.now_ns() + 2_500_000) is not None  # ... and carries on
    emu.control({"cmd": "fault", "seq_offset": 5})
    with pytest.raises(BadReading, match="out-of-order"):
        rig.sample(3, clock.now_ns() + 2_500_000)


class _PausingTransport(DirectTransport):
    """The first wait for a reply overshoots its deadline (a host pause of ``pause_ms``)
    while the emulator, sharing the paused CPU, has not yet answered."""

    def __init__(self, emulator, clock, pause_ms):
        super().__init__(emulator, clock)
        self.pause_ns = int(pause_ms * 1e6)
        self.held: list[bytes] = []

    def send(self, data):
        super().send(data)
        if self.pause_ns:
            self.held, self._replies = list(self._replies), type(self._replies)()

    def recv(self, deadline_ns):
        if self.pause_ns:
            self.clock.advance(deadline_ns - self.clock.now_ns() + self.pause_ns)
            self.pause_ns = 0
            self._replies.extend(self.held)  # the rig runs once the CPU is back
            return None
        return super().recv(deadline_ns)


@pytest.mark.parametrize("pause_ms", [0.5, 20.0])
def test_a_host_pause_during_the_wait_is_not_a_silent_rig(cfg, pause_ms):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    transport = _PausingTransport(emu, clock, 0.0)
    rig = FramedRig(transport, "direct", clock=clock)
    rig.open()
    transport.pause_ns = int(pause_ms * 1e6)
    reading = rig.sample(0, clock.now_ns() + 2_500_000)
    if pause_ms * 1e6 > rig.pause_ns:   # overshoot beyond pause_ns: the reply gets its grace
        assert reading is not None and rig.paused_waits == 1
    else:                               # a short overshoot is an ordinary timeout
        assert reading is None and rig.paused_waits == 0
        assert rig.sample(1, clock.now_ns() + 2_500_000) is not None  # late reply discarded
        assert rig.late_replies == 1


class _LaggingTransport(DirectTransport):
    """While ``lag`` is set the rig's replies are held back (a rig process the host does
    not schedule); ``release`` delivers them all, oldest first."""

    def __init__(self, emulator, clock):
        super().__init__(emulator, clock)
        self.lag = False
        self.held: list[bytes] = []

    def send(self, data):
        super().send(data)
        if self.lag:
            self.held.extend(self._replies)
            self._replies.clear()

    def release(self):
        self._replies.extend(self.held)
        self.held = []


@pytest.mark.parametrize("behind", [3, 200, 1000])
def test_replies_late_by_as_many_ticks_as_the_loop_tolerates_are_dropped_as_late(cfg, behind):
    # the loop lets up to Safety.unread_limit (at most 1000) ticks pass without a timely
    # reading: the replies to all of them, arriving late, are late replies, not a broken rig
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    transport = _LaggingTransport(emu, clock)
    rig = FramedRig(transport, "direct", clock=clock)
    rig.open()
    transport.lag = True
    for k in range(behind):
        assert rig.sample(k, clock.now_ns() + 2_500_000) is None
    transport.lag = False
    transport.release()
    assert rig.sample(behind, clock.now_ns() + 2_500_000) is not None
    assert rig.late_replies == behind


def test_a_reply_older_than_any_request_the_rig_remembers_is_a_bad_reading(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    transport = _LaggingTransport(emu, clock)
    rig = FramedRig(transport, "direct", clock=clock)
    rig.open()
    assert rig.sample(0, clock.now_ns() + 2_500_000) is not None
    emu.control({"cmd": "fault", "seq_offset": -1})  # the rig repeats an answered number
    with pytest.raises(BadReading, match="duplicated or stale"):
        rig.sample(1, clock.now_ns() + 2_500_000)


def test_a_silent_rig_still_times_out_after_a_pause(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    transport = _PausingTransport(emu, clock, 0.0)
    rig = FramedRig(transport, "direct", clock=clock)
    rig.open()
    emu.control({"cmd": "fault", "silent": -1})
    transport.pause_ns = 20_000_000
    deadline = clock.now_ns() + 2_500_000
    assert rig.sample(0, deadline) is None
    assert rig.paused_waits == 1
    assert clock.now_ns() >= deadline + 20_000_000 + rig.grace_ns  # waited out the grace


def test_open_rig_parses_backends(cfg):
    assert isinstance(open_rig("sim", cfg), SimRig)
    for bad in ("tcp://x:1", "udp://nohost", "serial://", "bogus"):
        with pytest.raises(ValueError):
            open_rig(bad, cfg)


@pytest.fixture
def udp_rig_sim(cfg):
    from frictionlab.realtime.clock import MonotonicClock

    emu = RigEmulator(cfg, MonotonicClock())
    stop = threading.Event()
    addr = {}
    ready = threading.Event()

    def on_ready(a):
        addr["a"] = a
        ready.set()

    th = threading.Thread(target=serve_udp, args=(emu, "127.0.0.1", 0, stop, on_ready),
                          kwargs={"prewarm_us": 0}, daemon=True)
    th.start()
    assert ready.wait(10)
    yield emu, addr["a"]
    stop.set()
    th.join(5)


def test_udp_backend_talks_to_the_emulator(cfg, udp_rig_sim):
    from frictionlab.realtime.rigsim import send_control

    _emu, (host, port) = udp_rig_sim
    rig = open_rig(f"udp://{host}:{port}", cfg)
    rig.open()
    try:
        assert rig.emulated and rig.info.watchdog_ms == 50
        readings = []
        for k in range(5):
            # generous deadlines: this checks the exchange, not its timing
            r = rig.sample(k, time.monotonic_ns() + 1_000_000_000)
            readings.append(r)
            rig.write(k, 0.01)
        assert all(r is not None for r in readings)
        theta = [np.pi * (r.y + 0.503) for r in readings]
        assert theta[0] == pytest.approx(cfg.sim.initial_angle, abs=np.pi * Q)
        st_ = send_control(host, port, {"cmd": "status"})
        assert st_["last_command_seq"] == 4 and st_["u_da"] == pytest.approx(0.01)
        rig.push(0.5)
        assert any(a["fault"] == "push" for a in send_control(host, port,
                                                              {"cmd": "status"})["applied"])
    finally:
        rig.close()
    assert send_control(host, port, {"cmd": "status"})["u_da"] == 0.0  # close zeroes


def test_udp_backend_without_a_rig_fails_to_open(cfg):
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rig = open_rig(f"udp://127.0.0.1:{port}", cfg)
    rig.hello_timeout = 0.3
    with pytest.raises(RigError, match="no answer"):
        rig.open()


def test_serial_backend_over_a_pty_pair(cfg):
    from frictionlab.realtime.clock import MonotonicClock

    master, slave = os.openpty()
    tty.setraw(slave)
    # a watchdog far beyond a stalled host's pauses: this checks the exchange, and the
    # watchdog is tested on a fake clock (test_emulator_watchdog_zeroes_the_motor_after_50_ms)
    emu = RigEmulator(cfg, MonotonicClock(), watchdog=5.0)
    stop = threading.Event()
    th = threading.Thread(target=serve_stream, args=(emu, master, stop), daemon=True)
    th.start()
    rig = open_rig(f"serial://{os.ttyname(slave)}?baud=115200", cfg)
    try:
        rig.open()
        assert rig.info.adc_bits == 12
        for k in range(5):
            r = rig.sample(k, time.monotonic_ns() + 1_000_000_000)
            assert r is not None and r.status & P.STATUS_EMULATED
            rig.write(k, -0.02)
        deadline = time.monotonic() + 5
        while emu.last_command_seq != 4 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert emu.last_command_seq == 4 and emu.u_da == pytest.approx(-0.02)
        # a corrupted frame on the line is a bad reading; the stream then resynchronises
        emu.control({"cmd": "fault", "corrupt": 1})
        with pytest.raises(BadReading, match="corrupt"):
            rig.sample(5, time.monotonic_ns() + 1_000_000_000)
        assert rig.sample(6, time.monotonic_ns() + 1_000_000_000) is not None
    finally:
        rig.close()
        stop.set()
        th.join(5)
        os.close(master)
        os.close(slave)
