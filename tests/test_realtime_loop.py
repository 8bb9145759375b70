"""The periodic loop on a fake clock: deadlines, skip-ahead, timing statistics, mailbox, gc.

No test here sleeps: :class:`FakeClock` jumps to each deadline, and the
in-process rig (``SimRig`` or the emulator behind :class:`DirectTransport`)
steps the plant in fake time.
"""

import dataclasses
import gc
import json
import math
import random
import subprocess
import sys

import numpy as np
import pytest

from frictionlab.config import ConfigError, build_config
from frictionlab.model.controller import controller_step
from frictionlab.model.design import PRESETS, design
from frictionlab.model.friction import friction_record
from frictionlab.model.switching import start_compensator
from frictionlab.realtime import FakeClock, RealtimeController, Safety
from frictionlab.realtime import loop as loop_mod
from frictionlab.realtime.loop import Loop
from frictionlab.realtime.params import ControlParams
from frictionlab.realtime.rigs import FramedRig, SimRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator
from frictionlab.realtime.samples import CHANGED, MISSED, NO_READING, OVERRUN, START, STOP

H_NS = 5_000_000


@pytest.fixture(scope="module")
def cfg():
    return build_config("fast", "classical")


def run_loop(cfg, clock, rig=None, duration=1.0, **kw):
    rig = rig or SimRig(cfg)
    rig.open()
    loop = Loop(rig, clock, ControlParams.from_config(cfg), duration=duration,
                realtime=False, manage_gc=kw.pop("manage_gc", False), **kw)
    samples = []
    loop.sinks = (samples.append,)
    loop.run()
    return loop, samples


class TimedRig:
    """Wraps a rig; lets fake time pass in ``sample``/``write`` at chosen ticks."""

    def __init__(self, rig, clock, read_ns=lambda k: 0, write_ns=lambda k: 0):
        self.rig, self.clock = rig, clock
        self.read_ns, self.write_ns = read_ns, write_ns

    def __getattr__(self, name):
        return getattr(self.rig, name)

    def sample(self, k, deadline_ns):
        self.clock.advance(self.read_ns(k))
        return self.rig.sample(k, deadline_ns)

    def write(self, k, u_da):
        self.clock.advance(self.write_ns(k))
        self.rig.write(k, u_da)


def test_deadlines_are_absolute_integer_ticks_despite_wakeup_latency(cfg):
    rng = random.Random(3)
    latencies = {}

    def latency(deadline):
        ns = rng.randrange(0, 2_000_000)
        latencies[deadline] = ns
        return ns

    clock = FakeClock(wake_latency=latency)
    loop, samples = run_loop(cfg, clock, duration=2.0)
    t0 = loop.t0_ns
    n = round(2.0 / 0.005)
    # every sleep targets t0 + k h exactly: no drift however late the wake-ups were
    assert clock.sleeps[:n] == [t0 + k * H_NS for k in range(n)]
    assert loop.ticks == n and loop.missed == 0
    assert [s.k for s in samples[:-1]] == list(range(n))
    # the jitter statistics are the wake-up latencies (1 us bins)
    lat = np.array([latencies[t0 + k * H_NS] for k in range(n)]) / 1e3
    st = loop.stats()
    assert st["jitter_ms"]["max"] == pytest.approx(lat.max() / 1e3, abs=1e-6)
    assert abs(st["jitter_ms"]["p50"] * 1e3 - np.percentile(lat, 50, method="inverted_cdf")) <= 1.0
    assert abs(st["jitter_ms"]["p99"] * 1e3 - np.percentile(lat, 99, method="inverted_cdf")) <= 1.0
    assert [s.jitter_us for s in samples[:n]] == pytest.approx(list(lat), abs=1e-3)
    assert samples[0].flags & START and samples[-1].flags & STOP
    assert loop.stop_reason == "duration"


