"""Predicting the friction limit cycle: closed-form oracles, long runs and the CLI."""

import json
import math

import control as ct
import numpy as np
import pytest
from scipy.optimize import brentq

from frictionlab.cli import main
from frictionlab.config import build_config
from frictionlab.model.design import design as make_design
from frictionlab.model.limit_cycles import FEATURES, crossings
from frictionlab.model.periodic import (
    I_S,
    LinearLoop,
    linear_loop,
    orbit_trajectory,
    periodic_orbit,
)
from frictionlab.model.plants.thesis import linearized_model, zoh
from frictionlab.runs import loop_spec, run_features, simulate_config
from frictionlab.studies.predict import (
    StaticFrictionNonlinearity,
    describing_function,
    discrete_describing_function_response,
    predict,
)

BAND = "friction.zero_velocity_band=0.03"
#: The zero-velocity band of each design's Tables (2-3 fast, 4-5 slow), as
#: ``frictionlab reproduce`` runs them (docs/model.md).
TABLE_BAND = {"fast": BAND, "slow": "friction.zero_velocity_band=0.001"}


def loop_of(tf_discrete) -> LinearLoop:
    """A LinearLoop whose three outputs are the output of a SISO discrete system."""
    ss = ct.ss(tf_discrete)
    A, B, C, D = (np.asarray(m, dtype=float) for m in ct.ssdata(ss))
    return LinearLoop(A, B, np.vstack([C, C, C]), np.vstack([D, D, D]), float(ss.dt))


# --------------------------------------------------------------------------
# describing function: closed-form oracles
# --------------------------------------------------------------------------


def test_relay_around_known_discrete_loop_gives_the_classic_oscillation():
    """Relay d around G(z) = b/(z - a)^3: the phase is -180 deg where
    arg(e^{jx} - a) = 60 deg, x = pi/3 + asin(-sqrt(3) a / 2), and the
    amplitude is 4 d |G| / pi."""
    a, b, Ts, d = 0.9, 0.01, 0.01, 1.5
    x = math.pi / 3 + math.asin(-math.sqrt(3) * a / 2)
    gain = b / abs(np.exp(1j * x) - a) ** 3
    H = ct.tf([b], np.poly([a, a, a]), Ts)
    cfg = build_config("fast", "coulomb", sets=[f"friction.coulomb={d}"])
    df = describing_function(cfg, loop=loop_of(H))
    assert df.amplitude == pytest.approx(4 * d * gain / math.pi, rel=1e-6)
    assert df.period == pytest.approx(2 * math.pi * Ts / x, rel=1e-6)
    assert [i.stable for i in df.intersections] == [True]


def test_relay_with_hysteresis_meets_the_horizontal_locus():
    """-1/N of a relay with hysteresis eps is -(pi/4d)(sqrt(A^2 - eps^2) + j eps):
    the cycle sits where Im G = -pi eps / (4 d), found here by bisection on
    the exact G."""
    a, b, Ts, d, eps = 0.9, 0.01, 0.01, 1.5, 0.3
    H = ct.tf([b], np.poly([a, a, a]), Ts)

    def G(w):
        return complex(H(np.exp(1j * w * Ts)))

    # between the phase crossover and the low frequencies Im G falls monotonically
    x180 = (math.pi / 3 + math.asin(-math.sqrt(3) * a / 2)) / Ts
    w = brentq(lambda w: G(w).imag + math.pi * eps / (4 * d), 0.3 * x180, x180)
    A = math.hypot(4 * d * (-G(w).real) / math.pi, eps)
    cfg = build_config("fast", "coulomb", sets=[f"friction.coulomb={d}",
                                                f"friction.hysteresis={eps}"])
    df = describing_function(cfg, loop=loop_of(H))
    assert df.amplitude == pytest.approx(A, rel=1e-6)
    assert df.period == pytest.approx(2 * math.pi / w, rel=1e-6)


