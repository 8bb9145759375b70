"""The model's check of controller settings (frictionlab.model.loopcheck) and
the refusals built on it (frictionlab.realtime.params): against hand-derived
matrices, the simulator, and the compensation study's evidence."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.model.controller import Controller
from frictionlab.model.design import PRESETS, design
from frictionlab.model.friction import FrictionParams
from frictionlab.model.loopcheck import check_loop, loop_matrices
from frictionlab.model.plants.thesis import PlantParams, zoh_closed_form
from frictionlab.realtime.params import ChangeError, ControlParams, UnsafeChange
from frictionlab.runs import make_controller, simulate_config

FAST, SLOW = PRESETS["fast"], PRESETS["slow"]
U_MAX = 1.0 / 0.022


def _hand_loop(spec, plant: PlantParams) -> np.ndarray:
    """The 8 x 8 sampled loop written out from Sec. 2.2-2.3 (no compensation).

    Plant: the closed-form ZOH matrices of Sec. 2.2 (zeta = 0).  Pendulum
    observer: forward differences of the scaled model linearised upright,
    x1+ = x1 + h (w0 x2 + k1 (theta - x1)), x2+ = x2 + h (w0 x1 - w0/g u + k2 (theta - x1));
    arm observer: eq. (11)'s double integrator with gains k3, k4;
    u = -L (x1, w0 x2, Omega_hat, Omega_dot_hat).
    """
    d = design(spec, plant)
    w0, h, g, L1 = spec.omega0, spec.h, plant.g, plant.arm_length
    l1, l2, l3, l4 = d.L
    k1, k2, k3, k4 = d.K
    Phi, Gam = zoh_closed_form(plant.omega0, g, L1, h)
    u_row = np.array([0, 0, 0, 0, -l1, -l2 * w0, -l3, -l4])  # u = u_row @ X
    M = np.zeros((8, 8))
    M[:4, :4] = Phi
    M[:4] += np.outer(Gam[:, 0], u_row)
    # x1
    M[4, 4] = 1 - h * k1
    M[4, 5] = h * w0
    M[4, 0] = h * k1
    # x2
    M[5, 5] = 1.0
    M[5, 4] = h * (w0 - k2)
    M[5, 0] = h * k2
    M[5] += -h * (w0 / g) * u_row
    # arm observer
    M[6, 6], M[6, 7], M[6, 2] = 1 - k3, h, k3
    M[6] += 0.5 * h * h / L1 * u_row
    M[7, 6], M[7, 7], M[7, 2] = -k4, 1.0, k4
    M[7] += h / L1 * u_row
    return M


@pytest.mark.parametrize("spec", [FAST, SLOW, dataclasses.replace(FAST, observer_omega1=50.0)])
def test_loop_matrix_equals_the_hand_derived_one(spec):
    """The check linearises the closed loop's own tick: the controller's rows are the
    hand-derived ones to rounding, the plant's the exact ZOH of Sec. 2.2 to the
    simulator's integration error (its pendulum steps are not the exact ZOH: 5e-5
    measured), the arm's exactly (its steps are exact for a held u)."""
    plant = PlantParams(zeta=0.0)
    M, N, K, D = loop_matrices(Controller(design(spec, plant)), plant)
    want = _hand_loop(spec, plant)
    np.testing.assert_allclose(M[4:], want[4:], atol=1e-7)
    np.testing.assert_allclose(M[2:4], want[2:4], atol=1e-7)
    np.testing.assert_allclose(M[:2], want[:2], atol=1e-4)
    assert np.abs(M[:2] - want[:2]).max() > 1e-7  # the tick's pendulum, not a copy of the ZOH
    d = design(spec, plant)
    np.testing.assert_allclose(K, [0, 0, 0, 0, *(-d.L * [1, spec.omega0, 1, 1])], atol=1e-7)
    np.testing.assert_allclose(D, 0.0, atol=1e-9)  # u comes from the predicted estimates
    # measurement errors enter the observers only: theta through k1, k2; Omega through k3, k4
    want_N = np.zeros((8, 3))
    want_N[4:, 0] = want[4:, 0]
    want_N[4:, 1] = want[4:, 2]
    np.testing.assert_allclose(N, want_N, atol=1e-7)
    ev = np.sort_complex(np.linalg.eigvals(M))
    np.testing.assert_allclose(ev, np.sort_complex(np.linalg.eigvals(want)), atol=1e-4)
    # the arm observer's error is exactly decoupled: its poles (eq. 11) are loop poles
    arm_poles = design(spec, plant).observer.achieved_discrete[2:]
    for z in arm_poles:
        assert np.min(np.abs(ev - z)) < 1e-6