def test_missed_deadline_skips_ahead_without_a_burst(cfg):
    stall_ns = 23_000_000
    t0_holder = {}

    def latency(deadline):
        t0 = t0_holder.setdefault("t0", deadline)
        return stall_ns if deadline == t0 + 50 * H_NS else 0

    clock = FakeClock(wake_latency=latency)
    loop, samples = run_loop(cfg, clock, duration=1.0)
    t0 = loop.t0_ns
    skipped = stall_ns // H_NS  # 4 deadlines passed during the stall
    assert loop.missed == skipped
    assert loop.ticks + loop.missed == 200
    # after the stall the loop sleeps to the next deadline on the grid: 50 -> 55
    i = clock.sleeps.index(t0 + 50 * H_NS)
    assert clock.sleeps[i + 1] == t0 + (50 + skipped + 1) * H_NS
    assert np.all(np.diff(clock.sleeps) > 0)
    ks = [s.k for s in samples[:-1]]
    assert 51 not in ks and ks[50] == 50 + skipped
    assert samples[50].flags & MISSED
    assert samples[50].jitter_us == pytest.approx((stall_ns - skipped * H_NS) / 1e3)
    st = loop.stats()
    assert st["stalls"] == 1 and st["stall_list"][0]["missed"] == skipped
    assert st["max_stall_ms"] == pytest.approx(stall_ns / 1e6)
    assert st["missed_fraction"] == pytest.approx(skipped / 200)


def test_compute_rig_time_and_overruns_are_measured(cfg):
    clock = FakeClock()
    rig = TimedRig(SimRig(cfg), clock, read_ns=lambda k: 200_000,
                   write_ns=lambda k: 6_000_000 if k == 40 else 30_000)
    loop, samples = run_loop(cfg, clock, rig=rig, duration=0.5)
    st = loop.stats()
    assert st["rig_us"]["p50"] == pytest.approx(200, abs=1)
    assert st["compute_us"]["p50"] == pytest.approx(30, abs=1)
    assert st["compute_us"]["max"] == pytest.approx(6000, abs=1)
    assert st["overruns"] == 1
    assert samples[40].flags & OVERRUN
    assert not any(s.flags & OVERRUN for s in samples if s.k != 40)
    # the overrun made the next wake-up late by (6 ms + 0.2 ms) - 5 ms, not a miss
    assert samples[41].k == 41 and samples[41].jitter_us == pytest.approx(1200, abs=1)
    assert loop.missed == 0


@pytest.mark.slow
def test_gc_is_kept_out_of_the_tick(cfg):
    seen = []

    class GcProbe(SimRig):
        def sample(self, k, deadline_ns):
            seen.append(gc.isenabled())
            return super().sample(k, deadline_ns)

    assert gc.isenabled()
    loop, _ = run_loop(cfg, FakeClock(), rig=GcProbe(cfg), duration=2.5, manage_gc=True)
    assert seen and not any(seen)
    assert gc.isenabled()
    assert loop.gc_runs >= 2  # the loop's own scheduled collections, between ticks


def test_realtime_refusal_is_reported_once(cfg, monkeypatch, capsys):
    note = "SCHED_FIFO is not permitted here (test); running at normal priority"
    monkeypatch.setattr(loop_mod, "try_realtime_priority", lambda prio, cpu=None: note)
    monkeypatch.setattr(loop_mod, "_rt_warned", False)
    for _ in range(2):
        loop = Loop(SimRig(cfg), FakeClock(), ControlParams.from_config(cfg), duration=0.05,
                    realtime=True, manage_gc=False)
        loop.rig.open()
        assert loop.run() == "duration"
        assert loop.rt_note == note and loop.sched_fifo is False
    assert capsys.readouterr().err.count("SCHED_FIFO is not permitted") == 1


def _replay_u(samples, params_at):
    """Replay the controller on the logged measurements; params_at(k) -> ControlParams.
    A new compensator starts as the loop starts it: at its steady value for the arm
    velocity measured in the tick before (here at once: no compensation transition)."""
    first = samples[0]
    p = params_at(first.k)
    s = p.controller.init(first.theta_m)
    out = []
    v_prev = 0.0
    for smp in samples:
        q = params_at(smp.k)
        if q.gp.compensator != p.gp.compensator and q.gp.compensator:
            start_compensator(s, q.gp.compensator, q.cp, v_prev)
        p = q
        u, _, _ = controller_step(s, p.gp, friction_record(p.cp), smp.theta_m, smp.arm_m,
                                  smp.arm_dot_m)
        out.append(u)
        v_prev = smp.arm_dot_m
    return np.array(out)


