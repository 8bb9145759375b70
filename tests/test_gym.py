"""Gymnasium environment frictionlab/Furuta-v0 (frictionlab.gym)."""

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import frictionlab.gym as fgym
from frictionlab.config import build_config
from frictionlab.gym import DEFAULT_RANDOMIZATION, ENV_ID, FurutaEnv, FurutaVectorEnv
from frictionlab.model.rig import RigScaling
from frictionlab.runs import make_controller, simulate_config

NORMALISE_HINT = "symmetric and normalized space"


def _check(env):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    return [str(w.message) for w in caught]


@pytest.mark.parametrize("kwargs", [
    {},
    {"action": "u_da", "observation": "raw"},
    {"friction": "lugre", "randomize": True, "sets": ["sim.noise=0.002",
                                                      "sim.quantization=1"]},
    {"friction": "coulomb", "action": "u_da",
     "randomize": {"friction.coulomb": (0.5, 1.5), "friction_kind": ("coulomb", "lugre")}},
])
def test_passes_gymnasiums_env_checker(kwargs):
    env = gymnasium.make(ENV_ID, **kwargs)
    msgs = _check(env.unwrapped)
    # the only remark: an action in m/s^2 is not normalised (u_da is)
    if kwargs.get("action") == "u_da":
        assert msgs == []
    else:
        assert all(NORMALISE_HINT in m for m in msgs), msgs


def test_registered_with_a_10_s_time_limit():
    spec = gymnasium.spec(ENV_ID)
    assert spec.max_episode_steps == fgym.MAX_EPISODE_STEPS == 2000
    env = gymnasium.make(ENV_ID, friction="none")
    env.reset(seed=3, options={"initial_angle": 0.0})
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, info = env.step(np.zeros(1))
        steps += 1
        assert not terminated  # exactly upright, no friction, no input: it stays
    assert steps == 2000 and info["t"] == pytest.approx(10.0)


@pytest.mark.parametrize("friction", ["classical", "lugre", "coulomb"])
def test_frictionlab_controller_as_policy_replays_the_simulator_exactly(friction):
    """Same compiled plant, same sensor, same controller: the env run is the
    simulator's run, tick for tick, bit for bit."""
    cfg = build_config("fast", friction, sets=["sim.initial_angle=0.08"])
    traj = simulate_config(cfg, 3.0)
    ctrl = make_controller(cfg)
    env = FurutaEnv(cfg)
    obs, info = env.reset(seed=0, options={"initial_angle": 0.08})
    s = ctrl.init(0.08)
    for k in range(len(traj)):
        np.testing.assert_array_equal(obs, [traj["theta_m"][k], traj["arm_m"][k],
                                            traj["arm_dot_m"][k]])
        assert info["theta"] == traj["theta"][k] and info["arm_dot"] == traj["arm_dot"][k]
        out, s = ctrl.step(s, *obs)
        assert out.u == traj["u"][k]
        obs, reward, terminated, _, info = env.step(env.action_from_u(out.u))
        assert info["friction"] == traj["friction"][k] and not terminated
        assert reward == pytest.approx(
            1 - (info["theta"] / (math.pi / 2)) ** 2 - 0.01 * (out.u * 0.022) ** 2)


