"""python-control interop: frictionlab.to_control / frictionlab.linearize, design.gains."""

import json
import subprocess
import sys

import control
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import frictionlab as fl
from frictionlab.config import build_config
from frictionlab.model.friction import make_model
from frictionlab.model.plants.thesis import linearized_model, zoh
from frictionlab.runs import simulate_config

CLI = [sys.executable, "-m", "frictionlab"]


@pytest.mark.slow
def test_import_frictionlab_does_not_import_python_control():
    code = ("import sys, frictionlab; assert 'control' not in sys.modules; "
            "f = frictionlab.linearize; assert 'control' in sys.modules; print(f.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "frictionlab.interop"
    assert "to_control" in dir(fl) and "linearize" in fl.__all__


@pytest.mark.parametrize("friction", ["none", "coulomb", "classical", "stribeck"])
def test_linearize_equals_eq7_with_friction_off(friction):
    # the discontinuous laws have no derivative at rest: their linearisation is eq. (7)
    cfg = build_config("fast", friction, sets=["plant.zeta=0"])
    ss = fl.linearize(cfg)
    assert isinstance(ss, control.StateSpace) and ss.isctime()
    A, B, C = linearized_model(6.8, 9.82, 0.21)
    np.testing.assert_allclose(ss.A, A, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ss.B, B, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(ss.C, C)
    np.testing.assert_array_equal(ss.D, np.zeros((3, 1)))
    assert ss.state_labels == ["theta", "theta_dot", "arm", "arm_dot"]
    assert ss.input_labels == ["u"] and ss.output_labels == ["theta", "arm", "arm_dot"]


def test_linearize_with_damping_gain_and_other_parameters():
    cfg = build_config("fast", "none", sets=["plant.zeta=0.1", "plant.omega0=7.3",
                                              "plant.input_gain=1.2", "plant.arm_length=0.3"])
    ss = fl.linearize(cfg)
    A, B, _ = linearized_model(7.3, 9.82, 0.3, zeta=0.1)
    np.testing.assert_allclose(ss.A, A, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ss.B, 1.2 * B, rtol=0, atol=1e-9)


def test_linearize_default_config_is_the_damped_frictionless_plant():
    ss = fl.linearize()
    A, B, _ = linearized_model(6.8, 9.82, 0.21, zeta=0.04)
    np.testing.assert_allclose(ss.A, A, atol=1e-9)
    np.testing.assert_allclose(ss.B, B, atol=1e-9)


def test_linearize_viscous_and_lugre_presliding():
    cfg = build_config("fast", "viscous", sets=["plant.zeta=0", "friction.viscous=0.3"])
    A = linearized_model(6.8, 9.82, 0.21)[0]
    A[3, 3] = -0.3 / 0.21
    A[1, 3] = 6.8**2 / 9.82 * 0.3
    np.testing.assert_allclose(fl.linearize(cfg).A, A, atol=1e-9)


@pytest.mark.parametrize("k", [0.0, 1.5])
def test_linearize_lugre_presliding_with_the_plants_observer_term(k):
    s0, s1, fv = 120.0, 4.0, 0.07
    cfg = build_config("fast", "lugre", sets=["plant.zeta=0", f"friction.sigma0={s0}",
                                              f"friction.sigma1={s1}", f"friction.viscous={fv}",
                                              f"friction.observer_gain={k}"])
    ss = fl.linearize(cfg)
    assert ss.state_labels[-1] == "z"
    w2g, L1 = 6.8**2 / 9.82, 0.21
    # z' = Omega_dot + k theta (eq. 19, e = -theta), F = s0 z + s1 z' + fv Omega_dot,
    # a = u - F
    A5 = np.zeros((5, 5))
    A5[0, 1] = A5[2, 3] = 1.0
    A5[1, 0] = 6.8**2 + w2g * s1 * k
    A5[1, 3], A5[1, 4] = w2g * (s1 + fv), w2g * s0
    A5[3, 0] = -s1 * k / L1
    A5[3, 3], A5[3, 4] = -(s1 + fv) / L1, -s0 / L1
    A5[4, 0], A5[4, 3] = k, 1.0
    np.testing.assert_allclose(ss.A, A5, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ss.B.ravel(), [0, -w2g, 0, 1 / L1, 0], atol=1e-9)


def test_design_model_zoh_of_linearize_is_the_designs_phi_gamma():
    cfg = build_config("fast", "none", sets=["plant.zeta=0"])
    sysd = control.c2d(fl.linearize(cfg), cfg.design.h)
    d = fl.design("fast")
    np.testing.assert_allclose(sysd.A, d.feedback.Phi, atol=1e-9)
    np.testing.assert_allclose(sysd.B, d.feedback.Gamma, atol=1e-9)


def _sys(friction, *sets):
    return fl.to_control(build_config("fast", friction, sets=list(sets)))


def _dx(sys, x, u):
    return np.asarray(sys.updfcn(0.0, np.asarray(x, float), np.array([u]), sys.params))


def test_to_control_names_and_outputs():
    sys_ = _sys("lugre")
    assert isinstance(sys_, control.NonlinearIOSystem) and sys_.isctime()
    assert sys_.state_labels == ["theta", "theta_dot", "arm", "arm_dot", "z"]
    assert sys_.input_labels == ["u"] and sys_.output_labels == ["theta", "arm", "arm_dot"]
    x = np.array([0.1, 0.2, 0.3, 0.4, 0.001])
    np.testing.assert_array_equal(sys_.outfcn(0.0, x, [0.0], {}), [0.1, 0.3, 0.4])
    assert _sys("classical").nstates == 4


@settings(max_examples=60, deadline=None)
@given(u=st.floats(-2.0, 2.0), th=st.floats(-0.5, 0.5), thd=st.floats(-3, 3))
def test_classical_friction_holds_the_arm_below_stiction(u, th, thd):
    # at rest, a force below F_S = 2.3 is balanced: no arm motion, no push on the pendulum
    sys_ = _sys("classical")
    dx = _dx(sys_, [th, thd, 0.0, 0.0], u)
    assert dx[3] == 0.0
    free = _dx(_sys("none"), [th, thd, 0.0, 0.0], 0.0)
    assert dx[1] == pytest.approx(free[1], abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(u=st.floats(-20.0, 20.0), v=st.floats(0.01, 5.0), sign=st.sampled_from([-1.0, 1.0]))
def test_coulomb_and_viscous_friction_oppose_sliding(u, v, sign):
    v *= sign
    dx = _dx(_sys("coulomb", "plant.input_gain=1.1"), [0.0, 0.0, 0.0, v], u)
    assert dx[3] == pytest.approx((1.1 * u - 1.5 * sign) / 0.21, rel=1e-12, abs=1e-12)
    dx = _dx(_sys("viscous", "friction.viscous=0.4"), [0.0, 0.0, 0.0, v], u)
    assert dx[3] == pytest.approx((u - 0.4 * v) / 0.21, rel=1e-12, abs=1e-12)


def test_lugre_steady_state_is_the_stribeck_curve():
    model = make_model("lugre")
    sys_ = _sys("lugre")
    for v in (-2.0, -0.3, 0.05, 0.7, 3.0):
        p = model.params
        g = (p.coulomb + (p.stiction - p.coulomb) * np.exp(-(v / p.stribeck_velocity) ** 2))
        z_ss = np.sign(v) * g / p.sigma0  # dz = 0
        dx = _dx(sys_, [0.0, 0.0, 0.0, v, z_ss], 0.0)
        assert abs(dx[4]) < 1e-12
        assert -dx[3] * 0.21 == pytest.approx(model.steady_state(v), rel=1e-12)


def test_to_control_refuses_coulomb_hysteresis():
    with pytest.raises(ValueError, match=r"friction\.hysteresis"):
        _sys("coulomb", "friction.hysteresis=0.05")
    with pytest.raises(TypeError, match="Config"):
        fl.to_control({"plant.omega0": 7})


def _worst_sample_error(cfg):
    """Largest state difference after one sample between the simulator and
    to_control's plant integrated to 1e-10 from the same state with the same
    held u, over a closed-loop run."""
    traj = simulate_config(cfg, 1.5)
    sys_ = fl.to_control(cfg)
    cols = ["theta", "theta_dot", "arm", "arm_dot", "z"][:sys_.nstates]
    states = np.column_stack([traj[c] for c in cols])
    worst = 0.0
    for k in range(len(traj) - 1):
        u = traj["u"][k]
        sol = solve_ivp(lambda t, y, u=u: _dx(sys_, y, u), (0.0, traj.h), states[k],
                        rtol=1e-10, atol=1e-12, method="DOP853")
        worst = max(worst, float(np.max(np.abs(sol.y[:4, -1] - states[k + 1, :4]))))
    return worst


@pytest.mark.slow
@pytest.mark.parametrize("friction,k,fine_bound", [("none", 0, 1e-7), ("lugre", 0, 5e-6),
                                                   ("lugre", 1, 5e-6)])
def test_the_simulator_converges_to_to_controls_plant(friction, k, fine_bound):
    """Same plant, same friction law (LuGre with eq. 19's term, e = -theta):
    the simulator's one-sample error against to_control's exact solution
    shrinks with its substeps (second order)."""
    sets = ["sim.initial_angle=0.1", f"friction.observer_gain={k}"]
    coarse = _worst_sample_error(build_config("fast", friction, sets=sets))
    fine = _worst_sample_error(build_config(
        "fast", friction, sets=[*sets, "sim.substeps=40", "sim.pendulum_steps=40"]))
    assert coarse < 1e-4  # the simulator's default accuracy
    assert fine < fine_bound and fine < coarse / 20, (coarse, fine)


@pytest.mark.slow
def test_lqr_from_python_control_through_design_gains(cli):
    cfg = build_config("fast", "none", sets=["plant.zeta=0"])
    sysd = control.c2d(fl.linearize(cfg), cfg.design.h)
    K, _, E = control.dlqr(sysd.A, sysd.B, np.diag([100.0, 0.0, 100.0, 1.0]), 1.0)
    gains = ",".join(f"{k:.17g}" for k in K.ravel())
    out = cli("design", "--set", f"design.gains={gains}", "--json")
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    np.testing.assert_array_equal(d["L"], K.ravel())
    assert d["method"] == "given" and d["spec"]["gains"] == list(K.ravel())
    poles = np.array([complex(*p) for p in d["poles"]])
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(E), atol=1e-9)
    # the observers keep their specs: K of the fast design
    np.testing.assert_allclose(d["K"], fl.design("fast").K)
    # and the loop runs on them: a friction-free plant settles
    cfg = build_config("fast", "none", sets=[f"design.gains={gains}"])
    traj = simulate_config(cfg, 10.0)
    assert traj.status == "ok" and abs(traj["theta"][-1]) < 1e-4


def test_design_gains_replace_placement_everywhere():
    spec = fl.preset("fast")
    import dataclasses

    L = (-80.0, -11.0, -18.0, -6.5)
    d = fl.design(dataclasses.replace(spec, gains=L))
    np.testing.assert_array_equal(d.L, L)
    Phi, Gamma = zoh(*linearized_model(6.8, 9.82, 0.21)[:2], 0.005)
    eig = np.linalg.eigvals(Phi - Gamma @ np.array(L).reshape(1, 4))
    np.testing.assert_allclose(np.sort_complex(d.feedback.achieved_poles),
                               np.sort_complex(eig), atol=1e-12)
    assert d.feedback.max_pole_error == 0.0
    # TOML arrays and the --set list give the same spec
    a = build_config(sets=[("design.gains", [-80, -11, -18, -6.5])]).design
    b = build_config(sets=["design.gains=-80,-11,-18,-6.5"]).design
    assert a == b and a.gains == L
    assert build_config(sets=["design.gains=none"]).design == spec


@pytest.mark.parametrize("value,msg", [
    ("1,2,3", "design.gains must be 4 finite numbers"),
    ("1,2,3,nan", "design.gains must be 4 finite numbers"),
    ("1,x,3,4", "design.gains: 'x' is not a number"),
    ("1,,3,4", "design.gains: '1,,3,4' is not a comma-separated list"),
])
def test_bad_design_gains_exit_2_naming_the_key(value, msg, capsys):
    from frictionlab.cli import main

    assert main(["simulate", "--set", f"design.gains={value}", "--json"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1 and msg in out.err, out.err


def test_design_gains_survive_a_sweep_resume(tmp_path, capsys):
    from frictionlab.cli import main

    gains = "design.gains=-69.5989,-10.1414,-9.39986,-4.99165"
    out = str(tmp_path / "g.csv")
    base = ["sweep", "--set", gains, "--duration", "4", "--workers", "1", "--no-progress",
            "--out", out, "--json"]
    assert main([*base, "--vary", "friction.coulomb=1.3,1.5"]) == 0
    assert main([*base, "--vary", "friction.coulomb=1.3,1.5,1.7", "--resume"]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["rows"] == 3
    # other gains are another sweep
    other = ["sweep", "--set", "design.gains=-70,-10,-9,-5", *base[3:]]
    assert main([*other, "--vary", "friction.coulomb=1.3,1.5", "--resume"]) == 2
    assert "design.gains" in capsys.readouterr().err