def saturation_example():
    """python-control's describing-function example: 8/(s^3 + 2s^2 + 2s + 1)
    with a unit saturation.  Closed form: the phase crossover is at
    omega = sqrt(2) with H = -8/3, so N(A) = 3/8."""
    H = ct.tf([8], [1, 2, 2, 1])
    F = ct.saturation_nonlinearity(1)
    A = brentq(lambda A: F.describing_function(A) - 3 / 8, 1.01, 10.0)
    return H, F, A, math.sqrt(2)


def test_saturation_example_through_the_frequency_response_route():
    H, F, A, w = saturation_example()
    amps = np.linspace(1, 4, 10)
    omega = np.logspace(-1, 1, 400)
    got = discrete_describing_function_response(lambda om: H(1j * om), F, amps, omega)
    assert len(got) == 1
    assert got[0][0] == pytest.approx(A, rel=1e-3)
    assert got[0][1] == pytest.approx(w, rel=1e-3)
    # the same numbers python-control documents for its own example
    assert got[0][0] == pytest.approx(3.3438, abs=1e-3)


def test_discrete_time_workaround_returns_rad_per_s():
    """Sampled at Ts, the example keeps its oscillation (ZOH adds a phase lag of
    about omega Ts / 2, shifting it slightly); python-control's own function
    reports sin(omega Ts) instead of omega for a discrete system, our route
    reports omega."""
    H, F, A, w = saturation_example()
    Ts = 0.001
    Hd = ct.c2d(H, Ts, "zoh")
    amps = np.linspace(1, 4, 10)
    omega = np.logspace(-1, math.log10(0.99 * math.pi / Ts), 800)
    got = discrete_describing_function_response(lambda om: Hd(np.exp(1j * om * Ts)), F, amps,
                                                omega)
    assert len(got) == 1
    assert got[0][1] == pytest.approx(w, rel=2e-3)
    assert got[0][0] == pytest.approx(A, rel=5e-3)
    # the library's own discrete-time result, which the workaround exists for
    # (when this starts to fail, python-control has fixed it)
    raw = ct.describing_function_response(Hd, F, amps, omega, refine=False)
    assert raw.intersections[0][1] == pytest.approx(math.sin(w * Ts), rel=5e-3)


@pytest.mark.slow
def test_static_friction_describing_function():
    nl_relay = StaticFrictionNonlinearity(lambda v: 1.5 * np.sign(v), "relay")
    for A in (0.1, 1.0, 7.0):
        assert nl_relay.describing_function(A).real == pytest.approx(4 * 1.5 / (math.pi * A),
                                                                     rel=1e-9)

    def stribeck(v):  # dead band 0.2, then a Stribeck decay
        return 0.0 if abs(v) < 0.2 else np.sign(v) * (1.5 + 0.8 * math.exp(-v * v))

    nl = StaticFrictionNonlinearity(stribeck, "stribeck", breakpoints=(0.2,))
    for A in (0.5, 2.0):
        ref = ct.describing_function(stribeck, A, num_points=200_000, try_method=False)
        assert nl.describing_function(A).real == pytest.approx(ref.real, rel=1e-4)
    assert nl.describing_function(0.1) == 0