def test_mailbox_applies_a_change_atomically_between_ticks(cfg, tmp_path):
    clock = FakeClock()
    ctl = RealtimeController(cfg, SimRig(cfg), log_dir=None, clock=clock, duration=1.0,
                             safety=Safety(gain_transition=0.0, compensation_transition=0.0),
                             realtime=False, manage_gc=False)
    sub = ctl.subscribe(maxlen=1000)
    before = ControlParams.from_config(cfg)
    futures = []
    change = {"design": "slow", "compensation": "coulomb"}
    # submitted from "another thread" while the loop sleeps between ticks 98 and 99; the
    # loop takes it from the mailbox after tick 99's output: in effect from tick 100
    clock.call_at(clock.now_ns() + H_NS + 98 * H_NS + H_NS // 2,
                  lambda: futures.append(ctl.submit(change)))
    stats = ctl.run()
    assert stats["stop_reason"] == "duration" and stats["changes_applied"] == 1
    samples = [s for s in sub.drain() if not s.flags & STOP]
    k_new = futures[0].result(timeout=0)
    assert k_new == 100
    changed = [s.k for s in samples if s.flags & CHANGED]
    assert changed == [k_new]
    after = before.apply(change)
    assert ctl.status()["design"]["preset"] == "slow"
    assert ctl.status()["compensation"]["kind"] == "coulomb"
    # every tick used either the old or the new parameters as a whole
    u_log = np.array([s.u for s in samples])
    u_rep = _replay_u(samples, lambda k: before if k < k_new else after)
    np.testing.assert_allclose(u_log, u_rep, rtol=0, atol=1e-9)
    # ... and not the new ones earlier or the old ones later
    u_wrong = _replay_u(samples, lambda k: before)
    assert np.max(np.abs(u_wrong[k_new:] - u_log[k_new:])) > 1e-3


@pytest.mark.slow
def test_new_gains_move_along_the_design_path_over_the_transition(cfg):
    clock = FakeClock()
    ctl = RealtimeController(cfg, SimRig(cfg), log_dir=None, clock=clock, duration=1.5,
                             safety=Safety(gain_transition=0.5), realtime=False,
                             manage_gc=False)
    sub = ctl.subscribe(maxlen=1000)
    before = ControlParams.from_config(cfg)
    after = before.apply({"design": "slow"})
    futures = []
    clock.call_at(clock.now_ns() + H_NS + 98 * H_NS + H_NS // 2,
                  lambda: futures.append(ctl.submit({"design": "slow"})))
    ctl.run()
    samples = [s for s in sub.drain() if not s.flags & STOP]
    k_new = futures[0].result(timeout=0)
    n = 100  # 0.5 s of ticks
    # L and K of the designs 0, 1/10, ..., 1 of the way from fast to slow (App. C each)
    nodes = np.array([np.concatenate([d.L, d.K]) for d in (
        design(dataclasses.replace(PRESETS["fast"], **{
            f: (1 - r) * getattr(PRESETS["fast"], f) + r * getattr(PRESETS["slow"], f)
            for f in ("omega0", "omega1", "zeta1", "omega2", "zeta2", "observer_omega1",
                      "observer_zeta1", "observer_omega2", "observer_zeta2")}))
        for r in np.linspace(0.0, 1.0, 11))])

    def params_at(k):
        if k < k_new:
            return before
        r = min(1.0, (k - k_new + 1) / n)
        g = [np.interp(r, np.linspace(0.0, 1.0, 11), nodes[:, i]) for i in range(8)]
        return dataclasses.replace(after, gp=after.gp.with_gains8(g))

    u_log = np.array([s.u for s in samples])
    np.testing.assert_allclose(u_log, _replay_u(samples, params_at), rtol=0, atol=1e-8)
    # a straight line in L (K at once) would have been different, at once too
    def straight(k):
        if k < k_new:
            return before
        a = min(1.0, (k - k_new + 1) / n)
        l_old, l_new = before.gp.feedback, after.gp.feedback
        return dataclasses.replace(after, gp=after.gp.with_feedback(l_old + a * (l_new - l_old)))

    for other in (straight, lambda k: before if k < k_new else after):
        u_other = _replay_u(samples, other)
        assert np.max(np.abs(u_other[k_new:k_new + n] - u_log[k_new:k_new + n])) > 1e-3
    assert ctl.status()["design"]["L"] == pytest.approx(list(after.gp.feedback))