@pytest.mark.slow
def test_the_dc_plant_is_checked_through_its_own_step():
    """The loop check of a QUBE-Servo 2 controller: the plant's rows are the ZOH of
    the DC plant's linearisation (its RK4 step), u = -L x_hat, the loop's eigenvalues
    the design's poles and observer poles (separation), and its verdict passes.  With
    the 4-state predictor observer (``design.full_observer=1``), whose u is built from
    the estimates alone; the default pendulum observer: tests/test_dc_observer.py."""
    cfg = build_config("fast", "classical", plant="qube2", sets=[("design.full_observer", 1)])
    ctrl = make_controller(cfg)
    d = ctrl.design
    M, N, K, D = loop_matrices(ctrl, cfg.plant)
    np.testing.assert_allclose(K[:4], 0.0, atol=1e-9)  # u from the estimates only
    np.testing.assert_allclose(K[4:], -d.L, rtol=1e-6)
    np.testing.assert_allclose(D, 0.0, atol=1e-9)
    # measurement errors enter the observer alone, through its gain (theta, arm, arm velocity)
    np.testing.assert_allclose(N[:4], 0.0, atol=1e-9)
    np.testing.assert_allclose(N[4:], d.K, atol=1e-7)
    np.testing.assert_allclose(M[:4, :4], d.Phi, atol=1e-6)
    np.testing.assert_allclose(M[:4, 4:], np.outer(d.Gamma[:, 0], K[4:]), atol=1e-5)
    ev = np.linalg.eigvals(M)
    for z in (*d.poles, *d.observer_poles):
        assert np.min(np.abs(ev - z)) < 1e-4, (z, ev)
    chk = check_loop(ctrl, cfg.plant)
    assert chk.ok, chk.reasons
    assert chk.spectral_radius == pytest.approx(max(np.abs([*d.poles, *d.observer_poles])),
                                                abs=1e-4)


def test_an_unstable_dc_design_is_refused_and_falls():
    cfg = build_config("fast", "classical", plant="qube2")
    d = make_controller(cfg).design
    ctrl = Controller(dataclasses.replace(d, L=-d.L), u_max=cfg.u_limit)
    chk = check_loop(ctrl, cfg.plant)
    assert chk.verdict == "unstable" and chk.spectral_radius > 1
    assert simulate_config(cfg, 3.0, controller=ctrl).status == "fell"


def test_the_sliding_check_has_the_centripetal_term():
    """Sliding at v, the tick's pendulum sees eq. (6)'s Omega_dot^2 sin(theta)cos(theta):
    the upright pendulum's omega0^2 becomes omega0^2 + Omega_dot^2, so theta_dot's answer
    to theta over a sample grows by h times the mean of Omega_dot^2 over it.  At the
    operating point the arm speeds up from v by -l4 v / L1 per second (the feedback on
    the estimated speed; the compensator cancels the plant's relay), so that mean is
    v^2 (1 + c + c^2/3), c = -l4 h / L1."""
    d = design(FAST)
    ctrl = Controller(d, "coulomb", FrictionParams.defaults("coulomb", "compensation"))
    rest = loop_matrices(ctrl, arm_speed=0.0, compensate=True)[0]
    assert rest.shape == (8, 8)
    c = -d.L[3] * FAST.h / PlantParams().arm_length
    for v in (0.5, 1.0, 3.0):
        sliding = loop_matrices(ctrl, arm_speed=v)[0]
        gain = (sliding[1, 0] - rest[1, 0]) / (FAST.h * v * v)
        assert gain == pytest.approx(1 + c + c * c / 3, rel=0.01), v
    assert np.allclose(loop_matrices(ctrl, arm_speed=0.0)[0], rest)  # no v^2 at rest


@pytest.mark.slow
def test_a_compensator_is_not_blamed_for_the_sliding_loops_own_instability():
    """The QUBE's slow design sliding at 3 rad/s: the centripetal term alone takes the
    loop past 1 (the Coulomb relay adds no slope); the Coulomb compensator is not
    refused for it (the console's fall check judges the design).  With the 4-state
    predictor observer (``design.full_observer=1``): the default pendulum observer's
    sliding loop stays inside (0.985)."""
    cfg = build_config("slow", "classical", "coulomb", plant="qube2",
                       sets=[("design.full_observer", 1)])
    ctrl = make_controller(cfg)
    free = np.max(np.abs(np.linalg.eigvals(
        loop_matrices(ctrl, cfg.plant, 3.0, compensate=False)[0])))
    assert free > 1.0
    chk = check_loop(ctrl, cfg.plant)
    assert chk.verdict == "ok", chk.reasons
    assert chk.compensator_radius == pytest.approx(free, abs=1e-6)


