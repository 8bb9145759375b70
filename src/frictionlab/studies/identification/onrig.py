"""Running an identification experiment on a rig through the real-time loop.

:func:`run_on_rig` plugs an experiment of :mod:`frictionlab.realtime.experiment`
into :class:`frictionlab.realtime.RealtimeController` (the loop of ``frictionlab
run``: the same timing, safety, signals and logging, whatever the backend:
``sim``, ``udp://HOST:PORT`` or ``serial://DEVICE``) and returns where the run
was logged; :func:`analyse_run` reads that log back and applies the analysis
of :mod:`.experiments`, the same one ``--log`` and ``--simulate`` use.

The run's ``.csv`` keeps every tick (the raw ``y, x, v, u_da`` too) and its
JSON sidecar the experiment's settings and marks (``experiment``), so a run
can be analysed again later with ``identify experiment NAME --log RUN.csv``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ...config import Config
from ...io.logs import read_log
from ...model.rig import RigScaling
from ...realtime import RealtimeController
from ...realtime.experiment import RigExperiment, make_experiment
from . import experiments as ex

__all__ = ["analyse_log", "analyse_run", "experiment_marks", "make_rig_experiment",
           "rig_scaling", "run_on_rig"]


def rig_scaling(cfg: Config) -> RigScaling:
    """The App. B conversion factors of ``cfg`` (``rig.*``; the thesis's by default)."""
    sc = getattr(cfg, "rig", None)
    return sc if isinstance(sc, RigScaling) else RigScaling()


def make_rig_experiment(name: str, cfg: Config, limits=None, *,
                        scaling: RigScaling | None = None, **options):
    """The experiment ``name`` for the loop, with ``cfg``'s period, k_u and omega_0."""
    if name == "free-oscillation":
        options.setdefault("omega0", cfg.design.omega0)
    sc = scaling or rig_scaling(cfg)
    return make_experiment(name, cfg.design.h, sc.u_scale, limits, **options)


def run_on_rig(experiment, cfg: Config, backend="sim", *, log_dir="runs", clock=None,
               realtime: bool = True, sim_lockstep: bool = False, on_start=None,
               poll=None, poll_interval: float = 0.5,
               scaling: RigScaling | None = None, on_prompt=None,
               hand: bool = False, safety=None) -> dict:
    """Run ``experiment`` through the real-time loop; return the run's statistics.

    Parameters
    ----------
    experiment : RigExperiment
        From :func:`make_rig_experiment` (one run per object).
    cfg : Config
        Design (h), ``rig.*`` scaling, and, for ``sim``, the simulated plant
        (its pendulum starts hanging at rest, ``sim.initial_angle`` = pi).
    backend : str or Rig
        ``sim``, ``udp://HOST:PORT``, ``serial://DEVICE`` or a rig object.
    log_dir : path
        Where the run is logged (``<run_id>.csv``/``.dat``/``.json``).
    clock : clock, optional
        A :class:`~frictionlab.realtime.FakeClock` runs the loop in the
        calling thread without sleeping (tests, ``--simulate``).
    on_start : callable, optional
        ``on_start(ctl)`` once the controller exists (signal handlers use it).
    poll : callable, optional
        ``poll(experiment)`` every ``poll_interval`` s while the run goes on
        (progress display); real-time runs only.
    scaling : RigScaling, optional
        The conversion factors the loop assumes (default ``cfg``'s ``rig.*``).
    on_prompt : callable, optional
        ``on_prompt(prompt)`` for each instruction of a guided step
        (``{"text", "hand"}``), e.g. to print it; real-time runs only.
    hand : bool
        Let the rig play the operator's hand for each guided step
        (``rig-sim`` over UDP: :meth:`RealtimeController.hand`).
    safety : Safety, optional
        The loop's stops (:class:`~frictionlab.realtime.Safety`; default its
        defaults).

    Returns
    -------
    dict
        The run's statistics (``stop_reason``, ``stop_detail``, ``log``, ...).

    Raises
    ------
    RigError, OSError
        The rig cannot be opened.
    """
    if not isinstance(experiment, RigExperiment):
        raise TypeError("experiment must be a RigExperiment")
    fake = clock is not None
    ctl = RealtimeController(cfg, backend, log_dir=log_dir, clock=clock,
                             realtime=realtime and not fake, manage_gc=not fake,
                             scaling=scaling or rig_scaling(cfg),
                             sim_lockstep=sim_lockstep or fake, experiment=experiment,
                             safety=safety)
    if on_start is not None:
        on_start(ctl)
    try:
        if fake:
            return ctl.run()
        ctl.start()
        prompts = experiment.prompts
        while not ctl.wait(0.05 if prompts or hand or on_prompt else poll_interval):
            while prompts:
                prompt = prompts.popleft()
                if on_prompt is not None:
                    on_prompt(prompt)
                if hand:
                    ctl.hand(prompt["hand"])
            if poll is not None:
                poll(experiment)
    finally:
        if ctl.running:
            ctl.stop("signal")
            ctl.wait(5.0)
    return ctl.last_stats


def experiment_marks(log_path) -> dict[str, float]:
    """The experiment's marks from a run's sidecar (``<run>.json``), or {}."""
    p = Path(log_path).with_suffix(".json")
    try:
        meta = json.loads(p.read_text())
    except (OSError, ValueError):
        return {}
    exp = meta.get("experiment") if isinstance(meta, dict) else None
    marks = exp.get("marks") if isinstance(exp, dict) else None
    if not isinstance(marks, dict):
        return {}
    return {k: float(v) for k, v in marks.items()
            if isinstance(v, int | float) and math.isfinite(v)}


def _finite_rows(log: Any, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The log's rows in which every one of ``names`` is finite (a run log has NaN
    rows for ticks without a reading and for the stop)."""
    cols = {}
    for n in names:
        try:
            cols[n] = np.asarray(log[n], dtype=float)
        except (KeyError, IndexError, ValueError):
            raise ex.IdentificationError(f"the log has no {n!r} signal") from None
    ok = np.ones(len(cols["t"]), dtype=bool)
    for c in cols.values():
        ok &= np.isfinite(c)
    return {n: c[ok] for n, c in cols.items()}


#: Signals each analysis reads.
SIGNALS = {"stiction": ("t", "u", "arm_dot_m"), "stribeck": ("t", "u", "arm_dot_m"),
           "free-oscillation": ("t", "theta_m"), "control-scaling": ("t", "u", "arm_dot_m"),
           "velocity-scale": ("t", "arm_m", "v"), "angle-scales": ("t", "y", "x")}


def analyse_log(name: str, log: Any, cfg: Config, *, marks: dict | None = None,
                max_amplitude: float = 0.15) -> dict:
    """The analysis of experiment ``name`` on ``log`` (a run log, a recording or a
    simulated trajectory); ``marks`` cut the free oscillation to its free decay."""
    data = _finite_rows(log, SIGNALS[name])
    marks = marks or {}
    if name == "free-oscillation" and "free" in marks:
        keep = data["t"] >= marks["free"]
        data = {k: v[keep] for k, v in data.items()}
    ku = cfg.plant.input_gain
    if name == "stiction":
        return ex.analyse_stiction(data, input_gain=ku, arm_length=cfg.plant.arm_length)
    if name == "stribeck":
        return ex.analyse_stribeck(data, input_gain=ku)
    if name == "free-oscillation":
        return ex.analyse_free_oscillation(data, max_amplitude=max_amplitude)
    if name == "control-scaling":
        return ex.analyse_control_scaling(data, coulomb=cfg.friction.coulomb,
                                          arm_length=cfg.plant.arm_length,
                                          nominal_u_scale=rig_scaling(cfg).u_scale)
    if name == "velocity-scale":
        return ex.analyse_velocity_scale(data)
    if name == "angle-scales":
        return ex.analyse_angle_scales(data, marks)
    raise ValueError(f"unknown experiment {name!r}")


def analyse_run(name: str, log_path, cfg: Config, *, max_amplitude: float = 0.15) -> dict:
    """Read a run's ``.csv`` and analyse it (marks from its sidecar)."""
    log = read_log(log_path, cfg.design.h)
    return analyse_log(name, log, cfg, marks=experiment_marks(log_path),
                       max_amplitude=max_amplitude)