@pytest.mark.slow
def test_slow_to_fast_in_mid_cycle_stays_inside_the_angle_limit():
    # the slow design's arm swings 1.4 rad about its reference at up to 5 rad/s:
    # the fast gains switched at once throw the pendulum past 0.35 rad (two times in
    # three); over the default 2 s transition it stays well inside
    cfg = build_config("slow", "classical")
    worst = {}
    for transition in (0.0, 2.0):
        peaks = []
        for t_switch in (10.2, 10.9, 11.6, 12.3):
            clock = FakeClock()
            ctl = RealtimeController(cfg, SimRig(cfg, lockstep=True), log_dir=None,
                                     clock=clock, duration=t_switch + 3.0,
                                     safety=Safety(angle_limit=1.2,
                                                   gain_transition=transition),
                                     realtime=False, manage_gc=False)
            sub = ctl.subscribe(maxlen=4000)
            clock.call_at(clock.now_ns() + round(t_switch * 1e9),
                          lambda ctl=ctl: ctl.submit({"design": "fast"}))
            stats = ctl.run()
            assert stats["stop_reason"] == "duration"
            theta = np.array([s.theta_m for s in sub.drain()
                              if s.k * 0.005 > t_switch and not s.flags & STOP])
            peaks.append(np.max(np.abs(theta)))
        worst[transition] = max(peaks)
    assert worst[0.0] > 0.35
    assert worst[2.0] < 0.33


def test_a_change_is_taken_from_the_mailbox_after_a_tick_without_a_reading(cfg):
    class Unanswered(SimRig):
        """The rig is alive, but the readings of ticks 50-59 come too late."""

        def sample(self, k, deadline_ns):
            r = super().sample(k, deadline_ns)
            return None if 50 <= k < 60 else r

    clock = FakeClock()
    ctl = RealtimeController(cfg, Unanswered(cfg), log_dir=None, clock=clock, duration=0.5,
                             safety=Safety(unread_limit=20, gain_transition=0.0), realtime=False,
                             manage_gc=False)
    sub = ctl.subscribe(maxlen=1000)
    futures = []
    t0 = clock.now_ns() + H_NS
    # submitted while the loop sleeps between ticks 52 and 53, neither of which has a reading
    clock.call_at(t0 + 52 * H_NS + H_NS // 2,
                  lambda: futures.append(ctl.submit({"design": "slow"})))
    stats = ctl.run()
    assert stats["stop_reason"] == "duration" and stats["changes_applied"] == 1
    # taken after tick 53 (no reading) like after any tick: in effect from tick 54, not from
    # the tick after the next reading (61)
    assert futures[0].result(timeout=0) == 54
    samples = {s.k: s for s in sub.drain() if not s.flags & STOP}
    assert all(samples[k].flags & NO_READING for k in range(50, 60))
    # a tick without a reading records no signal and holds the last u_DA written
    for k in range(50, 60):
        assert all(math.isnan(v) for v in samples[k][3:16]), k
        assert samples[k].u_da == samples[49].u_da and samples[k].rig_us >= 0
    assert not any(math.isnan(v) for v in samples[60][3:16])
    assert [k for k, s in samples.items() if s.flags & CHANGED] == [54]
    assert ctl.status()["design"]["preset"] == "slow"
    # from the first reading after the gap on, the slow design's gains controlled
    before = ControlParams.from_config(cfg)
    slow = before.apply({"design": "slow"})
    read = [s for k, s in samples.items() if not s.flags & NO_READING]
    u_log = np.array([s.u for s in read])
    u_rep = _replay_u(read, lambda k: slow if k >= 54 else before)
    np.testing.assert_allclose(u_log, u_rep, rtol=0, atol=1e-9)
    assert abs(_replay_u(read, lambda k: before)[50] - u_log[50]) > 1e-3


