r"""Gymnasium environment ``frictionlab/Furuta-v0``: the sampled loop at h = 5 ms.

``import frictionlab.gym`` registers the id (needs the ``gym`` extra,
``pip install 'frictionlab[gym]'``); then ``gymnasium.make("frictionlab/Furuta-v0")``.
An outer layer: this module imports gymnasium, the model does not.

One step is one sampling period ``design.h`` (5 ms) of the simulator's own
plant (:func:`frictionlab.model.plants.plant_step`, the compiled integrator of
``frictionlab simulate`` and of :class:`~frictionlab.model.simulation.SimulatedPlant`,
with the configured arm friction, any model), with the action held
(zero-order hold), exactly as the simulator's controller tick drives it.
The observation is what the rig measures at the start of the next tick.

:class:`FurutaVectorEnv` (``gymnasium.make_vec("frictionlab/Furuta-v0",
num_envs=N)``) steps N copies in one compiled loop, with next-step
autoreset: 3.5-7 (16 copies) to 16-27 (64 copies) times the environment steps
per second of Gymnasium's ``SyncVectorEnv`` over single environments
(``benchmarks/gym.py``, docs/performance.md).

Observation (``observation="si"``, the default)
    ``[theta_m, arm_m, arm_dot_m]``: measured pendulum angle (rad), arm angle
    (rad) and arm velocity (rad/s), with the simulator's sensor: Gaussian
    noise of standard deviation ``sim.noise`` in each signal's SI unit (drawn
    from the environment's generator, seeded by ``reset(seed=...)``), then the
    rig's 12-bit converter of App. B when ``sim.quantization`` is 1
    (:mod:`frictionlab.model.sensor`: the grid in raw units, biases included; the
    arm relative to its first reading).
``observation="raw"``
    The same measurements as the rig's raw ADC values ``[y, x, v]`` in
    [-1, 1] (App. B.5 scaling, :class:`frictionlab.model.rig.RigScaling`; the
    angle channels wrap, the velocity channel saturates).
Action (``action="u"``, the default)
    The control signal u in m/s^2, in [-u_max, u_max] with u_max = 1/0.022
    (the DAC range); values outside are saturated as the DAC does.
``action="u_da"``
    The DAC value u_DA = -0.022 u in [-1, 1] (App. B.3), the normalised
    action most RL libraries prefer.
Reward
    ``1 - (theta/fall_angle)^2 - 0.01 (u/u_max)^2`` per step, from the true
    pendulum angle and the applied u: 1 for a pendulum held exactly upright
    with no effort.
Episode
    Starts with the pendulum at rest at an angle drawn uniformly from
    ``[-a, a]``, ``a = |sim.initial_angle|`` (0.05 rad by default; ``reset(
    options={"initial_angle": x})`` sets it exactly), arm at rest at 0.
    *Terminated* when ``|theta| > sim.fall_angle`` (pi/2) or the state is
    not finite, as in the simulator; *truncated* after 2000 steps (10 s)
    by :func:`gymnasium.make`'s time limit.
Info
    The true state ``theta, theta_dot, arm, arm_dot, z`` (SI), the applied
    ``u``, the mean arm ``friction`` over the step (m/s^2), the time ``t``
    (s); after a reset also ``params``: the episode's randomised values (the
    vector environment: arrays of these, without ``params``).

Randomisation per episode (``randomize=True`` or a dict)
    Each reset draws the plant and friction parameters anew, uniformly,
    as multipliers of the configured values (:data:`DEFAULT_RANDOMIZATION`):
    ``plant.omega0`` x [0.9, 1.1] (the thesis's estimates span 6.8-7.5 rad/s),
    ``plant.zeta`` x [0.5, 1.5], ``plant.input_gain`` x [0.8, 1.2] (the k_u
    uncertainty of App. B.4), ``friction.stiction`` and ``friction.coulomb``
    x [0.7, 1.3] (Tables 2-3 vary F_C over 1.1-1.9), the stiction kept at or
    above the Coulomb level, ``friction.viscous``, ``friction.sigma0`` and
    ``friction.sigma1`` x [0.5, 2].  A dict ``{key: (lo, hi)}`` gives other
    ranges (any numeric ``plant.*``/``friction.*`` key); its optional entry
    ``"friction_kind": ("coulomb", "classical", "lugre")`` also draws the
    friction model per episode.  The controller design is not part of the
    environment.

QUBE-Servo 2 (``frictionlab/QubeServo2-v0``, ``plant="qube2"``; or ``"qube3"``, ``"furuta-dc"``)
    The same environment on the DC-motor Furuta pendulum
    (:mod:`frictionlab.model.plants.furuta_dc`): the action is the motor
    voltage, saturated at ``plant.voltage_limit`` (10 V), the friction levels
    are in volts (the preset's), the observation is the SI one (``si`` only;
    no converters: ``raw`` and ``u_da`` are refused), and ``randomize=True``
    draws :data:`DC_RANDOMIZATION` (R_m and m_p x [0.9, 1.1], the joints'
    damping x [0.5, 2], the friction as above).  Balancing only.

Swing-up variant (``frictionlab/FurutaSwingUp-v0``, or ``task="swing_up"``)
    The same plant, friction, sensor, action and randomisation; the task is
    to bring the pendulum up from hanging and keep it there.  Each episode
    starts hanging at rest, at pi plus an angle drawn uniformly from
    [-0.05, 0.05] rad (``reset(options={"initial_angle": x})``: exactly x,
    any angle in [-pi, pi]).  The measured angle in the ``si`` observation is
    wrapped into [-pi, pi) (the ``raw`` one wraps as the rig's channel does).
    Reward ``(1 + cos theta)/2 - 0.01 (u/u_max)^2``: 0 hanging, 1 upright.
    *Terminated* when the arm leaves the swing-up's safety limits
    (``|Omega| > swingup.arm_limit``, ``|Omega'| > swingup.arm_speed_limit``)
    or the state is not finite; *truncated* after 2000 steps (10 s).  The
    energy-control swing-up of :mod:`frictionlab.model.swingup` is a baseline
    policy (docs/swingup.md).

Examples
--------
>>> import gymnasium as gym
>>> import frictionlab.gym  # registers frictionlab/Furuta-v0
>>> env = gym.make("frictionlab/Furuta-v0", friction="lugre", randomize=True)
>>> obs, info = env.reset(seed=0)
>>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .config import PLANT_FRICTION_KINDS, Config, build_config
from .model._jit import jit
from .model.friction import KINDS, NP, friction_row, friction_view, plant_record
from .model.plants import plant_step
from .model.sensor import reading, wrap_angle
from .model.simulation import plant_tick_rows
from .runs import make_sensor

__all__ = [
    "DC_RANDOMIZATION",
    "DEFAULT_RANDOMIZATION",
    "ENV_ID",
    "MAX_EPISODE_STEPS",
    "QUBE2_ENV_ID",
    "SWINGUP_ENV_ID",
    "TASKS",
    "FurutaEnv",
    "FurutaVectorEnv",
]

#: The registered id.
ENV_ID = "frictionlab/Furuta-v0"
#: The registered id of the swing-up variant (``task="swing_up"``).
SWINGUP_ENV_ID = "frictionlab/FurutaSwingUp-v0"
#: The registered id of the QUBE-Servo 2 (``plant="qube2"``: u the motor voltage).
QUBE2_ENV_ID = "frictionlab/QubeServo2-v0"
#: The tasks: balance from near upright, swing up from hanging.
TASKS = ("balance", "swing_up")
#: Steps before an episode is truncated (10 s at 5 ms).
MAX_EPISODE_STEPS = 2000
#: Per-episode multipliers (lo, hi) of the configured values, drawn uniformly.
DEFAULT_RANDOMIZATION: dict[str, tuple[float, float]] = {
    "plant.omega0": (0.9, 1.1),
    "plant.zeta": (0.5, 1.5),
    "plant.input_gain": (0.8, 1.2),
    "friction.stiction": (0.7, 1.3),
    "friction.coulomb": (0.7, 1.3),
    "friction.viscous": (0.5, 2.0),
    "friction.sigma0": (0.5, 2.0),
    "friction.sigma1": (0.5, 2.0),
}
#: The default randomisation of a motor plant (``plant="qube2"``...).
DC_RANDOMIZATION: dict[str, tuple[float, float]] = {
    "plant.resistance": (0.9, 1.1),
    "plant.pendulum_mass": (0.9, 1.1),
    "plant.arm_damping": (0.5, 2.0),
    "plant.pendulum_damping": (0.5, 2.0),
    "friction.stiction": (0.7, 1.3),
    "friction.coulomb": (0.7, 1.3),
    "friction.viscous": (0.5, 2.0),
    "friction.sigma0": (0.5, 2.0),
    "friction.sigma1": (0.5, 2.0),
}
_BIG = float(np.finfo(np.float64).max)  # "unbounded" without an infinite Box bound
_INFO = ("theta", "theta_dot", "arm", "arm_dot", "z")


@jit
def _step_plants(mask, pcode, xs, us, mems, friction, substeps, ratios, h, pps, fkinds, fps):
    """Advance plant i (row i of ``xs``) over one sample with ``us[i]`` held,
    for every i with ``mask[i]``: the simulator's plant step (plant code ``pcode``)."""
    for i in range(xs.shape[0]):
        if mask[i]:
            friction[i], mems[i] = plant_step(pcode, xs[i], us[i], mems[i], substeps[i],
                                              ratios[i], h, pps[i], fkinds[i],
                                              friction_view(fps[i]))