def test_presets_and_rig_settings_pass():
    for spec in (FAST, SLOW):
        for comp in ("none", "coulomb", "classical", "lugre"):
            p = FrictionParams.defaults(comp if comp != "none" else "lugre", "compensation")
            chk = check_loop(Controller(design(spec), comp, p))
            assert chk.ok, (spec, comp, chk.reasons)
            assert chk.spectral_radius < 1 and chk.peak_u < U_MAX
            assert (chk.compensator_radius is None) == (comp == "none")


def _sim(design_name, friction, compensation, sets=(), error_signal="velocity_innovation",
         noise=0.002, duration=15.0):
    cfg = build_config(design_name, friction, compensation,
                       sets=[*sets, ("sim.noise", noise)])
    ctrl = make_controller(cfg, error_signal)
    return cfg, ctrl, simulate_config(cfg, duration, controller=ctrl)


@pytest.mark.parametrize("design_name, friction, compensation, sets, error_signal, verdict", [
    ("fast", "classical", "none", [("design.omega0", 100.0)], None, "unstable"),
    ("fast", "classical", "none", [("design.observer_omega1", 1000.0)], None, "unstable"),
    ("fast", "classical", "none", [("design.omega1", 50.0)], None, "saturating"),
    ("fast", "lugre", "lugre", [("compensation.sigma1", 1e5)], None, "compensator_unstable"),
    ("fast", "lugre", "lugre", [], "arm_angle", "compensator_unstable"),
    ("slow", "lugre", "lugre", [], "arm_velocity", "compensator_unstable"),
    ("fast", "classical", "none", [], None, "ok"),
    ("slow", "classical", "classical", [], None, "ok"),
    ("fast", "lugre", "lugre", [], None, "ok"),
    ("slow", "lugre", "lugre", [], "position_innovation", "ok"),
])
def test_verdict_agrees_with_the_simulated_loop(design_name, friction, compensation, sets,
                                                error_signal, verdict):
    """What the check refuses hurts the simulated motor; what it passes does not."""
    cfg, ctrl, traj = _sim(design_name, friction, compensation, sets,
                           error_signal or "velocity_innovation")
    chk = check_loop(ctrl, cfg.plant, noise=0.002)
    assert chk.verdict == verdict, chk.reasons
    u = traj["u"]
    saturated = np.mean(np.abs(u) >= U_MAX * 0.999)
    if verdict == "ok":
        assert traj.status == "ok" and np.max(np.abs(u)) < U_MAX
    elif verdict == "saturating":
        assert saturated > 0 and chk.peak_u > U_MAX > chk.peak_u_disturbance * 0.5
    else:  # unstable: the pendulum falls, with u at the rails (or u not even finite)
        assert traj.status == "fell" and (saturated > 0 or not np.all(np.isfinite(u)))


@pytest.mark.parametrize("sigma0", [100.0, 1000.0])
def test_compensator_check_matches_the_tuning_grid(sigma0):
    """docs/compensation.md: of the tuning grid's LuGre settings exactly those with k = 15
    and sigma1 >= 6 lost the pendulum; the check flags exactly those (simulated here)."""
    for sigma1 in (4.0, 6.0):
        for k in (7.0, 15.0):
            sets = [("compensation.sigma0", sigma0), ("compensation.sigma1", sigma1),
                    ("compensation.observer_gain", k)]
            cfg, ctrl, traj = _sim("fast", "lugre", "lugre", sets)
            chk = check_loop(ctrl, cfg.plant)
            assert (chk.verdict == "compensator_unstable") == (traj.status == "fell"), \
                (sigma1, k, chk.reasons, traj.status)
            assert (not chk.ok) == (k == 15.0 and sigma1 >= 6.0)


