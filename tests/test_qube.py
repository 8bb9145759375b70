"""The QUBE-Servo backend (``--backend qube2://ID``) against the emulated board.

In-process, on a fake clock that is also the board's time (tests/fake_quanser:
an independent QUBE-Servo 2 model, its watchdog, its faults and a record of
every call).  The real-process runs (signals, SIGSTOP) are in
test_qube_acceptance.py.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from qube_helpers import (
    calls_of,
    check_safe_sequence,
    index,
    load_fake,
    pendulum_from_upright,
    unload_fake,
    voltages,
)

from frictionlab.config import build_config
from frictionlab.model.params import ParamError
from frictionlab.realtime import FakeClock, RealtimeController, RigError
from frictionlab.realtime.qube import QUBE_RIG, QubeRig, parse_qube
from frictionlab.realtime.rigs import open_rig, parse_backend

H_NS = 5_000_000


@pytest.fixture
def clock():
    return FakeClock()


@pytest.fixture
def hw(clock, monkeypatch):
    """The emulated ``quanser.hardware`` on this test's fake clock."""
    monkeypatch.delenv("FAKE_QUANSER_FAULTS", raising=False)
    monkeypatch.delenv("FAKE_QUANSER_STATE", raising=False)
    monkeypatch.delenv("FAKE_QUANSER_LOG", raising=False)
    mod = load_fake(clock)
    yield mod
    unload_fake()


def qube_cfg(*sets):
    return build_config(sets=[*QUBE_RIG.items(), *sets])


def run(clock, tmp_path, backend="qube2://0", duration=1.0, cfg=None, **kw):
    ctl = RealtimeController(cfg or qube_cfg(), backend, log_dir=tmp_path, clock=clock,
                             realtime=False, duration=duration, **kw)
    return ctl, ctl.run()


# --- the backend string ---------------------------------------------------------------


def test_backend_strings_parse_and_refuse():
    assert parse_backend("qube2://0") == ("qube2", "0", None)
    assert parse_backend("qube3://1") == ("qube3", "1", None)
    assert parse_qube("qube2://0?watchdog=0.2&wait=upright")[2] == {"watchdog": 0.2,
                                                                     "wait": "upright"}
    for bad in ("qube2://", "qube4://0", "qube2://0/x", "qube2://0?watchdog=0",
                "qube2://0?watchdog=x", "qube2://0?speed=3"):
        with pytest.raises(ParamError) as err:
            parse_backend(bad)
        assert err.value.field == "backend"
    cfg = qube_cfg()
    assert isinstance(open_rig("qube3://0", cfg), QubeRig)
    assert open_rig("qube3://0", cfg).board_type == "qube_servo3_usb"


@pytest.mark.slow
def test_without_the_sdk_the_command_says_what_to_install(cli, tmp_path, monkeypatch):
    unload_fake()
    monkeypatch.setitem(sys.modules, "quanser", None)  # not installed
    res = cli("run", "--backend", "qube2://0", "--headless", "--duration", "1", "--json",
              "--log-dir", str(tmp_path / "logs"))
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "quanser_api" in lines[0] and "Quanser SDK" in lines[0]
    assert not list((tmp_path / "logs").glob("*.csv")) if (tmp_path / "logs").exists() else 1


def test_a_qube_backend_implies_volts_and_its_channels(cli, tmp_path, monkeypatch):
    """``--backend qube2://0`` applies the rig values the board implies before --set."""
    from frictionlab.cli.common import backend_rig_items

    class A:
        backend = "qube2://0"

    assert dict(backend_rig_items(A)) == QUBE_RIG
    assert QUBE_RIG["rig.u_scale"] == pytest.approx(0.1)
    A.backend = "udp://127.0.0.1:5000"
    assert backend_rig_items(A) == []


# --- readings and signs -----------------------------------------------------------------


