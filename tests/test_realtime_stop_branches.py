"""The 200 Hz loop's stop branches that no other module drives with the fault injected: a
swing-up stopped by its arm-speed limit, a swung-up pendulum pushed past the angle limit
(the balancing phase's check), an experiment that finishes.  Each asserts the motor
command: u_DA = 0 in the stop tick, nothing after it, the rig's output at zero.

Every stop branch of ``realtime/loop.py`` and of the rig backends, and its test:

* stop request: ``user``, ``signal``, ``exit``:
  test_realtime_safety::test_signal_stops_within_one_tick
  test_qube::test_a_stop_request_zeroes_the_motor_at_the_next_tick
  test_realtime_motor::test_controller_u_max_limits_the_volts_and_a_stop_request_zeroes_them
* ``duration``:
  test_realtime_safety::test_normal_end_zeroes_the_motor
* ``paused``: woke up late:
  test_realtime_faults::test_a_pause_longer_than_max_pause_stops_before_acting
* ``paused``: the rig's reply taken late:
  test_realtime_faults::test_a_pause_inside_a_tick_does_not_write_the_stale_u
* ``paused``: output due late (after the step):
  test_realtime_faults::test_a_stall_after_the_controller_step_does_not_write_its_u
* rig ``BadReading``: corrupt frame, duplicate, out-of-order / stale sequence number:
  test_realtime_safety::test_rig_faults_stop_the_motor_within_two_ticks
* rig ``BadReading``: unexpected frame type, bad payload:
  test_realtime_faults::test_an_unexpected_frame_type_or_bad_payload_from_the_rig_stops_it
* ``rig_silent``: nothing from the rig:
  test_realtime_safety::test_rig_faults_stop_the_motor_within_two_ticks[silent]
  test_realtime_motor::test_rig_faults_stop_the_motor_plant_within_two_ticks
* ``rig_silent``: replies too late:
  test_realtime_safety::test_late_replies_are_life_signs_but_not_readings
* ``bad_reading``: out of range or NaN:
  test_realtime_safety::test_rig_faults_stop_the_motor_within_two_ticks[nan, out_of_range]
* ``rig_fault``: the rig's watchdog / HELD status:
  test_realtime_faults::test_rig_status_watchdog_and_held_are_rig_faults
  test_realtime_faults::test_rig_watchdog_tripped_by_lost_commands_stops_the_run
* ``rig_fault``: commands not applied (echo):
  test_realtime_faults::test_a_rig_that_ignores_the_commands_is_a_rig_fault
  test_realtime_faults::test_commands_not_applied_for_more_than_echo_ticks_stop_the_run
* experiment end: ``finished``:
  test_an_experiment_that_finishes_ends_with_the_motor_at_zero (here)
* experiment end: ``experiment_limit``:
  test_rig_experiments::test_speed_limit_stops_the_experiment_with_the_motor_at_zero
* ``nonfinite_u``: the experiment's u:
  test_realtime_faults::test_an_experiment_computing_a_non_finite_u_stops_with_the_motor_at_zero
* ``not_upright``:
  test_realtime_safety::test_no_swing_up_start_needs_the_pendulum_upright
  test_realtime_motor::test_not_upright_and_an_exception_stop_the_motor_plant
* ``angle_limit`` (balancing):
  test_realtime_safety::test_pendulum_pushed_over_stops_at_the_angle_limit
* ``angle_limit`` (a swing-up's balancing phase):
  test_a_swung_up_pendulum_pushed_over_stops_at_the_angle_limit (here)
* swing-up ``not_caught``, ``arm_travel``:
  test_swingup::test_loop_swing_up_stops_with_its_reason_and_zeroes_the_motor
* swing-up ``arm_speed``:
  test_a_swing_up_stopped_by_its_arm_speed_limit_zeroes_the_motor (here)
* ``nonfinite_u``: the controller's u:
  test_realtime_faults::test_a_non_finite_u_stops_in_the_tick_that_computes_it
  test_realtime_faults::test_an_unstable_lugre_compensator_ends_in_nonfinite_u_not_a_write
* ``exception`` (in the tick):
  test_realtime_safety::test_exception_in_the_tick_stops_the_motor
* ``exception``: the link failing in the tick:
  test_realtime_faults::test_a_link_that_fails_in_the_tick_stops_and_still_tries_the_zero
* the zero write failing (``stop_motor`` fallback):
  test_realtime_faults::test_a_failing_zero_write_at_the_stop_falls_back_to_stop_motor
* ``log_failed``:
  test_realtime_faults::test_a_full_disk_stops_the_run_with_the_motor_at_zero
* QUBE board: ``watchdog_expired``:
  test_qube::test_an_expired_watchdog_zeroes_the_motor_and_stops_the_run
* QUBE board: ``amplifier_fault``, ``motor_stall``:
  test_qube::test_a_board_fault_stops_the_run
  test_qube::test_a_blocked_arm_under_voltage_stops_as_a_stall
* QUBE board: a failing read / refused write:
  test_qube::test_a_board_error_on_a_read_stops_as_rig_fault
  test_qube::test_a_write_the_expired_board_refuses_stops_the_next_tick
"""