@jit
def _sense(xs, draws, sp, steps, x0s, out):
    """The simulator's sensor (:func:`frictionlab.model.sensor.reading`): each signal
    (theta, Omega, Omega_dot) plus its noise draw, through the rig's converter;
    plant i's arm zero ``x0s[i]`` is taken at its first step."""
    for i in range(xs.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], x0s[i] = reading(
            sp, xs[i, 0] + draws[i, 0], xs[i, 2] + draws[i, 1], xs[i, 3] + draws[i, 2],
            steps[i] == 0, x0s[i])


class _Plants:
    """``n`` plants with their own (randomised) parameters and their sensor."""

    def __init__(self, n: int, cfg: Config):
        self.n = n
        self.h = cfg.design.h
        self.noise = cfg.sim.noise
        self.sensor = make_sensor(cfg)._replace(noise=0.0)  # the draws come from the env
        self.fall = cfg.sim.fall_angle
        self.pcode = cfg.plant_model.code  # the plant's code (model.plants.plant_step)
        self.xs = np.zeros((n, 5))
        self.mems = np.zeros(n)
        self.friction = np.zeros(n)
        self.us = np.zeros(n)
        self.substeps = np.zeros(n, dtype=np.int64)
        self.ratios = np.zeros(n, dtype=np.int64)
        self.pps = np.zeros((n, len(cfg.plant_row())))
        self.fkinds = np.zeros(n, dtype=np.int64)
        self.fps = np.zeros((n, NP))  # friction records as float rows
        self.steps = np.zeros(n, dtype=np.int64)
        self.configs: list[Config] = [cfg] * n
        self._draws = np.zeros((n, 3))
        self._arm_zero = np.zeros(n)
        self._out = np.zeros((n, 3))
        self._x0 = self.xs[0]  # a view: plant 0's state

    def start(self, i: int, cfg: Config, theta0: float) -> None:
        """Plant i at rest at ``theta0`` with the parameters of ``cfg``."""
        self.configs[i] = cfg
        self.pps[i] = cfg.plant_row()
        self.fps[i] = friction_row(plant_record(cfg.friction_kind, cfg.friction))
        self.fkinds[i] = KINDS.index(cfg.friction_kind)
        self.substeps[i] = cfg.substeps
        self.ratios[i] = cfg.pendulum_ratio
        self.xs[i] = 0.0
        self.xs[i, 0] = theta0
        self.mems[i] = 0.0
        self.friction[i] = 0.0
        self.us[i] = 0.0
        self.steps[i] = 0
        if i == 0:  # plant 0's arguments, ready for step_first
            self._first = (int(self.substeps[0]), int(self.ratios[0]), self.h, self.pps[0],
                           int(self.fkinds[0]), self.fps[0])

    def step(self, mask: np.ndarray, u: np.ndarray) -> None:
        self.us[mask] = u[mask]
        _step_plants(mask, self.pcode, self.xs, self.us, self.mems, self.friction, self.substeps,
                     self.ratios, self.h, self.pps, self.fkinds, self.fps)
        self.steps[mask] += 1

    def step_first(self, u: float) -> None:
        """:meth:`step` of plant 0 alone, without the batch's array work."""
        self.us[0] = u
        self.friction[0], self.mems[0] = plant_tick_rows(self.pcode, self._x0, u, self.mems[0],
                                                            *self._first)
        self.steps[0] += 1

    def measure(self, rng: np.random.Generator) -> np.ndarray:
        """The sensor's readings of every plant, shape (n, 3) (a new array)."""
        if self.noise > 0.0:
            rng.standard_normal(out=self._draws)
            self._draws *= self.noise
        _sense(self.xs, self._draws, self.sensor, self.steps, self._arm_zero, self._out)
        return self._out.copy()

    def fallen(self, theta, rest):
        """Ended (as in the simulator): ``|theta|`` past the fall angle or a state
        (``rest`` = theta_dot + arm_dot + z) not finite; floats or arrays."""
        return np.logical_not((np.abs(theta) <= self.fall) & (np.abs(rest) < math.inf))

    def info(self) -> dict[str, np.ndarray]:
        out = {name: self.xs[:, j].copy() for j, name in enumerate(_INFO)}
        out["u"] = self.us.copy()
        out["friction"] = self.friction.copy()
        out["t"] = self.steps * self.h
        return out