def open_rig_on(hw, clock, *sets, spec="qube2://0"):
    rig = QubeRig(spec, qube_cfg(*sets))
    rig.open(h=0.005)
    return rig, hw.BOARDS[-1]


def si(rig, reading):
    """What the loop makes of a reading (the one sensor law, the run's rig.* values)."""
    sc = rig.cfg.rig
    return (sc.theta(reading.y), sc.arm_velocity(reading.v))


def test_readings_follow_the_documented_signs(hw, clock, monkeypatch):
    monkeypatch.setenv("FAKE_QUANSER_STATE", '{"pendulum": 0.0}')
    rig, board = open_rig_on(hw, clock)
    r = rig.sample(0, 0)
    theta, _ = si(rig, r)
    assert abs(math.remainder(float(theta), 2 * math.pi)) == pytest.approx(math.pi)
    # a positive voltage step from hanging at rest: encoder 0 up, encoder 1 down at first
    rig.write(0, 0.5)  # 5 V
    assert board.enabled and board.voltage == pytest.approx(5.0)
    for k in range(1, 9):
        clock.advance(H_NS)
        r = rig.sample(k, 0)
        rig.write(k, 0.5)
    assert board.encoder(0) > 0 and board.encoder(1) < 0
    # the project's signs (eq. 6): the arm moved positively, hanging theta rose above pi
    theta, arm_dot = si(rig, r)
    assert rig.cfg.rig.arm_scale * (r.x - 0.0) > 0 and arm_dot > 0
    assert float(theta) % (2 * math.pi) > math.pi
    assert float(theta) % (2 * math.pi) == pytest.approx(
        pendulum_from_upright(board.encoder(1)) % (2 * math.pi), abs=1e-12)
    rig.close()


@pytest.mark.parametrize("arm_sign,pendulum_sign", [(-1, 1), (1, -1)])
def test_rig_signs_flip_an_encoder(hw, clock, monkeypatch, arm_sign, pendulum_sign):
    monkeypatch.setenv("FAKE_QUANSER_STATE", '{"pendulum": 0.4, "arm_rate": 2.0}')
    rig, board = open_rig_on(hw, clock, ("rig.arm_sign", arm_sign),
                             ("rig.pendulum_sign", pendulum_sign))
    clock.advance(H_NS)
    r = rig.sample(0, 0)
    board.encoder(1)
    theta, arm_dot = si(rig, r)
    tach = board.other_in(14000)
    assert float(arm_dot) == pytest.approx(arm_sign * tach * 2 * math.pi / 2048, rel=1e-12)
    # zeroed at open with the pendulum at 0.4 rad: it reads as hanging, flipped or not
    assert float(theta) % (2 * math.pi) == pytest.approx(
        pendulum_from_upright(board.encoder(1), pendulum_sign) % (2 * math.pi), abs=1e-12)
    rig.close()


# --- the safe sequence ------------------------------------------------------------------


@pytest.mark.slow
def test_a_swing_up_run_keeps_the_safe_sequence(hw, clock, tmp_path):
    """Watchdog armed before the amplifier, amplifier before volts, |V| <= 10, the end."""
    _ctl, st = run(clock, tmp_path, duration=1.5, swing_up=True)
    assert st["stop_reason"] == "duration"
    board = hw.BOARDS[-1]
    calls = calls_of(board)
    check_safe_sequence(calls)
    vs = [v for _i, _m, v in voltages(calls)]
    assert max(abs(v) for v in vs) > 1.0  # the swing-up drove the motor
    assert board.closed and not board.enabled and board.voltage == 0.0
    assert st["watchdog_reloads"] == st["ticks"] - 1  # every tick after the first
    assert board.led == [0.0, 0.0, 1.0]  # blue: stopped without a board fault