# --------------------------------------------------------------------------
# the pendulum loop
# --------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["fast", "slow"])
def test_linear_loop_equals_the_loop_built_by_hand(name):
    """Plant ZOH (exact), forward-difference pendulum observer, arm observer,
    u = -L x_hat: the simulator's linearised tick agrees to its integration
    error (the simulator's plant step is not the exact ZOH; 5e-5 measured)."""
    cfg = build_config(name, "coulomb")
    p, h = cfg.plant, cfg.design.h
    d = make_design(cfg.design, cfg.plant)
    A, B, _ = linearized_model(p.omega0, p.g, p.arm_length, p.zeta)
    Phi_p, Gam = zoh(A, B, h)
    k1, k2, k3, k4 = d.K
    w0, g, l, ku = cfg.design.omega0, d.g, p.arm_length, p.input_gain
    urow = np.zeros(8)
    urow[4:] = -np.array([d.L[0], d.L[1] * w0, d.L[2], d.L[3]])
    M = np.zeros((8, 8))
    M[:4, :4] = Phi_p
    M[:4] += ku * Gam @ urow[None]
    M[4, [0, 4, 5]] += [h * k1, 1 - h * k1, h * w0]
    M[5, [0, 4, 5]] += [h * k2, h * (w0 - k2), 1.0]
    M[5] += -h * w0 / g * urow
    M[6, [2, 6, 7]] += [k3, 1 - k3, h]
    M[6] += h * h / (2 * l) * urow
    M[7, [2, 6, 7]] += [k4, -k4, 1.0]
    M[7] += h / l * urow
    L = linear_loop(loop_spec(cfg))
    assert np.abs(L.Phi - M).max() < 2e-4
    assert np.abs(L.Gamma[:, 0] - np.concatenate([Gam[:, 0], np.zeros(4)])).max() < 1e-6
    assert np.allclose(L.C[2], urow, atol=1e-9)
    assert np.abs(L.poles()).max() < 1


@pytest.mark.slow
def test_describing_function_of_coulomb_friction_scales_with_the_level():
    """N is real for the relay, so the cycle sits at the loop's phase crossover
    whatever F_C, with A = 4 F_C |H| / pi."""
    out = []
    for fc in (1.1, 1.5, 1.9):
        cfg = build_config("fast", "classical", sets=[BAND, f"friction.coulomb={fc}"])
        df = describing_function(cfg)
        H = linear_loop(loop_spec(cfg)).frequency_response([2 * math.pi / df.period])[0]
        assert abs(H.imag) < 1e-9 * abs(H) and H.real < 0
        assert df.amplitude == pytest.approx(4 * fc * abs(H) / math.pi, rel=1e-9)
        out.append((df.period, df.amplitude / fc))
    assert out[0] == pytest.approx(out[1], rel=1e-9) == out[2]


def test_describing_function_leaves_out_what_it_cannot_describe():
    assert describing_function(build_config("fast", "viscous")).amplitude is None
    comp = describing_function(build_config("fast", "classical", "coulomb"))
    assert comp.amplitude is None and "uncompensated" in comp.message


# --------------------------------------------------------------------------
# periodic orbit against long runs
# --------------------------------------------------------------------------

TABLE_ROWS = [(design, f"{key}={v}")
              for design in ("fast", "slow")
              for key, values in (("friction.coulomb", (1.1, 1.3, 1.5, 1.7, 1.9)),
                                  ("friction.stiction", (1.9, 2.1, 2.3, 2.5, 2.7)))
              for v in values]

#: The first five random sets of docs/scripts/predict_study.py (seed 1).
RANDOM_SETS = [
    ("fast", "stribeck", ["friction.coulomb=1.860", "friction.stiction=1.981",
                          "plant.omega0=7.428", "plant.input_gain=0.925"]),
    ("slow", "coulomb", ["friction.coulomb=1.762", "friction.stiction=2.146",
                         "plant.omega0=6.869", "plant.input_gain=0.811",
                         "friction.hysteresis=0.05"]),
    ("slow", "lugre", ["friction.coulomb=1.364", "friction.stiction=2.417",
                       "plant.omega0=6.524", "plant.input_gain=0.981", "friction.sigma0=221",
                       "friction.sigma1=4.42"]),
    ("slow", "lugre", ["friction.coulomb=1.310", "friction.stiction=2.353",
                       "plant.omega0=6.493", "plant.input_gain=0.994", "friction.sigma0=983",
                       "friction.sigma1=7.77"]),
    ("fast", "classical", ["friction.coulomb=1.533", "friction.stiction=1.856",
                           "plant.omega0=6.325", "plant.input_gain=1.188", BAND]),
]


