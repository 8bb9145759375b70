"""The 200 Hz loop with a motor plant (``--plant qube2``): u in volts through the DAC law
u_DA = sat(u / 10 V), the emulated motor rig (encoders of 2048 counts per turn), and
every path that starts, stops or changes the motor command with the fault injected
(fake clock, no sleeping; the thesis plant's versions are tests/test_realtime_safety.py).
"""

import json
import math
import time

import numpy as np
import pytest
from test_realtime_bumpless import switch_in_the_loop
from test_realtime_safety import check_stopped, fault_tick, run_with_emulator

from frictionlab.cli.common import plant_from_args
from frictionlab.config import build_config
from frictionlab.model.sensor import dac, encoder_step
from frictionlab.realtime import FakeClock, RealtimeController, Safety
from frictionlab.realtime.rigs import SimRig


@pytest.fixture(scope="module")
def cfg():
    return build_config("fast", "classical", plant="qube2")


def test_a_motor_plants_rig_is_in_volts_with_a_qubes_encoders(cfg):
    assert cfg.rig.u_scale == pytest.approx(0.1) and cfg.u_limit == 10.0
    # one encoder count of 2048 per turn is the converter's grid on both angle channels
    assert cfg.sensor_step * cfg.rig.theta_scale == pytest.approx(2 * math.pi / 2048)
    assert encoder_step(2048, math.pi) == pytest.approx(2 / 2048)
    # upright and hanging a quarter turn from the raw channel's wrap
    assert cfg.rig.raw_theta(0.0) == pytest.approx(-0.5)
    assert cfg.rig.raw_theta(math.pi) == pytest.approx(0.5)
    assert float(cfg.rig.theta(cfg.rig.raw_theta(-3.0))) == pytest.approx(2 * math.pi - 3.0)
    # controller.u_max lowers the limit; the DAC's range (rig.u_scale) bounds it too
    assert cfg.with_values({"controller.u_max": 4.0}).u_limit == 4.0
    assert cfg.with_values({"rig.u_scale": 0.2}).u_limit == 5.0


@pytest.mark.slow
def test_balances_in_a_limit_cycle_within_10_volts_through_the_emulated_rig(cfg, tmp_path):
    """The emulated rig with the QUBE's encoders: balanced in a small friction cycle
    (the default pendulum observer: a few encoder counts, as the simulator's theta
    peak 0.007 rad), |u| within 10 V, u_DA = u / 10 V in every tick; the sidecar
    names the plant and u's unit."""
    _ctl, emu, _tx, stats, log, meta = run_with_emulator(cfg, tmp_path, duration=4.0)
    assert stats["stop_reason"] == "duration" and emu.u_da == 0.0
    th, u, uda = log["theta_m"][:-1], log["u"][:-1], log["u_da"][:-1]
    assert 0.0 < np.max(np.abs(th[-300:])) < 0.05  # moving by counts, not falling
    assert 0.0 < np.max(np.abs(u[-300:])) and np.max(np.abs(u)) < 10.0
    np.testing.assert_allclose(uda, [dac.py_func(v, 0.1) for v in u], rtol=1e-8)  # 9 digits
    # the angles arrive on the encoder's grid (one count 2 pi / 2048)
    counts = th / (2 * math.pi / 2048)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert (meta["plant"], meta["u_unit"]) == ("qube2", "V")
    assert meta["config"]["plant_kind"] == "qube2"


@pytest.mark.parametrize("faults, reason", [
    ({"nan": 1}, "bad_reading"),
    ({"silent": 1.0}, "rig_silent"),
    ({"push": 6.0}, "angle_limit"),
])
def test_rig_faults_stop_the_motor_plant_within_two_ticks(cfg, tmp_path, faults, reason):
    _ctl, emu, tx, stats, log, meta = run_with_emulator(cfg, tmp_path, faults, duration=2.0)
    k_fault = fault_tick(stats)
    if reason == "angle_limit":  # the push takes a few ticks to throw it past the limit
        k_fault = int(log["tick"][-1])
        assert stats["stop_tick"] > fault_tick(stats)
    check_stopped(emu, tx, stats, log, meta, reason, k_fault)
    assert np.nanmax(np.abs(log["u"])) <= 10.0  # NaN: the ticks without a reading


def test_controller_u_max_limits_the_volts_and_a_stop_request_zeroes_them(cfg, tmp_path):
    """``controller.u_max`` 2 V: every command within it (u_DA within 0.2); a stop asked
    for (the signal handler's way) at 1.5 s zeroes the motor in the next tick."""
    low = cfg.with_values({"controller.u_max": 2.0, "sim.initial_angle": 0.1})

    def on_clock(clock, ctl):
        clock.call_at(clock.now_ns() + 5_000_000 * 301 + 1_000_000,
                      lambda: ctl.stop("signal"))

    _ctl, emu, _tx, stats, log, _meta = run_with_emulator(low, tmp_path, duration=3.0,
                                                          on_clock=on_clock)
    assert stats["stop_reason"] == "signal" and stats["stop_tick"] == 301
    assert emu.u_da == 0.0 and emu.last_command_seq == 301
    assert np.max(np.abs(log["u"][:-1])) == pytest.approx(2.0)  # saturated at the start
    assert np.max(np.abs(log["u_da"])) <= 0.2 + 1e-12