@pytest.mark.parametrize("spec_name", ["fast", "slow"])
def test_predicted_peak_and_noise_of_u_match_the_simulator(spec_name):
    # noise-free recovery from 0.05 rad on a friction-free plant: the linear peak
    cfg, ctrl, traj = _sim(spec_name, "none", "none", noise=0.0, duration=4.0)
    chk = check_loop(ctrl, cfg.plant, noise=0.0, disturbance=cfg.sim.initial_angle)
    assert chk.u_noise_std == 0.0
    assert chk.peak_u_disturbance == pytest.approx(np.max(np.abs(traj["u"])), rel=0.02)
    assert chk.peak_u == pytest.approx(chk.peak_u_disturbance)
    # measurement noise: the stationary standard deviation of u (discrete Lyapunov equation)
    cfg, ctrl, traj = _sim(spec_name, "none", "none", noise=0.002, duration=60.0)
    chk = check_loop(ctrl, cfg.plant, noise=0.002)
    u = traj["u"][traj.t > 10.0]
    assert chk.u_noise_std == pytest.approx(np.std(u), rel=0.1)
    assert chk.peak_u == pytest.approx(chk.peak_u_disturbance + 3 * chk.u_noise_std)


def test_check_diagnostics_are_json_ready():
    chk = check_loop(Controller(design(dataclasses.replace(FAST, omega0=100.0))))
    out = chk.to_json()
    assert out["verdict"] == "unstable" and not out["ok"] and out["peak_u"] is None
    assert len(out["eigenvalues"]) == 8 and out["spectral_radius"] > 1
    assert abs(complex(*out["eigenvalues"][0])) == pytest.approx(chk.spectral_radius)
    with pytest.raises(ValueError, match="noise"):
        check_loop(Controller(design(FAST)), noise=-1.0)


# --- refusals of the controller's mailbox ------------------------------------------------


@pytest.fixture
def params():
    return ControlParams.from_config(build_config("fast", "classical"))


@pytest.mark.parametrize("changes, keys", [
    ({"design": {"zeta1": 2.0}}, ("design.zeta1",)),
    ({"design": {"omega1": 5.0, "zeta2": -1.0}}, ("design.zeta2",)),
    ({"set": {"design.omega1": 5.0, "compensation.sigma0": -3.0}}, ("compensation.sigma0",)),
    ({"compensation_params": {"sigma0": 250.0, "sigma1": "x"}}, ("compensation.sigma1",)),
    ({"compensation": "magic"}, ("compensation",)),
    ({"error_signal": "nope"}, ("error_signal",)),
    ({"compensation": "lugre", "compensation_params": {"stiction": 0.0, "coulomb": 0.0}},
     ("compensation.stiction", "compensation.coulomb")),
])
def test_invalid_changes_name_their_keys(params, changes, keys):
    with pytest.raises(ChangeError) as exc:
        params.apply(changes)
    assert exc.value.keys == keys


@pytest.mark.parametrize("changes", [
    {"design": {"omega0": 100.0}},
    {"design": {"observer_omega1": 1000.0, "observer_omega2": 20.0}},
    {"compensation": "lugre", "compensation_params": {"sigma1": 1e5}},
    {"compensation": "lugre", "compensation_params": {"sigma1": 10.0, "observer_gain": 15.0}},
])
def test_refusal_says_why_and_what_would_pass(params, changes):
    new = params.apply(changes)
    assert not new.loop_check.ok
    exc = params.refusal(new)
    assert isinstance(exc, UnsafeChange) and exc.check is new.loop_check
    assert set(exc.keys) >= {f"design.{k}" for k in changes.get("design", {})}
    assert new.loop_check.reasons[0] in str(exc)
    values = exc.safe["values"]
    assert values and set(values) <= set(exc.keys)
    # the suggested values pass, and lie between the current and the requested ones
    sets = {k: v for k, v in values.items()}
    passing = params.apply({k: v for k, v in changes.items() if k == "compensation"}
                           | {"set": sets})
    assert passing.loop_check.ok, passing.loop_check.reasons
    for key, v in values.items():
        section, name = key.split(".")
        now = getattr(params.cfg.design if section == "design"
                      else params.comp_params[new.comp_kind], name)
        want = getattr(new.cfg.design if section == "design"
                       else new.comp_params[new.comp_kind], name)
        assert min(now, want) <= v <= max(now, want)
        assert f"{key} = {v:g}" in str(exc)


def test_refused_error_signal_lists_the_passing_ones(params):
    new = params.apply({"compensation": "lugre", "error_signal": "arm_angle"})
    exc = params.refusal(new)
    assert exc.keys == ("compensation_enabled", "error_signal")  # LuGre was selected, off
    assert exc.safe["error_signals"] == ["none", "velocity_innovation", "position_innovation"]