def test_noise_and_quantisation_like_the_simulator():
    r = RigScaling()
    env = FurutaEnv(sets=["sim.noise=0.01", "sim.quantization=1"], friction="none")
    obs, info = env.reset(seed=5, options={"initial_angle": 0.0})
    errs = []
    for _ in range(1000):
        # quantised to the ADC steps of App. B, in raw units (biases included; the
        # arm relative to its first reading)
        raw = np.array([obs[0] / r.theta_scale - r.theta_bias, obs[1] / r.arm_scale,
                        obs[2] / r.velocity_scale - r.velocity_bias]) / (2 / 4096)
        np.testing.assert_allclose(raw, np.round(raw), atol=1e-6)
        errs.append(obs - [info["theta"], info["arm"], info["arm_dot"]])
        obs, _, _, _, info = env.step(np.zeros(1))
    errs = np.array(errs)
    # noise of standard deviation 0.01 (plus quantisation's q/sqrt(12), well below it)
    np.testing.assert_allclose(errs.std(axis=0), 0.01, rtol=0.12)
    np.testing.assert_allclose(errs.mean(axis=0)[[0, 2]], 0.0, atol=0.002)
    # the arm is measured from its first reading: its error is the noise less the first draw
    assert abs(errs[0, 1]) <= 25.8 * 2 / 4096
    # reproducible from the seed
    env2 = FurutaEnv(sets=["sim.noise=0.01", "sim.quantization=1"], friction="none")
    a, _ = env2.reset(seed=5, options={"initial_angle": 0.0})
    b, _ = env.reset(seed=5, options={"initial_angle": 0.0})
    np.testing.assert_array_equal(a, b)


def test_raw_observation_is_the_rigs_adc_reading():
    sets = ["sim.quantization=1", "sim.initial_angle=0.05"]
    si, raw = FurutaEnv(sets=sets), FurutaEnv(sets=sets, observation="raw")
    scaling = RigScaling()
    a, _ = si.reset(seed=1)
    b, _ = raw.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(200):
        assert np.all(np.abs(b) <= 1.0)
        np.testing.assert_allclose(
            [scaling.theta(b[0]), scaling.arm(b[1]), scaling.arm_velocity(b[2])], a,
            atol=1e-12)
        act = rng.uniform(-3.0, 3.0, size=1)
        a, _, term_a, _, _ = si.step(act)
        b, _, term_b, _, _ = raw.step(act)
        assert term_a == term_b
        if term_a:
            break


def test_u_da_action_is_the_dac_value():
    env_u, env_da = FurutaEnv(friction="lugre"), FurutaEnv(friction="lugre", action="u_da")
    assert env_da.action_space.low[0] == -1 and env_da.action_space.high[0] == 1
    env_u.reset(seed=2)
    env_da.reset(seed=2)
    for u_da in (0.1, -0.3, 1.0, -1.0):
        a, *_ = env_u.step(np.array([u_da / -0.022]))
        b, *_, ib = env_da.step(np.array([u_da]))
        np.testing.assert_allclose(a, b, rtol=1e-12)
        assert ib["u"] == pytest.approx(u_da / -0.022)
    # the DAC saturates: an action beyond the range applies the largest u
    assert env_da.u_from_action([3.0]) == pytest.approx(-1 / 0.022)
    assert env_u.u_from_action([-1e6]) == pytest.approx(-1 / 0.022)
    np.testing.assert_allclose(env_da.action_from_u(10.0), [-0.22])
    with pytest.raises(ValueError, match="finite"):
        env_u.step(np.array([math.nan]))


def test_falling_pendulum_terminates_past_the_fall_angle():
    env = FurutaEnv(friction="none", sets=["sim.fall_angle=0.5"])
    env.reset(seed=0, options={"initial_angle": 0.05})
    for _ in range(400):
        _, reward, terminated, _, info = env.step(np.zeros(1))
        if terminated:
            break
    assert terminated and abs(info["theta"]) > 0.5 and reward < 0
    # it fell when the unstable pendulum (omega0 = 6.8 rad/s) reached 0.5 rad
    assert info["t"] == pytest.approx(math.acosh(0.5 / 0.05) / 6.8, abs=0.02)


