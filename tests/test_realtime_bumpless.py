"""Bumpless switching while the loop runs (docs/compensation.md and docs/realtime.md,
"Switching while running"): turning a compensator on or off, changing its kind or its
parameters, switching to the adaptive one, and changing the design never make u jump
beyond what the cycle itself does.

The bound of each test: max |u| over the 0.3 s after the switch is at most 1.1 times the
max |u| over the 5 s before it (the console's default configuration: fast design,
classical plant friction).  Each switch type is checked in the simulator
(:func:`~frictionlab.model.simulation.simulate_config` with ``switches``) at switch times
spread over a cycle, and in the 200 Hz loop (the in-process simulated rig, lockstep, on a
fake clock) once, where its log must also be the simulator's run tick for tick: both
runners make the switch with the same code
(:func:`~frictionlab.model.switching.switch_controller`).
"""

import dataclasses

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.model.controller import LUGRE, new_state
from frictionlab.model.design import PRESETS, design, gain_path
from frictionlab.model.friction import FrictionParams, lugre_dz, steady_state
from frictionlab.model.switching import Transition, start_compensator, switch_controller
from frictionlab.realtime import FakeClock, RealtimeController, Safety
from frictionlab.realtime.params import ControlParams
from frictionlab.realtime.rigs import SimRig
from frictionlab.realtime.samples import STOP
from frictionlab.runs import simulate_config

H = 0.005
BOUND = 1.1
#: switch type -> (the run's configuration (design, compensation, sets), the operator's change)
SWITCHES = {
    "compensation_on": (("fast", "none", []), {"compensation": "lugre"}),
    "compensation_off": (("fast", "lugre", []), {"compensation_enabled": False}),
    "kind": (("fast", "lugre", []), {"compensation": "coulomb"}),
    "parameters": (("fast", "lugre", []),
                   {"compensation_params": {"sigma0": 600.0, "observer_gain": 3.0}}),
    "adaptive": (("fast", "none", []), {"compensation": "adaptive"}),
    "lugre_to_adaptive": (("fast", "lugre", ["compensation.observer_gain=0"]),
                          {"compensation": "adaptive"}),
    "design": (("fast", "none", []), {"design": "slow"}),
}


def setup(name):
    (design, comp, sets), change = SWITCHES[name]
    cfg = build_config(design, "classical", comp, sets=sets)
    before = ControlParams.from_config(cfg)
    return cfg, before, before.apply(change), change


def ratio(u, k):
    """max |u| over the 0.3 s from tick k on / over the 5 s before it."""
    u = np.abs(np.asarray(u))
    return u[k:k + round(0.3 / H)].max() / u[k - round(5.0 / H):k].max()


@pytest.mark.parametrize("name", SWITCHES)
def test_a_switch_in_the_simulator_is_bumpless_all_over_the_cycle(name):
    cfg, _before, after, _change = setup(name)
    ratios = []
    for t in np.arange(8.0, 9.2, 0.15):  # about a cycle of the fast design
        tr = simulate_config(cfg, t + 0.3, switches=[(t, after.controller)])
        assert tr.status == "ok"
        ratios.append(ratio(tr["u"], round(t / H)))
    assert max(ratios) <= BOUND, ratios


def test_switching_lugre_on_at_once_would_kick_the_motor():
    """The bound has teeth: without the transition (the compensator started at its
    steady estimate but its estimate and error applied at once) u jumps to several
    times the cycle's peak: the observers' velocity estimate, biased by the friction
    they did not model, drives the observer term k e of eq. (19)."""
    cfg, _before, after, _change = setup("compensation_on")
    worst = max(ratio(simulate_config(cfg, t + 0.3, switches=[(t, after.controller)],
                                      transition=(2.0, 0.0))["u"], round(t / H))
                for t in np.arange(8.0, 9.2, 0.3))
    assert worst > 3.0


def switch_in_the_loop(cfg, change, t_switch, h=H):
    """Run the 200 Hz loop on a fake clock and the simulated rig, submit ``change``
    (confirmed) while it sleeps after the tick of ``t_switch`` (in effect from the next),
    and stop 0.5 s later.  Returns the commands u of every tick and the tick the change
    took effect in, having checked that the run ended by its duration with one change."""
    clock = FakeClock()
    ctl = RealtimeController(cfg, SimRig(cfg, lockstep=True), log_dir=None, clock=clock,
                             duration=t_switch + 0.5, safety=Safety(angle_limit=1.2),
                             realtime=False, manage_gc=False)
    sub = ctl.subscribe(maxlen=4000)
    futures = []
    clock.call_at(clock.now_ns() + round((t_switch + h / 2) * 1e9),
                  lambda: futures.append(ctl.submit(change, confirm=True)))
    stats = ctl.run()
    assert stats["stop_reason"] == "duration" and stats["changes_applied"] == 1
    u = np.array([s.u for s in sub.drain() if not s.flags & STOP])
    k = futures[0].result(timeout=0)
    assert k == round(t_switch / h) + 1
    return u, k