class _Settings:
    """What a single and a vector environment share: the base configuration,
    the observation and action conversions, the randomisation."""

    def __init__(self, config, design, friction, sets, observation, action, randomize,
                 render_mode, task="balance", plant="thesis"):
        if task not in TASKS:
            raise ValueError(f"task must be one of {', '.join(TASKS)}, got {task!r}")
        self.task = task
        self.swing = task == "swing_up"
        if render_mode is not None:
            raise ValueError(f"render_mode must be None (no rendering), got {render_mode!r}")
        if observation not in ("si", "raw"):
            raise ValueError(f"observation must be 'si' or 'raw', got {observation!r}")
        if action not in ("u", "u_da"):
            raise ValueError(f"action must be 'u' or 'u_da', got {action!r}")
        if config is not None and not isinstance(config, Config):
            raise TypeError(f"config must be a frictionlab Config, got {type(config).__name__}")
        self.base = config if config is not None else build_config(design, friction,
                                                                   sets=list(sets),
                                                                   plant=plant)
        self.observation = observation
        self.action = action
        self.scaling = self.base.rig
        motor = self.base.motor
        if motor and (observation == "raw" or action == "u_da"):
            raise ValueError(f"the {self.base.plant_kind!r} plant has no 12-bit converters: "
                             "use observation='si' and action='u' (volts)")
        if motor and task == "swing_up":
            raise ValueError(f"the swing-up task of the {self.base.plant_kind!r} plant is not "
                             "implemented yet")
        # u's limit: the DAC's range, or a motor plant's voltage limit
        self.u_max = self.base.plant.voltage_limit if motor else self.scaling.u_max
        if randomize is True and motor:
            randomize = DC_RANDOMIZATION
        self.ranges, self.kinds = _check_randomization(self.base, randomize)
        if observation == "si":
            bound = np.array([2.0 * math.pi, _BIG, _BIG])
            self.observation_space = spaces.Box(-bound, bound, dtype=np.float64)
        else:
            self.observation_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float64)
        high = self.u_max if action == "u" else 1.0
        self.action_space = spaces.Box(-high, high, shape=(1,), dtype=np.float64)

    def draw(self, rng: np.random.Generator) -> tuple[Config, dict[str, Any]]:
        """An episode's configuration (randomised when asked) and its drawn values."""
        cfg = self.base
        if not (self.ranges or self.kinds):
            return cfg, {}
        if self.kinds:
            cfg = dataclasses.replace(cfg, friction_kind=self.kinds[int(rng.integers(
                len(self.kinds)))])
        values: dict[str, Any] = {}
        for key, (lo, hi) in self.ranges.items():
            values[key] = self.base.get(key) * float(rng.uniform(lo, hi))
        if "friction.stiction" in values or "friction.coulomb" in values:
            fs = values.get("friction.stiction", cfg.friction.stiction)
            fc = values.get("friction.coulomb", cfg.friction.coulomb)
            if fs < fc:
                values["friction.stiction"] = fc
        cfg = cfg.with_values(values) if values else cfg
        params = {"friction_kind": cfg.friction_kind} if self.kinds else {}
        params.update({k: cfg.get(k) for k in values})
        return cfg, params

    def initial_angle(self, rng: np.random.Generator, options: Mapping[str, Any] | None,
                      n: int) -> np.ndarray:
        fall = self.base.sim.fall_angle
        if options and "initial_angle" in options:
            theta0 = np.broadcast_to(np.asarray(options["initial_angle"], dtype=float),
                                     (n,)).copy()
            if self.swing:
                if not np.all(np.abs(theta0) <= math.pi):
                    raise ValueError(f"initial_angle must be in [-pi, pi], got "
                                     f"{options['initial_angle']}")
                return theta0
            if not np.all(np.abs(theta0) < fall):
                raise ValueError(f"initial_angle must be within the fall angle +-{fall:g} rad, "
                                 f"got {options['initial_angle']}")
            return theta0
        if self.swing:
            return math.pi + rng.uniform(-0.05, 0.05, size=n)
        a = abs(self.base.sim.initial_angle)
        return rng.uniform(-a, a, size=n)

    def u(self, actions) -> np.ndarray:
        """Control signals (m/s^2) of a batch of actions, saturated like the DAC."""
        a = np.asarray(actions, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {actions}")
        if self.action == "u_da":
            return np.asarray(self.scaling.u_from_da(a), dtype=np.float64)
        return np.clip(a, -self.u_max, self.u_max)

    def observe(self, measured: np.ndarray) -> np.ndarray:
        if self.observation == "raw":
            s = self.scaling
            return np.column_stack([s.raw_theta(measured[:, 0]), s.raw_arm(measured[:, 1]),
                                    s.raw_arm_velocity(measured[:, 2])])
        if self.swing:
            measured[:, 0] = wrap_angle.py_func(measured[:, 0])
        return measured

    def ended(self, plants: _Plants, x):
        """Terminated: fallen (balance) or out of the swing-up's arm limits (swing-up),
        or a state not finite; ``x`` one plant state (5,) or all (n, 5)."""
        if not self.swing:
            return plants.fallen(x[..., 0], x[..., 1] + x[..., 3] + x[..., 4])
        su = self.base.swingup
        ok = ((np.abs(x[..., 2]) <= su.arm_limit) & (np.abs(x[..., 3]) <= su.arm_speed_limit)
              & (np.abs(x[..., 0] + x[..., 1] + x[..., 4]) < math.inf))
        return np.logical_not(ok)

    def reward(self, theta, u):
        """``1 - (theta/fall_angle)^2 - 0.01 (u/u_max)^2`` (floats or arrays); swing-up:
        ``(1 + cos theta)/2 - 0.01 (u/u_max)^2``."""
        w = u / self.u_max
        if self.swing:
            return 0.5 * (1.0 + np.cos(theta)) - 0.01 * (w * w)
        q = theta / self.base.sim.fall_angle
        return 1.0 - q * q - 0.01 * (w * w)  # products: the same rounding for both


class FurutaEnv(gymnasium.Env):
    """The rotary pendulum with arm friction, one sampling period per step.

    See the module docstring for the observation, action, reward, episode
    and randomisation.

    Parameters
    ----------
    config : Config, optional
        Plant, friction, ``design.h`` and ``sim.*`` (noise, quantisation,
        initial and fall angle) settings; default ``build_config(design,
        friction, sets=sets)``.
    design, friction : str
        Used when ``config`` is None (``friction`` any of
        :data:`frictionlab.config.PLANT_FRICTION_KINDS`; default classical).
    sets : sequence of ``"KEY=VALUE"``
        Overrides when ``config`` is None, as ``--set`` on the command line.
    observation : {"si", "raw"}
    action : {"u", "u_da"}
    randomize : bool or mapping
        Per-episode randomisation: False (none), True
        (:data:`DEFAULT_RANDOMIZATION`) or ``{key: (lo, hi)}`` multipliers
        (plus an optional ``"friction_kind"`` sequence).
    render_mode : None
        No rendering (the info dict carries the true state).
    task : {"balance", "swing_up"}
        ``swing_up``: the swing-up variant (module docstring;
        ``frictionlab/FurutaSwingUp-v0``).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [], "render_fps": 200}

    def __init__(self, config: Config | None = None, *, design: str = "fast",
                 friction: str = "classical", sets: Sequence[str] = (),
                 observation: str = "si", action: str = "u",
                 randomize: bool | Mapping[str, Any] = False, render_mode: str | None = None,
                 task: str = "balance", plant: str = "thesis"):
        self._s = _Settings(config, design, friction, sets, observation, action, randomize,
                            render_mode, task, plant)
        self.render_mode = None
        self.observation_space = self._s.observation_space
        self.action_space = self._s.action_space
        self.u_max = self._s.u_max
        self._plants = _Plants(1, self._s.base)
        self._started = False

    @property
    def config(self) -> Config:
        """The configuration of the current episode (randomised when asked)."""
        return self._plants.configs[0]

    def u_from_action(self, action) -> float:
        """The control signal u (m/s^2) an action applies (saturated to the DAC range)."""
        s = self._s
        a = action[0] if isinstance(action, np.ndarray) and action.shape == (1,) else (
            np.asarray(action, dtype=np.float64).reshape(-1)[0])
        a = float(a)
        if not math.isfinite(a):
            raise ValueError(f"action must be finite, got {action}")
        if s.action == "u_da":
            return float(s.scaling.u_from_da(a))
        return min(max(a, -s.u_max), s.u_max)

    def action_from_u(self, u: float) -> np.ndarray:
        """The action that applies the control signal ``u`` (m/s^2)."""
        s = self._s
        a = float(s.scaling.u_da(u)) if s.action == "u_da" else float(
            np.clip(u, -s.u_max, s.u_max))
        return np.array([a], dtype=np.float64)

    def _info(self) -> dict[str, Any]:
        p = self._plants
        x = p.xs[0]
        return {"theta": float(x[0]), "theta_dot": float(x[1]), "arm": float(x[2]),
                "arm_dot": float(x[3]), "z": float(x[4]), "u": float(p.us[0]),
                "friction": float(p.friction[0]), "t": int(p.steps[0]) * p.h}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        cfg, params = self._s.draw(self.np_random)
        theta0 = self._s.initial_angle(self.np_random, options, 1)[0]
        self._plants.start(0, cfg, float(theta0))
        self._started = True
        info = self._info()
        info["params"] = params
        return self._s.observe(self._plants.measure(self.np_random))[0], info

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        p = self._plants
        u = self.u_from_action(action)
        p.step_first(u)
        x = p.xs[0]
        theta = float(x[0])
        terminated = bool(self._s.ended(p, x))
        reward = float(self._s.reward(theta, u))
        if not math.isfinite(reward):
            reward = -1.0
        obs = self._s.observe(p.measure(self.np_random))[0]
        return obs, reward, terminated, False, self._info()


class FurutaVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`FurutaEnv` stepped together in one compiled loop.

    The same plants, sensor, reward and randomisation (drawn per copy at each
    of its resets) as :class:`FurutaEnv`; next-step autoreset (a copy whose
    episode ended is reset by the following ``step``, which returns its first
    observation with reward 0); each copy is truncated after
    ``max_episode_steps``.  The info holds arrays of the single environment's
    entries (and their ``_name`` masks), without ``params``; ``configs`` lists
    the copies' current configurations.

    Parameters
    ----------
    num_envs : int
    max_episode_steps : int
        Default :data:`MAX_EPISODE_STEPS` (10 s).
    config, design, friction, sets, observation, action, randomize, render_mode, task
        As for :class:`FurutaEnv`.
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP,
                                          "render_modes": []}

    def __init__(self, num_envs: int = 8, config: Config | None = None, *,
                 design: str = "fast", friction: str = "classical", sets: Sequence[str] = (),
                 observation: str = "si", action: str = "u",
                 randomize: bool | Mapping[str, Any] = False,
                 max_episode_steps: int = MAX_EPISODE_STEPS, render_mode: str | None = None,
                 task: str = "balance", plant: str = "thesis"):
        if not (isinstance(num_envs, int) and num_envs >= 1):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if not (isinstance(max_episode_steps, int) and max_episode_steps >= 1):
            raise ValueError(f"max_episode_steps must be an integer >= 1, got "
                             f"{max_episode_steps!r}")
        self._s = _Settings(config, design, friction, sets, observation, action, randomize,
                            render_mode, task, plant)
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.render_mode = None
        self.single_observation_space = self._s.observation_space
        self.single_action_space = self._s.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._plants = _Plants(num_envs, self._s.base)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._started = False

    @property
    def configs(self) -> list[Config]:
        """Each copy's current configuration."""
        return list(self._plants.configs)

    def _start(self, which: np.ndarray, options=None) -> None:
        theta0 = self._s.initial_angle(self.np_random, options, self.num_envs)
        for i in np.flatnonzero(which):
            cfg, _ = self._s.draw(self.np_random)
            self._plants.start(int(i), cfg, float(theta0[i]))

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {}
        for k, v in self._plants.info().items():
            info[k] = v
            info[f"_{k}"] = np.ones(self.num_envs, dtype=np.bool_)
        return info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._start(np.ones(self.num_envs, dtype=np.bool_), options)
        self._autoreset[:] = False
        self._started = True
        return self._s.observe(self._plants.measure(self.np_random)), self._info()

    def step(self, actions):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        p = self._plants
        u = self._s.u(actions)
        if u.shape != (self.num_envs,):
            raise ValueError(f"actions must have shape {self.action_space.shape}, got "
                             f"{np.shape(actions)}")
        restart = self._autoreset.copy()
        if restart.any():
            self._start(restart)
        stepping = ~restart
        p.step(stepping, u)
        x = p.xs
        terminated = self._s.ended(p, x) & stepping
        truncated = (p.steps >= self.max_episode_steps) & stepping & ~terminated
        reward = self._s.reward(x[:, 0], p.us)
        reward = np.where(stepping, np.where(np.isfinite(reward), reward, -1.0), 0.0)
        self._autoreset = terminated | truncated
        obs = self._s.observe(p.measure(self.np_random))
        return obs, reward, terminated, truncated, self._info()


def _check_randomization(cfg: Config, randomize) -> tuple[dict[str, tuple[float, float]],
                                                          tuple[str, ...]]:
    """Validated (ranges, friction kinds) of the ``randomize`` argument."""
    if randomize is False or randomize is None:
        return {}, ()
    if randomize is True:
        spec: Mapping[str, Any] = DEFAULT_RANDOMIZATION
    elif isinstance(randomize, Mapping):
        spec = randomize
    else:
        raise ValueError(f"randomize must be True, False or a dict of key: (lo, hi), got "
                         f"{randomize!r}")
    ranges: dict[str, tuple[float, float]] = {}
    kinds: tuple[str, ...] = ()
    for key, value in spec.items():
        if key == "friction_kind":
            kinds = tuple(value)
            bad = [k for k in kinds if k not in PLANT_FRICTION_KINDS]
            if not kinds or bad:
                raise ValueError(f"randomize friction_kind: give models among "
                                 f"{', '.join(PLANT_FRICTION_KINDS)}, got {value!r}")
            continue
        if not (key.startswith("plant.") or key.startswith("friction.")):
            raise ValueError(f"randomize {key}: only plant.* and friction.* keys")
        try:
            lo, hi = (float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(f"randomize {key}: give (lo, hi) multipliers, got "
                             f"{value!r}") from None
        if not (0.0 < lo <= hi and math.isfinite(hi)):
            raise ValueError(f"randomize {key}: multipliers must satisfy 0 < lo <= hi, "
                             f"got ({lo:g}, {hi:g})")
        base = cfg.get(key)  # unknown keys: ConfigError naming the key
        if not isinstance(base, int | float):
            raise ValueError(f"randomize {key}: not a numeric key (value {base!r})")
        # both ends must be valid values of the key
        cfg.with_values({key: base * lo})
        cfg.with_values({key: base * hi})
        ranges[key] = (lo, hi)
    return ranges, kinds


def _register() -> None:
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="frictionlab.gym:FurutaEnv",
                           vector_entry_point="frictionlab.gym:FurutaVectorEnv",
                           max_episode_steps=MAX_EPISODE_STEPS)
    if SWINGUP_ENV_ID not in gymnasium.registry:
        gymnasium.register(id=SWINGUP_ENV_ID, entry_point="frictionlab.gym:FurutaEnv",
                           vector_entry_point="frictionlab.gym:FurutaVectorEnv",
                           max_episode_steps=MAX_EPISODE_STEPS,
                           kwargs={"task": "swing_up"})
    if QUBE2_ENV_ID not in gymnasium.registry:
        gymnasium.register(id=QUBE2_ENV_ID, entry_point="frictionlab.gym:FurutaEnv",
                           vector_entry_point="frictionlab.gym:FurutaVectorEnv",
                           max_episode_steps=MAX_EPISODE_STEPS, kwargs={"plant": "qube2"})


_register()
