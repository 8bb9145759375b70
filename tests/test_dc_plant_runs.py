"""The DC-motor Furuta plant (``--plant furuta-dc|qube2|qube3``) plugged into the
configuration, the controller, the closed loop and the command line.

Independent checks: the closed loop through the package's kernel against a
loop written here from the plant's tick and the observer's step; the
``design --json`` linearisation against finite differences of the nonlinear
right-hand side and against python-control; a free swing against the
small-amplitude closed-form period.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from frictionlab.config import ConfigError, build_config, describe_keys
from frictionlab.model.controller import gains_record, gains_row
from frictionlab.model.friction import KINDS
from frictionlab.model.plants import FURUTA_DC, PLANTS, THESIS
from frictionlab.model.plants.furuta_dc import QUBE2, QUBE3, rhs, tick
from frictionlab.model.plants.furuta_dc_design import dc_design, dc_observer_step, observer_row
from frictionlab.runs import loop_spec, make_controller, simulate_config


def test_the_registry_has_both_plants_with_their_codes_and_units():
    assert PLANTS["thesis"] is THESIS and THESIS.code == 0
    assert PLANTS["furuta-dc"] is FURUTA_DC and FURUTA_DC.code == 1
    assert FURUTA_DC.u_unit == "V"


@pytest.mark.parametrize("name, params", [("furuta-dc", QUBE2), ("qube2", QUBE2),
                                          ("qube3", QUBE3)])
def test_a_motor_plant_takes_its_preset_friction_in_volts_and_scaled_compensators(name,
                                                                                   params):
    cfg = build_config(plant=name, compensation="lugre")
    thesis = build_config(compensation="lugre")
    assert cfg.plant == params and cfg.motor and cfg.plant_model is FURUTA_DC
    assert (cfg.friction.coulomb, cfg.friction.stiction) == (0.15, 0.2)
    r = cfg.friction.coulomb / thesis.friction.coulomb
    assert cfg.compensation.coulomb == pytest.approx(thesis.compensation.coulomb * r)
    assert cfg.compensation.sigma0 == pytest.approx(thesis.compensation.sigma0 * r)
    # velocities are not scaled
    assert cfg.compensation.stribeck_velocity == thesis.compensation.stribeck_velocity
    # the Sec. 2.4 pattern on this plant: omega0 its unstable rate
    assert cfg.design.omega0 == pytest.approx(params.omega0)
    assert cfg.design.omega1 == pytest.approx(params.omega0)


def test_plant_keys_follow_the_plant_and_a_wrong_plants_key_is_refused():
    cfg = build_config(plant="qube2", sets=[("plant.resistance", "7.5")])
    assert cfg.plant.resistance == 7.5 and cfg.get("plant.resistance") == 7.5
    with pytest.raises(ConfigError, match=r"plant\.omega0"):
        build_config(plant="qube2", sets=[("plant.omega0", "7")])
    with pytest.raises(ConfigError, match=r"plant\.resistance"):
        build_config(sets=[("plant.resistance", "7")])
    with pytest.raises(ConfigError, match="plant must be one of"):
        build_config(plant="qube9")
    rows = {k: unit for k, _doc, unit, _rng in describe_keys("qube2")}
    assert rows["plant.resistance"] == "ohm" and rows["friction.coulomb"] == "V"
    assert rows["compensation.sigma0"] == "V/rad"
    assert "plant.omega0" not in rows


def test_keys_lists_a_plants_parameters_with_units(cli):
    res = cli("keys", "--plant", "qube2", "--json")
    assert res.returncode == 0
    keys = {r["key"]: r for r in json.loads(res.stdout)["keys"]}
    assert keys["plant.torque_constant"]["default"] == 0.042
    assert keys["plant.torque_constant"]["unit"] == "N m/A"
    assert keys["friction.stiction"]["default"] == 0.2
    bad = cli("simulate", "--plant", "qube2", "--set", "plant.omega0=7")
    assert bad.returncode == 2 and "plant.omega0" in bad.stderr


def test_the_dc_gains_round_trip_through_their_row():
    gp, _ = make_controller(build_config(plant="qube2")).record()
    assert gp.observer == 2 and gp.omega0 == 1.0
    assert gains_record(gains_row(gp)) == gp
    thesis, _ = make_controller(build_config()).record()
    assert thesis.observer == 0 and gains_record(gains_row(thesis)) == thesis


def _reference_loop(cfg, n):
    """The closed loop written here from the plant's tick and the observer's step
    (ideal sensor, no compensator): theta and u per tick."""
    d = dc_design(cfg.design, cfg.plant)
    row, pp = observer_row(d), cfg.plant.record()
    fp = cfg.friction.record()
    x = np.array([cfg.sim.initial_angle, 0.0, 0.0, 0.0, 0.0])
    xhat = np.array([cfg.sim.initial_angle, 0.0, 0.0, 0.0])
    mem, theta, us = 0.0, np.empty(n), np.empty(n)
    for k in range(n):
        u = min(10.0, max(-10.0, -float(d.L @ xhat)))
        theta[k], us[k] = x[0], u
        dc_observer_step(xhat, x[0], x[2], x[3], u, row)
        _, mem = tick(x, u, mem, cfg.substeps, 1, cfg.design.h, pp,
                      KINDS.index(cfg.friction_kind), fp)
    return theta, us


def test_the_closed_loop_is_the_plant_tick_with_the_predictor_observer():
    cfg = build_config(plant="qube2", friction="coulomb", sets=[("design.full_observer", 1)])
    tr = simulate_config(cfg, 2.0)
    theta, u = _reference_loop(cfg, len(tr))
    assert tr.status == "ok"
    np.testing.assert_allclose(tr["u"], u, rtol=0, atol=1e-9)
    np.testing.assert_allclose(tr["theta"], theta, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_the_qube2_balances_within_10_volts_in_a_friction_limit_cycle(cli):
    res = cli("simulate", "--plant", "qube2", "--duration", "20", "--json")
    out = json.loads(res.stdout)
    assert res.returncode == 0 and out["status"] == "limit_cycle"
    tr = simulate_config(build_config(plant="qube2"), 20.0)
    assert np.max(np.abs(tr["u"])) <= 10.0
    assert np.max(np.abs(tr["theta"][len(tr) // 2:])) < 0.2
    assert out["features"]["period"] > 0
    # without friction the same loop settles
    still = simulate_config(build_config(plant="qube2", friction="none"), 10.0)
    assert np.max(np.abs(still["theta"][-200:])) < 1e-6


@pytest.mark.parametrize("comp", ["coulomb", "classical", "lugre", "adaptive"])
def test_every_compensator_keeps_the_qube2_up_within_its_voltage_limit(comp):
    cfg = build_config(plant="qube2", compensation=comp)
    tr = simulate_config(cfg, 4.0)
    assert tr.status == "ok"
    assert np.max(np.abs(tr["u"])) <= cfg.plant.voltage_limit
    assert np.any(tr["friction_hat"] != 0.0)


def test_a_lower_voltage_limit_saturates_u():
    cfg = build_config(plant="qube2", sets=[("plant.voltage_limit", "1.5"),
                                            ("sim.initial_angle", "0.1")])
    tr = simulate_config(cfg, 0.5)
    assert np.max(np.abs(tr["u"])) == 1.5


def _fd_linearization(params, eps=1e-6):
    A = np.zeros((4, 4))
    for j in range(4):
        dx = np.zeros(4)
        dx[j] = eps
        A[:, j] = (rhs(0.0, dx, 0.0, params) - rhs(0.0, -dx, 0.0, params)) / (2 * eps)
    B = ((rhs(0.0, np.zeros(4), eps, params) - rhs(0.0, np.zeros(4), -eps, params))
         / (2 * eps)).reshape(4, 1)
    return A, B


@pytest.mark.slow  # imports python-control
@pytest.mark.parametrize("plant", ["qube2", "qube3", "thesis"])
def test_design_json_linearization_matches_finite_differences_and_python_control(cli, plant):
    import control

    res = cli("design", "--plant", plant, "--json")
    assert res.returncode == 0
    lin = json.loads(res.stdout)["linearization"]
    A, B = np.array(lin["A"]), np.array(lin["B"])
    assert lin["states"] == ["theta", "theta_dot", "arm", "arm_dot"]
    cfg = build_config(plant=plant)
    if plant == "thesis":
        from frictionlab.model.plants.thesis import rhs as thesis_rhs

        assert lin["input"] == "u (m/s^2)"
        fd = (np.zeros((4, 4)), np.zeros((4, 1)))
        for j in range(5):
            d = np.zeros(5)
            d[j] = 1e-6
            col = (thesis_rhs(0.0, d[:4], d[4], cfg.plant)
                   - thesis_rhs(0.0, -d[:4], -d[4], cfg.plant)) / 2e-6
            if j < 4:
                fd[0][:, j] = col
            else:
                fd[1][:, 0] = col
        fa, fb = fd
    else:
        assert lin["input"] == "u (V)"
        fa, fb = _fd_linearization(cfg.plant)
    np.testing.assert_allclose(A, fa, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(B, fb, rtol=1e-6, atol=1e-6)
    # python-control's own linearisation of the nonlinear system
    sys = control.NonlinearIOSystem(
        lambda t, x, u, params: (rhs if plant != "thesis" else thesis_rhs)(
            t, x, u[0], cfg.plant), None, inputs=1, states=4)
    ss = control.linearize(sys, np.zeros(4), [0.0])
    np.testing.assert_allclose(A, ss.A, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(B, ss.B, rtol=1e-5, atol=1e-5)
    if plant != "thesis":
        # upright is unstable at the plant's own omega0
        assert max(np.linalg.eigvals(A).real) == pytest.approx(cfg.plant.omega0)


def _period(t, theta):
    """Mean period of theta's oscillation about hanging (upward zero crossings
    of theta - pi, interpolated)."""
    y = theta - math.pi
    i = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    tc = t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])
    return float(np.mean(np.diff(tc)))


def test_a_free_swing_open_loop_has_the_closed_form_small_amplitude_period(cli, tmp_path):
    # no damping, no back-EMF, no friction: the hanging pendulum with the arm
    # free, omega^2 = c J_0 / (J_p J_0 - b^2)
    sets = ["plant.emf_constant=0", "plant.arm_damping=0", "plant.pendulum_damping=0",
            "sim.initial_angle=3.12"]
    out = tmp_path / "swing.csv"
    args = ["simulate", "--plant", "qube2", "--friction", "none", "--open-loop",
            "--duration", "5", "--save", str(out), "--json"]
    for s in sets:
        args += ["--set", s]
    res = cli(*args)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["duration"] == pytest.approx(5.0)
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert np.all(data["u"] == 0.0)
    j_p, j_0, b, c = (float(v) for v in QUBE2.record()[:4])
    period = 2 * math.pi / math.sqrt(c * j_0 / (j_p * j_0 - b * b))
    assert _period(data["t"], data["theta"]) == pytest.approx(period, rel=2e-3)


def test_open_loop_holds_u_at_zero_for_the_thesis_plant_and_does_not_stop_at_a_fall():
    cfg = build_config(sets=[("sim.initial_angle", "0.3")])
    closed = simulate_config(cfg, 3.0)
    free = simulate_config(cfg, 3.0, open_loop=True)
    assert closed.status == "ok"
    assert free.status == "ok" and len(free) == 600
    assert np.all(free["u"] == 0.0)
    assert np.max(np.abs(free["theta"])) > math.pi / 2  # fell, and the run went on


def test_a_loop_spec_carries_the_plant():
    spec = loop_spec(build_config(plant="qube3"))
    assert spec.plant is FURUTA_DC and spec.plant_params == QUBE3
    assert spec.controller.u_max == 10.0


def test_sweep_runs_the_motor_plant_as_simulate_does(cli, tmp_path):
    from frictionlab.model.limit_cycles import trajectory_features

    out = tmp_path / "dc.csv"
    res = cli("sweep", "--plant", "qube2", "--vary", "friction.coulomb=0.1,0.2",
              "--vary", "plant.voltage_limit=8", "--duration", "6", "--workers", "1",
              "--out", str(out), "--no-progress")
    assert res.returncode == 0, res.stderr
    import csv

    rows = list(csv.DictReader(out.open()))
    assert [float(r["friction.coulomb"]) for r in rows] == [0.1, 0.2]
    for r in rows:
        cfg = build_config(plant="qube2", sets=[("friction.coulomb", r["friction.coulomb"]),
                                                ("plant.voltage_limit", "8")])
        f = trajectory_features(simulate_config(cfg, 6.0))
        assert float(r["period"]) == pytest.approx(f.period, rel=1e-9)
        assert float(r["max_u"]) == pytest.approx(f.max_u, rel=1e-9) and f.max_u <= 8.0


@pytest.mark.slow
def test_predict_finds_the_qube2_limit_cycle(cli):
    res = cli("predict", "--plant", "qube2", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    orbit = out["periodic_orbit"]
    assert orbit["found"] and orbit["stable"]
    sim = trajectory_features_of(build_config(plant="qube2"))
    assert orbit["features"]["period"] == pytest.approx(sim.period, rel=0.05)
    assert out["describing_function"]["period"] > 0


def trajectory_features_of(cfg):
    from frictionlab.model.limit_cycles import trajectory_features

    return trajectory_features(simulate_config(cfg, 40.0))


@pytest.mark.slow  # imports python-control
def test_to_control_and_linearize_take_the_motor_plant():
    import control

    import frictionlab as fl
    from frictionlab.model.plants.furuta_dc import linearization

    cfg = build_config(plant="qube2", friction="none")
    ss = fl.linearize(cfg)
    A, B = linearization(cfg.plant)
    np.testing.assert_allclose(ss.A, A, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(ss.B, B, rtol=1e-6, atol=1e-6)
    # the classical law holds a resting arm against a voltage below stiction
    sys = fl.to_control(build_config(plant="qube2"))
    dx = sys.dynamics(0.0, np.zeros(4), [0.1])
    assert dx[3] == pytest.approx(0.0, abs=1e-12)
    moving = sys.dynamics(0.0, np.zeros(4), [1.0])
    assert moving[3] > 0
    assert isinstance(sys, control.NonlinearIOSystem)


@pytest.mark.slow  # imports gymnasium
def test_the_qube_servo_2_gymnasium_env_steps_the_motor_plant_in_volts():
    import gymnasium

    import frictionlab.gym  # noqa: F401  (registers the ids)

    env = gymnasium.make("frictionlab/QubeServo2-v0")
    obs0, _ = env.reset(seed=1, options={"initial_angle": 0.05})
    assert env.action_space.high[0] == 10.0 and obs0[0] == pytest.approx(0.05)
    cfg = build_config(plant="qube2")
    spec = loop_spec(cfg)
    from frictionlab.model.simulation import SimulatedPlant

    plant = SimulatedPlant(spec)
    st = plant.init(0.05)
    for u in (3.0, -2.0, 20.0):
        _obs, _r, _term, _trunc, info = env.step(np.array([u]))
        st = plant.step(st, min(u, 10.0))
        assert info["theta"] == pytest.approx(st.x[0], abs=1e-12)
        assert info["u"] == min(u, 10.0)
    with pytest.raises(ValueError, match="converters"):
        gymnasium.make("frictionlab/QubeServo2-v0", observation="raw")


@pytest.mark.slow
def test_identify_limit_cycle_fits_the_motor_plants_coulomb_level_in_volts(cli, tmp_path):
    from frictionlab.model.limit_cycles import trajectory_features

    f = trajectory_features(simulate_config(build_config(plant="qube2"), 10.0), 5.0)
    measured = tmp_path / "m.json"
    measured.write_text(json.dumps({"experiments": [{"design": "fast", "features": {
        "peak1": f.peak1, "peak2": f.peak2, "valley": f.valley, "period": f.period}}]}))
    res = cli("identify", "limit-cycle", "--plant", "qube2", "--measured", str(measured),
              "--fit", "friction.coulomb", "--duration", "10", "--window", "5",
              "--maxiter", "3", "--popsize", "4", "--workers", "1", "--json")
    assert res.returncode == 0, res.stderr
    # the thesis's default bounds (0.2-4) would exclude 0.15 V: the plant's are [v/2, 2v]
    assert json.loads(res.stdout)["estimate"]["friction.coulomb"] == pytest.approx(0.15,
                                                                                   rel=1e-3)


def test_compensate_compare_runs_the_compensator_in_volts_on_the_qube2(cli):
    # the default pendulum observer; the compensator's innovation against the
    # model's arm prediction (docs/model.md, "The controller on a motor plant")
    res = cli("compensate", "compare", "--plant", "qube2", "--compensation", "lugre",
              "--duration", "10", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["status"] == "limit_cycle"
    assert out["features"]["max_u"] <= 10.0
    # the LuGre compensator with the scaled defaults shrinks the QUBE's cycle
    assert out["reduction"] > 1.5


def test_a_motor_plants_figure_title_names_the_plant_and_its_own_design_preset():
    from frictionlab.plotting import config_title

    title = config_title(build_config(plant="qube2"), "simulate")
    assert "plant qube2 (u in V)" in title and "fast design" in title
    assert "modified" not in title and "resistance" not in title
    changed = config_title(build_config(plant="qube2", sets=[("plant.resistance", "7")]))
    assert "resistance=7" in changed
