"""Friction compensation in the real-time loop, end to end on a fake clock.

``frictionlab run --backend sim --sim-lockstep`` in-process: a
:class:`~frictionlab.realtime.RealtimeController` on the simulated plant
(:class:`~frictionlab.realtime.rigs.SimRig`, one plant step per executed
tick) with the LuGre plant friction of eq. (21).  The loop runs the
simulator's compiled controller step, compensator included, so without noise
its log must be :func:`frictionlab.runs.simulate_config`'s run tick by
tick; with noise (the rig backend draws its own) it must show the same
reduction of the limit cycle.  No test sleeps: :class:`FakeClock` jumps to
each deadline.
"""

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.io.logs import read_log
from frictionlab.model.limit_cycles import features
from frictionlab.realtime import FakeClock, RealtimeController
from frictionlab.realtime.samples import CHANGED, STOP
from frictionlab.runs import simulate_config
from frictionlab.studies.compensation import COMPENSATORS

NOISE = 0.002
H = 0.005


def run_logged(cfg, duration, log_dir, changes_at=None):
    """Run the loop for ``duration`` s; return its CSV log without the stop row.

    ``changes_at = (t, changes)`` submits ``changes`` as the operator would,
    while the loop sleeps ``t`` s into the run.
    """
    clock = FakeClock()
    ctl = RealtimeController(cfg, "sim", log_dir=log_dir, clock=clock, duration=duration,
                             realtime=False, manage_gc=False, sim_lockstep=True)
    if changes_at is not None:
        t, changes = changes_at
        # the first deadline is one period after the start
        clock.call_at(clock.now_ns() + round((t + H / 2) * 1e9), lambda: ctl.submit(changes))
    stats = ctl.run()
    assert stats["stop_reason"] == "duration"
    assert stats["ticks"] == round(duration / H) and stats["missed"] == 0
    log = read_log(stats["log"])
    assert int(log["flags"][-1]) & STOP
    return {k: v[:-1] for k, v in log.items()}


def peak_to_peak(log, t_from, t_to):
    """Peak-to-peak of the measured pendulum angle over [t_from, t_to) (smoothed
    as ``frictionlab simulate`` does for noisy measurements)."""
    m = (log["t"] >= t_from - 1e-9) & (log["t"] < t_to - 1e-9)
    f = features(log["t"][m], log["theta_m"][m], log["u"][m], log["arm_dot_m"][m],
                 noise=NOISE, window=t_to - t_from)
    return f.peak_to_peak, f.status


@pytest.mark.slow
@pytest.mark.parametrize("kind", COMPENSATORS)
def test_logged_control_equals_simulate_config_tick_by_tick(kind, tmp_path):
    cfg = build_config("fast", "lugre", kind)
    log = run_logged(cfg, 10.0, tmp_path)
    traj = simulate_config(cfg, 10.0)
    assert len(log["u"]) == len(traj["u"]) == 2000
    np.testing.assert_array_equal(log["tick"], np.arange(2000))
    # the log keeps 9 significant digits; the loop's ADC round trip adds rounding
    for name in ("u", "friction_hat", "theta_m", "arm_dot_m"):
        np.testing.assert_allclose(log[name], traj[name], rtol=1e-6, atol=1e-5,
                                   err_msg=name)
    # ... and the compensator did act: its estimate is in u, which differs from the
    # uncompensated loop's
    assert np.max(np.abs(log["friction_hat"])) > 1.0
    off = simulate_config(build_config("fast", "lugre"), 10.0)
    assert np.max(np.abs(log["u"] - off["u"])) > 1.0


@pytest.mark.slow
def test_lugre_compensation_shrinks_the_noisy_limit_cycle_5x(tmp_path):
    sets = [f"sim.noise={NOISE}"]
    on = run_logged(build_config("fast", "lugre", "lugre", sets=sets), 20.0, tmp_path)
    off = run_logged(build_config("fast", "lugre", "none", sets=sets), 20.0, tmp_path)
    ptp_on, _ = peak_to_peak(on, 10.0, 20.0)
    ptp_off, status_off = peak_to_peak(off, 10.0, 20.0)
    assert status_off == "limit_cycle"
    assert ptp_off >= 5.0 * ptp_on, (ptp_off, ptp_on)
    assert np.all(off["friction_hat"] == 0.0)
    assert np.max(np.abs(on["friction_hat"])) > 1.0


@pytest.mark.slow
def test_switching_compensation_on_mid_run_removes_the_limit_cycle(tmp_path):
    """The operator's Compensation button (Sec. 7.1): LuGre on after 15 s."""
    cfg = build_config("fast", "lugre", "none", sets=[f"sim.noise={NOISE}"])
    log = run_logged(cfg, 30.0, tmp_path, changes_at=(15.0, {"compensation": "lugre"}))
    flags = log["flags"].astype(int)
    changed = log["tick"][(flags & CHANGED) != 0]
    assert list(changed) == [3001]  # submitted after tick 3000's output
    before, after = slice(0, 3001), slice(3001, None)
    assert np.all(log["friction_hat"][before] == 0.0)
    assert np.max(np.abs(log["friction_hat"][after])) > 1.0
    ptp_before, status_before = peak_to_peak(log, 5.0, 15.0)
    ptp_after, _ = peak_to_peak(log, 20.0, 30.0)
    assert status_before == "limit_cycle"
    assert ptp_before >= 5.0 * ptp_after, (ptp_before, ptp_after)