_FIRST_CHANGES = r"""
import ctypes, json, os, sys
from frictionlab.config import build_config
from frictionlab.realtime import RealtimeController
from frictionlab.realtime.osrt import _BLAS_SET_THREADS

ctl = RealtimeController(build_config("fast", "classical"), "sim", log_dir=None, realtime=True)
modules = set(sys.modules)
for change in ({"design": "slow"}, {"design": "fast"}, {"compensation": "coulomb"},
               {"compensation": "classical"}, {"compensation": "lugre"},
               {"compensation_params": {"sigma0": 250.0}}, {"design": {"omega1": 5.0}}):
    ctl.submit(change)
threads = {}
with open("/proc/self/maps") as fh:
    paths = {line.split()[-1] for line in fh if "openblas" in line.lower()}
for path in paths:
    lib = ctypes.CDLL(path)
    for name in _BLAS_SET_THREADS:
        get = getattr(lib, name.replace("set_num_threads", "get_num_threads"), None)
        if get is not None:
            threads[os.path.basename(path)] = get()
            break
print(json.dumps({"new_modules": sorted(set(sys.modules) - modules), "threads": threads,
                  "limited": ctl.blas_single_threaded}))
"""


@pytest.mark.slow
def test_first_changes_import_nothing_and_blas_is_single_threaded():
    # a fresh process: what the first change of each kind would load is loaded by then
    out = subprocess.run([sys.executable, "-c", _FIRST_CHANGES], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    assert res["new_modules"] == []
    # every OpenBLAS in the process (numpy's and scipy's) runs one thread
    assert res["threads"] and set(res["threads"].values()) == {1}
    assert sorted(res["limited"]) == sorted(res["threads"])


def test_invalid_change_is_refused_and_nothing_changes(cfg):
    ctl = RealtimeController(cfg, SimRig(cfg), log_dir=None, clock=FakeClock(),
                             realtime=False, manage_gc=False)
    before = ctl.status()
    for bad in ({"set": {"design.omega1": -1.0}}, {"compensation": "magic"},
                {"design.h": 0.01}, {"set": {"design.h": 0.01}},
                {"compensation_params": {"sigma0": -3}}):
        with pytest.raises(ConfigError):
            ctl.submit(bad)
    assert ctl.status()["design"] == before["design"]
    assert ctl.status()["compensation"] == before["compensation"]
    fut = ctl.submit({"compensation": "lugre", "compensation_params": {"sigma0": 250}})
    assert fut.result(timeout=0) is None  # not running: applies to the next run
    st = ctl.status()["compensation"]
    assert st["kind"] == "lugre" and st["enabled"] and st["params"]["sigma0"] == 250


def test_loop_with_emulated_rig_balances_and_logs_raw_values(cfg):
    clock = FakeClock()
    emu = RigEmulator(cfg, clock)
    rig = FramedRig(DirectTransport(emu, clock), "direct", clock=clock)
    loop, samples = run_loop(cfg, clock, rig=rig, duration=3.0, safety=Safety())
    assert loop.stop_reason == "duration"
    assert loop.rig_timeouts == 0 and loop.missed == 0
    theta = np.array([s.theta_m for s in samples[:-1]])
    assert np.all(np.abs(theta) < 0.35)
    # raw readings on the 12-bit grid, converted with App. B
    y = np.array([s.y for s in samples[:-1]])
    q = 2.0 / 4096
    np.testing.assert_allclose(y / q, np.round(y / q), atol=1e-3)
    np.testing.assert_allclose(theta, np.pi * (y + 0.503), atol=1e-9)
    # u_DA = -0.022 u, and the emulator received the last command (u = 0 at the stop)
    u = np.array([s.u for s in samples[:-1]])
    uda = np.array([s.u_da for s in samples[:-1]])
    np.testing.assert_allclose(uda, np.clip(-0.022 * u, -1, 1), atol=1e-12)
    assert emu.last_command_seq == loop.stop_tick and emu.u_da == 0.0


@pytest.mark.parametrize("lockstep", [False, True])
def test_sim_rig_moves_on_through_missed_ticks_unless_lockstep(cfg, lockstep):
    steps = []

    class Counting(SimRig):
        def open(self):
            super().open()
            step = self.plant.step

            def counted(state, u):
                steps.append(u)
                return step(state, u)

            self.plant.step = counted

    def latency(deadline):
        return 23_000_000 if len(clock.sleeps) == 51 else 0

    clock = FakeClock(wake_latency=latency)
    rig = Counting(cfg, lockstep=lockstep)
    loop, samples = run_loop(cfg, clock, rig=rig, duration=0.5)
    assert loop.missed == 4
    # wall: the plant followed every deadline (100 steps); lockstep: one per executed tick
    assert len(steps) == (loop.ticks - 1 if lockstep else 99)
    ks = [smp.k for smp in samples if not smp.flags & STOP]
    if lockstep:
        # the tick count (the logged time t = k h) pauses with the plant: no gap, and
        # the run still covers its 0.5 s of simulated time
        assert ks == list(range(100)) and loop.ticks == 100
    else:
        # in real time the stall is a gap of 4 ticks in the log
        assert len(ks) == 96 and max(np.diff(ks)) == 5


def test_controller_api_record_push_subscribe_and_status(cfg, tmp_path):
    clock = FakeClock()
    rig = SimRig(cfg)
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=clock, duration=1.0,
                             realtime=False, manage_gc=False)
    sub = ctl.subscribe(maxlen=10)
    t0 = clock.now_ns() + H_NS
    saved, seen = {}, {}

    def at(k, fn):
        clock.call_at(t0 + k * H_NS - H_NS // 2, fn)

    at(50, ctl.record_start)
    at(60, lambda: seen.update(v=rig.state.x[1], status=ctl.status()))
    at(60, lambda: ctl.push(0.5))
    at(61, lambda: seen.update(v_after=rig.state.x[1]))
    at(150, lambda: saved.update(ctl.record_stop("balance")))
    stats = ctl.run()
    assert stats["stop_reason"] == "duration"
    # Save: the samples of ticks 50..149 under the given name
    assert saved["rows"] == 100 and saved["dat"] == str(tmp_path / "balance.dat")
    assert np.loadtxt(saved["dat"]).shape == (100, 10)
    # the push changed the simulated pendulum's velocity by 0.5 rad/s (plus one tick's
    # worth of acceleration, a few hundredths)
    assert seen["v_after"] - seen["v"] == pytest.approx(0.5, abs=0.1)
    # a slow subscriber loses samples, counted, and never blocks the loop
    assert len(sub) == 10 and sub.dropped == stats["ticks"] + 1 - 10
    assert stats["dropped_console_samples"] == sub.dropped
    st = seen["status"]
    for key in ("running", "run_id", "backend", "h", "t", "ticks", "missed", "overruns",
                "jitter_ms", "compute_us", "design", "compensation", "recording", "log",
                "stop_reason", "sched_fifo", "pending_changes", "safety", "friction"):
        assert key in st, key
    assert st["running"] and st["recording"] and st["friction"] == "classical"
    assert st["design"]["preset"] == "fast" and len(st["design"]["K"]) == 4
    assert not ctl.status()["running"] and ctl.status()["stop_reason"] == "duration"
    ctl.unsubscribe(sub)
    assert sub.closed


def test_a_stall_at_the_end_counts_only_the_run_s_deadlines(cfg):
    def latency(deadline):
        return 17_000_000 if len(clock.sleeps) == 99 else 0  # the wake-up for tick 98

    clock = FakeClock(wake_latency=latency)
    loop, _ = run_loop(cfg, clock, duration=0.5)
    assert loop.stop_reason == "duration"
    assert loop.ticks == 98 and loop.missed == 2  # 98 and 99 of the 100 deadlines
    assert loop.ticks + loop.missed == 100


def test_realtime_priority_is_dropped_when_the_run_ends(cfg):
    import os
    import threading

    out = {}

    def body():
        loop = Loop(SimRig(cfg), FakeClock(), ControlParams.from_config(cfg), duration=0.05,
                    realtime=True, manage_gc=False)
        loop.rig.open()
        seen = []
        loop.sinks = (lambda s: seen.append(os.sched_getscheduler(0)),)
        loop.run()
        out.update(fifo=loop.sched_fifo, during=seen, after=os.sched_getscheduler(0))

    th = threading.Thread(target=body)
    th.start()
    th.join(60)
    expected = os.SCHED_FIFO if out["fifo"] else os.SCHED_OTHER
    assert set(out["during"]) == {expected}
    assert out["after"] == os.SCHED_OTHER