@pytest.mark.slow
@pytest.mark.parametrize("name", SWITCHES)
def test_a_switch_in_the_loop_is_bumpless_and_the_simulators(name):
    cfg, _before, after, change = setup(name)
    t_switch = 8.3
    u, k = switch_in_the_loop(cfg, change, t_switch)
    assert ratio(u, k) <= BOUND
    # the simulator makes the same switch, tick for tick (the loop's ADC round trip
    # rounds the measurements: no noise, no quantisation here)
    tr = simulate_config(cfg, t_switch + 0.5, switches=[(k * H, after.controller)])
    np.testing.assert_allclose(u, tr["u"], rtol=0, atol=1e-6)


@pytest.mark.parametrize("v", [-2.0, -0.3, 0.4, 3.0])
def test_a_lugre_compensator_starts_at_its_steady_friction(v):
    """The bristle of steady sliding, z = s(v) sgn(v)/sigma0 (eq. 18 with z' = 0), makes
    the compensator's estimate the Stribeck curve: its force sigma0 z + F_v v is
    steady_state's, and its bristle rate (e = 0) is zero."""
    p = FrictionParams.defaults("lugre", "compensation").record()
    s = new_state(x1=0.1, relay=1.0, fc_hat=3.0)
    start_compensator(s, LUGRE, p, v)
    assert s.x1 == 0.1 and s.relay == 0.0 and s.fc_hat == 0.0  # the rest is untouched
    assert p.sigma0 * s.z_hat + p.fv * v == pytest.approx(steady_state(LUGRE, p, v))
    assert lugre_dz(v, s.z_hat, 0.0, p) == pytest.approx(0.0, abs=1e-12)
    start_compensator(s, LUGRE, p, 0.0)
    assert s.z_hat == 0.0  # at rest the bristle is not known: no estimate


def test_the_gain_path_passes_through_the_designs_in_between():
    """Each row of gain_path is the pole placement of a specification on the straight
    line between the two designs; a transition moves the gains piecewise linearly
    through them, j/n of the way at the j-th tick."""
    fast, slow = PRESETS["fast"], PRESETS["slow"]
    path = gain_path(fast, slow, steps=10)
    assert path.shape == (11, 8)
    mid = dataclasses.replace(fast, **{f: (getattr(fast, f) + getattr(slow, f)) / 2 for f in (
        "omega0", "omega1", "zeta1", "omega2", "zeta2", "observer_omega1", "observer_zeta1",
        "observer_omega2", "observer_zeta2")})
    for row, spec in ((0, fast), (5, mid), (10, slow)):
        d = design(spec)
        np.testing.assert_allclose(path[row], np.concatenate([d.L, d.K]), rtol=1e-12)
    # ... and not the straight line between the ends
    assert np.max(np.abs(path[5] - (path[0] + path[10]) / 2)) > 0.1
    target = ControlParams.from_config(build_config("slow")).gp
    tr = Transition(target, path[0], 100, 0, l_path=path)
    gains = [tr.advance() for _ in range(100)]
    assert tr.done and gains[-1] == target
    np.testing.assert_allclose(gains[49].gains8, path[5], rtol=1e-12)  # tick 50: r = 0.5
    np.testing.assert_allclose(gains[54].gains8, (path[5] + path[6]) / 2, rtol=1e-12)
    assert all(g.comp_weight == 1.0 and g.error_weight == 1.0 for g in gains)


def test_a_started_compensator_is_ramped_in_estimate_and_error():
    old = ControlParams.from_config(build_config("fast"))
    new = old.apply({"compensation": "lugre"})
    s = new_state(arm_dot=1.0)
    tr = switch_controller(s, old.gp, old.cp, new.gp, new.cp, 1.5, 400, 400)
    assert s.z_hat > 0.0  # started sliding forward
    w = np.array([(g.comp_weight, g.error_weight) for g in (tr.advance() for _ in range(400))])
    r = np.arange(1, 401) / 400
    np.testing.assert_allclose(w[:-1, 0], r[:-1], rtol=1e-12)
    np.testing.assert_allclose(w[:-1, 1], r[:-1] ** 3, rtol=1e-12)
    assert tuple(w[-1]) == (1.0, 1.0) and tr.done
    # a running compensator switched off, or given new levels, is not ramped
    for change in ({"compensation_enabled": False}, {"compensation_params": {"coulomb": 1.2}}):
        other = new.apply(change)
        assert switch_controller(s, new.gp, new.cp, other.gp, other.cp, 1.5, 400, 400).done


def test_the_transition_times_are_options_of_run(cli):
    res = cli("run", "--headless", "--duration", "1", "--compensation-transition", "-1")
    assert res.returncode == 2
    assert "--compensation-transition = -1 is out of range" in res.stderr