def test_randomisation_draws_each_episode_within_the_ranges():
    base = build_config("fast", "lugre")
    env = FurutaEnv(base, randomize=True)
    seen = []
    for ep in range(20):
        _, info = env.reset(seed=100 + ep)
        p = info["params"]
        assert set(p) == set(DEFAULT_RANDOMIZATION)
        for key, (lo, hi) in DEFAULT_RANDOMIZATION.items():
            if key != "friction.stiction":
                assert lo * base.get(key) <= p[key] <= hi * base.get(key)
            assert env.config.get(key) == p[key]  # the plant of this episode
        assert p["friction.stiction"] >= p["friction.coulomb"]
        seen.append(p["plant.omega0"])
    assert len(set(seen)) == 20 and np.ptp(seen) > 0.6  # spread over [6.12, 7.48]
    # the seed fixes the draw
    _, a = env.reset(seed=7)
    _, b = env.reset(seed=7)
    assert a["params"] == b["params"]
    env = FurutaEnv(randomize={"friction_kind": ("coulomb", "lugre", "none")})
    kinds = {env.reset(seed=s)[1]["params"]["friction_kind"] for s in range(30)}
    assert kinds == {"coulomb", "lugre", "none"}


@pytest.mark.parametrize("randomize,msg", [
    ({"plant.omega0": (1.2, 1.1)}, "plant.omega0"),
    ({"sim.noise": (1, 2)}, "only plant"),
    ({"plant.zeta": (0.5, 40.0)}, "plant.zeta"),  # 0.04 x 40 > 1
    ({"plant.bogus": (1, 2)}, "plant.bogus"),
    ({"friction_kind": ("dry",)}, "friction_kind"),
    ({"plant.omega0": 1.1}, "plant.omega0"),
])
def test_bad_randomisation_is_refused_naming_the_key(randomize, msg):
    with pytest.raises(ValueError, match=msg):
        FurutaEnv(randomize=randomize)


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="observation"):
        FurutaEnv(observation="pixels")
    with pytest.raises(ValueError, match="action"):
        FurutaEnv(action="torque")
    with pytest.raises(ValueError, match="render_mode"):
        FurutaEnv(render_mode="human")
    env = FurutaEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(1))
    with pytest.raises(ValueError, match="initial_angle"):
        env.reset(options={"initial_angle": 2.0})


@pytest.mark.slow
def test_make_vec_gives_the_native_vector_env():
    venv = gymnasium.make_vec(ENV_ID, num_envs=3, friction="lugre")
    assert isinstance(venv.unwrapped, FurutaVectorEnv) and venv.num_envs == 3
    assert venv.observation_space.shape == (3, 3) and venv.action_space.shape == (3, 1)
    assert venv.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.NEXT_STEP
    obs, info = venv.reset(seed=0)
    assert obs in venv.observation_space and info["theta"].shape == (3,)
    obs, reward, term, trunc, info = venv.step(venv.action_space.sample())
    assert obs.shape == (3, 3) and reward.shape == term.shape == trunc.shape == (3,)
    assert info["_theta"].all() and np.all(info["t"] == 0.005)
    assert venv.unwrapped.max_episode_steps == 2000  # the registered time limit


@pytest.mark.parametrize("friction", ["classical", "lugre"])
def test_vector_copies_step_exactly_like_single_envs(friction):
    """No noise, no randomisation: copy i of the vector env is a FurutaEnv with
    the same start and actions, bit for bit, through a fall and its autoreset."""
    n, angles = 3, [0.02, -0.05, 0.08]
    venv = FurutaVectorEnv(n, friction=friction, max_episode_steps=150)
    envs = [FurutaEnv(friction=friction) for _ in range(n)]
    obs, _ = venv.reset(seed=0, options={"initial_angle": angles})
    single = [e.reset(seed=0, options={"initial_angle": a})[0] for e, a in zip(envs, angles,
                                                                               strict=True)]
    np.testing.assert_array_equal(obs, single)
    rng = np.random.default_rng(1)
    twins: list = list(envs)
    restart = np.zeros(n, dtype=bool)
    restarts = 0
    for _ in range(400):
        acts = rng.uniform(-8.0, 8.0, size=(n, 1))
        obs, rew, term, trunc, info = venv.step(acts)
        for i in range(n):
            if restart[i]:  # the copy's episode ended last step: restarted now
                assert rew[i] == 0.0 and not term[i] and not trunc[i] and info["t"][i] == 0
                assert abs(info["theta"][i]) <= 0.05  # drawn in +-|sim.initial_angle|
                twins[i] = None  # its single twin's episode is over
                restarts += 1
            elif twins[i] is not None:
                o, r, te, _, inf = twins[i].step(acts[i])
                np.testing.assert_array_equal(obs[i], o)
                assert rew[i] == r and term[i] == te
                assert info["friction"][i] == inf["friction"]
                assert trunc[i] == (inf["t"] >= 150 * 0.005 - 1e-12 and not te)
        restart = term | trunc
        if all(t is None for t in twins):
            break
    assert restarts == n  # every copy ended (fell, or truncated at 150 steps) and restarted


