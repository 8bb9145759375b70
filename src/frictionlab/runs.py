"""The runs a configuration describes: the model's objects built from a
:class:`~frictionlab.config.Config`, and the simulations of it.

The model (:mod:`frictionlab.model`) knows no configuration: its kernels take
parameter records and a :class:`~frictionlab.model.simulation.LoopSpec`.  This
module, one layer above the configuration, builds them: the sensor
(:func:`make_sensor`), the controller (:func:`make_controller`), the whole loop
(:func:`loop_spec`), the simulated plant of the emulated rigs
(:func:`simulated_plant`), and runs the simulator (:func:`simulate_config`,
:func:`simulate`, :func:`run_features`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from .config import Config, build_config
from .model.actuator import ActuatedPlant
from .model.controller import DEFAULT_ERROR_SIGNAL, Controller
from .model.design import design as make_design
from .model.limit_cycles import LimitCycleFeatures, trajectory_features
from .model.plants.furuta_dc import linearization as dc_linearization
from .model.plants.furuta_dc_design import dc_design
from .model.plants.thesis import linearized_model
from .model.sensor import SensorParams, sensor_params
from .model.simulation import LoopSpec, SimulatedPlant, Trajectory
from .model.simulation import run_ticks as ticks_of
from .model.simulation import simulate as simulate_spec

__all__ = [
    "linearization_json",
    "loop_spec",
    "make_controller",
    "make_sensor",
    "plant_design",
    "plant_linearization",
    "run_features",
    "run_ticks",
    "simulate",
    "simulate_config",
    "simulated_plant",
]


def make_sensor(cfg: Config) -> SensorParams:
    """The sensor a configuration describes (``rig.*``, ``sim.quantization`` on the grid
    ``Config.sensor_step``,
    ``sim.noise``, ``sim.seed``; the arm's raw zero :data:`~frictionlab.model.sensor.ARM_START`)."""
    return sensor_params(cfg.rig, cfg.sim.quantization, cfg.sim.noise, cfg.sim.seed,
                         step=cfg.sensor_step)


def plant_design(cfg: Config, method: str = "closed_form"):
    """The balancing design of the configured plant: the thesis's
    (:func:`frictionlab.model.design.design`, ``method`` its computation), or
    for a motor plant :func:`frictionlab.model.plants.furuta_dc_design.dc_design`
    (the Sec. 2.4 pattern on its linearisation; ``design.omega0`` is the
    plant's own)."""
    if cfg.motor:
        return dc_design(cfg.design, cfg.plant)
    return make_design(cfg.design, cfg.plant, method=method)


def plant_linearization(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """The configured plant's continuous linearisation at upright: A (4, 4) and
    B (4, 1), states (theta, theta_dot, arm, arm_dot) in SI, input u in its
    units (m/s^2 for the thesis plant, with its damping and ``plant.input_gain``:
    eq. (7); volts for a motor plant:
    :func:`frictionlab.model.plants.furuta_dc.linearization`)."""
    p = cfg.plant
    if cfg.motor:
        return dc_linearization(p)
    A, B, _ = linearized_model(p.omega0, p.g, p.arm_length, p.zeta)
    return A, B * p.input_gain


def linearization_json(cfg: Config) -> dict:
    """:func:`plant_linearization` as ``design --json``'s ``linearization`` object."""
    A, B = plant_linearization(cfg)
    return {"A": [[float(v) for v in row] for row in A],
            "B": [[float(v) for v in row] for row in B],
            "states": ["theta", "theta_dot", "arm", "arm_dot"],
            "input": f"u ({cfg.plant_model.u_unit})"}


def make_controller(cfg: Config, error_signal: str = DEFAULT_ERROR_SIGNAL) -> Controller:
    """The balancing controller a configuration describes (design, compensator, the
    saturation of u at ``controller.u_max`` within the DAC's range or a motor
    plant's voltage limit, Config.u_limit)."""
    return Controller(plant_design(cfg), cfg.compensation_kind, cfg.compensation,
                      error_signal=error_signal, u_max=cfg.u_limit)


def loop_spec(cfg: Config, controller: Controller | None = None,
              open_loop: bool = False) -> LoopSpec:
    """The closed loop a configuration describes (``controller`` in place of its
    own; ``open_loop``: u held at 0, no fall stop, :class:`LoopSpec`)."""
    # the thesis plant with its actuator (App. B.4) when actuator.* is on
    plant = (ActuatedPlant(cfg.plant, cfg.actuator) if cfg.actuator.enabled and not cfg.motor
             else cfg.plant)
    return LoopSpec(cfg.plant_model, plant, cfg.friction_kind, cfg.friction,
                    controller or make_controller(cfg), make_sensor(cfg), cfg.design.h,
                    cfg.substeps, cfg.pendulum_ratio, cfg.sim.fall_angle, cfg.sim.initial_angle,
                    cfg.sim.duration, cfg, open_loop)


def simulated_plant(cfg: Config, duration: float | None = None) -> SimulatedPlant:
    """The plant of ``cfg`` with its friction, stepped one sample at a time (its
    friction drift spread over ``duration``, default ``sim.duration``)."""
    return SimulatedPlant(loop_spec(cfg), duration)


def run_ticks(cfg: Config, duration: float | None = None, record: bool = True) -> int:
    """Ticks of a run of ``duration`` s (default ``sim.duration``) at ``design.h``
    (:func:`frictionlab.model.simulation.run_ticks`: a ValueError for a duration
    that is not positive, shorter than a period or, recorded, too long)."""
    return ticks_of(cfg.design.h, cfg.sim.duration if duration is None else duration, record)


def simulate_config(
    cfg: Config,
    duration: float | None = None,
    *,
    record: bool = True,
    progress: Callable[[float], None] | None = None,
    controller: Controller | None = None,
    open_loop: bool = False,
    switches: Sequence[tuple[float, Controller]] = (),
    transition: tuple[float, float] = (2.0, 2.0),
) -> Trajectory:
    """Run the closed loop described by ``cfg``.

    Parameters
    ----------
    cfg : Config
        Plant, design, friction, compensation and simulation settings.
    duration : float, optional
        Simulated time in s (default ``sim.duration``).
    record : bool
        Keep every tick's signals (always true for the public API).
    progress : callable, optional
        Called with the fraction done (runs are chunked so long runs can
        report progress).
    controller : Controller, optional
        Use this controller instead of the one ``cfg`` describes.
    switches, transition
        Changes of controller while the loop runs, made bumpless as the 200 Hz
        loop makes them (:func:`frictionlab.model.simulation.simulate`).
    open_loop : bool
        Hold u at 0 for the whole run, with no fall stop (a free swing).
    """
    return simulate_spec(loop_spec(cfg, controller, open_loop), duration, record=record,
                         progress=progress, switches=switches, transition=transition)


def run_features(cfg: Config, duration: float | None = None,
                 window: float | None = None) -> LimitCycleFeatures:
    """Simulate ``cfg`` and reduce the run to its limit-cycle features.

    The unit of work of sweeps, identification and tuning.

    Returns
    -------
    LimitCycleFeatures
        ``status`` is ``"fell"`` if the pendulum fell, else the features'
        status (``"limit_cycle"`` or ``"settled"``).
    """
    return trajectory_features(simulate_config(cfg, duration), window)


def simulate(
    design: str = "fast",
    friction: str = "classical",
    compensation: str = "none",
    duration: float | None = None,
    **values,
) -> Trajectory:
    """Build a configuration and simulate it: ``simulate("fast", "classical",
    friction__coulomb=1.3)`` (:func:`simulate_config`).

    Keyword names are keys with ``.`` written as ``__``.
    """
    sets = [(k.replace("__", "."), v) for k, v in values.items()]
    cfg = build_config(design, friction, compensation, sets=sets)
    return simulate_config(cfg, duration)