def assert_features_close(orbit_features, ref, rel=0.01):
    for k in FEATURES:
        a, b = getattr(orbit_features, k), getattr(ref, k)
        assert (a is None) == (b is None), k
        if a is not None:
            assert a == pytest.approx(b, rel=rel), k


@pytest.mark.slow
@pytest.mark.parametrize("design,row", TABLE_ROWS)
def test_orbit_features_match_long_runs_on_the_table_grids(design, row):
    cfg = build_config(design, "classical", sets=[TABLE_BAND[design], row])
    orbit = periodic_orbit(loop_spec(cfg))
    assert orbit.found and orbit.stable
    assert orbit.half_period
    assert_features_close(orbit.features, run_features(cfg, 300, 200))


@pytest.mark.parametrize("design,kind,sets", RANDOM_SETS)
def test_orbit_features_match_long_runs_on_random_sets(design, kind, sets):
    cfg = build_config(design, kind, sets=sets)
    orbit = periodic_orbit(loop_spec(cfg))
    assert orbit.found and orbit.stable
    assert_features_close(orbit.features, run_features(cfg, 300, 200))


def test_orbit_of_the_lugre_plant_with_the_k_term():
    """Sec. 5.3's LuGre plant with eq. (19)'s k = 1 acting (App. F's setting)."""
    cfg = build_config("fast", "lugre", sets=["friction.observer_gain=1"])
    orbit = periodic_orbit(loop_spec(cfg))
    assert orbit.found and orbit.stable and orbit.half_period
    assert_features_close(orbit.features, run_features(cfg, 300, 200))