def test_not_upright_and_an_exception_stop_the_motor_plant(cfg, tmp_path):
    tilted = cfg.with_values({"sim.initial_angle": 0.3})
    _ctl, emu, _tx, stats, _log, _meta = run_with_emulator(
        tilted, tmp_path / "a", safety=Safety(start_tolerance=0.2), duration=1.0)
    assert stats["stop_reason"] == "not_upright" and stats["stop_tick"] == 0
    assert emu.u_da == 0.0

    class Broken(SimRig):
        def sample(self, k, deadline_ns):
            if k == 100:
                raise RuntimeError("tachometer cable unplugged")
            return super().sample(k, deadline_ns)

    rig = Broken(cfg)
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path / "b", clock=FakeClock(),
                             duration=1.0, realtime=False, manage_gc=False)
    st = ctl.run()
    assert st["stop_reason"] == "exception" and st["stop_tick"] == 100
    assert rig.u_da == 0.0 and rig._u == 0.0
    with open(st["log_files"]["json"]) as fh:
        assert json.load(fh)["plant"] == "qube2"


@pytest.mark.slow
def test_the_loop_swings_the_motor_plant_up_within_10_volts(cfg, tmp_path):
    """``run --plant qube2 --swing-up`` on the sim backend (lockstep, fake clock): from
    hanging, swung up within the voltage limit and caught, then balanced (|theta| <
    0.2 rad over the last 2 s); the log marks the phases."""
    from frictionlab.realtime.samples import SWINGING_FLAG

    hanging = cfg.with_values({"sim.initial_angle": math.pi})
    ctl = RealtimeController(hanging, SimRig(hanging, lockstep=True), log_dir=None,
                             clock=FakeClock(), duration=5.0, realtime=False,
                             manage_gc=False, swing_up=True)
    sub = ctl.subscribe(maxlen=2000)
    st = ctl.run()
    assert st["stop_reason"] == "duration", st
    assert st["swing_up"]["phase"] == "balancing" and st["swing_up"]["swing_up_time"] < 3.0
    s = [x for x in sub.drain() if np.isfinite(x.theta_m)]
    assert any(x.flags & SWINGING_FLAG for x in s)
    th = np.array([math.remainder(x.theta_m, 2 * math.pi) for x in s])
    assert np.max(np.abs(th[-400:])) < 0.2
    assert max(abs(x.u) for x in s) <= 10.0


def test_a_qube_backend_implies_its_plant():
    def plant(plant, backend):
        return plant_from_args(type("Args", (), {"plant": plant, "backend": backend})())

    assert plant(None, "qube2://0") == "qube2"
    assert plant(None, "qube3://0?wait=upright") == "qube3"
    assert plant(None, "sim") == "thesis"
    assert plant("furuta-dc", "qube2://0") == "furuta-dc"  # as asked, with a note
    assert plant("thesis", "qube2://0") == "thesis"


@pytest.mark.slow
def test_a_motor_rig_over_a_serial_line(cfg):
    """``--plant furuta-dc --backend serial://PTY`` (the home-built rig's way): the
    emulated motor rig behind a pseudo-terminal answers on the encoder's grid and
    applies u_DA as u_DA / 0.1 volts; the stop's 0 reaches it.  (The exchange only: the
    whole loop over a line is the firmware's HIL test, the loop with a motor plant the
    tests above.)"""
    import os
    import threading
    import tty

    from frictionlab.realtime.clock import MonotonicClock
    from frictionlab.realtime.rigs import open_rig
    from frictionlab.realtime.rigsim import RigEmulator, serve_stream

    dc = build_config("fast", "classical", plant="furuta-dc")
    master, slave = os.openpty()
    tty.setraw(slave)
    emu = RigEmulator(dc, MonotonicClock(), watchdog=5.0)  # the exchange, not the watchdog
    stop = threading.Event()
    th = threading.Thread(target=serve_stream, args=(emu, master, stop), daemon=True)
    th.start()
    rig = open_rig(f"serial://{os.ttyname(slave)}", dc)
    try:
        rig.open()
        thetas = []
        for k in range(5):
            r = rig.sample(k, time.monotonic_ns() + 1_000_000_000)
            thetas.append(float(dc.rig.theta(r.y)))
            rig.write(k, 0.35 if k < 4 else 0.0)
            deadline = time.monotonic() + 5
            while emu.last_command_seq != k and time.monotonic() < deadline:
                time.sleep(0.005)
            assert emu.u_da == pytest.approx(0.35 if k < 4 else 0.0)
            assert emu._u == pytest.approx(3.5 if k < 4 else 0.0)  # volts
    finally:
        rig.close()
        stop.set()
        th.join(5)
        os.close(master)
        os.close(slave)
    step = 2 * math.pi / 2048  # one count of the QUBE's encoder
    np.testing.assert_allclose(np.array(thetas) / step, np.round(np.array(thetas) / step),
                               atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("change", [{"compensation": "lugre"},
                                   {"design": {"omega1": 14.0}}],
                         ids=["compensation_on", "design"])
def test_a_switch_while_the_motor_plant_runs_is_bumpless_and_the_simulators(cfg, change):
    """A compensator switched on or new gains while the QUBE balances: u (V) does not jump
    beyond the cycle's own (max |u| over 0.3 s after the switch at most 1.1 times that
    over the 5 s before), and the loop's run is the simulator's, tick for tick."""
    from frictionlab.realtime.params import ControlParams
    from frictionlab.runs import simulate_config

    h, t_switch = 0.005, 5.3
    after = ControlParams.from_config(cfg).apply(change)
    u, k = switch_in_the_loop(cfg, change, t_switch, h)
    a = np.abs(u)
    assert a[k:k + 60].max() <= 1.1 * a[k - 1000:k].max()
    tr = simulate_config(cfg, t_switch + 0.5, switches=[(k * h, after.controller)])
    np.testing.assert_allclose(u, tr["u"], rtol=0, atol=1e-6)