def test_a_stop_while_opening_never_enables(hw, clock, tmp_path, monkeypatch):
    """A signal while the board is being opened: the run stops at tick 0 with 0 V."""
    ctl = RealtimeController(qube_cfg(), "qube2://0", log_dir=tmp_path, clock=clock,
                             realtime=False, duration=1.0, swing_up=True)
    real_open = QubeRig.open

    def open_then_signal(self, h=None, cancel=None):
        real_open(self, h, cancel)
        ctl.stop("signal", "SIGINT")

    monkeypatch.setattr(QubeRig, "open", open_then_signal)
    st = ctl.run()
    assert st["stop_reason"] == "signal"
    calls = calls_of(hw.BOARDS[-1])
    assert index(calls, "write_digital", lambda a: a[1][0] == 1) is None
    assert all(v == 0.0 for _i, _m, v in voltages(calls))
    check_safe_sequence(calls)


def test_a_stop_request_zeroes_the_motor_at_the_next_tick(hw, clock, tmp_path):
    ctl = RealtimeController(qube_cfg(), "qube2://0", log_dir=tmp_path, clock=clock,
                             realtime=False, duration=0.6, swing_up=True)
    t_sig = []

    def signal():
        t_sig.append(clock.now_ns())
        ctl.stop("signal", "SIGINT")

    clock.call_at(clock.now_ns() + 300_000_000 + H_NS // 3, signal)
    st = ctl.run()
    assert st["stop_reason"] == "signal"
    calls = calls_of(hw.BOARDS[-1])
    t0 = hw.BOARDS[-1].t0
    after = [v for _i, m, v in voltages(calls) if m > (t_sig[0] - t0) / 1e9]
    assert after and all(v == 0.0 for v in after[1:])  # at most the tick in flight
    assert any(v != 0.0 for _i, m, v in voltages(calls) if m < (t_sig[0] - t0) / 1e9)
    check_safe_sequence(calls)


# --- board faults --------------------------------------------------------------------------


@pytest.mark.parametrize("fault,reason", [("amplifier_fault", "amplifier_fault"),
                                          ("stall", "motor_stall"),
                                          ("stall_error", "motor_stall")])
def test_a_board_fault_stops_the_run(hw, clock, tmp_path, monkeypatch, fault, reason):
    monkeypatch.setenv("FAKE_QUANSER_FAULTS", f'{{"{fault}_at": 0.3}}')
    _ctl, st = run(clock, tmp_path, duration=0.6, swing_up=True)
    assert st["stop_reason"] == reason and st["board_fault"] == reason
    board = hw.BOARDS[-1]
    calls = calls_of(board)
    t_fault = next(c[0] for c in calls if c[2] == "event" and c[3][0] == fault)
    after = [v for _i, m, v in voltages(calls) if m >= t_fault]
    assert after and all(v == 0.0 for v in after)  # the tick that reads it writes 0
    assert any(v != 0.0 for _i, m, v in voltages(calls) if m < t_fault)
    enables = [i for i, c in enumerate(calls) if c[2] == "write_digital" and c[3][1] == [1]]
    assert len(enables) == 1
    check_safe_sequence(calls)
    assert board.led == [1.0, 0.0, 0.0]  # red: the board stopped the run


def test_an_expired_watchdog_zeroes_the_motor_and_stops_the_run(hw, clock, tmp_path):
    """A controller that does not reload in time (a 30 ms gap, under the loop's own
    50 ms pause limit): the board zeroes the motor, the next tick stops, nothing is
    enabled again."""
    gap_at = []

    def latency(deadline):
        if not gap_at and deadline > clock_start + 300_000_000:
            gap_at.append(deadline)
            return 30_000_000
        return 0

    clock_start = 1_000_000_000
    clk = FakeClock(clock_start, wake_latency=latency)
    hw.CLOCK = clk.now_ns
    _ctl, st = run(clk, tmp_path, backend="qube2://0?watchdog=0.02", duration=0.6,
                  swing_up=True)
    assert st["stop_reason"] == "watchdog_expired"
    board = hw.BOARDS[-1]
    calls = calls_of(board)
    expired = index(calls, "event", lambda a: a[0] == "watchdog_expired")
    assert expired is not None
    t_exp = calls[expired][0]
    assert calls[expired][3][1] == {"voltage": 0.0, "enabled": False}
    # the board zeroed the motor at its own time, within the timeout of the last reload
    last_reload = max(c[0] for c in calls[:expired] if c[2] == "watchdog_reload")
    assert t_exp == pytest.approx(last_reload + 0.02, abs=1e-6)
    assert index(calls[expired:], "write_digital", lambda a: a[1][0] == 1) is None
    assert all(v == 0.0 for _i, _m, v in voltages(calls[expired:]))
    check_safe_sequence(calls)


def test_a_board_error_on_a_read_stops_as_rig_fault(hw, clock, tmp_path, monkeypatch):
    n = [0]
    real = hw.HIL.read_encoder

    def flaky(self, *args):
        n[0] += 1
        if n[0] == 50:
            raise hw.HILError(-1, "USB transfer failed")
        return real(self, *args)

    monkeypatch.setattr(hw.HIL, "read_encoder", flaky)
    _ctl, st = run(clock, tmp_path, duration=0.6, swing_up=True)
    assert st["stop_reason"] == "rig_fault" and "USB transfer failed" in st["stop_detail"]
    check_safe_sequence(calls_of(hw.BOARDS[-1]))


def test_open_refuses_a_board_in_fault_and_closes_it(hw, clock, monkeypatch):
    monkeypatch.setenv("FAKE_QUANSER_FAULTS", '{"amplifier_fault_at": 0.0}')
    rig = QubeRig("qube2://0", qube_cfg())
    with pytest.raises(RigError, match="amplifier fault"):
        rig.open(h=0.005)
    assert hw.BOARDS[-1].closed
    with pytest.raises(RigError, match="cannot open"):
        QubeRig("qube2://7", qube_cfg()).open(h=0.005)
    with pytest.raises(RigError, match="shorter than two periods"):
        QubeRig("qube2://0?watchdog=0.005", qube_cfg()).open(h=0.005)


def test_close_tries_every_step_after_the_watchdog_expired(hw, clock):
    rig, board = open_rig_on(hw, clock)
    rig.sample(0, 0)
    rig.write(0, 0.3)
    clock.advance(100_000_000)  # no reload: the board expires
    rig.close()
    calls = calls_of(board)
    names = [c[2] for c in calls]
    assert "watchdog_expired" in [c[3][0] for c in calls if c[2] == "event"]
    assert names[-1] == "close" and "watchdog_stop" in names
    assert not board.enabled and board.voltage == 0.0 and board.closed
    rig.close()  # twice is harmless
    assert [c[2] for c in calls_of(board)].count("close") == 1


def test_wait_upright_starts_when_the_pendulum_is_lifted(hw, clock, monkeypatch):
    """``?wait=upright``: the thesis's start; the motor stays off while waiting."""
    rig = QubeRig("qube2://0?wait=upright", qube_cfg())
    polls = [0]

    def cancel():
        polls[0] += 1
        if polls[0] == 3 and hw.BOARDS:
            b = hw.BOARDS[-1]  # the hand lifts the pendulum to 0.05 rad from upright
            b.x = (b.x[0], 0.05, 0.0, 0.0)
        return polls[0] > 50

    monkeypatch.setattr("frictionlab.realtime.qube.time.sleep", lambda s: clock.advance(10**7))
    rig.open(h=0.005, cancel=cancel)
    assert polls[0] == 3
    r = rig.sample(0, 0)
    assert abs(float(rig.cfg.rig.theta(r.y))) < 0.1
    assert not hw.BOARDS[-1].enabled
    rig.close()


# --- the emulation itself (an independent model: check it against closed forms) ------


def test_emulated_plant_conserves_energy_without_damping(hw, monkeypatch):
    monkeypatch.setattr(hw, "D_R", 0.0)
    monkeypatch.setattr(hw, "D_P", 0.0)
    x = (0.0, 2.0, 3.0, -1.0)  # a large swing with the arm turning
    e0 = hw.energy(x)
    for _ in range(10000):  # 10 s, amplifier off
        x = hw.rk4(x, None, 0.001)
    assert abs(hw.energy(x) - e0) <= 1e-6 * abs(e0)


def test_emulated_hanging_swing_has_the_closed_form_period(hw, monkeypatch):
    """Small swings with the arm free (amplifier off, no damping):
    omega^2 = (m_p g L_p/2) / (J_p - a^2/J_0) from the linearised equations."""
    monkeypatch.setattr(hw, "D_R", 0.0)
    monkeypatch.setattr(hw, "D_P", 0.0)
    j_r = hw.M_R * hw.L_R**2 / 3
    j_p = hw.M_P * hw.L_P**2 / 3
    a = hw.M_P * hw.L_R * hw.L_P / 2
    j0 = j_r + hw.M_P * hw.L_R**2
    omega = math.sqrt(0.5 * hw.M_P * hw.G * hw.L_P / (j_p - a * a / j0))
    x = (0.0, math.pi + 1e-3, 0.0, 0.0)
    dt, t, prev, ups = 0.001, 0.0, x[1] - math.pi, []
    while len(ups) < 6:
        x = hw.rk4(x, None, dt)
        t += dt
        d = x[1] - math.pi
        if prev < 0 <= d:
            ups.append(t - dt * d / (d - prev))
        prev = d
    period = np.mean(np.diff(ups))
    assert period == pytest.approx(2 * math.pi / omega, rel=1e-4)


def test_emulated_board_refuses_what_the_sdk_refuses(hw, clock):
    card = hw.HIL("qube_servo2_usb", "0")
    ch = np.array([0], dtype=np.uint32)
    with pytest.raises(TypeError):
        card.write_analog(ch, 1, np.zeros(1, dtype=np.float32))
    with pytest.raises(hw.HILError):
        card.watchdog_start(0.1)  # no expiration state set
    card.watchdog_set_analog_expiration_state(ch, 1, np.zeros(1))
    card.watchdog_start(0.1)
    card.write_analog(ch, 1, np.array([3.0]))
    clock.advance(150_000_000)
    assert card.watchdog_is_expired() and hw.BOARDS[-1].voltage == 0.0
    with pytest.raises(hw.HILError):
        card.write_analog(ch, 1, np.array([3.0]))
    assert card.watchdog_reload() is False
    card.close()
    with pytest.raises(hw.HILError):
        hw.HIL("qube_servo2_usb", "5")


def test_a_write_the_expired_board_refuses_stops_the_next_tick(hw, clock):
    """Suspended between a tick's reading and its output (SIGSTOP): the board has
    zeroed the motor and refuses the late command; the next tick stops as
    ``watchdog_expired`` without enabling anything again."""
    from frictionlab.realtime.qube import RigStop

    rig, board = open_rig_on(hw, clock)
    rig.sample(0, 0)
    rig.write(0, 0.3)
    clock.advance(100_000_000)  # the process was stopped here
    rig.write(1, 0.3)  # refused, not raised
    with pytest.raises(RigStop) as stop:
        rig.sample(2, 0)
    assert stop.value.reason == "watchdog_expired"
    rig.write(2, 0.0)
    rig.close()
    calls = calls_of(board)
    expired = index(calls, "event", lambda a: a[0] == "watchdog_expired")
    assert index(calls[expired:], "write_digital", lambda a: a[1][0] == 1) is None
    assert board.voltage == 0.0 and not board.enabled
    check_safe_sequence(calls)


# --- the identification workflow on a QUBE (docs/qube.md) ---------------------------------


def identify_on_qube(clock, tmp_path, name, **options):
    from frictionlab.studies.identification.onrig import (
        analyse_run,
        make_rig_experiment,
        run_on_rig,
    )

    cfg = qube_cfg(("design.omega0", 10.68), ("plant.omega0", 10.68))
    exp = make_rig_experiment(name, cfg, **options)
    st = run_on_rig(exp, cfg, "qube2://0", log_dir=tmp_path, clock=clock, realtime=False)
    assert st["stop_reason"] == "finished", st["stop_detail"]
    return analyse_run(name, st["log"], cfg)


@pytest.mark.slow
def test_free_oscillation_finds_the_qube_pendulum(hw, clock, tmp_path):
    """App. A on the QUBE: omega_0 of a uniform rod, sqrt(3 g / 2 L_p), within 2 %
    (the arm, held by the experiment's PD loop in volts, gives a little)."""
    est = identify_on_qube(clock, tmp_path, "free-oscillation", duration=4.0)
    assert est["omega0"] == pytest.approx(math.sqrt(1.5 * hw.G / hw.L_P), rel=0.02)
    assert est["rest_angle"] == pytest.approx(math.pi, abs=0.01)


@pytest.mark.slow
def test_stribeck_on_the_bare_arm_sees_back_emf_plus_bearing(hw, clock, tmp_path,
                                                            monkeypatch):
    """App. E.2 with the pendulum module off: the viscous level in volts is the
    motor's k_m plus the bearing's damping D_r R_m / k_t; no Coulomb friction."""
    monkeypatch.setenv("FAKE_QUANSER_STATE", '{"pendulum_module": false}')
    est = identify_on_qube(clock, tmp_path, "stribeck", references=[1.0, 2.0, 3.0, 4.0],
                           gain=2.0, hold=1.5)
    assert est["viscous"] == pytest.approx(hw.K_M + hw.D_R * hw.R_M / hw.K_T, rel=0.05)
    assert abs(est["coulomb"]) < 0.02


@pytest.mark.slow
def test_a_program_that_dies_with_the_motor_on_still_stops_and_closes(tmp_path):
    """A script that drives the backend and ends with an uncaught exception, never
    closing it: at exit the backend writes 0 V, turns the amplifier off, stops the
    watchdog and closes the board."""
    import os
    import subprocess

    from qube_helpers import FAKE, read_record

    script = (
        "from frictionlab.config import build_config\n"
        "from frictionlab.realtime.qube import QUBE_RIG, QubeRig\n"
        "rig = QubeRig('qube2://0?watchdog=1', build_config(sets=list(QUBE_RIG.items())))\n"
        "rig.open(h=0.005)\n"
        "rig.sample(0, 0)\n"
        "rig.write(0, 0.4)\n"
        "raise RuntimeError('the script died with the motor at 4 V')\n")
    env = {**os.environ, "PYTHONPATH": FAKE, "FAKE_QUANSER_LOG": str(tmp_path / "b.jsonl")}
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 1 and "died with the motor" in res.stderr
    calls = read_record(tmp_path / "b.jsonl")
    assert any(v == pytest.approx(4.0) for _i, _m, v in voltages(calls))  # u_DA / 0.1 V
    check_safe_sequence(calls)


def test_odd_commands_and_a_failing_set_up_leave_the_motor_off(hw, clock, monkeypatch):
    rig, board = open_rig_on(hw, clock)
    rig.sample(0, 0)
    rig.write(0, math.nan)  # never from the loop, which zeroes a NaN u itself
    assert board.voltage == 0.0 and not board.enabled
    rig.write(1, 7.0)  # beyond the DAC: clipped to 10 V
    assert board.voltage == 10.0 and board.enabled
    rig.close()

    def broken(self, *args):
        raise hw.HILError(-2, "encoder reset failed")

    monkeypatch.setattr(hw.HIL, "set_encoder_counts", broken)
    with pytest.raises(RigError, match="encoder reset failed"):
        QubeRig("qube2://0", qube_cfg()).open(h=0.005)
    board = hw.BOARDS[-1]
    assert board.closed and not board.enabled and board.voltage == 0.0


def turn_by_hand(hw, clock, start_s, joint):
    """The operator's hand on the emulated QUBE: one lap of ``joint`` over 1 s from
    ``start_s`` (s of board time), the other joint held, then at rest."""
    t0 = hw.BOARDS[-1].t0 if hw.BOARDS else clock.now_ns()
    for i in range(1001):
        def move(i=i):
            b = hw.BOARDS[-1]
            b.advance()
            x = list(b.x)
            turning = 0.0 if i == 1000 else 2 * math.pi
            if joint == "pendulum":
                x = [0.0, math.pi + 2 * math.pi * i / 1000, 0.0, turning]
            else:
                x = [2 * math.pi * i / 1000, 3 * math.pi, turning, 0.0]
            b.x = tuple(x)
        clock.call_at(t0 + int((start_s + i / 1000) * 1e9), move)


@pytest.mark.slow
def test_angle_scales_on_a_qube_is_a_check_of_the_encoders(hw, clock, tmp_path):
    """App. B.1/B.2 by hand: the laps give back the scales in use (pi, pi) and the
    hanging reading 0.5: on a QUBE the step checks the encoders, sets nothing."""
    from frictionlab.studies.identification.onrig import (
        analyse_run,
        make_rig_experiment,
        run_on_rig,
    )

    cfg = qube_cfg()
    exp = make_rig_experiment("angle-scales", cfg, wait=20.0, settle=0.5)
    turn_by_hand(hw, clock, 0.8, "pendulum")
    turn_by_hand(hw, clock, 3.0, "arm")
    st = run_on_rig(exp, cfg, "qube2://0", log_dir=tmp_path, clock=clock, realtime=False)
    assert st["stop_reason"] == "finished", st["stop_detail"]
    est = analyse_run("angle-scales", st["log"], cfg)
    assert est["theta_scale"] == pytest.approx(math.pi, rel=1e-3)
    assert est["arm_scale"] == pytest.approx(math.pi, rel=1e-3)
    assert est["theta_bias"] == pytest.approx(0.5, abs=1e-3)


def test_a_board_failing_while_waiting_for_the_lift_is_a_rig_error(hw, clock, monkeypatch):
    def broken(self, *args):
        raise hw.HILError(-3, "USB unplugged")

    monkeypatch.setattr(hw.HIL, "read_encoder", broken)
    with pytest.raises(RigError, match="USB unplugged"):
        QubeRig("qube2://0?wait=upright", qube_cfg()).open(h=0.005, cancel=lambda: False)
    board = hw.BOARDS[-1]
    assert board.closed and not board.enabled


def test_a_blocked_arm_under_voltage_stops_as_a_stall(hw, clock, monkeypatch):
    """The board's own stall detection (more than 5 V, the arm still): the next
    sample stops the run as ``motor_stall`` and the motor is off."""
    from frictionlab.realtime.qube import RigStop

    monkeypatch.setenv("FAKE_QUANSER_STATE", '{"arm_blocked": true}')
    rig, board = open_rig_on(hw, clock)
    with pytest.raises(RigStop) as stop:
        for k in range(400):  # 2 s at 6 V
            rig.sample(k, 0)
            rig.write(k, 0.6)
            clock.advance(H_NS)
    assert stop.value.reason == "motor_stall" and 0.5 <= k * 0.005 <= 0.55
    assert board.voltage == 0.0 and not board.enabled
    rig.close()
    check_safe_sequence(calls_of(board))


def test_a_qube3_gets_its_card_options_before_any_output(hw, clock):
    rig, board = open_rig_on(hw, clock, spec="qube3://0")
    assert board.card_type == "qube_servo3_usb"
    assert board.options["pwm_en"] == "0" and board.options["deadband_compensation"] == "0"
    names = [c[1] for c in board.calls]
    assert names.index("set_card_specific_options") < names.index("write_analog")
    rig.close()