def test_fixed_point_is_the_state_a_long_run_crosses_the_section_with():
    """The long run's state at a late upward crossing (plant and observer
    states, interpolated like the section) is the orbit's, to the sampling
    phase (a run's crossings fall anywhere between ticks)."""
    cfg = build_config("fast", "classical", sets=[BAND])
    orbit = periodic_orbit(loop_spec(cfg))
    traj = simulate_config(cfg, 60)
    w0 = cfg.design.omega0
    X = np.column_stack([traj["theta"], traj["theta_dot"], traj["arm"], traj["arm_dot"],
                         traj["theta_hat"], traj["theta_dot_hat"] / w0, traj["arm_hat"],
                         traj["arm_dot_hat"]])
    _t, up, _dt, _di = crossings(traj.t, traj["theta"], 0.05)
    k = int(up[-1])
    a = -X[k - 1, 0] / (X[k, 0] - X[k - 1, 0])
    crossing = X[k - 1] + a * (X[k] - X[k - 1])
    idx = [0, 1, 2, 3, I_S, I_S + 1, I_S + 2, I_S + 3]
    amplitude = np.abs(X[len(X) // 2:]).max(axis=0)
    assert np.abs((crossing - orbit.state[idx]) / amplitude).max() < 0.01


def test_half_and_full_period_maps_find_the_same_orbit():
    cfg = build_config("fast", "lugre")
    half, full = periodic_orbit(loop_spec(cfg)), periodic_orbit(loop_spec(cfg), symmetric=False)
    assert half.half_period and not full.half_period
    assert half.period == pytest.approx(full.period, rel=1e-4)
    assert_features_close(half.features, full.features, rel=1e-3)
    # the smooth LuGre loop: both give the same leading multiplier, well inside
    assert abs(abs(half.floquet_multipliers[0]) - abs(full.floquet_multipliers[0])) < 0.03
    assert abs(half.floquet_multipliers[0]) < 0.3


@pytest.mark.parametrize("kind,sets", [("lugre", []), ("classical", [BAND])])
def test_a_perturbation_dies_out_as_the_multipliers_say(kind, sets):
    """From 2 % off the orbit, a plain run comes back to it within four periods
    (to the floor of sampling phase and event timing, 0.1-0.2 %): the
    multipliers are inside the unit circle.  (One period is not enough to
    tell: the Jacobian is far from normal, a perturbation can first shrink by
    only half.)"""
    cfg = build_config("fast", kind, sets=sets)
    orbit = periodic_orbit(loop_spec(cfg))
    assert orbit.stable and abs(orbit.floquet_multipliers[0]) < 0.5
    w0 = cfg.design.omega0
    cols = ["theta_dot", "arm", "arm_dot", "theta_hat", "theta_dot_hat", "arm_hat",
            "arm_dot_hat"]
    idx = [1, 2, 3, I_S, I_S + 1, I_S + 2, I_S + 3]

    def section_states(run):
        _t, up, _dt, _di = crossings(run.t, run["theta"], 0.05)
        out = []
        for k in up:
            a = run["theta"][k - 1] / (run["theta"][k - 1] - run["theta"][k])
            y = np.array([run[c][k - 1] + a * (run[c][k] - run[c][k - 1]) for c in cols])
            y[4] /= w0
            out.append(y)
        return out

    ref = orbit_trajectory(loop_spec(cfg), orbit.state, 2.2 * orbit.period)
    scale = np.abs(np.column_stack([ref[c] for c in cols])).max(axis=0)
    scale[4] /= w0
    X = orbit.state.copy()
    X[idx] += 0.02 * scale
    states = section_states(orbit_trajectory(loop_spec(cfg), X, 4.2 * orbit.period))
    assert len(states) == 4
    dist = [np.abs((y - orbit.state[idx]) / scale).max() for y in states]
    assert dist[-1] < 0.003


def test_asymmetric_friction_uses_the_full_period_map():
    cfg = build_config("fast", "classical", sets=[BAND, "friction.coulomb_negative=1.2"])
    orbit = periodic_orbit(loop_spec(cfg))
    assert orbit.found and not orbit.half_period
    assert_features_close(orbit.features, run_features(cfg, 300, 200))


def test_no_orbit_without_switching_friction_or_when_the_pendulum_falls():
    none = periodic_orbit(loop_spec(build_config("fast", "none")))
    assert not none.found and none.stable is None and "no switching" in none.message
    fell = periodic_orbit(loop_spec(build_config("fast", "classical",
                                                 sets=[BAND, "design.omega2=1"])))
    assert run_features(build_config("fast", "classical", sets=[BAND, "design.omega2=1"]),
                        60).status == "fell"
    assert not fell.found and "fell" in fell.message


def test_compensated_loop_has_an_orbit_but_no_describing_function():
    cfg = build_config("slow", "classical", "coulomb", sets=[BAND])
    p = predict(cfg)
    assert p.periodic_orbit.found
    assert_features_close(p.periodic_orbit.features, run_features(cfg, 300, 200))
    assert p.describing_function.amplitude is None


# --------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------


@pytest.mark.slow
def test_cli_predict_json(capsys, tmp_path):
    plot = tmp_path / "p.png"
    assert main(["predict", "--set", BAND, "--json", "--plot", str(plot)]) == 0
    out = json.loads(capsys.readouterr().out)
    po, df = out["periodic_orbit"], out["describing_function"]
    assert po["found"] is True and po["stable"] is True
    assert set(po["features"]) == set(FEATURES)
    assert all(len(m) == 2 for m in po["floquet_multipliers"])
    assert df["period"] > 0 and df["amplitude"] > 0
    assert plot.stat().st_size > 10_000


@pytest.mark.slow
def test_cli_predict_text_and_noise_note(capsys):
    assert main(["predict", "--design", "slow", "--friction", "lugre", "--set",
                 "sim.noise=0.001"]) == 0
    cap = capsys.readouterr()
    assert "periodic orbit: found, stable" in cap.out
    assert "noise" in cap.err


@pytest.mark.parametrize("argv", [
    ["predict", "--set", "friction.coulomb=-1", "--json"],
    ["predict", "--set", "nope.key=1", "--json"],
    ["predict", "--plot", "p.txt", "--json"],
])
def test_cli_predict_bad_input_exits_2(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0]