def test_adaptive_on_a_drifting_plant_equals_simulate_config_tick_by_tick(tmp_path):
    """Plain eq. (18) compensation (k = 0), so that the adaptation acts; the plant's
    levels fall 40 % over the run.  The loop's log is the simulator's run, and its
    sidecar holds the adapted levels the simulator ends with."""
    from frictionlab.realtime.datalog import read_sidecar

    cfg = build_config("fast", "lugre", "adaptive",
                       sets=["friction.drift=-0.4", "compensation.observer_gain=0",
                             "compensation.coulomb=1.2"])
    log = run_logged(cfg, 10.0, tmp_path)
    traj = simulate_config(cfg, 10.0)
    for name in ("u", "friction_hat", "theta_m", "arm_dot_m"):
        np.testing.assert_allclose(log[name], traj[name], rtol=1e-6, atol=1e-5,
                                   err_msg=name)
    # the adaptation did act, and the drift did too
    assert traj["coulomb_hat"][-1] != 1.2 and traj["stiction_hat"][-1] != 2.3
    steady = simulate_config(build_config("fast", "lugre", "adaptive",
                                          sets=["compensation.observer_gain=0",
                                                "compensation.coulomb=1.2"]), 10.0)
    assert np.max(np.abs(steady["u"] - log["u"])) > 0.1
    (sidecar,) = [read_sidecar(p) for p in tmp_path.glob("*.json")]
    ad = sidecar["adaptation"]
    assert ad["start"] == {"coulomb": 1.2, "stiction": 2.3}
    assert ad["status"] in ("adapting", "stuck", "presliding", "bad_signal", "saturated")
    assert ad["coulomb"] == pytest.approx(traj["coulomb_hat"][-1], rel=1e-6, abs=1e-6)
    assert ad["stiction"] == pytest.approx(traj["stiction_hat"][-1], rel=1e-6, abs=1e-6)


def test_switching_to_adaptive_mid_run_starts_it_from_its_parameters(tmp_path):
    """LuGre (k = 0) for 2 s, then the operator selects Adaptive with F_C 1.1: from
    the next tick the adaptive law starts afresh at its starting values, on the LuGre
    observer that keeps running (its bristle carried over, so the estimate does not
    jump), and the sidecar reports the adaptation."""
    from frictionlab.realtime.datalog import read_sidecar

    cfg = build_config("fast", "lugre", "lugre", sets=["compensation.observer_gain=0"])
    log = run_logged(cfg, 4.0, tmp_path, changes_at=(2.0, {
        "compensation": "adaptive", "compensation_params": {"coulomb": 1.1}}))
    flags = log["flags"].astype(int)
    assert list(log["tick"][(flags & CHANGED) != 0]) == [401]
    # the bristle estimate carries on through the switch (logged before the step) ...
    z, f_hat = log["z_hat"], log["friction_hat"]
    assert z[401] != 0.0 and abs(z[401] - z[400]) <= np.abs(np.diff(z[200:401])).max()
    # ... and so does the estimate: no step larger than the cycle's own
    assert abs(f_hat[401] - f_hat[400]) <= np.abs(np.diff(f_hat[200:401])).max()
    after = log["tick"] >= 401
    assert np.all(np.isfinite(log["friction_hat"][after]))
    (sidecar,) = [read_sidecar(p) for p in tmp_path.glob("*.json")]
    assert sidecar["current"]["compensation"]["kind"] == "adaptive"
    ad = sidecar["adaptation"]
    assert ad["start"] == {"coulomb": 1.1, "stiction": 2.3}
    assert 0.05 <= ad["coulomb"] <= 6.0 and 0.05 <= ad["stiction"] <= 6.0


def test_a_glitched_velocity_reading_does_not_move_the_adapted_levels(tmp_path):
    """Fault injected at the rig: one arm-velocity reading 3 rad/s off while the law
    adapts (inside the ADC's range, so the loop runs on).  The law freezes on it and
    on the sample that starts at it: the adapted levels do not move, and the run goes
    on to its end."""
    from frictionlab.model.adaptive import A_ADAPTING, A_BAD, A_PRESLIDING, A_STUCK
    from frictionlab.realtime.rigs import SimRig

    cfg = build_config("fast", "lugre", "adaptive",
                       sets=["compensation.observer_gain=0", "compensation.coulomb=1.2"])

    class Glitch(SimRig):
        ctl = None
        glitch_at = None

        def sample(self, k, deadline_ns):
            r = super().sample(k, deadline_ns)
            s = self.ctl._loop.state
            if s is not None:  # the controller state after tick k - 1
                self.trace[k] = np.array([s.adapt, s.fc_hat, s.fs_hat])
                if self.glitch_at is None and k >= 400 and s.adapt == A_ADAPTING:
                    self.glitch_at = k
                    r = r._replace(v=r.v + 3.0 / self.scaling.velocity_scale)
            return r

    rig = Glitch(cfg, lockstep=True)
    rig.trace = {}
    ctl = RealtimeController(cfg, rig, log_dir=tmp_path, clock=FakeClock(), duration=8.0,
                             realtime=False, manage_gc=False, sim_lockstep=True)
    rig.ctl = ctl
    stats = ctl.run()
    assert stats["stop_reason"] == "duration"
    k, tr = rig.glitch_at, rig.trace
    assert k is not None, "the law never adapted after 2 s"
    before, at, after = tr[k], tr[k + 1], tr[k + 2]
    assert at[0] == A_BAD and after[0] in (A_BAD, A_PRESLIDING, A_STUCK)
    np.testing.assert_array_equal(at[1:], before[1:])
    np.testing.assert_array_equal(after[1:], before[1:])
    log = read_log(stats["log"])
    assert np.all(np.isfinite(log["friction_hat"][:-1]))