from __future__ import annotations

import math

import numpy as np

from frictionlab.config import build_config
from frictionlab.io.logs import read_log
from frictionlab.realtime import FakeClock, RealtimeController
from frictionlab.realtime import protocol as P
from frictionlab.realtime.rigs import FramedRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator
from frictionlab.realtime.samples import STOP

HANGING = ("sim.initial_angle", math.pi)


def run_framed(cfg, tmp_path, *, duration, faults=None, swing_up=False, experiment=None):
    """A run through the emulated rig's protocol on a fake clock: its status, the frames
    the loop sent, the emulator, the log."""
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    tx = DirectTransport(emu, clock)
    rig = FramedRig(tx, "direct", clock=clock)
    if faults:
        assert emu.control({"cmd": "fault", **faults}) == {"ok": True}
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=clock, duration=duration,
                             realtime=False, manage_gc=False, swing_up=swing_up)
    stats = ctl.run() if experiment is None else None
    if experiment is not None:
        ctl.start(experiment=experiment)
        assert ctl.wait(120)
        stats = ctl.last_stats
    ctl.close()
    return stats, tx, emu, read_log(stats["log"], cfg.design.h)


def assert_zeroed(stats, tx, emu, log) -> None:
    """u_DA = 0 written in the stop tick and nothing after it; the rig's output at zero; the
    log's last row the stop."""
    k = stats["stop_tick"]
    cmds = [(f.seq, P.parse_command(f)) for f in tx.sent if f.type == P.MSG_COMMAND]
    assert any(u != 0.0 for _, u in cmds)  # the motor was driven before the stop
    assert cmds[-1] == (k, 0.0) and all(u == 0.0 for seq, u in cmds if seq >= k)
    assert emu.u_da == 0.0
    assert int(log["flags"][-1]) & STOP and log["u_da"][-1] == 0.0


def test_a_swing_up_stopped_by_its_arm_speed_limit_zeroes_the_motor(tmp_path):
    cfg = build_config("fast", "classical", sets=[HANGING, ("swingup.arm_speed_limit", 2.0)])
    stats, tx, emu, log = run_framed(cfg, tmp_path, duration=5.0, swing_up=True)
    assert stats["stop_reason"] == "arm_speed", stats["stop_detail"]
    assert "swingup.arm_speed_limit 2" in stats["stop_detail"]
    assert_zeroed(stats, tx, emu, log)


def test_a_swung_up_pendulum_pushed_over_stops_at_the_angle_limit(tmp_path):
    """Swung up, caught and balancing, then pushed: the balancing phase's angle limit (the
    angle taken modulo 2 pi: it came up through a lap) stops the run."""
    cfg = build_config("fast", "classical", sets=[HANGING])
    stats, tx, emu, log = run_framed(cfg, tmp_path, duration=8.0, swing_up=True,
                                     faults={"after": 5.0, "push": 6.0})
    assert stats["stop_reason"] == "angle_limit", stats["stop_detail"]
    assert stats["swing_up"]["phase"] == "balancing" and stats["swing_up"]["swing_up_time"]
    assert stats["stop_tick"] * cfg.design.h > 5.0  # the push threw it, not the swing
    theta = np.angle(np.exp(1j * log["theta_m"][:-1]))
    assert abs(theta[-1]) <= 0.35  # the first reading past the limit is the stop tick
    assert_zeroed(stats, tx, emu, log)


def test_an_experiment_that_finishes_ends_with_the_motor_at_zero(tmp_path):
    from frictionlab.studies.identification.onrig import make_rig_experiment

    cfg = build_config("fast", "classical", sets=[HANGING])
    exp = make_rig_experiment("control-scaling", cfg, None, levels=(4.0, 6.0))
    stats, tx, emu, log = run_framed(cfg, tmp_path, duration=None, experiment=exp)
    assert stats["stop_reason"] == "finished", stats["stop_detail"]
    assert_zeroed(stats, tx, emu, log)


def test_the_table_names_tests_that_exist_and_every_stop_reason():
    """The table above stays true: each test it names exists, and each of the loop's stop
    reasons has a row."""
    import re
    from pathlib import Path

    from frictionlab.realtime.loop import STOP_REASONS

    doc = __doc__
    here = Path(__file__).parent
    named = set(re.findall(r"(test_\w+)::(test_\w+)", doc))
    named |= {(Path(__file__).stem, n) for n in re.findall(r"(test_\w+) \(here\)", doc)}
    assert len(named) >= 30
    for module, name in named:
        assert re.search(rf"^def {name}\(", (here / f"{module}.py").read_text(),
                         re.MULTILINE), (module, name)
    missing = [r for r in STOP_REASONS if f"``{r}``" not in doc]
    assert not missing, missing