def test_vector_randomises_each_copy():
    venv = FurutaVectorEnv(6, friction="lugre", randomize=True)
    venv.reset(seed=3)
    omegas = [c.plant.omega0 for c in venv.configs]
    assert len(set(omegas)) == 6 and all(6.8 * 0.9 <= w <= 6.8 * 1.1 for w in omegas)
    venv.reset(seed=3)
    assert [c.plant.omega0 for c in venv.configs] == omegas
    with pytest.raises(ValueError, match="num_envs"):
        FurutaVectorEnv(0)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((5, 1)))


# --- the swing-up variant ---------------------------------------------------------------


@pytest.mark.parametrize("kwargs", [{}, {"action": "u_da", "observation": "raw",
                                         "randomize": True, "sets": ["sim.noise=0.002"]}])
def test_swing_up_variant_passes_the_env_checker(kwargs):
    env = gymnasium.make(fgym.SWINGUP_ENV_ID, **kwargs)
    assert env.spec.max_episode_steps == 2000
    msgs = _check(env.unwrapped)
    assert all(NORMALISE_HINT in m for m in msgs), msgs
    assert env.unwrapped._s.task == "swing_up"


def test_swing_up_episode_starts_hanging_and_the_energy_controller_brings_it_up():
    from frictionlab.model.swingup import SwingUp

    env = gymnasium.make(fgym.SWINGUP_ENV_ID, sets=["sim.noise=0.002"])
    obs, info = env.reset(seed=4)
    assert abs(abs(info["theta"]) - math.pi) <= 0.05 and info["theta_dot"] == 0.0
    assert abs(obs[0]) > 3.0  # measured angle wrapped into [-pi, pi)
    cfg = env.unwrapped.config
    ctl = SwingUp(make_controller(cfg), cfg.swingup)
    state = ctl.init(obs[0])
    rewards = []
    for _ in range(1600):  # 8 s
        out, state = ctl.step(state, *obs)
        obs, r, terminated, truncated, info = env.step(env.unwrapped.action_from_u(out.u))
        rewards.append(r)
        assert not terminated and not truncated
        assert -math.pi <= obs[0] < math.pi
    assert out.phase == "balancing"
    assert rewards[0] < 0.01 and min(rewards[-200:]) > 0.95
    assert abs(math.remainder(info["theta"], 2 * math.pi)) < 0.35


def test_swing_up_terminates_at_the_arm_limits_not_at_the_fall_angle():
    env = gymnasium.make(fgym.SWINGUP_ENV_ID)
    env.reset(seed=0, options={"initial_angle": math.pi})
    for _k in range(400):
        _, _, terminated, _, info = env.step(np.array([20.0]))
        if terminated:
            break
    assert terminated
    su = env.unwrapped.config.swingup
    assert abs(info["arm"]) > su.arm_limit or abs(info["arm_dot"]) > su.arm_speed_limit
    vec = FurutaVectorEnv(3, task="swing_up")
    obs, _ = vec.reset(seed=1)
    assert np.all(np.abs(obs[:, 0]) > 3.0)
    _, r, term, _, _ = vec.step(np.zeros((3, 1)))
    assert not term.any() and np.all(r < 0.01)
    with pytest.raises(ValueError, match="task"):
        FurutaEnv(task="juggle")
